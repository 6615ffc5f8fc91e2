"""Conversion fidelity: small Mitsuba scenes rendered by Mitsuba and, after ``convert-scene``, by the reference renderer.

Each scene (``SCENES``) is a Mitsuba XML written by code, with the files it needs. ``measure`` renders
it twice with Mitsuba (``llvm_ad_rgb``, seeds 1 and 2) and once with the reference renderer from
the converted stage, at the same size and sample count, and reports

* ``ratio``: mean of the reference renderer's image / mean of Mitsuba's (seed 1), per channel;
* ``psnr``: PSNR of the reference renderer's image against Mitsuba's (seed 1);
* ``psnr_seed``: PSNR of Mitsuba seed 2 against seed 1, the ceiling set by Mitsuba's noise alone;
* ``noise_ratio``: MSE(reference renderer, Mitsuba) / (the MSE that the two images' noise alone explains:
  half the MSE of the two Mitsuba seeds plus the reference renderer's own variance of the pixel mean).
  About 1 for a faithful conversion; bias and misplaced structure raise it. It separates conversion
  errors from the reference renderer simply being noisier than Mitsuba at equal spp (which lowers
  ``psnr`` below ``psnr_seed`` without any conversion error).

PSNR uses the peak ``max`` of Mitsuba's seed-1 image: ``10 log10(peak^2 / MSE)``. A faithful conversion
has ratio 1 (within noise) and ``psnr`` close to ``psnr_seed`` (both images carry the same amount
of noise). ``python -m nasset_converters.mitsuba.fidelity`` writes the table at full size into
docs/conversion-fidelity.md.
"""

from __future__ import annotations

import argparse
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HEADER = """<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
<sensor type="perspective"><float name="fov" value="40"/>
 <transform name="to_world"><lookat origin="{origin}" target="0, 0.3, 0" up="0, 1, 0"/></transform>
 <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>{rfilter}</film>
</sensor>
"""
BOX = '<rfilter type="box"/>'
FLOOR = """<shape type="rectangle" id="floor"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="2"/></transform>
 {bsdf}</shape>
"""
SUN = ('<emitter type="directional" id="sun"><vector name="direction" value="-0.4, -0.8, -0.45"/>'
       '<rgb name="irradiance" value="2.5, 2.4, 2.2"/></emitter>\n')
SKY = '<emitter type="constant" id="sky"><rgb name="radiance" value="0.3, 0.35, 0.45"/></emitter>\n'


