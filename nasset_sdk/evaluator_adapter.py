"""The SDK's answers to evaluator test-vector queries (spec/evaluator-vectors.md#queries).

The one place that calls the kinds' evaluators for the vectors: :func:`answer` maps each query of the
protocol onto the evaluator methods of spec/kinds/*.md. It is also the SDK's own evaluator command,
``python -m nasset_sdk.evaluator_adapter ASSET INPUT.npz OUTPUT.npz``, so the SDK passes the vectors
through the same protocol as any other implementation.
"""

from __future__ import annotations

import sys

import numpy as np

from .kinds.encodings import fourier_features, spherical_coords, to_unit_box


def _rna(ev, q: str, a: dict) -> dict:
    frame = a["t"] if ev.fiber else a["n"]
    h = a.get("h")
    un, sh = ev.evaluate(a["x"], frame, a["wo"], a["wi"], h)
    inp = ev.network_input(a["x"], frame, a["wo"], a["wi"], h)
    return {"unshadowed": un, "shadowed": sh, "input": inp}


def _neupress(ev, q: str, a: dict) -> dict:
    if q == "subsurface":
        n = np.zeros_like(np.asarray(a["x"], np.float64))  # not a network input
        feats = fourier_features(ev.G, ev.appearance_input(a["x"], a["wo"], a["wi"]))
        return {"y": ev.evaluate(a["x"], n, a["wo"], a["wi"]), "input": feats}
    if q == "reflection":
        return {"y": ev.surface_reflection(a["n"], a["wo"], a["wi"])}
    if q == "sigma":
        v = np.concatenate([to_unit_box(a["x"], ev.lo, ev.hi), spherical_coords(a["wo"])], axis=1)
        return {"sigma": ev.sigma(a["x"], a["wo"]), "input": fourier_features(ev.Gs, v)}
    if q == "lobe_pdf":
        return {"pdf": ev.lobe_pdf(a["x"], a["n"], a["wo"], a["wi"])}
    if q == "lobe_sample":
        wi, pdf = ev.sample_lobe(a["x"], a["n"], a["wo"], a["u"])
        return {"wi": wi, "pdf": pdf}
    if q == "prt":
        return {"y": ev.prt_radiance(a["light_sh"], a["vertex"], a["n"], a["wo"])}
    raise KeyError(q)


def _eightdna(ev, q: str, a: dict) -> dict:
    if q == "albedo":
        return {"y": ev.albedo(a["x"], a["wo"]), "input": ev.base_features(a["x"], a["wo"])}
    if q == "pdf":
        return {"pdf": ev.pdf(a["x"], a["wo"], a["ui"], a["wi"], a["channel"])}
    if q == "sample":
        ui, wi, pdf = ev.sample(a["x"], a["wo"], a["channel"], u=a["u"])
        return {"ui": ui, "wi": wi, "pdf": pdf}
    if q == "direct":
        return {"y": ev.direct_eval(a["n"], a["wo"], a["wi"])}
    if q == "direct_pdf":
        return {"pdf": ev.direct_pdf(a["n"], a["wo"], a["wi"])}
    if q == "direct_sample":
        wi, pdf = ev.direct_sample(a["n"], a["wo"], a["u"])
        return {"wi": wi, "pdf": pdf}
    raise KeyError(q)


_BY_KIND = {"rna": _rna, "neupress": _neupress, "8dna": _eightdna}


def answer(asset_path, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Outputs ``{query.output: array}`` for the inputs ``{query.argument: array}`` of one vector case."""
    from .asset import Asset

    asset = Asset.open(asset_path, load="all")
    # 8dna: the stored flow networks run whole (the render-time fused first layer sums in another order)
    ev = asset.evaluator(**({"fuse_first_layer": False} if asset.kind == "8dna" else {}))
    by_query: dict[str, dict] = {}
    for key, arr in inputs.items():
        q, _, arg = key.partition(".")
        by_query.setdefault(q, {})[arg] = arr
    out = {}
    for q, args in by_query.items():
        for name, arr in _BY_KIND[asset.kind](ev, q, args).items():
            out[f"{q}.{name}"] = np.asarray(arr, np.float32)
    return out


def main(argv=None) -> int:
    """Evaluator command of the protocol: ASSET INPUT.npz OUTPUT.npz."""
    from .evaluator_vectors import read_npz, write_npz

    asset, inp, out = (argv if argv is not None else sys.argv[1:])
    write_npz(out, answer(asset, read_npz(inp)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
