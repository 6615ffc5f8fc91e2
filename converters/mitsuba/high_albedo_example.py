"""The built-in high-albedo translucent example (``nasset bake --kind rna|neupress --example high-albedo``).

A pebble (ellipsoid mesh) with a rough dielectric boundary (GGX, alpha 0.15, IOR 1.5) around a
homogeneous medium of single-scattering albedo >= 0.99 in every channel (sigma_t 25 per unit), on a
diffuse ground under a sun (directional) and a constant sky, rendered with ``volpath`` max_depth 128.
Long random walks under a rough boundary reached by next-event estimation only: the case where path
tracing is most expensive and the ground truth most heavy-tailed (spec/accuracy.md#examples). The
asset is the single shape ``pebble``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .examples import write_ply

#: shape ids that form the asset
EXAMPLE_ASSET_IDS = ("pebble",)
#: the medium's single-scattering albedo (RGB) and extinction (per scene unit)
ALBEDO = (0.997, 0.993, 0.99)
SIGMA_T = 25.0
#: the scene integrator's path depth
MAX_DEPTH = 128

_XML = """<scene version="3.0.0">
    <integrator type="volpath">
        <integer name="max_depth" value="{max_depth}"/>
    </integrator>
    <sensor type="perspective" id="camera">
        <float name="fov" value="30"/>
        <transform name="to_world">
            <lookat origin="1.3, 0.9, 1.5" target="0, 0.12, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="256"/>
            <integer name="height" value="256"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <medium type="homogeneous" id="pebble_medium">
        <rgb name="albedo" value="{albedo}"/>
        <float name="sigma_t" value="{sigma_t}"/>
    </medium>
    <shape type="ply" id="pebble">
        <string name="filename" value="meshes/pebble.ply"/>
        <bsdf type="roughdielectric">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.15"/>
            <float name="int_ior" value="1.5"/>
            <float name="ext_ior" value="1.0"/>
        </bsdf>
        <ref name="interior" id="pebble_medium"/>
    </shape>
    <shape type="rectangle" id="ground">
        <transform name="to_world">
            <rotate x="1" angle="-90"/>
            <scale value="3"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.4, 0.4, 0.4"/></bsdf>
    </shape>
    <emitter type="directional" id="sun">
        <vector name="direction" value="-0.5, -0.75, -0.3"/>
        <rgb name="irradiance" value="3.0, 2.9, 2.7"/>
    </emitter>
    <emitter type="constant" id="sky">
        <rgb name="radiance" value="0.25, 0.3, 0.4"/>
    </emitter>
</scene>
"""


def pebble_mesh():
    """The pebble: an icosphere scaled to an ellipsoid (semi-axes 0.3, 0.15, 0.22), resting on y = 0."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    m.apply_transform(np.diag([0.3, 0.15, 0.22, 1.0]))
    m.apply_translation([0.0, 0.15 + 1e-3, 0.0])
    return m


def write_example_scene(folder: str | Path, size: str | None = None, *, max_depth: int = MAX_DEPTH) -> Path:
    """Write ``scene.xml`` and ``meshes/pebble.ply`` into ``folder``; returns the XML path (``size`` unused)."""
    folder = Path(folder)
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    m = pebble_mesh()
    write_ply(folder / "meshes" / "pebble.ply", m.vertices, m.faces, m.vertex_normals)
    xml = folder / "scene.xml"
    xml.write_text(_XML.format(max_depth=int(max_depth), albedo=", ".join(f"{a:g}" for a in ALBEDO), sigma_t=f"{SIGMA_T:g}"))
    return xml
