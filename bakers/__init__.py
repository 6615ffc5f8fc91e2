"""Bakers: an object of a source scene -> a trained neural asset (spec/bake.md).

Stages: scene -> data (the converters' ground truth) -> train (:mod:`nasset_bakers.train`) -> export
(ONNX + tensors through ``nasset_sdk``) -> check (the written asset against torch). One module per
source and kind (``mitsuba/rna.py``, ``mitsuba/neupress.py``, ``mitsuba/eightdna.py``,
``blender/rna.py``), each registering itself in :mod:`nasset_bakers.registry`.
"""

from .registry import BAKERS, baker_for, register_baker  # noqa: I001  (first: the baker modules register into it)
from .blender import rna as _blender_rna  # noqa: F401
from .mitsuba import eightdna as _mitsuba_eightdna, neupress as _mitsuba_neupress, rna as _mitsuba_rna  # noqa: F401

__all__ = ["BAKERS", "baker_for", "register_baker"]
