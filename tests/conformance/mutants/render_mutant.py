"""The reference renderer with one deliberate bug: checks that the conformance cases catch it.

    python tests/conformance/mutants/render_mutant.py MUTANT SCENE OUT SPP WIDTH HEIGHT SEED
    python tests/conformance/mutants/render_mutant.py --list

Each mutant patches one thing in ``nasset_reference_renderer`` / the rna evaluator (in this process
only), then renders like ``nasset render``. Used as a ``--renderer`` of ``nasset conformance``
by tests/renderer/test_conformance.py.
"""

from __future__ import annotations

import sys

import numpy as np


def _patch_evaluate(fn):
    from nasset_sdk.kinds import rna

    orig = rna.RnaEvaluator.evaluate

    def evaluate(self, x, frame, wo, wi, h=None):
        u, s = orig(self, x, frame, wo, wi, h)
        return fn(u, s, frame, wi)

    rna.RnaEvaluator.evaluate = evaluate


def swap_branches():
    """Shadowed and unshadowed outputs swapped (y[0:3] used where the asset blocks the shadow ray)."""
    _patch_evaluate(lambda u, s, n, wi: (s, u))


def cos_factor():
    """Transport multiplied by cos(n, wi), as if T were a BRDF (light intensity off by a cosine)."""

    def fn(u, s, n, wi):
        nn = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        ww = wi / np.maximum(np.linalg.norm(wi, axis=1, keepdims=True), 1e-12)
        c = np.maximum((nn * ww).sum(1), 0.0)[:, None].astype(np.float32)
        return u * c, s * c

    _patch_evaluate(fn)


def world_directions():
    """wo and wi handed to the network in world space (not mapped by the inverse linear part)."""
    from nasset_reference_renderer.integrator import PathIntegrator

    orig = PathIntegrator.to_object

    def to_object(self, v, inst, point=False):
        return orig(self, v, inst, point) if point else np.array(v, np.float64)

    PathIntegrator.to_object = to_object


def world_points():
    """Hit points handed to the network in world space (no inverse instance transform)."""
    from nasset_reference_renderer.integrator import PathIntegrator

    orig = PathIntegrator.to_object

    def to_object(self, v, inst, point=False):
        return np.array(v, np.float64) if point else orig(self, v, inst, point)

    PathIntegrator.to_object = to_object


def triplane_uv_swapped():
    """Triplane planes read with u and v swapped (YX, ZY, XZ instead of XY, YZ, ZX)."""
    from nasset_sdk.kinds import encodings

    encodings.TRIPLANE_AXES = ((1, 0), (2, 1), (0, 2))


def triplane_planes_rotated():
    """Triplane plane order wrong (planes read as YZ, ZX, XY)."""
    from nasset_sdk.kinds import encodings

    encodings.TRIPLANE_AXES = ((1, 2), (2, 0), (0, 1))


def other_shadows_ignored():
    """Light samples at an asset vertex are not blocked by other objects (only the self test)."""
    from nasset_reference_renderer.integrator import PathIntegrator

    orig = PathIntegrator.trace

    def trace(self, o, d, tmax=None, ignore=None, *rest):
        h = orig(self, o, d, tmax, ignore, *rest)
        if tmax is not None and ignore is not None and sys._getframe(1).f_code.co_name == "light_shadows":  # the asset vertex's light samples
            h.prim[:] = -1
        return h

    PathIntegrator.trace = trace


def asset_casts_no_shadow():
    """Shadow rays of ordinary surfaces pass through neural assets."""
    from nasset_reference_renderer.accel import Accel
    from nasset_reference_renderer.integrator import PathIntegrator

    orig_init = PathIntegrator.__init__

    def init(self, scene, plan, settings):
        orig_init(self, scene, plan, settings)
        keep = ~self.inst_neural[scene.tri_inst] if len(scene.tri_inst) else np.zeros(0, bool)
        self._mesh_accel = Accel(scene.triangles[keep], scene.tri_inst[keep], backend=settings.backend)

    def occluded(self, o, d, tmax):
        return self._mesh_accel.occluded(o, d, tmax)

    PathIntegrator.__init__ = init
    PathIntegrator.occluded = occluded


