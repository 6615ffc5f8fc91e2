"""Built-in example assets (random networks for kinds whose bake has not landed)."""

from __future__ import annotations

import numpy as np

from .kinds import get_kind


def example_builder(kind: str = "rna", *, variant: str = "surface", size: str = "small", seed: int = 0,
                    quality_variants: bool = False):
    """AssetBuilder of ``kind`` with random networks; with ``quality_variants`` the required
    components are stored twice, as quality variants 'small' and 'hq' (default 'small')."""
    rng = np.random.default_rng(seed)
    contract = get_kind(kind)
    builder = contract.build_random(rng, variant=variant, size=size)
    if quality_variants:
        hq = contract.build_random(np.random.default_rng(seed + 1), variant=variant, size="hq", geometry=builder.geometry)
        for name in contract.required_components(variant):
            small_data = builder.components.pop(name)[""]
            builder.default_quality.pop(name, None)
            builder.components[name] = {"small": small_data, "hq": hq.components[name][""]}
            builder.default_quality[name] = "small"
    return builder


def run(args) -> int:
    """CLI: nasset example -o OUT."""
    path = example_builder(args.kind, variant=args.variant, size=args.size, seed=args.seed,
                           quality_variants=args.quality_variants).write(args.output)
    print(f"wrote {args.kind} ({args.variant}, {args.size}) example asset to {path}")
    return 0
