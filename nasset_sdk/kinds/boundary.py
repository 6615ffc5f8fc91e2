"""Analytic rough-dielectric boundary reflection (GGX, Walter et al. 2007) shared by neupress and 8dna
(spec/kinds/encodings.md#ggx).

Parameters are a tensor ``[eta, alpha]``: eta = n_inside / n_outside (relative IOR), alpha = GGX
roughness. alpha is clamped to [ALPHA_MIN, 1], eta to [1e-3, 1e3]. All directions are object-space
unit vectors pointing away from the surface; n is the outward shading normal.

Value (cosine-weighted BRDF, 1/sr; integrate against incident radiance over the sphere):

    h = normalize(wo + wi);  f(wo, wi) |n.wi| = F(|wo.h|, eta) D(h) G2(wo, wi) / (4 |n.wo|)

for n.wo > 0 and n.wi > 0, else 0. Sampling draws h from D(h) (n.h) and reflects wo about it;
its density over the whole sphere is D(h) (n.h) / (4 |wo.h|) with h = +-normalize(wo + wi) chosen so that
n.h >= 0 (0 if n.wo <= 0).
"""

from __future__ import annotations

import numpy as np

from .encodings import dot3, from_local, unit64

ALPHA_MIN = 1e-4
_EPS = 1e-12


def boundary_params(tensor) -> tuple[float, float]:
    """(eta, alpha) from a [2] tensor, clamped to their valid ranges."""
    p = np.nan_to_num(np.asarray(tensor, np.float64).reshape(-1), nan=1.0)
    eta = float(np.clip(p[0], 1e-3, 1e3))
    alpha = float(np.clip(p[1], ALPHA_MIN, 1.0))
    return eta, alpha


def fresnel_dielectric(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance at |cos_i| for relative IOR eta (1 under total internal reflection)."""
    c = np.clip(np.abs(np.nan_to_num(np.asarray(cos_i, np.float64), nan=0.0)), 0.0, 1.0)
    sin_t2 = (1.0 - c * c) / (eta * eta)
    tir = sin_t2 >= 1.0
    ct = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    rs = (c - eta * ct) / np.maximum(c + eta * ct, _EPS)
    rp = (eta * c - ct) / np.maximum(eta * c + ct, _EPS)
    return np.where(tir, 1.0, np.clip(0.5 * (rs * rs + rp * rp), 0.0, 1.0))


def ggx_d(cos_h: np.ndarray, alpha: float) -> np.ndarray:
    """GGX normal distribution D(h) = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2) for n.h > 0, else 0."""
    c = np.asarray(cos_h, np.float64)
    a2 = alpha * alpha
    den = c * c * (a2 - 1.0) + 1.0
    return np.where(c > 0, a2 / (np.pi * np.maximum(den * den, _EPS)), 0.0)


def ggx_lambda(cos_t: np.ndarray, alpha: float) -> np.ndarray:
    """Smith Lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2, written as (sqrt(c^2 + alpha^2 (1 - c^2)) / |c| - 1) / 2."""
    c = np.maximum(np.abs(np.asarray(cos_t, np.float64)), _EPS)
    c = np.minimum(c, 1.0)
    return 0.5 * (np.sqrt(c * c + alpha * alpha * (1.0 - c * c)) / c - 1.0)


def _dots(n, wo, wi):
    n, wo, wi = unit64(n), unit64(wo), unit64(wi)
    h = wo + wi
    hl = np.sqrt(dot3(h, h))[:, None]  # np.linalg.norm's sum, in its order
    h = np.where(hl > 1e-12, h / np.maximum(hl, 1e-12), n)
    return dot3(n, wo), dot3(n, wi), dot3(n, h), dot3(wo, h)


def _reflection(dots, eta: float, alpha: float) -> np.ndarray:
    cos_o, cos_i, cos_h, cos_oh = dots
    g2 = 1.0 / (1.0 + ggx_lambda(cos_o, alpha) + ggx_lambda(cos_i, alpha))
    val = fresnel_dielectric(cos_oh, eta) * ggx_d(cos_h, alpha) * g2 / (4.0 * np.maximum(cos_o, _EPS))
    return np.where((cos_o > 0) & (cos_i > 0), val, 0.0)


def _pdf(dots, alpha: float) -> np.ndarray:
    cos_o, _, cos_h, cos_oh = dots
    flip = np.where(cos_h < 0, -1.0, 1.0)
    cos_h, cos_oh = cos_h * flip, cos_oh * flip
    pdf = ggx_d(cos_h, alpha) * cos_h / (4.0 * np.maximum(np.abs(cos_oh), _EPS))
    return np.where((cos_o > 0) & (cos_h > 0), pdf, 0.0)


def ggx_reflection(n, wo, wi, eta: float, alpha: float) -> np.ndarray:
    """Cosine-weighted reflection f(wo, wi) |n.wi| [N] (1/sr)."""
    return _reflection(_dots(n, wo, wi), eta, alpha)


def ggx_pdf(n, wo, wi, alpha: float) -> np.ndarray:
    """Density per steradian of :func:`ggx_sample` at wi [N]; h = +-normalize(wo + wi) with n.h >= 0."""
    return _pdf(_dots(n, wo, wi), alpha)


def ggx_reflection_pdf(n, wo, wi, eta: float, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`ggx_reflection`, :func:`ggx_pdf`) [N] each, from one set of dot products: the same values."""
    dots = _dots(n, wo, wi)
    return _reflection(dots, eta, alpha), _pdf(dots, alpha)


def ggx_sample(n, wo, u2, alpha: float, eta: float | None = None):
    """Reflect wo about h ~ D(h) (n.h): tan^2 theta_h = alpha^2 u1 / (1 - u1), phi_h = 2 pi u2.

    Returns (wi [N,3], pdf [N]), and with ``eta`` also :func:`ggx_reflection` at wi [N] (the same dot
    products); wi may lie below the surface (then the value is 0).
    """
    u2 = np.clip(np.nan_to_num(np.asarray(u2, np.float64)), 0.0, 1.0 - 1e-16)
    tan2 = alpha * alpha * u2[:, 0] / np.maximum(1.0 - u2[:, 0], 1e-16)
    cos_t = 1.0 / np.sqrt(1.0 + tan2)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    phi = 2.0 * np.pi * u2[:, 1]
    h = from_local(np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1), n)
    wo = unit64(wo)
    wi = 2.0 * dot3(wo, h)[:, None] * h - wo
    wi = unit64(wi)
    if eta is None:
        return wi, ggx_pdf(n, wo, wi, alpha)
    val, pdf = ggx_reflection_pdf(n, wo, wi, eta, alpha)
    return wi, pdf, val
