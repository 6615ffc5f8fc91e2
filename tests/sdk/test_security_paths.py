"""Hostile paths, hidden layer content, memory amplification and shapes (spec/security.md#paths, #layer-content, #bounds).

Path cases (tests/corpus/gen_paths.py) point outside the package at named pipes: a reader that opens
one blocks, so every reader runs in a child with a time limit and a regression fails instead of
hanging. Each case must be refused by the validator, ``Asset.open``, ``inspect_asset`` and the
scene loader before anything composes.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nasset_sdk.errors import NassetError
from nasset_sdk.validate import validate_file
from tests.corpus import gen_layers, gen_paths

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]  # the checkout: children import tests.* from there

CHILD_TIMEOUT_S = 480


def _reader_results(case_dirs: list[str], probe_names: set[str]) -> dict:
    """In this (child) process: what each reader does with each case, as JSON-ready dicts."""
    from nasset_reference_renderer.scene import load_scene, open_stage
    from nasset_sdk.asset import Asset
    from nasset_sdk.inspect import inspect_asset

    out = {}
    for d in case_dirs:
        asset = Path(d) / "asset.usdc"
        scene = Path(d) / "scene.usda"
        scene.write_text('#usda 1.0\ndef Xform "World" {\n  def "Obj" (prepend references = @./asset.usdc@) {}\n}\n')
        row = {}
        name = Path(d).name
        row["validate"] = sorted(validate_file(asset, probe=name in probe_names, probe_timeout=30).codes("error"))
        for label, fn in (("open", lambda a=asset: Asset.open(a, load="all")), ("inspect", lambda a=asset: inspect_asset(a)),
                          ("scene", lambda sc=scene: open_stage(str(sc))), ("render_asset", lambda a=asset: load_scene(str(a)))):
            try:
                fn()
                row[label] = None
            except NassetError as exc:
                row[label] = exc.code
            except Exception as exc:  # noqa: BLE001 - an untyped failure is a finding of the test
                row[label] = f"untyped {type(exc).__name__}: {exc}"
        out[name] = row
        print("@@row@@" + json.dumps({name: row}), flush=True)
    return out


def _run_child(fn: str, payload) -> tuple[dict, str]:
    """Run ``fn(payload)`` of this module in a child with a wall clock limit; rows it printed, and why it stopped."""
    code = ("import sys, json; import tests.sdk.test_security_paths as t; "
            f"t.{fn}(*json.loads(sys.argv[1]))")
    proc = subprocess.Popen([sys.executable, "-c", code, json.dumps(payload)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, cwd=str(ROOT))
    try:
        out, err = proc.communicate(timeout=CHILD_TIMEOUT_S)
        why = "" if proc.returncode == 0 else f"exit {proc.returncode}: {err.strip()[-500:]}"
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        why = f"timed out after {CHILD_TIMEOUT_S} s (a reader opened a named pipe?)"
    rows = {}
    for line in out.splitlines():
        if line.startswith("@@row@@"):
            rows.update(json.loads(line[len("@@row@@"):]))
    return rows, why


@pytest.fixture(scope="module")
def path_cases(tmp_path_factory):
    return {c.name: c for c in gen_paths.make_cases(tmp_path_factory.mktemp("paths"))}


@pytest.fixture(scope="module")
def path_results(path_cases):
    dirs = [str(c.path.parent) for c in path_cases.values()]
    probe = {n for n in path_cases if n.endswith(("symlink_file", "pipe_inside", "bracket_unbalanced"))}
    return _run_child("_reader_results", [dirs, sorted(probe)])


PATH_NAMES = [f"path_{arc}_{form}" for arc in gen_paths.ARCS + gen_paths.VALUES
              for form in (gen_paths.FORMS if arc in gen_paths.FULL_ARCS else gen_paths.SHORT_FORMS)]
#: readers compose arcs; asset-valued attributes are data they never open, so they need not refuse them
COMPOSING = {a for a in gen_paths.ARCS}


@pytest.mark.parametrize("name", PATH_NAMES)
def test_path_case_refused_before_composing(path_cases, path_results, name):
    rows, why = path_results
    assert name in rows, f"no result for {name}: {why}"
    row = rows[name]
    assert "ASSET_PATH_ESCAPES" in row["validate"], row
    assert "CHECK_FAILED" not in row["validate"], row
    arc = name[len("path_"):].rsplit("_", 1)[0]
    for label in ("open", "inspect", "render_asset"):
        assert row[label] == "ASSET_PATH_ESCAPES", (label, row)
    assert row["scene"] == "SCENE_INVALID", row
    del arc


def test_path_cases_count():
    assert len(PATH_NAMES) >= 80 and len(set(PATH_NAMES)) == len(PATH_NAMES)


# -- layer content, amplification, shapes ---------------------------------------------------------------
@pytest.fixture(scope="module")
def layer_cases(tmp_path_factory):
    return {c.name: c for c in gen_layers.make_cases(tmp_path_factory.mktemp("layers"))}


def _layer_names():
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return [c.name for c in gen_layers.make_cases(d, amplification=False)] + [
            f"amp_face_indices_{n // 3 >> 20}M_faces" for n in gen_layers.AMP_SIZES] + ["amp_custom_data", "amp_face_counts_over_bound",
                                                                         "amp_string_array_repeats_one_string"]


@pytest.mark.parametrize("name", _layer_names())
def test_layer_case_yields_its_code(layer_cases, name):
    case = layer_cases[name]
    # amplification cases are bounded by the probe child: never read them in this process
    report = validate_file(case.path, probe=case.probe or name.startswith("amp_"))
    assert case.code in report.codes("error"), report.format_text()
    assert "CHECK_FAILED" not in report.codes(), report.format_text()


@pytest.mark.parametrize("name", ["shape_wraps_to_zero", "shape_wraps_to_values", "shape_wraps_negative", "shape_zero_dim"])
def test_asset_tensor_refuses_bad_shapes(layer_cases, name):
    from nasset_sdk.asset import Asset

    asset = Asset.open(layer_cases[name].path, load="all")
    with pytest.raises(NassetError) as info:
        asset.tensor("core", "triplane")
    assert info.value.code == layer_cases[name].code


def test_asset_open_refuses_non_ascii_version(layer_cases):
    from nasset_sdk.asset import Asset

    with pytest.raises(NassetError) as info:
        Asset.open(layer_cases["version_arabic_indic"].path)
    assert info.value.code == "SPEC_VERSION"


# -- legitimate arcs stay allowed for readers ---------------------------------------------------------------
def test_readers_follow_checked_in_package_layers(tmp_path):
    from nasset_reference_renderer.scene import open_stage
    from nasset_sdk.asset import Asset
    from nasset_sdk.examples import example_builder
    from nasset_sdk.paths import check_layer_tree

    asset = example_builder("rna", size="tiny", quality_variants=True).write(tmp_path / "a.usdc")
    (tmp_path / "side.usda").write_text('#usda 1.0\nover "Asset"\n{\n    custom string note = "side"\n}\n')
    scene = tmp_path / "s.usda"
    scene.write_text('#usda 1.0\n(\n subLayers = [@./side.usda@]\n)\ndef "World" {\n def "A" (prepend references = @./a.usdc@) {}\n'
                     f' def "B" (prepend references = @{asset}@) {{}}\n}}\n')
    assert check_layer_tree(scene, scene=True) == []
    stage = open_stage(str(scene))
    assert stage.GetPrimAtPath("/World/A").GetTypeName() == "NeuralAsset"
    assert Asset.open(asset, load="all").components()["core"].qualities
    assert validate_file(asset).ok


# -- bounded fuzz of composition arcs -----------------------------------------------------------------------
PIECES = ("..", ".", "", "a", "evil.usda", "x[", "]", "p.usdz[", "~", "/", "\\", "C:", "https:", "file:", "`", "link",
          "linkdir", "pipe", "dir", "sub.usda", "%2e%2e", "\u2024\u2024", "..\\..", "//")


def _author_arc(layer, where: str, s: str) -> None:
    from pxr import Sdf

    if where == "sublayer":
        layer.subLayerPaths.append(s)
        return
    spec = layer.GetPrimAtPath("/Asset/Extra") or Sdf.CreatePrimInLayer(layer, "/Asset/Extra")
    spec.specifier = Sdf.SpecifierDef
    if where == "variant":
        vset = spec.variantSets.get("v") or Sdf.VariantSetSpec(spec, "v")
        spec = Sdf.PrimSpec(Sdf.VariantSpec(vset, f"x{len(vset.variants)}").primSpec, "In", Sdf.SpecifierDef)
        layer.GetPrimAtPath("/Asset/Extra").variantSelections["v"] = "x0"
    if where == "payload":
        spec.payloadList.prependedItems.append(Sdf.Payload(s))
    else:
        spec.referenceList.prependedItems.append(Sdf.Reference(s))


def _fuzz(seed: int, n: int, out: str) -> None:
    """In this (child) process: ``n`` random arcs; each must be refused by both checks or stay inside the package."""
    from pxr import Sdf, Tf

    from nasset_sdk.asset import Asset
    from nasset_sdk.examples import example_builder
    from nasset_sdk.paths import is_under
    from nasset_sdk.validate.rules import Validation

    rng = random.Random(seed)
    root = Path(out)
    outside = root / "outside"
    outside.mkdir(parents=True, exist_ok=True)
    (outside / "evil.usda").write_text('#usda 1.0\ndef "Evil" {}\n')
    base = example_builder("rna", size="tiny").write(root / "base.usdc")
    stats = {"refused": 0, "inside": 0}
    t0 = time.perf_counter()
    for i in range(n):
        pkg = root / f"p{i}"
        pkg.mkdir()
        (pkg / "sub.usda").write_text('#usda 1.0\nover "Asset" {}\n')
        (pkg / "dir").mkdir()
        os.mkfifo(pkg / "pipe")
        (pkg / "link").symlink_to(outside / "evil.usda")
        (pkg / "linkdir").symlink_to(outside, target_is_directory=True)
        layer = Sdf.Layer.OpenAsAnonymous(str(base))
        paths = []
        for _ in range(rng.randint(1, 3)):
            k = rng.randint(1, 4)
            s = rng.choice(["", "./", "./", "../"]) + "/".join(rng.choice(PIECES) for _ in range(k))
            if rng.random() < 0.3:
                s += rng.choice(["]", "[x.usda]", "[../../evil.usda]", ".usda"])
            where = rng.choice(["sublayer", "reference", "payload", "variant"])
            try:
                _author_arc(layer, where, s)
            except Tf.ErrorException:  # USD itself refuses to author it (e.g. an empty sublayer path)
                continue
            paths.append(s)
        target = pkg / "asset.usdc"
        layer.Export(str(target))
        v = Validation(str(target), probe=False)
        v._open()
        v._asset_paths()
        v_codes = {f.code for f in v.report.findings}
        try:  # the path checks alone (probe=False): probing each layer costs a child each (tests/sdk/test_security_readers.py)
            asset = Asset.open(target, load="all", probe=False)
        except NassetError as exc:
            assert exc.code == "ASSET_PATH_ESCAPES", (paths, exc)
            assert "ASSET_PATH_ESCAPES" in v_codes, (paths, v_codes)
            stats["refused"] += 1
            continue
        used = [lyr.realPath for lyr in asset.stage.GetUsedLayers() if lyr.realPath]
        assert all(is_under(u, pkg) for u in used), (paths, used)
        assert "ASSET_PATH_ESCAPES" not in v_codes, (paths, v.report.format_text())
        assert "LAYER_EXTERNAL" in v_codes or not any(paths), (paths, v_codes)
        stats["inside"] += 1
    stats["seconds"] = round(time.perf_counter() - t0, 1)
    print("@@row@@" + json.dumps({"fuzz": stats}), flush=True)


def test_fuzz_composition_arcs(tmp_path):
    rows, why = _run_child("_fuzz", [1234, 300, str(tmp_path)])
    assert "fuzz" in rows, why
    stats = rows["fuzz"]
    assert stats["refused"] + stats["inside"] == 300 and stats["refused"] > 100, stats
    assert stats["seconds"] < 30, stats


# -- killing validate takes its probe child down --------------------------------------------------------------
def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_killing_validate_kills_its_probe_child(tmp_path, how):
    fifo = tmp_path / "hang.usdc"
    os.mkfifo(fifo)  # the probe child blocks opening it for ever
    # SIGINT as a shell gives it to `nasset validate`: a SIG_IGN disposition that a library set in this test
    # process (inherited through exec) would make the SIGINT case hang for a reason outside the product
    code = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
            f"from nasset_sdk.safeopen import probe; probe({str(fifo)!r}, timeout=600)")
    parent = subprocess.Popen([sys.executable, "-c", code], cwd=str(ROOT), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 60
        kids: list[int] = []
        while time.time() < deadline and not kids:
            time.sleep(0.2)
            kids = _children(parent.pid)
        assert kids, "the probe child did not start"
        time.sleep(1.0)  # let the child reach its blocking open
        parent.send_signal(how)
        parent.wait(timeout=30)
        deadline = time.time() + 10
        while time.time() < deadline and any(_alive(k) for k in kids):
            time.sleep(0.1)
        assert not any(_alive(k) for k in kids), f"probe child still running after {how.name} of validate"
    finally:
        for k in _children(parent.pid):
            os.kill(k, signal.SIGKILL)
        parent.kill()



def test_security_generators_cover_their_codes(layer_cases):
    from tests.sdk.test_validator import SECURITY_CORPUS_CODES

    assert SECURITY_CORPUS_CODES <= {c.code for c in layer_cases.values()}


# -- arcs inside a usdz package are anchored inside it ----------------------------------------------------------
def _usdz_with_inner_sublayer(tmp_path) -> tuple[Path, Path]:
    """``pkg/a.usdz``: its root layer sublayers ``./inner.usda`` (inside the package), which sublayers a file outside."""
    import zipfile

    from pxr import Sdf

    from nasset_sdk.examples import example_builder

    outside = tmp_path / "outside"
    outside.mkdir()
    evil = outside / "evil.usda"
    evil.write_text('#usda 1.0\nover "Asset"\n{\n    custom string secret = "outside"\n}\n')
    base = example_builder("rna", size="tiny").write(tmp_path / "base.usdc")
    root = Sdf.Layer.OpenAsAnonymous(str(base))
    root.subLayerPaths.append("./inner.usda")
    assert root.Export(str(tmp_path / "root.usdc"))
    inner = Sdf.Layer.CreateAnonymous(".usda")
    inner.subLayerPaths.append(str(evil))
    (tmp_path / "inner.usda").write_text(inner.ExportToString())
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    with zipfile.ZipFile(pkg / "a.usdz", "w", zipfile.ZIP_STORED) as z:  # the first file is the package's root layer
        z.write(tmp_path / "root.usdc", "root.usdc")
        z.write(tmp_path / "inner.usda", "inner.usda")
    return pkg / "a.usdz", evil


def test_arcs_of_layers_inside_a_usdz_are_checked_where_composition_anchors_them(tmp_path):
    """Before: './inner.usda' in a.usdz was checked as the file beside the package (absent: skipped), so the inner
    layer's absolute sublayer was never checked and Asset.open composed the outside file."""
    from pxr import Sdf

    from nasset_reference_renderer.scene import open_stage
    from nasset_sdk.asset import Asset

    usdz, evil = _usdz_with_inner_sublayer(tmp_path)
    with pytest.raises(NassetError) as exc:
        Asset.open(usdz)
    assert exc.value.code == "ASSET_PATH_ESCAPES"
    assert "a.usdz[inner.usda]" in exc.value.message and "is absolute" in exc.value.message
    scene = tmp_path / "scene.usda"
    scene.write_text('#usda 1.0\ndef Xform "World"\n{\n    def Xform "A" (\n        prepend references = @./pkg/a.usdz@\n    )\n'
                     '    {\n    }\n}\n')
    with pytest.raises(NassetError) as exc:
        open_stage(str(scene))
    assert exc.value.code == "SCENE_INVALID" and "a.usdz[inner.usda]" in exc.value.message
    assert Sdf.Layer.Find(str(evil)) is None  # never opened
    assert "LAYER_EXTERNAL" in validate_file(usdz).codes("error")


