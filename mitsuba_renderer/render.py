"""Neural assets rendered inside Mitsuba 3: a second, independent implementation of spec/renderer.md.

    python -m nasset_mitsuba_renderer.render SCENE.usda OUT.exr SPP [--width W --height H --seed S --max-depth D --neupress-sampling M]

The USD scene becomes a Mitsuba scene (``mi.load_dict``): meshes and every neural-asset
instance are ``mi.Mesh`` shapes in world space; point, delta distant, sphere and rectangle lights
are Mitsuba emitters; a ``perspective`` sensor mirrors the USD camera. The integrator
``nasset_numpy_path`` (a Python ``mi.SamplingIntegrator`` registered with ``mi.register_integrator``)
renders it as wavefronts: numpy path state, Mitsuba ray casts on whole batches, Mitsuba emitter
sampling and evaluation, the neural transport evaluated per batch with onnxruntime. See
``mitsuba_renderer/`` for the pieces and spec/conformance-notes.md for the readings of the
spec this implementation made.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings

import numpy as np

from nasset_sdk.cli import seed_arg
from nasset_sdk.errors import NassetError, SceneError, error

from . import eightdna, neupress  # noqa: F401  (eightdna: importing it registers the 8dna shader)
from .integrator import ASSET_SHADERS, Kind, PathTracer
from .lights import build_lights
from .loader import is_jit, load_mitsuba
from .rna import KNOWN_KINDS, asset_kind
from .usdscene import read_scene

#: not ``nasset_path``: that name is the JIT plugin's (nasset_mitsuba_plugin), and both may be registered in one process
INTEGRATOR = "nasset_numpy_path"
_CONTEXTS: dict[str, dict] = {}
_REGISTERED = False


def _face_normals(pts, faces):
    p0, p1, p2 = (pts[faces[:, k]] for k in range(3))
    c = np.cross(p1 - p0, p2 - p0)
    return c / np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-30)


def mi_mesh(mi, name, pts, faces):
    """A ``mi.Mesh`` of world-space points [V, 3] and triangles [F, 3] (no normals: flat shading)."""
    m = mi.Mesh(name, len(pts), len(faces))
    prm = mi.traverse(m)
    prm["vertex_positions"] = mi.Float(np.ascontiguousarray(pts, np.float32).ravel())
    prm["faces"] = mi.UInt32(np.ascontiguousarray(faces, np.uint32).ravel())
    prm.update()
    return m


def _planar(pts, fn) -> bool:
    if len(fn) == 0:
        return True
    n0 = fn[0]
    return bool(np.all(np.abs(fn @ n0) > 1 - 1e-6) and np.all(np.abs((pts - pts[0]) @ n0) < 1e-6 * (1 + np.abs(pts).max())))


def open_asset(path: str, threads: int = 0):
    """Asset object of ``path`` through the shader registered for its kind (integrator.ASSET_SHADERS)."""
    kind = asset_kind(path)
    cls = ASSET_SHADERS.get(kind)
    if cls is None:
        what = "a kind this renderer does not implement" if kind in KNOWN_KINDS else "not a registered kind"
        raise SceneError("SCENE_UNSUPPORTED", f"nasset:kind {kind!r} is {what} (supported: {', '.join(sorted(ASSET_SHADERS))})", file=path)
    return cls.open(path, threads)


def register(mi) -> None:
    """Register the ``nasset_numpy_path`` integrator with Mitsuba (idempotent)."""
    global _REGISTERED
    if _REGISTERED:
        return

    class NassetPathIntegrator(mi.SamplingIntegrator):
        def __init__(self, props):
            super().__init__(props)
            self.context = props.get("context", "")
            self.max_depth = int(props.get("max_depth", 5))
            self.batch = int(props.get("batch", 1 << 17))

        def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
            ctx = _CONTEXTS[self.context]
            pt = PathTracer(mi, scene, ctx["objects"], ctx["lights"], ctx["camera"], max_depth=self.max_depth,
                            shadow_scene=ctx.get("shadow_scene"))
            img = pt.render(ctx["width"], ctx["height"], int(spp), int(seed), batch=self.batch, pixel_filter=ctx["pixel_filter"])
            return mi.TensorXf(img.astype(np.float32))

        def sample(self, scene, sampler, ray, medium=None, active=True):
            raise NotImplementedError(f"{INTEGRATOR} renders whole wavefronts; use render()")

        def to_string(self):
            return f"NassetPathIntegrator[max_depth={self.max_depth}]"

    mi.register_integrator(INTEGRATOR, lambda props: NassetPathIntegrator(props))
    _REGISTERED = True


def sensor_dict(mi, cam, width: int, height: int) -> dict:
    """Mitsuba sensor of a USD camera (spec/renderer.md#cameras), box-filtered RGB film: ``perspective``
    (horizontal aperture -> x field of view; aperture offsets -> the principal point, in film widths right and film
    heights down), ``thinlens`` (aperture radius, focus distance) or ``orthographic`` (the window 0.1 x the
    apertures, as a to_world scale of Mitsuba's [-1, 1] film width). Mitsuba's thin-lens and orthographic sensors
    have no principal point: with an aperture offset they are SCENE_UNSUPPORTED. The exposure scale is the
    caller's (a factor on the image)."""
    eye = cam.to_world[3, :3]
    fwd = -cam.to_world[2, :3]
    frame = mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=(eye + fwd).tolist(), up=cam.to_world[1, :3].tolist())
    film = {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}, "pixel_format": "rgb"}
    if (cam.orthographic or cam.lens_radius > 0) and (cam.h_offset or cam.v_offset):
        raise SceneError("SCENE_UNSUPPORTED", "Mitsuba's thin-lens and orthographic sensors have no lens shift (aperture "
                         "offsets)", prim=cam.prim)
    if cam.orthographic:
        half = 0.05 * cam.h_aperture  # scene units: Mitsuba's film spans x in [-1, 1] before to_world
        return {"type": "orthographic", "near_clip": 1e-6, "to_world": frame @ mi.ScalarTransform4f().scale([half, half, 1.0]),
                "film": film}
    fov = float(np.degrees(2.0 * np.arctan(cam.h_aperture / (2.0 * cam.focal))))
    if cam.lens_radius > 0:
        return {"type": "thinlens", "fov_axis": "x", "fov": fov, "aperture_radius": float(cam.lens_radius),
                "focus_distance": float(cam.focus_distance), "to_world": frame, "film": film}
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": fov,
        "principal_point_offset_x": float(cam.h_offset / cam.h_aperture),
        "principal_point_offset_y": float(-cam.v_offset / (cam.h_aperture * height / width)),
        "to_world": frame,
        "film": film,
    }


