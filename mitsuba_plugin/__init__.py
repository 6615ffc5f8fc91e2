"""Neural assets rendered inside Mitsuba 3's JIT: every per-sample operation runs in Dr.Jit.

Unlike ``nasset_mitsuba_renderer`` (Mitsuba ray casts, numpy shading, onnxruntime), this package
compiles the whole path (ray tracing, Mitsuba BSDFs and emitters, the asset's triplane lookup and
decoder MLP) into Dr.Jit kernels, so the same code runs on ``llvm_ad_rgb`` (CPU) and
``cuda_ad_rgb`` (GPU):

- :mod:`.variant` sets a JIT Mitsuba variant (typed error when none is usable);
- :mod:`.network` traces an asset's ONNX network (read once) into Dr.Jit (affine layers through ``drjit.nn``);
- :mod:`.rna` evaluates an ``rna`` surface asset's transport (spec/kinds/rna.md) in Dr.Jit;
- :mod:`.preview` is UsdPreviewSurface as a Dr.Jit BSDF (``nasset_preview``), :mod:`.lights` the cone
  DistantLight as a Dr.Jit emitter (``nasset_cone``), both for USD scenes;
- :mod:`.plugins` registers the ``nasset`` BSDF (marks a shape as an asset instance) and the
  ``nasset_path`` integrator (spec/renderer.md#neural-assets at asset hits, Mitsuba's ``path`` elsewhere);
- :mod:`.prt` is the integrator's neupress PRT mode (``prt``: the dome's SH projection per instance at load
  time, the per-vertex gathers in Dr.Jit);
- :mod:`.scene` builds Mitsuba scenes holding assets: ``asset_shape()`` for dict scenes,
  ``load_file()`` for XML with ``<shape type="nasset">``, ``usd_scene()`` for nasset USD scenes;
- :mod:`.render` is the command line (``python -m nasset_mitsuba_plugin.render``), a conformance renderer.
"""