def test_value_clip_templates_are_refused_before_anything_reads_through_them(tmp_path):
    """``templateAssetPath`` is a plain string (not an asset path): the walker did not see it, the asset validated clean,
    and reading the attribute through Asset.open composed the generated outside layer ('FROM-OUTSIDE-CLIP')."""
    from pxr import Sdf

    from nasset_sdk.asset import Asset
    from nasset_sdk.examples import example_builder

    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "clip.0.usda").write_text('#usda 1.0\ndef "Evil"\n{\n    custom string secret.timeSamples = {\n'
                                         '        0: "FROM-OUTSIDE-CLIP",\n    }\n}\n')
    base = example_builder("rna", size="tiny").write(tmp_path / "base.usdc")
    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    spec = layer.GetPrimAtPath("/Asset/Looks/Fallback")
    Sdf.AttributeSpec(spec, "secret", Sdf.ValueTypeNames.String)
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    for name, template in (("absolute", str(outside / "clip.#.usda")), ("inside", "./clip.#.usda")):
        spec.SetInfo("clips", {"default": {"templateAssetPath": template, "primPath": "/Evil", "templateStartTime": 0.0,
                                           "templateEndTime": 0.0, "templateStride": 1.0}})
        path = pkg / f"{name}.usdc"
        assert layer.Export(str(path))
        codes = validate_file(path).codes("error")
        assert {"ASSET_PATH_ESCAPES", "LAYER_EXTERNAL"} <= codes, (name, codes)
        with pytest.raises(NassetError) as exc:
            Asset.open(path)
        assert exc.value.code == "ASSET_PATH_ESCAPES" and "value clip template" in exc.value.message
    assert Sdf.Layer.Find(str(outside / "clip.0.usda")) is None  # never opened


