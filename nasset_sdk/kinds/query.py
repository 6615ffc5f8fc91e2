"""One evaluator interface for every kind (spec/kinds/README.md#evaluator-interface).

A :class:`Query` holds N shading configurations in object space; :meth:`Evaluator.radiance` returns
the outgoing radiance RGB [N, 3] (float32, finite, >= 0, units 1/sr) at each point towards w_o per unit
irradiance (measured perpendicular to w_i) of a distant light in direction w_i. Kind-specific
quantities (rna's two visibility branches, neupress's lobe sampling and PRT, 8dna's flow sample and
pdf) stay as further methods of each kind's evaluator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arrays import real_dtype
from ..errors import UsageError

#: the [N, 3] fields of a query, in order
VECTOR_FIELDS = ("x", "n", "wo", "wi")


@dataclass(frozen=True)
class Query:
    """N shading configurations, object space, directions pointing away from the point.

    x [N,3] positions (the asset's geometry units); n [N,3] shading frame: the surface normal, or the
    fiber tangent for fiber variants; wo [N,3] towards the viewer; wi [N,3] towards the light. n, wo,
    wi need not be unit length (they are normalised) but must be nonzero. Optional:
    shadowed [N] bool, the asset's own geometry blocks a shadow ray from x towards wi (default: no);
    h [N] the cross-fiber offset in [-1, 1] (rna fiber only, default 0).
    """

    x: object
    n: object
    wo: object
    wi: object
    shadowed: object = None
    h: object = None

    def checked(self, *, file: str | None = None) -> "Query":
        """A copy with float64 [N,3] vectors, bool [N] ``shadowed`` and float64 [N] or None ``h``.

        Raises UsageError naming the field and the expected shape for a wrong shape, a non-numeric
        dtype, a non-finite value or a zero direction."""
        n_rows = None
        out = {}
        for name in VECTOR_FIELDS:
            a = _numeric(name, getattr(self, name), file)
            if a.ndim != 2 or a.shape[1] != 3 or (n_rows is not None and a.shape[0] != n_rows):
                want = "[N, 3]" if n_rows is None else f"[N, 3] with N = {n_rows} (the rows of 'x')"
                raise UsageError(f"query field {name!r}: expected shape {want}, got {tuple(a.shape)}", file=file)
            n_rows = a.shape[0]
            if not np.isfinite(a).all():
                raise UsageError(f"query field {name!r} [N, 3] holds NaN or Inf", file=file)
            if name != "x" and n_rows and not (np.abs(a).max(axis=1) > 0).all():
                raise UsageError(f"query field {name!r} [N, 3] holds a zero vector; directions must be nonzero", file=file)
            out[name] = a
        if self.shadowed is None:
            out["shadowed"] = np.zeros(n_rows, bool)
        else:
            s = np.asarray(self.shadowed)
            if s.dtype != bool:
                raise UsageError(f"query field 'shadowed': expected dtype bool, got {s.dtype}", file=file)
            out["shadowed"] = _rows1("shadowed", s, n_rows, file)
        if self.h is None:
            out["h"] = None
        else:
            h = _rows1("h", _numeric("h", self.h, file), n_rows, file)
            if not (np.isfinite(h).all() and (np.abs(h) <= 1.0).all()):
                raise UsageError("query field 'h' [N] must be finite and in [-1, 1]", file=file)
            out["h"] = h
        return Query(**out)


def _numeric(name: str, value, file) -> np.ndarray:
    if real_dtype(value) is None:
        raise UsageError(f"query field {name!r}: expected a real number array, got dtype {np.asarray(value, object).dtype}",
                         file=file)
    return np.asarray(value).astype(np.float64)


def _rows1(name: str, a: np.ndarray, n_rows: int, file) -> np.ndarray:
    if a.shape != (n_rows,):
        raise UsageError(f"query field {name!r}: expected shape [N] with N = {n_rows} (the rows of 'x'), got {tuple(a.shape)}",
                         file=file)
    return a


def check_shapes(file: str | None = None, **fields) -> int:
    """Shape check for the per-kind methods: every field a real number [N, 3] of one N (None fields skipped); returns N.

    Cheap (no copy, no finiteness pass), so hot render loops can afford it; UsageError names the field."""
    n_rows = None
    for name, value in fields.items():
        if value is None:
            continue
        if real_dtype(value) is None:
            raise UsageError(f"argument {name!r}: expected a real number array [N, 3]", file=file)
        shape = np.shape(value)
        if len(shape) != 2 or shape[1] != 3 or (n_rows is not None and shape[0] != n_rows):
            want = "[N, 3]" if n_rows is None else f"[N, 3] with N = {n_rows} (the rows of the first argument)"
            raise UsageError(f"argument {name!r}: expected shape {want}, got {tuple(shape)}", file=file)
        n_rows = shape[0]
    return 0 if n_rows is None else n_rows


class Evaluator:
    """Base class of every kind's evaluator. Subclasses set ``asset`` and implement :meth:`_radiance`."""

    asset = None

    def radiance(self, query: Query | None = None, /, **fields) -> np.ndarray:
        """Outgoing radiance RGB [N, 3] float32 (1/sr, finite, >= 0) per unit distant-light irradiance.

        Pass a :class:`Query` or its fields as keywords: ``radiance(x=x, n=n, wo=wo, wi=wi)``."""
        if query is None:
            query = Query(**fields)
        elif fields:
            raise UsageError(f"pass a Query or keyword fields, not both (got {sorted(fields)})")
        if not isinstance(query, Query):
            raise UsageError(f"radiance() takes a nasset_sdk.Query, got {type(query).__name__}")
        file = str(getattr(self.asset, "path", "")) or None
        rgb = np.asarray(self._radiance(query.checked(file=file)), np.float64)
        rgb = np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0)
        return np.maximum(rgb, 0.0).astype(np.float32)

    def _radiance(self, q: Query) -> np.ndarray:
        raise NotImplementedError

    def _no_h(self, q: Query) -> None:
        if q.h is not None:
            raise UsageError("query field 'h' applies to rna fiber assets only",
                             file=str(getattr(self.asset, "path", "")) or None)