def other_instance_is_self():
    """Rays leaving an instance skip every instance of the same asset file, not only its own triangles."""
    from nasset_reference_renderer.accel import Accel
    from nasset_reference_renderer.integrator import PathIntegrator

    orig_init = PathIntegrator.__init__
    orig_trace = PathIntegrator.trace

    def init(self, scene, plan, settings):
        orig_init(self, scene, plan, settings)
        first = {}
        canon = np.arange(len(scene.instances))
        for i, inst in enumerate(scene.instances):
            if inst.kind == "neural":
                canon[i] = first.setdefault(inst.asset, i)
        self._canon = canon
        self.accel = Accel(scene.triangles, canon[scene.tri_inst], backend=settings.backend, separate=self.inst_neural)

    def trace(self, o, d, tmax=None, ignore=None, *rest):
        if ignore is not None:
            ignore = np.where(ignore >= 0, self._canon[np.maximum(ignore, 0)], ignore)
        return orig_trace(self, o, d, tmax, ignore, *rest)

    PathIntegrator.__init__ = init
    PathIntegrator.trace = trace


def distant_angle_ignored():
    """DistantLight angle ignored (always a delta light)."""
    from nasset_reference_renderer import lights, scene

    class Delta(lights.DistantLight):
        def __init__(self, direction, irradiance, angle_deg, prim=""):
            super().__init__(direction, irradiance, 0.0, prim)

    scene.DistantLight = Delta


def dome_mirrored():
    """DomeLight lat-long map mirrored left-right (u -> 1 - u), consistently for lookup and sampling."""
    from nasset_reference_renderer.lights import DomeLight

    to_uv, to_dir = DomeLight.dir_to_uv, DomeLight.uv_to_dir
    DomeLight.dir_to_uv = staticmethod(lambda d: to_uv(d * np.array([-1.0, 1.0, 1.0])))
    DomeLight.uv_to_dir = staticmethod(lambda uv: (lambda r: (r[0] * np.array([-1.0, 1.0, 1.0]), r[1]))(to_dir(uv)))


def one_escaped_light():
    """Escaping rays see only the first light at infinity (a renderer that keeps one environment light); the others
    are still sampled."""
    from nasset_reference_renderer import lights

    first: list = []
    for cls in (lights.DistantLight, lights.DomeLight):
        def le_escaped(self, d, _orig=cls.le_escaped):
            first[:] = first or [id(self)]
            le = _orig(self, d)
            return le if first[0] == id(self) else np.zeros_like(le)

        cls.le_escaped = le_escaped


def camera_visibility_ignored():
    """``nasset:cameraVisibility`` = false ignored: camera rays see every light surface and the dome."""
    from nasset_reference_renderer import lights

    lights.Light.camera_visible = property(lambda self: True, lambda self, value: None)


def spot_shaping_ignored():
    """UsdLux.ShapingAPI ignored: a spot light is an unshaped point light."""
    from nasset_reference_renderer import scene

    scene._Loader._shaping = lambda self, prim, M: {}


def beckmann_as_ggx():
    """``nasset:microfacet`` = beckmann ignored: every lobe is GGX at the same alpha (a renderer without Beckmann)."""
    from nasset_reference_renderer import scene

    scene._beckmann_column = lambda flags: None


def sphere_shaping_ignored():
    """UsdLux.ShapingAPI ignored on a SphereLight of radius > 0 (the rule before 2026-12-07): a spot with a radius
    lights every direction like an unshaped sphere light."""
    from nasset_reference_renderer import lights

    init = lights.SphereLight.__init__

    def unshaped(self, center, radius, radiance, prim="", **shaping):
        init(self, center, radius, radiance, prim)

    lights.SphereLight.__init__ = unshaped


def spread_ignored():
    """``nasset:spread`` ignored: every RectLight and DiskLight a Lambertian emitter."""
    from nasset_sdk import stage_rules

    stage_rules.light_spread = lambda prim, time, file: stage_rules.MAX_SPREAD


def light_surfaces_occlude():
    """A ray ends at the first light surface it meets (Mitsuba's emitter shapes; the spec's rule before 2026-12-07)
    instead of going on past every light surface; a RectLight's back still lets it through."""
    from nasset_reference_renderer import lights

    lights.Light.opaque = property(lambda self: True, lambda self, value: None)


