"""Mitsuba's analytic shapes (``sphere``, ``rectangle``, ``disk``, ``cylinder``) as triangle meshes.

A neural asset's geometry is a triangle mesh. A bake whose object is an analytic shape renders its
training data from a tessellation of it, with the shape's own BSDF and media, so that the data and
the asset's surface agree exactly (spec/bake.md#analytic-shapes). The tessellations are closed where
the shape is (a sphere: one vertex per pole, no seam), carry the analytic unit normals as vertex
normals, and are fine enough that the surface lies within ``1e-3`` of the shape's size of the true one.
``convert-scene`` writes disks and cylinders with the same tessellation (spheres and rectangles have
their own USD prims there).
"""

from __future__ import annotations

import numpy as np

#: Mitsuba classes of the shapes tessellated here
ANALYTIC_CLASSES = ("Sphere", "Rectangle", "Disk", "Cylinder")
#: latitude rings of a sphere (2x as many longitudes): a face's circumcentre lies 1 - cos(sqrt(2) pi / 128) = 6.0e-4
#: of the radius inside the sphere (at the equator; less towards the poles)
SPHERE_RINGS = 64
#: segments around a disk or a cylinder: a chord's sagitta is 1 - cos(pi / 192) = 1.3e-4 of the radius
ROUND_SEGMENTS = 192


