"""The dense-hair benchmark of benchmarks/renderer_throughput.py runs, and its counts are consistent (a smoke
test: that a ray's Embree calls do not grow with the fibres it crosses is tested in
tests/renderer/test_render_accel.py, on rays that cross many)."""

import argparse

import numpy as np

from nasset_benchmarks.renderer_throughput import hair_scene, run_hair, tessellation_bytes


def test_hair_benchmark_small():
    scene = hair_scene(300, 3, floor=False)
    mem = tessellation_bytes(scene)
    assert mem["segments"] == 300 * 3 and mem["triangles"] == 28 * 300 * 3  # 2N + 2 (N - 2) triangles, N = 8
    # renderer: 28 x (72 B corners + 16 B ids + 24 B normal); Embree: 16 float32 points, 14 quads of 16 + 12 B
    assert mem["renderer"] == 28 * 112 and mem["embree"] == 16 * 12 + 14 * 28 + 12 / 900
    r = run_hair(scene, argparse.Namespace(spp=1, res=24, batch=65536, workers=1))
    assert r["samples"] == 24 * 18
    assert np.isfinite([r["rate"], r["rays"], r["setup"], r["first_setup"]]).all() and r["rate"] > 0
    # camera ray (one query where it meets the hair's box) + one branch test per hair hit (+ exempt steps)
    assert 0 < r["rays"] <= 3.0
