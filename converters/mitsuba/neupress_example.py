"""The built-in heterogeneous translucent example for ``nasset bake --kind neupress --example``
(spec/bake-neupress.md#example).

A paperweight: a flattened ellipsoid (``boundary``: rough dielectric, IOR 1.45, GGX alpha 0.2) filled
with a noise-driven heterogeneous medium (``gridvolume`` sigma_t and RGB albedo written as Mitsuba
``.vol`` grids), holding an opaque diffuse torus (``inner``) whose exterior medium is that same
medium. The scene is lit by an environment map (a sky gradient with a small bright sun, written as
EXR) and has a camera; no ground, so the asset is the whole picture. The asset is the two shapes
``boundary`` and ``inner``; its surface geometry is the boundary alone (the inner torus is hidden
behind it and lives only in the baked transport).

Presets differ in the boundary mesh (PRT stores one coefficient block per vertex): ``tiny`` 162
vertices, ``small`` and ``hq`` 642.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nasset_sdk.errors import UsageError

from .examples import write_ply

#: shape ids that form the asset; the first is the refractive boundary (the asset's surface)
EXAMPLE_ASSET_IDS = ("boundary", "inner")
#: boundary mesh subdivision per preset (icosphere)
SUBDIVISIONS = {"tiny": 2, "small": 3, "hq": 3}
#: boundary size (metres): ellipsoid radii
RADII = (0.5, 0.38, 0.5)
GRID = 32  # medium grid resolution per axis
SIGMA_T_SCALE = 8.0  # 1/m: the density grid (in [0.1, 1]) times this
ENV_SIZE = (64, 128)  # env map rows, columns

_XML = """<scene version="3.0.0">
    <integrator type="volpath">
        <integer name="max_depth" value="{max_depth}"/>
        <integer name="rr_depth" value="8"/>
    </integrator>
    <sensor type="perspective" id="camera">
        <float name="fov" value="30"/>
        <transform name="to_world">
            <lookat origin="0.9, 1.0, 2.6" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="128"/>
            <integer name="height" value="128"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <medium type="heterogeneous" id="fill">
        <volume name="sigma_t" type="gridvolume">
            <string name="filename" value="media/sigma_t.vol"/>
            <transform name="to_world">{grid_to_world}</transform>
        </volume>
        <volume name="albedo" type="gridvolume">
            <string name="filename" value="media/albedo.vol"/>
            <transform name="to_world">{grid_to_world}</transform>
        </volume>
        <float name="scale" value="{scale}"/>
    </medium>
    <shape type="ply" id="boundary">
        <string name="filename" value="meshes/boundary.ply"/>
        <bsdf type="roughdielectric">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="{alpha}"/>
            <float name="int_ior" value="{ior}"/>
            <float name="ext_ior" value="1.0"/>
        </bsdf>
        <ref name="interior" id="fill"/>
    </shape>
    <shape type="ply" id="inner">
        <string name="filename" value="meshes/inner.ply"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.12, 0.05"/></bsdf>
        <ref name="exterior" id="fill"/>
    </shape>
    <emitter type="envmap" id="sky">
        <string name="filename" value="env.exr"/>
    </emitter>
