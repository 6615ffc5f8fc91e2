"""A shader input fed by nodes the converter cannot map (procedural textures) baked by Cycles into an image texture.

A Noise, Voronoi, Checker, Wave, Gradient, Magic or Brick texture, a Color Ramp on one, any node chain that is not
an Image Texture through foldable nodes (:mod:`texel_ops`): Cycles evaluates it per shading point. Routed into an
Emission shader (strength 1) on the Material Output of a temporary copy of the material and baked with Cycles'
bake API (``bpy.ops.object.bake(type='EMIT')``) over the object's active render UV map, the input's value at every
point of the surface lands in a linear float image (a colour as it is, a float grey), which the stage reads through
``st`` like any image texture. The object's own Texture Coordinate (Generated, Object, UV) is what Cycles evaluates
during the bake, on the object itself: the image is right for those coordinates, once per object (Generated
coordinates follow each object's bounds). Resolution: twice the object's extent on screen in render pixels, a power
of two within BAKE_MIN..BAKE_MAX (BAKE_MAX without a camera or for an object reaching behind it, BAKE_BEHIND
for one wholly behind it). Cost measured on two cores: 0.01-0.02 s per object at
64 x 64, 0.1-0.2 s at 256 x 256, 1.5-3.1 s at 1024 x 1024 (spec/bake-blender.md#scene-conversion).
"""

from __future__ import annotations

import math

import numpy as np

#: baked image sizes (square, power of two)
BAKE_MIN, BAKE_MAX = 64, 1024
#: size for an object wholly behind the camera
BAKE_BEHIND = 256
#: Cycles samples per texel (anti-aliasing within the texel)
BAKE_SAMPLES = 4
#: Texture Coordinate outputs and nodes whose values depend on where an object is placed, not on its mesh
_PLACED_OUTPUTS = ("Camera", "Window", "Reflection")
_PLACED_NODES = ("ShaderNodeNewGeometry", "ShaderNodeCameraData", "ShaderNodeLightPath", "ShaderNodeObjectInfo")


