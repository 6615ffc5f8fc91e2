"""Adversarial input strategies shared by the numerical stress tests."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

TINY = 5e-324  # smallest float64 subnormal
F16_MAX = 65504.0
F16_SUB = float(np.float16(2.0 ** -24))  # smallest float16 subnormal

#: component values that break naive code: signed zeros, subnormals, overflow-prone magnitudes, NaN/Inf
SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, -0.5, TINY, -TINY, 1e-310, 1e-300, 1e-20, 1e-8, 1e-4, 1e4, 1e20, 1e150,
           1e300, -1e300, 1.7976931348623157e308, -1.7976931348623157e308, np.nan, np.inf, -np.inf,
           float(np.nextafter(1.0, 0.0)), float(np.nextafter(1.0, 2.0)), float(np.sqrt(0.5)), F16_MAX, -F16_MAX, F16_SUB]
FINITE_SPECIAL = [v for v in SPECIAL if np.isfinite(v)]

#: unit-ish directions at the poles and exactly on cube-map face edges and corners (every sign pattern)
_BASE_DIRS = [(0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1), (1, 1 - 1e-16, 0),
              (1, 1, 1 - 1e-16), (1, 1e-300, 0), (1, 0, TINY), (1, 1e-9, 1e-9)]
EDGE_DIRS = sorted({tuple(float(s * c) for s, c in zip(signs, d, strict=True))
                    for d in _BASE_DIRS for signs in itertools.product((1.0, -1.0), repeat=3)})

component = st.one_of(st.sampled_from(SPECIAL), st.floats(-2.0, 2.0), st.floats(allow_nan=True, allow_infinity=True))
unit_interval = st.one_of(st.sampled_from([0.0, TINY, 1e-310, 1e-16, 0.5, 1.0 - 1e-16, float(np.nextafter(1.0, 0.0)), 1.0]),
                          st.floats(0.0, 1.0))


def rows(n_max: int = 24, width: int = 3, elements=component):
    """[N, width] float64 arrays, N in 1..n_max, of adversarial components."""
    return st.integers(1, n_max).flatmap(lambda n: arrays(np.float64, (n, width), elements=elements))


def edge_dir_rows(n_max: int = 24):
    """Directions mixing cube edges/corners/poles, exact or scaled, with generic adversarial vectors."""
    scaled = st.tuples(st.sampled_from(EDGE_DIRS), st.sampled_from([1.0, 1e-300, TINY, 1e-20, 1e300, 1e308, 3.0]))
    vec = st.one_of(scaled.map(lambda p: tuple(c * p[1] for c in p[0])), st.tuples(component, component, component))
    return st.lists(vec, min_size=1, max_size=n_max).map(lambda v: np.array(v, np.float64))


def finite_all(*arrays_) -> bool:
    return all(np.isfinite(np.asarray(a, np.float64)).all() for a in arrays_)