</scene>
"""

ALPHA = 0.2
IOR = 1.45


def _smooth_noise(rng, n: int, sigma: float) -> np.ndarray:
    """Gaussian-filtered white noise [n, n, n] rescaled to [0, 1]."""
    from scipy.ndimage import gaussian_filter

    f = gaussian_filter(rng.normal(size=(n, n, n)), sigma, mode="wrap")
    return (f - f.min()) / max(float(np.ptp(f)), 1e-12)


def medium_grids(seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """(sigma_t density [Z, Y, X, 1] in [0.1, 1], albedo [Z, Y, X, 3]) on the GRID^3 lattice (float32).

    Density: smooth noise pushed through a soft threshold (wisps of dense material in a thin fill);
    albedo: two colours (a warm amber and a cool milky blue) mixed by a second noise field."""
    rng = np.random.default_rng(seed)
    d = _smooth_noise(rng, GRID, 2.5)
    density = 0.1 + 0.9 / (1.0 + np.exp(-(d - 0.5) * 12.0))
    m = _smooth_noise(rng, GRID, 3.5)[..., None]
    warm, cool = np.array([0.97, 0.72, 0.35]), np.array([0.55, 0.8, 0.97])
    albedo = (1 - m) * warm + m * cool
    return density[..., None].astype(np.float32), albedo.astype(np.float32)


def env_map() -> np.ndarray:
    """Lat-long environment [rows, cols, 3] float32: sky gradient, darker ground, a small bright sun."""
    rows, cols = ENV_SIZE
    theta = (np.arange(rows) + 0.5) / rows * np.pi  # 0 at the zenith (+Y)
    phi = (np.arange(cols) + 0.5) / cols * 2 * np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    up = np.cos(t)[..., None]
    sky = np.where(up > 0, np.array([0.35, 0.5, 0.85]) * (0.4 + 0.6 * up), np.array([0.25, 0.2, 0.15]) * (0.6 - 0.4 * up))
    sun_dir = np.array([np.sin(0.9) * np.cos(1.0), np.cos(0.9), np.sin(0.9) * np.sin(1.0)])
    d = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1)
    sun = np.exp(-(1.0 - np.clip(d @ sun_dir, -1, 1)) / 0.004)[..., None] * np.array([30.0, 28.0, 24.0])
    return (sky + sun).astype(np.float32)


def example_meshes(size: str = "small"):
    """(name, trimesh) for the asset shapes in scene (= asset object) space, +Y up, metres."""
    import trimesh

    if size not in SUBDIVISIONS:
        raise UsageError(f"neupress example preset must be one of {sorted(SUBDIVISIONS)}, got {size!r}")
    boundary = trimesh.creation.icosphere(subdivisions=SUBDIVISIONS[size], radius=1.0)
    boundary.apply_scale(RADII)
    inner = trimesh.creation.torus(major_radius=0.17, minor_radius=0.06, major_sections=32, minor_sections=12)
    inner.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 3, [1, 0, 0.3]))
    return [("boundary", boundary), ("inner", inner)]


def write_example_scene(folder: str | Path, size: str = "small", *, max_depth: int = 64) -> Path:
    """Write ``scene.xml``, its meshes, medium grids and env map into ``folder``; returns the XML path."""
    from nasset_reference_renderer.film import write_exr

    from . import load_mitsuba

    mi = load_mitsuba()  # VolumeGrid needs a variant

    folder = Path(folder)
    for sub in ("meshes", "media"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    for name, mesh in example_meshes(size):
        write_ply(folder / "meshes" / f"{name}.ply", mesh.vertices, mesh.faces, mesh.vertex_normals)
    density, albedo = medium_grids()
    mi.VolumeGrid(density).write(str(folder / "media" / "sigma_t.vol"))
    mi.VolumeGrid(albedo).write(str(folder / "media" / "albedo.vol"))
    write_exr(folder / "env.exr", env_map())
    lo = -np.asarray(RADII)
    # Mitsuba applies nested transform elements in order: scale the unit cube first, then translate
    grid_to_world = (f'<scale value="{2 * RADII[0]}, {2 * RADII[1]}, {2 * RADII[2]}"/>'
                     f'<translate value="{lo[0]}, {lo[1]}, {lo[2]}"/>')
    xml = folder / "scene.xml"
    tmp = xml.with_suffix(".xml.part")
    tmp.write_text(_XML.format(max_depth=int(max_depth), grid_to_world=grid_to_world, scale=SIGMA_T_SCALE,
                               alpha=ALPHA, ior=IOR))
    tmp.replace(xml)
    return xml
