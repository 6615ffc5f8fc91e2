"""Blender (bpy) converter: Cycles ground truth, rna surface and fiber bakes, scene conversion.

Coordinates: Blender is right-handed with +Z up; assets and USD stages are right-handed with +Y
up (spec/format.md#geometry). Every point and direction leaving Blender goes through
:data:`Z_UP_TO_Y_UP` (``p_usd = R p_blender``: (x, y, z) -> (x, z, -y)), and every camera or lamp
placed in Blender from asset space goes through its transpose (spec/bake-blender.md#coordinates).
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.errors import error

CONVERTER_VERSION = "0.4"  # 0.2: held-out views unclamped, in two halves; 0.3: training views unclamped by default;
#                            0.4: several suns of a view in Cycles light groups (one render, every pixel a sample per sun)

#: Blender world (+Z up) -> asset / USD space (+Y up), column-vector form p_usd = R @ p_blender
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def load_bpy():
    """``import bpy`` or CONVERT_BACKEND (the Blender module is the optional ``bpy`` wheel)."""
    try:
        import bpy
    except ImportError as exc:
        raise error("CONVERT_BACKEND", f"Blender's Python module is not installed ({exc}); pip install bpy "
                    "(Blender 5.0, Python 3.11)") from None
    return bpy


def to_y_up(v) -> np.ndarray:
    """[N,3] Blender points or directions -> +Y-up space."""
    return np.asarray(v, np.float64) @ Z_UP_TO_Y_UP.T


def to_z_up(v) -> np.ndarray:
    """[N,3] +Y-up points or directions -> Blender space."""
    return np.asarray(v, np.float64) @ Z_UP_TO_Y_UP


class quiet_stdout:
    """Silence Blender's C-level stdout (render progress and 'Saved:' lines) inside the block, so
    ``--json`` output stays clean; Python's sys.stdout is flushed first and restored after."""

    def __enter__(self):
        import os
        import sys

        sys.stdout.flush()
        self._saved = os.dup(1)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.close(null)
        return self

    def __exit__(self, *exc):
        import os

        os.dup2(self._saved, 1)
        os.close(self._saved)
        return False