def _checker_png(path: Path, colors, n: int = 64, squares: int = 8) -> None:
    """An 8-bit sRGB PNG of a ``squares`` x ``squares`` checkerboard of two colours (uint8 triples), with a
    gradient on one axis so that flips and offsets show."""
    from nasset_sdk.images import write_png

    y, x = np.mgrid[0:n, 0:n]
    sq = ((x * squares // n) + (y * squares // n)) % 2
    img = np.where(sq[..., None] == 0, np.asarray(colors[0], np.float64), np.asarray(colors[1], np.float64))
    img = img * (0.55 + 0.45 * (y / (n - 1)))[..., None]  # darker toward the top row
    write_png(path, np.clip(np.round(img), 0, 255).astype(np.uint8))


def _textures(folder: Path, size: int) -> str:
    _checker_png(folder / "floor.png", [(230, 200, 120), (60, 90, 160)])
    _checker_png(folder / "ball.png", [(250, 70, 40), (240, 240, 230)], squares=6)
    return (HEADER.format(depth=4, rfilter=BOX, origin="0.9, 1.5, 2.6", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
                                '<string name="filename" value="floor.png"/><transform name="to_uv"><scale x="2" y="1.5"/>'
                                '<rotate z="1" angle="20"/><translate x="0.1" y="0.3"/></transform></texture></bsdf>')
            + '<shape type="sphere" id="ball"><point name="center" x="0" y="0.45" z="0"/><float name="radius" value="0.45"/>\n'
              ' <bsdf type="principled"><texture type="bitmap" name="base_color"><string name="filename" value="ball.png"/>'
              '</texture><float name="roughness" value="0.6"/></bsdf></shape>\n'
            + SUN + SKY + "</scene>")


def _texture_sampling(folder: Path, size: int) -> str:
    # a coarse 8 x 8 gradient bitmap scaled 2.5x by to_uv (most of each panel lies outside the unit square) on three
    # panels seen from above: wrap_mode clamp, mirror (filter_type nearest) and repeat (nearest)
    from nasset_sdk.images import write_png

    y, x = np.mgrid[0:8, 0:8]
    write_png(folder / "grad.png", np.stack([x * 255 // 7, y * 255 // 7, 128 + 0 * x], -1).astype(np.uint8))

    def panel(sid, px, wrap, filt):
        return (f'<shape type="rectangle" id="{sid}"><transform name="to_world"><scale value="0.31"/><rotate x="1" angle="-90"/>'
                f'<translate x="{px}" y="0.01"/></transform><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
                f'<string name="filename" value="grad.png"/><string name="wrap_mode" value="{wrap}"/>'
                f'<string name="filter_type" value="{filt}"/><transform name="to_uv"><scale value="2.5"/>'
                '<translate x="-0.7" y="-0.6"/></transform></texture></bsdf></shape>\n')

    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 2.1, 0.3", size=size).replace('target="0, 0.3, 0"', 'target="0, 0, 0"')
            + panel("clamped", -0.66, "clamp", "bilinear") + panel("mirrored", 0.0, "mirror", "nearest")
            + panel("repeated", 0.66, "repeat", "nearest") + SKY + "</scene>")


def _sidedness(folder: Path, size: int) -> str:
    # one-sided diffuse panels seen from the front and from behind (black in Mitsuba), a twosided one, and a
    # twosided one with a different back BSDF seen from behind
    panel = ('<shape type="rectangle" id="{id}"><transform name="to_world"><scale value="0.5"/><rotate y="1" angle="{a}"/>'
             '<translate x="{x}" y="0.6"/></transform><bsdf type="{t}">{inner}</bsdf></shape>\n')
    diffuse = '<rgb name="reflectance" value="0.8, 0.5, 0.2"/>'
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.2, 2.8", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>')
            + panel.format(id="front", a=20, x=-0.6, t="diffuse", inner=diffuse)
            + panel.format(id="back", a=200, x=0.6, t="diffuse", inner=diffuse)
            + panel.format(id="both", a=160, x=0.0, t="twosided", inner=f'<bsdf type="diffuse">{diffuse}</bsdf>')
            + panel.format(id="two", a=180, x=0.0, t="twosided", inner=f'<bsdf type="diffuse">{diffuse}</bsdf><bsdf type="diffuse">'
                           '<rgb name="reflectance" value="0.2, 0.4, 0.9"/></bsdf>').replace('y="0.6"', 'y="1.3"')
            + SUN + SKY + "</scene>")


def _orientation(folder: Path, size: int) -> str:
    # which side is the front: mirrored (scale z -1) and flip_normals shapes, one-sided, seen from their
    # Mitsuba back (black); a rectangle emitter turned to the floor by flip_normals; a twosided emitting
    # panel seen from its back (Mitsuba's area emitter emits from its front only); a flip_normals disk emitter (a
    # DiskLight)
    (folder / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n")
    (folder / "up.obj").write_text("v -0.3 0 -0.3\nv 0.3 0 -0.3\nv 0.3 0 0.3\nv -0.3 0 0.3\nf 4 3 2 1\n")
    def panel(sid, shape, x, scale_z="0.25", flip=False):
        # a reflectance of its own: Mitsuba's parser merges shapes of equal BSDFs, and refuses to merge flipped ones
        diffuse = f'<bsdf type="diffuse"><rgb name="reflectance" value="0.8, {0.5 + 0.1 * x:.2f}, 0.2"/></bsdf>'

        return (f'<shape type="{shape}" id="{sid}">' + ('<string name="filename" value="quad.obj"/>' if shape == "obj" else "")
                + ('<boolean name="flip_normals" value="true"/>' if flip else "")
                + f'<transform name="to_world"><scale x="0.25" y="0.25" z="{scale_z}"/><translate x="{x}" y="0.45"/>'
                f"</transform>{diffuse}</shape>\n")

    emit = '<emitter type="area"><rgb name="radiance" value="4, 3.6, 3"/></emitter>'
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.0, 2.8", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>')
            + panel("mirrored", "rectangle", -0.9, scale_z="-0.25") + panel("mirrored_obj", "obj", -0.3, scale_z="-0.25")
            + panel("flipped", "rectangle", 0.3, flip=True) + panel("front", "rectangle", 0.9)
            + '<shape type="rectangle" id="light"><boolean name="flip_normals" value="true"/><transform name="to_world">'
              '<scale value="0.2"/><rotate x="1" angle="-90"/><translate x="-0.5" y="1.2" z="0.4"/></transform>'
            + emit + "</shape>\n"
            + '<shape type="disk" id="disk_light"><boolean name="flip_normals" value="true"/><transform name="to_world">'
              '<scale value="0.15"/><rotate x="1" angle="-90"/><translate x="0.1" y="1.0" z="-0.4"/></transform>'
            + emit + "</shape>\n"
            + '<shape type="obj" id="lamp"><string name="filename" value="up.obj"/><transform name="to_world">'
              '<translate x="0.5" y="1.3" z="0.4"/></transform><bsdf type="twosided"><bsdf type="diffuse"/></bsdf>'
            + emit + "</shape>\n"
            + SKY + "</scene>")


GREY_DIFFUSE = '<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>'


def _objects(box_z: float = -0.9, floor_bsdf: str = GREY_DIFFUSE) -> str:
    """A floor, a ball and a box (at ``box_z``) under a sun and a sky (the camera scenes)."""
    return (FLOOR.format(bsdf=floor_bsdf)
            + '<shape type="sphere" id="ball"><point name="center" x="0.3" y="0.3" z="0"/><float name="radius" value="0.3"/>'
              '<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.4, 0.2"/></bsdf></shape>\n'
            + '<shape type="cube" id="box"><transform name="to_world"><scale value="0.2"/><translate x="-0.5" y="0.2" '
              f'z="{box_z:g}"/></transform><bsdf type="diffuse"><rgb name="reflectance" value="0.1, 0.6, 0.6"/></bsdf></shape>\n'
            + SUN + SKY + "</scene>")


def _lens_shift(folder: Path, size: int) -> str:
    # the sensor's principal point moved by 0.15 film widths and -0.1 film heights, over a floor and two shapes
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 1.4, 2.8", size=size).replace(
                '<float name="fov" value="40"/>', '<float name="fov" value="40"/><float name="principal_point_offset_x" '
                'value="0.15"/><float name="principal_point_offset_y" value="-0.1"/>')
            + _objects(box_z=-0.3))


def _orthographic(folder: Path, size: int) -> str:
    # an orthographic sensor whose to_world scale (1.3) sets the view's half-width, looking down at 30 degrees
    sensor = ('<sensor type="orthographic"><transform name="to_world"><scale x="1.3" y="1.3"/>'
              '<lookat origin="0.6, 1.6, 2.6" target="0, 0.3, 0" up="0, 1, 0"/></transform>')
    head = HEADER.format(depth=3, rfilter=BOX, origin="0, 1, 2", size=size)
    return head.split("<sensor")[0] + sensor + head.split("</transform>", 1)[1] + _objects()


def _depth_of_field(folder: Path, size: int) -> str:
    # a thin lens (aperture radius 0.35) focused on the ball; the box behind it and the checkered floor blur
    _checker_png(folder / "floor.png", [(230, 200, 120), (60, 90, 160)])
    head = HEADER.format(depth=3, rfilter=BOX, origin="0.2, 0.9, 2.4", size=size).replace(
        '<sensor type="perspective"><float name="fov" value="40"/>',
        '<sensor type="thinlens"><float name="fov" value="40"/><float name="aperture_radius" value="0.35"/>'
        '<float name="focus_distance" value="2.4"/>')
    checker = ('<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="floor.png"/>'
               '</texture></bsdf>')
    return head + _objects(floor_bsdf=checker)


def _pbr_textures(folder: Path, size: int) -> str:
    # principled BSDFs with a roughness bitmap on the floor (a raw checker, 0.15 / 0.85) and a metallic bitmap on a
    # ball (0 / 1), under a low sun and the sky
    _checker_png(folder / "rough.png", [(38, 38, 38), (217, 217, 217)])
    _checker_png(folder / "metal.png", [(0, 0, 0), (255, 255, 255)], squares=4)

    def raw(name, file):
        return (f'<texture type="bitmap" name="{name}"><string name="filename" value="{file}"/>'
                '<boolean name="raw" value="true"/></texture>')
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 1.2, 2.6", size=size)
            + FLOOR.format(bsdf='<bsdf type="principled"><rgb name="base_color" value="0.5, 0.45, 0.4"/>'
                                + raw("roughness", "rough.png") + '</bsdf>')
            + '<shape type="sphere" id="ball"><point name="center" x="0" y="0.4" z="0"/><float name="radius" value="0.4"/>'
              '<bsdf type="principled"><rgb name="base_color" value="0.9, 0.6, 0.3"/><float name="roughness" value="0.6"/>'
            + raw("metallic", "metal.png") + '</bsdf></shape>\n'
            + SUN.replace("-0.4, -0.8, -0.45", "0, -0.35, -1") + SKY + "</scene>")


