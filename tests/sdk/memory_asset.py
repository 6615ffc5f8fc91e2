"""An AssetBuilder's in-memory data behind the reader interface the kind evaluators use."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nasset_sdk.networks import make_session


class MemoryAsset:
    """Evaluate a builder without writing it (its domain rounded to float32, as the file stores it)."""

    def __init__(self, builder):
        self.b = builder
        self.variant = builder.variant
        self.domain = tuple(np.asarray(d, np.float32).astype(np.float64) for d in builder.domain)

    def tensor(self, comp, name):
        return self.b.components[comp][""].tensors[name][0]

    def session(self, comp, name, **kw):
        return make_session(self.b.components[comp][""].networks[name])

    def components(self):
        return {c: SimpleNamespace(loaded=True) for c in self.b.components}
