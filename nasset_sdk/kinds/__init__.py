"""Kind registry: each kind declares its components, tensor shapes and network widths, and
provides numpy + onnxruntime evaluation (spec/kinds/).

Shapes are written with symbols: ``("3", "R", "R", "C")`` binds R and C from the stored tensor,
and a network width such as ``"C+12"`` must then equal the bound expression. One checker
(:meth:`KindContract.findings`) serves the writer, the reader and the validator.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np


@dataclass(frozen=True)
class TensorSpec:
    dims: tuple[str, ...]  # ints as strings, symbols, or expressions of bound symbols
    layout: str
    meaning: str = ""


@dataclass(frozen=True)
class NetworkSpec:
    inputs: tuple[tuple[str, str], ...]  # (name, width expression)
    outputs: tuple[tuple[str, str], ...]
    meaning: str = ""


@dataclass(frozen=True)
class ComponentSpec:
    required: bool
    purpose: str
    tensors: dict[str, TensorSpec] = field(default_factory=dict)
    networks: dict[str, NetworkSpec] = field(default_factory=dict)


@dataclass(frozen=True)
class Finding:
    """One contract violation, in the validator's terms."""

    code: str
    message: str
    prim: str | None = None
    attribute: str | None = None
    #: None: the rule's severity; "warning" for content this contract version does not know
    #: (readers ignore it, spec/kinds/README.md#undeclared)
    severity: str | None = None


_SYMBOL = re.compile(r"^[A-Za-z_]\w*$")


def _eval_dim(expr: str, env: dict[str, int]) -> int | None:
    """Evaluate an integer dimension expression ('C+12', '2*K', 'R'); None if a symbol is unbound."""
    names = set(re.findall(r"[A-Za-z_]\w*", expr))
    if not names <= set(env):
        return None
    return int(eval(expr, {"__builtins__": {}}, dict(env)))  # expressions come from our own contracts only


class KindContract:
    """Base class of a kind. Subclasses set the class attributes and implement the hooks."""

    id: str = ""
    variants: tuple[str, ...] = ("surface",)
    paper: str = ""

    def components(self, variant: str) -> dict[str, ComponentSpec]:
        raise NotImplementedError

    def required_components(self, variant: str) -> list[str]:
        return [n for n, c in self.components(variant).items() if c.required]

    # -- contract checking -----------------------------------------------------------------
    def findings(
        self,
        variant: str,
        present: dict[str, tuple[dict[str, tuple[int, ...]], dict[str, tuple[tuple[str, ...], tuple[int, ...], tuple[str, ...], tuple[int, ...]]]]],
        get_tensor: Callable[[str, str], np.ndarray] | None = None,
        prim_of: Callable[[str, str | None], str] = lambda c, n=None: f"{c}/{n}" if n else c,
    ) -> list[Finding]:
        """Check what is present against the contract.

        present: component -> (tensor name -> shape, network name -> (input names, input widths,
        output names, output widths)). get_tensor(component, name) returns values for the
        kind-specific checks (:meth:`value_findings`); None skips them.
        """
        out: list[Finding] = []
        specs = self.components(variant)
        for cname, spec in specs.items():
            if cname not in present:
                if spec.required:
                    out.append(Finding("COMPONENT_MISSING", f"required component {cname!r} absent", prim_of(cname)))
                continue
            tensors, networks = present[cname]
            env: dict[str, int] = {}
            for tname, tspec in spec.tensors.items():
                if tname not in tensors:
                    out.append(Finding("TENSOR_MISSING", f"tensor {tname!r} ({tspec.layout}) absent", prim_of(cname, tname)))
                    continue
                shape = tensors[tname]
                if len(shape) != len(tspec.dims):
                    out.append(Finding("TENSOR_CONTRACT", f"rank {len(shape)} != {len(tspec.dims)} for {tspec.dims}", prim_of(cname, tname), "shape"))
                    continue
                for dim, size in zip(tspec.dims, shape, strict=True):
                    if _SYMBOL.match(dim) and dim not in env:
                        env[dim] = int(size)
                        if size <= 0:
                            out.append(Finding("TENSOR_CONTRACT", f"dimension {dim} must be > 0", prim_of(cname, tname), "shape"))
                        continue
                    want = _eval_dim(dim, env)
                    if want is not None and want != size:
                        out.append(Finding("TENSOR_CONTRACT", f"shape {tuple(shape)} does not match {tspec.dims} (bound {env})",
                                           prim_of(cname, tname), "shape"))
                        break
            for nname, nspec in spec.networks.items():
                if nname not in networks:
                    out.append(Finding("NETWORK_MISSING", f"network {nname!r} absent", prim_of(cname, nname)))
                    continue
                in_names, in_w, out_names, out_w = networks[nname]
                want_in = tuple(n for n, _ in nspec.inputs)
                want_out = tuple(n for n, _ in nspec.outputs)
                if tuple(in_names) != want_in or tuple(out_names) != want_out:
                    out.append(Finding("NETWORK_IO", f"I/O names {tuple(in_names)}->{tuple(out_names)} != {want_in}->{want_out}",
                                       prim_of(cname, nname), "onnx:inputNames"))
                    continue
                if len(in_w) != len(nspec.inputs) or len(out_w) != len(nspec.outputs):
                    out.append(Finding("NETWORK_IO", f"declared widths {tuple(in_w)}->{tuple(out_w)} do not match the I/O names",
                                       prim_of(cname, nname), "onnx:inputWidths"))
                    continue
                pairs = list(zip(nspec.inputs, in_w, strict=True)) + list(zip(nspec.outputs, out_w, strict=True))
                for (name, expr), got in pairs:
                    if _SYMBOL.match(expr) and expr not in env:
                        env[expr] = int(got)
                        continue
                    want = _eval_dim(expr, env)
                    if want is not None and want != got:
                        out.append(Finding("NETWORK_IO", f"{name!r} width {got} != {expr} = {want}", prim_of(cname, nname), "onnx:inputWidths"))
            for extra in sorted(tensors.keys() - spec.tensors.keys()):
                out.append(Finding("TENSOR_CONTRACT", f"tensor {extra!r} not in the {self.id} contract (readers ignore it)",
                                   prim_of(cname, extra), severity="warning"))
            for extra in sorted(networks.keys() - spec.networks.keys()):
                out.append(Finding("NETWORK_IO", f"network {extra!r} not in the {self.id} contract (readers ignore it)",
                                   prim_of(cname, extra), severity="warning"))
        for cname in present.keys() - specs.keys():
            out.append(Finding("COMPONENT_UNKNOWN", f"component {cname!r} not declared by kind {self.id}", prim_of(cname)))
        if get_tensor is not None and not any(f.code in ("TENSOR_CONTRACT", "TENSOR_MISSING") and f.severity is None for f in out):
            out += self.value_findings(variant, present, get_tensor, prim_of)
        return out

    def probe_unit_columns(self, variant: str, component: str, network: str, input_name: str, width: int) -> tuple[int, ...]:
        """First columns of the 3-wide unit-direction blocks of a network input (the validator's
        runtime probe draws unit vectors there, uniform [-1, 1] elsewhere). Default: none."""
        return ()

    def value_findings(self, variant, present, get_tensor, prim_of) -> list[Finding]:
        """Kind-specific checks on tensor values (e.g. monotone spline knots). Default: none."""
        return []

    def check_builder(self, builder) -> None:
        """Raise UsageError if an AssetBuilder does not satisfy the contract."""
        from ..errors import UsageError
        from ..networks import info_from_model

        for cname, levels in builder.components.items():
            for quality, data in levels.items():
                tensors = {n: tuple(a.shape) for n, (a, _, _) in data.tensors.items()}
                nets = {}
                for n, blob in data.networks.items():
                    i = info_from_model(blob)
                    nets[n] = (i.input_names, i.input_widths, i.output_names, i.output_widths)
                found = self.findings(builder.variant, {**{c: ({}, {}) for c in builder.components}, cname: (tensors, nets)},
                                      lambda c, n, d=data: d.tensors[n][0])
                found = [f for f in found if not (f.code == "COMPONENT_MISSING" or (f.prim or "").split("/")[0] != cname)]
                if found:
                    raise UsageError(f"{self.id} contract ({cname}{'/' + quality if quality else ''}): "
                                     + "; ".join(f"[{f.code}] {f.message}" for f in found))
        specs = self.components(builder.variant)
        for cname, levels in builder.components.items():
            for data in levels.values():
                if cname in specs and data.required != specs[cname].required:
                    raise UsageError(f"{self.id} component {cname!r} must have required={specs[cname].required}")
        missing = [c for c in self.required_components(builder.variant) if c not in builder.components]
        if missing:
            raise UsageError(f"{self.id} asset lacks required components {missing}")

    # -- construction and evaluation -------------------------------------------------------
    def build_random(self, rng: np.random.Generator, *, variant: str = "surface", size: str = "small", geometry=None):
        """An AssetBuilder with randomly initialised tensors and networks (format tests, examples)."""
        raise NotImplementedError

    def evaluator(self, asset, **options):
        raise NotImplementedError