#: ``nasset:maxDepth = -1`` (unbounded, spec/renderer.md#render-settings): this many bounces, with Russian roulette
UNBOUNDED_DEPTH = 1024


def build(scene_path: str, width: int | None = None, height: int | None = None, *, max_depth: int | None = None,
          threads: int = 0, batch: int = 1 << 17):
    """USD scene -> (mitsuba module, mi.Scene, integrator, (width, height)). ``max_depth`` None: the render settings'
    ``nasset:maxDepth``, else 5."""
    mi = load_mitsuba()
    if not is_jit(mi):
        raise error("CONVERT_BACKEND", f"the neural renderer needs a vectorised Mitsuba variant (llvm_ad_rgb); got {mi.variant()}")
    register(mi)
    desc = read_scene(scene_path)
    w, h = desc.camera.resolution(width, height)
    rs = desc.render_settings
    if max_depth is None:
        max_depth = rs.get("max_depth", 5)
        max_depth = UNBOUNDED_DEPTH if max_depth == -1 else max_depth
    entries: dict = {"type": "scene"}
    objects = []
    for k, mesh in enumerate(desc.meshes):
        name = f"nasset_obj_{k}"
        if mesh.material.per_hit is not None:  # spec/renderer.md#textures: the Mitsuba plugin renders them
            warnings.warn(f"{desc.path}:{mesh.prim}: textures and primvar colours are not rendered by this implementation; "
                          "the inputs' own values are used", stacklevel=2)
        if mesh.material.presence is not None:  # spec/renderer.md#cutouts: the Mitsuba plugin renders them
            warnings.warn(f"{desc.path}:{mesh.prim}: opacity < 1 rendered opaque by this implementation (cut-outs)", stacklevel=2)
        fn = _face_normals(mesh.points, mesh.faces)
        entries[name] = mi_mesh(mi, name, mesh.points, mesh.faces)
        cn = mesh.corner_normals if mesh.corner_normals is not None else np.repeat(fn[:, None], 3, 1)
        objects.append({"id": name, "kind": Kind.MESH, "material": mesh.material, "face_normals": fn, "corner_normals": cn,
                        "points": np.asarray(mesh.points, np.float64), "faces": np.asarray(mesh.faces, np.int64),
                        "one_sided": mesh.one_sided, "back_material": mesh.back_material, "front_sign": mesh.front_sign,
                        "planar": _planar(mesh.points, fn), "prim": mesh.prim, "bbox": (mesh.points.min(0), mesh.points.max(0))})
    cache: dict = {}
    for j, inst in enumerate(desc.assets):
        try:
            asset = cache.get(inst.file) or open_asset(inst.file, threads)
        except SceneError as exc:
            raise SceneError(exc.code, f"{exc.message} (asset {exc.file})", file=scene_path, prim=inst.prim) from None
        cache[inst.file] = asset
        mw = inst.to_world
        if abs(np.linalg.det(mw[:3, :3])) < 1e-30:
            raise SceneError("SCENE_INVALID", "asset instance transform is singular", file=scene_path, prim=inst.prim)
        pts = asset.points @ mw[:3, :3] + mw[3, :3]
        name = f"nasset_inst_{j}"
        entries[name] = mi_mesh(mi, name, pts, asset.faces)
        objects.append({"id": name, "kind": Kind.ASSET, "asset": asset, "to_world": mw, "m3_inv": np.linalg.inv(mw[:3, :3]),
                        "face_normals": _face_normals(pts, asset.faces), "points": pts, "faces": np.asarray(asset.faces, np.int64),
                        "prim": inst.prim, "bbox": (pts.min(0), pts.max(0))})
    lights, light_entries = build_lights(desc.lights, scene_path)
    for lt in lights:
        if getattr(lt, "has_shape", False):
            objects.append({"id": lt.key, "kind": Kind.LIGHT, "light": lt, "face_normals": np.zeros((1, 3)), "prim": lt.desc.prim})
    entries.update(light_entries)
    cam = desc.camera
    entries["sensor"] = sensor_dict(mi, cam, w, h)
    try:
        scene = mi.load_dict(entries)
    except Exception as exc:
        raise SceneError("SCENE_INVALID", f"Mitsuba could not build the scene: {str(exc).splitlines()[0][:300]}", file=scene_path) from None
    # shadow rays pass every light surface: traced on the other shapes alone (Mitsuba's analytic shapes are costly to
    # intersect, and each one met cost a re-cast: 100 sphere lights made a render 80x slower)
    solid = [o["id"] for o in objects if o["kind"] != Kind.LIGHT]
    shadow_scene = (mi.load_dict({"type": "scene", **{k: entries[k] for k in solid}}) if len(solid) < len(objects)
                    else None)
    key = f"ctx{len(_CONTEXTS)}"
    _CONTEXTS[key] = {"objects": objects, "lights": lights, "camera": cam, "width": w, "height": h, "shadow_scene": shadow_scene,
                      "pixel_filter": (rs.get("pixel_filter", "box"), rs.get("pixel_filter_stddev", 0.5))}
    integrator = mi.load_dict({"type": INTEGRATOR, "context": key, "max_depth": int(max_depth), "batch": int(batch)})
    return mi, scene, integrator, (w, h)


