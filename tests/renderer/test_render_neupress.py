"""Reference renderer, kind neupress (spec/renderer.md#neupress): the sampling strategies agree,
PRT agrees with path mode under a dome of SH degree <= 2, and the plan loads only what it uses."""

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, make_plan, render
from nasset_reference_renderer.film import write_exr
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.asset import Asset
from nasset_sdk.errors import UsageError
from nasset_sdk.examples import example_builder
from nasset_sdk.kinds.encodings import sh9
from tests.renderer.render_stats import assert_renders_agree, render_finite

Z_MEAN = 4.5  # |difference of image means| / its standard error, per channel
Z_PIXEL, PIXEL_FRACTION = 3.5, 0.05  # at most 5 % of pixels may differ by more than 3.5 sigma


def _gradient_dome(path, c0=1.0, c1=0.8, hot=0.0, rows=64, cols=16):
    """Lat-long texture L = c0 + c1 cos(theta) (theta at the row centre), optionally with a bright patch."""
    theta = (np.arange(rows) + 0.5) / rows * np.pi
    img = np.repeat((c0 + c1 * np.cos(theta))[:, None, None], cols, 1).repeat(3, 2)
    if hot:
        img[rows // 5:rows // 5 + 3, cols // 4:cols // 4 + 2] += hot
    write_exr(path, img.astype(np.float32))
    return str(path)


def _scene(tmp_path, asset, *, lights=True, dome_tex=None, name="s.usda"):
    b = SceneBuilder()
    b.camera((0, 0.3, 3.0), (0, 0, 0), focal=55)
    b.dome("Dome", 0.6, texture=dome_tex, color=(1.0, 0.8, 0.6))
    if lights:
        b.sphere_light("Bulb", (1.4, 1.6, 1.2), 0.6, 6.0)
        b.distant("Sun", (0.3, 1.0, -0.4), 1.5)
    b.asset("Obj", asset)
    return b.write(tmp_path / name)


def _render(path, **kw):
    return render_finite(path, **kw)


def _agree(a, b):
    return assert_renders_agree(a, b, z_mean=Z_MEAN, z_pixel=Z_PIXEL, pixel_fraction=PIXEL_FRACTION)


def test_sampling_strategies_converge_to_one_image(tmp_path):
    asset = example_builder("neupress", size="tiny", seed=5).write(tmp_path / "np.usdc")
    tex = _gradient_dome(tmp_path / "dome.exr", hot=10.0)
    path = _scene(tmp_path, asset, dome_tex=tex)
    res = {m: _render(path, spp=96, seed=i, neupress_sampling=m) for i, m in enumerate(("dome", "lobe", "mis"))}
    assert res["mis"].image.max() > 0
    _agree(res["dome"], res["mis"])
    _agree(res["lobe"], res["mis"])
    _agree(res["dome"], res["lobe"])
    # MIS is never much worse than the better single technique
    var = {m: r.variance.sum() for m, r in res.items()}
    assert var["mis"] < 1.5 * min(var["dome"], var["lobe"]), var


def test_uniform_sphere_fallback_without_sampling_component(tmp_path):
    b = example_builder("neupress", size="tiny", seed=6)
    del b.components["sampling"]
    asset = b.write(tmp_path / "nosamp.usdc")
    path = _scene(tmp_path, asset)
    plan = make_plan(load_scene(path), width=8, height=8, spp=1, max_depth=5, tile=64, batch=65536, neupress_sampling="mis")
    assert plan.asset_modes[0]["lobe"] is False and "uniform sphere" in plan.explain()
    _agree(_render(path, spp=64, seed=1, neupress_sampling="dome"), _render(path, spp=64, seed=2, neupress_sampling="mis"))


def _wi_only_asset(tmp_path):
    """A neupress asset whose S depends on w_i only (smooth), with zero surface reflection (eta 1), and
    PRT coefficients a_k = integral S Y_k computed here by quadrature. Returns (file, S on the grid, grid dirs, d omega)."""
    b = example_builder("neupress", size="tiny", seed=11)
    core = b.components["core"][""]
    g = np.random.default_rng(3).normal(18.0, 1.0, (16, 7))
    g[:, :5] = 0.0  # no x_o / w_o dependence: PRT bins and vertex interpolation are then exact
    g[:, 5:] *= 0.08  # about 1.5 cycles over the sphere: a smooth S
    core.add_tensor("fourier", g, dtype="float32", layout="frequency,input")
    core.add_tensor("boundary", np.array([1.0, 0.2]), dtype="float32", layout="parameter")  # eta 1: F = 0
    first = b.write(tmp_path / "wi0.usdc")
    ev = Asset.open(first, load="all").evaluator()
    nz, nphi = 256, 512
    z = 1 - (np.arange(nz) + 0.5) / nz * 2
    phi = (np.arange(nphi) + 0.5) / nphi * 2 * np.pi - np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(1 - zz ** 2)
    dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], -1).reshape(-1, 3)
    dw = 4 * np.pi / len(dirs)
    ones = np.tile([0.0, 0.0, 1.0], (len(dirs), 1))
    S = ev.evaluate(ones * 0.1, ones, ones, dirs).astype(np.float64)
    a = (sh9(dirs)[:, :, None] * S[:, None, :]).sum(0) * dw  # [9, 3]
    sh = b.components["prt"][""].tensors["sh"][0]
    prt = np.broadcast_to(a, sh.shape[:3] + (9, 3)).copy()
    b.components["prt"][""].add_tensor("sh", prt, dtype="float32", layout="vertex,theta_o,phi_o,sh,rgb")
    return b.write(tmp_path / "wi.usdc"), S, dirs, dw