def _stripes_normal_png(path: Path, n: int = 64, stripes: int = 8, tilt_deg: float = 35.0) -> None:
    """An 8-bit tangent-space normal map, (n + 1) / 2: stripes across s whose normals lean +-``tilt_deg`` along s."""
    from nasset_sdk.images import write_png

    x = np.arange(n)
    sign = np.where((x * stripes // n) % 2 == 0, 1.0, -1.0)
    t = np.radians(tilt_deg)
    nrm = np.stack([sign * np.sin(t), np.zeros(n), np.full(n, np.cos(t))], -1)
    write_png(path, np.clip(np.round((np.broadcast_to(nrm, (n, n, 3)) + 1) / 2 * 255), 0, 255).astype(np.uint8))


def _normal_maps(folder: Path, size: int) -> str:
    # a floor under a normalmap of stripes leaning +-35 deg along u (a raw bitmap), lit by a low sun along +x
    _stripes_normal_png(folder / "stripes.png")
    bsdf = ('<bsdf type="normalmap"><texture type="bitmap" name="normalmap"><string name="filename" value="stripes.png"/>'
            '<boolean name="raw" value="true"/></texture><bsdf type="diffuse"><rgb name="reflectance" '
            'value="0.6, 0.6, 0.6"/></bsdf></bsdf>')
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 2.4, 2.0", size=size) + FLOOR.format(bsdf=bsdf)
            + SUN.replace("-0.4, -0.8, -0.45", "-0.8, -0.5, 0") + SKY + "</scene>")


def _color_grid_ply(path: Path, n: int = 6) -> None:
    """An ASCII PLY: an n x n grid of triangle pairs (2 x 2 units, in the XZ plane, normal +Y) with a float colour in
    [0, 1] per vertex (Mitsuba takes 8-bit ones as they are, 0 .. 255, and warns)."""
    rng = np.random.default_rng(5)
    g = np.linspace(-1.0, 1.0, n + 1)
    x, z = np.meshgrid(g, g)
    cols = rng.uniform(0.1, 0.9, ((n + 1) ** 2, 3))
    faces = [t for i in range(n) for j in range(n) for t in (
        (i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1),
        (i * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1))]
    lines = ["ply", "format ascii 1.0", f"element vertex {(n + 1) ** 2}", "property float x", "property float y",
             "property float z", "property float red", "property float green", "property float blue",
             f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    lines += [f"{a:.6f} 0 {b:.6f} {c[0]:.6f} {c[1]:.6f} {c[2]:.6f}" for a, b, c in zip(x.ravel(), z.ravel(), cols, strict=True)]
    lines += ["3 " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def _vertex_colors(folder: Path, size: int) -> str:
    # a PLY grid with a colour per vertex, shaded by a diffuse BSDF whose reflectance is a mesh_attribute texture
    _color_grid_ply(folder / "grid.ply")
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 2.0, 1.6", size=size)
            + '<shape type="ply" id="grid"><string name="filename" value="grid.ply"/><transform name="to_world">'
              '<scale value="1.2"/></transform><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">'
              '<string name="name" value="vertex_color"/></texture></bsdf></shape>\n'
            + SUN + SKY + "</scene>")


def _curves(folder: Path, size: int) -> str:
    # a linearcurve of three arcs and a bsplinecurve of two loops (radius 0.02-0.05) over a floor
    t = np.linspace(0.0, 1.0, 9)
    arcs = ["\n".join(f"{x0 + 0.6 * s:.5f} {0.05 + 0.5 * np.sin(np.pi * s):.5f} {z0:.5f} {0.03 + 0.02 * s:.5f}"
                      for s in t) for x0, z0 in ((-1.0, -0.4), (-0.9, 0.0), (-0.8, 0.4))]
    (folder / "arcs.txt").write_text("\n\n".join(arcs) + "\n")
    u = np.linspace(0.0, 2 * np.pi, 14)
    loops = ["\n".join(f"{xc + 0.35 * np.cos(a):.5f} {0.4 + 0.3 * np.sin(a):.5f} {zc + 0.1 * np.sin(2 * a):.5f} 0.035"
                       for a in u) for xc, zc in ((0.5, -0.3), (0.6, 0.4))]
    (folder / "loops.txt").write_text("\n\n".join(loops) + "\n")
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 1.6, 2.6", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>')
            + '<shape type="linearcurve" id="arcs"><string name="filename" value="arcs.txt"/><bsdf type="diffuse">'
              '<rgb name="reflectance" value="0.8, 0.3, 0.2"/></bsdf></shape>\n'
            + '<shape type="bsplinecurve" id="loops"><string name="filename" value="loops.txt"/><bsdf type="diffuse">'
              '<rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>\n'
            + SUN + SKY + "</scene>")


def _emitter_texture(folder: Path, size: int) -> str:
    # an area emitter whose radiance is an sRGB checker bitmap on a rectangle over a floor, seen by
    # the camera and lighting the floor, and a dim sky
    _checker_png(folder / "screen.png", [(240, 80, 40), (40, 120, 240)], squares=4)
    emitter = ('<shape type="rectangle" id="screen"><transform name="to_world"><scale value="0.5"/><rotate x="1" '
               'angle="60"/><translate y="0.8" z="-0.4"/></transform><bsdf type="diffuse"><rgb name="reflectance" '
               'value="0, 0, 0"/></bsdf><emitter type="area"><texture type="bitmap" name="radiance"><string '
               'name="filename" value="screen.png"/></texture></emitter></shape>\n')
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 1.4, 2.4", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>')
            + emitter + SKY.replace("0.3, 0.35, 0.45", "0.05, 0.05, 0.06") + "</scene>")


def _cutouts(folder: Path, size: int) -> str:
    # a horizontal panel whose mask opacity is a black / white checker bitmap (holes), casting a patterned shadow on
    # the floor seen through it, and an upright panel of constant opacity 0.4; volpath (Mitsuba's path integrator
    # stops shadow rays at any mask)
    _checker_png(folder / "holes.png", [(0, 0, 0), (255, 255, 255)], squares=4)
    panel = ('<shape type="rectangle" id="{id}"><transform name="to_world">{place}</transform>'
             '<bsdf type="mask">{opacity}<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" '
             'value="{rgb}"/></bsdf></bsdf></bsdf></shape>\n')
    return (HEADER.format(depth=4, rfilter=BOX, origin="0.3, 1.9, 2.2", size=size).replace('type="path"', 'type="volpath"')
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>')
            + panel.format(id="holes", place='<scale value="0.5"/><rotate x="1" angle="-90"/><translate y="0.7"/>',
                           opacity='<texture type="bitmap" name="opacity"><string name="filename" value="holes.png"/>'
                                   '</texture>', rgb="0.8, 0.3, 0.2")
            + panel.format(id="veil", place='<scale value="0.35"/><translate x="-0.6" y="0.35" z="0.2"/>',
                           opacity='<float name="opacity" value="0.4"/>', rgb="0.2, 0.4, 0.8")
            + SUN.replace("-0.4, -0.8, -0.45", "-0.2, -0.9, -0.3") + SKY + "</scene>")


def _many_lights(folder: Path, size: int) -> str:
    # 24 small sphere emitters and 16 point lights over a floor beside a ball, powers over 30x: more than the reference
    # renderer samples at every vertex (it draws 8 per kind, spec/renderer.md#light-selection), and more than the plugin
    # leaves to Mitsuba's choice by weight. Mitsuba picks among the 40 uniformly: at 32 x 32 x 64 spp its image mean
    # moves by 2-3 % between seeds, so the test renders 256 spp
    rng = np.random.default_rng(24)
    lights = []
    for i in range(24):
        x, y, z = rng.uniform(-1.8, 1.8), rng.uniform(0.15, 1.2), rng.uniform(-1.8, 1.2)
        r, g, b = rng.uniform(0.3, 1.0, 3) * 10 ** rng.uniform(0.3, 1.5)
        lights.append(f'<shape type="sphere" id="bulb{i}"><point name="center" x="{x:.4f}" y="{y:.4f}" z="{z:.4f}"/>'
                      f'<float name="radius" value="{rng.uniform(0.02, 0.06):.4f}"/><emitter type="area"><rgb name="radiance" '
                      f'value="{r:.4f}, {g:.4f}, {b:.4f}"/></emitter></shape>\n')
    for i in range(16):
        x, y, z = rng.uniform(-1.8, 1.8), rng.uniform(0.2, 1.4), rng.uniform(-1.8, 1.2)
        r, g, b = rng.uniform(0.3, 1.0, 3) * 10 ** rng.uniform(-1.2, 0.0)
        lights.append(f'<emitter type="point" id="point{i}"><point name="position" x="{x:.4f}" y="{y:.4f}" z="{z:.4f}"/>'
                      f'<rgb name="intensity" value="{r:.4f}, {g:.4f}, {b:.4f}"/></emitter>\n')
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 2.2, 3.0", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>')
            + '<shape type="sphere" id="ball"><point name="center" x="0.3" y="0.3" z="-0.2"/><float name="radius" value="0.3"/>\n'
              ' <bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.6, 0.3"/></bsdf></shape>\n'
            + "".join(lights) + "</scene>")


