"""Optional dependencies (pip extras): one check that names every missing package at once.

The extras and their packages are read from the installed distribution's metadata, i.e. from
``[project.optional-dependencies]`` in pyproject.toml, so that table stays the only list.
"""

from __future__ import annotations

import importlib.util
import re

from .errors import error

DISTRIBUTION = "nasset-sdk"
#: distribution name -> import name, where they differ
IMPORT_NAMES = {"openexr": "OpenEXR", "usd-core": "pxr", "pillow": "PIL", "flip-evaluator": "flip_evaluator",
                "import-linter": "importlinter", "pytest-xdist": "xdist"}
_EXTRA = re.compile(r"""extra\s*==\s*["']([^"']+)["']""")
_NAME = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)")


def extra_packages(extra: str) -> list[str]:
    """Distribution names the extra ``extra`` adds (empty when nasset-sdk's metadata is not installed)."""
    from importlib.metadata import PackageNotFoundError, requires

    try:
        reqs = requires(DISTRIBUTION) or []
    except PackageNotFoundError:  # a checkout that was never installed: nothing to compare against
        return []
    out = []
    for req in reqs:
        m = _EXTRA.search(req)
        name = _NAME.match(req)
        if m and name and m.group(1) == extra and name.group(1) not in out:
            out.append(name.group(1))
    return out


def missing_packages(*extras: str) -> list[str]:
    """Packages of ``extras`` whose module cannot be found (in order, without duplicates)."""
    missing: list[str] = []
    for extra in extras:
        for dist in extra_packages(extra):
            module = IMPORT_NAMES.get(dist.lower(), dist.replace("-", "_"))
            if dist not in missing and importlib.util.find_spec(module) is None:
                missing.append(dist)
    return missing


def require_extras(*extras: str, purpose: str) -> None:
    """Raise ``EXTRA_MISSING`` listing every missing package of ``extras`` and the pip command that adds them."""
    missing = missing_packages(*extras)
    if missing:
        names = ",".join(extras)
        raise error("EXTRA_MISSING", f"{purpose} needs the package(s) {', '.join(missing)}, not installed; "
                    f"pip install '{DISTRIBUTION}[{names}]'")


__all__ = ["extra_packages", "missing_packages", "require_extras"]
