"""Wavefront path tracer of spec/renderer.md on top of Mitsuba's ray tracing.

Design: every path state lives in numpy arrays; each bounce builds one ``mi.Ray3f`` for the
whole wavefront and calls ``scene.ray_intersect`` (Mitsuba/Embree-free BVH in the llvm variant).
Rays that must ignore an asset instance re-trace past its hits (recording that they passed
through it: the rna branch choice). Lights are sampled one by one (NEE on every light), area
lights through Mitsuba's emitters; plain surfaces use the spec's UsdPreviewSurface BSDF in numpy
(Mitsuba has no BSDF with that exact lobe), with the glass lobe of a transmitting material; neural-asset vertices evaluate the asset's
transport in batches through onnxruntime.

Kinds plug in through :data:`ASSET_SHADERS` (kind -> shader class; ``register_shader(kind, cls)``):
the CLI opens each asset file with ``cls.open(path, threads)`` (an object with ``kind``, ``fiber``,
object-space ``points``, ``faces`` and ``face_normals``) and the tracer builds one ``cls(self)`` per
kind present, calling its ``vertex(...)`` for every wavefront of hits on that kind's instances (see
:class:`RnaShader` for the contract, :mod:`.neupress` for a second kind). A kind module registers
itself at import; ``mitsuba_renderer/render.py`` imports it.
"""

from __future__ import annotations

import numpy as np

from .lights import MitsubaLight, p3, v3

FOUR_PI = 4.0 * np.pi
INV_FOUR_PI = 1.0 / FOUR_PI


def normalized(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def dot(a, b):
    return np.einsum("ij,ij->i", a, b)


#: ray-offset scale: a few hundred float32 ulps of the hit's coordinates, plus a tiny fraction of
#: the scene's size (set by PathTracer), so the offset tracks both far-from-origin and tiny scenes.
_EPS_REL = 4e-6
_EPS_SCENE = [1e-6]


def ray_eps(p):
    return _EPS_REL * np.max(np.abs(p), axis=1) + _EPS_SCENE[0]


def fresnel(c, eta):
    """Unpolarised dielectric Fresnel reflectance [m] at |c| for relative IOR eta (1 under total internal reflection)."""
    c = np.abs(c)
    st2 = (1.0 - c * c) / (eta * eta)
    ct = np.sqrt(np.maximum(1.0 - st2, 0.0))
    rs = (c - eta * ct) / np.maximum(c + eta * ct, 1e-12)
    rp = (eta * c - ct) / np.maximum(eta * c + ct, 1e-12)
    return np.where(st2 >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))


def power(a, b):
    a2, b2 = a * a, b * b
    return np.where(a2 + b2 > 0, a2 / np.maximum(a2 + b2, 1e-300), 0.0)


def mis_weight(prev_pdf, light_pdf):
    """Weight of emission reached by a continuation of pdf ``prev_pdf``: > 0 power heuristic against
    the light's pdf; 0 weight 1 (camera rays, unsampled techniques); < 0 weight 0 (the light's
    emission is counted by its light samples alone)."""
    return np.where(prev_pdf > 0, power(np.maximum(prev_pdf, 0.0), light_pdf), np.where(prev_pdf < 0, 0.0, 1.0))


class Tracer:
    """Batch ray casting with optional per-ray ignored shape (and pass-through recording)."""

    def __init__(self, mi, scene, shape_ids) -> None:
        import drjit as dr

        self.mi, self.dr, self.scene = mi, dr, scene
        self.shape_ids = shape_ids  # registry id -> index into self.kinds
        self.max_id = max(shape_ids) + 1 if shape_ids else 1
        lut = np.full(self.max_id + 1, -1, np.int64)
        for rid, idx in shape_ids.items():
            lut[rid] = idx
        self.lut = lut

    def _cast(self, o, d, maxt):
        mi, dr = self.mi, self.dr
        ray = mi.Ray3f(p3(mi, o), v3(mi, d))
        ray.maxt = mi.Float(np.ascontiguousarray(np.minimum(maxt, 3.0e38), np.float32))
        si = self.scene.ray_intersect(ray, mi.RayFlags.Minimal, True)
        valid = si.is_valid().numpy().astype(bool)
        sid = dr.reinterpret_array(mi.UInt32, si.shape).numpy().astype(np.int64)
        obj = np.where(valid, self.lut[np.clip(sid, 0, self.max_id)], -1)
        t = si.t.numpy().astype(np.float64)
        ng = si.n.numpy().T.astype(np.float64)
        return valid & (obj >= 0), obj, t, si.prim_index.numpy().astype(np.int64), si.uv.numpy().T.astype(np.float64), ng

    def trace(self, o, d, maxt=None, ignore=None, transparent=None, max_skips=64, exempt=None, until_passed=False,
              back_through=None):
        """-> dict(hit, obj, t, prim, b1, b2, passed).

        ``ignore[i]``: object index ray i passes through, recording it in ``passed`` (-1: none);
        ``exempt[i]``: triangle range [lo, hi) of the ignored object passed through without record
        (a fiber hit's own segment and its neighbours: spec/renderer.md#fibers);
        ``transparent``: bool per object index, objects every ray passes through without record
        (light shapes for shadow rays); ``until_passed``: a ray ends where it first passes through its ignored
        object (with ``transparent`` everything: whether the ray meets that object's own triangles at all);
        ``back_through``: bool per object index, objects a ray passes through where it meets them from behind (the
        light surfaces of spec/renderer.md#light-surfaces: a RectLight's back, a SphereLight from inside).
        """
        m = len(o)
        o = np.array(o, np.float64)
        d = np.asarray(d, np.float64)
        maxt = np.full(m, np.inf) if maxt is None else np.array(maxt, np.float64)
        ignore = np.full(m, -1, np.int64) if ignore is None else np.asarray(ignore, np.int64)
        exempt = None if exempt is None else np.asarray(exempt, np.int64)
        res = {"hit": np.zeros(m, bool), "obj": np.full(m, -1, np.int64), "t": np.full(m, np.inf), "prim": np.zeros(m, np.int64),
               "b1": np.zeros(m), "b2": np.zeros(m), "passed": np.zeros(m, bool)}
        travelled = np.zeros(m)
        todo = np.arange(m)
        for _ in range(max_skips):
            if len(todo) == 0:
                break
            hit, obj, t, prim, uv, ng = self._cast(o[todo], d[todo], maxt[todo] - travelled[todo])
            through = hit & (obj == ignore[todo])
            skip = through
            if exempt is not None:
                through = through & ~((prim >= exempt[todo, 0]) & (prim < exempt[todo, 1]))
            if transparent is not None:
                skip = skip | (hit & transparent[np.maximum(obj, 0)])
            if back_through is not None:
                skip = skip | (hit & back_through[np.maximum(obj, 0)] & (np.einsum("ij,ij->i", ng, d[todo]) > 0))
            if until_passed:
                skip = skip & ~through
            fin = ~skip
            idx = todo[fin]
            res["hit"][idx] = hit[fin]
            res["obj"][idx] = np.where(hit[fin], obj[fin], -1)
            res["t"][idx] = np.where(hit[fin], travelled[idx] + t[fin], np.inf)
            res["prim"][idx] = prim[fin]
            res["b1"][idx], res["b2"][idx] = uv[fin, 0], uv[fin, 1]
            s = todo[skip]
            res["passed"][todo[through]] = True
            # continue from the far side of the skipped surface (offset along its normal)
            hp = o[s] + d[s] * t[skip, None]
            n = ng[skip]
            side = np.where(np.einsum("ij,ij->i", n, d[s]) >= 0, 1.0, -1.0)[:, None]
            o_new = hp + n * side * ray_eps(hp)[:, None]
            travelled[s] += np.einsum("ij,ij->i", o_new - o[s], d[s])
            o[s] = o_new
            todo = s
        res["p"] = np.asarray(o, np.float64)  # placeholder, recomputed by the caller from t
        return res