def _spot(folder: Path, size: int) -> str:
    spot = ('<emitter type="spot" id="spot"><transform name="to_world"><lookat origin="0.5, 1.8, 0.4" target="-0.2, 0, 0" '
            'up="0, 1, 0"/></transform><rgb name="intensity" value="12, 11, 9"/><float name="cutoff_angle" value="22"/>'
            '<float name="beam_width" value="15"/></emitter>\n')
    point = ('<emitter type="point" id="bulb"><point name="position" x="-1.2" y="1.0" z="0.8"/>'
             '<rgb name="intensity" value="0.6, 0.7, 1.0"/></emitter>\n')
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 2.2, 3.0", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>')
            + '<shape type="sphere" id="ball"><point name="center" x="0.3" y="0.3" z="-0.2"/><float name="radius" value="0.3"/>\n'
              ' <bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.6, 0.3"/></bsdf></shape>\n'
            + spot + point + "</scene>")


def _defaults(folder: Path, size: int) -> str:
    # Mitsuba's defaults: unbounded path length (max_depth -1) and the Gaussian reconstruction filter (no rfilter
    # element), in an open-fronted box of bright walls where long paths carry much of the light
    def wall(wid, rotate, translate, rgb):
        return (f'<shape type="rectangle" id="{wid}"><transform name="to_world">{rotate}<translate {translate}/>'
                f'</transform><bsdf type="diffuse"><rgb name="reflectance" value="{rgb}"/></bsdf></shape>\n')

    white = "0.9, 0.9, 0.88"
    return (HEADER.format(depth=-1, rfilter="", origin="0, 1, 3.2", size=size).replace('target="0, 0.3, 0"', 'target="0, 1, 0"')
            + wall("floor", '<rotate x="1" angle="-90"/>', 'y="0"', white)
            + wall("ceiling", '<rotate x="1" angle="90"/>', 'y="2"', white)
            + wall("back", "", 'y="1" z="-1"', white)
            + wall("left", '<rotate y="1" angle="90"/>', 'x="-1" y="1"', "0.9, 0.3, 0.25")
            + wall("right", '<rotate y="1" angle="-90"/>', 'x="1" y="1"', "0.3, 0.9, 0.3")
            + '<emitter type="point" id="bulb"><point name="position" x="0" y="1.6" z="0"/>'
              '<rgb name="intensity" value="3, 3, 3"/></emitter>\n'
            + "</scene>")


def _wrappers(folder: Path, size: int) -> str:
    from nasset_sdk.images import write_png

    write_png(folder / "flat.png", np.full((4, 4, 3), (128, 128, 255), np.uint8))  # tangent-space +Z: the mesh normal
    y, x = np.mgrid[0:64, 0:64] / 64.0  # a height field of 6 x 4 bumps (sRGB-encoded, as a painted height map is)
    write_png(folder / "bumps.png", np.repeat(np.round(255 * (0.5 + 0.25 * np.sin(6 * np.pi * x) * np.cos(4 * np.pi * y)))
                                              .astype(np.uint8)[..., None], 3, -1))
    diffuse = '<bsdf type="diffuse"><rgb name="reflectance" value="{}"/></bsdf>'

    def ball(bid, x, bsdf):
        return (f'<shape type="sphere" id="{bid}"><point name="center" x="{x}" y="0.3" z="0"/><float name="radius" '
                f'value="0.3"/>{bsdf}</shape>\n')

    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.4, 2.8", size=size)
            + FLOOR.format(bsdf='<bsdf type="blendbsdf"><float name="weight" value="0.3"/>' + diffuse.format("0.8, 0.2, 0.1")
                           + diffuse.format("0.1, 0.3, 0.8") + "</bsdf>")
            + ball("normal", -0.7, '<bsdf type="normalmap"><texture type="bitmap" name="normalmap"><string name="filename" '
                   'value="flat.png"/><boolean name="raw" value="true"/></texture>' + diffuse.format("0.7, 0.7, 0.2") + "</bsdf>")
            + ball("bump", 0.0, '<bsdf type="bumpmap"><texture type="bitmap"><string name="filename" value="bumps.png"/>'
                   '</texture><float name="scale" value="0.3"/>' + diffuse.format("0.2, 0.7, 0.7") + "</bsdf>")
            + ball("mask", 0.7, '<bsdf type="mask"><float name="opacity" value="1"/>' + diffuse.format("0.7, 0.2, 0.7") + "</bsdf>")
            + SUN + SKY + "</scene>")


def _instances(folder: Path, size: int) -> str:
    group = ('<shape type="shapegroup" id="group">\n'
             ' <shape type="sphere" id="head"><point name="center" x="0" y="0.45" z="0"/><float name="radius" value="0.15"/>'
             '<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.3, 0.1"/></bsdf></shape>\n'
             ' <shape type="cube" id="body"><transform name="to_world"><scale x="0.15" y="0.15" z="0.15"/><translate y="0.15"/>'
             '</transform><bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>\n'
             '</shape>\n')
    inst = ('<shape type="instance" id="{id}"><ref id="group"/><transform name="to_world"><rotate y="1" angle="{a}"/>'
            '<translate x="{x}" z="{z}"/></transform></shape>\n')
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.4, 2.8", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>')
            + group + inst.format(id="a", a=0, x=-0.7, z=0) + inst.format(id="b", a=30, x=0, z=-0.3)
            + inst.format(id="c", a=60, x=0.7, z=0.2) + SUN + SKY + "</scene>")


def _mesh_emitter(folder: Path, size: int) -> str:
    # an area emitter on an OBJ quad facing down (front side only, as Mitsuba emits), above a floor and a ball
    (folder / "panel.obj").write_text("v -0.4 1.6 -0.4\nv 0.4 1.6 -0.4\nv 0.4 1.6 0.4\nv -0.4 1.6 0.4\nf 1 2 3 4\n")
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.2, 2.8", size=size)
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>')
            + '<shape type="sphere" id="ball"><point name="center" x="0.2" y="0.3" z="0"/><float name="radius" value="0.3"/>'
              '<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.4, 0.2"/></bsdf></shape>\n'
            + '<shape type="obj" id="panel"><string name="filename" value="panel.obj"/>'
              '<emitter type="area"><rgb name="radiance" value="6, 6, 5"/></emitter></shape>\n'
            + "</scene>")


def _envmap(folder: Path, size: int) -> str:
    # a coarse, high-contrast lat-long map seen directly behind the objects: its interpolation shows
    from nasset_sdk.images import write_exr

    h, w = 8, 16
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    img = np.stack([0.2 + 1.5 * ((np.floor(u * 4) + np.floor(v * 2)) % 2), 0.3 + u, 0.2 + 0.8 * (1 - v)], -1)
    write_exr(folder / "sky.exr", img.astype(np.float32))
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 0.9, 2.6", size=size).replace('target="0, 0.3, 0"', 'target="0, 0.6, 0"')
            + FLOOR.format(bsdf='<bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>')
            + '<shape type="sphere" id="ball"><point name="center" x="0" y="0.4" z="0"/><float name="radius" value="0.4"/>'
              '<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf></shape>\n'
            + '<emitter type="envmap" id="sky"><string name="filename" value="sky.exr"/><transform name="to_world">'
              '<rotate y="1" angle="40"/></transform></emitter>\n'
            + "</scene>")


