"""A JIT Mitsuba variant for the plugin (``llvm_ad_rgb`` or ``cuda_ad_rgb``), or a typed error."""

from __future__ import annotations

from nasset_mitsuba_renderer.loader import load_mitsuba
from nasset_sdk.errors import NassetError, error

#: variants the plugin's kernels are written for (one code path: Dr.Jit traces the same Python)
JIT_VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")


def jit_mitsuba(variant: str | None = None):
    """Import Mitsuba with a JIT variant set and return the module.

    ``variant=None`` keeps a JIT variant already set, else tries ``llvm_ad_rgb``. Raises
    CONVERT_BACKEND (a SceneError) when the variant is not a JIT one or cannot be set (no libLLVM,
    no CUDA driver, Mitsuba missing)."""
    if variant is not None and variant not in JIT_VARIANTS:
        raise error("CONVERT_BACKEND", f"the nasset Mitsuba plugin needs one of {', '.join(JIT_VARIANTS)}; got {variant!r}")
    try:
        import mitsuba as mi

        current = mi.variant()
    except ImportError:
        current = None
    if variant is None and current in JIT_VARIANTS:
        return mi
    try:
        mi = load_mitsuba(variant or JIT_VARIANTS[0])
    except NassetError as exc:
        raise error("CONVERT_BACKEND", f"the nasset Mitsuba plugin cannot use a JIT variant: {exc.message}") from None
    return mi
