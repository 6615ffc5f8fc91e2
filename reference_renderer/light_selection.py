"""Which lights a shading vertex samples (spec/renderer.md#light-selection).

Every light that can reach geometry is sampled once per vertex while the scene has at most ``draws`` of them of
its kind (delta lights; lights with a surface or a solid angle). ``draws`` is ``RenderSettings.light_draws``
(default ``DRAWS``). A kind with more lights is sampled by ``draws`` stratified draws per vertex, light k with
probability ``P_k(x)`` at the vertex x: a share ``UNIFORM_SHARE`` uniform, the rest in proportion to a bound of the
irradiance the light can give at x (its importance). A draw of light k is a sample of k with density ``n_k p_k`` (``n_k = draws P_k(x)``,
the expected number of draws of k), which is both what its estimate divides by and what multiple importance
sampling counts for it, at light samples and where a BSDF or continuation sample from x meets the light. A vertex
then costs ``draws`` light samples and shadow rays per kind, however many lights the scene holds; choosing costs
O(lights) arithmetic per vertex (a light tree would make it O(log lights)).
"""

from __future__ import annotations

import numpy as np

from .lights import DistantLight, DomeLight, Light, MeshLight, PointLight, RectLight, SphereLight, _SurfaceLight
from .sampling import luminance

#: light samples per vertex and kind when that kind has more lights than this (the default of
#: ``RenderSettings.light_draws``)
DRAWS = 8
#: the largest ``light_draws`` a render accepts
MAX_DRAWS = 1024
#: share of the selection probability spread uniformly: every light keeps at least this share of 1 / count
UNIFORM_SHARE = 0.1
#: vertices x lights evaluated at once (bounds the memory of the importance matrix)
CHUNK = 1 << 21
#: the largest u below 1 (a remapped uniform must stay in [0, 1))
_ONE_BELOW = np.nextafter(1.0, 0.0)


def importance_terms(light: Light) -> tuple[np.ndarray | None, float, float]:
    """(centre [3] or None for lights at infinity, a, b): the light's importance at a point x is ``a / max(|x -
    centre|^2, b)``, or ``a`` at infinity, a bound of the irradiance it gives there (luminance): a point light or
    spot (as a point light: it aims at the scene) I / d^2, a sphere pi L r^2 / d^2, a light surface or emissive mesh
    L A / d^2 (both sides of a mesh), each capped where x is within the light's size, a sun E and a dome pi times its
    mean radiance. a is finite and >= 0; b > 0."""
    if isinstance(light, PointLight):
        c, a, b = light.c, luminance(light.I), 0.0
    elif isinstance(light, SphereLight):
        c, a, b = light.c, np.pi * light.r * light.r * luminance(light.L), light.r * light.r
    elif isinstance(light, _SurfaceLight):
        c, a, b = light.c, light.A * luminance(light.L), light.A
    elif isinstance(light, MeshLight):
        c, a, b = light.centroid, light.area_total * (luminance(light.L) + luminance(light.L_back)), light.area_total
    elif isinstance(light, DistantLight):
        c, a, b = None, luminance(light.E), 1.0
    elif isinstance(light, DomeLight):
        c, a, b = None, np.pi * luminance(light.mean_radiance), 1.0
    else:
        c, a, b = None, 0.0, 1.0
    a = float(a)
    a = a if np.isfinite(a) and a > 0.0 else 0.0
    b = float(b)
    b = b if np.isfinite(b) and b > 1e-30 else 1e-30
    if c is not None and not np.isfinite(c).all():
        c, a = None, 0.0
    return (None if c is None else np.asarray(c, np.float64)), a, b


