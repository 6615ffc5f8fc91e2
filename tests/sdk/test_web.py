"""``nasset web``: the export (files, typed errors), the local server, the checked-in page build, and the page
itself in headless Chromium (Debian's package, driven by tools/web-viewer/drive.mjs) against the reference
renderer. scripts/setup.sh installs Chromium and the npm packages; in CI (``CI`` set) a missing browser or
package fails the browser tests instead of skipping them."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import urllib.request
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from nasset_sdk import Asset, portable, web
from nasset_sdk.errors import NassetError
from nasset_sdk.examples import example_builder

VIEWER = Path(__file__).resolve().parents[2] / "tools" / "web-viewer"
CHROMIUM = "/usr/bin/chromium"
#: wall-clock bound of one browser run (WASM compilation and SwiftShader on a loaded 2-core machine)
BROWSER_TIMEOUT_S = 180


def tool_or_skip(*packages: str, browser: bool = False) -> str:
    node = shutil.which("node")
    missing = "node is not on PATH" if node is None else None
    for p in packages:
        if missing is None and not (VIEWER / "node_modules" / p).is_dir():
            missing = f"{p} is not installed in {VIEWER} (run scripts/setup.sh)"
    if missing is None and browser and not os.access(CHROMIUM, os.X_OK):
        missing = f"{CHROMIUM} is missing (Debian's chromium; scripts/setup.sh installs it)"
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"web viewer tools unavailable in CI: {missing}")
        pytest.skip(f"web viewer tools unavailable outside CI: {missing}")
    return node


def portable_asset(tmp_path: Path, kind: str = "rna", seed: int = 3) -> Path:
    src = tmp_path / "a.usdc"
    example_builder(kind, size="small", seed=seed).write(src)
    portable.add_portable(src, tmp_path / "p.usdc")
    return tmp_path / "p.usdc"


@contextmanager
def serving(folder: Path):
    server = web.make_server(folder, 0)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


def drive(node: str, work: Path, url: str, **job) -> dict:
    """Run the page at ``url`` in headless Chromium through drive.mjs; returns its result.json."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "job.json").write_text(json.dumps({"url": url, "out": "result.json", "timeoutS": BROWSER_TIMEOUT_S, **job}))
    r = subprocess.run([node, str(VIEWER / "drive.mjs"), str(work / "job.json")], capture_output=True, text=True,
                       timeout=BROWSER_TIMEOUT_S + 60)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads((work / "result.json").read_text())


# -- export -----------------------------------------------------------------------------------


def test_export_writes_the_page_mesh_graph_and_metadata(tmp_path):
    path = portable_asset(tmp_path)
    report = web.export(path, tmp_path / "site")
    site = tmp_path / "site"
    for name in (*web.PAGE_FILES, "asset.json", "mesh.bin", "decoder.onnx"):
        assert (site / name).is_file(), name
    assert report["totalBytes"] == sum(p.stat().st_size for p in site.iterdir())
    doc = json.loads((site / "asset.json").read_text())
    asset = Asset.open(path, load="all")
    assert (doc["kind"], doc["variant"]) == ("rna", "surface")
    # the graph file is the stored portable network, byte for byte
    assert (site / "decoder.onnx").read_bytes() == asset.network_bytes("portable", "decoder")
    assert doc["graphs"]["decoder"]["inputs"] == {"x": 3, "frame": 3, "wo": 3, "wi": 3}
    # mesh.bin: the asset's points, normals and triangles in the documented layout
    geo = asset.geometry()
    v, f = doc["mesh"]["vertices"], doc["mesh"]["triangles"]
    raw = (site / "mesh.bin").read_bytes()
    assert len(raw) == 24 * v + 12 * f
    np.testing.assert_array_equal(np.frombuffer(raw[:12 * v], "<f4").reshape(v, 3), np.asarray(geo.points, np.float32))
    n = np.frombuffer(raw[12 * v:24 * v], "<f4").reshape(v, 3)
    want_n = np.asarray(geo.normals, np.float64)
    np.testing.assert_allclose(n, want_n / np.linalg.norm(want_n, axis=1, keepdims=True), atol=1e-6)
    np.testing.assert_array_equal(np.frombuffer(raw[24 * v:], "<u4").reshape(f, 3), np.asarray(geo.faces))
    meta = doc["metadata"]
    assert meta["kind"] == "rna" and meta["fileBytes"] == path.stat().st_size and meta["provenance"]["generator"] == "random"
    assert len(doc["channels"]) == asset.tensor_refs("core")["triplane"].shape[-1]