def _hide_emitters(folder: Path, size: int) -> str:
    # a path integrator with hide_emitters: the sky, a panel light and a light bulb in view are black to the camera,
    # and they light the floor and the ball (no sun: the panel and the bulb would cast its shadows in Mitsuba)
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.5, 2.6", size=size)
            .replace('<integer name="max_depth" value="4"/>', '<integer name="max_depth" value="4"/>'
                     '<boolean name="hide_emitters" value="true"/>').replace('target="0, 0.3, 0"', 'target="0, 0.9, 0"')
            + FLOOR.format(bsdf=GREY_DIFFUSE)
            + '<shape type="sphere" id="ball"><point name="center" x="0.3" y="0.4" z="0"/><float name="radius" value="0.4"/>'
              '<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf></shape>\n'
            + '<shape type="rectangle" id="panel"><transform name="to_world"><scale value="0.3"/><rotate y="1" angle="30"/>'
              '<translate x="-0.6" y="0.9" z="-0.3"/></transform><emitter type="area"><rgb name="radiance" value="4, 3.5, 3"/>'
              '</emitter></shape>\n'
            + '<shape type="sphere" id="bulb"><point name="center" x="0.6" y="1.1" z="-0.2"/><float name="radius" value="0.1"/>'
              '<emitter type="area"><rgb name="radiance" value="6, 6, 5"/></emitter></shape>\n'
            + SKY + "</scene>")


def _sunsky(folder: Path, size: int) -> str:
    # Mitsuba's physical sun and sky (turbidity 3), a low sun casting long shadows; the sky and the horizon in view
    return (HEADER.format(depth=4, rfilter=BOX, origin="0, 1.4, 2.6", size=size).replace('target="0, 0.3, 0"', 'target="0, 0.9, 0"')
            + _objects(box_z=-0.5).replace(SUN + SKY, "").replace("</scene>", "")  # their lights: the sunsky's
            + '<emitter type="sunsky" id="sky"><vector name="sun_direction" value="-0.6, 0.35, -0.5"/>'
              '<transform name="to_world"><rotate x="1" angle="-90"/></transform></emitter>\n'  # its up is local +Z
            + "</scene>")


def _glass(folder: Path, size: int) -> str:
    # dielectrics over a checkered floor under a sky and a rectangle light: an upright thindielectric pane (tinted), a
    # smooth dielectric ball, a roughdielectric (GGX, alpha 0.15) box
    _checker_png(folder / "floor.png", [(40, 40, 40), (220, 220, 220)], squares=8)
    floor = ('<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="floor.png"/>'
             '</texture></bsdf>')
    return (HEADER.format(depth=8, rfilter=BOX, origin="0, 1.2, 2.6", size=size)
            + FLOOR.format(bsdf=floor)
            + '<shape type="rectangle" id="pane"><transform name="to_world"><scale x="0.45" y="0.3"/>'
              '<rotate y="1" angle="20"/><translate x="-0.45" y="0.3" z="0.5"/></transform>'
              '<bsdf type="thindielectric"><rgb name="specular_transmittance" value="0.9, 1.0, 0.8"/></bsdf></shape>\n'
            + '<shape type="sphere" id="ball"><point name="center" x="0.35" y="0.3" z="0.1"/><float name="radius" '
              'value="0.3"/><bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf></shape>\n'
            + '<shape type="cube" id="box"><transform name="to_world"><scale value="0.2"/><translate x="-0.35" y="0.2" '
              'z="-0.5"/></transform><bsdf type="roughdielectric"><string name="distribution" value="ggx"/>'
              '<float name="alpha" value="0.15"/></bsdf></shape>\n'
            + '<shape type="rectangle" id="light"><boolean name="flip_normals" value="true"/><transform name="to_world">'
              '<scale value="0.4"/><rotate x="1" angle="-90"/><translate x="0.3" y="1.6" z="0.3"/></transform>'
              '<emitter type="area"><rgb name="radiance" value="6, 6, 6"/></emitter></shape>\n'
            + SKY + "</scene>")


def _uv_layouts(folder: Path, size: int) -> str:
    # one checker bitmap on the three layouts a converter must make itself: a standing cylinder with its seam
    # (phi = 0) toward the camera, a disk (polar uv) and an OBJ without texture coordinates (Mitsuba's uv there: the
    # barycentric coordinates of each triangle)
    _checker_png(folder / "check.png", [(235, 90, 40), (30, 60, 200)], squares=6)
    (folder / "prism.obj").write_text("v -0.3 0 0.3\nv 0.3 0 0.3\nv 0 0.55 0.3\nv 0 0 -0.3\n"
                                      "f 1 2 3\nf 2 4 3\nf 4 1 3\n")
    tex = ('<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="check.png"/>'
           '</texture></bsdf>')
    return (HEADER.format(depth=3, rfilter=BOX, origin="0, 1.1, 2.6", size=size)
            + FLOOR.format(bsdf=GREY_DIFFUSE)
            + '<shape type="cylinder" id="can"><transform name="to_world"><scale x="0.25" y="0.25" z="0.6"/>'
              f'<rotate x="1" angle="-90"/><rotate y="1" angle="-90"/><translate x="-0.55"/></transform>{tex}</shape>\n'
            + '<shape type="disk" id="disk"><transform name="to_world"><scale value="0.3"/><rotate x="1" angle="-60"/>'
              f'<translate x="0.05" y="0.35" z="-0.2"/></transform>{tex}</shape>\n'
            + '<shape type="obj" id="prism"><string name="filename" value="prism.obj"/><boolean name="face_normals" '
              f'value="true"/><transform name="to_world"><rotate y="1" angle="25"/><translate x="0.6" z="0.1"/></transform>{tex}'
              '</shape>\n'
            + SUN + SKY + "</scene>")


@dataclass
class FidelityScene:
    """A named scene: ``write(folder, size)`` writes its files and returns the XML text."""

    name: str
    write: object
    what: str
    unsupported: str = ""  # why the conversion does not render like Mitsuba; "" when it does
    test_spp: int = 64  # spp of its 32 x 32 test: more where Mitsuba's own image mean is noisier than the 3 % bound


