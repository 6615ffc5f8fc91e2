"""Mitsuba 3 converter: ground truth for neural assets from a Mitsuba scene (spec/bake.md).

``load_mitsuba()`` picks the JIT variant ``llvm_ad_rgb`` (with libLLVM 19 when installed, since
older Debian LLVMs crash on AVX-512 machines) and falls back to ``scalar_rgb`` with a warning.
Mitsuba is an optional dependency: importing this package does not import it.
"""

from __future__ import annotations

import os
import warnings

from nasset_sdk.errors import error

#: bumped when the data a bake produces changes meaning (stored in provenance and in dataset dirs).
CONVERTER_VERSION = "0.3.0"  # 0.3: no clamp by default, held-out references unclamped in two halves

LLVM_CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
)

PREFERRED_VARIANT = "llvm_ad_rgb"
FALLBACK_VARIANT = "scalar_rgb"


def _point_drjit_at_llvm() -> None:
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    for cand in LLVM_CANDIDATES:
        if os.path.exists(cand):
            os.environ["DRJIT_LIBLLVM_PATH"] = cand
            return


def load_mitsuba(variant: str | None = None):
    """Import mitsuba and set a variant; returns the module.

    ``variant=None`` tries ``llvm_ad_rgb`` then ``scalar_rgb`` (RuntimeWarning on fallback).
    Raises CONVERT_BACKEND when mitsuba is not installed or no variant can be set.
    """
    _point_drjit_at_llvm()
    try:
        import mitsuba as mi
    except ImportError as exc:
        raise error("CONVERT_BACKEND", f"mitsuba is not installed ({exc}); pip install 'nasset-sdk[mitsuba]'") from None
    current = mi.variant()
    wanted = [variant] if variant else [PREFERRED_VARIANT, FALLBACK_VARIANT]
    if current in wanted and (variant or current == PREFERRED_VARIANT):
        return mi
    failures = []
    for v in wanted:
        try:
            mi.set_variant(v)
            break
        except Exception as exc:  # missing libLLVM surfaces as ImportError / RuntimeError from drjit
            failures.append(f"{v}: {str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__}")
    else:
        raise error("CONVERT_BACKEND", "no usable Mitsuba variant: " + "; ".join(failures))
    if failures and not variant:
        warnings.warn(
            f"Mitsuba variant {PREFERRED_VARIANT} unavailable ({failures[0]}); falling back to {mi.variant()}, "
            "which is ~10x slower. Install libLLVM 19 (apt-get install libllvm19) and set DRJIT_LIBLLVM_PATH.",
            RuntimeWarning,
            stacklevel=2,
        )
    return mi


def is_jit(mi) -> bool:
    """True for vectorised (llvm/cuda) variants, False for scalar ones."""
    return not mi.variant().startswith("scalar")
