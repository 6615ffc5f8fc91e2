"""An AssetBuilder's in-memory data behind the reader interface the kind evaluators use."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nasset_sdk.asset import NetworkRef
from nasset_sdk.networks import info_from_model, make_session


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

    def network_bytes(self, comp, name):
        return self.b.components[comp][""].networks[name]

    def check_runtime(self, comp, name):
        """The builder's own networks: trusted, as Asset trusts a file this process wrote."""

    path = "<memory>"

    def network_refs(self, comp):
        nets = self.b.components[comp][""].networks
        return {n: NetworkRef(comp, n, f"/_NassetPayloads/{comp}/{n}", info_from_model(blob)) for n, blob in nets.items()}

    def tensor_refs(self, comp):
        return {n: SimpleNamespace(prim_path=f"/_NassetPayloads/{comp}/{n}") for n in self.b.components[comp][""].tensors}

    def components(self):
        return {c: SimpleNamespace(loaded=True) for c in self.b.components}
