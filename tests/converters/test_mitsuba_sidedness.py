"""Mitsuba's front side read off a loaded shape (converters/mitsuba/sidedness.py, spec/bake.md#front-sides)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_converters.mitsuba import load_mitsuba  # noqa: E402
from nasset_converters.mitsuba.sidedness import faces_facing_as_mitsuba, front_sign  # noqa: E402

QUAD = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
TRIS = np.array([[0, 1, 2], [0, 2, 3]])


def _obj(tmp_path, *, flip: bool, normals: bool, scale_z: float = 1.0):
    mi = load_mitsuba()
    f = tmp_path / ("n.obj" if normals else "q.obj")
    f.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n" + ("vn 0 0 1\nf 1//1 2//1 3//1\nf 1//1 3//1 4//1\n"
                                                             if normals else "f 1 2 3\nf 1 3 4\n"))
    shape = mi.load_dict({"type": "obj", "filename": str(f), "flip_normals": flip,
                          "to_world": mi.ScalarTransform4f().scale([1.0, 1.0, scale_z])})
    p = mi.traverse(shape)
    pts = np.asarray(p["vertex_positions"], np.float64).reshape(-1, 3)
    nrm = np.asarray(p["vertex_normals"], np.float64).reshape(-1, 3) if normals else None
    return mi, shape, pts, nrm


@pytest.mark.parametrize("flip", [False, True])
@pytest.mark.parametrize("normals", [False, True])
def test_front_sign_reads_flip_normals_off_the_shape(tmp_path, flip, normals):
    mi, shape, pts, nrm = _obj(tmp_path, flip=flip, normals=normals)
    assert front_sign(mi, shape, pts, TRIS, nrm) == (-1.0 if flip else 1.0)


def test_mirrored_mesh_with_normals_is_rewound_to_its_normals(tmp_path):
    """Mitsuba keeps the winding of a mesh under a mirroring to_world and turns its normals: its front follows
    the normals (+Z becomes -Z), so the faces written for USD must wind about -Z."""
    mi, shape, pts, nrm = _obj(tmp_path, flip=False, normals=True, scale_z=-1.0)
    assert np.allclose(nrm, [0.0, 0.0, -1.0])
    faces = faces_facing_as_mitsuba(mi, shape, pts, TRIS, nrm)
    t = pts[faces]
    assert (np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2] < 0).all()


@pytest.mark.parametrize("flip, scale_z, front_z", [(False, 1.0, 1.0), (True, 1.0, -1.0), (False, -1.0, -1.0),
                                                    (True, -1.0, 1.0)])
def test_rectangle_written_with_its_transform_keeps_mitsubas_front(flip, scale_z, front_z):
    """A rectangle is written as the local quad under its to_world; USD's front of a mirrored prim is the left-hand
    side of the world winding. The front the written faces get is Mitsuba's sampled normal in every case."""
    mi = load_mitsuba()
    shape = mi.load_dict({"type": "rectangle", "flip_normals": flip,
                          "to_world": mi.ScalarTransform4f().scale([1.0, 1.0, scale_z])})
    world = QUAD * [1.0, 1.0, scale_z]
    faces = faces_facing_as_mitsuba(mi, shape, world, np.array([[0, 1, 2, 3]]), np.tile([0.0, 0.0, scale_z], (4, 1)),
                                    mirrored=scale_z < 0)
    t = world[faces[0][:3]]
    usd_front = np.cross(t[1] - t[0], t[2] - t[0]) * (-1.0 if scale_z < 0 else 1.0)
    assert np.sign(usd_front[2]) == front_z
