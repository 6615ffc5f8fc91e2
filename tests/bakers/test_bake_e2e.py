"""End-to-end bake: Mitsuba ground truth -> torch training -> ONNX + tensors -> SDK evaluation.

Runs at tiny scale (a few seconds of rendering and training on 2 cores). Skipped only when
mitsuba or torch cannot be imported; CI installs both (extras ``train`` and ``mitsuba``).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="bake tests need mitsuba (pip install 'nasset-sdk[mitsuba]')")
torch = pytest.importorskip("torch", reason="bake tests need torch (pip install torch==2.13.0)")

from nasset_bakers.mitsuba.rna import bake  # noqa: E402
from nasset_bakers.train.rna import build_model, display_psnr, select_branch  # noqa: E402
from nasset_converters.mitsuba.dataset import DatasetDir  # noqa: E402
from nasset_sdk.asset import Asset  # noqa: E402
from nasset_sdk.kinds.encodings import to_unit_box, triplane  # noqa: E402

#: held-out PSNR floor for the tiny bake of the example scene (display PSNR, spec/bake.md#psnr) on its unclamped
#: held-out views. Measured 17.8 dB (seed 0: 16 views of 24^2, per-pixel lights, plain L2 loss); the floor leaves
#: 1.8 dB of margin for platform differences in Mitsuba's sampling and torch's float summation order. With
#: training disabled (``opt.step()`` removed in ``train/rna.py``) the bake scores 7.0 dB, with the feature planes
#: frozen (their learning rate 0) 15.9 dB: both fail (the latter also the constant-colour margin below).
TINY_PSNR_FLOOR_DB = 16.0
#: SDK (numpy triplane + onnxruntime) vs torch model on the same held-out inputs. Measured ~1e-7
#: (tiny) and ~4e-6 (small; the decoder's exp lobe features amplify float32 rounding) -- both use
#: the stored float16 planes widened to float32; 1e-4 allows for BLAS/threading order.
PARITY_TOL = 1e-4
#: margin over the best constant colour (held-out mean) on the same held-out pixels. Measured +1.9 dB
#: (18.8 vs 16.9) with clamped held-out references and the log loss; +0.65 dB (17.8 vs 17.2) since the
#: held-out references are unclamped (their noise caps both scores, spec/accuracy.md) and the loss is
#: plain L2. About half of the current margin is required: a model that learned nothing scores <= 0.
BEAT_CONSTANT_DB = 0.3


@pytest.fixture(scope="module")
def tiny_bake(tmp_path_factory):
    out = tmp_path_factory.mktemp("bake") / "example_tiny.usdc"
    summary = bake(None, None, out, size="tiny", example=True, quiet=True)
    return out, summary


def test_tiny_bake_writes_valid_asset(tiny_bake):
    out, summary = tiny_bake
    assert out.exists() and summary["asset_bytes"] == out.stat().st_size
    from nasset_sdk.validate import validate_file

    report = validate_file(out)
    assert report.ok, report.to_dict()
    asset = Asset.open(out)
    asset.load("all")
    assert asset.kind == "rna" and asset.variant == "surface"
    planes = asset.tensor("core", "triplane")
    assert planes.shape == (3, 8, 8, 4)
    prov = asset.provenance
    assert prov["source"]["shapes"] == ["shell", "jelly"]
    assert prov["source"]["variant"] in ("llvm_ad_rgb", "scalar_rgb")
    assert prov["onnx"]["max_abs_diff_vs_torch"] < 1e-4
    assert prov["validation"]["psnr_db"] > TINY_PSNR_FLOOR_DB
    assert set(prov["timings_s"]) >= {"scene_s", "dataset_s", "train_s"}
    json.dumps(prov)  # provenance is strict JSON (no NaN)


def test_tiny_bake_sdk_evaluation_on_held_out_views(tiny_bake):
    out, summary = tiny_bake
    store = DatasetDir(summary["dataset_dir"])
    val = store.load_split("val", summary["val_views"])
    assert len(val["x"]) > 100
    asset = Asset.open(out)
    asset.load("all")
    un, sh = asset.evaluator().evaluate(val["x"], val["n"], val["wo"], val["wi"])
    y = np.concatenate([un, sh], axis=1)
    assert np.isfinite(y).all() and (y >= 0).all()
    psnr, mse, peak = display_psnr(select_branch(y, val["vis"]), val["rgb"])
    assert peak > 0 and math.isfinite(mse)
    assert psnr > TINY_PSNR_FLOOR_DB, f"held-out PSNR {psnr:.2f} dB below floor {TINY_PSNR_FLOOR_DB}"
    # the best constant colour (the held-out mean), a baseline independent of the model
    base = display_psnr(np.broadcast_to(val["rgb"].mean(0), val["rgb"].shape), val["rgb"])[0]
    print(f"\nrna tiny bake: held-out {psnr:.2f} dB, constant colour {base:.2f} dB")
    assert psnr >= base + BEAT_CONSTANT_DB, (psnr, base)
    assert summary["sdk_vs_torch_max_abs"] < PARITY_TOL
    assert abs(summary["sdk_val_psnr_db"] - psnr) < 1e-3


def test_torch_triplane_lookup_matches_sdk_encoding():
    """grid_sample(align_corners=False, border) == encodings.grid_sample_2d, incl. out-of-box points."""
    model = build_model("tiny", init_std=1.0, seed=3).eval()
    rng = np.random.default_rng(0)
    xn = rng.uniform(-1.3, 1.3, (5000, 3)).astype(np.float32)  # also outside [-1, 1]: edge clamp
    xn[:10] = [[-1, -1, -1], [1, 1, 1], [0, 0, 0], [-1, 1, 0], [0.999, -0.999, 0.5]] * 2
    with torch.no_grad():
        f_torch = model.features(torch.from_numpy(xn), 0.0).numpy()
    planes = model.planes.detach().permute(0, 2, 3, 1).numpy()  # [3, v, u, C]
    f_sdk = triplane(planes, xn)
    assert np.max(np.abs(f_torch - f_sdk)) < 1e-5


def test_decoder_features_are_the_documented_functions():
    """The exported decoder's parameter-free feature step (encoding "lobes", spec/bake.md#training) appends
    n.wi, n.wo, n.h, wo.wi and exp(k (n.h - 1)), h = normalise(wo + wi): checked against numpy on rows with
    grazing, below-horizon and opposite directions (h undefined), and through onnxruntime (the graph assets store)."""
    from nasset_bakers.train.rna import LOBE_SHARPNESS, export_onnx, onnx_parity

    rng = np.random.default_rng(5)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    n, wo, wi = (unit(rng.normal(size=(400, 3))) for _ in range(3))
    n[0], wo[0], wi[0] = [0, 0, 1], [1, 0, 0], [0, 1, 0]  # both grazing
    n[1], wo[1], wi[1] = [0, 0, 1], [0, 0, -1], [0, 0, 1]  # wo below the horizon
    wi[2] = -wo[2]  # wo + wi = 0
    model = build_model("tiny", seed=1).eval()
    c = model.in_width - 12
    row = np.concatenate([rng.normal(size=(400, c + 3)), n, wo, wi], 1).astype(np.float32)
    with torch.no_grad():
        got = model.decoder[0](torch.from_numpy(row)).numpy()
    assert np.array_equal(got[:, :model.in_width], row)  # the contract's row passes through unchanged
    h = wo + wi
    h = h / np.sqrt((h * h).sum(1, keepdims=True) + 1e-8)
    dot = lambda a, b: (a * b).sum(1)  # noqa: E731
    nh = dot(n, h)
    want = [dot(n, wi), dot(n, wo), nh, dot(wo, wi)] + [np.exp(k * (nh - 1)) for k in LOBE_SHARPNESS]
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got[:, model.in_width:], np.stack(want, 1), atol=2e-6)
    assert onnx_parity(model, export_onnx(model)) < 1e-5


def test_unit_box_matches_domain(tiny_bake):
    out, _ = tiny_bake
    asset = Asset.open(out)
    geo = asset.geometry()
    lo, hi = asset.domain
    xn = to_unit_box(geo.points, lo, hi)
    assert xn.min() >= -1 and xn.max() <= 1


def test_resume_reuses_dataset(tiny_bake, tmp_path):
    """A second bake into the same dataset folder renders nothing (all views present)."""
    out, summary = tiny_bake
    out2 = tmp_path / "again.usdc"
    s2 = bake(None, None, out2, size="tiny", example=True, quiet=True, resume=summary["dataset_dir"], epochs=2)
    assert s2["train_samples"] == summary["train_samples"]
    assert s2["times_s"]["dataset_s"] < summary["times_s"]["dataset_s"] + 1.0


@pytest.mark.slow
def test_small_bake_example(tmp_path):
    """The `small` preset on the example scene (~2.5 min on 2 shared cores, up to ~4 min under load).
    Measured 34.3 dB held-out (seed 0; reference 1024 spp, clamp 10: spec/bake.md#ablations)."""
    summary = bake(None, None, tmp_path / "small.usdc", size="small", example=True, quiet=True)
    assert summary["sdk_vs_torch_max_abs"] < PARITY_TOL
    assert summary["val_psnr_db"] > 30.0
