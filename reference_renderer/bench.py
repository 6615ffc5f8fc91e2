"""Benchmark (not a test): render throughput vs the bound set by onnxruntime and Embree.

    python -m reference_renderer.bench [--size small] [--res 128] [--spp 8] [--threads 0]

Scene: one rna asset under a distant light (no other objects: NEE only). Prints camera samples
per second, the decoder's raw onnxruntime throughput, Embree's raw ray throughput, the bound
1 / (evals_per_sample / onnx_rate + rays_per_sample / embree_rate) and the ratio, and a time
breakdown (trace / network / other).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="small")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--batch", type=int, default=65536)
    a = ap.parse_args(argv)
    from .accel import EmbreeBackend
    from .integrator import RenderSettings, render
    from .scene import load_scene
    from .testscenes import SceneBuilder, random_rna_asset

    tmp = Path(tempfile.mkdtemp())
    asset = random_rna_asset(tmp / "a.usdc", size=a.size)
    b = SceneBuilder()
    b.camera((0, 0.3, 2.2), (0, 0, 0), focal=35)
    b.distant("Sun", (0.4, 1.0, 0.3), 3.0)
    b.asset("Obj", asset)
    scene = load_scene(b.write(tmp / "bench.usda"))
    settings = RenderSettings(spp=a.spp, width=a.res, height=a.res, threads=a.threads, batch=a.batch)
    render(scene, RenderSettings(spp=1, width=16, height=16, threads=a.threads))  # warm up
    res = render(scene, settings)
    st = res.stats
    rate = st.camera_samples / st.time_total
    # raw decoder throughput
    ev = scene.assets[0].evaluator
    n = a.batch
    width = ev.session.get_inputs()[0].shape[1]
    x = np.random.default_rng(0).random((n, width)).astype(np.float32)
    ev.session.run(None, {"x": x})
    t = time.perf_counter()
    reps = 5
    for _ in range(reps):
        ev.session.run(None, {"x": x})
    onnx_rate = reps * n / (time.perf_counter() - t)
    # raw embree throughput (closest hit, coherent-ish random rays at the asset)
    emb = EmbreeBackend(scene.triangles)
    rng = np.random.default_rng(1)
    o = np.tile([[0.0, 0.3, 2.2]], (n, 1))
    d = rng.normal(0, 0.15, (n, 3)) + [0, -0.3, -2.2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    emb.closest(o, d, np.full(n, np.inf))
    t = time.perf_counter()
    for _ in range(reps):
        emb.closest(o, d, np.full(n, np.inf))
    ray_rate = reps * n / (time.perf_counter() - t)
    evals_ps = st.network_evals / st.camera_samples
    rays_ps = st.rays / st.camera_samples
    bound = 1.0 / (evals_ps / onnx_rate + rays_ps / ray_rate)
    print(f"scene: rna '{a.size}' asset, distant light, {a.res}x{a.res} x {a.spp} spp")
    print(f"render:      {rate:12,.0f} camera samples/s  ({st.time_total:.2f} s)")
    print(f"onnxruntime: {onnx_rate:12,.0f} decoder evals/s (batch {n})")
    print(f"embree:      {ray_rate:12,.0f} rays/s")
    print(f"per sample:  {evals_ps:.3f} network evals, {rays_ps:.3f} rays")
    print(f"bound:       {bound:12,.0f} samples/s -> ratio {rate / bound:.2f}")
    tt = st.time
    print(f"time: trace {tt['trace']:.2f} s, network (incl. triplane encode) {tt['network']:.2f} s, "
          f"other numpy {tt['other']:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
