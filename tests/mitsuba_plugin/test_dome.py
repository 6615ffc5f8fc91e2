"""The plugin's ``nasset_dome`` emitter (spec/renderer.md#lights, DomeLight): radiance against the
reference renderer's dome, its sampler against its pdf and the image's integral, and the dome
conformance case."""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import lights as lights_jit  # noqa: E402
from nasset_mitsuba_plugin.scene import load_file  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.lights import DomeLight  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402
from tests.mitsuba_plugin.test_plugin import _run_case, _vec  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    lights_jit.register(mi)
    return mi


def _rotation(rng, mirror: bool) -> np.ndarray:
    """A random orthogonal 3x3 (row-vector convention, local -> world), with det -1 when ``mirror``."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return q @ np.diag([1.0, 1.0, -1.0]) if mirror else q


def _dome(mi, image, scale, rot_rows):
    m = np.eye(4)
    m[:3, :3] = rot_rows.T  # Mitsuba's to_world is column-vector
    ent = {"type": lights_jit.DOME, "radiance": mi.ScalarColor3f(list(scale)), "to_world": mi.ScalarTransform4f(m.tolist())}
    if image is not None:
        ent["bitmap"] = mi.Bitmap(np.ascontiguousarray(image, np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB)
    return mi.load_dict(ent)


def _image(rng, h=16, w=32):
    img = rng.gamma(0.5, 1.0, (h, w, 3))
    img[3, 7] = 200.0  # a sun: importance sampling matters
    return img


@pytest.mark.parametrize("mirror", [False, True])
def test_dome_radiance_matches_reference_renderer(mi, rng, mirror):
    """L(d) of the plugin's dome = the reference renderer's DomeLight (lat-long lookup in the rotated
    frame, nearest texel, times the scale) on random world directions; float32 atan2/acos against
    float64 may pick the neighbouring texel within ~1e-6 of a texel edge: at most 0.1 % of directions."""
    img, scale, rot = _image(rng), np.array([0.5, 1.0, 2.0]), _rotation(rng, mirror)
    ref = DomeLight(scale, img, rotation=rot)
    em = _dome(mi, img, scale, rot)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = -_vec(mi, d)
    got = np.asarray(em.eval(si).numpy()).T
    want = ref.le_escaped(d)
    same = np.all(np.isclose(got, want, rtol=1e-5), axis=1)
    assert same.mean() > 0.999, same.mean()
    # the orientation matters: the same lookup without the rotation differs
    assert np.mean(np.all(np.isclose(DomeLight(scale, img).le_escaped(d), want, rtol=1e-5), axis=1)) < 0.5


def test_dome_sampler_pdf_and_integral(mi, rng):
    """Sampling: each sample's pdf equals pdf_direction at its direction (but for texel edges); the pdf integrates to 1
    over the sphere (uniform-direction estimate); E[L / pdf] equals the image's integral over the
    sphere, sum of texel radiance times texel solid angle dphi (cos theta0 - cos theta1) (closed form).
    Tolerances: 5 standard errors of each estimate."""
    img, scale, rot = _image(rng), np.array([1.0, 0.7, 0.3]), _rotation(rng, False)
    em = _dome(mi, img, scale, rot)
    n = 400000
    it = dr.zeros(mi.Interaction3f, n)
    u = rng.random((n, 2)).astype(np.float32)
    ds, w = em.sample_direction(it, mi.Point2f(u[:, 0], u[:, 1]))
    pdf_s = np.asarray(ds.pdf.numpy())
    pdf_e = np.asarray(em.pdf_direction(it, ds).numpy())
    ok = pdf_s > 0
    assert ok.mean() > 0.999
    # a sample drawn at a texel's edge can map back (float32) to the neighbouring texel: <= 0.1 %
    assert np.mean(np.isclose(pdf_e[ok], pdf_s[ok], rtol=1e-3)) > 0.999
    est = np.asarray(w.numpy()).T  # L / pdf
    h, wdt = img.shape[:2]
    th = np.arange(h + 1) / h * np.pi
    omega = (2 * np.pi / wdt) * (np.cos(th[:-1]) - np.cos(th[1:]))  # [h] solid angle of a texel in row r
    exact = (img * omega[:, None, None]).sum((0, 1)) * scale
    se = est.std(0) / math.sqrt(n)
    assert np.all(np.abs(est.mean(0) - exact) < 5 * se + 1e-6), (est.mean(0), exact, se)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    dsu = dr.zeros(mi.DirectionSample3f, n)
    dsu.d = _vec(mi, d)
    p = np.asarray(em.pdf_direction(it, dsu).numpy()) * 4 * np.pi
    assert abs(p.mean() - 1.0) < 5 * p.std() / math.sqrt(n)


def test_dome_not_a_rotation(mi, tmp_path):
    """A Mitsuba XML ``nasset_dome`` whose to_world scales: SCENE_INVALID, not a Mitsuba traceback."""
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><emitter type="nasset_dome"><transform name="to_world"><scale value="2,1,1"/></transform>'
        '</emitter></scene>')
    with pytest.raises(NassetError) as exc:
        load_file(tmp_path / "s.xml", mi=mi)
    assert exc.value.code == "SCENE_INVALID"


def test_dome_conformance_case(tmp_path):
    """``rna_dome_exr``: a rotated lat-long EXR dome lighting an rna asset (reference renderer at the
    case's ref_spp; tolerance from its measured noise)."""
    row = _run_case("rna_dome_exr", tmp_path)
    assert row["passed"], row


def test_dome_from_xml_file(mi, tmp_path, rng):
    """An XML ``nasset_dome`` reading its lat-long EXR by filename shows texel (row 0, +Y) times the
    radiance straight up; a missing file is FILE_NOT_FOUND naming it, through load_file."""
    img = _image(rng, 8, 16)
    mi.Bitmap(np.ascontiguousarray(img, np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB).write(str(tmp_path / "sky.exr"))
    xml = ('<scene version="3.0.0"><emitter type="nasset_dome"><string name="filename" value="{f}"/>'
           '<rgb name="radiance" value="2, 1, 0.5"/></emitter></scene>')
    (tmp_path / "s.xml").write_text(xml.format(f="sky.exr"))
    em = load_file(tmp_path / "s.xml", mi=mi).emitters()[0]
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0, -1, 0)  # looking up
    up = np.asarray(em.eval(si).numpy()).ravel()
    row0 = img[0] * np.array([2.0, 1.0, 0.5])
    assert np.isclose(row0, up, rtol=1e-5).all(axis=1).any(), (up, row0)
    (tmp_path / "bad.xml").write_text(xml.format(f="nope.exr"))
    with pytest.raises(NassetError) as exc:
        load_file(tmp_path / "bad.xml", mi=mi)
    assert exc.value.code == "FILE_NOT_FOUND" and "nope.exr" in str(exc.value)
