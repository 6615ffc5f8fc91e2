"""The bakers' registry: ``(source, kind) -> bake function``; each baker module registers itself.

Every bake function takes ``(scene, asset_ids, output, **options)`` (``example`` a name or None) and
returns the summary dict (also stored in the asset's provenance).
"""

from __future__ import annotations

from typing import Callable

from nasset_sdk.errors import UsageError

#: (source, kind) -> bake function; sources: "mitsuba" (.xml scenes), "blender" (.blend scenes)
BAKERS: dict[tuple[str, str], Callable[..., dict]] = {}

SOURCE_NAMES = {"mitsuba": "Mitsuba 3", "blender": "Blender"}


def register_baker(source: str, kind: str, bake: Callable[..., dict]) -> Callable[..., dict]:
    """Make ``bake`` the baker of ``kind`` assets from ``source`` scenes; returns it."""
    BAKERS[(source, kind)] = bake
    return bake


def source_of(scene, example: str | None) -> str:
    """``blender`` for ``.blend`` files and ``blender-*`` examples, ``mitsuba`` otherwise."""
    blender = (scene is not None and str(scene).lower().endswith(".blend")) or (example or "").startswith("blender")
    return "blender" if blender else "mitsuba"


def baker_for(kind: str, scene, example: str | None) -> Callable[..., dict]:
    """The bake function for a kind and a source scene (or built-in example); UsageError when there is none."""
    source = source_of(scene, example)
    bake = BAKERS.get((source, kind))
    if bake is not None:
        return bake
    if any(k == kind for _, k in BAKERS):
        kinds = ", ".join(sorted(k for s, k in BAKERS if s == source))
        raise UsageError(f"{SOURCE_NAMES.get(source, source)} scenes bake to kind {kinds} only, not {kind!r}")
    raise UsageError(f"unknown kind {kind!r}")