def emission_cone(light: Light) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(apex [3], unit axis [3], cos theta) of the cone outside which ``light`` sends no light, or None: a spot (apex
    its position, theta its cone angle), a SphereLight with a spot cone below 90 degrees or a RectLight or DiskLight
    with a spread below pi (theta half the spread). A light surface's apex is moved back along the axis until the cone
    holds the light's bounding sphere (radius rho): rho / sin(theta) behind its centre for a spot cone, rho / tan(theta)
    for a planar light (its plane's disk of radius rho lies on the cone); every ray the light emits leaves a point
    inside the cone within theta of the axis, so it stays inside (spec/renderer.md#light-selection)."""
    if isinstance(light, PointLight) and light.axis is not None:
        return np.asarray(light.c, np.float64), light.axis, float(np.cos(np.radians(min(light.cone_deg, 180.0))))
    if isinstance(light, SphereLight) and light.axis is not None and light.cone_deg < 90.0:
        theta = np.radians(max(light.cone_deg, 1e-6))
        return light.c - light.axis * light.r / np.sin(theta), light.axis, float(np.cos(theta))
    if isinstance(light, RectLight) and light.spread < np.pi:  # DiskLight too
        h = 0.5 * light.spread
        centre, rho = light.bounding_sphere()
        return np.asarray(centre, np.float64) - light.n * rho / np.tan(h), light.n, float(np.cos(h))
    return None


def _below(cdf: np.ndarray, j: np.ndarray) -> np.ndarray:
    """[r, d] the cdf [r, m] just below column j [r, d] of each row (0 below the first)."""
    return np.where(j > 0, np.take_along_axis(cdf, np.maximum(j - 1, 0), 1), 0.0)


class _Kind:
    """Lights of one kind that are drawn: indices [m] into the scene's lights and their importance terms."""

    def __init__(self, lights: list, kind: np.ndarray) -> None:
        self.kind = kind
        self.delta = bool(lights[kind[0]].delta)
        terms = [importance_terms(lights[k]) for k in kind]
        self.finite = np.array([c is not None for c, _, _ in terms])
        self.centre = np.array([np.zeros(3) if c is None else c for c, _, _ in terms])
        self.a = np.array([a for _, a, _ in terms])
        self.b = np.array([b for _, _, b in terms])
        self.slot = {int(k): i for i, k in enumerate(kind)}  # scene index -> column
        self.origin = self.centre[self.finite].mean(0) if self.finite.any() else np.zeros(3)
        self.c = self.centre - self.origin
        self.c2 = np.einsum("mk,mk->m", self.c, self.c)
        cones = [emission_cone(lights[k]) for k in kind]
        self.coned = np.array([i for i, cone in enumerate(cones) if cone is not None], np.int64)  # columns with a cone
        self.apex = np.array([cones[i][0] for i in self.coned]).reshape(-1, 3)
        self.axis = np.array([cones[i][1] for i in self.coned]).reshape(-1, 3)
        self.cos_cone = np.array([cones[i][2] for i in self.coned])

    def probabilities(self, p: np.ndarray) -> np.ndarray:
        """[n, m] probability of each light of the kind at points ``p`` [n,3]: UNIFORM_SHARE uniform, the rest by
        importance (uniform where every importance is 0 or not finite). Rows sum to 1."""
        m = len(self.kind)
        # squared distances by |x|^2 + |c|^2 - 2 x.c about the lights' mean centre (a matrix product, not an [n, m, 3]
        # array; the importance only steers the choice, and the cap b keeps it bounded where the sum cancels). A row's
        # value does not depend on the other rows: the draw and the MIS weight at a point read the same P.
        x = p - self.origin
        d2 = np.einsum("nk,nk->n", x, x)[:, None] + self.c2[None] - 2.0 * (x @ self.c.T)
        imp = np.where(self.finite, self.a / np.maximum(d2, self.b), self.a)
        if len(self.coned):  # 0 outside a light's emission cone (emission_cone)
            v = [p[:, k:k + 1] - self.apex[:, k] for k in range(3)]  # [n, c] each: from each apex to x
            along = v[0] * self.axis[:, 0] + v[1] * self.axis[:, 1] + v[2] * self.axis[:, 2]
            imp[:, self.coned] *= along >= self.cos_cone * np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        total = imp.sum(1, keepdims=True)
        ok = np.isfinite(total) & (total > 0)
        share = np.where(ok, imp / np.where(ok, total, 1.0), 1.0 / m)
        return UNIFORM_SHARE / m + (1.0 - UNIFORM_SHARE) * share


class LightSelection:
    """The light samples of the integrator's vertices.

    ``lights``: the scene's lights; ``nee``: indices of those sampled at vertices (the plan's); ``draws``: draws per
    vertex of a kind with more lights than that (0: every light is sampled)."""

    def __init__(self, lights: list, nee: list[int], draws: int = DRAWS) -> None:
        self.lights = lights
        self.nee = list(nee)
        self.draws = int(draws)
        self.kinds: list[_Kind] = []
        for delta in (True, False):
            kind = np.array([k for k in self.nee if lights[k].delta == delta], np.int64)
            if self.draws and len(kind) > self.draws:
                self.kinds.append(_Kind(lights, kind))
        self._kind_of = {k: kind for kind in self.kinds for k in kind.slot}
        self._sampled = set(self.nee)

    @property
    def any_drawn(self) -> bool:
        return bool(self.kinds)

    def describe(self) -> str:
        """One line for ``nasset render --explain``: how the vertices' light samples are chosen."""
        if not self.kinds:
            return f"light selection: every light sampled at every vertex ({len(self.nee)} with shadow rays)"
        parts = [f"{len(k.kind)} {'delta lights' if k.delta else 'lights with a surface or solid angle'}: "
                 f"{self.draws} stratified draws per vertex by importance" for k in self.kinds]
        rest = len(self.nee) - sum(len(k.kind) for k in self.kinds)
        if rest:
            parts.append(f"{rest} others: each sampled at every vertex")
        return "light selection (spec/renderer.md#light-selection): " + "; ".join(parts)

    def count(self, k: int, p: np.ndarray) -> np.ndarray:
        """[n] expected number of samples of light ``k`` per vertex at points ``p`` [n,3]: 1 where every light of
        its kind is sampled, ``draws P_k(p)`` where its kind is drawn, 0 for a light not sampled at vertices."""
        return self.counts([(k, np.arange(len(p)))], p)[0]

    def counts(self, pairs: list, p: np.ndarray) -> list[np.ndarray]:
        """:meth:`count` of several lights at once: ``pairs`` of (light k, rows [r] of ``p`` [n,3]); the probabilities
        of each drawn kind are computed once for the rows any of its lights needs."""
        out = [None] * len(pairs)
        need: dict[int, list] = {}
        for i, (k, rows) in enumerate(pairs):
            kind = self._kind_of.get(k)
            if kind is None:
                out[i] = np.full(len(rows), 1.0 if k in self._sampled else 0.0)
            else:
                need.setdefault(id(kind), []).append(i)
        for kind in self.kinds:
            todo = need.get(id(kind))
            if not todo:
                continue
            union = np.unique(np.concatenate([pairs[i][1] for i in todo]))
            prob = np.empty((len(union), len(kind.kind)))
            step = max(1, CHUNK // len(kind.kind))
            for s in range(0, len(union), step):
                prob[s:s + step] = kind.probabilities(p[union[s:s + step]])
            for i in todo:
                k, rows = pairs[i]
                out[i] = self.draws * prob[np.searchsorted(union, rows), kind.slot[k]]
        return out

    def samples(self, p: np.ndarray, rng: np.random.Generator, *, delta_only: bool = False):
        """Yields the light samples of the vertices at points ``p`` [n,3], one sample per vertex each time:
        (delta: bool, wi [n,3], dist [n], Li [n,3], pdf [n]), the pdf that of the light technique (solid angle,
        times the drawn light's ``count``; 1 times it for delta lights). ``delta_only``: only delta lights.

        Without drawn kinds this is every light of ``nee`` in turn, ``rng`` used as ``light.sample(p, rng.random((n,
        2)))`` each (the order of draws the integrator always had)."""
        n = len(p)
        for k in self.nee:
            if k in self._kind_of:
                continue
            light = self.lights[k]
            if delta_only and not light.delta:
                continue
            yield (light.delta, *light.sample(p, rng.random((n, 2))))
        for kind in self.kinds:
            if delta_only and not kind.delta:
                continue
            yield from self._drawn(kind, p, rng)

    def _drawn(self, kind: _Kind, p: np.ndarray, rng: np.random.Generator):
        """``draws`` samples of a drawn kind at points ``p``, stratified: a vertex's draw t picks the light whose slice
        of the vertex's cdf holds ``(t + v) / draws`` (one uniform v per vertex: a light of probability P is drawn
        floor(draws P) or ceil(draws P) times, draws P on average), and that number, rescaled
        to [0, 1) inside the slice, is the first coordinate of the light's own sample; each light chosen samples all
        its (vertex, draw) pairs in one call."""
        n, d, m = len(p), self.draws, len(kind.kind)
        u = rng.random((n, d, 2))
        u[:, :, 0] = np.minimum((np.arange(d)[None, :] + rng.random((n, 1))) / d, _ONE_BELOW)
        col = np.empty((n, d), np.int64)
        prob = np.empty((n, d))
        step = max(1, CHUNK // m)
        for s in range(0, n, step):
            rows = slice(s, min(n, s + step))
            prob_rows = kind.probabilities(p[rows])
            cdf = np.cumsum(prob_rows, 1)
            cdf[:, -1] = 1.0
            r, ur = cdf.shape[0], u[rows, :, 0]
            # one sorted search over the rows' cdfs laid end to end (row i shifted by i), then one step to undo the
            # shift's rounding: u lies in [lo, hi) of its own row's light j
            flat = (cdf + np.arange(r)[:, None]).ravel()
            j = np.searchsorted(flat, (ur + np.arange(r)[:, None]).ravel(), side="right").reshape(r, d)
            j = np.clip(j - np.arange(r)[:, None] * m, 0, m - 1)
            j = np.clip(j - (ur < _below(cdf, j)) + (ur >= np.take_along_axis(cdf, j, 1)), 0, m - 1)
            lo, hi = _below(cdf, j), np.take_along_axis(cdf, j, 1)
            u[rows, :, 0] = np.clip((ur - lo) / np.maximum(hi - lo, 1e-300), 0.0, _ONE_BELOW)
            col[rows], prob[rows] = j, np.take_along_axis(prob_rows, j, 1)
        # (draw, vertex) pairs in draw-major order
        col, prob, u = col.T.ravel(), prob.T.ravel(), u.transpose(1, 0, 2).reshape(-1, 2)
        pts = np.tile(p, (d, 1))
        wi, dist, li, pdf = np.zeros((d * n, 3)), np.zeros(d * n), np.zeros((d * n, 3)), np.zeros(d * n)
        order = np.argsort(col, kind="stable")
        ends = np.cumsum(np.bincount(col, minlength=m))
        start = 0
        for i, end in enumerate(ends):
            if end > start:
                rows = order[start:end]
                wi[rows], dist[rows], li[rows], pk = self.lights[int(kind.kind[i])].sample(pts[rows], u[rows])
                pdf[rows] = pk * d * prob[rows]
            start = end
        for t in range(d):
            r = slice(t * n, (t + 1) * n)
            yield kind.delta, wi[r], dist[r], li[r], pdf[r]
