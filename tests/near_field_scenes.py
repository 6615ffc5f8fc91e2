"""Scenes with closed forms for the near-field fetch of rna assets (spec/kinds/rna.md#near-field-fetch), shared by the
tests of both Mitsuba-based renderers (tests/mitsuba_renderer/test_near_field.py, each test on both).

A constant-transport icosphere (radius 0.5, centred on the origin: the encoding box's centre c is the origin) seen
from CAMERA:

- :func:`point_light_scene`: lit by a point light of intensity I at LIGHT from above, direct lighting only. With
  f = 1 every hit fetches its light at c, so a fully covered pixel shows T I / |LIGHT - c|^2, T the unshadowed
  transport on the upper half (the ray from x toward the light leaves the asset) and the shadowed one on the lower
  half; with f = 0 it falls off as 1 / |LIGHT - x|^2. Black occluders: ``"centre"`` blocks the line c -> LIGHT and no
  line x -> LIGHT of the hits in view, ``"side"`` blocks lines x -> LIGHT of part of them but not c -> LIGHT,
  ``"inside"`` lies inside the asset, hidden from the camera, on the upward lines of some hits of its lower half and
  not on c -> LIGHT (the branch from x counts only the asset's own triangles: it stays shadowed).
- :func:`dome_square_scene`: under a white dome of radiance 1 with a black square just below the asset, every path
  length (continuations reach the dome, the square or nothing). T is 1 unshadowed, 0 shadowed, so a hit x shows
  the solid angle of the directions w that leave the asset at x (n . w > 0 on the convex mesh) and along which a ray
  from the fetch point p reaches the dome: :func:`dome_square_expected`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nasset_reference_renderer.testscenes import SceneBuilder, constant_rna_asset

CAMERA = (0.0, 0.0, 3.0)
LIGHT, INTENSITY = np.array([0.0, 3.0, 0.0]), 9.0
UNSHADOWED, SHADOWED = (1.0, 0.5, 0.25), (0.1, 0.2, 0.3)
#: half-width of the view at unit distance (SceneBuilder.camera: aperture 20.955 / 2 over focal 35)
TAN_HALF = 20.955 / 2.0 / 35.0
#: the black square below the asset in the dome scene: centre height and size
SQUARE_Y, SQUARE = -0.6, 1.2


def with_fetch(src, dst, f: float) -> str:
    """A copy of the asset file ``src`` at ``dst`` with ``nasset:nearFieldFetch`` = f."""
    from nasset_sdk.asset import Asset, AssetBuilder

    b = AssetBuilder.from_asset(Asset.open(src))
    b.near_field_fetch = float(f)
    return str(b.write(dst))


def with_fetch_authored(src, dst, value) -> str:
    """A copy of the asset ``src`` at ``dst`` (a .usda path) whose ``nasset:nearFieldFetch`` is ``value`` as authored,
    whatever it is and whatever the asset's kind (the builder writes no attribute for 0, refuses values outside
    [0, 1] and any f > 0 on 8dna). An rna or neupress copy declares format 0.3, as the builder writes it."""
    from pxr import Sdf, Usd

    from nasset_sdk.asset import NEAR_FIELD_FETCH, NEAR_FIELD_KINDS, Asset, AssetBuilder
    from nasset_sdk.safeopen import trust

    b = AssetBuilder.from_asset(Asset.open(src))
    if b.kind in NEAR_FIELD_KINDS:
        b.near_field_fetch = 0.5
    b.write(dst)
    stage = Usd.Stage.Open(str(dst))
    root = stage.GetDefaultPrim()
    attr = root.GetAttribute(NEAR_FIELD_FETCH) or root.CreateAttribute(NEAR_FIELD_FETCH, Sdf.ValueTypeNames.Float)
    attr.Set(float(value))
    stage.GetRootLayer().Save()
    trust(dst)
    return str(dst)


def constant_asset(tmp_path, f: float, unshadowed=UNSHADOWED, shadowed=SHADOWED) -> str:
    base = constant_rna_asset(tmp_path / f"const_{unshadowed[0]}_{shadowed[0]}.usda", unshadowed=unshadowed, shadowed=shadowed)
    return with_fetch(base, tmp_path / f"const_{unshadowed[0]}_{shadowed[0]}_f{f}.usda", f)


#: the constant neupress asset: S^ (1/sr, every input) and the boundary (eta, alpha) of core/boundary
NEUPRESS_S, NEUPRESS_BOUNDARY = (0.02, 0.015, 0.01), (3.0, 0.5)


def constant_neupress_asset(tmp_path, f: float, s=NEUPRESS_S, boundary=NEUPRESS_BOUNDARY) -> str:
    """A neupress icosphere like :func:`constant_asset`'s (radius 0.5, centred on the origin) whose appearance network
    returns the constant S^ ``s``, with GGX boundary ``boundary`` = (eta, alpha) (eta = 1: no surface reflection), no
    vertex normals (the shading normal is the face normal) and no ``sampling`` component (the A sample is the uniform
    sphere); ``nasset:nearFieldFetch`` = f (spec/kinds/neupress.md#near-field-fetch)."""
    import trimesh

    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.geometry import MeshGeometry
    from nasset_sdk.networks import mlp_onnx

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    b = AssetBuilder("neupress", variant="surface")
    b.set_geometry(MeshGeometry(np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32), None))
    core = b.component("core", required=True, purpose="evaluation", quality=None)
    core.add_tensor("fourier", np.zeros((2, 7)), dtype="float32", layout="frequency,input")
    core.add_tensor("boundary", np.asarray(boundary, np.float64), dtype="float32", layout="parameter")
    core.add_network("appearance", mlp_onnx([np.zeros((4, 3), np.float32)], [np.asarray(s, np.float32)]))
    b.provenance = {"generator": "constant"}
    b.near_field_fetch = float(f)
    return str(b.write(tmp_path / f"neupress_{s[0]}_{boundary[0]}_f{f}.usda"))


