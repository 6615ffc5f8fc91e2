"""A node tree's links as Cycles evaluates them (spec/bake-blender.md#scene-conversion).

Cycles ignores muted and invalid links (the input keeps its own value), passes a Reroute node or a muted node
through (the node's internal link; a muted node without one gives nothing: a muted shader is no shader), and
reads an RGB or Value node as its constant. :func:`resolved_copy` writes these rules into a temporary copy of a
material so the mapping reads plain links: every link reaches a node that computes something, and constants sit
in the sockets they feed. Measured with Cycles (Blender 5.0): a muted link of a blue RGB node into a red Diffuse
BSDF renders red; a muted Invert node and a Reroute between them render blue; a Material Output without a Surface
link and a muted Diffuse BSDF render black.
"""

from __future__ import annotations

from contextlib import contextmanager

#: socket types whose values :func:`_fold` converts
_VALUE_TYPES = ("RGBA", "VALUE", "VECTOR")
#: nodes whose output is a constant held by the output socket itself
_CONSTANT_NODES = ("ShaderNodeRGB", "ShaderNodeValue")


def _passes_through(node) -> bool:
    return node.bl_idname == "NodeReroute" or node.mute


def _live(socket) -> list:
    return [link for link in socket.links if not link.is_muted and link.is_valid]


class _Constant:
    def __init__(self, socket) -> None:
        self.type, self.value = socket.type, _value(socket.default_value)


def _value(v):
    try:
        return tuple(float(x) for x in v)
    except TypeError:
        return float(v)


def _source(output, depth: int = 0):
    """What feeds whatever reads ``output`` (an output socket): a real node's output socket, a :class:`_Constant`,
    or None (nothing: the reader keeps its own value)."""
    node = output.node
    if node.bl_idname in _CONSTANT_NODES:
        return _Constant(output)
    if not _passes_through(node):
        return output
    if depth > 256:
        return None
    if node.bl_idname == "NodeReroute":
        inp = node.inputs[0]
    else:
        inp = next((link.from_socket for link in node.internal_links if link.to_socket == output), None)
        if inp is None:
            return None
    live = _live(inp)
    if live:
        return _source(live[0].from_socket, depth + 1)
    return _Constant(inp) if inp.type in _VALUE_TYPES and hasattr(inp, "default_value") else None


def _fold(socket, const: _Constant) -> bool:
    """Set input ``socket`` to ``const`` as Cycles converts between colour, float and vector; False when the types
    do not convert here."""
    if socket.type not in _VALUE_TYPES or const.type not in _VALUE_TYPES:
        return False
    v = const.value
    if const.type == "VALUE":
        rgb = (v, v, v)
    elif const.type == "RGBA":
        rgb = v[:3]
    else:
        rgb = v[:3]
    if socket.type == "VALUE":
        # colour -> float: Rec. 709 luminance (Cycles' linear scene space); vector -> float: the average
        value = v if const.type == "VALUE" else (0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
                                                  if const.type == "RGBA" else sum(rgb) / 3.0)
        socket.default_value = value
    elif socket.type == "RGBA":
        socket.default_value = (*rgb, 1.0)
    else:
        socket.default_value = rgb
    return True


#: node properties not copied when a group is ungrouped (layout and identity)
_LAYOUT = {"name", "location", "location_absolute", "parent", "select", "width", "height", "dimensions", "hide",
           "show_options", "show_preview", "show_texture", "use_custom_color", "color", "bl_idname", "bl_label",
           "bl_description", "bl_icon", "bl_static_type", "bl_width_default", "bl_width_min", "bl_width_max",
           "bl_height_default", "bl_height_min", "bl_height_max", "type", "warning_propagation"}
#: group nesting deeper than this is left grouped (the mapping then names the group node)
MAX_GROUP_DEPTH = 16


def _same(socket, sockets):
    """The socket of ``sockets`` with ``socket``'s identifier (a copied node's counterpart), or None."""
    return next((s for s in sockets if s.identifier == socket.identifier), None)