def render(scene_path: str, spp: int, *, width: int | None = None, height: int | None = None, seed: int = 0,
           max_depth: int | None = None,
           threads: int = 0, batch: int = 1 << 17) -> np.ndarray:
    """Render ``scene_path``; returns float32 [H, W, 3] radiance."""
    if spp < 1:
        raise SceneError("SCENE_INVALID", f"spp must be >= 1 (got {spp})", file=scene_path)
    mi, scene, integrator, _ = build(scene_path, width, height, max_depth=max_depth, threads=threads, batch=batch)
    try:
        img = integrator.render(scene, scene.sensors()[0], seed, spp)
        return np.asarray(img.numpy(), np.float32)
    finally:
        _CONTEXTS.pop(integrator.context, None)  # release the scene's objects and sessions with the render


def write_exr(path: str, img: np.ndarray) -> None:
    mi = load_mitsuba()
    mi.Bitmap(np.ascontiguousarray(img, np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB).write(str(path))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m nasset_mitsuba_renderer.render", description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("output")
    ap.add_argument("spp", type=int)
    ap.add_argument("--width", type=int, default=None)
    ap.add_argument("--height", type=int, default=None)
    ap.add_argument("--seed", type=seed_arg, default=0)
    ap.add_argument("--max-depth", type=int, default=None, help="bounces (default: the render settings' nasset:maxDepth, else 5)")
    ap.add_argument("--threads", type=int, default=0, help="onnxruntime intra-op threads (0 = auto)")
    ap.add_argument("--batch", type=int, default=1 << 17, help="paths per wavefront")
    ap.add_argument("--neupress-sampling", default="auto", choices=list(neupress.MODES), help="neupress techniques (spec/renderer.md#neupress)")
    args = ap.parse_args(argv)
    neupress.SAMPLING[0] = args.neupress_sampling
    t0 = time.time()
    try:
        img = render(args.scene, args.spp, width=args.width, height=args.height, seed=args.seed, max_depth=args.max_depth,
                     threads=args.threads, batch=args.batch)
        write_exr(args.output, img)
    except NassetError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({img.shape[1]}x{img.shape[0]}, {args.spp} spp) in {time.time() - t0:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