class Kind:
    MESH, ASSET, LIGHT = 0, 1, 2


def _filter_offsets(rng, n: int, kind: str, stddev: float) -> np.ndarray:
    """Offsets [n] from a pixel's left (top) edge distributed as the pixel filter along one axis: box, uniform in
    [0, 1); gaussian, ``exp(-x^2/2s^2) - exp(-r^2/2s^2)`` on |x| < r = 4s around the pixel centre, by rejection
    from the uniform density on (-r, r) (acceptance above 0.2 for every s)."""
    if kind == "box":
        return rng.random(n)
    r, floor = 4.0 * stddev, np.exp(-8.0)
    out = np.empty(n)
    todo = np.arange(n)
    while len(todo):
        x = (2.0 * rng.random(len(todo)) - 1.0) * r
        keep = rng.random(len(todo)) * (1.0 - floor) < np.exp(-x * x / (2.0 * stddev * stddev)) - floor
        out[todo[keep]] = 0.5 + x[keep]
        todo = todo[~keep]
    return out


class PathTracer:
    def __init__(self, mi, scene, objects, lights, camera, *, max_depth=5, rr_depth=3, log=None, shadow_scene=None) -> None:
        """``objects``: list of dicts (kind, mesh/asset data, world triangles) indexed by Tracer object index;
        ``shadow_scene``: the same shapes without the light surfaces (None: ``scene`` has none), for the rays that pass
        every light surface (shadow rays, branch tests)."""
        import drjit as dr

        self.mi, self.scene, self.objects, self.lights, self.camera = mi, scene, objects, lights, camera
        self.max_depth, self.rr_depth = int(max_depth), int(rr_depth)
        ids = {}
        by_name = {o["id"]: k for k, o in enumerate(objects)}
        for sh in scene.shapes():
            k = by_name.get(sh.id())
            if k is not None:
                ids[int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(sh))[0])] = k
        self.tracer = Tracer(mi, scene, ids)
        self.shadow_tracer = self.tracer if shadow_scene is None else Tracer(mi, shadow_scene, ids)  # shapes shared
        geo = [o_["bbox"] for o_ in objects if "bbox" in o_]
        if geo:
            lo = np.min([g[0] for g in geo], axis=0)
            hi = np.max([g[1] for g in geo], axis=0)
            _EPS_SCENE[0] = 1e-6 * max(float(np.linalg.norm(hi - lo)), 1e-30)
        for lt in lights:
            if isinstance(lt, MitsubaLight):
                for em in scene.emitters():
                    if em.id() == lt.key:
                        lt.emitter = em
                if lt.emitter is None:  # shape-attached emitters carry the shape's id
                    for sh in scene.shapes():
                        if sh.id() == lt.key and sh.emitter() is not None:
                            lt.emitter = sh.emitter()
        self.light_of_obj = {k: o["light"] for k, o in enumerate(objects) if o["kind"] == Kind.LIGHT}
        reflective = [k for k, o in enumerate(objects) if o["kind"] != Kind.LIGHT]
        # light shapes: seen by camera and continuation rays, which go on past them (but for opaque ones,
        # nasset:opaqueSurface, where they end); no light shape blocks shadow rays (spec/renderer.md#light-surfaces)
        self.light_shapes = np.array([o["kind"] == Kind.LIGHT for o in objects] + [False])
        self.clear_lights = self.light_shapes & ~np.array(
            [o["kind"] == Kind.LIGHT and bool(getattr(o["light"].desc, "opaque", False)) for o in objects] + [False])
        self.every_shape = np.ones(len(objects) + 1, bool)
        self.n_reflective = len(reflective)
        # nasset:cameraVisibility = false (spec/renderer.md#light-surfaces): camera rays pass through the light's shape
        hidden = [o["kind"] == Kind.LIGHT and not getattr(o["light"].desc, "camera_visible", True) for o in objects]
        self.hidden_shapes = np.array(hidden + [False]) if any(hidden) else None
        self.log = log
        kinds = {o_["asset"].kind for o_ in objects if o_["kind"] == Kind.ASSET}
        self.shaders = {kd: ASSET_SHADERS[kd](self) for kd in sorted(kinds)}

    # -- geometry helpers -----------------------------------------------------------------------------

    def _geo(self, obj, prim):
        """World geometric normals of hits (obj, prim)."""
        ng = np.zeros((len(obj), 3))
        for k in np.unique(obj):
            sel = obj == k
            ng[sel] = self.objects[k]["face_normals"][prim[sel]]
        return ng

    def _surface_points(self, obj, prim, b1, b2, fallback):
        """World hit points [n,3] on triangles (obj, prim) at barycentrics (b1, b2), from the float64 vertices: exactly on
        the surface, however many surfaces the ray was carried past (:meth:`Tracer.trace` offsets each restart off the
        skipped surface, sideways of the ray). ``fallback`` rows where the object has no triangles (light shapes)."""
        p = np.array(fallback, np.float64)
        for k in np.unique(obj):
            ob = self.objects[k] if k >= 0 else {}
            if "points" not in ob:
                continue
            sel = obj == k
            v = ob["points"][ob["faces"][prim[sel]]]
            p[sel] = (1.0 - b1[sel] - b2[sel])[:, None] * v[:, 0] + b1[sel][:, None] * v[:, 1] + b2[sel][:, None] * v[:, 2]
        return p

    def _continues(self, obj, depth):
        # the last vertex (depth max_depth) continues too, for the emission its sample reaches (MIS with its light
        # samples, as spec/renderer.md#integrator weighs every vertex): with NEE alone there, a sharp lobe's light
        # (a glass's, a mirror's) came from rare huge light samples. With max_depth 1 no vertex continues.
        cont = np.full(len(obj), self.max_depth > 1) & (depth <= self.max_depth)
        if self.n_reflective <= 1:  # a lone planar mesh: NEE only, unless it transmits or its lobe is sharp
            planar = np.array([self.objects[k].get("planar", False) and not self._needs_continuation(k)
                               for k in range(len(self.objects))] + [False])
            cont &= ~planar[obj] & np.array([self.objects[k]["kind"] == Kind.MESH for k in range(len(self.objects))] + [False])[obj]
        return cont

    def _needs_continuation(self, k) -> bool:
        """Whether mesh k's material transmits or has a GGX alpha below 0.1 (spec/renderer.md#plan): light samples
        alone rarely meet such a lobe."""
        mats = [m for m in (self.objects[k].get("material"), self.objects[k].get("back_material")) if m is not None]
        return any(m.glass is not None or m.alpha < 0.1 for m in mats)

    # -- BSDF (spec/renderer.md#materials) -------------------------------------------------------------

    @staticmethod
    def _microfacet_terms(n, wo, wi, alpha, beckmann):
        """(h, n.h, D(h), height-correlated G2) of the GGX lobe, Beckmann's on rows where ``beckmann`` [m] bool (its
        Lambda in Walter et al.'s rational form, spec/renderer.md#materials)."""
        h = normalized(wo + wi)
        nh = np.clip(dot(n, h), 0.0, 1.0)
        co, ci = np.clip(np.abs(dot(n, wo)), 1e-12, 1.0), np.clip(np.abs(dot(n, wi)), 1e-12, 1.0)
        a2 = alpha * alpha
        den = nh * nh * (a2 - 1.0) + 1.0
        dd = a2 / (np.pi * den * den)

        def lam(c):
            return (np.sqrt(c * c + a2 * (1.0 - c * c)) / c - 1.0) * 0.5

        lo, li = lam(co), lam(ci)
        if np.any(beckmann):
            c2 = np.maximum(nh * nh, 1e-150)  # c2^2 stays a normal number
            tan2 = np.maximum(1.0 - c2, 0.0) / c2
            dd = np.where(beckmann, np.exp(-tan2 / a2) / (np.pi * a2 * c2 * c2), dd)

            def lam_beckmann(c):
                a = c / (alpha * np.sqrt(np.maximum(1.0 - c * c, 1e-300)))
                return np.where(a < 1.6, (1.0 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a), 0.0)

            lo, li = np.where(beckmann, lam_beckmann(co), lo), np.where(beckmann, lam_beckmann(ci), li)
        return h, nh, dd, 1.0 / (1.0 + lo + li)

    def glass_eval(self, mat, n, wo, wi):
        """Glass lobe (spec/renderer.md#transmission) -> f * |cos_i| [m, 3] and its pdf: reflection above n, below it
        refraction (solid) or the reflection mirrored through the tangent plane (thin); h sampled by D(h) (n.h)."""
        eta, thin, alpha = mat["eta"], mat["thin"], mat["alpha"]
        co, ci = dot(n, wo), dot(n, wi)
        up = ci > 0
        a2 = alpha * alpha

        def d_of(nh):
            den = nh * nh * (a2 - 1.0) + 1.0
            return np.where(nh > 0, a2 / (np.pi * den * den), 0.0)

        def lam(c):
            c = np.clip(np.abs(c), 1e-12, 1.0)
            return (np.sqrt(c * c + a2 * (1.0 - c * c)) / c - 1.0) * 0.5

        g2 = 1.0 / (1.0 + lam(co) + lam(ci))
        mirrored = wi - 2.0 * ci[:, None] * n
        hr = normalized(wo + np.where(up[:, None], wi, mirrored))
        nh, oh = dot(n, hr), dot(wo, hr)
        f = fresnel(oh, eta)
        r = np.where(thin, 2.0 * f / (1.0 + f), f)
        w = np.where(up, r, 1.0 - r)
        dr = d_of(nh)
        val_r = w * dr * g2 / (4.0 * np.maximum(co, 1e-12))
        pdf_r = w * dr * nh / (4.0 * np.maximum(np.abs(oh), 1e-12))
        ok_r = (up | thin) & (oh > 0) & (co > 0)
        ht = -(wo + eta[:, None] * wi)
        ht = normalized(np.where((dot(n, ht) < 0)[:, None], -ht, ht))
        o_h, i_h, n_h = dot(wo, ht), dot(wi, ht), dot(n, ht)
        den = np.maximum((o_h + eta * i_h) ** 2, 1e-300)
        t = 1.0 - fresnel(o_h, eta)
        dt = d_of(n_h)
        val_t = t * dt * g2 * np.abs(o_h) * np.abs(i_h) / (np.maximum(co, 1e-12) * den)
        pdf_t = t * dt * n_h * eta * eta * np.abs(i_h) / den
        ok_t = ~up & ~thin & (o_h > 0) & (i_h < 0) & (co > 0)
        val = np.where(ok_r, val_r, np.where(ok_t, val_t, 0.0))[:, None] * np.where(up[:, None], mat["reflect"], mat["tint"])
        return val, np.where(ok_r, pdf_r, np.where(ok_t, pdf_t, 0.0))

    def bsdf_eval(self, mat, n, wo, wi):
        """-> f * cos_i [m, 3] and pdf of bsdf_sample (solid angle); with glass rows (``mat["t"]`` > 0) the mixture
        (1 - t) opaque + t glass."""
        val, pdf = self._opaque_eval(mat, n, wo, wi)
        if "t" not in mat:
            return val, pdf
        gv, gp = self.glass_eval(mat, n, wo, wi)
        t = mat["t"]
        return (1.0 - t)[:, None] * val + t[:, None] * gv, (1.0 - t) * pdf + t * gp

    def _opaque_eval(self, mat, n, wo, wi):
        co, ci = dot(n, wo), dot(n, wi)
        ok = (co > 0) & (ci > 0)
        val = mat["kd"] / np.pi * ci[:, None]
        pdf = (1.0 - mat["ps"]) * np.maximum(ci, 0.0) / np.pi
        if np.any(mat["spec"]):
            h, nh, dd, g2 = self._microfacet_terms(n, wo, wi, mat["alpha"], mat["beckmann"])
            oh = np.clip(dot(wo, h), 0.0, 1.0)
            f = mat["f0"] + (1.0 - mat["f0"]) * ((1.0 - oh) ** 5)[:, None]
            spec = (dd * g2 / (4.0 * np.maximum(co, 1e-12)))[:, None] * f
            val = val + np.where(mat["spec"][:, None], spec, 0.0)
            pdf = pdf + mat["ps"] * dd * nh / (4.0 * np.maximum(np.abs(dot(wo, h)), 1e-12))
        return np.where(ok[:, None], val, 0.0), np.where(ok, pdf, 0.0)

    def bsdf_sample(self, mat, n, wo, u, us):
        t = normalized(np.cross(np.where(np.abs(n[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]]), n))
        b = np.cross(n, t)
        # cosine lobe
        r = np.sqrt(u[:, 0])
        ph = 2.0 * np.pi * u[:, 1]
        z = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0]))
        wd = (r * np.cos(ph))[:, None] * t + (r * np.sin(ph))[:, None] * b + z[:, None] * n
        # D(h)(n.h) lobes: GGX (the glass lobe's always), Beckmann's where the material says
        a2 = mat["alpha"] ** 2

        def half_vector(tan2):
            ct = 1.0 / np.sqrt(1.0 + tan2)
            st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
            return (st * np.cos(ph))[:, None] * t + (st * np.sin(ph))[:, None] * b + ct[:, None] * n

        h = half_vector(a2 * u[:, 0] / np.maximum(1.0 - u[:, 0], 1e-12))
        h_spec = h
        if np.any(mat["beckmann"]):
            h_beck = half_vector(-a2 * np.log(np.maximum(1.0 - u[:, 0], 1e-16)))
            h_spec = np.where(mat["beckmann"][:, None], h_beck, h)
        ws = 2.0 * dot(wo, h_spec)[:, None] * h_spec - wo
        valid = np.ones(len(wo), bool)
        glass = np.zeros(len(wo), bool)
        if "t" in mat:  # us < t: the glass lobe (us / t: reflect or pass), else the opaque lobes with us rescaled
            t = mat["t"]
            glass = us < t
            us = np.where(glass, us / np.maximum(t, 1e-300), (us - t) / np.maximum(1.0 - t, 1e-300))
        pick_spec = us < mat["ps"]
        wi = np.where(pick_spec[:, None], ws, wd)
        if glass.any():
            eta, oh = mat["eta"], dot(wo, h)
            f = fresnel(oh, eta)
            keep = us < np.where(mat["thin"], 2.0 * f / (1.0 + f), f)
            cos_t = np.sqrt(np.maximum(1.0 - (1.0 - oh * oh) / (eta * eta), 0.0))
            refracted = (oh / eta - cos_t)[:, None] * h - wo / eta[:, None]
            wr = 2.0 * oh[:, None] * h - wo  # reflected by the glass lobe's (GGX) h
            mirrored = wr - 2.0 * dot(wr, n)[:, None] * n
            passed = np.where(mat["thin"][:, None], mirrored, refracted)
            wg = np.where(keep[:, None], wr, passed)
            wi = np.where(glass[:, None], wg, wi)
            # a reflection below, a transmission above, or an opaque sample below a glass: no sample
            valid = np.where(glass, (oh > 0) & np.where(keep | mat["thin"], dot(wr, n) > 0, dot(wg, n) < 0),
                             dot(wi, n) > 0)
        fc, pdf = self.bsdf_eval(mat, n, wo, normalized(wi))
        return normalized(wi), np.where(valid[:, None], fc, 0.0), np.where(valid, pdf, 0.0)

    def _backs(self, obj, prim, wo):
        """[n] bool: mesh hits seen from their back (spec/renderer.md#sidedness: the front normal faces away from wo)."""
        back = np.zeros(len(obj), bool)
        for k in np.unique(obj):
            ob = self.objects[k] if k >= 0 else {}
            if ob.get("kind") == Kind.MESH and (ob.get("one_sided") or ob.get("back_material") is not None):
                sel = obj == k
                back[sel] = dot(ob["face_normals"][prim[sel]] * ob["front_sign"], wo[sel]) < 0
        return back

    def _side_material(self, k, back_rows):
        """The material of object k's hits: its back material on back rows where it has one."""
        ob = self.objects[k]
        return ob["back_material"] if back_rows and ob.get("back_material") is not None else ob["material"]

    def _materials(self, obj, back, outside=None):
        """Per-row material arrays of hits on objects ``obj`` (``back``: seen from the back, for back materials); with
        a transmitting material also the glass rows' t, tint, reflect, thin and eta (the IOR seen from ``outside``,
        the prim's front; else its inverse; spec/renderer.md#transmission)."""
        m = len(obj)
        kd, f0, alpha, ps, spec = np.zeros((m, 3)), np.zeros((m, 3)), np.ones(m), np.zeros(m), np.zeros(m, bool)
        beckmann = np.zeros(m, bool)
        t, tint, reflect, ior, thin = np.zeros(m), np.ones((m, 3)), np.ones((m, 3)), np.ones(m), np.zeros(m, bool)
        any_glass = False
        for k in np.unique(obj):
            for side in (False, True):
                sel = (obj == k) & (back == side)
                if not np.any(sel):
                    continue
                mt = self._side_material(k, side)
                kd[sel], f0[sel], alpha[sel], spec[sel], beckmann[sel] = mt.kd, mt.f0, mt.alpha, mt.specular, mt.beckmann
                if mt.specular:
                    a, b = float(np.max(mt.f0)), float(np.max(mt.kd))
                    ps[sel] = 1.0 if b <= 0 else float(np.clip(a / max(a + b, 1e-12), 0.1, 0.9))
                if mt.glass is not None:
                    any_glass = True
                    gw, gt, gi, gthin, gr = mt.glass
                    t[sel], tint[sel], reflect[sel], ior[sel] = gw, gt, gr, gi
                    thin[sel] = gthin
        out = {"kd": kd, "f0": f0, "alpha": alpha, "ps": ps, "spec": spec, "beckmann": beckmann}
        if any_glass:
            front = np.ones(m, bool) if outside is None else outside
            out.update(t=t, tint=tint, reflect=reflect, thin=thin, eta=np.where(front | thin, ior, 1.0 / ior))
        return out

    # -- main loop ------------------------------------------------------------------------------------

    def render(self, width, height, spp, seed, batch=1 << 17, pixel_filter=("box", 0.5)):
        """[H, W, 3] radiance; ``pixel_filter`` (kind, stddev in pixels) of spec/renderer.md#render-settings: each camera
        sample's position is drawn from the filter (weight 1)."""
        rng = np.random.default_rng(seed)
        npix = width * height
        total = npix * spp
        acc = np.zeros((npix, 3))
        for s in range(0, total, batch):
            e = min(total, s + batch)
            ids = np.arange(s, e)
            pix = ids % npix
            px = (pix % width) + _filter_offsets(rng, len(ids), *pixel_filter)
            py = (pix // width) + _filter_offsets(rng, len(ids), *pixel_filter)
            lens = rng.random((len(ids), 2)) if self.camera.lens_radius > 0 else None
            o, d = self.camera_rays(px, py, width, height, lens)
            contrib = self.radiance(o, d, rng)
            np.add.at(acc, pix, contrib)
        return (acc * (self.camera.exposure / spp)).reshape(height, width, 3)

    def camera_rays(self, px, py, width, height, lens=None):
        """Origins and unit directions [n,3] (spec/renderer.md#cameras): the film position on the image window
        (tenths of a scene unit), a pinhole, a thin lens (``lens`` [n,2] in [0,1)^2, concentric disk map) or
        parallel rays (orthographic)."""
        cam = self.camera
        u = (2.0 * px / width - 1.0) * (0.5 * cam.h_aperture) + cam.h_offset
        v = (1.0 - 2.0 * py / height) * (0.5 * cam.h_aperture * height / width) + cam.v_offset
        m3, eye = cam.to_world[:3, :3], cam.to_world[3, :3]
        if cam.orthographic:
            local = np.stack([0.1 * u, 0.1 * v, np.zeros_like(u)], 1)
            return local @ m3 + eye, normalized(np.tile(-m3[2], (len(u), 1)))
        target = np.stack([u / cam.focal, v / cam.focal, -np.ones_like(u)], 1)  # the image plane at distance 1
        if lens is None:
            return np.tile(eye, (len(u), 1)), normalized(target @ m3)
        a, b = 2.0 * lens[:, 0] - 1.0, 2.0 * lens[:, 1] - 1.0  # Shirley-Chiu concentric map onto the disk
        wide = np.abs(a) > np.abs(b)
        r = np.where(wide, a, b)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.where(wide, 0.25 * np.pi * b / a, 0.5 * np.pi - 0.25 * np.pi * a / b)
        phi = np.where(r == 0, 0.0, phi)
        start = np.stack([cam.lens_radius * r * np.cos(phi), cam.lens_radius * r * np.sin(phi), np.zeros_like(u)], 1)
        return start @ m3 + eye, normalized((target * cam.focus_distance - start) @ m3)

    def radiance(self, o, d, rng):
        m = len(o)
        L = np.zeros((m, 3))
        idx = np.arange(m)
        beta = np.ones((m, 3))
        depth = np.zeros(m, np.int64)
        prev_pdf = np.zeros(m)  # 0: camera ray (or weight-1 emission)
        prev_p = o.copy()
        ignore = np.full(m, -1, np.int64)
        while len(idx):
            camera = depth == 0  # camera rays: every ray of the first pass, none after
            tr = self._trace_past_lights(L, idx, o, d, ignore, camera.all(), prev_pdf, prev_p, beta)
            p = o + d * np.where(np.isfinite(tr["t"]), tr["t"], 0.0)[:, None]
            p = self._surface_points(tr["obj"], tr["prim"], tr["b1"], tr["b2"], p)
            # escaped: infinite lights
            miss = ~tr["hit"]
            if np.any(miss):
                dm = d[miss]
                le = np.zeros((int(miss.sum()), 3))
                for lt in self.lights:
                    if getattr(lt, "infinite", False):
                        w = mis_weight(prev_pdf[miss], lt.pdf_dir(dm))
                        if not getattr(lt.desc, "camera_visible", True):  # a dome hidden from camera rays: they see black
                            w = np.where(camera[miss], 0.0, w)
                        le += lt.eval_dir(dm) * w[:, None]
                np.add.at(L, idx[miss], beta[miss] * le)
            obj = tr["obj"]
            kinds = np.array([o_["kind"] for o_ in self.objects] + [-1])[obj]
            # plain meshes: emission
            hm = kinds == Kind.MESH
            if np.any(hm):
                em = np.zeros((len(idx), 3))
                back = self._backs(np.where(hm, obj, -1), tr["prim"], -d)
                for k in np.unique(obj[hm]):
                    ob = self.objects[k]
                    em[(obj == k) & ~back] = ob["material"].emission
                    # a back side emits its back material's emission; a one-sided mesh's back nothing, back material or not
                    if not ob.get("one_sided"):
                        em[(obj == k) & back] = self._side_material(k, True).emission
                np.add.at(L, idx[hm], beta[hm] * em[hm])
            # compact to surface vertices; a ray from the last vertex (depth max_depth) gathers emission only
            surf = (hm | (kinds == Kind.ASSET)) & (depth < self.max_depth)
            sel = np.nonzero(surf)[0]
            if len(sel) == 0:
                break
            idx, o, d, beta, depth, obj = idx[sel], o[sel], d[sel], beta[sel], depth[sel] + 1, obj[sel]
            p, prim, b1, b2 = p[sel], tr["prim"][sel], tr["b1"][sel], tr["b2"][sel]
            ng = self._geo(obj, prim)
            wo = -d
            cont = self._continues(obj, depth)
            is_asset = np.array([o_["kind"] == Kind.ASSET for o_ in self.objects])[obj]
            new_d = np.zeros_like(d)
            new_pdf = np.zeros(len(idx))
            alive = np.zeros(len(idx), bool)
            # plain surfaces
            pm = np.nonzero(~is_asset)[0]
            if len(pm):
                nb, dn, pdfn, al = self._shade_mesh(L, idx[pm], p[pm], ng[pm], wo[pm], obj[pm], prim[pm], b1[pm], b2[pm], beta[pm], cont[pm], rng)
                beta[pm], new_d[pm], new_pdf[pm], alive[pm] = nb, dn, pdfn, al
            new_o = np.full_like(p, np.nan)  # NaN rows: the default offset origin below
            akind = np.array([o_["asset"].kind if o_["kind"] == Kind.ASSET else "" for o_ in self.objects] + [""])[obj]
            for kd in np.unique(akind[is_asset]):
                am = np.nonzero(is_asset & (akind == kd))[0]
                nb, dn, pdfn, al, no = self.shaders[kd].vertex(L, idx[am], p[am], ng[am], wo[am], obj[am], prim[am], b1[am], b2[am], beta[am],
                                                               cont[am], depth[am], rng)
                beta[am], new_d[am], new_pdf[am], alive[am] = nb, dn, pdfn, al
                if no is not None:
                    new_o[am] = no
            # Russian roulette
            rr = alive & (depth >= self.rr_depth)
            if np.any(rr):
                q = np.clip(np.max(beta, axis=1), 0.05, 1.0)
                surv = rng.random(len(idx)) < q
                alive &= ~rr | surv
                beta = np.where((rr & surv)[:, None], beta / q[:, None], beta)
            alive &= np.any(beta > 0, axis=1)
            k = np.nonzero(alive)[0]
            side = np.sign(dot(new_d[k], ng[k]))[:, None]
            origin = p[k] + ng[k] * side * ray_eps(p[k])[:, None]
            origin = np.where(np.isnan(new_o[k]), origin, new_o[k])
            idx, beta, depth = idx[k], beta[k], depth[k]
            prev_p = np.where(np.isnan(new_o[k]), p[k], new_o[k])  # light pdfs of MIS are taken from the ray origin
            o, d, prev_pdf = origin, new_d[k], new_pdf[k]
            ignore = np.where(is_asset[k], obj[k], -1)
        return L

    def _trace_past_lights(self, L, idx, o, d, ignore, camera: bool, prev_pdf, prev_p, beta, max_lights: int = 64):
        """:meth:`Tracer.trace` of rays among light surfaces (spec/renderer.md#light-surfaces): each light surface a ray
        meets on its emitting side adds its emission (MIS-weighted) to ``L`` and the ray goes on past it (they occlude
        nothing; met from behind they are passed by the tracer; ``camera`` rays pass the ones hidden from the camera
        without adding them), but for an opaque one (``nasset:opaqueSurface``), where it ends. Returns the trace of the
        rays' first hit that is not a light surface they pass, ``t`` from ``o``."""
        hidden = self.hidden_shapes if camera else None
        tr = self.tracer.trace(o, d, ignore=ignore, transparent=hidden, back_through=self.light_shapes)
        start = np.zeros(len(o))  # distance from o of each row's current trace origin
        rows = np.arange(len(o))
        for _ in range(max_lights):
            rows = rows[self.light_shapes[tr["obj"][rows]]]
            if not len(rows):
                break
            at = start[rows] + tr["t"][rows]  # the light surface, from o
            hl = np.zeros(len(o), bool)
            hl[rows] = True
            t_hit = np.where(hl, start + tr["t"], 0.0)
            near = o + d * t_hit[:, None]
            before = o + d * np.maximum(t_hit - 10.0 * ray_eps(near), 0.0)[:, None]  # re-intersected for its emission
            self._shape_light_hits(L, idx, hl, tr["obj"], before, d, prev_pdf, prev_p, beta)
            go_on = self.clear_lights[tr["obj"][rows]]  # an opaque light surface ends the ray: its hit stays
            rows, at = rows[go_on], at[go_on]
            if not len(rows):
                break
            beyond = o[rows] + d[rows] * at[:, None]
            beyond = beyond + d[rows] * (10.0 * ray_eps(beyond))[:, None]
            more = self.tracer.trace(beyond, d[rows], ignore=ignore[rows], transparent=hidden, back_through=self.light_shapes)
            start[rows] = np.einsum("ij,ij->i", beyond - o[rows], d[rows])
            for key in ("hit", "obj", "prim", "b1", "b2"):
                tr[key][rows] = more[key]
            tr["t"][rows] = np.where(more["hit"], start[rows] + more["t"], np.inf)
            tr["passed"][rows] |= more["passed"]
        return tr

    def _shape_light_hits(self, L, idx, hl, obj, o, d, prev_pdf, prev_p, beta):
        mi = self.mi
        for k in np.unique(obj[hl]):
            sel = np.nonzero(hl & (obj == k))[0]
            lt = self.light_of_obj[k]
            ray = mi.Ray3f(p3(mi, o[sel]), v3(mi, d[sel]))
            si = self.scene.ray_intersect(ray)
            le = np.asarray(lt.emitter.eval(si).numpy(), np.float64)
            le = le.T if le.ndim == 2 else np.broadcast_to(le, (len(sel), 3))
            if lt.has_profile:  # its emission toward the ray's origin (spec/renderer.md#lights, #spot-lights)
                n = np.asarray(si.n.numpy(), np.float64)
                le = le * lt.profile(-d[sel], n.T if n.ndim == 2 else np.broadcast_to(n, (len(sel), 3)))[:, None]
            w = np.ones(len(sel))
            cam = prev_pdf[sel] == 0
            if np.any(~cam):
                it = mi.Interaction3f()
                it.p = p3(mi, prev_p[sel])
                it.t = mi.Float(np.zeros(len(sel), np.float32))
                ds = mi.DirectionSample3f(self.scene, si, it)
                pl = np.broadcast_to(np.asarray(lt.emitter.pdf_direction(it, ds).numpy(), np.float64), (len(sel),))
                w = np.where(cam, 1.0, mis_weight(prev_pdf[sel], pl))
            np.add.at(L, idx[sel], beta[sel] * le * w[:, None])

    def _nee(self, p, ng, n_for_light, rng, ignore, at=None):
        """Yield (wi, le/pdf, pdf_light, delta, visible, passed) per light (one sample of every light).

        ``at`` [m, 3]: where each row's incident light is fetched (spec/kinds/rna.md#near-field-fetch; None: at p):
        the light is sampled there (:meth:`light_rays`)."""
        m = len(p)
        fetch = p if at is None else at
        moved = np.zeros(m, bool) if at is None else np.any(at != p, axis=1)
        for lt in self.lights:
            u = rng.random((m, 2))
            wi, dist, le, pdf = lt.sample(self.mi, fetch, n_for_light, u)
            wi = normalized(wi)
            valid = (pdf > 0) & np.any(le > 0, axis=1)
            side = np.sign(dot(wi, ng))[:, None]
            side[side == 0] = 1.0
            offset = ng * side * ray_eps(p)[:, None]
            maxt = np.where(np.isfinite(dist), dist * (1.0 - 1e-3), np.inf)
            vis = np.zeros(m, bool)
            passed = np.zeros(m, bool)
            v = np.nonzero(valid)[0]
            if len(v):
                vis[v], passed[v] = self.light_rays(p[v] + offset[v], fetch[v] + offset[v], moved[v], wi[v], maxt[v],
                                                    None if ignore is None else ignore[v])
            yield wi, le / np.maximum(pdf, 1e-300)[:, None] * valid[:, None], pdf, lt.delta, vis & valid, passed

    def light_rays(self, o, at, moved, wi, maxt, obj, exempt=None):
        """(visible [n], passed [n]) of light-sample rays wi from hits ``o`` [n, 3] (ray origins) whose light is
        fetched at ``at`` (spec/kinds/rna.md#near-field-fetch; ``moved``: rows where ``at`` differs from ``o``).

        Blocking by other objects is a ray from ``at``, object ``obj[i]`` (None: no asset) passed through; ``passed``
        (the asset lies on the ray) is, where visible and moved, the branch from ``o`` (:meth:`own_branch`)."""
        tr = self.shadow_tracer.trace(at, wi, maxt, obj, transparent=self.light_shapes, exempt=exempt)
        vis, passed = ~tr["hit"], tr["passed"]
        b = np.nonzero(vis & moved)[0]
        if len(b):
            passed[b] = self.own_branch(o[b], wi[b], maxt[b], obj[b], None if exempt is None else exempt[b])
        return vis, passed

    def continuation_rays(self, o, moved, wc, obj, exempt=None):
        """[n] bool passed: whether continuations wc from hits ``o`` [n, 3] (ray origins) on asset ``obj[i]`` meet
        it; where the light is fetched elsewhere (``moved``) only the asset's own triangles count (:meth:`own_branch`;
        the radiance ray leaves the fetch point, spec/kinds/rna.md#near-field-fetch)."""
        passed = np.zeros(len(o), bool)
        here, away = np.nonzero(~moved)[0], np.nonzero(moved)[0]
        if len(here):
            passed[here] = self.tracer.trace(o[here], wc[here], None, obj[here], transparent=self.clear_lights,
                                             back_through=self.light_shapes,
                                             exempt=None if exempt is None else exempt[here])["passed"]
        if len(away):
            passed[away] = self.own_branch(o[away], wc[away], np.full(len(away), np.inf), obj[away],
                                           None if exempt is None else exempt[away])
        return passed

    def own_branch(self, o, d, maxt, obj, exempt=None):
        """[n] bool: whether the rays meet a triangle of object ``obj[i]`` (outside ``exempt[i]``) before ``maxt``, every
        other surface passed through: the branch from x of a hit whose light is fetched elsewhere
        (spec/kinds/rna.md#near-field-fetch: only the asset's own triangles count on that ray)."""
        return self.shadow_tracer.trace(o, d, maxt, obj, transparent=self.every_shape, exempt=exempt,
                                        until_passed=True)["passed"]

    def fetch_points(self, p, obj):
        """(fetch points [m, 3], rows where they differ from p) of rna and neupress hits p on instances ``obj``:
        p + f (c_w - p), c_w the instance's encoding box centre in world space (spec/kinds/rna.md#near-field-fetch)."""
        at = p.copy()
        for k in np.unique(obj):
            inst = self.objects[k]
            f = inst["asset"].fetch
            if f > 0:
                sel = obj == k
                c_w = inst["asset"].centre @ inst["to_world"][:3, :3] + inst["to_world"][3, :3]
                at[sel] = p[sel] + f * (c_w - p[sel])
        return at, np.any(at != p, axis=1)

    def _shade_mesh(self, L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, rng):
        flip = dot(ng, wo) < 0
        ngf = np.where(flip[:, None], -ng, ng)
        ns = np.zeros_like(ng)
        for k in np.unique(obj):
            sel = obj == k
            cn = self.objects[k]["corner_normals"][prim[sel]]
            ns[sel] = (1.0 - b1[sel] - b2[sel])[:, None] * cn[:, 0] + b1[sel][:, None] * cn[:, 1] + b2[sel][:, None] * cn[:, 2]
        front = np.array([float(o_.get("front_sign", 1.0)) for o_ in self.objects] + [1.0])[obj]
        ns = normalized(np.where((flip != (front < 0))[:, None], -ns, ns))  # flipped with the front side's ng
        n = np.where((dot(ns, wo) <= 1e-6)[:, None], ngf, ns)
        back = self._backs(obj, prim, wo)
        mat = self._materials(obj, back, outside=dot(ng * front[:, None], wo) > 0)
        # glass rows take light from below the surface too, where both normals agree
        through = mat["t"] > 0 if "t" in mat else np.zeros(len(p), bool)
        one_sided = np.array([bool(o_.get("one_sided")) for o_ in self.objects] + [False])[obj]
        beta = np.where((one_sided & back)[:, None], 0.0, beta)  # the back of a one-sided mesh: the path ends
        for wi, lw, pl, delta, vis, _ in self._nee(p, ng, n, rng, None):
            fc, pb = self.bsdf_eval(mat, n, wo, wi)
            above = (dot(wi, ngf) > 0) | (through & (dot(wi, ngf) < 0) & (dot(wi, n) < 0))
            fc = fc * above[:, None]
            w = np.ones(len(p)) if delta else np.where(cont, power(pl, pb), 1.0)
            c = beta * fc * lw * (w * vis)[:, None]
            np.add.at(L, idx, c)
        wi, fc, pdf = self.bsdf_sample(mat, n, wo, rng.random((len(p), 2)), rng.random(len(p)))
        ok = cont & (pdf > 0) & ((dot(wi, ngf) > 0) | (through & (dot(wi, ngf) < 0) & (dot(wi, n) < 0)))
        nb = np.where(ok[:, None], beta * fc / np.maximum(pdf, 1e-300)[:, None], 0.0)
        return nb, wi, pdf, ok


class RnaShader:
    """The rna vertex (spec/renderer.md#neural-assets; fibers: #fibers): T and the branch at x, the incident light at
    the fetch point (spec/kinds/rna.md#near-field-fetch; the hit itself for f = 0)."""

    def __init__(self, pt: PathTracer) -> None:
        self.pt = pt

    @staticmethod
    def open(path: str, threads: int = 0):
        from .rna import RnaAsset

        return RnaAsset(path, threads=threads)

    def vertex(self, L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, depth, rng):
        """Shade asset vertices; -> (new beta, new direction, its pdf (see :func:`mis_weight`), alive, new origins or None)."""
        fib = np.array([o_["kind"] == Kind.ASSET and o_["asset"].fiber for o_ in self.pt.objects] + [False])[obj]
        if np.all(fib):
            return self._fiber_vertex(L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, depth, rng)
        if np.any(fib):  # both variants: shade each part, then merge
            out = [np.zeros_like(beta), np.zeros_like(wo), np.zeros(len(p)), np.zeros(len(p), bool), np.full_like(p, np.nan)]
            for part, fn in ((fib, self._fiber_vertex), (~fib, self.vertex)):
                r = np.nonzero(part)[0]
                res = fn(L, idx[r], p[r], ng[r], wo[r], obj[r], prim[r], b1[r], b2[r], beta[r], cont[r], depth[r], rng)
                for j in range(4):
                    out[j][r] = res[j]
                if res[4] is not None:
                    out[4][r] = res[4]
            return tuple(out)
        m = len(p)
        at, moved = self.pt.fetch_points(p, obj)
        entries = []  # (wi, weight [m, 3], valid mask, shadowed branch)
        for wi, lw, pl, delta, vis, passed in self.pt._nee(p, ng, ng, rng, obj, at):
            w = np.ones(m) if delta else np.where(cont, power(pl, INV_FOUR_PI), 1.0)
            entries.append((wi, lw * w[:, None], vis, passed))
        # continuation: uniform sphere
        u = rng.random((m, 2))
        z = 1.0 - 2.0 * u[:, 0]
        s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        ph = 2.0 * np.pi * u[:, 1]
        wc = np.stack([s * np.cos(ph), s * np.sin(ph), z], 1)
        cidx = np.nonzero(cont)[0]
        cpassed = np.zeros(m, bool)
        new_o = np.full_like(p, np.nan)  # NaN: the integrator's origin, x offset to wc's side
        if len(cidx):
            side = np.sign(dot(wc[cidx], ng[cidx]))[:, None]
            offset = ng[cidx] * side * ray_eps(p[cidx])[:, None]
            mc = moved[cidx]
            cpassed[cidx] = self.pt.continuation_rays(p[cidx] + offset, mc, wc[cidx], obj[cidx])
            new_o[cidx[mc]] = at[cidx[mc]] + offset[mc]  # the radiance: a ray from the fetch point
        entries.append((wc, np.full((m, 3), FOUR_PI), cont, cpassed))
        T = self._transport(entries, p, wo, obj, prim, b1, b2)
        for (_, lw, vis, _), t in zip(entries[:-1], T[:-1], strict=True):
            np.add.at(L, idx, beta * t * lw * vis[:, None])
        nb = np.where(cont[:, None], beta * T[-1] * FOUR_PI, 0.0)
        return nb, wc, np.full(m, INV_FOUR_PI), cont, new_o if moved.any() else None

    def _transport(self, entries, p, wo, obj, prim, b1, b2):
        """Evaluate T for every entry where its mask is set, grouped by asset file."""
        m = len(p)
        out = [np.zeros((m, 3)) for _ in entries]
        for k in np.unique(obj):
            sel = np.nonzero(obj == k)[0]
            inst = self.pt.objects[k]
            asset, minv = inst["asset"], inst["m3_inv"]
            x = (p[sel] - inst["to_world"][3, :3]) @ minv
            n = asset.shading_normal(prim[sel], b1[sel], b2[sel])
            wo_o = normalized(wo[sel] @ minv)
            rows, where = [], []
            for j, (wi, _, mask, passed) in enumerate(entries):
                ms = sel[mask[sel]]
                if len(ms) == 0:
                    continue
                loc = np.searchsorted(sel, ms)
                rows.append((x[loc], n[loc], wo_o[loc], normalized(wi[ms] @ minv), passed[ms]))
                where.append((j, ms))
            if not rows:
                continue
            cat = [np.concatenate([r[c] for r in rows]) for c in range(5)]
            t = asset.transport(*cat)
            s = 0
            for j, ms in where:
                out[j][ms] = t[s:s + len(ms)]
                s += len(ms)
        return out

    def _fiber_vertex(self, L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, _depth, rng):
        """Fiber hits: tangent and h inputs, rays from x itself, own segment and neighbours exempt."""
        pt = self.pt
        m = len(p)
        t_o, h, wo_o, exempt = np.zeros((m, 3)), np.zeros(m), np.zeros((m, 3)), np.zeros((m, 2), np.int64)
        for k in np.unique(obj):
            sel = obj == k
            inst = pt.objects[k]
            minv = inst["m3_inv"]
            x = (p[sel] - inst["to_world"][3, :3]) @ minv
            wo_o[sel] = normalized(wo[sel] @ minv)
            t_o[sel], h[sel], exempt[sel] = inst["asset"].fiber_frame(prim[sel], x, wo_o[sel])
        at, moved = self.pt.fetch_points(p, obj)  # rays from the fetch point, like those from x, without offset
        rows = []  # (wi, weight [m, 3], valid, shadowed branch)
        for lt in pt.lights:
            u = rng.random((m, 2))
            wi, dist, le, pdf = lt.sample(pt.mi, at, ng, u)
            wi = normalized(wi)
            valid = (pdf > 0) & np.any(le > 0, axis=1)
            maxt = np.where(np.isfinite(dist), dist * (1.0 - 1e-3), np.inf)
            vis, passed = np.zeros(m, bool), np.zeros(m, bool)
            v = np.nonzero(valid)[0]
            if len(v):
                vis[v], passed[v] = pt.light_rays(p[v], at[v], moved[v], wi[v], maxt[v], obj[v], exempt[v])
            w = np.ones(m) if lt.delta else np.where(cont, power(pdf, INV_FOUR_PI), 1.0)
            rows.append((wi, le / np.maximum(pdf, 1e-300)[:, None] * (valid * w)[:, None], vis & valid, passed))
        u = rng.random((m, 2))
        z = 1.0 - 2.0 * u[:, 0]
        sz = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        ph = 2.0 * np.pi * u[:, 1]
        wc = np.stack([sz * np.cos(ph), sz * np.sin(ph), z], 1)
        cpassed = np.zeros(m, bool)
        cidx = np.nonzero(cont)[0]
        if len(cidx):
            cpassed[cidx] = pt.continuation_rays(p[cidx], moved[cidx], wc[cidx], obj[cidx], exempt[cidx])
        rows.append((wc, np.full((m, 3), FOUR_PI), cont, cpassed))
        T = [np.zeros((m, 3)) for _ in rows]
        for k in np.unique(obj):
            sel = np.nonzero(obj == k)[0]
            inst = pt.objects[k]
            x = (p[sel] - inst["to_world"][3, :3]) @ inst["m3_inv"]
            cat = [sel[r[2][sel]] for r in rows]
            allm = np.concatenate(cat)
            if not len(allm):
                continue
            loc = np.concatenate([np.searchsorted(sel, ms) for ms in cat])
            wis = np.concatenate([normalized(r[0][ms] @ inst["m3_inv"]) for r, ms in zip(rows, cat, strict=True)])
            sh = np.concatenate([r[3][ms] for r, ms in zip(rows, cat, strict=True)])
            val = inst["asset"].transport(x[loc], t_o[allm], wo_o[allm], wis, sh, h=h[allm])
            s0 = 0
            for j, ms in enumerate(cat):
                T[j][ms] = val[s0:s0 + len(ms)]
                s0 += len(ms)
        for (_, lw, vis, _), t in zip(rows[:-1], T[:-1], strict=True):
            np.add.at(L, idx, beta * t * lw * vis[:, None])
        nb = np.where(cont[:, None], beta * T[-1] * FOUR_PI, 0.0)
        return nb, wc, np.full(m, INV_FOUR_PI), cont, at


#: kind -> shader class of the asset vertex. A shader class has ``open(path, threads)`` (static: the
#: asset object, with ``kind``, object-space ``points``/``faces`` and ``face_normals``) and, built with
#: the PathTracer, ``vertex(L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, depth, rng)`` returning
#: (new beta, new direction, its pdf for :func:`mis_weight`, alive, new origins or None). Kind modules
#: register with :func:`register_shader`.
ASSET_SHADERS: dict[str, type] = {"rna": RnaShader}


def register_shader(kind: str, cls: type) -> None:
    ASSET_SHADERS[kind] = cls
