"""Colour and float nodes between an Image Texture and a shader input, folded into the texture's texels.

Artists tint, remap and unpack textures on their way to a BSDF: a Mix node multiplying a texture by a colour, a
Color Ramp on a mask, a Separate Color taking the green channel of a packed roughness map, a Math or Map Range
node scaling it. Each such node acts on every shading point's looked-up value alone, so applying it to every
texel gives the same result wherever it commutes with the lookup's interpolation: exactly for the affine ones
(Mix with a constant, Invert, Brightness/Contrast, Math add/subtract/multiply/divide by a constant, Map Range,
Separate Color, RGB to BW), and to the texel spacing for the others (Color Ramp, Gamma, power, minimum/maximum,
clamping), on textures already resampled finer for 8-bit sRGB decoding. The formulas are Cycles' (svm_mix,
svm_math, svm_map_range, svm_brightness, svm_gamma, svm_invert; a colour into a float socket is its Rec. 709
luminance, a float into a colour socket grey).

:func:`texel_chain` walks back from a socket to the Image Texture through such nodes (each with one linked input
and constants elsewhere); :func:`apply_chain` applies them to texels [H, W, 3].
"""

from __future__ import annotations

import numpy as np

#: Rec. 709 luminance, as Cycles converts a colour to a float in its default (linear Rec. 709) scene space
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Mix node blend types folded (svm_mix)
MIX_BLENDS = ("MIX", "ADD", "MULTIPLY", "SUBTRACT", "SCREEN", "DIFFERENCE", "DARKEN", "LIGHTEN")
#: Math node operations folded (svm_math), with the texture's value as either operand
MATH_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "POWER", "MINIMUM", "MAXIMUM")
#: samples of a Color Ramp's table over [0, 1] (its lookup between them is linear)
RAMP_SAMPLES = 4096


def _main_input(node):
    """The one linked input of a node this module folds, or None when it has none or several, or is not one of them."""
    kind = node.bl_idname
    if kind == "ShaderNodeMix":
        if node.data_type not in ("RGBA", "FLOAT") or node.blend_type not in MIX_BLENDS:
            return None
        names = ("A_Color", "B_Color") if node.data_type == "RGBA" else ("A_Float", "B_Float")
        fac = next(s for s in node.inputs if s.identifier == "Factor_Float")
        if fac.is_linked:
            return None
        linked = [s for s in node.inputs if s.identifier in names and s.is_linked]
        return linked[0] if len(linked) == 1 else None
    if kind == "ShaderNodeMath":
        if node.operation not in MATH_OPS:
            return None
        linked = [s for s in node.inputs[:2] if s.is_linked]
        return linked[0] if len(linked) == 1 else None
    if kind == "ShaderNodeMapRange":
        if node.data_type != "FLOAT" or node.interpolation_type != "LINEAR":
            return None
        rest = [s for s in node.inputs if s.enabled and s.identifier != "Value"]
        value = node.inputs["Value"]
        return value if value.is_linked and not any(s.is_linked for s in rest) else None
    main = {"ShaderNodeValToRGB": "Fac", "ShaderNodeInvert": "Color", "ShaderNodeGamma": "Color",
            "ShaderNodeBrightContrast": "Color", "ShaderNodeSeparateColor": "Color", "ShaderNodeRGBToBW": "Color"}.get(kind)
    if main is None or (kind == "ShaderNodeSeparateColor" and node.mode != "RGB"):
        return None
    sock = node.inputs[main]
    others = [s for s in node.inputs if s.enabled and s != sock]
    return sock if sock.is_linked and not any(s.is_linked for s in others) else None


def texel_chain(socket):
    """(the link leaving an Image Texture node, [(node, output socket, input socket) from the texture towards
    ``socket``]) when ``socket`` is fed by an Image Texture through foldable nodes only; else (None, the first node
    that is neither)."""
    ops = []
    link = socket.links[0]
    for _ in range(64):
        node = link.from_node
        if node.bl_idname == "ShaderNodeTexImage":
            return link, ops[::-1]
        sock = _main_input(node)
        if sock is None:
            return None, node
        ops.append((node, link.from_socket, sock))
        link = sock.links[0]
    return None, link.from_node


def _value(sock, default=0.0):
    v = getattr(sock, "default_value", default)
    try:
        return np.array([float(x) for x in v][:3])
    except TypeError:
        return np.full(3, float(v))


def _as(value: np.ndarray, is_color: bool, socket_type: str) -> np.ndarray:
    """A value [..., 3] converted for a socket: a colour into a float socket is its luminance (in all 3 channels)."""
    if is_color and socket_type == "VALUE":
        return np.repeat((value @ LUMINANCE)[..., None], 3, -1)
    return value