def no_asset_indirect():
    """Rays never continue from a neural asset (next-event estimation only, even with other objects)."""
    from nasset_reference_renderer import integrator, plan

    orig = plan.make_plan

    def make_plan(scene, **kw):
        p = orig(scene, **kw)
        for i, inst in enumerate(scene.instances):
            if inst.kind == "neural":
                p.instance_indirect[i] = False
        return p

    plan.make_plan = integrator.make_plan = make_plan  # (the render verb imports it from .plan when it runs)


def mis_weights_one():
    """Power-heuristic weights replaced by 1 (light samples and BSDF/continuation hits both counted)."""
    from nasset_reference_renderer import integrator

    integrator.power_heuristic = lambda a, b: np.ones(np.broadcast(a, b).shape)


def quality_hq():
    """The plan loads the 'hq' quality variant instead of the asset's default."""
    from nasset_sdk.asset import Asset

    orig = Asset.load

    def load(self, which="required"):
        if any(c.qualities and "hq" in c.qualities for c in self.components().values()):
            self.select_quality("hq")
        return orig(self, which)

    Asset.load = load


# -- neupress, 8dna, rna fiber --------------------------------------------------------------------------------------
def neupress_wi_flipped():
    """neupress: the subsurface network evaluated at -w_i (w_i taken as the direction light travels, not towards it)."""
    from nasset_sdk.kinds.neupress import NeupressEvaluator

    orig = NeupressEvaluator.evaluate
    NeupressEvaluator.evaluate = lambda self, x, n, wo, wi: orig(self, x, n, wo, -np.asarray(wi))


def neupress_reflection_dropped():
    """neupress: the analytic rough-dielectric surface reflection left out (subsurface part only)."""
    from nasset_sdk.kinds.neupress import NeupressEvaluator

    orig = NeupressEvaluator.surface_reflection
    NeupressEvaluator.surface_reflection = lambda self, n, wo, wi: 0.0 * orig(self, n, wo, wi)


def neupress_lobe_width():
    """neupress: the boundary's GGX alpha squared again (read as a perceptual roughness), so the reflection lobe is
    too narrow (alpha 0.2 -> 0.04 for the example asset)."""
    from nasset_sdk.kinds.neupress import NeupressEvaluator

    orig = NeupressEvaluator.__init__

    def init(self, *a, **k):
        orig(self, *a, **k)
        self.alpha = self.alpha ** 2

    NeupressEvaluator.__init__ = init


def eightdna_pdf_scale():
    """8dna: the flow's joint density left in t-space units (per unit t^4) instead of per unit box area and steradian:
    too large by the 4 pi of the direction measure (its position marginal unchanged)."""
    from nasset_sdk.kinds.eightdna import EightDnaEvaluator

    orig, orig_at, orig_own = EightDnaEvaluator.pdf, EightDnaEvaluator.pdf_rgb_at, EightDnaEvaluator.pdf_rgb_sampled
    EightDnaEvaluator.pdf = lambda self, *a, **k: 4 * np.pi * orig(self, *a, **k)
    EightDnaEvaluator.pdf_rgb_at = lambda self, *a, **k: 4 * np.pi * orig_at(self, *a, **k)
    EightDnaEvaluator.pdf_rgb_sampled = lambda self, *a, **k: 4 * np.pi * orig_own(self, *a, **k)


def eightdna_direction_flipped():
    """8dna: the flow's density evaluated at -w_i (direction convention flipped)."""
    from nasset_sdk.kinds.eightdna import EightDnaEvaluator

    orig, orig_at = EightDnaEvaluator.pdf, EightDnaEvaluator.pdf_rgb_at
    EightDnaEvaluator.pdf = lambda self, x, wo, ui, wi, ch: orig(self, x, wo, ui, -np.asarray(wi), ch)
    EightDnaEvaluator.pdf_rgb_at = lambda self, fs, rows, wi: orig_at(self, fs, rows, -np.asarray(wi))
    EightDnaEvaluator.pdf_rgb_sampled = lambda self, fs, rows: orig_at(self, fs, rows, -fs.wi[np.asarray(rows, np.int64)])


