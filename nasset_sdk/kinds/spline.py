"""Monotone rational-quadratic splines and the 8DNA bounding-box flow (spec/kinds/8dna.md#spline).

A spline maps [0, 1] onto [0, 1] through K bins (Durkan et al. 2019, "Neural Spline Flows").
Its parameters for one channel are a row of 3K+1 unnormalised numbers ``[w~ (K), h~ (K), d~ (K+1)]``:

    widths  w_k = m_w + (1 - K m_w) softmax(w~)_k      knots x_0 = 0, x_k = sum_{l<k} w_l, x_K = 1
    heights h_k = m_h + (1 - K m_h) softmax(h~)_k      knots y_0 = 0, ..., y_K = 1
    derivatives d_k = m_d + softplus(d~_k),  k = 0..K

Forward (latent z -> value y) in bin k, xi = (z - x_k) / w_k, s_k = h_k / w_k:

    y = y_k + h_k (s_k xi^2 + d_k xi (1 - xi)) / (s_k + (d_{k+1} + d_k - 2 s_k) xi (1 - xi))
    dy/dz = s_k^2 (d_{k+1} xi^2 + 2 s_k xi (1 - xi) + d_k (1 - xi)^2) / (s_k + (d_{k+1} + d_k - 2 s_k) xi (1 - xi))^2

Inverse: with dy = y - y_k, delta = d_{k+1} + d_k - 2 s_k, a = h_k (s_k - d_k) + dy delta,
b = h_k d_k - dy delta, c = -s_k dy: xi = 2c / (-b - sqrt(max(b^2 - 4ac, 0))) (the root in [0, 1],
written in the form without cancellation), z = x_k + xi w_k.

All math is float64 and vectorised over a batch: parameters [N, 3K+1], points [N].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arrays import real_array
from ..errors import UsageError

#: Durkan et al.'s defaults; the 8DNA asset stores its own values in core/splineMinimums.
MIN_BIN_WIDTH = 1e-3
MIN_BIN_HEIGHT = 1e-3
MIN_DERIVATIVE = 1e-3
_TINY = 1e-300
#: the float types a spline may compute in (float64: the spec)
SPLINE_DTYPES = (np.float64, np.float32)


def finite64(a) -> np.ndarray:
    """float64 copy of a with NaN -> 0, +-inf -> +-1e30: ``np.nan_to_num``'s result, one pass when all are finite."""
    a = np.array(a, np.float64)
    if np.isfinite(a).all():
        return a
    return np.nan_to_num(a, copy=False, nan=0.0, posinf=1e30, neginf=-1e30)


def clamp01(a) -> np.ndarray:
    """float64 copy of a [N] clamped to [0, 1], NaN -> 0: ``np.clip(np.nan_to_num(a, nan=0.0), 0, 1)`` in two passes."""
    a = np.array(a, np.float64).reshape(-1)
    np.fmax(a, 0.0, out=a)  # fmax / fmin return the number where one side is NaN
    np.fmin(a, 1.0, out=a)
    return a


def _softplus(a: np.ndarray) -> np.ndarray:
    """log(1 + e^a) for finite a, without overflow."""
    return np.maximum(a, 0.0) + np.log1p(np.exp(-np.abs(a)))