SCENES = {
    "textures": FidelityScene("textures", _textures, "8-bit sRGB PNG bitmaps on a floor (diffuse, tiled and turned by "
                                      "to_uv) and a sphere (principled)"),
    "spot": FidelityScene("spot", _spot, "spot light (cutoff 22 deg, beam 15 deg) and a point light over a floor and a ball"),
    "many_lights": FidelityScene("many_lights", _many_lights, "24 small sphere emitters and 16 point lights over a floor "
                                 "and a ball, powers over 30x (lights drawn per vertex by the reference renderer, chosen by "
                                 "the vertex in the plugin)", test_spp=256),
    "defaults": FidelityScene("defaults", _defaults, "Mitsuba defaults: max_depth -1 (unbounded) and the Gaussian "
                              "reconstruction filter, bright diffuse walls"),
    "wrappers": FidelityScene("wrappers", _wrappers, "blendbsdf of two diffuse BSDFs; normalmap (flat), bumpmap (a sinusoidal height on a sphere), "
                              "mask (opaque) around diffuse BSDFs"),
    "instances": FidelityScene("instances", _instances, "shapegroup (sphere + cube) placed by three instances"),
    "mesh_emitter": FidelityScene("mesh_emitter", _mesh_emitter, "area emitter on an OBJ quad (a mesh light: "
                                  "light-sampled with MIS)"),
    "envmap": FidelityScene("envmap", _envmap, "coarse high-contrast envmap (16 x 8) seen behind a ball, rotated 40 deg"),
    "sidedness": FidelityScene("sidedness", _sidedness, "one-sided diffuse panels from the front and from behind; twosided "
                               "panels, one with a different back BSDF"),
    "lens_shift": FidelityScene("lens_shift", _lens_shift, "a sensor with its principal point offset (x 0.15, y -0.1)"),
    "pbr_textures": FidelityScene("pbr_textures", _pbr_textures, "principled BSDFs with a roughness bitmap (a raw "
                                  "checker, 0.15 / 0.85) and a metallic bitmap (0 / 1) under a low sun"),
    "emitter_texture": FidelityScene("emitter_texture", _emitter_texture, "an area emitter with a bitmap radiance (an "
                                     "sRGB checker) on a rectangle lighting a floor"),
    "curves": FidelityScene("curves", _curves, "a linearcurve of three arcs and a bsplinecurve of two loops (radius "
                            "0.03-0.05) over a floor"),
    "vertex_colors": FidelityScene("vertex_colors", _vertex_colors, "a PLY grid with a colour per vertex read by a "
                                   "mesh_attribute texture on a diffuse reflectance"),
    "normal_maps": FidelityScene("normal_maps", _normal_maps, "a normalmap BSDF on a floor: stripes leaning +-35 deg "
                                 "along u, a low sun"),
    "cutouts": FidelityScene("cutouts", _cutouts, "mask BSDFs: a panel cut by a checker bitmap opacity casting a patterned "
                             "shadow, a panel of opacity 0.4 (volpath)"),
    "orthographic": FidelityScene("orthographic", _orthographic, "an orthographic sensor (to_world scale 1.3) over a floor, "
                                  "a ball and a box"),
    "depth_of_field": FidelityScene("depth_of_field", _depth_of_field, "a thinlens sensor (aperture radius 0.35) focused on "
                                    "the ball, a box behind it and a checkered floor out of focus"),
    "texture_sampling": FidelityScene("texture_sampling", _texture_sampling, "an 8 x 8 bitmap tiled 2.5x by to_uv on "
                                      "three panels: wrap_mode clamp, mirror (filter_type nearest), repeat (nearest)"),
    "hide_emitters": FidelityScene("hide_emitters", _hide_emitters, "a path integrator with hide_emitters: a sky, a panel "
                                   "light and a light bulb in view, black to the camera, light a floor and a ball"),
    "sunsky": FidelityScene("sunsky", _sunsky, "Mitsuba's sunsky (a low sun, turbidity 3) over a floor, a ball and a box; "
                                             "the sky in view"),
    "glass": FidelityScene("glass", _glass, "dielectrics over a checkered floor: a tinted thindielectric pane, a smooth "
                           "dielectric ball, a roughdielectric box (GGX alpha 0.15), max_depth 8"),
    "uv_layouts": FidelityScene("uv_layouts", _uv_layouts, "one checker bitmap on a cylinder (its seam in view), a disk "
                                "(polar uv) and an OBJ without texture coordinates (Mitsuba reads barycentrics there)"),
    "orientation": FidelityScene("orientation", _orientation, "front sides: one-sided panels mirrored (scale -1) or with "
                                 "flip_normals, flip_normals rectangle and disk emitters, a twosided emitting panel"),
}


def psnr(img: np.ndarray, ref: np.ndarray) -> float:
    """PSNR (dB) of ``img`` against ``ref`` (both [H, W, 3]) with peak ``max(ref)``; inf for identical images."""
    mse = float(np.mean((np.asarray(img, np.float64) - ref) ** 2))
    peak = float(np.max(ref))
    return math.inf if mse <= 0 else 10.0 * math.log10(max(peak, 1e-30) ** 2 / mse)


#: renderers of the converted stage: the reference renderer, or the Mitsuba plugin (nasset_mitsuba_plugin: the same
#: engine as the source, shading the USD stage by spec/renderer.md)
RENDERERS = ("reference", "plugin")


