"""The Mitsuba implementation's own evaluators (mitsuba_renderer/*.py) as an ``--evaluator`` command of
spec/evaluator-vectors.md, so they are checked on the same test vectors as the SDK.

    python -m tests.mitsuba_renderer.vector_evaluator ASSET INPUT.npz OUTPUT.npz

The ``prt`` query is not answered: the Mitsuba implementation has no PRT path.
"""

from __future__ import annotations

import sys

import numpy as np

from nasset_mitsuba_renderer.eightdna import EightDnaAsset, box_jacobian
from nasset_mitsuba_renderer.neupress import NeupressAsset, ggx_reflection, lobe_pdf, lobe_sample
from nasset_mitsuba_renderer.rna import RnaAsset, asset_kind, safe_normalize


def _rna(path, q, a):
    asset = RnaAsset(path)
    n = len(a["x"])
    frame = a["t"] if asset.fiber else a["n"]
    args = (a["x"], frame, a["wo"], a["wi"])
    return {"unshadowed": asset.transport(*args, np.zeros(n, bool), a.get("h")),
            "shadowed": asset.transport(*args, np.ones(n, bool), a.get("h"))}


def _neupress(path, q, a):
    asset = NeupressAsset(path)
    if q == "subsurface":
        return {"y": asset.subsurface(a["x"], a["wo"], a["wi"])}
    if q == "reflection":
        return {"y": ggx_reflection(a["n"], a["wo"], a["wi"], asset.eta, asset.alpha)}
    if q == "prt":
        return {}
    asset.load_sampling()
    sigma = asset.sigma(a["x"], a["wo"])
    if q == "sigma":
        return {"sigma": sigma}
    if q == "lobe_pdf":
        return {"pdf": lobe_pdf(a["n"], sigma, a["wi"])}
    wi = safe_normalize(lobe_sample(a["n"], sigma, np.clip(a["u"], 0.0, np.nextafter(1.0, 0.0))))
    return {"wi": wi, "pdf": lobe_pdf(a["n"], sigma, wi)}


def _eightdna(path, q, a):
    asset = EightDnaAsset(path)
    if q in ("direct", "direct_pdf", "direct_sample"):
        n, wo = safe_normalize(a["n"]), safe_normalize(a["wo"])
        if q == "direct_sample":
            wi, pdf = asset.ggx.sample(n, wo, np.clip(a["u"], 0.0, np.nextafter(1.0, 0.0)))
            return {"wi": safe_normalize(wi), "pdf": pdf}
        wi = safe_normalize(a["wi"])
        return {"y": np.repeat(asset.ggx.eval(n, wo, wi)[:, None], 3, 1)} if q == "direct" else {"pdf": asset.ggx.pdf(n, wo, wi)}
    base = asset.base(a["x"], a["wo"])
    if q == "albedo":
        return {"y": asset.albedo(base)}
    ch = np.asarray(a["channel"], np.int64)
    if q == "sample":
        ui, wi, s = asset.sample(base, ch, np.clip(a["u"], 0.0, 1.0))
    else:
        ui, wi = a["ui"], a["wi"]
        s = asset.params_of(ui, wi)
    logp = asset.log_dz(base, s, (0, 1, 2, 3))[np.arange(len(ch)), ch]
    pdf = np.exp(logp) / (16 * np.pi ** 2) * box_jacobian(np.asarray(ui, np.float64) - asset.center, asset.half)
    return {"pdf": pdf} if q == "pdf" else {"ui": ui, "wi": wi, "pdf": pdf}


KINDS = {"rna": _rna, "neupress": _neupress, "8dna": _eightdna}


def main(argv=None) -> int:
    path, inp, out = argv if argv is not None else sys.argv[1:]
    queries: dict[str, dict] = {}
    with np.load(inp, allow_pickle=False) as z:
        for k in z.files:
            q, _, arg = k.partition(".")
            queries.setdefault(q, {})[arg] = z[k]
    answer = KINDS[asset_kind(path)]
    result = {f"{q}.{name}": np.asarray(v, np.float32) for q, args in queries.items() for name, v in answer(path, q, args).items()}
    np.savez(out, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
