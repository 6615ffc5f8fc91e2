"""The built-in example scene for ``nasset bake --example``.

A ring (``shell``: rough plastic torus, self-occluding and inter-reflecting) holding a translucent
ball (``jelly``: rough dielectric boundary around a scattering homogeneous medium), standing on a
ground plane, lit by a distant (directional) light and a constant environment. The asset is the
two shapes ``shell`` and ``jelly``; the ground and the lights are the scene around it.

The scene is written as ordinary Mitsuba XML plus binary PLY meshes, so a bake of the example
exercises exactly the path a user scene takes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: shape ids that form the asset in the example scene
EXAMPLE_ASSET_IDS = ("shell", "jelly")

_XML = """<scene version="3.0.0">
    <integrator type="volpath">
        <integer name="max_depth" value="24"/>
    </integrator>
    <sensor type="perspective" id="camera">
        <float name="fov" value="35"/>
        <transform name="to_world">
            <lookat origin="1.6, 1.1, 1.9" target="0, 0.18, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="256"/>
            <integer name="height" value="256"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="roughplastic" id="shell_bsdf">
        <rgb name="diffuse_reflectance" value="0.75, 0.32, 0.08"/>
        <float name="alpha" value="0.25"/>
    </bsdf>
    <medium type="homogeneous" id="jelly_medium">
        <rgb name="albedo" value="0.92, 0.75, 0.45"/>
        <float name="sigma_t" value="12"/>
    </medium>
    <shape type="ply" id="shell">
        <string name="filename" value="meshes/shell.ply"/>
        <ref id="shell_bsdf"/>
    </shape>
    <shape type="ply" id="jelly">
        <string name="filename" value="meshes/jelly.ply"/>
        <bsdf type="roughdielectric">
            <float name="alpha" value="0.15"/>
            <float name="int_ior" value="1.4"/>
            <float name="ext_ior" value="1.0"/>
        </bsdf>
        <ref name="interior" id="jelly_medium"/>
    </shape>
    <shape type="rectangle" id="ground">
        <transform name="to_world">
            <rotate x="1" angle="-90"/>
            <scale value="3"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.45, 0.45, 0.45"/></bsdf>
    </shape>
    <emitter type="directional" id="sun">
        <vector name="direction" value="-0.45, -0.8, -0.35"/>
        <rgb name="irradiance" value="3.0, 2.9, 2.7"/>
    </emitter>
    <emitter type="constant" id="sky">
        <rgb name="radiance" value="0.25, 0.3, 0.4"/>
    </emitter>
</scene>
"""


def write_ply(path: Path, points: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None) -> None:
    """Binary little-endian PLY with float32 positions (and normals) and uint32 triangle indices."""
    points = np.asarray(points, "<f4")
    faces = np.asarray(faces, "<u4")
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(points)}"]
    head += [f"property float {p}" for p in props]
    head += [f"element face {len(faces)}", "property list uchar uint vertex_indices", "end_header"]
    verts = points if normals is None else np.concatenate([points, np.asarray(normals, "<f4")], axis=1)
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode("ascii"))
        f.write(np.ascontiguousarray(verts, "<f4").tobytes())
        rec = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<u4", (3,))])
        rec["n"] = 3
        rec["i"] = faces
        f.write(rec.tobytes())


def example_meshes():
    """(name, trimesh) for the asset shapes, in scene (= asset object) space, +Y up, metres."""
    import trimesh

    shell = trimesh.creation.torus(major_radius=0.34, minor_radius=0.14, major_sections=48, minor_sections=20)
    shell.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    shell.apply_translation([0, 0.14, 0])
    jelly = trimesh.creation.icosphere(subdivisions=3, radius=0.19)
    jelly.apply_translation([0, 0.21, 0])
    return [("shell", shell), ("jelly", jelly)]


def write_example_scene(folder: str | Path) -> Path:
    """Write ``scene.xml`` and its meshes into ``folder``; returns the XML path."""
    folder = Path(folder)
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    for name, mesh in example_meshes():
        write_ply(folder / "meshes" / f"{name}.ply", mesh.vertices, mesh.faces, mesh.vertex_normals)
    xml = folder / "scene.xml"
    xml.write_text(_XML)
    return xml