def eightdna_u_untransformed():
    """8dna: the flow's u_i used in object space (not mapped by the instance transform) for its light samples, shadow
    rays and continuations."""
    from nasset_reference_renderer.shaders import common

    common.Frames.point_to_world = lambda self, p, inst: np.array(p, np.float64)


def eightdna_light_at_xo():
    """8dna: the neural term's light samples drawn as seen from the hit point x_o instead of u_i (direction, distance,
    radiance and pdf of a near light taken where a distant light would be); shadow rays still leave u_i."""
    from nasset_reference_renderer.shaders import common, eightdna

    orig_vertex, orig_world = eightdna.EightdnaShader.vertex, common.Frames.point_to_world

    def vertex(self, r, idx, x, *a, **k):
        x_o = x[r]
        u_seen = []

        def point_to_world(frames, p, inst):
            u = orig_world(frames, p, inst)
            u_seen.append(u)
            return u

        lights = self.integ.scene.lights
        samplers = [light.sample for light in lights]

        def at_xo(sample):
            return lambda p, u: sample(x_o if any(p is s for s in u_seen) else p, u)

        common.Frames.point_to_world = point_to_world
        for light, sample in zip(lights, samplers, strict=True):
            light.sample = at_xo(sample)
        try:
            return orig_vertex(self, r, idx, x, *a, **k)
        finally:
            common.Frames.point_to_world = orig_world
            for light, sample in zip(lights, samplers, strict=True):
                light.sample = sample

    eightdna.EightdnaShader.vertex = vertex


def fiber_h_sign():
    """rna fiber: the cross-fiber offset h handed to the network with the wrong sign."""
    from nasset_reference_renderer.shaders import rna_fiber as neural_fiber

    orig = neural_fiber.fiber_frame

    def fiber_frame(tubes, seg, x_obj, wo_obj):
        t, h = orig(tubes, seg, x_obj, wo_obj)
        return t, -h

    neural_fiber.fiber_frame = fiber_frame


def near_field_ignored():
    """rna and neupress: nasset:nearFieldFetch ignored (every hit's light taken at the hit, the rule of format 0.2)."""
    from nasset_reference_renderer.integrator import PathIntegrator

    PathIntegrator.fetch_points = lambda self, x, inst: None


def fiber_exempt_stops_search():
    """rna fiber: a ray leaving a fiber whose first asset triangle is exempt (its own segment or a neighbour's)
    stops looking for the asset there, so fibres further along never pick the shadowed branch."""
    from nasset_reference_renderer import accel

    accel.MAX_EXEMPT_STEPS = 1


MUTANTS = {f.__name__: f for f in (swap_branches, cos_factor, world_directions, world_points, triplane_uv_swapped,
                                   triplane_planes_rotated, other_shadows_ignored, asset_casts_no_shadow, other_instance_is_self,
                                   distant_angle_ignored, dome_mirrored, one_escaped_light, camera_visibility_ignored,
                                   spot_shaping_ignored, beckmann_as_ggx, spread_ignored,
                                   sphere_shaping_ignored, light_surfaces_occlude,
                                   no_asset_indirect, mis_weights_one, quality_hq,
                                   neupress_wi_flipped, neupress_reflection_dropped, neupress_lobe_width,
                                   eightdna_pdf_scale, eightdna_direction_flipped, eightdna_u_untransformed,
                                   eightdna_light_at_xo,
                                   fiber_h_sign, fiber_exempt_stops_search, near_field_ignored)}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--list"]:
        for k, f in MUTANTS.items():
            print(f"{k}: {f.__doc__}")
        return 0
    if len(argv) != 7 or argv[0] not in MUTANTS:
        print(__doc__, file=sys.stderr)
        return 2
    name, scene, out, spp, width, height, seed = argv
    MUTANTS[name]()
    from nasset_sdk.cli import main as nasset

    # one render thread: some mutants patch shared objects for the length of one call (eightdna_light_at_xo)
    return nasset(["render", scene, "-o", out, "--spp", spp, "--width", width, "--height", height, "--seed", seed, "--quiet",
                   "--workers", "1"])


if __name__ == "__main__":
    sys.exit(main())
