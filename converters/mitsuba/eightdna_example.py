"""The built-in translucent example of the ``8dna`` kind (``nasset bake --kind 8dna --example``).

The asset ``blob`` is a slightly squashed icosphere (about 0.4 m across) with a GGX rough-dielectric
boundary (IOR 1.4, alpha 0.15) around a scattering homogeneous medium (sigma_t 14 /m, albedo
(0.96, 0.85, 0.65), isotropic phase): a translucent, orange-tinted object whose look is dominated by
multiple scattering. The benchmark scene lights it with a small spherical area light (radius 0.035 m)
about 0.17 m from its surface and just outside the camera's view, the near-field case the 8D model
exists for; there is no ground and no environment, so every pixel is either the asset or black. The scene is plain Mitsuba XML plus a
binary PLY mesh, so a bake of the example runs exactly the path a user scene takes. The
``heterogeneous`` variant (``--example heterogeneous``) replaces the medium by a grid of the same mean
density (:func:`density_grid`, a Mitsuba ``.vol`` file).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: shape id of the asset in the example scene
EXAMPLE_ASSET_IDS = ("blob",)

#: the small near light (sphere centre, radius in metres, RGB radiance)
LIGHT_CENTER = (0.35, 0.04, 0.12)
LIGHT_RADIUS = 0.035
LIGHT_RADIANCE = (60.0, 60.0, 60.0)
#: the boundary of the asset: (relative IOR, GGX alpha); also written into the asset's core/direct
BOUNDARY = (1.4, 0.15)
MEDIUM_ALBEDO = (0.96, 0.85, 0.65)
MEDIUM_SIGMA_T = 14.0
CAMERA = dict(origin=(0.0, 0.12, 1.25), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=30.0)

_XML = """<scene version="3.0.0">
    <integrator type="volpath">
        <integer name="max_depth" value="{max_depth}"/>
    </integrator>
    <sensor type="perspective" id="camera">
        <float name="fov" value="{fov}"/>
        <string name="fov_axis" value="x"/>
        <transform name="to_world">
            <lookat origin="{origin}" target="{target}" up="{up}"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="{res}"/>
            <integer name="height" value="{res}"/>
            <rfilter type="box"/>
        </film>
    </sensor>
{medium}
    <shape type="ply" id="blob">
        <string name="filename" value="meshes/blob.ply"/>
        <bsdf type="roughdielectric">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="{alpha}"/>
            <float name="int_ior" value="{ior}"/>
            <float name="ext_ior" value="1.0"/>
        </bsdf>
        <ref name="interior" id="blob_medium"/>
    </shape>
{light}</scene>
"""

_HOMOGENEOUS = """    <medium type="homogeneous" id="blob_medium">
        <rgb name="albedo" value="{albedo}"/>
        <float name="sigma_t" value="{sigma_t}"/>
        <phase type="isotropic"/>
    </medium>
"""

_GRID = """    <medium type="heterogeneous" id="blob_medium">
        <rgb name="albedo" value="{albedo}"/>
        <volume type="gridvolume" name="sigma_t">
            <string name="filename" value="media/density.vol"/>
            <transform name="to_world">
                <translate value="{lo}"/>
                <scale value="{span}"/>
            </transform>
        </volume>
        <float name="scale" value="{scale}"/>
        <phase type="isotropic"/>
    </medium>
"""

_LIGHT = """    <shape type="sphere" id="lamp">
        <point name="center" value="{c}"/>
        <float name="radius" value="{r}"/>
        <emitter type="area"><rgb name="radiance" value="{L}"/></emitter>
    </shape>
"""


def _v(t) -> str:
    return ", ".join(f"{float(x):g}" for x in t)


def blob_mesh():
    """The asset's trimesh in scene (= asset object) space, metres: an icosphere of radius 0.2 scaled (1, 0.85, 0.95)."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4, radius=0.2)
    m.apply_scale([1.0, 0.85, 0.95])
    return m


def density_grid(n: int = 24) -> np.ndarray:
    """[n, n, n, 1] relative density of the ``heterogeneous`` example in [0.15, 1.85] (mean 1): smooth lobes
    plus a dense inner blob, so light meets thin and thick regions (z, y, x order as Mitsuba's grid files)."""
    g = (np.arange(n) + 0.5) / n * 2 - 1
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    d = 1.0 + 0.55 * np.sin(3.1 * x + 0.4) * np.cos(2.3 * y - 0.3) * np.sin(2.7 * z + 1.1) + 0.6 * np.exp(-((x - 0.2) ** 2 + y ** 2 + z ** 2) / 0.08)
    d = np.clip(d, 0.15, None)
    return (d / d.mean())[..., None].astype(np.float32)


def write_example_scene(folder: str | Path, *, light: bool = True, res: int = 128, max_depth: int = 1024,
                        heterogeneous: bool = False, light_center=LIGHT_CENTER) -> Path:
    """Write ``scene.xml`` (asset + small sphere light, or the asset alone) and ``meshes/blob.ply``; returns the XML path.

    ``heterogeneous``: the medium is a grid (``media/density.vol``, :func:`density_grid` times sigma_t) instead of
    homogeneous. ``light_center``: the lamp's centre (m; default LIGHT_CENTER, right of the blob)."""
    from .examples import write_ply

    folder = Path(folder)
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    m = blob_mesh()
    write_ply(folder / "meshes" / "blob.ply", m.vertices, m.faces, np.asarray(m.vertex_normals))
    if heterogeneous:
        from . import load_mitsuba

        mi = load_mitsuba()
        (folder / "media").mkdir(exist_ok=True)
        mi.VolumeGrid(density_grid()).write(str(folder / "media" / "density.vol"))
        lo, hi = m.bounds[0] - 0.005, m.bounds[1] + 0.005
        medium = _GRID.format(albedo=_v(MEDIUM_ALBEDO), lo=_v(lo), span=_v(hi - lo), scale=MEDIUM_SIGMA_T)
    else:
        medium = _HOMOGENEOUS.format(albedo=_v(MEDIUM_ALBEDO), sigma_t=MEDIUM_SIGMA_T)
    lamp = _LIGHT.format(c=_v(light_center), r=LIGHT_RADIUS, L=_v(LIGHT_RADIANCE)) if light else ""
    xml = folder / "scene.xml"
    xml.write_text(_XML.format(max_depth=max_depth, fov=CAMERA["fov"], origin=_v(CAMERA["origin"]), target=_v(CAMERA["target"]),
                               up=_v(CAMERA["up"]), res=int(res), medium=medium, alpha=BOUNDARY[1], ior=BOUNDARY[0],
                               light=lamp))
    return xml
