"""Every bake preset in one place: ``--size`` (tiny, small, hq) picks one row of each table of its baker.

A baker's preset has three parts: what it renders or samples (``DATA``, per source and kind), how it
trains (``TRAIN``, per kind) and the network shapes, which are the kind's own
(``nasset_sdk.kinds.<kind>.SIZES``, shared with ``nasset example``). :func:`preset` returns the three.
"""

from __future__ import annotations

from nasset_sdk.kinds import eightdna, neupress, rna

SIZES = ("tiny", "small", "hq")

# -- data ----------------------------------------------------------------------------------------
#: data presets (nasset_converters.mitsuba.dataset.DataSettings fields). lights_per_view 0: every training
#: pixel has its own random light; held-out views: one light per view, lower res, many more spp
#: (their noise bounds the measurable PSNR; spec/bake.md#psnr). Measured in spec/bake.md#ablations.
RNA_MITSUBA_DATA = {
    "tiny": dict(views=16, val_views=2, res=24, spp=8, val_res=24, val_spp=64, lights_per_view=0),
    "small": dict(views=192, val_views=24, res=96, spp=64, val_res=64, val_spp=1024, lights_per_view=0),
    "hq": dict(views=200, val_views=16, res=160, spp=128, val_res=96, val_spp=2048, lights_per_view=0),
}

#: near-field calibration of Mitsuba rna surface and neupress bakes (nasset_converters.mitsuba.near_field.NearFieldSettings
#: fields). Measured
#: on the high-albedo pebble (spec/bake.md#near-field): f from 32 views of 32^2 at 512 spp moved by +-0.06 between
#: view seeds, so `small` takes 64 views (40-70 s; its two halves of 256 spp gave f within 0.03-0.08 of each other)
MITSUBA_NEAR_FIELD = {
    "tiny": dict(views=8, res=16, spp=64),
    "small": dict(views=64, res=32, spp=512),
    "hq": dict(views=128, res=32, spp=1024),
}

#: data presets (nasset_converters.blender.dataset.DataSettings fields). Cycles has no per-pixel light, so presets use
#: many small views to see many light directions, and at `small` 8 suns per view, each in its own Cycles light group
#: (one render, 8 samples per pixel; spec/bake-blender.md#light-groups). Measured in spec/accuracy.md#light-groups:
#: on the surface example 8 suns against 1 gave 31.5 against 28.7 dB in the scene (the `hq` preset's 31.7 dB) for a
#: 258 s bake against 100 s; on the dense hair, below, 28.5-28.7 against 25.6 dB
RNA_BLENDER_DATA = {
    "tiny": dict(views=24, val_views=2, res=32, spp=16, val_res=32, val_spp=128),
    "small": dict(views=160, val_views=6, res=64, spp=64, val_res=64, val_spp=1024, lights_per_view=8),
    "hq": dict(views=400, val_views=12, res=96, spp=128, val_res=96, val_spp=2048),
}
#: what fiber (hair) bakes change in RNA_BLENDER_DATA: a fiber's highlights depend sharply on the light, and more light
#: directions moved every figure of the dense hair example (spec/accuracy.md#dense-hair). With 8 suns per view, 200
#: views against 400 one-sun views: in the scene 28.5-28.7 against 25.6 dB bias-corrected (two seeds), every channel
#: within 2.5 % against red 3.85 % dark; the bake 561-611 s from scratch against 679 s (spec/accuracy.md#light-groups)
RNA_BLENDER_FIBER_DATA = {"small": dict(views=200)}
#: what fiber bakes change in RNA_TRAIN: at `small` a decoder 128 wide (4 x 128), measured on 400 one-sun views: in the scene
#: 96.8 / 98.2 / 97.7 % and 27.2 dB against 95.0 / 96.7 / 98.2 % and 26.4 dB for 4 x 64, same training time
#: (spec/accuracy.md#dense-hair)
RNA_BLENDER_FIBER_TRAIN = {"small": dict(hidden=128)}
#: what Blender bakes change in RNA_TRAIN: at `small` 24 epochs for the eight samples per pixel of 8-sun views. Measured
#: in the scene (spec/accuracy.md#light-groups): the surface example 32.3 against 31.1 dB, the dense hair example 29.4
#: against 28.7 dB, an unseen groom +1.4 to +1.8 % and 28.7 dB against +2.8 to +7.0 % and 27.0 dB, for 80-140 s more
#: training
RNA_BLENDER_TRAIN = {"small": dict(epochs=24)}
#: what Mitsuba fiber bakes (curve shapes) change in RNA_TRAIN: the Blender fibers' wider decoder; their views keep
#: RNA_MITSUBA_DATA, whose per-pixel lights already give every pixel its own light direction (12 epochs: 40 moved the
#: Mitsuba hair by +0.8 dB, within the seed spread; docs/bench-mitsuba-jit.md#hair-dense)
RNA_MITSUBA_FIBER_TRAIN = RNA_BLENDER_FIBER_TRAIN