def _mix(blend: str, c1, c2, t):
    out = {"MIX": c2, "ADD": c1 + c2, "MULTIPLY": c1 * c2, "SUBTRACT": c1 - c2, "DIFFERENCE": np.abs(c1 - c2),
           "DARKEN": np.minimum(c1, c2), "LIGHTEN": np.maximum(c1, c2)}.get(blend)
    if blend == "SCREEN":
        return 1.0 - ((1.0 - t) + t * (1.0 - c2)) * (1.0 - c1)
    return (1.0 - t) * c1 + t * out


def _math(op: str, a, b):
    if op == "DIVIDE":
        return np.divide(a, b, out=np.zeros(np.broadcast(a, b).shape), where=np.asarray(b) != 0.0)
    if op == "POWER":  # Cycles: 0 for a negative base with a non-integer exponent
        a, b = np.broadcast_arrays(a, b)
        ok = (a >= 0.0) | (b == np.round(b))
        return np.where(ok, np.power(np.where(ok, a, 1.0), b), 0.0)
    return {"ADD": np.add, "SUBTRACT": np.subtract, "MULTIPLY": np.multiply, "MINIMUM": np.minimum,
            "MAXIMUM": np.maximum}[op](a, b)


def apply_chain(ops, value: np.ndarray, is_color: bool) -> tuple[np.ndarray, bool]:
    """Apply :func:`texel_chain`'s nodes to texels ``value`` [..., 3] (a colour when ``is_color``, else a float in
    all three channels); returns the result and whether it is a colour."""
    for node, out, inp in ops:
        x = _as(value, is_color, inp.type)
        kind = node.bl_idname
        if kind == "ShaderNodeMix":
            fac = float(next(s for s in node.inputs if s.identifier == "Factor_Float").default_value)
            t = float(np.clip(fac, 0.0, 1.0)) if node.clamp_factor else fac
            other = next(s for s in node.inputs if s.enabled and s.identifier in ("A_Color", "B_Color", "A_Float",
                                                                                  "B_Float") and s != inp)
            const = _value(other)
            a, b = (x, const) if inp.identifier.startswith("A_") else (const, x)
            x = _mix(node.blend_type if node.data_type == "RGBA" else "MIX", a, b, t)
            if node.data_type == "RGBA" and node.clamp_result:
                x = np.clip(x, 0.0, 1.0)
        elif kind == "ShaderNodeMath":
            other = node.inputs[1] if inp == node.inputs[0] else node.inputs[0]
            const = float(other.default_value)
            a, b = (x, const) if inp == node.inputs[0] else (const, x)
            x = _math(node.operation, a, b)
            if node.use_clamp:
                x = np.clip(x, 0.0, 1.0)
        elif kind == "ShaderNodeMapRange":
            lo, hi, to_lo, to_hi = (float(node.inputs[k].default_value) for k in ("From Min", "From Max", "To Min",
                                                                                  "To Max"))
            f = np.divide(x - lo, hi - lo, out=np.zeros_like(x), where=hi != lo) if hi != lo else np.zeros_like(x)
            x = to_lo + f * (to_hi - to_lo)
            if node.clamp:
                x = np.clip(x, min(to_lo, to_hi), max(to_lo, to_hi))
        elif kind == "ShaderNodeValToRGB":
            grid = np.linspace(0.0, 1.0, RAMP_SAMPLES)
            table = np.array([node.color_ramp.evaluate(float(g)) for g in grid])  # RGBA
            f = np.clip(x[..., 0], 0.0, 1.0)
            channels = range(3) if out.name == "Color" else (3, 3, 3)
            x = np.stack([np.interp(f, grid, table[:, c]) for c in channels], -1)
        elif kind == "ShaderNodeInvert":
            fac = float(node.inputs["Fac"].default_value)
            x = (1.0 - fac) * x + fac * (1.0 - x)
        elif kind == "ShaderNodeGamma":
            g = float(node.inputs["Gamma"].default_value)
            x = np.where(x > 0.0, np.power(np.maximum(x, 0.0), g), x)
        elif kind == "ShaderNodeBrightContrast":
            bright, contrast = float(node.inputs["Bright"].default_value), float(node.inputs["Contrast"].default_value)
            x = np.maximum((1.0 + contrast) * x + (bright - contrast * 0.5), 0.0)
        elif kind == "ShaderNodeSeparateColor":
            x = np.repeat(x[..., ("Red", "Green", "Blue").index(out.name)][..., None], 3, -1)
        elif kind == "ShaderNodeRGBToBW":
            x = _as(x, True, "VALUE")
        value, is_color = x, out.type == "RGBA"
    return value, is_color


def describe(ops) -> str:
    """The folded nodes, named, for the texture's description."""
    return " -> ".join(f"{node.bl_label}" + (f" {node.blend_type.lower()}" if node.bl_idname == "ShaderNodeMix" else
                                             f" {node.operation.lower()}" if node.bl_idname == "ShaderNodeMath" else "")
                       for node, _, _ in ops)
