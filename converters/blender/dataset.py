"""Training data for the rna kind, rendered by Blender Cycles (spec/bake-blender.md#data).

Per view: a square pinhole camera on a sphere of ``distance`` bounding radii around the asset
looks at its centre; a sun lamp of angular radius ``light_angle_deg`` (Blender ``angle`` = twice
that) and irradiance 1 W/m^2 shines from a random direction wi (Cycles has no per-pixel light,
spec/bake-blender.md#deviations). ``lights_per_view = k`` puts k suns in a training view, each in its own Cycles
light group, so one render gives every pixel k samples, one per sun (spec/bake-blender.md#light-groups); held-out
views have one sun. The asset is rendered alone (every other object
hidden, black world, transparent film) by Cycles on the CPU with a 0.01-pixel filter, so each
pixel is point-sampled at its centre, unclamped (Cycles' sample clamps off by default; ``--clamp C`` sets both) for training
views; held-out views are unclamped, rendered as two independent halves (``rgb_a``, ``rgb_b``; the
alpha of their mean divides both) so their own noise is measured (spec/accuracy.md#metrics).

The geometric inputs come from our own ray caster on the exported geometry (Embree, the
reference renderer's :class:`nasset_reference_renderer.accel.Accel`, with fibers tessellated exactly
as the renderer tessellates them), along the very pixel-centre rays of the Cycles camera: hit
point x, shading normal n (surfaces; interpolated vertex normals) or tangent t and offset h
(fibers; :func:`nasset_reference_renderer.shaders.rna_fiber.fiber_frame`), and the light visibility V from
the hit against the asset alone, cast the way the renderer casts it. Pixels kept: our ray hits
and Cycles' alpha is >= ``alpha_min`` (both agree the pixel centre is on the asset); the
fraction of disagreeing pixels is recorded (``mask_disagreement``: silhouettes of curved
geometry vs our tessellation).

Folder layout, resume and atomic writes: ``nasset_converters.mitsuba.dataset.DatasetDir`` (same FIELDS;
fibers add ``h``).
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from nasset_converters.caster import Caster, agree
from nasset_converters.mitsuba.dataset import DatasetDir, camera_rays, unit_sphere  # noqa: F401 - re-exported
from nasset_sdk.errors import error

from . import CONVERTER_VERSION, quiet_stdout, to_z_up


@dataclass(frozen=True)
class DataSettings:
    views: int = 48
    val_views: int = 4
    res: int = 64
    spp: int = 64
    val_res: int = 0  # 0: res
    val_spp: int = 512
    light_angle_deg: float = 0.5  # angular radius of the sun (Blender angle = 2x)
    distance: float = 2.6  # camera distance in bounding-sphere radii
    upper_hemisphere: bool = False
    clamp_direct: float = 0.0  # Cycles sample_clamp_direct; 0: none (the paper's 20 throws energy away, spec/bake.md#clamp)
    clamp_indirect: float = 0.0  # Cycles sample_clamp_indirect; 0: none (the paper's 10)
    max_bounces: int = 32
    alpha_min: float = 0.99
    seed: int = 0
    lights_per_view: int = 1  # k suns per training view, each its own light group: k samples per pixel from one render

    @property
    def spp_per_target(self) -> float:
        """The paths behind one training target: k suns share a render's spp (each path's light sample picks one sun),
        so each sun's target is about as noisy as a one-sun render of spp / k (spec/bake-blender.md#light-groups)."""
        return self.spp / max(1, int(self.lights_per_view))