def bake_size(bpy, ob) -> int:
    """Twice the longest side of ``ob``'s bounding box on screen (render pixels), a power of two in
    [BAKE_MIN, BAKE_MAX]; BAKE_MAX when the scene has no camera or the box reaches behind it, BAKE_BEHIND when it lies
    wholly behind it."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    scene = bpy.context.scene
    if scene.camera is None:
        return BAKE_MAX
    r = scene.render
    res = np.array([r.resolution_x, r.resolution_y]) * r.resolution_percentage / 100.0
    pts = np.array([tuple(world_to_camera_view(scene, scene.camera, ob.matrix_world @ Vector(c)))
                    for c in ob.bound_box])
    if np.all(pts[:, 2] <= 0.0):  # behind the camera: seen in reflections and lighting only
        return BAKE_BEHIND
    if np.any(pts[:, 2] <= 0.0):  # reaching behind the camera (a floor under it): close to it
        return BAKE_MAX
    extent = float(((pts[:, :2].max(0) - pts[:, :2].min(0)).clip(0.0, 2.0) * res).max())
    return int(np.clip(2 ** math.ceil(math.log2(max(2.0 * extent, 1.0))), BAKE_MIN, BAKE_MAX))


def reads_placement(socket) -> bool:
    """Whether the nodes feeding ``socket`` read where the object is placed (world position, camera, an object's
    frame): instances of one mesh then differ, which one image per mesh cannot hold."""
    seen, todo = set(), [socket]
    while todo:
        for link in todo.pop().links:
            node = link.from_node
            if node.bl_idname in _PLACED_NODES or (node.bl_idname == "ShaderNodeTexCoord" and (
                    link.from_socket.name in _PLACED_OUTPUTS or (link.from_socket.name == "Object" and node.object))):
                return True
            if node.name not in seen:
                seen.add(node.name)
                todo.extend(s for s in node.inputs if s.is_linked)
    return False


def bake_input(bpy, ob, material, socket, size: int, normal: bool = False) -> np.ndarray:
    """Linear values [size, size, 3] (top row first) of input ``socket`` of a node of ``material`` over ``ob``'s
    active render UV map, baked by Cycles (module docstring). ``normal``: instead, the material's shading normal
    (its Bump and Normal Map nodes, and a bump-only Displacement, as Cycles applies them) in the tangent space of that
    UV map, encoded ``(n + 1) / 2`` (Cycles' ``NORMAL`` bake, +X +Y +Z: the frame of renderer.md#normal-maps).
    ``ob``'s material slots, the selection and the render settings are put back; the temporary material and image
    are removed. Raises RuntimeError (Cycles' message) when Cycles cannot bake the object."""
    from . import quiet_stdout

    scene, layer = bpy.context.scene, bpy.context.view_layer
    tmp = material.copy()
    img = bpy.data.images.new("nasset_bake", size, size, alpha=False, float_buffer=True)
    slots = [s.material for s in ob.material_slots]
    selected = [o for o in layer.objects if o.select_get()]
    active, engine = layer.objects.active, scene.render.engine
    c = scene.cycles
    settings = (c.samples, c.use_denoising, c.use_adaptive_sampling, c.device)
    outside = ob.name not in layer.objects  # a collection instance's object: linked into the scene for the bake
    try:
        if outside:
            scene.collection.objects.link(ob)
        nt = tmp.node_tree
        out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output)
        for name in ("Volume",) if normal else ("Volume", "Displacement"):
            for link in list(out.inputs[name].links):
                nt.links.remove(link)
        if not normal:
            src = next(s for s in nt.nodes[socket.node.name].inputs if s.identifier == socket.identifier)
            feed = src.links[0].from_socket
            emit = nt.nodes.new("ShaderNodeEmission")
            emit.inputs["Strength"].default_value = 1.0
            nt.links.new(feed, emit.inputs["Color"])  # a float becomes grey, as Cycles converts it
            nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
        target = nt.nodes.new("ShaderNodeTexImage")
        target.image = img
        nt.nodes.active = target
        for s in ob.material_slots:  # every face bakes the chain (faces of other slots: their own UV area)
            s.material = tmp
        for o in selected:
            o.select_set(False)
        ob.select_set(True)
        layer.objects.active = ob
        scene.render.engine = "CYCLES"
        c.samples, c.use_denoising, c.use_adaptive_sampling, c.device = BAKE_SAMPLES, False, False, "CPU"
        with quiet_stdout():
            if normal:
                bpy.ops.object.bake(type="NORMAL", normal_space="TANGENT", normal_r="POS_X", normal_g="POS_Y",
                                    normal_b="POS_Z", margin=max(2, size // 64), use_clear=True, target="IMAGE_TEXTURES")
            else:
                bpy.ops.object.bake(type="EMIT", margin=max(2, size // 64), use_clear=True, target="IMAGE_TEXTURES")
        px = np.array(img.pixels[:], np.float64).reshape(size, size, 4)[::-1, :, :3]  # Blender rows bottom-up
    finally:
        for s, m in zip(ob.material_slots, slots, strict=False):
            s.material = m
        if outside:
            scene.collection.objects.unlink(ob)
        else:
            ob.select_set(False)
        for o in selected:
            o.select_set(True)
        layer.objects.active = active
        scene.render.engine = engine
        c.samples, c.use_denoising, c.use_adaptive_sampling, c.device = settings
        bpy.data.materials.remove(tmp)
        bpy.data.images.remove(img)
    return np.nan_to_num(px, nan=0.0, posinf=0.0, neginf=0.0)


def uv_triangles(mesh, uv_name: str, slots, n_slots: int) -> np.ndarray:
    """UVs [T, 3, 2] of an (evaluated) mesh's triangles whose material slot is one of ``slots`` (of ``n_slots``;
    indices past the last slot read the last one, as Cycles does)."""
    mesh.calc_loop_triangles()
    n = len(mesh.loop_triangles)
    loops, index = np.zeros(3 * n, np.int64), np.zeros(n, np.int64)
    mesh.loop_triangles.foreach_get("loops", loops)
    mesh.loop_triangles.foreach_get("material_index", index)
    uv = np.zeros(2 * len(mesh.loops))
    mesh.uv_layers[uv_name].data.foreach_get("uv", uv)
    keep = np.isin(np.minimum(index, max(n_slots, 1) - 1), list(slots))
    return uv.reshape(-1, 2)[loops].reshape(-1, 3, 2)[keep]


#: texels of the grid :func:`uv_overlap` tests (at most; fewer when the triangles' boxes would cover more than
#: OVERLAP_BUDGET texel tests)
OVERLAP_GRID = 256
OVERLAP_BUDGET = 1 << 24


def uv_overlap(tris: np.ndarray) -> float:
    """The fraction of the texel centres covered by UV triangles ``tris`` [T, 3, 2] that more than one triangle
    covers: mirrored or stacked UV islands, whose texels a bake fills with one part's values only. A grid of
    OVERLAP_GRID texels a side (coarser when the triangles' boxes are large), tested in chunks of bounded size."""
    tris = np.asarray(tris, np.float64)
    tris = tris[np.abs(_cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])) > 1e-12]
    if not len(tris):
        return 0.0
    res = OVERLAP_GRID
    while res > 16 and _box_texels(tris, res).sum() > OVERLAP_BUDGET:
        res //= 2
    p = tris * res - 0.5 + np.array([1.3e-4, 1.7e-4])  # texel centres at integer coordinates, off any shared edge
    lo = np.ceil(p.min(1)).astype(np.int64)
    size = np.maximum(np.floor(p.max(1)).astype(np.int64) - lo + 1, 0)
    count = np.zeros(res * res, np.int64)
    kind = 2 ** np.ceil(np.log2(np.maximum(size.max(1), 1))).astype(np.int64)
    for k in np.unique(kind):  # triangles by box size class
        idx = np.nonzero(kind == k)[0]
        off = np.stack(np.meshgrid(np.arange(k), np.arange(k), indexing="xy"), -1).reshape(-1, 2)
        step = max(1, (1 << 22) // len(off))
        for s in range(0, len(idx), step):
            j = idx[s:s + step]
            q = lo[j, None, :] + off[None]  # [t, k*k, 2] candidate texel centres
            a, b, c = (p[j, n, None, :] for n in range(3))
            e = np.stack([_cross(b - a, q - a), _cross(c - b, q - b), _cross(a - c, q - c)], -1)
            inside = (np.all(e >= 0, -1) | np.all(e <= 0, -1)) & np.all((q >= 0) & (q < res), -1)
            inside &= np.all(q < lo[j, None, :] + size[j, None, :], -1)
            hits = q[inside]
            count += np.bincount(hits[:, 1] * res + hits[:, 0], minlength=res * res)
    covered = int((count > 0).sum())
    return float((count > 1).sum()) / covered if covered else 0.0


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _box_texels(tris, res: int) -> np.ndarray:
    ext = (tris.max(1) - tris.min(1)) * res + 1.0
    return ext[:, 0] * ext[:, 1]
