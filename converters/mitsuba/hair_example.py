"""The built-in Mitsuba hair example (``nasset bake --kind rna --example hair-dense``).

The head of hair of Blender's ``blender-hair-dense`` (the same strands: 20 000 light strands of 16
points, 1.6 mm wide at the root tapering to 0.8 mm, on a dark scalp sphere of radius 0.245 m) as a
Mitsuba ``linearcurve`` shape (id ``hair``) with Mitsuba's ``hair`` BSDF (Chiang et al.'s model, light
blond: eumelanin and pheomelanin 0.05 each, the concentrations Cycles derives from melanin 0.1), on a
diffuse ground under a sun (directional) and a dim constant sky, rendered by ``path`` with max_depth
64. Light hair is where multiple scattering between fibres carries much of the look, and where a path
tracer pays for it: the case the rna fiber variant is for, in one engine (spec/accuracy.md#examples).
``size="tiny"`` writes 1 000 strands (the tests' size).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nasset_sdk.errors import UsageError

#: shape ids that form the asset
EXAMPLE_ASSET_IDS = ("hair",)
#: strands per size (16 points each)
STRANDS = {"tiny": 1_000, "small": 20_000, "hq": 20_000}
#: the scene integrator's path depth
MAX_DEPTH = 64

_XML = """<scene version="3.0.0">
    <integrator type="path">
        <integer name="max_depth" value="{max_depth}"/>
    </integrator>
    <sensor type="perspective" id="camera">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="1.4, 1.3, 2.2" target="0, 0.35, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="128"/>
            <integer name="height" value="128"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="linearcurve" id="hair">
        <string name="filename" value="curves/hair.txt"/>
        <bsdf type="hair">
            <float name="eumelanin" value="0.05"/>
            <float name="pheomelanin" value="0.05"/>
        </bsdf>
    </shape>
    <shape type="sphere" id="scalp">
        <point name="center" value="0, 0.25, 0"/>
        <float name="radius" value="0.245"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.25, 0.15, 0.1"/></bsdf>
    </shape>
    <shape type="rectangle" id="ground">
        <transform name="to_world">
            <rotate x="1" angle="-90"/>
            <scale value="4"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
    </shape>
    <emitter type="directional" id="sun">
        <vector name="direction" value="-0.45, -0.8, -0.4"/>
        <rgb name="irradiance" value="3.0, 3.0, 3.0"/>
    </emitter>
    <emitter type="constant" id="sky">
        <rgb name="radiance" value="0.05, 0.06, 0.08"/>
    </emitter>
</scene>
"""


def write_curves(path: Path, points: np.ndarray, radius: np.ndarray, k: int) -> None:
    """Mitsuba's curve file: one ``x y z radius`` line per control point, an empty line between curves."""
    rows = np.concatenate([np.asarray(points, np.float64), np.asarray(radius, np.float64)[:, None]], 1).reshape(-1, k, 4)
    lines = "\n\n".join("\n".join(" ".join(f"{v:.7g}" for v in p) for p in strand) for strand in rows)
    tmp = path.with_suffix(".part")
    tmp.write_text(lines + "\n")
    tmp.replace(path)


def write_example_scene(folder: str | Path, size: str | None = None, *, max_depth: int = MAX_DEPTH) -> Path:
    """Write ``scene.xml`` and ``curves/hair.txt`` into ``folder``; returns the XML path."""
    from nasset_converters.blender import to_y_up
    from nasset_converters.blender.examples import hair_strands

    size = size or "small"
    if size not in STRANDS:
        raise UsageError(f"unknown size {size!r} ({', '.join(STRANDS)})")
    folder = Path(folder)
    (folder / "curves").mkdir(parents=True, exist_ok=True)
    k = 16
    pts, radius = hair_strands(STRANDS[size], k, root_radius=0.0008)
    write_curves(folder / "curves" / "hair.txt", to_y_up(pts), radius, k)
    xml = folder / "scene.xml"
    xml.write_text(_XML.format(max_depth=int(max_depth)))
    return xml