def new_evaluator(cls, asset, options: dict):
    """``cls(asset, **options)``, with USAGE naming the options ``cls`` does not take: they are bound to its signature
    first, so a TypeError raised inside the constructor stays what it is."""
    import inspect

    from ..errors import UsageError

    signature = inspect.signature(cls)
    try:
        signature.bind(asset, **options)
    except TypeError as exc:
        takes = ", ".join(p for p in list(signature.parameters)[1:]) or "no options"
        path = getattr(asset, "path", None)
        raise UsageError(f"the {getattr(asset, 'kind', cls.__name__)} evaluator does not take these options ({exc}); "
                         f"it takes {takes}", file=None if path is None else str(path)) from None
    return cls(asset, **options)


def rows3(*arrays) -> list[np.ndarray]:
    """Evaluator argument check: each array as float64 [N, 3], all with the same N (UsageError otherwise)."""
    from ..arrays import real_dtype
    from ..errors import UsageError

    out, n = [], None
    for i, a in enumerate(arrays):
        if real_dtype(a) is None:
            raise UsageError(f"points and directions must be real number arrays [N, 3]; argument {i + 1} of {len(arrays)} is not")
        a = np.atleast_2d(np.asarray(a, np.float64))
        if a.ndim != 2 or a.shape[1] != 3 or (n is not None and len(a) != n):
            shapes = ", ".join(str(tuple(np.shape(b))) for b in arrays)
            raise UsageError(f"points and directions must be [N, 3] arrays of one N; argument {i + 1} of {len(arrays)} "
                             f"is {tuple(np.shape(arrays[i]))} (all: {shapes})")
        n = len(a)
        out.append(a)
    return out


KINDS: dict[str, KindContract] = {}


def register_kind(contract: KindContract) -> KindContract:
    """Add a kind to the registry (kind modules call this at import)."""
    KINDS[contract.id] = contract
    return contract


def get_kind(kind_id: str) -> KindContract:
    from ..errors import error

    if kind_id not in KINDS:
        raise error("KIND_UNKNOWN", f"kind {kind_id!r} is not one of {sorted(KINDS)}")
    return KINDS[kind_id]


def kind_ids() -> Iterable[str]:
    return sorted(KINDS)


# kind modules register themselves on import
from . import eightdna, neupress, rna  # noqa: E402,F401
