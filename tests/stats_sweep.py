"""Seed sweep of every chi-squared test of the default suite: are its p-values uniform under the null?

Runs the chi-squared tests in-process once per seed shift (``NASSET_STAT_SEED`` = 0 .. N-1; 0 is the suite's own
seeds), collects the p-value of every chi-squared statistic they compute (:data:`stats.RECORD`), and reports per test
the Kolmogorov-Smirnov distance of the p-values to U(0, 1), the KS p-value, a 10-bin histogram, the smallest p-value
and how many seeds would fail at :data:`stats.SIGNIFICANCE`. A test whose expected probabilities are integrated too
coarsely shows up as p-values piled near 0 (small KS p-value).

    .venv/bin/python -m tests.stats_sweep --seeds 50 [--json out.json] [pytest node ids or -k expression ...]

Not collected by pytest (the file name does not start with ``test_``); minutes of CPU per seed.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: the default suite's chi-squared tests (the bakes' trained-sampler tests need a bake per seed: not swept)
CHI2_TESTS = [
    "tests/renderer/test_render_samplers.py",
    "tests/sdk/test_kind_neupress.py::test_lobe_sampler_chi2",
    "tests/sdk/test_kind_8dna.py::test_position_marginal_integrates_to_one_and_matches_samples",
    "tests/sdk/test_kind_8dna.py::test_direction_conditional_integrates_to_one_and_matches_samples",
    "tests/sdk/test_kind_8dna.py::test_ggx_sampler_chi2",
]


def _memoise_expected_side(stats) -> None:
    """The expected side of a chi-squared test (quadrature of the pdf) does not depend on the seed: compute it once per
    test and inputs (the assets are built from fixed seeds). Caches the sphere-bin quadrature and the 8dna marginal /
    conditional pdfs per test by input bytes."""
    import hashlib

    import numpy as np

    from nasset_sdk.kinds.eightdna import EightDnaEvaluator

    sphere = stats.sphere_bin_probabilities
    cache: dict = {}

    def sphere_cached(*args, **kw):
        key = (os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0], args, tuple(sorted(kw.items())))
        if key not in cache:
            cache[key] = sphere(*args, **kw)
        return cache[key][0].copy(), cache[key][1]

    stats.sphere_bin_probabilities = sphere_cached

    def by_bytes(fn):
        def wrapped(self, *args):
            h = hashlib.blake2b(os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0].encode())  # same asset per test
            for a in args:
                h.update(np.ascontiguousarray(a).tobytes() if isinstance(a, np.ndarray) else repr(a).encode())
            key = (fn.__name__, h.hexdigest())
            if key not in cache:
                cache[key] = fn(self, *args)
            return cache[key].copy()

        return wrapped

    for name in ("pdf_position", "pdf_direction"):
        setattr(EightDnaEvaluator, name, by_bytes(getattr(EightDnaEvaluator, name)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--report", type=Path, help="only print the summary of a .partial.json written by a sweep")
    ap.add_argument("tests", nargs="*", default=CHI2_TESTS)
    a = ap.parse_args(argv)

    import numpy as np
    import pytest
    from scipy.stats import kstest

    from tests import stats

    os.chdir(HERE.parent)
    _memoise_expected_side(stats)
    per_test: dict[str, list[float]] = defaultdict(list)
    if a.report:
        per_test.update(json.loads(a.report.read_text())["p"])
    for s in range(0 if a.report else a.seeds):
        os.environ["NASSET_STAT_SEED"] = str(s)
        stats.RECORD.clear()
        pytest.main(["-q", "-p", "no:cacheprovider", "--no-header", "-o", "addopts=", "--tb=line", *a.tests])
        seen: dict[str, int] = defaultdict(int)
        for test, p in stats.RECORD:
            seen[test] += 1
            per_test[f"{test}#{seen[test]}" if seen[test] > 1 else test].append(p)
        print(f"seed {s}: {len(stats.RECORD)} chi-squared statistics", file=sys.stderr, flush=True)
        if a.json:  # the p-values so far, after every seed (a long sweep can be stopped and still reported)
            a.json.with_suffix(".partial.json").write_text(json.dumps({"seeds_done": s + 1, "p": per_test}))
    rows = {}
    for test, ps in sorted(per_test.items()):
        ps_a = np.array(ps)
        ks = kstest(ps_a, "uniform")
        rows[test] = dict(n=len(ps), ks_d=float(ks.statistic), ks_p=float(ks.pvalue), min_p=float(ps_a.min()),
                          fails=int((ps_a <= stats.SIGNIFICANCE).sum()), hist=np.histogram(ps_a, 10, (0, 1))[0].tolist())
    all_p = np.concatenate([np.array(v) for v in per_test.values()]) if per_test else np.zeros(0)
    pooled = kstest(all_p, "uniform") if len(all_p) else None
    w = max((len(t) for t in rows), default=10)
    print(f"{'test':<{w}}  n   KS D   KS p    min p     fails  histogram of p (10 bins)")
    for t, r in rows.items():
        print(f"{t:<{w}}  {r['n']:<3d} {r['ks_d']:.3f}  {r['ks_p']:.3f}  {r['min_p']:.2e}  {r['fails']:<5d}  {r['hist']}")
    if pooled is not None:
        print(f"pooled: {len(all_p)} p-values, KS D {pooled.statistic:.4f}, KS p {pooled.pvalue:.3f}, "
              f"histogram {np.histogram(all_p, 10, (0, 1))[0].tolist()}")
    if a.json:
        a.json.write_text(json.dumps({"seeds": a.seeds, "tests": rows, "pooled_ks_p": pooled.pvalue if pooled else None}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