def test_asset_path_scan_of_a_deep_layer_spells_prim_paths_only_where_found(monkeypatch):
    """A layer's asset paths are listed in time linear in its specs: a prim's path (as long as its depth) is spelled
    only for a spec that holds an asset path, not for each of the specs of a chain nested thousands deep (counted)."""
    from pxr import Sdf

    from nasset_sdk.paths import layer_asset_paths

    spelled = [0]
    prim_path = Sdf.Path.GetPrimPath

    def counted(path):
        spelled[0] += path.pathElementCount
        return prim_path(path)

    monkeypatch.setattr(Sdf.Path, "GetPrimPath", counted)

    def scan(depth):
        layer = Sdf.Layer.CreateAnonymous(".usda")
        where = Sdf.Path("/Chain")
        for _ in range(depth):
            spec = Sdf.CreatePrimInLayer(layer, where)
            spec.specifier = Sdf.SpecifierDef
            Sdf.AttributeSpec(spec, "size", Sdf.ValueTypeNames.Double).default = 1.0
            where = where.AppendChild("X")
        spec.referenceList.Prepend(Sdf.Reference("./bottom.usda"))  # the one asset path, at the bottom
        spelled[0] = 0
        found = layer_asset_paths(layer)
        assert [(s, prim) for _, s, prim, _ in found] == [("./bottom.usda", str(spec.path))]
        return spelled[0]

    small, large = scan(200), scan(400)
    assert large <= 2.2 * small, (small, large)  # every spec's path spelled: 4x
