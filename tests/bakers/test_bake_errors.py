"""Bad input to ``nasset bake``: typed errors, backend fallback, interruption and resume."""

from __future__ import annotations

import types
import warnings

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="bake tests need mitsuba (pip install 'nasset-sdk[mitsuba]')")
pytest.importorskip("torch", reason="bake tests need torch (pip install torch==2.13.0)")

import nasset_converters.mitsuba as cm  # noqa: E402
from nasset_bakers.mitsuba.rna import DATA_PRESETS, bake  # noqa: E402
from nasset_converters.mitsuba import dataset as ds  # noqa: E402
from nasset_converters.mitsuba.examples import write_example_scene  # noqa: E402
from nasset_sdk.cli import main  # noqa: E402
from nasset_sdk.errors import NassetError, SceneError, UsageError  # noqa: E402


def _code(excinfo) -> str:
    return excinfo.value.code


@pytest.fixture(scope="module")
def example_xml(tmp_path_factory):
    return write_example_scene(tmp_path_factory.mktemp("scene"))


def test_missing_scene_file(tmp_path):
    with pytest.raises(SceneError) as e:
        bake(tmp_path / "nope.xml", ["a"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SCENE_MISSING"
    assert not (tmp_path / "o.usdc").exists()


def test_unknown_shape_id(example_xml, tmp_path):
    with pytest.raises(SceneError) as e:
        bake(example_xml, ["shell", "teapot"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SHAPE_UNKNOWN"
    assert "teapot" in str(e.value) and "jelly" in str(e.value)  # names the known ids


def test_an_emitter_id_is_named_as_one(tmp_path):
    """``--asset sun`` where ``sun`` is the scene's directional light: said to be an emitter (it read as a typo)."""
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><emitter type="directional" id="sun"/>'
                                    '<shape type="cube" id="box"/></scene>')
    with pytest.raises(SceneError) as e:
        bake(tmp_path / "s.xml", ["sun"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SHAPE_UNKNOWN" and "is an emitter" in str(e.value) and "box" in str(e.value)


def test_non_mesh_shape_is_unsupported(tmp_path):
    """An instance of a shape group is neither a mesh nor an analytic shape (those bake: test_analytic_shapes.py)."""
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="shapegroup" id="g"><shape type="sphere"/></shape>'
                   '<shape type="instance" id="ball"><ref id="g"/></shape></scene>')
    with pytest.raises(SceneError) as e:
        bake(xml, ["ball"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SHAPE_UNSUPPORTED" and "sphere" in str(e.value)  # names the shapes that do bake
    assert not (tmp_path / "o.usdc").exists()


def _ply_scene(tmp_path, points, faces):
    import numpy as np

    from nasset_converters.mitsuba.examples import write_ply

    write_ply(tmp_path / "m.ply", np.asarray(points, np.float32), np.asarray(faces, np.int64))
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="ply" id="m"><string name="filename" value="m.ply"/></shape></scene>')
    return xml


def test_shape_without_area_is_unsupported(tmp_path):
    xml = _ply_scene(tmp_path, [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], [[0, 1, 2]])  # collinear triangle
    with pytest.raises(SceneError) as e:
        bake(xml, ["m"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SHAPE_UNSUPPORTED" and "no surface area" in str(e.value)
    assert not (tmp_path / "o.usdc").exists()


def test_closed_surface_check():
    import numpy as np

    from nasset_converters.mitsuba.scene import is_closed

    tetra = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
    assert is_closed(tetra) and not is_closed(tetra[:3])
    # the same tetrahedron with its vertices split per face (hard edges, UV seams): closed once welded by position
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    split = np.arange(12).reshape(4, 3)
    points = corners[tetra.reshape(-1)]
    assert not is_closed(split) and is_closed(split, points) and not is_closed(split[:3], points)


def test_open_shape_warning_from_geometry(tmp_path):
    from nasset_converters.mitsuba.scene import load_scene, mesh_geometry, pick_shapes

    mi = cm.load_mitsuba()
    xml = _ply_scene(tmp_path, [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    shapes = pick_shapes(load_scene(mi, xml), ["m"])
    with pytest.warns(RuntimeWarning, match="closed surface"):
        mesh_geometry(mi, shapes)


def test_a_cube_with_split_vertices_is_closed(tmp_path):
    """Mitsuba's ``cube`` has 24 vertices (four per face, for its hard edges): it used to be called open."""
    import warnings

    from nasset_converters.mitsuba.scene import load_scene, mesh_geometry, pick_shapes

    mi = cm.load_mitsuba()
    (tmp_path / "c.xml").write_text('<scene version="3.0.0"><shape type="cube" id="c"/></scene>')
    shapes = pick_shapes(load_scene(mi, tmp_path / "c.xml"), ["c"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        geo = mesh_geometry(mi, shapes)
    assert len(geo.points) == 24


def test_a_flat_shape_beside_a_smooth_one_keeps_both_shadings(tmp_path):
    """A shape without vertex normals (``face_normals``) in one asset with a smooth one: the smooth one used to lose
    its normals too (the merged asset had none: faceted everywhere)."""
    from nasset_converters.mitsuba.scene import load_scene, mesh_geometry, pick_shapes

    mi = cm.load_mitsuba()
    (tmp_path / "c.xml").write_text(
        '<scene version="3.0.0"><shape type="sphere" id="s"/><shape type="obj" id="t">'
        '<string name="filename" value="t.obj"/><boolean name="face_normals" value="true"/></shape></scene>')
    (tmp_path / "t.obj").write_text("v 3 0 0\nv 4 0 0\nv 3 1 0\nv 3 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n")
    shapes = pick_shapes(load_scene(mi, tmp_path / "c.xml"), ["s", "t"])
    geo = mesh_geometry(mi, shapes)
    sphere = np.linalg.norm(geo.points, axis=1) < 1.5
    np.testing.assert_allclose(np.sum(geo.normals[sphere] * geo.points[sphere], axis=1), 1.0, atol=1e-3)  # radial
    tri = geo.points[geo.faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    flat = ~sphere[geo.faces[:, 0]]
    assert flat.sum() == 4
    for corner in range(3):
        np.testing.assert_allclose(geo.normals[geo.faces[flat, corner]], face_n[flat], atol=1e-5)


def test_dataset_write_failure_is_typed(tmp_path, monkeypatch):
    import numpy as np

    obj = ds.DatasetDir.__new__(ds.DatasetDir)
    obj.root = tmp_path
    (tmp_path / "train").mkdir()

    def full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full)
    with pytest.raises(SceneError) as e:
        obj.save("train", 0, {"x": np.zeros(3)})
    assert _code(e) == "CONVERT_DATASET" and "No space left" in str(e.value)
    assert list((tmp_path / "train").iterdir()) == []


def test_scene_mitsuba_cannot_load(tmp_path):
    xml = tmp_path / "broken.xml"
    xml.write_text('<scene version="3.0.0"><shape type="no_such_plugin" id="x"/></scene>')
    with pytest.raises(SceneError) as e:
        bake(xml, ["x"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SCENE_LOAD"
    xml.write_text("<scene version=")  # not even XML
    with pytest.raises(SceneError) as e:
        bake(xml, ["x"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert _code(e) == "CONVERT_SCENE_LOAD"


def test_usage_errors(tmp_path):
    with pytest.raises(UsageError):
        bake(None, None, tmp_path / "o.usdc", size="huge", example=True, quiet=True)
    with pytest.raises(UsageError):
        bake(None, None, tmp_path / "o.png", size="tiny", example=True, quiet=True)
    with pytest.raises(UsageError):
        bake(None, None, tmp_path / "o.usdc", size="tiny", example=True, quiet=True, views=0)
    # too large: --res 100000 used to end in a numpy MemoryError (74.5 GiB for one view's image)
    for option, value in (("res", 100_000), ("views", 10**6), ("spp", 1 << 30), ("epochs", 10**9)):
        with pytest.raises(UsageError, match=f"--{option} must be <="):
            bake(None, None, tmp_path / "o.usdc", size="tiny", example=True, quiet=True, **{option: value})
    assert not (tmp_path / "o.usdc.bake").exists()


@pytest.mark.parametrize("kind", ["rna", "neupress", "8dna"])
def test_python_api_arguments_of_the_wrong_type_fail_before_any_work(tmp_path, kind):
    """The bake functions (the CLI's checks are argparse's) refuse a seed outside 0 .. 2^32 - 1, a count that is not an
    integer, and a scene or output that is not a path as USAGE before any work. A None output or an int scene used to
    fail as a bare TypeError; a string count trained on."""
    import importlib

    run = importlib.import_module(f"nasset_bakers.mitsuba.{'eightdna' if kind == '8dna' else kind}").bake
    cases = [dict(seed=-1), dict(seed=1 << 40), dict(seed=1.5), dict(epochs="3"), dict(epochs=2.0), dict(epochs=True)]
    for extra in cases:
        with pytest.raises(UsageError, match="seed|epochs"):
            run(None, None, tmp_path / "o.usdc", size="tiny", example=True, quiet=True, **extra)
    with pytest.raises(UsageError, match="the output must be a file path"):
        run(None, None, None, size="tiny", example=True, quiet=True)
    with pytest.raises(UsageError, match="the scene must be a file path"):
        run(5, ["a"], tmp_path / "o.usdc", size="tiny", quiet=True)
    assert not (tmp_path / "o.usdc.bake").exists()


def test_cli_exit_codes(tmp_path, capsys):
    rc = main(["bake", str(tmp_path / "missing.xml"), "--asset", "a", "-o", str(tmp_path / "o.usdc"), "--quiet"])
    assert rc == 1
    assert "CONVERT_SCENE_MISSING" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [["--near-field-fetch", "2"], ["--near-field-fetch", "nan"], ["--near-field-fetch", "far"],
                                   ["--near-field-fetch", "0.3", "--kind", "8dna"],
                                   ["--near-field-fetch", "0.3", "--example", "blender-surface"]])
def test_near_field_fetch_option_is_checked_before_any_work(tmp_path, capsys, extra):
    """--near-field-fetch: auto or a number in [0, 1], rna and neupress bakes from Mitsuba only; a usage error (exit 2)
    otherwise."""
    args = ["bake", "-o", str(tmp_path / "o.usdc"), "--quiet", "--size", "tiny", *extra]
    rc = main(args if "--example" in extra else args + ["--example"])
    assert rc == 2, capsys.readouterr().err
    assert "--near-field-fetch" in capsys.readouterr().err
    assert not (tmp_path / "o.usdc.bake").exists()


@pytest.mark.parametrize("extra", [["--suns-per-view", "4", "--example"], ["--suns-per-view", "4", "--kind", "neupress", "--example"],
                                   ["--suns-per-view", "0", "--example", "blender-surface"]])
def test_suns_per_view_option_is_checked_before_any_work(tmp_path, capsys, extra):
    """--suns-per-view: an integer >= 1, bakes from Blender scenes only; a usage error (exit 2) otherwise."""
    if "blender-surface" in extra:
        pytest.importorskip("bpy")
    rc = main(["bake", "-o", str(tmp_path / "o.usdc"), "--quiet", "--size", "tiny", *extra])
    assert rc == 2, capsys.readouterr().err
    assert "--suns-per-view" in capsys.readouterr().err
    assert not (tmp_path / "o.usdc.bake").exists()


def test_suns_per_view_given_reaches_the_blender_dataset(tmp_path):
    """``nasset bake --example blender-surface --suns-per-view 3``: three suns per training view, recorded."""
    pytest.importorskip("bpy")
    from nasset_sdk.asset import Asset

    assert main(["bake", "--example", "blender-surface", "-o", str(tmp_path / "o.usdc"), "--quiet", "--size", "tiny",
                 "--res", "16", "--spp", "3", "--epochs", "1", "--suns-per-view", "3"]) == 0
    data = Asset.open(tmp_path / "o.usdc", load="none").provenance["data"]
    assert data["lights_per_view"] == 3 and data["noise"]["spp"] == 1.0


def test_near_field_fetch_given_is_stored_without_measuring(tmp_path):
    from nasset_sdk.asset import Asset

    assert main(["bake", "--example", "-o", str(tmp_path / "o.usdc"), "--quiet", "--size", "tiny",
                 "--near-field-fetch", "0.25"]) == 0
    a = Asset.open(tmp_path / "o.usdc", load="none")
    assert a.near_field_fetch == 0.25 and a.provenance["near_field"]["measured"] is False and a.spec_version == "0.3"


def test_llvm_missing_falls_back_to_scalar_with_warning(monkeypatch):
    """load_mitsuba: when llvm_ad_rgb cannot be set, scalar_rgb is used and a RuntimeWarning says so."""
    state = {"variant": None}

    def set_variant(v):
        if v == "llvm_ad_rgb":
            raise ImportError("libLLVM not found")
        state["variant"] = v

    fake = types.SimpleNamespace(variant=lambda: state["variant"], set_variant=set_variant)
    monkeypatch.setitem(__import__("sys").modules, "mitsuba", fake)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mi = cm.load_mitsuba()
    assert mi.variant() == "scalar_rgb"
    assert any("falling back" in str(w.message) for w in caught)


def test_no_variant_at_all_is_typed(monkeypatch):
    def set_variant(v):
        raise ImportError("nothing works")

    fake = types.SimpleNamespace(variant=lambda: None, set_variant=set_variant)
    monkeypatch.setitem(__import__("sys").modules, "mitsuba", fake)
    with pytest.raises(NassetError) as e:
        cm.load_mitsuba()
    assert _code(e) == "CONVERT_BACKEND"


def test_interrupt_keeps_dataset_and_resume_finishes(tmp_path, monkeypatch):
    """Ctrl-C while rendering: no asset file, the views so far stay; --resume renders only the rest."""
    real = ds.render_view
    calls = {"n": 0}

    def flaky(*a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(*a, **k)

    out = tmp_path / "a.usdc"
    work = tmp_path / "data"
    monkeypatch.setattr(ds, "render_view", flaky)
    with pytest.raises(KeyboardInterrupt):
        bake(None, None, out, size="tiny", example=True, quiet=True, resume=work, epochs=2)
    assert not out.exists()
    assert len(list((work / "train").glob("*.npz"))) == 2
    assert not list(work.rglob("*.part.npz"))
    calls["n"] = -100  # no more interrupts; count renders of the resumed run
    summary = bake(None, None, out, size="tiny", example=True, quiet=True, resume=work, epochs=2)
    assert out.exists()
    tiny = DATA_PRESETS["tiny"]
    assert calls["n"] == -100 + tiny["views"] + tiny["val_views"] - 2  # 2 views were kept
    assert summary["views"] == tiny["views"]


def test_resume_with_other_settings_is_refused(tmp_path):
    work = tmp_path / "data"
    bake(None, None, tmp_path / "a.usdc", size="tiny", example=True, quiet=True, resume=work, epochs=1)
    with pytest.raises(SceneError) as e:
        bake(None, None, tmp_path / "b.usdc", size="tiny", example=True, quiet=True, resume=work, res=16, epochs=1)
    assert _code(e) == "CONVERT_DATASET"


@pytest.mark.parametrize("kind", ["rna", "8dna"])
def test_output_folder_that_cannot_be_made_fails_before_any_work(tmp_path, kind):
    """``-o`` under a file (or a read-only folder): WRITE_FAILED naming it at the start. Before, the default
    dataset folder's mkdir raised a raw NotADirectoryError, and with ``--resume`` elsewhere the whole bake ran
    and failed only when the asset was written."""
    import nasset_bakers  # noqa: F401  (registers the bakers)
    from nasset_bakers.registry import baker_for

    (tmp_path / "afile").write_text("")
    for resume in (None, tmp_path / "data"):
        with pytest.raises(NassetError) as e:
            baker_for(kind, None, None)(None, None, tmp_path / "afile" / "a.usdc", size="tiny", example="default", quiet=True,
                                resume=resume)
        assert _code(e) == "WRITE_FAILED" and "afile" in str(e.value)
        assert not (tmp_path / "data").exists()  # nothing was started


def test_dataset_folder_that_cannot_be_made_is_typed(tmp_path):
    (tmp_path / "afile").write_text("")
    with pytest.raises(NassetError) as e:
        bake(None, None, tmp_path / "a.usdc", size="tiny", example=True, quiet=True, resume=tmp_path / "afile" / "d")
    assert _code(e) == "WRITE_FAILED" and "afile" in str(e.value)


@pytest.mark.parametrize("flip", [False, True])
def test_a_flip_normals_shape_keeps_the_side_mitsuba_shades(tmp_path, flip):
    """``flip_normals`` (or a mirroring ``to_world`` on an analytic shape): Mitsuba shades the inside, so the training
    data's ``n`` points inwards; the asset's normals and winding must too (and an analytic shape's tessellation, which
    the data is rendered from, lost the flip). They pointed outwards (the file's), so every render queried the network with normals it
    never saw: a twosided diffuse cube read 81 / 175 / 162 %, 13.1 dB in its scene (``tiny``) against
    102 / 134 / 102 %, 16.5 dB now (the same cube unflipped: 92 / 129 / 124 %, 17.8 dB)."""
    from nasset_converters.mitsuba.scene import asset_geometry, load_scene, pick_shapes

    mi = cm.load_mitsuba()
    f = f'<boolean name="flip_normals" value="{str(flip).lower()}"/>'
    (tmp_path / "t.obj").write_text("v 3 0 0\nv 4 0 0\nv 3 1 0\nv 3 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n")
    (tmp_path / "c.xml").write_text(
        f'<scene version="3.0.0"><shape type="cube" id="c">{f}</shape><shape type="obj" id="t">{f}'
        '<string name="filename" value="t.obj"/><boolean name="face_normals" value="true"/></shape>'
        f'<shape type="sphere" id="s">{f}<transform name="to_world"><translate x="-4"/></transform></shape>'
        f'<shape type="sphere" id="m">{f}<transform name="to_world"><scale x="-1"/><translate x="8"/></transform></shape>'
        '</scene>')
    scene = load_scene(mi, tmp_path / "c.xml")
    shapes = pick_shapes(scene, ["c", "t", "s", "m"])  # analytic spheres: tessellated; "m" mirrored (Mitsuba turns it)
    for shape in shapes:
        sign = (-1.0 if flip else 1.0) * (-1.0 if shape.id() == "m" else 1.0)
        _, geo = asset_geometry(mi, [shape])  # analytic shapes: their tessellation
        tri = geo.points[geo.faces]
        outward = tri.mean(1) - geo.points.mean(0)
        winding = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        assert (sign * np.sum(winding * outward, axis=1) > 0).all()
        if geo.normals is not None:
            assert (sign * np.sum(geo.normals[geo.faces].mean(1) * outward, axis=1) > 0).all()
        origin = [float(v) for v in geo.points.mean(0) + [0, 0, 5]]
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(0, 0, -1)))
        assert sign * float(np.asarray(si.sh_frame.n)[2].ravel()[0]) > 0  # Mitsuba's own shading normal, for reference


def test_a_mirror_is_refused_before_rendering(tmp_path):
    """A smooth conductor reflects a distant light into one direction: every training pixel was black, and the bake
    wrote an asset of black transport without a word (in its scene, 15 / 31 / 21 % of a mirror cube's energy)."""
    from nasset_converters.mitsuba.scene import load_scene, mirror_shapes, pick_shapes

    (tmp_path / "m.xml").write_text(
        '<scene version="3.0.0"><shape type="cube" id="chrome"><bsdf type="conductor"/></shape>'
        '<shape type="sphere" id="ball"><bsdf type="plastic"/></shape>'
        '<shape type="cube" id="twochrome"><bsdf type="twosided"><bsdf type="conductor"/></bsdf>'
        '<transform name="to_world"><translate x="4"/></transform></shape>'
        '<shape type="cube" id="rough"><bsdf type="roughconductor"/><transform name="to_world"><translate x="8"/>'
        '</transform></shape></scene>')
    mi = cm.load_mitsuba()
    shapes = pick_shapes(load_scene(mi, tmp_path / "m.xml"), ["chrome", "ball", "twochrome", "rough"])
    assert mirror_shapes(mi, shapes) == ["chrome", "twochrome"]  # plastic has a diffuse base, roughconductor a lobe
    for ids in (["chrome"], ["chrome", "twochrome"]):
        with pytest.raises(SceneError) as e:
            bake(tmp_path / "m.xml", ids, tmp_path / "o.usdc", size="tiny", quiet=True)
        assert _code(e) == "CONVERT_SHAPE_UNSUPPORTED" and "chrome" in str(e.value) and "SmoothConductor" in str(e.value)
        assert not (tmp_path / "o.usdc.bake" / "train").exists()  # refused before any view


@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_light_visibility_far_from_the_origin_is_the_renderers(tmp_path, offset):
    """V of a convex cube is 1 exactly where the light is above the face. 10^4 units from the origin Mitsuba's
    spawn_ray moves the shadow ray's origin by (1 + |p|) x 8.9e-5 ~ 0.9 units, through the 0.6-unit cube: every V
    was 1, the renderer's (its own offset, 0.2 there) half 0, and the asset read 127 / 127 / 270 %, 8.4 dB in its
    scene (``tiny``) against 91 / 129 / 124 %, 17.8 dB at the origin; now V is cast as the renderer casts it
    (91 / 127 / 121 %, 18.2 dB)."""
    from dataclasses import replace

    from nasset_bakers.mitsuba.rna import _view_renderer
    from nasset_converters.mitsuba.scene import bounding_sphere, load_scene, mesh_geometry, pick_shapes

    mi = cm.load_mitsuba()
    (tmp_path / "c.xml").write_text(
        '<scene version="3.0.0"><shape type="cube" id="c"><transform name="to_world"><scale value="0.3"/>'
        f'<translate x="{offset}" z="{offset}"/></transform></shape></scene>')
    shapes = pick_shapes(load_scene(mi, tmp_path / "c.xml"), ["c"])
    geo = mesh_geometry(mi, shapes)
    center, radius = bounding_sphere(geo)
    dset = replace(ds.DataSettings(), **DATA_PRESETS["tiny"])
    view = _view_renderer(mi, shapes, geo, center, radius, dset)("train", 0)
    above = np.sum(view["n"] * view["wi"], axis=1) > 0
    assert 0.2 < above.mean() < 0.8
    assert np.mean(view["vis"].astype(bool) == above) > 0.99


@pytest.mark.parametrize("place, warns", [('<scale value="0.3"/>', False),
                                          ('<scale value="300"/><translate y="300"/>', False),  # a millimetre scene
                                          ('<scale value="0.3"/><translate x="10000"/>', True)])
def test_shapes_far_from_the_origin_for_their_size_are_warned(tmp_path, place, warns):
    """Mitsuba's own ray offset there (0.9 units at 10^4) crosses the asset: its images of the scene lose the asset's
    self-shadowing and interreflections (the benches' reference; the bakers move the shapes to the origin,
    tests/bakers/test_far_from_origin.py)."""
    from nasset_converters.mitsuba.scene import far_from_origin, load_scene, pick_shapes

    mi = cm.load_mitsuba()
    (tmp_path / "c.xml").write_text(f'<scene version="3.0.0"><shape type="cube" id="c"><transform name="to_world">{place}'
                                    '</transform></shape></scene>')
    msg = far_from_origin(mi, pick_shapes(load_scene(mi, tmp_path / "c.xml"), ["c"]))
    assert bool(msg) == warns and (not warns or "'c'" in msg and "origin" in msg)
