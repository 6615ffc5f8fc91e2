"""Bias and noise of the finite-angle distant light vs the delta light (spec/bake.md#light).

    python -m nasset_benchmarks.light_study [--spp 256] [--res 16]

A sphere (radius 0.5, icosphere mesh) around a homogeneous medium (albedo 0.9, sigma_t 4) with a
rough (alpha 0.2) and a smooth dielectric boundary (IOR 1.5), lit head-on from the camera side
rotated by 45 degrees; the centre res x res pixels are rendered twice with independent seeds.
Prints, per boundary and light angle: mean transport, its ratio to the delta light's (rough
boundary only: the delta light is exact there) and the per-pixel relative noise at ``spp``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from nasset_converters.mitsuba import load_mitsuba
from nasset_converters.mitsuba.dataset import DataSettings, Renderer, camera_rays
from nasset_converters.mitsuba.scene import IsolatedAsset
from nasset_sdk.cli import MAX_IMAGE_SIDE, MAX_SPP, count_arg


def _sphere_shape(mi, bsdf: dict):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    scene = mi.load_dict({"type": "scene", "ball": {"type": "obj", "filename": _write_obj(m), "bsdf": bsdf,
                                                     "interior": {"type": "homogeneous", "albedo": 0.9, "sigma_t": 4.0}}})
    return scene.shapes()[0]


def _write_obj(m) -> str:
    import tempfile

    f = tempfile.NamedTemporaryFile("w", suffix=".obj", delete=False)
    for v in m.vertices:
        f.write(f"v {v[0]} {v[1]} {v[2]}\n")
    for vn in m.vertex_normals:
        f.write(f"vn {vn[0]} {vn[1]} {vn[2]}\n")
    for a, b, c in np.asarray(m.faces) + 1:
        f.write(f"f {a}//{a} {b}//{b} {c}//{c}\n")
    f.close()
    return f.name


def study(spp: int = 256, res: int = 16, angles=(0.0, 1.0, 2.0, 5.0, 10.0)) -> list[dict]:
    mi = load_mitsuba()
    mi.set_log_level(mi.LogLevel.Error)
    rows = []
    wi = np.array([np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])
    o, d = camera_rays(np.array([0.0, 0.0, 3.0]), np.zeros(3), np.arctan(0.12), res)
    for name, bsdf in (("rough", {"type": "roughdielectric", "alpha": 0.2, "int_ior": 1.5}),
                       ("smooth", {"type": "dielectric", "int_ior": 1.5})):
        shape = _sphere_shape(mi, bsdf)
        ref = None
        for ang in angles:
            iso = IsolatedAsset(mi, [shape], np.zeros(3), 0.5, angle_deg=ang)
            r = Renderer(mi, iso, DataSettings(chunk=1 << 21))
            iso.set_light(wi)
            a = r.transport(o, d, spp, seed=1).astype(np.float64)
            b = r.transport(o, d, spp, seed=2).astype(np.float64)
            mean = float((a + b).mean() / 2)
            noise = float(np.std(a - b) / np.sqrt(2) / max(mean, 1e-12))
            if ang == 0.0:
                ref = mean
            rows.append({"boundary": name, "angle_deg": ang, "mean_T": mean,
                         "ratio_to_delta": mean / ref if ref else None, "rel_noise_per_pixel": noise, "spp": spp})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=count_arg(1, MAX_SPP), default=256)
    ap.add_argument("--res", type=count_arg(8, MAX_IMAGE_SIDE), default=16)
    args = ap.parse_args()
    rows = study(args.spp, args.res)
    for r in rows:
        ratio = "n/a" if r["ratio_to_delta"] is None else f"{r['ratio_to_delta']:.3f}"
        print(f"{r['boundary']:6s} angle {r['angle_deg']:5.1f}  mean T {r['mean_T']:.4f}  vs delta {ratio}  "
              f"rel. noise/pixel {r['rel_noise_per_pixel']:.3f}")
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