class RQSpline:
    """A batch of monotone rational-quadratic splines on [0, 1] (one per row).

    xk [N, K+1] input knots (xk[:, 0] = 0, xk[:, K] = 1), yk [N, K+1] output knots, dk [N, K+1]
    derivatives at the knots (> 0). :meth:`from_raw` keeps the derivatives unnormalised (``d_raw``,
    ``d_min``) and applies softplus only to the two knots of each evaluated bin.

    Stored bin-major (knot k of all rows contiguous, ``[K+1, N]``): every step over the bins (softmax,
    prefix sums, bin search) is then one pass over contiguous rows of N values, not a reduction over
    N short rows; ``xk``, ``yk``, ``dk`` are transposed views."""

    def __init__(self, xk: np.ndarray, yk: np.ndarray, dk: np.ndarray | None = None, *, d_raw: np.ndarray | None = None,
                 d_min: float = MIN_DERIVATIVE) -> None:
        if (dk is None) == (d_raw is None):
            raise UsageError("give the knot derivatives dk or their unnormalised values d_raw, not both")
        bins = lambda a: None if a is None else np.ascontiguousarray(np.asarray(a, np.float64).T)  # noqa: E731
        self._init_bins(bins(xk), bins(yk), bins(dk), bins(d_raw), d_min)

    def _init_bins(self, xb, yb, db, d_raw_b, d_min) -> None:
        """xb, yb, db or d_raw_b: bin-major [K+1, N] (contiguous, all of one float dtype)."""
        self._xb, self._yb, self._db, self._draw_b, self.d_min = xb, yb, db, d_raw_b, float(d_min)

    @classmethod
    def _from_bins(cls, xb, yb, *, d_raw_b, d_min) -> "RQSpline":
        spl = cls.__new__(cls)
        spl._init_bins(xb, yb, None, d_raw_b, d_min)
        return spl

    @property
    def xk(self) -> np.ndarray:
        """[N, K+1] input knots."""
        return self._xb.T

    @property
    def yk(self) -> np.ndarray:
        """[N, K+1] output knots."""
        return self._yb.T

    @property
    def d_raw(self) -> np.ndarray | None:
        """[N, K+1] unnormalised derivatives (None if the spline was given its derivatives)."""
        return None if self._draw_b is None else self._draw_b.T

    @property
    def dk(self) -> np.ndarray:
        """[N, K+1] derivatives at the knots."""
        if self._db is None:
            self._db = self.d_min + _softplus(self._draw_b)
        return self._db.T

    @classmethod
    def from_raw(cls, raw: np.ndarray, *, min_bin_width: float = MIN_BIN_WIDTH, min_bin_height: float = MIN_BIN_HEIGHT,
                 min_derivative: float = MIN_DERIVATIVE, dtype=np.float64) -> "RQSpline":
        """Splines from unnormalised parameters raw [N, 3K+1] = [w~ (K), h~ (K), d~ (K+1)].

        ``dtype`` float64 is the spec's arithmetic; float32 (:data:`SPLINE_DTYPES`) is for renderers, which
        must match images within noise, not evaluator vectors bit for bit."""
        if dtype not in SPLINE_DTYPES:
            raise UsageError(f"spline dtype must be one of {[d.__name__ for d in SPLINE_DTYPES]}, got {dtype!r}")
        raw = np.asarray(raw)
        if raw.ndim < 2:
            raw = raw.reshape(1, -1)
        p = raw.shape[1]
        if (p - 1) % 3 or p < 4:
            raise UsageError(f"spline parameters need 3K+1 columns (K >= 1), got {p}")
        k = (p - 1) // 3
        if not (0 <= min_bin_width * k < 1 and 0 <= min_bin_height * k < 1 and min_derivative > 0):
            raise UsageError(f"spline minimums ({min_bin_width}, {min_bin_height}, {min_derivative}) invalid for K={k}")
        rb = np.array(raw.T, dtype=dtype, order="C")  # [3K+1, N], always a copy (worked on in place); float32 -> float64 is exact
        if not np.isfinite(rb).all():
            np.nan_to_num(rb, copy=False, nan=0.0, posinf=1e30, neginf=-1e30)
        n = rb.shape[1]
        # widths and heights together: e [2, K, N]; the softmax over the bins, then the knots
        e = rb[:2 * k].reshape(2, k, n)
        e -= e.max(axis=1, keepdims=True)
        np.exp(e, out=e)
        m = np.array([min_bin_width, min_bin_height], dtype)[:, None, None]
        e *= (1 - m * k) / e.sum(axis=1, keepdims=True)  # >= 1: the largest term is exp(0)
        e += m
        knots = np.empty((2, k + 1, n), dtype)  # x and y knots, each bin-major [K+1, N]
        knots[:, 0] = 0.0
        for b in range(k - 1):  # running sums from the left, one bin at a time (np.cumsum over an outer axis is ~7x slower)
            np.add(knots[:, b], e[:, b], out=knots[:, b + 1])
        knots[:, k] = 1.0
        return cls._from_bins(knots[0], knots[1], d_raw_b=rb[2 * k:], d_min=min_derivative)

    @classmethod
    def from_raw_rgb(cls, raw: np.ndarray, **minimums) -> "RQSpline":
        """Splines of all three channels of raw [N, 3 (3K+1)] (channel-major columns): row 3 n + c is
        channel c of row n."""
        raw = np.asarray(raw)
        return cls.from_raw(raw.reshape(3 * len(raw), raw.shape[1] // 3), **minimums)

    @property
    def bins(self) -> int:
        return self._xb.shape[0] - 1

    @staticmethod
    def _bin(knots: np.ndarray, v: np.ndarray) -> np.ndarray:
        # comparison-sum search over interior knots: k = #{x_l <= v, l = 1..K-1}, one knot row at a time
        k = np.zeros(len(v), np.int64)
        for col in range(1, knots.shape[0] - 1):
            k += v >= knots[col]
        return k

    def _gather(self, k: np.ndarray, rows: np.ndarray | None = None):
        """Bin k's (x_k, y_k, w_k, h_k, d_k, d_{k+1}) of each row (of rows [M] of the batch if given)."""
        n = self._xb.shape[1]
        i = k * n + (np.arange(len(k)) if rows is None else rows)  # flat indices of (k, row) in the [K+1, N] arrays
        xk, yk = self._xb.reshape(-1), self._yb.reshape(-1)
        f64 = lambda a: a.astype(np.float64, copy=False)  # noqa: E731 (the bin's arithmetic is float64 whatever the knots)
        x0, y0 = f64(xk[i]), f64(yk[i])
        i1 = i + n
        w = f64(xk[i1]) - x0
        h = f64(yk[i1]) - y0
        if self._db is None:
            dr = self._draw_b.reshape(-1)
            d0, d1 = self.d_min + _softplus(f64(dr[i])), self.d_min + _softplus(f64(dr[i1]))
        else:
            dk = self._db.reshape(-1)
            d0, d1 = f64(dk[i]), f64(dk[i1])
        return x0, y0, np.maximum(w, _TINY), np.maximum(h, _TINY), d0, d1

    def forward(self, z: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """y = rqs(z) and log|dy/dz| for z [N] (clamped to [0, 1], NaN -> 0); with ``rows`` [M], z [M]
        goes through the splines of those rows."""
        z = clamp01(z)
        k = self._bin(self._xb if rows is None else self._xb[:, rows], z)
        x0, y0, w, h, d0, d1 = self._gather(k, rows)
        s = h / w
        xi = np.clip((z - x0) / w, 0.0, 1.0)
        t = xi * (1 - xi)
        den = s + (d1 + d0 - 2 * s) * t  # >= min(s, (d0 + d1) / 2) > 0 for xi in [0, 1]
        den = np.maximum(den, _TINY)
        y = y0 + h * (s * xi * xi + d0 * t) / den
        deriv = s * s * (d1 * xi * xi + 2 * s * t + d0 * (1 - xi) ** 2) / (den * den)
        return np.clip(y, 0.0, 1.0), np.log(np.maximum(deriv, _TINY))

    def inverse(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z = rqs^-1(y) and log|dz/dy| for y [N] (clamped to [0, 1], NaN -> 0)."""
        y = clamp01(y)
        k = self._bin(self._yb, y)
        x0, y0, w, h, d0, d1 = self._gather(k)
        s = h / w
        dy = y - y0
        delta = d1 + d0 - 2 * s
        a = h * (s - d0) + dy * delta
        b = h * d0 - dy * delta
        c = -s * dy
        disc = np.maximum(b * b - 4 * a * c, 0.0)
        den = -b - np.sqrt(disc)  # <= 0; == 0 only where c == 0 (xi = 0)
        safe = den < -_TINY
        xi = np.clip(np.where(safe, 2 * c / np.where(safe, den, -1.0), 0.0), 0.0, 1.0)
        z = np.clip(x0 + xi * w, 0.0, 1.0)
        t = xi * (1 - xi)
        dd = np.maximum(s + delta * t, _TINY)
        deriv = s * s * (d1 * xi * xi + 2 * s * t + d0 * (1 - xi) ** 2) / (dd * dd)
        return z, -np.log(np.maximum(deriv, _TINY))


# ----------------------------------------------------------------------------------------
# 8DNA bounding-box cylindrical parameterisation (paper Eq. 9-10; spec/kinds/8dna.md#bbox)

#: cap of the flow densities: exp(700) times the box Jacobian of a tiny box would overflow to inf
PDF_MAX = 1e300

#: |ds / dt| for t in [0, 1]^4 -> s = (2 t1 - 1, 2 pi t2 - pi, 2 t3 - 1, 2 pi t4 - pi)
S_PER_T = 2.0 * 2.0 * np.pi * 2.0 * 2.0 * np.pi


def cylindrical_to_direction(z: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """(z, phi) -> unit direction (sqrt(1 - z^2) cos phi, sqrt(1 - z^2) sin phi, z), z clamped to [-1, 1]."""
    z, phi = np.asarray(z, np.float64), np.asarray(phi, np.float64)
    if not np.isfinite(z).all():  # one pass where all are finite (the common case)
        z = np.nan_to_num(z)
    z = np.clip(z, -1.0, 1.0)
    if not np.isfinite(phi).all():
        phi = np.nan_to_num(phi)
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def direction_to_cylindrical(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit-normalised d [N,3] (zero -> +Z) -> (z in [-1, 1], phi = atan2(d_y, d_x) in [-pi, pi])."""
    from .encodings import atan2_columns, unit64

    d = unit64(d)
    return np.clip(d[:, 2], -1.0, 1.0), atan2_columns(d, 1, 0)


class BoxParam:
    """The bounding box (centre c, half extents e > 0) and the map s <-> (u, w) of the 8DNA paper."""

    def __init__(self, lo, hi) -> None:
        lo = np.asarray(lo, np.float64).reshape(3)
        hi = np.asarray(hi, np.float64).reshape(3)
        if not (np.isfinite(lo).all() and np.isfinite(hi).all() and (hi > lo).all()):
            raise UsageError(f"box {lo} .. {hi} must be finite with hi > lo")
        self.center = 0.5 * (lo + hi)
        self.half = 0.5 * (hi - lo)

    def project(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray from the centre along unit d [N,3] -> (u [N,3] box point relative to the centre,
        tau [N] = |u|, face axis [N]). tau = min_k e_k / |d_k| (ties to the lower axis)."""
        ad = np.abs(d)
        ratio = np.where(ad > 1e-300, self.half / np.maximum(ad, 1e-300), np.inf)
        axis = np.argmin(ratio, axis=1)
        tau = np.take_along_axis(ratio, axis[:, None], 1)[:, 0]
        return d * tau[:, None], tau, axis

    def face_normal(self, u: np.ndarray) -> np.ndarray:
        """Outward unit normal [N,3] of the face holding box points u [N,3] (object space): the face the ray
        from the centre through u leaves by (:meth:`project`)."""
        rel = np.asarray(u, np.float64) - self.center
        _, _, axis = self.project(rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-300))
        n = np.zeros((len(rel), 3))
        rows = np.arange(len(rel))
        n[rows, axis] = np.where(rel[rows, axis] < 0, -1.0, 1.0)
        return n

    def jacobian(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_object [N,3], |n_u . u| / |u|^3 [N]): solid angle of the direction of u per unit box area."""
        u, tau, axis = self.project(d)
        e_face = self.half[axis]
        return u + self.center, e_face / np.maximum(tau, 1e-300) ** 3

    def s_from_t(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, np.float64)
        return np.stack([2 * t[:, 0] - 1, 2 * np.pi * t[:, 1] - np.pi, 2 * t[:, 2] - 1, 2 * np.pi * t[:, 3] - np.pi], axis=1)

    @staticmethod
    def s_from_t_dim(j: int, t: np.ndarray) -> np.ndarray:
        """Dimension j (1..4) of :meth:`s_from_t` for t_j [N]."""
        return 2 * t - 1 if j in (1, 3) else 2 * np.pi * t - np.pi

    def t_from_s(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, np.float64)
        t = np.stack([(s[:, 0] + 1) / 2, (s[:, 1] + np.pi) / (2 * np.pi),
                      (s[:, 2] + 1) / 2, (s[:, 3] + np.pi) / (2 * np.pi)], axis=1)
        return np.clip(t, 0.0, 1.0)

    def to_rays(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """s [N,4] -> (u_i [N,3] object space on the box, w_i [N,3] unit, jacobian |n_u . u| / |u|^3 [N])."""
        d = cylindrical_to_direction(s[:, 0], s[:, 1])
        u, jac = self.jacobian(d)
        w = cylindrical_to_direction(s[:, 2], s[:, 3])
        return u, w, jac

    def from_rays(self, u: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_i, w_i) -> (s [N,4], jacobian [N]); u_i is taken as the box point in direction u_i - c."""
        from .encodings import unit64

        d = unit64(np.asarray(u, np.float64) - self.center)
        z1, p1 = direction_to_cylindrical(d)
        z3, p3 = direction_to_cylindrical(w)
        _, jac = self.jacobian(d)
        return np.stack([z1, p1, z3, p3], axis=1), jac


def surface_pdf(pdf_box: np.ndarray, n_x: np.ndarray, n_u: np.ndarray, w: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """Eq. 9: density per unit area at the asset surface x_i: pdf_box |n_x . w| / max(|n_u . w|, eps)."""
    from .encodings import unit64

    w = unit64(w)
    num = np.abs((unit64(n_x) * w).sum(1))
    den = np.maximum(np.abs((unit64(n_u) * w).sum(1)), eps)
    return np.asarray(pdf_box, np.float64) * num / den


# ----------------------------------------------------------------------------------------
# autoregressive flow over t in [0, 1]^4 (spec/kinds/8dna.md#flow)


def _channels(channel, n: int) -> np.ndarray:
    c = np.asarray(channel)
    if c.ndim == 0:
        c = np.full(n, int(c))
    c = c.reshape(-1)
    if len(c) != n or not np.issubdtype(c.dtype, np.integer) or (c < 0).any() or (c > 2).any():
        raise UsageError("channel must be 0, 1 or 2 (an int or an int array [N])")
    return c.astype(np.int64)


def take_rows(ctx, rows):
    """Rows of a flow context: its ``take(rows)``, each member of a tuple, or the array's rows."""
    if hasattr(ctx, "take") and not isinstance(ctx, np.ndarray):
        return ctx.take(rows)
    if isinstance(ctx, tuple):
        return tuple(np.asarray(a)[rows] for a in ctx)
    return np.asarray(ctx)[rows]


@dataclass
class FlowSample:
    """One flow sample per row (:meth:`BoxFlow.sample_state`) and what densities at its u_i reuse:
    conditioners 1-3 do not depend on w_i, so p^k(u_i, w_i) for any new w_i needs only conditioner 4.
    The per-channel position densities p^k(u_i) are built on demand, only for the rows asked for
    (:meth:`log_position_rgb`), and kept."""

    ui: np.ndarray  # [N, 3] object-space point on the box
    wi: np.ndarray  # [N, 3] unit direction
    pdf: np.ndarray  # [N] density of the sampled channel, per box area and steradian
    ctx: object  # the flow context of the rows
    s: np.ndarray  # [N, 4] box parameters of the sample
    jac: np.ndarray  # [N] |n_u . u| / |u|^3
    raw12: tuple[np.ndarray, np.ndarray]  # [N, 3 (3K+1)] conditioner-1 and -2 outputs (all channels)
    t12: np.ndarray  # [N, 2] the sample's t1, t2
    raw3: np.ndarray  # [N, 3 (3K+1)] conditioner-3 output: it depends on s1, s2 only
    flow: "BoxFlow"
    dir_rows: np.ndarray | None = None  # [D] sorted rows whose steps 3-4 ran (w_i drawn); None: all rows
    raw4: np.ndarray | None = None  # [D, 3 (3K+1)] conditioner-4 output of those rows at their own w_i
    ch: np.ndarray | None = None  # [N] the sampled channel of each row
    log_steps: np.ndarray | None = None  # [N, 4] log density of each step's t_j in the sampled channel (0: not drawn)
    _log_pos: np.ndarray | None = None  # [N, 3] log densities of (t1, t2) per channel, NaN where not built yet

    def direction_index(self, rows) -> np.ndarray:
        """Positions in ``raw4`` of rows [M] (each must have had its w_i drawn)."""
        rows = np.asarray(rows, np.int64).reshape(-1)
        if self.dir_rows is None:
            return rows
        pos = np.searchsorted(self.dir_rows, rows)
        if len(rows) and (pos.max() >= len(self.dir_rows) or (self.dir_rows[pos] != rows).any()):
            raise UsageError("rows must be rows of the flow sample whose direction w_i was drawn")
        return pos

    def log_position_rgb(self, rows=None) -> np.ndarray:
        """[M, 3] per channel: log density of (t1, t2) (steps 1-2) of rows [M] (default all), built for the
        rows not asked for before."""
        n = len(self.s)
        rows = np.arange(n) if rows is None else np.asarray(rows, np.int64).reshape(-1)
        if self._log_pos is None:
            self._log_pos = np.full((n, 3), np.nan)
        todo = np.unique(rows[np.isnan(self._log_pos[rows, 0])])
        if len(todo):
            if self.ch is None:
                lp = np.zeros((len(todo), 3))
                for raw, t in zip(self.raw12, self.t12.T, strict=True):
                    lp += self.flow._log_inverse_rgb(self.flow._splines_rgb(raw[todo]), t[todo])
            else:  # the sampled channel's from its own steps; splines for the other two only
                ch = self.ch[todo]
                other = sum(self.flow._log_inverse_others(raw[todo], ch, t[todo]) for raw, t in zip(self.raw12, self.t12.T, strict=True))
                lp = _by_channel(self.log_steps[todo, 0] + self.log_steps[todo, 1], other, ch)
            self._log_pos[todo] = lp
        return self._log_pos[rows]

    def pdf_position_rgb(self, rows=None) -> np.ndarray:
        """[M, 3]: marginal density of u_i per unit box area, per channel (:meth:`BoxFlow.pdf_position`), of rows
        [M] (default all)."""
        jac = self.jac if rows is None else self.jac[np.asarray(rows, np.int64).reshape(-1)]
        return np.minimum(np.exp(np.minimum(self.log_position_rgb(rows), 700.0)) / (2.0 * 2.0 * np.pi) * jac[:, None], PDF_MAX)


def _others(ch: np.ndarray) -> np.ndarray:
    """[M, 2]: the channels other than ch [M], in the order (ch + 1) % 3, (ch + 2) % 3."""
    return (ch[:, None] + np.array([1, 2])) % 3


def _by_channel(own: np.ndarray, other: np.ndarray, ch: np.ndarray) -> np.ndarray:
    """[M, 3]: channel ch [M] from own [M], the other two (:func:`_others`) from other [M, 2]."""
    out = np.empty((len(ch), 3))
    i = np.arange(len(ch))
    out[i, ch] = own
    out[i[:, None], _others(ch)] = other
    return out


class BoxFlow:
    """p(u_i, w_i | x_o, w_o) per colour channel: an autoregressive spline flow over t in [0, 1]^4.

    ``conditioner(j, ctx, s_prev)`` (j = 1..4, s_prev [N, j-1] the already fixed s^1..s^{j-1}, ctx =
    ``context(x, wo)`` computed once per call, default the tuple (x, wo)) returns unnormalised spline
    parameters [N, 3 (3K+1)], channel-major (channel c owns columns c (3K+1) .. (c+1)(3K+1) - 1).
    The density w.r.t. box area
    at u_i times solid angle at w_i is

        pdf(u_i, w_i) = prod_j exp(log|d rqs_j^-1 / dt_j|) / S_PER_T * |n_u . u| / |u|^3.

    ``spline_dtype``: float type of the spline knots (:meth:`RQSpline.from_raw`); float64 is the spec's
    arithmetic, float32 a renderer's option (spec/kinds/8dna.md#evaluation-cost).
    """

    def __init__(self, box: BoxParam, conditioner, *, context=None, min_bin_width=MIN_BIN_WIDTH,
                 min_bin_height=MIN_BIN_HEIGHT, min_derivative=MIN_DERIVATIVE, spline_dtype=np.float64) -> None:
        self.box = box
        self.conditioner = conditioner
        self.context = context if context is not None else (lambda x, wo: (x, wo))
        self.minimums = dict(min_bin_width=float(min_bin_width), min_bin_height=float(min_bin_height),
                             min_derivative=float(min_derivative), dtype=spline_dtype)

    def _raw(self, j: int, ctx, s_prev, n: int) -> np.ndarray:
        raw = np.asarray(self.conditioner(j, ctx, s_prev))  # float64 in the spline (RQSpline.from_raw)
        if raw.ndim != 2 or raw.shape[1] % 3 or len(raw) != n:
            raise UsageError(f"conditioner {j} returned shape {raw.shape}; expected [N, 3 (3K+1)]")
        return raw

    def _channel_spline(self, raw: np.ndarray, ch: np.ndarray, rows: np.ndarray | None = None) -> RQSpline:
        """Splines of channel ch [M] of raw's rows [M] (default all rows, M = N): one gather."""
        p = raw.shape[1] // 3
        return RQSpline.from_raw(raw.reshape(len(raw), 3, p)[np.arange(len(raw)) if rows is None else rows, ch], **self.minimums)

    def _spline(self, j: int, ctx, s_prev, ch: np.ndarray) -> RQSpline:
        return self._channel_spline(self._raw(j, ctx, s_prev, len(ch)), ch)

    def _splines_rgb(self, raw: np.ndarray) -> RQSpline:
        return RQSpline.from_raw_rgb(raw, **self.minimums)

    def _log_inverse_others(self, raw: np.ndarray, ch: np.ndarray, t: np.ndarray) -> np.ndarray:
        """[M, 2]: log|d rqs^-1 / dt| at t [M] of the splines of raw [M, 3 (3K+1)] in the two channels other than ch
        [M] (:func:`_others`)."""
        m, p = len(raw), raw.shape[1] // 3
        rows = (3 * np.arange(m)[:, None] + _others(ch)).reshape(-1)  # rows of raw as [3M, 3K+1]
        spl = RQSpline.from_raw(raw.reshape(3 * m, p).take(rows, axis=0), **self.minimums)
        return spl.inverse(np.repeat(t, 2))[1].reshape(m, 2)

    @staticmethod
    def _log_inverse_rgb(spl: RQSpline, t: np.ndarray) -> np.ndarray:
        """[N, 3]: log|d rqs^-1 / dt| at t [N] of all-channel splines spl (row 3 n + c)."""
        return spl.inverse(np.repeat(t, 3))[1].reshape(-1, 3)

    def _walk(self, x, wo, ch, *, t=None, z=None, steps=(1, 2, 3, 4), s_prev=None):
        """Run steps in order; forward from latents z or inverse from values t. Returns (t, s, logp)."""
        n = len(ch)
        t_out = np.zeros((n, 4)) if t is None else np.array(t, np.float64)
        s = np.zeros((n, 4)) if s_prev is None else np.array(s_prev, np.float64)
        logp = np.zeros(n)
        ctx = self.context(x, wo)
        for j in steps:
            spl = self._spline(j, ctx, s[:, : j - 1], ch)
            if z is not None:
                tj, ld = spl.forward(z[:, j - 1])
                logp -= ld
            else:
                _, ld = spl.inverse(t_out[:, j - 1])
                tj = np.clip(t_out[:, j - 1], 0.0, 1.0)
                logp += ld
            t_out[:, j - 1] = tj
            s[:, j - 1] = self.box.s_from_t_dim(j, tj)
        return t_out, s, logp

    @staticmethod
    def _prep(x, wo):
        message = "x_o and w_o must be real number arrays [N, 3]"
        x = np.atleast_2d(real_array(x, message, dtype=np.float64))
        wo = np.atleast_2d(real_array(wo, message, dtype=np.float64))
        if x.shape[1:] != (3,) or wo.shape != x.shape:
            raise UsageError(f"x_o {x.shape} and w_o {wo.shape} must both be [N, 3]")
        return x, wo

    @staticmethod
    def _latents(n: int, k: int, rng, u):
        if u is not None:
            u = np.asarray(u, np.float64)
            if u.shape != (n, k):
                raise UsageError(f"u must be [N, {k}], got {u.shape}")
            return np.clip(np.nan_to_num(u), 0.0, 1.0)
        if rng is None:
            raise UsageError("give rng (numpy Generator) or u")
        return rng.random((n, k))

    def sample(self, x, wo, channel, rng=None, *, u=None):
        """(u_i [N,3], w_i [N,3], pdf [N]) for latents u [N,4] in [0,1) (drawn from rng if u is None)."""
        x, wo = self._prep(x, wo)
        ch = _channels(channel, len(x))
        z = self._latents(len(x), 4, rng, u)
        _, s, logp = self._walk(x, wo, ch, z=z)
        ui, wi, jac = self.box.to_rays(s)
        return ui, wi, np.minimum(np.exp(np.minimum(logp, 700.0)) / S_PER_T * jac, PDF_MAX)

    def sample_state(self, x, wo, channel, rng=None, *, u=None, context=None, directions=None) -> FlowSample:
        """:meth:`sample` plus the per-channel position densities and the conditioner outputs that
        :meth:`pdf_rgb_at` and :meth:`pdf_rgb_sampled` reuse; ``context`` is ``self.context(x, wo)`` if the
        caller has it. ``directions`` (bool [N], default all): rows whose w_i is drawn (steps 3-4); the
        others get u_i only, w_i = 0 and pdf = 0 (conditioner 3, which depends on u_i only, runs for all)."""
        x, wo = self._prep(x, wo)
        n = len(x)
        ch = _channels(channel, n)
        z = self._latents(n, 4, rng, u)
        ctx = self.context(x, wo) if context is None else context
        if directions is None:
            d = None
        else:
            directions = np.asarray(directions, bool).reshape(-1)
            if len(directions) != n:
                raise UsageError(f"directions must be a bool mask of the {n} rows, got {len(directions)}")
            d = np.nonzero(directions)[0]
        s, logs, t12, raws = np.zeros((n, 4)), np.zeros((n, 4)), np.zeros((n, 2)), []
        rr = slice(None) if d is None else d  # rows of steps 3-4
        for j in (1, 2, 3, 4):
            if j < 4 or d is None:
                raw = self._raw(j, ctx, s[:, : j - 1], n)
            else:  # conditioner 4 only where w_i is drawn
                raw = self._raw(4, take_rows(ctx, d), s[d, :3], len(d))
            raws.append(raw)
            r = slice(None) if j <= 2 else rr
            # the sampled channel only; the other channels' splines are built for the rows whose densities are asked for
            tj, ld = self._channel_spline(raw, ch[r], d if j == 3 else None).forward(z[r, j - 1])
            if j <= 2:
                t12[:, j - 1] = tj
            logs[r, j - 1] = -ld
            s[r, j - 1] = self.box.s_from_t_dim(j, tj)
        logp = ((logs[:, 0] + logs[:, 1]) + logs[:, 2]) + logs[:, 3]  # 0 - ld_1 - ld_2 - ... in the order of the steps
        ui, wi, jac = self.box.to_rays(s)
        pdf = np.minimum(np.exp(np.minimum(logp, 700.0)) / S_PER_T * jac, PDF_MAX)
        if d is not None:
            skip = ~directions
            wi[skip], pdf[skip] = 0.0, 0.0
        return FlowSample(ui, wi, pdf, ctx, s, jac, (raws[0], raws[1]), t12, raws[2], self, d, raws[3], ch, logs)

    def pdf_rgb_at(self, fs: FlowSample, rows, wi) -> np.ndarray:
        """[M, 3]: :meth:`pdf_rgb` at (u_i of ``fs`` rows [M], w_i [M, 3]), evaluating only conditioner 4."""
        rows = np.asarray(rows, np.int64).reshape(-1)
        wi = np.asarray(wi, np.float64).reshape(-1, 3)
        if len(wi) != len(rows):
            raise UsageError(f"w_i {wi.shape} must have one row per index ({len(rows)})")
        if len(rows) and (rows.min() < 0 or rows.max() >= len(fs.s)):
            raise UsageError(f"rows must index the {len(fs.s)} rows of the flow sample")
        if not len(rows):
            return np.zeros((0, 3))
        z3, p3 = direction_to_cylindrical(wi)
        t3, t4 = np.clip((z3 + 1) / 2, 0.0, 1.0), np.clip((p3 + np.pi) / (2 * np.pi), 0.0, 1.0)
        s_prev = np.concatenate([fs.s[rows, :2], z3[:, None]], axis=1)
        spl4 = self._splines_rgb(self._raw(4, take_rows(fs.ctx, rows), s_prev, len(rows)))
        spl3 = self._splines_rgb(fs.raw3[rows])
        logp = fs.log_position_rgb(rows) + self._log_inverse_rgb(spl3, t3) + self._log_inverse_rgb(spl4, t4)
        return np.minimum(np.exp(np.minimum(logp, 700.0)) / S_PER_T * fs.jac[rows, None], PDF_MAX)

    def pdf_rgb_sampled(self, fs: FlowSample, rows) -> np.ndarray:
        """[M, 3]: :meth:`pdf_rgb_at` at the sample's own (u_i, w_i) of rows [M] (whose w_i was drawn), reusing
        its conditioner-3 and -4 outputs: no network runs."""
        rows = np.asarray(rows, np.int64).reshape(-1)
        if len(rows) and (rows.min() < 0 or rows.max() >= len(fs.s)):
            raise UsageError(f"rows must index the {len(fs.s)} rows of the flow sample")
        pos = fs.direction_index(rows)
        if not len(rows):
            return np.zeros((0, 3))
        t = self.box.t_from_s(fs.s[rows])
        if fs.ch is None:
            spl3, spl4 = self._splines_rgb(fs.raw3[rows]), self._splines_rgb(fs.raw4[pos])
            logd = self._log_inverse_rgb(spl3, t[:, 2]) + self._log_inverse_rgb(spl4, t[:, 3])
        else:  # the sampled channel's from its own steps 3-4; splines for the other two only
            ch = fs.ch[rows]
            logd = _by_channel(fs.log_steps[rows, 2] + fs.log_steps[rows, 3],
                               self._log_inverse_others(fs.raw3[rows], ch, t[:, 2])
                               + self._log_inverse_others(fs.raw4[pos], ch, t[:, 3]), ch)
        logp = fs.log_position_rgb(rows) + logd
        return np.minimum(np.exp(np.minimum(logp, 700.0)) / S_PER_T * fs.jac[rows, None], PDF_MAX)

    def pdf(self, x, wo, ui, wi, channel) -> np.ndarray:
        """Density of (u_i, w_i) per unit box area and steradian, for one channel per row."""
        x, wo = self._prep(x, wo)
        ch = _channels(channel, len(x))
        s, jac = self.box.from_rays(ui, wi)
        _, _, logp = self._walk(x, wo, ch, t=self.box.t_from_s(s), s_prev=s)
        return np.minimum(np.exp(np.minimum(logp, 700.0)) / S_PER_T * jac, PDF_MAX)

    def pdf_rgb(self, x, wo, ui, wi) -> np.ndarray:
        """[N, 3]: :meth:`pdf` for each colour channel."""
        n = len(np.atleast_2d(x))
        return np.stack([self.pdf(x, wo, ui, wi, np.full(n, c)) for c in range(3)], axis=1)

    def pdf_position(self, x, wo, ui, channel) -> np.ndarray:
        """Marginal density of u_i per unit box area (steps 1-2 only)."""
        x, wo = self._prep(x, wo)
        ch = _channels(channel, len(x))
        s, jac = self.box.from_rays(ui, np.tile([0.0, 0.0, 1.0], (len(x), 1)))
        _, _, logp = self._walk(x, wo, ch, t=self.box.t_from_s(s), s_prev=s, steps=(1, 2))
        return np.minimum(np.exp(np.minimum(logp, 700.0)) / (2.0 * 2.0 * np.pi) * jac, PDF_MAX)

    def sample_direction(self, x, wo, ui, channel, rng=None, *, u=None):
        """Given u_i, draw w_i from p(w_i | u_i) (steps 3-4): (w_i [N,3], conditional pdf per steradian [N])."""
        x, wo = self._prep(x, wo)
        ch = _channels(channel, len(x))
        s, _ = self.box.from_rays(ui, np.tile([0.0, 0.0, 1.0], (len(x), 1)))
        z = np.zeros((len(x), 4))
        z[:, 2:] = self._latents(len(x), 2, rng, u)
        _, s, logp = self._walk(x, wo, ch, z=z, steps=(3, 4), s_prev=s)
        w = cylindrical_to_direction(s[:, 2], s[:, 3])
        return w, np.exp(np.minimum(logp, 700.0)) / (2.0 * 2.0 * np.pi)

    def pdf_direction(self, x, wo, ui, wi, channel) -> np.ndarray:
        """Conditional density p(w_i | u_i) per steradian (steps 3-4)."""
        x, wo = self._prep(x, wo)
        ch = _channels(channel, len(x))
        s, _ = self.box.from_rays(ui, wi)
        _, _, logp = self._walk(x, wo, ch, t=self.box.t_from_s(s), s_prev=s, steps=(3, 4))
        return np.exp(np.minimum(logp, 700.0)) / (2.0 * 2.0 * np.pi)