class CyclesRig:
    """The isolated asset in Cycles with our own camera and sun; renders RGBA views."""

    def __init__(self, settings: DataSettings, workdir, threads: int = 0) -> None:
        from . import load_bpy

        bpy = self.bpy = load_bpy()
        self.s = settings
        sc = self.scene = bpy.context.scene
        cam = bpy.data.cameras.new("nasset_camera")
        cam.lens_unit = "FOV"
        cam.sensor_fit = "HORIZONTAL"
        self.cam = bpy.data.objects.new("nasset_camera", cam)
        sc.collection.objects.link(self.cam)
        sc.camera = self.cam
        self.layer = bpy.context.view_layer
        self.suns: list = []  # sun i lights the layer's light group LIGHT_GROUP.format(i)
        self.cam.hide_render = False
        r = sc.render
        r.engine = "CYCLES"
        r.film_transparent = True
        r.resolution_percentage = 100
        r.use_persistent_data = True
        r.use_single_layer = True  # the active view layer only: one Combined pass and its light groups
        r.image_settings.media_type = "MULTI_LAYER_IMAGE"
        r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
        r.image_settings.color_depth = "32"
        if threads:
            r.threads_mode = "FIXED"
            r.threads = int(threads)
        c = sc.cycles
        c.device = "CPU"
        c.use_denoising = False
        c.use_adaptive_sampling = False
        c.filter_width = 0.01
        c.sample_clamp_direct = settings.clamp_direct
        c.sample_clamp_indirect = settings.clamp_indirect
        c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = settings.max_bounces
        c.volume_bounces = settings.max_bounces
        c.transparent_max_bounces = settings.max_bounces
        c.caustics_reflective = c.caustics_refractive = True
        c.blur_glossy = 0.0
        sc.view_settings.view_transform = "Standard"
        self.tmp = Path(tempfile.mkdtemp(prefix="cycles_", dir=workdir))

    def place_camera(self, eye, target, half_fov: float, res: int) -> None:
        """Camera at eye (asset space, +Y up) looking at target, matching :func:`camera_rays`."""
        from mathutils import Matrix

        fwd = np.asarray(target, np.float64) - np.asarray(eye, np.float64)
        fwd /= max(float(np.linalg.norm(fwd)), 1e-12)
        up0 = np.array([0.0, 1.0, 0.0]) if abs(fwd[1]) < 0.95 else np.array([1.0, 0.0, 0.0])
        right = np.cross(fwd, up0)
        right /= max(float(np.linalg.norm(right)), 1e-12)
        up = np.cross(right, fwd)
        cols = to_z_up(np.stack([right, up, -fwd]))  # camera local X, Y, Z in Blender world
        m = np.eye(4)
        m[:3, :3] = cols.T
        m[:3, 3] = to_z_up(np.asarray(eye, np.float64)[None])[0]
        self.cam.matrix_world = Matrix(m.tolist())
        self.cam.data.angle = 2.0 * half_fov
        self.scene.render.resolution_x = self.scene.render.resolution_y = int(res)

    def place_suns(self, wis) -> None:
        """Suns shining from directions ``wis`` [k, 3] (asset space, unit, towards the light), sun i in light group i;
        suns beyond k are switched off."""
        from mathutils import Vector

        bpy = self.bpy
        wis = np.asarray(wis, np.float64).reshape(-1, 3)
        while len(self.suns) < len(wis):
            i = len(self.suns)
            sun = bpy.data.lights.new(f"nasset_sun_{i}", "SUN")
            sun.energy = 1.0  # irradiance, W/m^2
            sun.angle = math.radians(2.0 * self.s.light_angle_deg)
            ob = bpy.data.objects.new(f"nasset_sun_{i}", sun)
            self.scene.collection.objects.link(ob)
            group = self.layer.lightgroups.add()
            group.name = ob.lightgroup = LIGHT_GROUP.format(i)
            self.suns.append(ob)
        for i, ob in enumerate(self.suns):
            ob.hide_render = i >= len(wis)
            if i < len(wis):
                z = Vector(to_z_up(wis[i][None])[0].tolist())
                ob.rotation_euler = z.to_track_quat("Z", "Y").to_euler()

    def render(self, spp: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """(RGBA [res, res, 4], the light groups' RGB [k, res, res, 3]) float32 for the k suns placed, row 0 at the
        top: every light reaching the film, and each sun's own share of it."""
        import OpenEXR

        sc = self.scene
        sc.cycles.samples = int(spp)
        sc.cycles.seed = int(seed) & 0x7FFFFFFF
        path = self.tmp / "view.exr"
        sc.render.filepath = str(path)
        with quiet_stdout():
            self.bpy.ops.render.render(write_still=True)
        with OpenEXR.File(str(path)) as f:
            passes = {p.name().rsplit(".", 1)[-1]: p.channels for p in f.parts}
            k = sum(not ob.hide_render for ob in self.suns)
            try:
                rgba = _pixels(passes["Combined"], 4)
                groups = np.stack([_pixels(passes["Combined_" + LIGHT_GROUP.format(i)], 3) for i in range(k)])
            except KeyError as exc:
                raise error("CONVERT_BACKEND", f"Cycles wrote no {exc.args[0]} pass (passes: {', '.join(passes)})",
                            file=str(path)) from None
        os.remove(path)
        return (np.nan_to_num(rgba, nan=0.0, posinf=0.0, neginf=0.0),
                np.nan_to_num(groups, nan=0.0, posinf=0.0, neginf=0.0))

    def close(self) -> None:
        try:
            os.rmdir(self.tmp)
        except OSError:
            pass


#: the light group of sun i (``CyclesRig.place_suns``)
LIGHT_GROUP = "nasset_sun_{}"


def _pixels(channels: dict, n: int) -> np.ndarray:
    """One pass of an OpenEXR part as [h, w, n] float32 (one interleaved channel, or one per letter)."""
    if len(channels) == 1:
        return np.asarray(next(iter(channels.values())).pixels, np.float32)[..., :n]
    names = sorted(channels, key=lambda c: "RGBA".find(c.rsplit(".", 1)[-1]))
    return np.stack([np.asarray(channels[c].pixels, np.float32) for c in names[:n]], -1)


def view_camera(s: DataSettings, center, radius: float, view_id: int, validation: bool):
    """(rng, eye, half_fov, res) of a view; deterministic in (seed, split, view)."""
    rng = np.random.default_rng([s.seed, 1 if validation else 0, view_id])
    cam_dir = unit_sphere(rng, 1, s.upper_hemisphere)[0]
    eye = np.asarray(center, np.float64) + s.distance * radius * cam_dir
    half_fov = float(np.arcsin(min(1.0 / max(s.distance, 1.0 + 1e-6), 0.999))) * 1.04
    res = (s.val_res or s.res) if validation else s.res
    return rng, eye, half_fov, res


def render_view(rig: CyclesRig, caster: Caster, center, radius: float, view_id: int, *, validation: bool) -> dict:
    """One view's samples (FIELDS, plus 'h' for fibers) and its statistics."""
    s = rig.s
    rng, eye, half_fov, res = view_camera(s, center, radius, view_id, validation)
    o, d = camera_rays(eye, np.asarray(center, np.float64), half_fov, res)
    hit = caster.hits(o, d)
    k = 1 if validation else max(1, int(s.lights_per_view))
    wis = unit_sphere(rng, k, s.upper_hemisphere)  # k = 1 draws what one sun per view always drew
    rig.place_camera(eye, center, half_fov, res)
    rig.place_suns(wis)
    spp = s.val_spp if validation else s.spp
    vseed = hash((s.seed, int(validation), view_id)) & 0xFFFFFF
    halves = None
    if validation:  # held-out: unclamped, two independent halves (spec/accuracy.md#metrics)
        c = rig.scene.cycles
        saved = (c.sample_clamp_direct, c.sample_clamp_indirect)
        c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
        try:
            halves = [rig.render(max(1, spp // 2), seed=hs) for hs in (vseed, vseed ^ 0x800000)]
        finally:
            c.sample_clamp_direct, c.sample_clamp_indirect = saved
        rgba = 0.5 * (halves[0][0] + halves[1][0])
        suns = 0.5 * (halves[0][1] + halves[1][1])
    else:
        rgba, suns = rig.render(spp, seed=vseed)
    rgba = rgba.reshape(-1, 4)
    alpha = rgba[:, 3]
    sel, disagree, covered = agree(hit, len(o), alpha >= s.alpha_min, alpha > 0.5)
    pix = sel["pix"]
    inv_alpha = 1.0 / np.maximum(alpha[pix], 1e-6)[:, None]

    def sun_rgb(groups):  # [k, res, res, 3] -> [k * kept, 3], sun-major, divided by the combined alpha
        g = groups.reshape(k, -1, 3)[:, pix]
        return np.maximum(g * inv_alpha[None], 0.0).reshape(-1, 3).astype(np.float32)

    wi_all = np.repeat(wis, len(pix), 0)  # sample j of sun i at row i * kept + j
    rows = {key: np.concatenate([v] * k) if isinstance(v, np.ndarray) and len(v) == len(pix) else v
            for key, v in sel.items()}  # the kept hits, once per sun
    vis = caster.visibility(rows, wi_all)
    out = {
        "x": rows["x"].astype(np.float32), "n": rows["frame"].astype(np.float32),
        "wo": np.tile(-d[pix], (k, 1)).astype(np.float32), "wi": wi_all.astype(np.float32), "vis": vis.astype(np.uint8),
        "rgb": sun_rgb(suns), "pix": rows["pix"].astype(np.int32), "res": np.int32(res),
        "disagree": np.int32(disagree), "covered": np.int32(covered),
    }
    if caster.variant == "fiber":
        out["h"] = rows["h"].astype(np.float32)
    if halves is not None:
        for name, (_, hv) in zip(("rgb_a", "rgb_b"), halves, strict=True):
            out[name] = sun_rgb(hv)
    return out


def settings_digest(source_key: str, object_names, variant: str, settings: DataSettings) -> dict:
    """What a dataset folder must agree on to be resumed (source_key: the .blend's sha256 or the example name)."""
    return {
        "converter": f"blender {CONVERTER_VERSION}",
        "source": source_key,
        "objects": list(object_names),
        "variant": variant,
        "settings": asdict(settings),
    }


def file_sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_split(store: DatasetDir, split: str, count: int, fiber: bool) -> dict:
    """All views of a split concatenated (FIELDS, 'h' for fibers) plus 'view' and the mask statistics."""
    out = store.load_split(split, count)
    if fiber != ("h" in out) or "disagree" not in out:
        raise error("CONVERT_DATASET", f"the {split} views are not those of a {'fiber' if fiber else 'surface'} Cycles bake",
                    file=str(store.root))
    return out
