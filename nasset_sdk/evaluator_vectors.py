"""Evaluator test vectors (spec/evaluator-vectors.md): small generated assets, queries with edge cases,
and the SDK's answers, shipped as package data in ``nasset_sdk/evaluator_cases/<case>/``
(asset.usdc, inputs.npz, expected.npz, case.json).

:func:`generate` rebuilds every case deterministically from fixed seeds; the SDK's answers come from
:mod:`.evaluator_adapter`. ``scripts/make_evaluator_vectors.py`` writes them into the package.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from .errors import UsageError
from .images import write_text_atomic

#: the vectors shipped with the SDK (package data)
VECTORS_DIR = Path(__file__).resolve().parent / "evaluator_cases"

#: case -> (kind, variant, seed, {query: (arguments, outputs)}) -- spec/evaluator-vectors.md#queries
CASES: dict[str, tuple[str, str, int, dict[str, tuple[tuple[str, ...], tuple[str, ...]]]]] = {
    "rna_surface": ("rna", "surface", 11, {
        "transport": (("x", "n", "wo", "wi"), ("unshadowed", "shadowed")),
    }),
    "rna_fiber": ("rna", "fiber", 12, {
        "transport": (("x", "t", "h", "wo", "wi"), ("unshadowed", "shadowed")),
    }),
    "neupress": ("neupress", "surface", 13, {
        "subsurface": (("x", "wo", "wi"), ("y",)),
        "reflection": (("n", "wo", "wi"), ("y",)),
        "sigma": (("x", "wo"), ("sigma",)),
        "lobe_pdf": (("x", "n", "wo", "wi"), ("pdf",)),
        "lobe_sample": (("x", "n", "wo", "u"), ("wi", "pdf")),
        "prt": (("light_sh", "vertex", "n", "wo"), ("y",)),
    }),
    "8dna": ("8dna", "surface", 14, {
        "albedo": (("x", "wo"), ("y",)),
        "pdf": (("x", "wo", "ui", "wi", "channel"), ("pdf",)),
        "sample": (("x", "wo", "channel", "u"), ("ui", "wi", "pdf")),
        "direct": (("n", "wo", "wi"), ("y",)),
        "direct_pdf": (("n", "wo", "wi"), ("pdf",)),
        "direct_sample": (("n", "wo", "u"), ("wi", "pdf")),
    }),
}

#: (query, output) -> (atol, rtol): |got - want| <= atol + rtol |want| (spec/evaluator-vectors.md#tolerances)
TOLERANCES: dict[tuple[str, str], tuple[float, float]] = {
    ("reflection", "y"): (1e-6, 1e-5), ("direct", "y"): (1e-6, 1e-5), ("direct_pdf", "pdf"): (1e-6, 1e-5),
    ("direct_sample", "wi"): (1e-6, 0.0), ("direct_sample", "pdf"): (1e-6, 1e-5),
    ("prt", "y"): (1e-5, 1e-5),
    ("lobe_sample", "wi"): (1e-4, 0.0), ("sample", "ui"): (1e-4, 0.0), ("sample", "wi"): (1e-4, 0.0),
    ("pdf", "pdf"): (1e-5, 1e-3), ("sample", "pdf"): (1e-5, 1e-3),
}
#: network outputs and everything else
DEFAULT_TOLERANCE = (1e-5, 1e-4)
#: the optional network-input rows, compared bit for bit (the exact tier)
NETWORK_INPUT = "input"

# -- queries --------------------------------------------------------------------------------------------
_Z = -0.0
#: directions with signed zeros, poles, axes, grazing, unnormalised, huge, tiny and non-finite components
EDGE_DIRECTIONS = np.array([
    (0, 0, 1), (0, 0, -1), (_Z, _Z, 1), (_Z, _Z, -1), (0, _Z, -1), (_Z, 0, -1), (1, 0, 0), (-1, 0, 0), (-1, _Z, 0),
    (0, 1, 0), (0, -1, 0), (0, _Z, 1), (1, 1, 1e-9), (1e-10, 1e-10, 1), (2, 3, -6), (1e-3, -2e-3, 5e-4),
    (1e20, 1e20, -1e20), (1e300, -1e300, 1e300), (1e-25, 0, 0), (0, 0, 0), (np.inf, 0, 0), (np.nan, 1, 0),
    (-np.inf, np.inf, 1), (0.6, -0.8, 0), (-0.6, 0.8, _Z),
], np.float64)


def _points(rng, lo, hi, n_random: int, resolution: int | None) -> np.ndarray:
    """Points [N, 3]: box corners and face centres, the centre, outside and far points, texel centres and
    texel borders of a ``resolution``-texel plane, then ``n_random`` uniform points inside the box."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    unit = [np.array(c, np.float64) for c in ((-1, -1, -1), (1, 1, 1), (1, -1, 1), (0, 0, 0), (1, 0, 0), (0, -1, 0),
                                               (0, 0, 1), (2, 0.5, -0.5), (-3, -3, 4), (1e6, -1e6, 0), (-1, _Z, 0))]
    if resolution:
        r = resolution
        for k in (0, 1, r // 2, r - 1):
            c = (2 * k + 1) / r - 1  # texel centre
            e = 2 * k / r - 1  # texel border
            unit += [np.array((c, e, c)), np.array((e, c, e)), np.array((e, e, e))]
    unit += list(rng.uniform(-1, 1, (n_random, 3)))
    xn = np.stack(unit)
    return lo + (xn + 1.0) * 0.5 * (hi - lo)


def _directions(rng, n: int) -> np.ndarray:
    """[n, 3]: the edge directions in a seeded order, cycled, then Gaussian random ones."""
    edge = EDGE_DIRECTIONS[rng.permutation(len(EDGE_DIRECTIONS))]
    k = min(n, len(EDGE_DIRECTIONS))
    return np.concatenate([edge[:k], rng.normal(size=(n - k, 3))]) if n > k else edge[:n].copy()


def _latents(rng, n: int, k: int) -> np.ndarray:
    """[n, k] in [0, 1): the ends 0 and 1 - 2^-53 and 1/2 first, then uniform."""
    u = rng.random((n, k))
    u[:3] = [[0.0] * k, [np.nextafter(1.0, 0.0)] * k, [0.5] * k]
    return u


def _grazing(rng, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(normal, wo, wi) [n, 3]: grazing pairs, wo = wi, wo = -wi, below-surface pairs, then edge/random mixes."""
    nrm = np.tile([0.0, 0.0, 1.0], (8, 1))
    wo = np.array([(1, 0, 1e-7), (1, 0, 1e-13), (0.3, 0.4, 0.5), (0.3, 0.4, 0.5), (0, 0, 1), (1, 0, -0.1), (1, 0, 0.2), (0, 0, 1)])
    wi = np.array([(-1, 0, 1e-7), (1, 0, 1e-13), (0.3, 0.4, 0.5), (-0.3, -0.4, -0.5), (0, 0, 1), (-1, 0, 0.1), (1, 0, -0.2), (0, 1e-9, 1)])
    return (np.concatenate([nrm, _directions(rng, n - 8)]), np.concatenate([wo, _directions(rng, n - 8)]),
            np.concatenate([wi, _directions(rng, n - 8)]))


def make_queries(kind_id: str, variant: str, queries: dict, asset, rng) -> dict[str, np.ndarray]:
    """Inputs ``{query.argument: array}`` for one case (float64; ``vertex`` and ``channel`` int64)."""
    lo, hi = asset.domain
    res = None
    if "triplane" in asset.tensor_refs("core"):
        res = int(asset.tensor_refs("core")["triplane"].shape[1])
    x = _points(rng, lo, hi, 24, res)
    n = len(x)
    out: dict[str, np.ndarray] = {}
    for q, (args, _) in queries.items():
        nrm, wo, wi = _grazing(rng, n)
        vals = {"x": x, "n": nrm, "t": nrm, "wo": wo, "wi": wi,
                "h": np.concatenate([[0.0, _Z, 1.0, -1.0, 2.5, -7.0, np.nan, 1e-30], rng.uniform(-1, 1, n - 8)]),
                "u": _latents(rng, n, 4 if q == "sample" else 2),
                "channel": np.arange(n, dtype=np.int64) % 3,
                "light_sh": rng.normal(size=(9, 3))}
        if q == "pdf":  # points on the box: faces, edges, corners, then random directions from the centre
            c, e = (np.asarray(lo) + np.asarray(hi)) / 2, (np.asarray(hi) - np.asarray(lo)) / 2
            d = np.concatenate([np.eye(3), -np.eye(3), [[1, 1, 1], [-1, 1, -1], [1, 1, 0], [0, _Z, -1]],
                                rng.normal(size=(n - 10, 3))])
            d = d / np.linalg.norm(d, axis=1, keepdims=True)
            tau = np.min(e / np.maximum(np.abs(d), 1e-300), axis=1, keepdims=True)
            tau[-2:] *= [[0.5], [2.0]]  # two points off the box: readers project along u_i - c
            vals["ui"] = c + tau * d
        if q == "prt":
            v = int(asset.tensor_refs("prt")["sh"].shape[0])
            vals["vertex"] = np.concatenate([[0, v - 1], rng.integers(0, v, n - 2)]).astype(np.int64)
        for a in args:
            out[f"{q}.{a}"] = np.asarray(vals[a])
    return out


# -- files ------------------------------------------------------------------------------------------------
def read_npz(path) -> dict[str, np.ndarray]:
    """All arrays of an NPZ file (no pickles)."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def write_npz(path, arrays: dict[str, np.ndarray]) -> None:
    """Write an uncompressed NPZ atomically with fixed member timestamps (byte-identical for equal arrays)."""
    path = Path(path)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for k in sorted(arrays):
            item = io.BytesIO()
            np.lib.format.write_array(item, np.ascontiguousarray(arrays[k]), allow_pickle=False)
            zf.writestr(zipfile.ZipInfo(f"{k}.npy", date_time=(1980, 1, 1, 0, 0, 0)), item.getvalue())
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=path.parent)
    with os.fdopen(fd, "wb") as fh:
        fh.write(buf.getvalue())
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)


