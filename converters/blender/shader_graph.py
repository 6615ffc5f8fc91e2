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


def resolve_links(tree) -> None:
    """Rewrite ``tree`` in place (module docstring): muted and invalid links removed, links through Reroute and muted
    nodes replaced by links from what feeds them, constants folded into the sockets they feed."""
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
    """A temporary copy of a material or world with :func:`resolve_links` applied to its node tree (removed on
    exit)."""
    store = bpy.data.worlds if isinstance(idblock, bpy.types.World) else bpy.data.materials
    copy = idblock.copy()
    try:
        resolve_links(copy.node_tree)
        yield copy
    finally:
        store.remove(copy)
