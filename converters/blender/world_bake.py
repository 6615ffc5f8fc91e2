"""A Blender world the converter cannot map node by node, rendered by Cycles into a lat-long map.

Sky Texture, gradients and noise, shader mixes, a Strength from nodes, a mirror-ball environment: whatever the
world's node tree computes per direction, Cycles' equirectangular panoramic camera at the origin sees it. The camera
is turned (local -Z to world +X, local +Y to world +Z) so that the rendered image has the layout of an Environment
Texture's pixels (rows top-down, +X at the centre column; measured: the render of an Environment Texture world
matches its source image to the interpolation), and goes through the same dome mapping. The render uses a
temporary scene holding only the camera and the world: the file's own scene is not touched.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

#: size of the rendered map (lat-long, 2:1) and Cycles samples per texel
WORLD_WIDTH = 1024
WORLD_SPP = 16


def render_world(bpy, world, width: int = WORLD_WIDTH, spp: int = WORLD_SPP) -> np.ndarray:
    """Radiance [width / 2, width, 3] of ``world`` per direction, rows top-down, as an Environment Texture's pixels.
    The world's camera ray visibility is switched on for the render and put back."""
    import OpenEXR

    from . import quiet_stdout

    scene = bpy.data.scenes.new("nasset_world_bake")
    cam = bpy.data.cameras.new("nasset_world_bake")
    ob = bpy.data.objects.new("nasset_world_bake", cam)
    shown = world.cycles_visibility.camera
    try:
        cam.type, cam.panorama_type = "PANO", "EQUIRECTANGULAR"
        scene.collection.objects.link(ob)
        scene.camera, scene.world = ob, world
        ob.rotation_euler = (math.pi / 2.0, 0.0, -math.pi / 2.0)
        r, c = scene.render, scene.cycles
        r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage = "CYCLES", int(width), int(width) // 2, 100
        r.film_transparent = False
        r.image_settings.file_format, r.image_settings.color_depth = "OPEN_EXR", "32"
        r.image_settings.color_mode = "RGB"
        scene.view_settings.view_transform = "Standard"
        c.device, c.samples, c.use_denoising, c.use_adaptive_sampling = "CPU", int(spp), False, False
        c.pixel_filter_type, c.filter_width = "BOX", 1.0
        world.cycles_visibility.camera = True
        with tempfile.TemporaryDirectory() as tmp:
            r.filepath = str(Path(tmp) / "world.exr")
            with quiet_stdout():
                bpy.ops.render.render(write_still=True, scene=scene.name)
            with OpenEXR.File(r.filepath) as f:
                ch = f.parts[0].channels
                px = np.asarray(ch["RGB"].pixels, np.float32) if "RGB" in ch else np.stack(
                    [np.asarray(ch[k].pixels, np.float32) for k in "RGB"], -1)
    finally:
        world.cycles_visibility.camera = shown
        bpy.data.objects.remove(ob)
        bpy.data.cameras.remove(cam)
        bpy.data.scenes.remove(scene)
    return np.nan_to_num(np.maximum(px, 0.0), nan=0.0, posinf=0.0)


def reads_light_path(tree) -> bool:
    """Whether a world's node tree reads the Light Path node (camera rays then see another world than lighting does:
    the render shows what camera rays see)."""
    return any(n.bl_idname == "ShaderNodeLightPath" for n in tree.nodes)