def render_converted(stage, size: int, spp: int, renderer: str = "reference") -> tuple[np.ndarray, np.ndarray]:
    """(image [H, W, 3], its variance of the pixel mean [H, W, 3]) of a converted stage rendered by ``renderer`` (one of
    :data:`RENDERERS`) at ``size`` x ``size``; depth and pixel filter from the stage. The plugin's variance is estimated
    from a second seed, ``(p1 - p2)^2 / 2``."""
    if renderer not in RENDERERS:
        raise ValueError(f"renderer {renderer!r} is not one of {RENDERERS}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if renderer == "plugin":
            from nasset_mitsuba_plugin.render import render as plugin

            p1, p2 = (np.asarray(plugin(str(stage), spp, width=size, height=size, seed=s), np.float64) for s in (5, 6))
            return p1, 0.5 * (p1 - p2) ** 2
        from nasset_reference_renderer import RenderSettings, load_scene, render

        result = render(load_scene(str(stage)), RenderSettings(spp=spp, width=size, height=size, seed=5))
    return result.image, result.variance


def measure(name: str, folder, *, size: int = 32, spp: int = 64, renderer: str = "reference") -> dict:
    """Render scene ``name`` with Mitsuba (two seeds) and converted with ``renderer`` (module docstring,
    :func:`render_converted`).

    Returns {"ratio": [3], "psnr", "psnr_seed", "warnings": [...], "images": (mitsuba1, mitsuba2, nasset)}.
    """
    from . import load_mitsuba
    from .usd_export import convert_scene

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    xml = folder / f"{name}.xml"
    xml.write_text(SCENES[name].write(folder, size))
    mi = load_mitsuba()
    scene = mi.load_file(str(xml))
    a = np.asarray(mi.render(scene, spp=spp, seed=1), np.float64)[..., :3]
    b = np.asarray(mi.render(scene, spp=spp, seed=2), np.float64)[..., :3]
    res = convert_scene(xml, folder / f"{name}.usda", check_usd=False)
    return {**compare(a, b, *render_converted(res.output, size, spp, renderer)), "warnings": list(res.warnings)}


def excess_error(a: np.ndarray, b: np.ndarray, out: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Error map [H, W]: per pixel, the squared error of ``out`` against the mean of the source's seeds ``a``,
    ``b`` beyond what the noise of both explains, summed over channels (all inputs [H, W, 3], ``variance`` is
    ``out``'s variance of the pixel mean): ``|out - (a + b) / 2|^2 - |a - b|^2 / 4 - variance``. Its expectation
    is the squared bias (0 where the conversion is faithful); single pixels are noisy (and may be negative), so
    read it summed over regions."""
    m = 0.5 * (a + b)
    return (((out - m) ** 2 - 0.25 * (a - b) ** 2) - variance).sum(-1)


def compare(a: np.ndarray, b: np.ndarray, out: np.ndarray, variance: np.ndarray) -> dict:
    """Measures of the reference renderer's image ``out`` against the source renderer's seeds ``a``, ``b`` (all
    [H, W, 3]); ``variance`` [H, W, 3] is ``out``'s variance of the pixel mean (module docstring).

    Returns {"ratio": [3], "psnr", "psnr_seed", "noise_ratio", "images": (a, b, out), "excess": :func:`excess_error`}.
    """
    ratio = out.reshape(-1, 3).mean(0) / np.maximum(a.reshape(-1, 3).mean(0), 1e-30)
    seed_mse, var = float(np.mean((a - b) ** 2)), float(np.mean(variance))
    noise = seed_mse / 2.0 + var
    mse = float(np.mean((out - a) ** 2))
    noise_ratio = mse / max(noise, 1e-300)
    # the MSE with the reference renderer's own noise replaced by the source's (half the seed-to-seed MSE): the
    # PSNR it would reach at the source's noise level, comparable with psnr_seed (equal for a faithful conversion)
    # (at least half the seed-to-seed MSE: where the variance estimate exceeds the MSE the excess is noise too)
    mse_eq = max(mse - var + seed_mse / 2.0, seed_mse / 2.0, 1e-300)
    psnr_eq = 10.0 * math.log10(max(float(np.max(a)), 1e-30) ** 2 / mse_eq)
    return {"ratio": ratio.tolist(), "psnr": psnr(out, a), "psnr_seed": psnr(b, a), "noise_ratio": noise_ratio,
            "psnr_eq": psnr_eq, "images": (a, b, out), "excess": excess_error(a, b, out, variance)}


def table(results: dict, scenes: dict | None = None, source: str = "Mitsuba") -> str:
    """Markdown table of ``measure`` results keyed by scene name (``scenes``: their FidelityScenes, default ours)."""
    scenes = SCENES if scenes is None else scenes
    owner = source + ("'" if source.endswith("s") else "'s")
    rows = [f"| scene | what | ratio R / G / B | PSNR (dB) | {source} seed-to-seed PSNR (dB) | PSNR at {owner} noise (dB) "
            "| MSE / noise |", "|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        ratio = " / ".join(f"{x:.3f}" for x in r["ratio"])
        what = scenes[name].what + (f" (**unsupported**: {scenes[name].unsupported})" if scenes[name].unsupported else "")
        rows.append(f"| {name} | {what} | {ratio} | {r['psnr']:.1f} | {r['psnr_seed']:.1f} | {r['psnr_eq']:.1f} | "
                    f"{r['noise_ratio']:.2f} |")
    return "\n".join(rows) + "\n"


def write_section(path, heading: str, body: str) -> None:
    """Replace the section ``heading`` (a ``## `` line, up to the next ``## `` line) of the markdown file ``path``
    with ``body``, or append it; the file is written atomically (created with a title if missing)."""
    from nasset_sdk.images import atomic_output

    path = Path(path)
    text = path.read_text() if path.is_file() else "# Conversion fidelity\n"
    lines = text.splitlines(keepends=True)
    start = next((i for i, ln in enumerate(lines) if ln.rstrip("\n") == heading), None)
    section = [heading + "\n", "\n", body if body.endswith("\n") else body + "\n"]
    if start is None:
        lines += (["\n"] if lines and lines[-1].strip() else []) + section
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        lines[start:end] = section + (["\n"] if end < len(lines) else [])
    with atomic_output(path, "fidelity table") as tmp:
        Path(tmp).write_text("".join(lines))


NOTES = """
- *ratio*: mean of the reference renderer's image over Mitsuba's (seed 1), per channel. *PSNR*: against
  Mitsuba seed 1, peak = its maximum; the seed-to-seed PSNR (Mitsuba seed 2 against seed 1) is the
  ceiling set by Mitsuba's noise. *MSE / noise*: the MSE against Mitsuba over what the two images'
  noise explains (half Mitsuba's seed-to-seed MSE plus the reference renderer's variance of the
  pixel mean); about 1 when the conversion is faithful.
- *PSNR at Mitsuba's noise*: the PSNR with the reference renderer's variance in the MSE replaced by
  Mitsuba's (half its seed-to-seed MSE); for a faithful conversion it equals the seed-to-seed PSNR, so the
  "within 3 dB of the seed-to-seed PSNR" target is read on this column.
- A PSNR below the seed-to-seed PSNR with MSE / noise near 1 is the reference renderer being noisier
  than Mitsuba at equal spp, not a conversion error (defaults: Gaussian filter drawn by importance
  sampling, and Russian roulette from depth 3).
- mesh_emitter was 0.9 % dark with MSE / noise 1.7: the renderer's shadow rays toward an emitting mesh left the
  offset origin along the direction sampled from the unoffset point, so at grazing angles they met the emitter's
  own plane before their end and were shadowed by the light itself (a floor point 3 m beside a panel 1 m up
  got 0 instead of its irradiance). They are now aimed at the light sample from the offset origin, at mesh
  vertices and neural-asset hits alike (spec/renderer.md#ray-offsets).
- uv_layouts was 2.96 (64 x 64, 64 spp; the reference renderer): the OBJ without texture coordinates read the bitmap's corner texel
  where Mitsuba reads each triangle's barycentrics, the disk had no uv (Mitsuba's is polar), and the cylinder's faces across
  phi = 0 ran u back from 0.995 to 0. All three are faceVarying `st` now (spec/bake.md#shapes).
- Residual: envmap keeps MSE / noise 1.7 from the resampled map (8x, nearest texels) against Mitsuba's
  bilinear lookup.
- Before these conversions the issue measured (ratio, PSNR vs seed-to-seed): 8-bit textures 1.8-2.0
  (10.2 vs 35.4 dB), spot 4.5-5.3 (9.4 vs 37.2), instances dropped 1.07-1.19 (24.5 vs 42.0),
  one-sided back faces 0.88-2.01 (15.9 vs 36.4), mesh emitter 1.02 (24.3 vs 37.6).
- orientation was 1.25 / 1.15 / 1.06 with MSE / noise 474 (96 x 96, 64 spp): the renderer took the world winding's
  right-hand side as every prim's front (a mirrored prim keeps its own front in USD), the back of an emitter
  emitted, and the converter wrote Mitsuba's `flip_normals` and a mirroring `to_world` as if absent (a flipped
  rectangle emitter lit the other side). Mitsuba's front is now read off each shape (a sampled position's
  normal), the renderer follows USD's effective orientation, and an emitter's back material has no emission
  (spec/renderer.md#sidedness).
- textures read 0.99 / 0.99 / 1.01 with MSE / noise 58 (64 x 64, 64 spp) once its floor bitmap had a `to_uv`
  (scale 2 x 1.5, 20 deg, offset): the transform was dropped (warned). It is now the texture's UsdTransform2d
  (spec/renderer.md#textures).
- lens_shift was 1.05 / 1.04 / 1.02 with MSE / noise 21.5 (64 x 64, 64 spp): the principal point offset was
  dropped (warned). It is now the camera's aperture offsets, which the renderer applies
  (spec/renderer.md#cameras).
- orthographic had no camera at all (an orthographic sensor was not converted: nothing rendered), and
  depth_of_field read MSE / noise 5.8 (32 x 32, 64 spp; 1.02 now): the thinlens sensor was written as a pinhole.
  They are now an orthographic camera (apertures from the to_world scale) and the thin lens of `fStop` and
  `focusDistance`, in USD's lens unit (spec/renderer.md#cameras).
- cutouts read MSE / noise 12.5 (32 x 32, 64 spp; 1.04 now) while the renderer drew every surface opaque: a mask's
  opacity is now presence (spec/renderer.md#cutouts), a bitmap opacity a texture of its luminance. Mitsuba's `path`
  integrator stops shadow rays at a mask whatever its opacity (measured: no light through opacity 0.25, where
  `volpath` passes 0.75); the converted scene passes them as `volpath` does, warned for `path` scenes.
- pbr_textures read MSE / noise 2.1 (32 x 32, 64 spp; 1.3 now): bitmaps on principled roughness and metallic were
  written as their means and the renderer textured diffuseColor only. They are now grey textures on roughness and
  metallic, which the renderer reads per hit (spec/renderer.md#textures). What remains is the principled
  conversion's 1-2 % (the floor), not the textures.
- emitter_texture read MSE / noise 71 (32 x 32, 64 spp; 0.92 now): an area emitter's bitmap radiance was written as
  its mean (a RectLight). A textured emitter is now a mesh with a textured emissiveColor, which the renderer reads per
  hit and per light sample (spec/renderer.md#textures).
- curves read MSE / noise 5.7 (32 x 32, 64 spp; 1.04 now): linearcurve and bsplinecurve shapes were skipped (and a
  scene with BasisCurves was refused by the renderer). They are now BasisCurves (linear, or cubic B-spline) of their
  control points and radii, which the renderer draws as tubes (spec/renderer.md#curves-and-points).
- vertex_colors read MSE / noise 11.6 (32 x 32, 64 spp; 1.1 now): a mesh_attribute reflectance was written as grey
  0.5 without a warning. It is now a colour primvar of the mesh read by a UsdPrimvarReader_float3
  (spec/renderer.md#primvar-colors).
- normal_maps read ratio 1.15 and MSE / noise 17 (32 x 32, 64 spp; 1.04 now): the converter wrote the normalmap to
  UsdPreviewSurface normal, which the renderer ignored. It now turns the shading normal in Mitsuba's frame and
  applies Mitsuba's default bump-terminator term (spec/renderer.md#normal-maps).
- Beckmann roughness (Mitsuba's default distribution of `roughconductor` and `roughplastic`; not in the table): a
  twosided aluminium floor at alpha 0.4 read 1.17 / 1.13 / 1.08, MSE / noise 32.9 (32 x 32, 256 spp), the same floor
  with `distribution="ggx"` ratio 1.01, MSE / noise 1.24. A Beckmann alpha is now written as the GGX alpha whose lobe is closest
  (spec/bake.md#materials): 24.0; a mirror floor at 0.7 28.0 -> 24.0 (20 % dark: GGX keeps less energy at high
  roughness), a copper ball at 0.3 3.55 -> 2.62. What was left needed a lobe UsdPreviewSurface does not have: since
  2026-12-07 the material says `nasset:microfacet = beckmann` (spec/renderer.md#materials) and the three renderers
  draw Beckmann's lobe. Side by side with the GGX stand-in (32 x 32, 256 spp): the aluminium floor 1.13, MSE / noise
  8.86 -> 1.004, 1.00; the mirror floor at 0.7 0.90, 23.3 -> 1.002, 0.98; the copper ball 3.86 -> 1.12.
- bumpmap (the `wrappers` ball, a sinusoidal height at scale 0.3) read MSE / noise 2.1 (32 x 32, 64 spp; 1.0 now)
  while its bump was dropped. The height is now written as the tangent-space normal map it amounts to on the shape's
  uv layout (spec/bake.md#materials). A floor of sinusoidal stripes (32 x 32, 64 spp) read 1.22 (MSE / noise 31) at
  bump scale 0.5 and 1.44 (79) at scale 2 while dropped; converted, 1.025 (4.1) and 1.17 (31): steep bumps stay
  brighter, as 12 % and 30 % of that floor face away from the camera, which Mitsuba shades black and the renderer
  with the unmapped normal (spec/renderer.md#normal-maps). A ball and a box with moderate bumps: 1.019 (2.1) -> 1.00
  (0.95).
- glass (dielectric, roughdielectric, thindielectric) read 0.811 / 0.807 / 0.829, MSE / noise 67 (64 x 64, 128 spp)
  while every dielectric was written as an opaque black reflector. They are now written as a MaterialX
  standard_surface with transmission (spec/renderer.md#transmission), which the reference renderer and the plugin
  render: 0.997, 1.39. A dielectric box resting on a floor (its bottom face and the floor coincide) still reads 0.977,
  MSE / noise 10.8 (48 x 48, 128 spp; 1.005, 1.05 lifted 0.1): a ray leaving the glass there starts past the floor in
  the renderer; each renderer resolves coincident surfaces its own way.
- Not converted: an area emitter on a null BSDF. Mitsuba's path tracer does not show it to the camera and
  lights the scene from it by emitter samples only, which no USD light reproduces; the shape is skipped with
  a warning.
"""

PLUGIN_NOTES = """
- Before 2026-12-07 the plugin rendered 10 of these 21 stages: the other 11 hold implicit prims (the converter writes
  Mitsuba's spheres as `UsdGeom.Sphere`) or BasisCurves, which it refused (`SCENE_UNSUPPORTED`). Of the 10, six were
  wrong (64 x 64, 128 spp, MSE / noise): textures 71 (grey), texture_sampling 231, vertex_colors 150 (primvar colours
  as their mean), emitter_texture 461 (the input's own value), normal_maps 37 (flat), cutouts 13 (opaque). It now
  tessellates implicit prims and curves as the reference renderer does (`nasset_sdk.implicit`, `nasset_sdk.curves`),
  and shades smooth normals, textures, primvar colours, emissive textures, normal maps and cut-outs per hit
  (`mitsuba_plugin/textures.py`, docs/bench-mitsuba-jit.md).
"""


def main(argv=None) -> int:
    """Measure every scene and write the table (``--out``, default docs/conversion-fidelity.md)."""
    import tempfile

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/conversion-fidelity.md")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--renderer", choices=RENDERERS, default="reference",
                    help="what renders the converted stage: the reference renderer, or the Mitsuba plugin")
    args = ap.parse_args(argv)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            results[name] = measure(name, Path(tmp) / name, size=args.size, spp=args.spp, renderer=args.renderer)
            print(name, {k: v for k, v in results[name].items() if k in ("ratio", "psnr", "psnr_seed", "noise_ratio")},
                  flush=True)
    if args.renderer == "plugin":
        text = (f"Generated by `python -m nasset_converters.mitsuba.fidelity --renderer plugin --size {args.size} --spp "
                f"{args.spp}` ({args.size} x {args.size} pixels, {args.spp} spp for both; the plugin's variance from a "
                "second seed). The scenes of the section above, their converted stages rendered by the Mitsuba plugin "
                "(`python -m nasset_mitsuba_plugin.render`): the same engine as the source, with the USD rules of "
                "spec/renderer.md. `tests/converters/test_conversion_fidelity.py` runs them at 32 x 32, 64 spp.\n\n"
                + table(results) + PLUGIN_NOTES)
        write_section(args.out, "## Mitsuba plugin (Mitsuba -> convert-scene -> Mitsuba plugin)", text)
        return 0
    text = (f"Generated by `python -m nasset_converters.mitsuba.fidelity --size {args.size} --spp {args.spp}` "
            f"({args.size} x {args.size} pixels, {args.spp} spp for both renderers); scenes and measures are defined in "
            "`converters/mitsuba/fidelity.py`, and `tests/converters/test_conversion_fidelity.py` runs them at "
            "32 x 32, 64 spp.\n\n" + table(results) + NOTES)
    write_section(args.out, "## Mitsuba (Mitsuba -> convert-scene -> nasset render)", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