def test_export_refuses_assets_it_cannot_show(tmp_path):
    plain = tmp_path / "plain.usdc"
    example_builder("rna", size="tiny", seed=1).write(plain)
    with pytest.raises(NassetError) as exc:
        web.export(plain, tmp_path / "site")
    assert exc.value.code == "COMPONENT_MISSING"
    assert "nasset optimize" in str(exc.value) and "--portable" in str(exc.value) and "plain.usdc" in str(exc.value)
    junk = tmp_path / "junk.usdc"
    junk.write_text("not a USD layer")
    with pytest.raises(NassetError) as exc:
        web.export(junk, tmp_path / "site")
    assert exc.value.code in ("FILE_UNREADABLE", "ROOT_MISSING") and "junk.usdc" in str(exc.value)
    with pytest.raises(NassetError) as exc:
        web.export(tmp_path / "nosuch.usdc", tmp_path / "site")
    assert exc.value.code == "FILE_NOT_FOUND"
    assert not (tmp_path / "site").exists()


def test_cli_verb_exports_and_reports_errors(tmp_path, capsys):
    from nasset_sdk.cli import all_verbs, main

    assert "web" in all_verbs()
    path = portable_asset(tmp_path)
    assert main(["web", str(path), "-o", str(tmp_path / "site")]) == 0
    assert "MiB" in capsys.readouterr().out
    plain = tmp_path / "plain.usdc"
    example_builder("rna", size="tiny", seed=1).write(plain)
    assert main(["web", str(plain), "-o", str(tmp_path / "site2")]) == 1
    assert "--portable" in capsys.readouterr().err


def test_server_serves_wasm_with_its_mime_type(tmp_path):
    (tmp_path / "m.wasm").write_bytes(b"\0asm\1\0\0\0")
    (tmp_path / "asset.json").write_text("{}")
    with serving(tmp_path) as url:
        with urllib.request.urlopen(url + "m.wasm") as r:
            assert r.headers["Content-Type"] == "application/wasm" and r.read() == b"\0asm\1\0\0\0"
        with urllib.request.urlopen(url + "asset.json") as r:
            assert r.headers["Content-Type"] == "application/json"
        assert url.startswith("http://127.0.0.1:")