def tolerance(query: str, output: str) -> tuple[float, float]:
    return TOLERANCES.get((query, output), DEFAULT_TOLERANCE)


def _subnormal_corners(builder) -> None:
    """float16 subnormals (2^-24 .. 4 2^-24, and -3e-6) in the corner texels that the box-corner queries read."""
    core = builder.components["core"][""]
    if "triplane" not in core.tensors:
        return
    arr, dtype, layout = core.tensors["triplane"]
    arr = np.array(arr, np.float64)
    arr[0, 0, 0, :] = 2.0 ** -24 * np.arange(1, arr.shape[-1] + 1)
    arr[1, -1, -1, :] = -3e-6
    core.add_tensor("triplane", arr, dtype=dtype, layout=layout)


def generate(out_dir, names=None) -> list[Path]:
    """Write every case (or ``names``) into ``out_dir/<case>/``; returns the case folders."""
    import trimesh

    from .asset import Asset
    from .evaluator_adapter import answer
    from .geometry import MeshGeometry
    from .kinds import get_kind

    out_dir = Path(out_dir)
    names = list(CASES) if names is None else list(names)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise UsageError(f"unknown evaluator vector cases {unknown}; known: {', '.join(CASES)}")
    folders = []
    for name in names:
        kind_id, variant, seed, queries = CASES[name]
        rng = np.random.default_rng(seed)
        geometry = None if variant == "fiber" else MeshGeometry.from_trimesh(trimesh.creation.icosahedron())
        folder = out_dir / name
        folder.mkdir(parents=True, exist_ok=True)
        builder = get_kind(kind_id).build_random(rng, variant=variant, size="tiny", geometry=geometry)
        _subnormal_corners(builder)
        builder.write(folder / "asset.usdc")
        os.chmod(folder / "asset.usdc", 0o644)
        asset = Asset.open(folder / "asset.usdc", load="all")
        inputs = make_queries(kind_id, variant, queries, asset, rng)
        expected = answer(folder / "asset.usdc", inputs)
        write_npz(folder / "inputs.npz", inputs)
        write_npz(folder / "expected.npz", expected)
        info = {"kind": kind_id, "variant": variant, "queries": {
            q: {"arguments": list(args), "outputs": {o: dict(zip(("atol", "rtol"), tolerance(q, o), strict=True)) for o in outs},
                "network_input": f"{q}.{NETWORK_INPUT}" in expected}
            for q, (args, outs) in queries.items()}}
        write_text_atomic(folder / "case.json", json.dumps(info, indent=1, sort_keys=True) + "\n")
        folders.append(folder)
    return folders