def _copy_node(src, dst) -> None:
    """Copy a node's settings and socket values onto a new node of the same type in another tree."""
    for prop in src.bl_rna.properties:
        if prop.is_readonly or prop.identifier in _LAYOUT:
            continue
        try:
            setattr(dst, prop.identifier, getattr(src, prop.identifier))
        except (AttributeError, TypeError, ValueError, RuntimeError):
            pass
    ramp = getattr(src, "color_ramp", None)
    if ramp is not None:
        out = dst.color_ramp
        out.interpolation, out.color_mode = ramp.interpolation, ramp.color_mode
        while len(out.elements) < len(ramp.elements):
            out.elements.new(0.0)
        for a, b in zip(ramp.elements, out.elements, strict=False):
            b.position, b.color = a.position, tuple(a.color)
    for sockets, copies in ((src.inputs, dst.inputs), (src.outputs, dst.outputs)):
        for sock in sockets:
            twin = _same(sock, copies)
            if twin is not None and hasattr(sock, "default_value") and hasattr(twin, "default_value"):
                try:
                    twin.default_value = sock.default_value
                except (AttributeError, TypeError, ValueError):
                    pass


def _ungroup(tree, group) -> None:
    """Replace group node ``group`` of ``tree`` by copies of its nodes: links into its Group Input come from what
    feeds the group node's inputs (or their values), links to its Group Output go where the group's outputs went."""
    inner = group.node_tree
    copies = {n.name: tree.nodes.new(n.bl_idname) for n in inner.nodes
              if n.bl_idname not in ("NodeGroupInput", "NodeGroupOutput", "NodeFrame")}
    for name, node in copies.items():
        _copy_node(inner.nodes[name], node)
    outer_out: dict = {}  # group output identifier -> [outer target sockets]
    for link in tree.links:
        if link.from_node == group:
            outer_out.setdefault(link.from_socket.identifier, []).append(link.to_socket)
    for link in inner.links:
        if link.is_muted or not link.is_valid:
            continue
        if link.from_node.bl_idname == "NodeGroupInput":
            outer = _same(link.from_socket, group.inputs)
            if outer is None:
                continue
            live = _live(outer)
            src = live[0].from_socket if live else (_Constant(outer) if outer.type in _VALUE_TYPES else None)
        else:
            src = _same(link.from_socket, copies[link.from_node.name].outputs)
        if link.to_node.bl_idname == "NodeGroupOutput":
            targets = outer_out.get(link.to_socket.identifier, [])
        elif link.to_node.name in copies:
            targets = [_same(link.to_socket, copies[link.to_node.name].inputs)]
        else:
            continue
        for target in targets:
            if target is None or src is None:
                continue
            if isinstance(src, _Constant):
                for old in list(target.links):
                    tree.links.remove(old)
                _fold(target, src)
            else:
                tree.links.new(src, target)
    tree.nodes.remove(group)


def ungroup_all(tree) -> None:
    """Ungroup every (unmuted) group node of ``tree``, nested groups too, up to MAX_GROUP_DEPTH levels."""
    for _ in range(MAX_GROUP_DEPTH):
        groups = [n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree is not None and not n.mute]
        if not groups:
            return
        for group in groups:
            _ungroup(tree, group)


def resolve_links(tree) -> None:
    """Rewrite ``tree`` in place (module docstring): node groups ungrouped, muted and invalid links removed, links
    through Reroute and muted nodes replaced by links from what feeds them, constants folded into the sockets they
    feed."""
    ungroup_all(tree)
    for link in list(tree.links):
        if link.is_muted or not link.is_valid:
            tree.links.remove(link)
    for link in list(tree.links):
        target = link.to_socket
        if _passes_through(link.to_node):
            continue  # removed with the node below
        src = _source(link.from_socket)
        if src is link.from_socket:
            continue
        if isinstance(src, _Constant):
            if _fold(target, src):
                tree.links.remove(link)
            elif _passes_through(link.from_node):
                tree.links.remove(link)  # a constant through a pass-through node into a socket that takes none
            continue
        tree.links.remove(link)
        if src is not None:
            tree.links.new(src, target)
    for node in [n for n in tree.nodes if _passes_through(n)]:
        tree.nodes.remove(node)


@contextmanager
def resolved_copy(bpy, idblock):
    """A temporary copy of a material, world or light with :func:`resolve_links` applied to its node tree (removed on
    exit)."""
    store = (bpy.data.worlds if isinstance(idblock, bpy.types.World) else bpy.data.lights
             if isinstance(idblock, bpy.types.Light) else bpy.data.materials)
    copy = idblock.copy()
    try:
        resolve_links(copy.node_tree)
        yield copy
    finally:
        store.remove(copy)
