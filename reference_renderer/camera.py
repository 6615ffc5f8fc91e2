"""Camera from a UsdGeom.Camera (looks down local -Z, +Y up): perspective (pinhole or thin lens) or orthographic.

USD measures ``focalLength``, the apertures and their offsets in tenths of a scene unit, ``focusDistance`` in
scene units (UsdGeomCamera, "Units of Measure"). Pixels are square: the horizontal extent comes from
``horizontalAperture`` and the vertical one follows the image aspect (horizontal fit, as USD's ``fitWindow``
default does for renderers that keep square pixels).

- perspective: the image window at distance 1 spans ``x = +-horizontalAperture / (2 focalLength)``, moved by
  ``offset / focalLength`` (lens shift). With ``fStop > 0`` and ``focusDistance > 0`` the lens is a thin lens:
  rays start on a disk of radius ``0.1 focalLength / (2 fStop)`` (the f-number's aperture) in the camera's plane
  and pass through the pinhole ray's point on the plane of focus ``z = -focusDistance``.
- orthographic: parallel rays along -Z from the camera plane ``z = 0``, the window ``0.1 x`` the apertures and
  offsets in scene units.

Every camera sample's radiance is multiplied by the camera's linear exposure scale (``exposure`` and the
``exposure:*`` attributes, ``UsdGeomCamera::ComputeLinearExposureScale``).

spec/renderer.md#cameras.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sampling import normalize, square_to_uniform_disk

LENS_UNIT = 0.1  # scene units per unit of focalLength and the apertures (tenths of a scene unit)


@dataclass
class Camera:
    to_world: np.ndarray  # 4x4 row-vector convention: p_world = [p, 1] @ to_world
    focal_length: float  # tenths of a scene unit (perspective only)
    horizontal_aperture: float  # tenths of a scene unit
    vertical_aperture: float
    prim: str = ""
    resolution: tuple[int, int] | None = None  # from a UsdRender.Settings prim, if the stage has one
    horizontal_offset: float = 0.0  # horizontalApertureOffset, tenths of a scene unit
    vertical_offset: float = 0.0  # verticalApertureOffset
    orthographic: bool = False
    lens_radius: float = 0.0  # scene units; > 0: thin lens (perspective only)
    focus_distance: float = 0.0  # scene units, the plane of focus of a thin lens
    exposure_scale: float = 1.0  # multiplies every camera sample's radiance (UsdGeomCamera exposure)

    @property
    def needs_lens_samples(self) -> bool:
        """True when :meth:`generate_rays` takes a point on the lens (a thin lens)."""
        return self.lens_radius > 0.0

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

    def generate_rays(self, px, py, width: int, height: int, lens=None):
        """World rays (origins [n,3], unit directions [n,3]) through continuous film positions px in [0, W),
        py in [0, H) (row 0 at top); ``lens`` [n,2] uniform in [0,1)^2 picks the point on a thin lens (needed
        when :attr:`needs_lens_samples`, ignored otherwise)."""
        lin, eye = self.to_world[:3, :3], self.to_world[3, :3]
        if self.orthographic:
            half_w = 0.5 * self.horizontal_aperture
            x = ((2.0 * px / width - 1.0) * half_w + self.horizontal_offset) * LENS_UNIT
            y = ((1.0 - 2.0 * py / height) * half_w * (height / width) + self.vertical_offset) * LENS_UNIT
            o_loc = np.stack([x, y, np.zeros_like(x)], 1)
            d = normalize(np.broadcast_to(np.array([0.0, 0.0, -1.0]) @ lin, o_loc.shape))
            return o_loc @ lin + eye, d
        tan_h = 0.5 * self.horizontal_aperture / self.focal_length
        x = (2.0 * px / width - 1.0) * tan_h + self.horizontal_offset / self.focal_length
        y = (1.0 - 2.0 * py / height) * tan_h * (height / width) + self.vertical_offset / self.focal_length
        d_loc = np.stack([x, y, -np.ones_like(x)], 1)
        if not self.needs_lens_samples:
            d = normalize(d_loc @ lin)
            return np.broadcast_to(eye, d.shape).copy(), d
        if lens is None:
            raise ValueError("a thin-lens camera needs lens samples")
        o_loc = np.zeros_like(d_loc)
        o_loc[:, :2] = self.lens_radius * square_to_uniform_disk(lens)
        d = normalize((d_loc * self.focus_distance - o_loc) @ lin)  # toward the point in focus
        return o_loc @ lin + eye, d