def test_serve_flag_prints_the_url_and_serves_the_export(tmp_path):
    path = portable_asset(tmp_path)
    nasset = Path(shutil.which("nasset") or Path(sys.executable).with_name("nasset"))
    proc = subprocess.Popen([str(nasset), "web", str(path), "-o", str(tmp_path / "site"), "--serve", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        while not any(line.startswith("serving") for line in lines):
            line = proc.stdout.readline()
            assert line, (lines, proc.stderr.read()[-2000:])
            lines.append(line)
        url = lines[-1].split(" at ")[1].split()[0]
        assert url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(url, timeout=30) as r:
            assert r.read() == (web.PAGE_DIR / "index.html").read_bytes()
        with urllib.request.urlopen(url + "asset.json", timeout=30) as r:
            assert json.loads(r.read())["kind"] == "rna"
    finally:
        proc.terminate()
        proc.wait(timeout=30)

def test_checked_in_page_equals_a_fresh_build(tmp_path):
    node = tool_or_skip("esbuild", "three", "onnxruntime-web")
    r = subprocess.run([node, str(VIEWER / "build.mjs"), str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    for name in web.PAGE_FILES:
        fresh, shipped = (tmp_path / name).read_bytes(), (web.PAGE_DIR / name).read_bytes()
        assert fresh == shipped, f"nasset_sdk/web_viewer/{name} differs from a fresh build: run node tools/web-viewer/build.mjs"


# -- the page in headless Chromium ------------------------------------------------------------

#: view and light of the comparison (object space, +Y up; the asset is a sphere of radius 0.5 at the origin)
EYE, TARGET, FOV_DEG = (0.0, 0.5, 2.5), (0.0, 0.0, 0.0), 35.0
LIGHT, IRRADIANCE = (0.5, 0.8, 0.3), 2.0
SIZE, WEB_SAMPLES, REF_SPP = 128, 16, 32
#: display exposure (stops) of the canvas check: the page's tone mapping must equal the reference renderer's PNG curve
EXPOSURE = 0.5


def relative_l1(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).sum() / max(np.abs(b).sum(), 1e-12))


def reference_render(tmp_path: Path, asset: Path, seed: int) -> np.ndarray:
    """``nasset render`` of the same view and light (a delta distant light, no ambient, one bounce): [H, W, 3]."""
    from nasset_reference_renderer.testscenes import SceneBuilder
    from nasset_sdk.images import read_exr

    b = SceneBuilder()
    b.camera(EYE, TARGET, focal=35.0, aperture=70.0 * np.tan(np.radians(FOV_DEG / 2)))
    b.distant("Key", LIGHT, IRRADIANCE)
    b.asset("Asset", asset)
    scene = b.write(tmp_path / "scene.usda")
    out = tmp_path / f"ref{seed}.exr"
    nasset = Path(shutil.which("nasset") or Path(sys.executable).with_name("nasset"))
    r = subprocess.run([str(nasset), "render", scene, "-o", str(out), "--spp", str(REF_SPP), "--seed", str(seed), "--max-depth", "1",
                        "--width", str(SIZE), "--height", str(SIZE), "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return read_exr(out)[..., :3].astype(np.float64)


def test_page_matches_the_reference_renderer(tmp_path):
    """The page's linear radiance against two ``nasset render`` images (different seeds) of the same view: the
    mean over the object within 3 % (a graph output scaled by 1.1 is off by 10 %) and the per-pixel relative L1
    below 8 % and below 1.3x the reference's own seed-to-seed difference (the noise ceiling: pixel-footprint noise of 32
    spp; the page's 16 stratified jittered samples add less).
    A flipped light direction swaps the lit and unlit sides (relative L1 near 1). The canvas's 8-bit pixels equal
    the reference renderer's tone curve of the page's radiance at the chosen exposure, within one level."""
    from scipy.ndimage import binary_erosion

    node = tool_or_skip("playwright-core", browser=True)
    path = portable_asset(tmp_path)
    web.export(path, tmp_path / "site")
    with serving(tmp_path / "site") as url:
        res = drive(node, tmp_path / "drive", f"{url}?size={SIZE}", camera={"eye": EYE, "target": TARGET, "fovDeg": FOV_DEG},
                    settings={"light": LIGHT, "irradiance": IRRADIANCE, "ambient": 0.0, "samples": WEB_SAMPLES, "exposure": EXPOSURE},
                    canvas=True)
    assert res["error"] is None, (res["error"], res["console"][-10:])
    lin = res["linear"]
    assert (lin["width"], lin["height"]) == (SIZE, SIZE) and res["stats"]["samples"] == WEB_SAMPLES
    got = np.asarray(lin["rgb"], np.float64).reshape(SIZE, SIZE, 3)
    mask = np.asarray(lin["mask"]).reshape(SIZE, SIZE) > 0
    assert np.isfinite(got).all()
    ref0, ref1 = reference_render(tmp_path, path, 0), reference_render(tmp_path, path, 1)
    ref = 0.5 * (ref0 + ref1)
    covered = ref.max(-1) > 0
    # coverage agrees up to the silhouette (pixels partly covered are averaged differently)
    assert (mask ^ covered).sum() <= 0.05 * covered.sum()
    inner = binary_erosion(mask & covered, iterations=2)
    assert inner.sum() > 2000
    mean_ratio = got[inner].mean() / ref[inner].mean()
    err = relative_l1(got[inner], ref[inner])
    ceiling = relative_l1(ref0[inner], ref1[inner])
    print(f"web vs reference: mean ratio {mean_ratio:.4f}, relative L1 {err:.4f}; reference seed-to-seed relative L1 {ceiling:.4f}")
    assert abs(mean_ratio - 1.0) < 0.03, mean_ratio
    assert err < min(0.08, 1.3 * ceiling), (err, ceiling)
    # what the canvas shows is nasset_sdk.images.tonemap (the reference renderer's PNG curve) of that radiance
    from nasset_sdk.images import tonemap

    shown = np.asarray(res["canvas"]["rgba"], np.int64).reshape(SIZE, SIZE, 4)[..., :3]
    want = tonemap(got.astype(np.float32), EXPOSURE).astype(np.int64)
    assert np.abs(shown - want)[mask].max() <= 1
    assert np.ptp(want[mask]) > 100  # a real range of tones was compared


def test_page_says_what_is_missing_instead_of_a_blank_canvas(tmp_path):
    node = tool_or_skip("playwright-core", browser=True)
    site = tmp_path / "site"
    web.export(portable_asset(tmp_path), site)
    doc = json.loads((site / "asset.json").read_text())
    doc["graphs"] = {}  # what an export of an asset without the portable component would hold
    (site / "asset.json").write_text(json.dumps(doc))
    with serving(site) as url:
        res = drive(node, tmp_path / "drive", url)
    assert res["error"] and "nasset optimize" in res["message"] and "--portable" in res["message"]


@pytest.mark.slow
def test_page_without_an_export_webgl_or_a_known_kind_says_so(tmp_path):
    node = tool_or_skip("playwright-core", browser=True)
    site = tmp_path / "site"
    web.export(portable_asset(tmp_path), site)
    (site / "asset.json").unlink()
    with serving(site) as url:
        res = drive(node, tmp_path / "d1", url)
    assert res["error"] and "asset.json" in res["message"] and "nasset web" in res["message"]
    web.export(portable_asset(tmp_path), site)
    with serving(site) as url:
        res = drive(node, tmp_path / "d2", url, extraArgs=["--disable-webgl", "--disable-3d-apis"])
    assert res["error"] and "WebGL" in res["message"]
    doc = json.loads((site / "asset.json").read_text())
    doc["kind"] = "9dna"
    (site / "asset.json").write_text(json.dumps(doc))
    with serving(site) as url:
        res = drive(node, tmp_path / "d3", url)
    assert res["error"] and "does not know the asset kind" in res["message"] and "9dna" in res["message"]


def kind_radiance(asset, q: dict, irradiance: float) -> np.ndarray:
    """What the page must show at its G-buffer queries, from the kind's evaluator (not the portable graph): rna
    E T (shadowed branch where the light is blocked; fibres h = 0), neupress E S, 8dna the albedo. [n, 3]."""
    n = len(q["x"])
    x = np.asarray(q["x"], np.float64)
    wo = np.asarray(q["eye"], np.float64) - x
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    named = {"x": x.astype(np.float32), "wo": wo.astype(np.float32),
             "wi": np.tile(np.asarray(q["wi"], np.float32), (n, 1)), "frame": np.asarray(q["frame"], np.float32)}
    if asset.kind == "rna":
        if asset.variant == "fiber":
            named["h"] = np.zeros((n, 1), np.float32)
        out = portable.reference_outputs(asset, named)
        return irradiance * np.where(np.asarray(q["lit"])[:, None] > 0, out["unshadowed"], out["shadowed"])
    if asset.kind == "neupress":
        return irradiance * portable.reference_outputs(asset, {k: named[k] for k in ("x", "wo", "wi")})["transport"]
    return portable.reference_outputs(asset, {k: named[k] for k in ("x", "wo")})["albedo"]


@pytest.mark.parametrize("kind,variant", [("neupress", "surface"), pytest.param("8dna", "surface", marks=pytest.mark.slow),
                                          pytest.param("rna", "fiber", marks=pytest.mark.slow)])
def test_page_shades_each_kind_as_its_evaluator(tmp_path, kind, variant):
    """Per pixel, the page's radiance equals the kind's evaluator at the page's own G-buffer (position, frame,
    light visibility; w_o towards the camera computed here): the graph's inputs are wired by name and its outputs combined per kind."""
    from tests.sdk.test_portable import ATOL

    node = tool_or_skip("playwright-core", browser=True)
    src = tmp_path / "a.usdc"
    example_builder(kind, variant=variant, size="small", seed=5).write(src)
    portable.add_portable(src, tmp_path / "p.usdc")
    web.export(tmp_path / "p.usdc", tmp_path / "site")
    size, irradiance = 64, 1.7
    with serving(tmp_path / "site") as url:
        res = drive(node, tmp_path / "drive", f"{url}?size={size}", queries=True,
                    settings={"light": [0.3, 0.9, -0.3], "irradiance": irradiance, "ambient": 0.0, "samples": 1})
    assert res["error"] is None, (res["error"], res["console"][-10:])
    q = res["queries"]
    assert len(q["pixel"]) > 300
    got = np.asarray(res["linear"]["rgb"], np.float64).reshape(-1, 3)[q["pixel"]]
    want = kind_radiance(Asset.open(tmp_path / "p.usdc", load="all"), q, irradiance)
    assert np.abs(want).max() > 0.1
    np.testing.assert_allclose(got, want, rtol=0, atol=ATOL[kind] * max(irradiance, 1.0) + 1e-6)


def test_export_runs_the_runtime_probe_on_the_graphs_it_hands_to_the_browser(tmp_path):
    """A portable graph whose output is NaN on probe inputs (static checks pass) is refused, not exported (before: written)."""
    import hashlib

    import numpy as np
    from onnx import ModelProto, helper, numpy_helper
    from pxr import Sdf, Vt

    from nasset_sdk.errors import NassetError

    path = portable_asset(tmp_path)
    layer = Sdf.Layer.OpenAsAnonymous(str(path))
    spec = layer.GetPrimAtPath("/_NassetPayloads/portable/decoder")
    model = ModelProto()
    model.ParseFromString(bytes(np.asarray(spec.attributes["onnx:model"].default, np.uint8)))
    out = model.graph.output[0].name
    for node in model.graph.node:
        node.output[:] = [f"{o}_raw" if o == out else o for o in node.output]
    model.graph.initializer.extend([numpy_helper.from_array(np.float32(0), "nan_zero"), numpy_helper.from_array(np.float32(1), "nan_one")])
    model.graph.node.extend([helper.make_node("Mul", [f"{out}_raw", "nan_zero"], ["nan_t0"]),
                             helper.make_node("Sub", ["nan_t0", "nan_one"], ["nan_t1"]), helper.make_node("Log", ["nan_t1"], [out])])
    blob = model.SerializeToString()
    spec.attributes["onnx:model"].default = Vt.UCharArray.FromNumpy(np.frombuffer(blob, np.uint8))
    spec.attributes["onnx:sha256"].default = hashlib.sha256(blob).hexdigest()
    assert layer.Export(str(tmp_path / "nan.usdc"))
    site = tmp_path / "site"
    with pytest.raises(NassetError) as exc:
        web.export(tmp_path / "nan.usdc", site)
    assert exc.value.code == "NETWORK_OUTPUT" and exc.value.prim.endswith("/portable/decoder")
    assert not (site / "decoder.onnx").exists()
