"""Perspective pinhole camera from a UsdGeom.Camera (looks down local -Z, +Y up).

The horizontal field of view is fixed by ``horizontalAperture / focalLength``; pixels are
square, so the vertical extent follows the image aspect (horizontal fit, as USD's
``fitWindow`` default does for renderers that keep square pixels). ``horizontalApertureOffset`` and
``verticalApertureOffset`` (lens shift) move the window by ``offset / focalLength`` in the image plane at
distance 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sampling import normalize


@dataclass
class PerspectiveCamera:
    to_world: np.ndarray  # 4x4 row-vector convention: p_world = [p, 1] @ to_world
    focal_length: float
    horizontal_aperture: float
    vertical_aperture: float
    prim: str = ""
    resolution: tuple[int, int] | None = None  # from a UsdRender.Settings prim, if the stage has one
    horizontal_offset: float = 0.0  # horizontalApertureOffset, the aperture's units (mm)
    vertical_offset: float = 0.0  # verticalApertureOffset

    def default_resolution(self, width: int | None, height: int | None) -> tuple[int, int]:
        """Explicit sizes win; else the stage's render settings; else 256 wide at the aperture's aspect."""
        aspect = self.vertical_aperture / self.horizontal_aperture
        if width is None and height is None:
            if self.resolution is not None:
                return self.resolution
            width = 256
        if width is None:
            width = max(1, int(round(height / aspect)))
        if height is None:
            height = max(1, int(round(width * aspect)))
        return int(width), int(height)

    def generate_rays(self, px, py, width: int, height: int):
        """Rays through continuous film positions px in [0, W), py in [0, H) (row 0 at top)."""
        tan_h = 0.5 * self.horizontal_aperture / self.focal_length
        x = (2.0 * px / width - 1.0) * tan_h + self.horizontal_offset / self.focal_length
        y = (1.0 - 2.0 * py / height) * tan_h * (height / width) + self.vertical_offset / self.focal_length
        d_loc = np.stack([x, y, -np.ones_like(x)], 1)
        lin = self.to_world[:3, :3]
        d = normalize(d_loc @ lin)
        o = np.broadcast_to(self.to_world[3, :3], d.shape).copy()
        return o, d
