"""Mitsuba 3 converter: ground truth for neural assets from a Mitsuba scene (spec/bake.md).

``load_mitsuba()`` (from :mod:`nasset_mitsuba_renderer.loader`) picks the Mitsuba variant.
Mitsuba is an optional dependency: importing this package does not import it.
"""

from __future__ import annotations

from nasset_mitsuba_renderer.loader import is_jit, load_mitsuba  # noqa: F401  (the converters' Mitsuba entry)

#: bumped when the data a bake produces changes meaning (stored in provenance and in dataset dirs).
CONVERTER_VERSION = "0.4.0"  # 0.3: no clamp by default, held-out references unclamped in two halves; 0.4: normals of
# flip_normals shapes as Mitsuba shades them, light visibility cast as the renderer casts it (far from the origin)