#: data presets (neupress_dataset.NeupressDataSettings fields); measured in spec/bake-neupress.md
NEUPRESS_MITSUBA_DATA = {
    "tiny": dict(views=12, val_views=2, res=24, spp=8, val_res=24, val_spp=128),
    "small": dict(views=640, val_views=12, res=64, spp=32, val_res=64, val_spp=1024),
    "hq": dict(views=400, val_views=16, res=128, spp=64, val_res=96, val_spp=4096),
}

#: the data-noise rule of rna and neupress bakes (spec/bake.md#data-noise): where the training set's relative
#: noise is above ``target``, more training views (at most ``max_factor`` x the preset's) bring it down; None: views as
#: the preset. Measured on the high-albedo pebble and the built-in examples (spec/accuracy.md#data-noise)
DATA_NOISE_SMALL = dict(target=4.5e-6, max_factor=2.0)
RNA_MITSUBA_DATA_NOISE = {"tiny": None, "small": DATA_NOISE_SMALL, "hq": None}
RNA_BLENDER_DATA_NOISE = {"tiny": None, "small": DATA_NOISE_SMALL, "hq": None}
NEUPRESS_MITSUBA_DATA_NOISE = {"tiny": None, "small": DATA_NOISE_SMALL, "hq": None}

#: sampler presets: held-out tuples, Russian-roulette start, depth cap
EIGHTDNA_MITSUBA_SAMPLER = {
    "tiny": dict(heldout=2048, rr_depth=4, max_depth=256),
    "small": dict(heldout=16384, rr_depth=4, max_depth=1024),
    "hq": dict(heldout=65536, rr_depth=8, max_depth=4096),
}

#: points (x_o, w_o) on which the albedo is renormalised for the flow's unlit mass (spec/bake-8dna.md#renormalise)
EIGHTDNA_RENORM = {"tiny": dict(points=2048), "small": dict(points=8192), "hq": dict(points=32768)}


# -- training ------------------------------------------------------------------------------------
#: per-preset training defaults (network sizes: nasset_sdk.kinds.rna.SIZES)
RNA_TRAIN = {
    "tiny": dict(epochs=40, batch=1024),
    "small": dict(epochs=12, batch=1024, plane_lr=3e-3),
    "hq": dict(epochs=40, batch=8192, plane_lr=3e-3),
}

#: per-preset training defaults (network sizes: nasset_sdk.kinds.neupress.SIZES)
NEUPRESS_TRAIN = {
    "tiny": dict(epochs=30, batch=512, sampling_epochs=15, sampling_samples=1024, sampling_bins=12, prt_dirs=64),
    "small": dict(epochs=12, batch=2048, sampling_epochs=30, sampling_samples=4096, sampling_bins=16, prt_dirs=256),
    "hq": dict(epochs=80, batch=4096, sampling_epochs=40, sampling_samples=16384, sampling_bins=24, prt_dirs=1024),
}

#: per-preset training defaults (network sizes: nasset_sdk.kinds.eightdna.SIZES). small: 13 000 steps, each buffer
#: used once (fresh tuples), the weight average, hq's 4 x 128 flows: under the bench's light every seed of four within
#: 2.8 % and bias^2 mean 1.17e-5; backlit means +4 / +3 / -1 %; bake 14.5 min on an idle 2-core machine
#: (spec/bake-8dna.md#steps)
EIGHTDNA_TRAIN = {
    "tiny": dict(steps=60, batch=1024, buffer=1 << 14, reuse=1),
    "small": dict(steps=13000, batch=2048, buffer=1 << 18, reuse=1, average=0.999),
    "hq": dict(steps=20000, batch=8192, buffer=1 << 21, reuse=1),
}


#: (source, kind) -> data table; kind -> training table; kind -> network shapes
DATA = {("mitsuba", "rna"): RNA_MITSUBA_DATA, ("blender", "rna"): RNA_BLENDER_DATA,
        ("mitsuba", "neupress"): NEUPRESS_MITSUBA_DATA, ("mitsuba", "8dna"): EIGHTDNA_MITSUBA_SAMPLER}
TRAIN = {"rna": RNA_TRAIN, "neupress": NEUPRESS_TRAIN, "8dna": EIGHTDNA_TRAIN}
NETWORK = {"rna": rna.SIZES, "neupress": neupress.SIZES, "8dna": eightdna.SIZES}


def preset(source: str, kind: str, size: str) -> dict:
    """The three parts of one preset: ``{"data": ..., "train": ..., "network": ...}`` (KeyError when unknown)."""
    return {"data": DATA[(source, kind)][size], "train": TRAIN[kind][size], "network": NETWORK[kind][size]}