def test_prt_matches_path_mode_under_degree2_dome(tmp_path):
    asset, S, dirs, dw = _wi_only_asset(tmp_path)
    c0, c1, rows = 1.0, 0.8, 64
    tex = _gradient_dome(tmp_path / "grad.exr", c0, c1, rows=rows)
    path = _scene(tmp_path, asset, lights=False, dome_tex=tex, name="prt.usda")
    prt = _render(path, spp=4, prt=True)
    ref = _render(path, spp=128, neupress_sampling="mis")
    k = 16 * 16
    se = np.sqrt(ref.variance.sum((0, 1))) / k
    m_prt, m_ref = prt.image.mean((0, 1)), ref.image.mean((0, 1))
    # SH2 captures a degree-1 dome exactly; what remains is the texel quantisation of the dome (about 1 %)
    # and Monte Carlo noise of the path-mode image
    assert (np.abs(m_prt - m_ref) < 4 * se + 0.01 * m_ref).all(), (m_prt, m_ref, se)
    # and the PRT value of an asset pixel is the exact integral of S against the (texel) dome
    theta = np.arccos(np.clip(dirs[:, 1], -1, 1))  # the asset is not rotated: object = world = dome frame
    row = np.minimum((theta / np.pi * rows).astype(int), rows - 1)
    lum = 0.6 * (c0 + c1 * np.cos((row + 0.5) / rows * np.pi))[:, None] * np.array([1.0, 0.8, 0.6])
    exact = (S * lum).sum(0) * dw
    centre = prt.image[8, 8]
    np.testing.assert_allclose(centre, exact, rtol=0.01)
    assert np.ptp(prt.image[6:10, 6:10], axis=(0, 1)).max() < 1e-3 * centre.max()  # S independent of x_o, w_o


def test_plan_loads_only_used_components(tmp_path):
    asset = example_builder("neupress", size="tiny", seed=7).write(tmp_path / "np.usdc")
    path = _scene(tmp_path, asset)
    for mode, loaded in (("dome", ["core"]), ("lobe", ["core", "sampling"]), ("mis", ["core", "sampling"])):
        scene = load_scene(path)
        res = render(scene, RenderSettings(width=4, height=4, spp=1, neupress_sampling=mode))
        comps = scene.assets[0].asset.components()
        assert sorted(n for n, c in comps.items() if c.loaded) == loaded, mode
        assert res.plan.components[str(scene.assets[0].path)] == (loaded, [n for n in ("core", "sampling", "prt")
                                                                         if n not in loaded])
        assert "neupress np.usdc" in res.plan.explain()
    scene = load_scene(path)
    res = render(scene, RenderSettings(width=4, height=4, spp=1, prt=True))
    comps = scene.assets[0].asset.components()
    assert comps["prt"].loaded and not comps["sampling"].loaded
    assert "PRT" in res.plan.explain() and np.isfinite(res.image).all()
    # PRT needs a dome light and the prt component
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", (0, 1, 0), 1.0)
    b.asset("Obj", asset)
    with pytest.raises(UsageError, match="DomeLight"):
        make_plan(load_scene(b.write(tmp_path / "nodome.usda")), width=4, height=4, spp=1, max_depth=2, tile=8, batch=64,
                  prt=True)


def test_cli_flags_and_explain(tmp_path, capsys):
    from nasset_sdk.cli import main

    asset = example_builder("neupress", size="tiny", seed=8).write(tmp_path / "np.usdc")
    path = _scene(tmp_path, asset, lights=False)
    out = tmp_path / "o.exr"
    assert main(["render", path, "-o", str(out), "--spp", "1", "--width", "4", "--height", "4", "--explain", "--quiet",
                 "--neupress-sampling", "dome"]) == 0
    text = capsys.readouterr().out
    assert "load ['core']; skip ['sampling', 'prt']" in text and "light sampling only" in text
    assert main(["render", path, "-o", str(out), "--spp", "1", "--width", "4", "--height", "4", "--explain", "--quiet",
                 "--prt"]) == 0
    assert "load ['core', 'prt']; skip ['sampling']" in capsys.readouterr().out