def local_mesh(cls: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(points [V,3], faces [F,3], normals [V,3], uv [V,2])`` of the shape ``cls`` in Mitsuba's local frame:
    the unit sphere about the origin (poles on ±Z), the square [-1, 1]² at z = 0 facing +Z, the unit disk at
    z = 0 facing +Z, the open unit cylinder from z = 0 to 1 (normals outward). ``uv`` follows Mitsuba's
    parameterisation (sphere u = phi / 2pi, v = theta / pi; rectangle (x + 1, y + 1) / 2; disk u = r, v = phi / 2pi;
    cylinder u = phi / 2pi, v = z)."""
    if cls == "Sphere":
        return _sphere(SPHERE_RINGS)
    if cls == "Rectangle":
        pts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
        return pts, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0.0, 0.0, 1.0], (4, 1)), 0.5 * (pts[:, :2] + 1.0)
    n = ROUND_SEGMENTS
    a = 2.0 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(a), np.sin(a), np.zeros(n)], 1)
    nxt = (np.arange(n) + 1) % n
    if cls == "Disk":
        pts = np.concatenate([[[0.0, 0.0, 0.0]], ring])
        faces = np.stack([np.zeros(n, np.int64), 1 + np.arange(n), 1 + nxt], 1)
        return pts, faces, np.tile([0.0, 0.0, 1.0], (n + 1, 1)), np.c_[np.r_[0.0, np.ones(n)], np.r_[0.0, a / (2.0 * np.pi)]]
    if cls == "Cylinder":
        top = ring + [0.0, 0.0, 1.0]
        pts = np.concatenate([ring, top])
        i = np.arange(n)
        faces = np.concatenate([np.stack([i, nxt, n + nxt], 1), np.stack([i, n + nxt, n + i], 1)])
        nrm = np.concatenate([ring, ring])
        uv = np.stack([np.tile(a / (2.0 * np.pi), 2), np.repeat([0.0, 1.0], n)], 1)
        return pts, faces, nrm, uv
    raise ValueError(f"not an analytic shape class: {cls!r}")


def corner_uv(cls: str) -> np.ndarray:
    """Mitsuba's ``uv`` at each corner of :func:`local_mesh`'s faces [F, 3, 2] (a faceVarying ``st``) for the disk and
    the cylinder, whose angle coordinate (disk v, cylinder u = phi / 2pi in [0, 1)) wraps: a face across phi = 0
    reads 1 at its corners on that side, not 0, and a disk's centre reads its face's middle angle (u = r = 0 there)."""
    _, faces, _, uv = local_mesh(cls)
    out = uv[faces].copy()
    k, ring = (1, slice(1, None)) if cls == "Disk" else (0, slice(None))  # the angle coordinate, its corners
    a = out[:, ring, k]
    out[:, ring, k] = np.where(np.ptp(a, axis=1, keepdims=True) > 0.5, np.where(a < 0.5, a + 1.0, a), a)
    if cls == "Disk":
        out[:, 0, k] = out[:, 1:, k].mean(1)
    return out


def _sphere(rings: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A closed latitude-longitude unit sphere: one vertex per pole, ``rings - 1`` rings of ``2 rings`` vertices."""
    cols = 2 * rings
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2.0 * np.pi * np.arange(cols) / cols
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    body = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    pts = np.concatenate([[[0.0, 0.0, 1.0]], body, [[0.0, 0.0, -1.0]]])
    uv = np.concatenate([[[0.0, 0.0]], np.stack([ph / (2.0 * np.pi), th / np.pi], -1).reshape(-1, 2), [[0.0, 1.0]]])
    j = np.arange(cols)
    jn = (j + 1) % cols
    north, south = 0, len(pts) - 1
    faces = [np.stack([np.full(cols, north), 1 + j, 1 + jn], 1)]  # counter-clockwise seen from outside
    for r in range(rings - 2):
        a, b = 1 + r * cols + j, 1 + r * cols + jn
        c, d = a + cols, b + cols
        faces += [np.stack([a, c, d], 1), np.stack([a, d, b], 1)]
    last = 1 + (rings - 2) * cols
    faces.append(np.stack([last + j, np.full(cols, south), last + jn], 1))
    return pts, np.concatenate(faces).astype(np.int64), pts.copy(), uv


def shape_class(shape) -> str:
    """Mitsuba's class name of a shape ("PLYMesh", "Sphere", "LinearCurve", ...)."""
    return str(shape).split("[")[0].strip()


def drawn_to_world(mi, shape) -> np.ndarray:
    """A shape's ``to_world`` (4x4, column vectors) as Mitsuba draws the shape. A sphere stays round whatever its
    scale: Mitsuba takes the scale along its x axis as the radius (and warns about a non-uniform one), so a
    non-uniformly scaled sphere's matrix is rebuilt as that radius times the nearest rotation (a mirror kept)."""
    m = np.asarray(mi.traverse(shape)["to_world"].matrix, np.float64)
    m = m.reshape(4, 4, -1)[:, :, 0] if m.size > 16 else m.reshape(4, 4)
    if shape_class(shape) != "Sphere":
        return m
    lin = m[:3, :3]
    radius = float(np.linalg.norm(lin[:, 0]))
    if np.allclose(np.linalg.norm(lin, axis=0), radius, rtol=1e-4):
        return m
    u, _, vt = np.linalg.svd(lin)
    out = m.copy()
    out[:3, :3] = radius * (u @ vt)
    return out


def world_mesh(mi, shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(points [V,3], faces [F,3], unit normals [V,3])`` of an analytic Mitsuba shape in world space
    (its ``to_world`` as Mitsuba draws it, :func:`drawn_to_world`; normals by the inverse transpose)."""
    pts, faces, nrm, _ = local_mesh(shape_class(shape))
    m = drawn_to_world(mi, shape)
    wp = pts @ m[:3, :3].T + m[:3, 3]
    wn = nrm @ np.linalg.inv(m[:3, :3])
    wn /= np.maximum(np.linalg.norm(wn, axis=1, keepdims=True), 1e-30)
    return wp, faces, wn


def as_mesh(mi, shape):
    """A Mitsuba triangle mesh in place of the analytic ``shape``: its tessellation in world space with the
    shape's id, BSDF and interior / exterior media (an emitter is not carried: an asset emits nothing). It faces the
    side Mitsuba shades the shape on (``flip_normals``, or a mirroring ``to_world`` turns an analytic shape's normal
    over): its normals negated and each face wound on that side where needed, so the data and the asset do too."""
    from .sidedness import faces_facing_as_mitsuba, front_sign

    pts, faces, nrm = world_mesh(mi, shape)
    sign = front_sign(mi, shape, pts, faces, nrm)
    faces = faces_facing_as_mitsuba(mi, shape, pts, faces, nrm)
    nrm = nrm * sign
    props = mi.Properties()
    props.set_id(shape.id())
    for key, obj in (("bsdf", shape.bsdf()), ("interior", shape.interior_medium()), ("exterior", shape.exterior_medium())):
        if obj is not None:
            props[key] = obj
    mesh = mi.Mesh(shape.id() or "analytic", len(pts), len(faces), props, has_vertex_normals=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.ascontiguousarray(pts, np.float32).ravel())
    params["faces"] = mi.UInt32(np.ascontiguousarray(faces, np.uint32).ravel())
    params["vertex_normals"] = mi.Float(np.ascontiguousarray(nrm, np.float32).ravel())
    params.update()
    return mesh
