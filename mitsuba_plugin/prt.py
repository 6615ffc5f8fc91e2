"""PRT mode of the ``nasset_path`` integrator (``prt`` true) for neupress assets (spec/renderer.md#neupress,
"PRT mode"; spec/kinds/neupress.md#component-prt).

At a hit on a neupress instance inside triangle (v_0, v_1, v_2) with barycentrics lambda:

    L_o = sum_j lambda_j sum_k a_k(v_j, w_o) b_k   (per channel)

a_k from the asset's ``prt`` component in the w_o bin of the vertex normal n_v's frame
(:meth:`.neupress.NeupressJit.prt_radiance`), b_k the SH projection of every ``nasset_dome`` emitter in
the instance's object space (the reference renderer's quadrature, :func:`dome_sh`). No shadow rays, no
other lights, no continuation, no surface reflection. Other kinds render as in path mode.

Load time (:func:`tables`, numpy, once per render call): b per instance, and per asset its faces and
vertex normals n_v (authored, else area-weighted face normals). Per sample (:func:`radiance`): Dr.Jit gathers.
"""

from __future__ import annotations

import numpy as np

from nasset_reference_renderer.lights import DomeLight
from nasset_reference_renderer.shaders.neupress import dome_sh, dome_sh_world
from nasset_sdk.errors import error
from nasset_sdk.view import vertex_normals

#: SH coefficients per instance: 9 basis functions x RGB, b[k, c] at 3 k + c
SH_RGB = 27


class PrtTables:
    """Dr.Jit tables of the PRT mode: ``light`` Float [instances * 27] (b of each instance, 0 for other
    kinds), ``assets`` [(asset index, NeupressJit)], ``faces`` {asset index: UInt32 [F * 3]}, ``normals``
    {asset index: Float [V * 3] n_v in object space}."""

    def __init__(self, light, assets, faces, normals) -> None:
        self.light, self.assets, self.faces, self.normals = light, assets, faces, normals


def domes(scene) -> list:
    """The scene's ``nasset_dome`` emitters (alone, or parts of a ``nasset_sky``) as the reference renderer's
    DomeLight (scale, image, rotation)."""
    out = []
    for em in scene.emitters():
        for part in getattr(em, "parts", [em]):
            if type(part).__name__ == "DomeLight" and hasattr(part, "rotation"):
                out.append(DomeLight(part.scale, part.image, rotation=part.rotation))
    return out


def check(scene, assets) -> list:
    """Usage errors of the PRT mode (the reference renderer's), for scenes holding neupress assets: an asset
    without ``prt``, a scene without a DomeLight. Returns :func:`domes` of the scene."""
    mine = [asset for asset in assets if asset.kind == "neupress"]
    for asset in mine:
        if "prt" not in asset.asset.components():
            raise error("USAGE", "--prt: the asset has no 'prt' component", file=asset.path)
    lights = domes(scene)
    if mine and not lights:
        raise error("USAGE", "--prt needs a DomeLight in the scene (nasset_dome; the PRT lighting is the dome's SH projection)")
    return lights


def tables(mi, scene, assets, tab) -> PrtTables:
    """:class:`PrtTables` of a scene whose asset instances are ``assets`` and ``tab``
    (:func:`.plugins._instance_tables`); typed usage errors from :func:`check`."""
    lights = check(scene, assets)
    if not assets:
        return PrtTables(mi.Float(0), [], {}, {})
    which = np.asarray(tab["asset"].numpy(), np.int64).reshape(-1)
    inv = np.asarray(tab["inv"].numpy(), np.float64).reshape(-1, 3, 4)
    b = np.zeros((len(which), SH_RGB))
    quadrature = dome_sh_world(lights)  # once per call; per instance only the SH of its object-space directions
    for i, a in enumerate(which):
        if assets[a].kind == "neupress":  # world -> object linear part, row vectors: d @ M3^-T
            b[i] = dome_sh(quadrature, inv[i, :, :3].T).ravel()
    if not np.isfinite(b).all():
        raise error("SCENE_INVALID", "the dome's SH projection is not finite")
    prt_assets = [(a, asset) for a, asset in enumerate(assets) if asset.kind == "neupress"]
    faces, normals = {}, {}
    for a, asset in prt_assets:
        g = asset.geometry
        faces[a] = mi.UInt32(np.ascontiguousarray(g.faces, np.uint32).ravel())
        normals[a] = mi.Float(np.ascontiguousarray(vertex_normals(g), np.float32).ravel())
    light = mi.Float(np.ascontiguousarray(b, np.float32).ravel()) if len(b) else mi.Float(0)
    return PrtTables(light, prt_assets, faces, normals)


def radiance(mi, prt: PrtTables, a: int, asset, k, prim, uv, wo, active):
    """L_o [Color3f] at hits on instances k [UInt32] of asset a: triangle ``prim`` [UInt32] of the asset's
    faces, barycentrics ``uv`` [Point2f] (Mitsuba's (lambda_1, lambda_2)), ``wo`` object-space [Vector3f]."""
    import drjit as dr

    b = [dr.gather(mi.Float, prt.light, k * SH_RGB + j, active) for j in range(SH_RGB)]
    lam = [1.0 - uv.x - uv.y, uv.x, uv.y]
    out = mi.Color3f(0)
    for j in range(3):
        v = dr.gather(mi.UInt32, prt.faces[a], prim * 3 + j, active)
        n = mi.Vector3f(*[dr.gather(mi.Float, prt.normals[a], v * 3 + c, active) for c in range(3)])
        out += lam[j] * asset.prt_radiance(b, v, n, wo)
    return out
