"""How a USD scene refers to an asset, in the plugin (spec/format.md#referencing-an-asset): a flattened scene holds the
asset's specs inline; the plugin reads them from a copy (nasset_sdk.references.embedded_asset_file). Both Mitsuba
implementations refused such a scene (SCENE_UNSUPPORTED); the reference renderer rendered it."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.render import render  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder, random_rna_asset  # noqa: E402


def test_flattened_scene_renders_as_the_referencing_one(tmp_path):
    """The same image at the same seed, with the asset file deleted after flattening, to float32 rounding. The two
    instances are two embedded copies in the flattened layer; without their placement (the xformOps) they are the same
    specs, so one file and one asset to the plugin (it was one per instance: a flattened scene of N instances read and
    held the asset N times)."""
    from pxr import Usd

    from nasset_mitsuba_renderer.usdscene import read_scene

    random_rna_asset(tmp_path / "a.usdc")
    b = SceneBuilder()
    b.camera((0, 0.6, 3), (0, 0, 0), focal=45)
    b.quad("Floor", (0, -0.5, 0), 4.0, diffuse=(0.5, 0.5, 0.5))
    b.distant("Sun", (0.3, 1.0, 0.5), 2.0)
    for name, x in (("Left", -0.6), ("Right", 0.6)):
        m = np.eye(4)
        m[3, :3] = (x, 0.0, 0.0)
        b.asset(name, "./a.usdc", m, typed="Xform")
    scene = b.write(tmp_path / "scene.usda")
    want = render(str(scene), 4, seed=2, width=32, height=24)
    Usd.Stage.Open(str(scene)).Flatten().Export(str(tmp_path / "flat.usda"))
    (tmp_path / "a.usdc").unlink()
    got = render(str(tmp_path / "flat.usda"), 4, seed=2, width=32, height=24)
    files = {inst.file for inst in read_scene(str(tmp_path / "flat.usda")).assets}
    assert len(files) == 1, files
    assert want[:, :16].mean() > 0.01 and want[:, 16:].mean() > 0.01  # both instances in view
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
