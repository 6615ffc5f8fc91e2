"""Asset geometry: triangle meshes (surface variant) and linear fiber curves (fiber variant).

Object space is right-handed, +Y up, in the stage's metersPerUnit (spec/format.md#geometry).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import limits
from .arrays import real_array, real_dtype
from .errors import UsageError


def scale_problem(lo, hi) -> str | None:
    """Why geometry of bounding box ``lo``..``hi`` (object space) is beyond float32 ray casting, the GEOMETRY_SCALE rule
    of spec/security.md#bounds: a coordinate above MAX_GEOMETRY_COORDINATE, or a diagonal below MIN_GEOMETRY_SIZE or below
    MIN_GEOMETRY_SIZE_RATIO x the largest |coordinate| (an asset far from its origin for its size); None when within."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    reach = float(max(np.abs(lo).max(), np.abs(hi).max()))
    diag = float(np.linalg.norm(hi - lo))
    if reach > limits.MAX_GEOMETRY_COORDINATE or diag < limits.MIN_GEOMETRY_SIZE or diag < limits.MIN_GEOMETRY_SIZE_RATIO * reach:
        return (f"bounding box {[lo.tolist(), hi.tolist()]} (diagonal {diag:.3g}): coordinates must stay within "
                f"{limits.MAX_GEOMETRY_COORDINATE:g} and the diagonal be >= {limits.MIN_GEOMETRY_SIZE:g} and >= "
                f"{limits.MIN_GEOMETRY_SIZE_RATIO:g} x the largest |coordinate|")
    return None


@dataclass
class MeshGeometry:
    """points [V,3] float32; faces [F,3] int32 (counter-clockwise = front); normals [V,3] or None."""

    points: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None

    @classmethod
    def from_trimesh(cls, mesh) -> "MeshGeometry":
        """From a ``trimesh.Trimesh``; keeps its vertex normals."""
        pts = np.asarray(mesh.vertices, np.float32)
        faces = np.asarray(mesh.faces, np.int32)
        normals = np.asarray(mesh.vertex_normals, np.float32)
        return cls(pts, faces, normals)

    def __post_init__(self) -> None:  # numpy arrays from here on; USAGE for what holds no numbers
        self.points = real_array(self.points, "mesh points must be a real number array")
        self.faces = _index("mesh faces", self.faces)
        if self.normals is not None:
            self.normals = real_array(self.normals, "mesh normals must be a real number array")

    def validate(self) -> None:
        p, f = self.points, self.faces
        if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
            raise UsageError(f"mesh points must be [V,3], got {p.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise UsageError(f"mesh faces must be [F,3], got {f.shape}")
        if f.min() < 0 or f.max() >= len(p):
            raise UsageError("mesh face index out of range")
        if not np.isfinite(p).all():
            raise UsageError("mesh points contain NaN/Inf")
        if self.normals is not None and np.asarray(self.normals).shape != p.shape:
            raise UsageError("mesh normals must be [V,3] like points")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.points.min(0), self.points.max(0)


@dataclass
class CurvesGeometry:
    """Linear fiber curves. points [P,3]; counts [C] vertices per curve (>= 2); widths [P]."""

    points: np.ndarray
    counts: np.ndarray
    widths: np.ndarray

    def __post_init__(self) -> None:  # numpy arrays from here on; USAGE for what holds no numbers
        self.points = real_array(self.points, "curve points must be a real number array")
        self.widths = real_array(self.widths, "curve widths must be a real number array")
        self.counts = _index("curve counts", self.counts)

    def validate(self) -> None:
        p, c, w = self.points, self.counts, self.widths
        if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
            raise UsageError(f"curve points must be [P,3], got {p.shape}")
        if c.ndim != 1 or len(c) == 0 or (c < 2).any() or int(c.sum()) != len(p):
            raise UsageError("curve counts must be >= 2 each and sum to the number of points")
        if w.shape != (len(p),) or not np.isfinite(w).all() or (w <= 0).any():
            raise UsageError("curve widths must be [P], finite and > 0")
        if not np.isfinite(p).all():
            raise UsageError("curve points contain NaN/Inf")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        r = self.widths[:, None] * 0.5
        return (self.points - r).min(0), (self.points + r).max(0)


def _index(what: str, value) -> np.ndarray:
    """``value`` as a numpy integer array (whole-number floats converted), or USAGE naming ``what`` when it does not
    hold integers."""
    dt = real_dtype(value)
    if dt is not None and dt.kind == "f":  # whole numbers stored as floats (a text file's columns) are indices too
        a = np.asarray(value)
        if np.isfinite(a).all() and (a == np.round(a)).all():
            return a.astype(np.int64)
    if dt is None or dt.kind not in "iu":
        raise UsageError(f"{what} must be an integer array")
    return np.asarray(value)