def point_light_scene(tmp_path, asset: str, occluder: str | None = None, matrix=None) -> str:
    b = SceneBuilder()
    b.camera(CAMERA, (0, 0, 0))
    b.sphere_light("Point", tuple(LIGHT), 0.0, INTENSITY)
    b.asset("A", asset, matrix)
    black = dict(diffuse=(0.0, 0.0, 0.0), specular=(0.0, 0.0, 0.0))
    if occluder == "centre":
        b.quad("Occluder", (0.0, 1.0, 0.0), 0.12, **black)
    elif occluder == "side":
        b.quad("Occluder", (0.25, 0.8, 0.25), 0.3, **black)
    elif occluder == "inside":
        b.quad("Occluder", (0.0, -0.2, 0.3), 0.15, **black)
    return b.write(tmp_path / f"point_{occluder}_{Path(asset).stem}.usda")


def moved_constant_asset(tmp_path, f: float):
    """(asset, instance matrix M [4x4, USD row vectors], world centre c_w): the constant icosphere moved off its object
    origin (centre c = (0.4, -0.2, 0.1)), instanced rotated 30 degrees about y, scaled (0.8, 1.2, 0.9) and translated so
    that c_w = c M lies near the origin, in view."""
    from nasset_sdk.asset import Asset, AssetBuilder
    from nasset_sdk.geometry import MeshGeometry

    a = Asset.open(constant_asset(tmp_path, f))
    g = a.geometry()
    b = AssetBuilder.from_asset(a)
    b.set_geometry(MeshGeometry(np.asarray(g.points, np.float32) + np.float32([0.4, -0.2, 0.1]), g.faces, g.normals))
    path = str(b.write(tmp_path / f"moved_f{f}.usda"))
    lo, hi = (np.asarray(v, np.float64) for v in Asset.open(path).domain)
    c = 0.5 * (lo + hi)
    t = np.radians(30.0)
    rot = np.array([[np.cos(t), 0.0, -np.sin(t)], [0.0, 1.0, 0.0], [np.sin(t), 0.0, np.cos(t)]])
    m = np.eye(4)
    m[:3, :3] = np.diag([0.8, 1.2, 0.9]) @ rot
    m[3, :3] = np.array([0.05, 0.1, -0.05]) - c @ m[:3, :3]
    return path, m, c @ m[:3, :3] + m[3, :3]


def dome_square_scene(tmp_path, asset: str) -> str:
    from pxr import UsdGeom

    b = SceneBuilder()
    b.camera(CAMERA, (0, 0, 0))
    # the sky: an emissive shell of 320 triangles, too many to be light-sampled (spec/renderer.md#mesh-lights)
    b.sphere_mesh("Shell", (0.0, 0.0, 0.0), 20.0, subdivisions=2, diffuse=(0.0, 0.0, 0.0), emission=(1.0, 1.0, 1.0))
    b.asset("A", asset)
    # one-sided and facing down: rays from above meet its back, which ends the path (no Fresnel glint of a black mesh)
    square = b.quad("Square", (0.0, SQUARE_Y, 0.0), SQUARE, normal=(0.0, -1.0, 0.0), diffuse=(0.0, 0.0, 0.0))
    UsdGeom.Mesh(square.GetPrim()).CreateDoubleSidedAttr(False)
    return b.write(tmp_path / f"dome_{Path(asset).stem}.usda")


