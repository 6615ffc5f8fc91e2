"""Second implementation of spec/renderer.md: neural assets rendered inside Mitsuba 3.

Written from the specification text (spec/format.md, spec/kinds/rna.md, spec/kinds/neupress.md, spec/kinds/encodings.md,
spec/renderer.md) and independent of ``nasset_sdk``'s evaluators and of ``nasset_reference_renderer``:

- :mod:`.usdscene` reads the USD scene (camera, meshes + UsdPreviewSurface, UsdLux lights,
  NeuralAsset prims); which prims, camera, image size and bindings a render reads (render settings, purposes,
  visibility, payloads, time) are the scene rules of ``nasset_sdk.stage_rules``, shared with the reference
  renderer; the shading is this package's own;
- :mod:`.rna` reads an ``rna`` asset file (sha256-checked decoder, triplane; mesh or fiber curves
  tessellated into the spec's prisms) and evaluates its transport with its own triplane lookup and
  onnxruntime;
- :mod:`.neupress` reads a ``neupress`` asset (Fourier features, appearance and sigma networks,
  GGX boundary) and shades its far-field vertex (light sampling + lobe / uniform technique, MIS);
- :mod:`.lights` wraps Mitsuba emitters (point, directional, sphere and rectangle area lights)
  and adds what Mitsuba lacks with the spec's exact conventions (cone distant light, nearest-texel
  lat-long dome, the spot cone's linear and smoothstep falloffs on point lights);
- :mod:`.eightdna` reads an ``8dna`` asset (encodings, spline flow) and shades its vertices
  (direct lobe + neural estimator, spec/renderer.md#8dna);
- :mod:`.integrator` is the wavefront path tracer (Mitsuba ray tracing on whole batches, shading
  in numpy, neural transport batched through onnxruntime); per-kind shaders plug in through its
  ``ASSET_SHADERS`` registry.

The CLI is ``python -m nasset_mitsuba_renderer.render``.
"""
