"""Tessellation of USD's implicit prims (spec/renderer.md#implicit-prims), in the prim's own space.

Sphere: an icosphere subdivided 4 times; Cube: 12 flat triangles; Cylinder, Cone, Capsule: SECTIONS segments
around their ``axis`` (capped; the cone's apex toward +axis); Plane: 2 triangles facing +axis, ``width`` and
``length`` along the axes USD assigns. Corner normals are the surface's own (radial, axial on caps), not averages
across edges (the sphere's: the spec's corner-angle-weighted vertex normals).
"""

from __future__ import annotations

import numpy as np

#: prims :func:`implicit_mesh` tessellates, with their schema's size attributes and fallbacks
IMPLICIT_PRIMS = {
    "Sphere": {"radius": 1.0},
    "Cube": {"size": 2.0},
    "Cylinder": {"radius": 1.0, "height": 2.0},
    "Cone": {"radius": 1.0, "height": 2.0},
    "Capsule": {"radius": 0.5, "height": 1.0},
    "Plane": {"width": 2.0, "length": 2.0},
}
#: segments around the axis of a cylinder, cone or capsule
SECTIONS = 64
#: local Z-aligned coordinates -> the prim's axis (cyclic permutations, determinant +1)
_AXIS = {"Z": [0, 1, 2], "X": [2, 0, 1], "Y": [1, 2, 0]}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def implicit_mesh(tname: str, size: dict, axis: str = "Z") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points [V, 3], faces [F, 3] wound about the outside (Plane: about +axis), unit corner normals [F, 3, 3]) of
    the implicit prim ``tname`` with the size attributes ``size`` (IMPLICIT_PRIMS' keys, positive and finite)."""
    import trimesh

    if tname == "Sphere":
        tm = trimesh.creation.icosphere(subdivisions=4, radius=size["radius"])
        pts, faces = np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64)
        return pts, faces, _unit(np.asarray(tm.vertex_normals, np.float64))[faces]  # angle-weighted, within 0.15 deg of radial
    if tname == "Cube":
        s = size["size"]
        tm = trimesh.creation.box(extents=(s, s, s))
        pts, faces = np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64)
        t = pts[faces]
        return pts, faces, np.repeat(_unit(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))[:, None], 3, 1)
    if tname == "Plane":
        w, ln = 0.5 * size["width"], 0.5 * size["length"]
        # width and length run along (X: z, y), (Y: x, z), (Z: x, y); the quad faces +axis
        u, v = {"X": (2, 1), "Y": (0, 2), "Z": (0, 1)}[axis]
        normal = np.eye(3)[{"X": 0, "Y": 1, "Z": 2}[axis]]
        pts = np.zeros((4, 3))
        pts[:, u], pts[:, v] = [-w, w, w, -w], [-ln, -ln, ln, ln]
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        if np.cross(pts[1] - pts[0], pts[2] - pts[0]) @ normal < 0:
            faces = faces[:, ::-1].copy()
        return pts, faces, np.broadcast_to(normal, (2, 3, 3)).copy()
    r, h = size["radius"], size["height"]
    if tname == "Capsule":
        tm = trimesh.creation.capsule(height=h, radius=r, count=[SECTIONS, SECTIONS // 2])
        pts, faces = np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64)
        core = np.zeros_like(pts)
        core[:, 2] = np.clip(pts[:, 2], -0.5 * h, 0.5 * h)
        n = _unit(pts - core)[faces]
    else:
        make = trimesh.creation.cylinder if tname == "Cylinder" else trimesh.creation.cone
        tm = make(radius=r, height=h, sections=SECTIONS)
        pts, faces = np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64)
        if tname == "Cone":
            pts[:, 2] -= 0.5 * h  # trimesh's cone stands on z = 0; USD's is centred, apex at +height / 2
        t = pts[faces]
        ng = _unit(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
        rho = np.linalg.norm(t[..., :2], axis=-1, keepdims=True)
        slope = 0.0 if tname == "Cylinder" else r / h  # the side's normal rises by r / h per unit radial
        side = _unit(np.concatenate([t[..., :2] / np.maximum(rho, 1e-300), np.full(rho.shape, slope)], -1))
        side = np.where(rho > 1e-9 * r, side, ng[:, None])  # the apex: the face's own normal
        cap = np.abs(ng[:, 2]) > 0.999
        n = np.where(cap[:, None, None], ng[:, None], side)
    perm = _AXIS[axis]
    return pts[:, perm], faces, n[..., perm]
