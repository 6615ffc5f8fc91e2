"""Argument checks for arrays a caller hands the SDK: do they hold real numbers?

Booleans, strings, objects and complex numbers are refused as USAGE naming the argument, before numpy
fails on them with a bare ``ValueError`` or ``TypeError`` deep inside a computation.
"""

from __future__ import annotations

import numpy as np

from .errors import UsageError


def real_dtype(value) -> np.dtype | None:
    """The dtype of ``value`` (an array, or what numpy makes of a list) when it holds real numbers (integer or
    floating), else None: booleans, strings, objects, complex numbers, ragged nesting."""
    dt = getattr(value, "dtype", None)
    if not isinstance(dt, np.dtype):
        try:
            dt = np.asarray(value).dtype
        except (ValueError, TypeError):  # ragged nesting
            return None
    return dt if dt.kind in "fiu" else None


def real_array(value, message: str, *, dtype=None) -> np.ndarray:
    """``value`` as a numpy array (its own real dtype, or ``dtype``); UsageError(``message``) when it holds no real
    numbers."""
    if real_dtype(value) is None:
        raise UsageError(message)
    return np.asarray(value, dtype)
