"""Make Blender's context depsgraph evaluate a scene as Cycles renders it (spec/bake-blender.md#scene-conversion).

Python only reaches the *viewport* depsgraph (``bpy.context.evaluated_depsgraph_get``), which evaluates
with the viewport's settings: Subdivision Surface and Multires ``levels`` instead of ``render_levels``,
modifiers shown in the viewport instead of those enabled in renders, a curve's ``resolution_u`` instead
of ``render_resolution_u``, a metaball's ``resolution`` instead of ``render_resolution``, particle
systems' display amount and method, Simplify's viewport limits, and objects or collections hidden in
the viewport left out (with the instances they place). Cycles renders with the render settings, so
before, the converter and the bake read other geometry than Cycles renders (a cube under a Subdivision
Surface of viewport level 0 and render level 2 was written as its 12 triangles).

:func:`evaluate_as_render` copies each render setting onto its viewport counterpart in the open file
(the file is not saved; Cycles' own renders read the render settings either way). What no setting
carries (a Geometry Nodes *Is Viewport* node, adaptive subdivision) comes back as notes.
"""

from __future__ import annotations


def _mirror(owner, attr: str, value, notes: list, what: str) -> None:
    """``owner.attr = value`` where they differ; a note naming ``what`` when Blender refuses (linked data)."""
    if getattr(owner, attr) == value:
        return
    try:
        setattr(owner, attr, value)
    except (AttributeError, TypeError, ValueError, RuntimeError) as exc:
        notes.append(f"{what}: its viewport {attr} {getattr(owner, attr)!r} differs from the render value {value!r} "
                     f"and cannot be changed ({str(exc).splitlines()[0][:120]}): evaluated as in the viewport")


def _reads_is_viewport(tree, seen: set) -> bool:
    """Whether a node tree (or a group inside it) has an Is Viewport node."""
    if tree is None or tree.as_pointer() in seen:
        return False
    seen.add(tree.as_pointer())
    for node in tree.nodes:
        if node.bl_idname == "GeometryNodeIsViewport":
            return True
        if getattr(node, "node_tree", None) is not None and _reads_is_viewport(node.node_tree, seen):
            return True
    return False


def evaluate_as_render(bpy) -> list[str]:
    """Copy the render settings of the open file onto the viewport ones the context depsgraph evaluates with
    (module docstring), update the view layer, and return notes on what still differs. Idempotent."""
    notes: list[str] = []
    scene = bpy.context.scene
    r = scene.render
    _mirror(r, "simplify_subdivision", r.simplify_subdivision_render, notes, "scene Simplify")
    _mirror(r, "simplify_child_particles", r.simplify_child_particles_render, notes, "scene Simplify")
    for ob in bpy.data.objects:
        what = f"object {ob.name}"
        if not ob.hide_render:
            _mirror(ob, "hide_viewport", False, notes, what)
        _mirror(ob, "show_instancer_for_viewport", ob.show_instancer_for_render, notes, what)
        for mod in ob.modifiers:
            where = f"{what}, modifier {mod.name}"
            _mirror(mod, "show_viewport", mod.show_render, notes, where)
            if mod.type in ("SUBSURF", "MULTIRES"):
                _mirror(mod, "levels", mod.render_levels, notes, where)
            if mod.show_render and getattr(mod, "use_adaptive_subdivision", False):
                notes.append(f"{where}: adaptive subdivision (Cycles dices by pixel size) written at the modifier's "
                             f"render levels ({mod.render_levels})")
            if mod.type == "NODES" and mod.show_render and _reads_is_viewport(mod.node_group, set()):
                notes.append(f"{where}: its node group {mod.node_group.name!r} reads Is Viewport, which is true here: "
                             "the viewport branch is written (Cycles renders the other)")
    for ob in bpy.context.view_layer.objects:
        if ob.hide_get():  # hidden in the viewport (eye): Cycles renders it
            ob.hide_set(False)
    for coll in bpy.data.collections:
        if not coll.hide_render:
            _mirror(coll, "hide_viewport", False, notes, f"collection {coll.name}")

    def show_layers(layer):
        for child in layer.children:
            _mirror(child, "hide_viewport", False, notes, f"collection {child.name}")
            show_layers(child)

    show_layers(bpy.context.view_layer.layer_collection)
    for cu in bpy.data.curves:  # curves, surfaces, text: a render resolution of 0 means the viewport one
        for axis in ("u", "v"):
            render = getattr(cu, f"render_resolution_{axis}")
            if render > 0:
                _mirror(cu, f"resolution_{axis}", render, notes, f"curve {cu.name}")
    for mb in bpy.data.metaballs:
        _mirror(mb, "resolution", mb.render_resolution, notes, f"metaball {mb.name}")
    for st in bpy.data.particles:
        what = f"particle settings {st.name}"
        _mirror(st, "display_method", "RENDER", notes, what)
        _mirror(st, "display_percentage", 100, notes, what)
        _mirror(st, "display_step", st.render_step, notes, what)
        _mirror(st, "child_percent", st.rendered_child_count, notes, what)
    bpy.context.view_layer.update()
    return notes


def hidden_original(ob) -> bool:
    """Whether Cycles leaves out ``ob``'s own surface although it is render-visible: its parent instances it on
    vertices or faces (Blender hides such originals in renders, shows them in the viewport), or it is an instancer
    (instances, particle systems) with Show Instancer for Render off."""
    parent = ob.parent
    if parent is not None and parent.instance_type in ("VERTS", "FACES"):
        return True
    instancer = ob.instance_type != "NONE" or len(getattr(ob, "particle_systems", ())) > 0
    return instancer and not ob.show_instancer_for_render