def camera_dirs(px, py, width: int, height: int) -> np.ndarray:
    """World directions [n, 3] of camera rays through film positions (px, py) in pixels (CAMERA looks down -z)."""
    u = (2.0 * np.asarray(px) / width - 1.0) * TAN_HALF
    v = (1.0 - 2.0 * np.asarray(py) / height) * TAN_HALF * height / width
    d = np.stack([u, v, -np.ones_like(u)], 1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def first_hits(points, faces, o, d):
    """(hit point [n, 3], outward face normal [n, 3], hit [n]) of rays o + t d on the triangle mesh (closest hit)."""
    v0, v1, v2 = (points[faces[:, k]] for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    pv = np.cross(d[:, None], e2[None])
    det = np.einsum("nfk,fk->nf", pv, e1)
    inv = 1.0 / np.where(np.abs(det) > 1e-12, det, np.inf)
    tv = o[None, None] - v0[None] if o.ndim == 1 else o[:, None] - v0[None]
    bu = np.einsum("nfk,nfk->nf", tv, pv) * inv
    qv = np.cross(tv, e1[None])
    bv = np.einsum("nk,nfk->nf", d, qv) * inv
    t = np.einsum("fk,nfk->nf", e2, qv) * inv
    ok = (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t > 1e-9) & (det != 0)
    t = np.where(ok, t, np.inf)
    j = np.argmin(t, 1)
    tt = t[np.arange(len(d)), j]
    n = np.cross(e1, e2)[j]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n *= np.sign(np.einsum("nk,nk->n", n, points[faces[j]].mean(1)))[:, None]  # outward (a convex mesh around 0)
    origin = np.broadcast_to(o, d.shape)
    return origin + d * np.where(np.isfinite(tt), tt, 0.0)[:, None], n, np.isfinite(tt)


def point_light_neupress_expected(asset: str, width: int, height: int, sub: int = 8):
    """(rows, cols, expected [n, 3]) of the point-light scene's pixels that the constant neupress asset covers whole, at
    f = 1: the light sample of every hit is fetched at c, so a hit x with face normal n shows
    (S^ + f_r(n, w_o, w_c) V_self) I / |LIGHT - c|^2, w_c = (LIGHT - c) / |LIGHT - c| (V_self = 1 exactly where
    n . w_c > 0 on the convex mesh, where f_r is non-zero), f_r from the SDK's NeupressEvaluator.surface_reflection;
    box-filtered over sub x sub film positions."""
    from nasset_sdk.asset import Asset

    a = Asset.open(asset)
    ev = a.evaluator()
    g = a.geometry()
    pts, faces = np.asarray(g.points, np.float64), np.asarray(g.faces, np.int64).reshape(-1, 3)
    e_c = INTENSITY / float(np.sum(LIGHT ** 2))
    w_c = LIGHT / np.linalg.norm(LIGHT)
    s = (np.arange(sub) + 0.5) / sub
    rows, cols, out = [], [], []
    for row in range(height):
        for col in range(width):
            px, py = (col + s[None, :] + 0 * s[:, None]).ravel(), (row + s[:, None] + 0 * s[None, :]).ravel()
            d = camera_dirs(px, py, width, height)
            x, n, hit = first_hits(pts, faces, np.asarray(CAMERA), d)
            if not hit.all():
                continue
            wi = np.broadcast_to(w_c, n.shape)
            s_hat = ev.evaluate(x, n, -d, wi)
            fr = ev.surface_reflection(n, -d, wi) * (n @ w_c > 0)[:, None]
            rows.append(row)
            cols.append(col)
            out.append(e_c * np.mean(s_hat + fr, 0))
    return np.asarray(rows), np.asarray(cols), np.asarray(out)


def fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    ph = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([r * np.cos(ph), r * np.sin(ph), z], 1)


def dome_square_expected(asset: str, f: float, width: int, height: int, sub: int = 3, dirs: int = 4000, leaving=True):
    """(rows, cols, expected values) of the dome scene's pixels that the asset covers whole, at fetch fraction f: the
    box-filtered average over sub x sub film positions of the solid angle of {w : n . w > 0, the ray p + s w misses
    the square} (n the hit triangle's outward normal, p = x + f (c - x)); ``leaving`` False: of all w whose ray from p
    misses the square (a transport that is the same on both branches, the constant neupress asset without reflection)."""
    from nasset_sdk.asset import Asset

    a = Asset.open(asset)
    g = a.geometry()
    pts, faces = np.asarray(g.points, np.float64), np.asarray(g.faces, np.int64).reshape(-1, 3)
    centre = 0.5 * (np.asarray(a.domain[0], np.float64) + np.asarray(a.domain[1], np.float64))
    w = fibonacci_sphere(dirs)
    s = (np.arange(sub) + 0.5) / sub
    rows, cols, out = [], [], []
    for row in range(height):
        for col in range(width):
            px, py = (col + s[None, :] + 0 * s[:, None]).ravel(), (row + s[:, None] + 0 * s[None, :]).ravel()
            x, n, hit = first_hits(pts, faces, np.asarray(CAMERA), camera_dirs(px, py, width, height))
            if not hit.all():
                continue
            p = x + f * (centre - x)
            leaves = n @ w.T > 0 if leaving else np.ones((len(x), len(w)), bool)  # [sub^2, dirs]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (SQUARE_Y - p[:, 1:2]) / w[None, :, 1]
                q = p[:, None, :] + t[..., None] * w[None]
            blocked = (t > 0) & (np.abs(q[..., 0]) <= SQUARE / 2) & (np.abs(q[..., 2]) <= SQUARE / 2)
            rows.append(row)
            cols.append(col)
            out.append(4.0 * np.pi * np.mean(leaves & ~blocked))
    return np.asarray(rows), np.asarray(cols), np.asarray(out)
