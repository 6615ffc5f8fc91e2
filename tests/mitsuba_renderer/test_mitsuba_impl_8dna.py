"""The 8dna kind of the second implementation (mitsuba_renderer/eightdna.py).

Its rational-quadratic spline is written from spec/kinds/8dna.md#spline alone, so these tests check
the equations themselves: inverse(forward(z)) = z, log|dz/dt| = -log(dt/dz), and the density
integrates to 1; then the whole estimator passes the 8dna conformance case through the CLI.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytest.importorskip("onnxruntime")
pytest.importorskip("pxr")

from nasset_mitsuba_renderer.eightdna import Spline, box_jacobian, box_point, cubemap  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("k,mins", [(4, (0.01, 0.02, 0.001)), (16, (0.0, 0.0, 1e-3)), (32, (0.03, 0.001, 0.5))])
def test_spline_inverse_and_normalisation(k, mins):
    rng = np.random.default_rng(k)
    g = rng.normal(scale=3.0, size=(6, 3 * k + 1))
    g[0, :] = 0.0  # identity-like spline
    n = 4001
    z = np.tile(np.linspace(0.0, 1.0, n), 6)
    sp = Spline(np.repeat(g, n, 0), mins)
    t, dtdz = sp.forward(z)
    assert np.all(np.diff(t.reshape(6, n), axis=1) > 0) and np.all(dtdz > 0)
    assert np.allclose(t.reshape(6, n)[:, [0, -1]], [0.0, 1.0], atol=1e-12)
    z2, logdz = sp.inverse(t)
    assert np.max(np.abs(z2 - z)) < 1e-9
    assert np.allclose(logdz, -np.log(dtdz), atol=1e-7)
    # the density of t = forward(z), z ~ U[0, 1], integrates to 1 over [0, 1]. The density has narrow
    # spikes (where dt/dz is tiny), so the midpoint rule runs on the mesh forward(z_j), z_j uniform.
    zz = np.linspace(0.0, 1.0, 100001)
    for row in range(6):
        sp1 = Spline(np.repeat(g[row:row + 1], len(zz), 0), mins)
        tj = sp1.forward(zz)[0]
        assert np.all(np.diff(tj) > 0)
        tm = 0.5 * (tj[1:] + tj[:-1])
        _, ld = Spline(np.repeat(g[row:row + 1], len(tm), 0), mins).inverse(tm)
        assert np.sum(np.exp(ld) * np.diff(tj)) == pytest.approx(1.0, abs=1e-4)

def test_flow_pdf_integrates_to_one(tmp_path):
    """E[1 / p(u, w)] over flow samples = measure of (box surface) x (sphere) when p integrates to 1
    (the pdf is recomputed from the sampled u_i, w_i: inverse spline, Jacobian J(u))."""
    from nasset_mitsuba_renderer.eightdna import EightDnaAsset
    from nasset_sdk.examples import example_builder

    a = EightDnaAsset(example_builder("8dna", size="tiny", seed=0).write(tmp_path / "a.usda"))
    rng = np.random.default_rng(0)
    n = 60000
    x = np.tile(rng.uniform(-0.3, 0.3, (1, 3)), (n, 1))
    wo = np.tile([[0.3, 0.4, 0.866]], (n, 1))
    base = a.base(x, wo)
    u, w, _ = a.sample(base, 1, rng.random((n, 4)))
    s = a.params_of(u, w)
    pdf = a.pdf_position_rgb(base, u, s)[:, 1] * a.pdf_direction_rgb(base, s)[:, 1]
    e = a.half
    measure = 8.0 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2]) * 4.0 * np.pi
    assert np.mean(1.0 / pdf) / measure == pytest.approx(1.0, abs=0.06)



def test_box_jacobian_integrates_to_sphere():
    """dω(d12) = e_k*/τ³ dA: integrating J over the box surface gives 4π (Archimedes map is equal-area)."""
    rng = np.random.default_rng(0)
    e = np.array([0.3, 0.5, 0.8])
    faces = rng.integers(0, 6, 400000)
    uv = rng.uniform(-1.0, 1.0, (len(faces), 2))
    ax = faces // 2
    u = np.zeros((len(faces), 3))
    for a in range(3):
        sel = ax == a
        o = [b for b in range(3) if b != a]
        u[sel, a] = np.where(faces[sel] % 2 == 0, 1.0, -1.0) * e[a]
        u[sel, o[0]], u[sel, o[1]] = uv[sel, 0] * e[o[0]], uv[sel, 1] * e[o[1]]
    w = np.array([e[1] * e[2], e[0] * e[2], e[0] * e[1]])[ax]  # face area / 4, sampled with prob 1/6
    est = np.mean(box_jacobian(u, e) * w * 4.0 * 6.0)
    assert est == pytest.approx(4.0 * np.pi, rel=0.01)
    d = u / np.linalg.norm(u, axis=1, keepdims=True)
    tau, _ = box_point(d, e)
    assert np.allclose(tau[:, None] * d, u, atol=1e-12)


def test_cubemap_is_continuous_across_seams():
    rng = np.random.default_rng(1)
    grid = rng.normal(size=(6, 4, 4, 3))
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    step = rng.normal(size=d.shape) * 1e-7
    a, b = cubemap(grid, d), cubemap(grid, d + step)
    assert np.max(np.abs(a - b)) < 1e-4
    # every pair straddles a seam: both sides of each of the 12 cube edges (axis i = +-1, axis j = +-(1 -+ eps)), and
    # the 8 corners approached from each of their 3 faces
    eps, m = 1e-7, 2000
    for i in range(3):
        for j in range(3):
            if i == j:
                continue
            k = 3 - i - j
            for si in (-1.0, 1.0):
                for sj in (-1.0, 1.0):
                    p, q = np.zeros((m, 3)), np.zeros((m, 3))
                    p[:, i], p[:, j] = si, sj * (1 - eps)  # on face i, just before the edge
                    q[:, i], q[:, j] = si * (1 - eps), sj  # on face j, just past it
                    p[:, k] = q[:, k] = rng.uniform(-1, 1, m)
                    np.testing.assert_allclose(cubemap(grid, p), cubemap(grid, q), atol=1e-4, err_msg=f"edge {i}{j} {si} {sj}")
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float64)
    for c in corners:
        near = np.array([c * np.where(np.arange(3) == f, 1.0, 1 - eps) for f in range(3)])
        vals = cubemap(grid, near)
        assert np.ptp(vals, axis=0).max() < 1e-4, c


@pytest.mark.parametrize("case", ["8dna_distant", "8dna_near"])
def test_8dna_conformance_case_via_cli(tmp_path, case):
    tpl = f"{sys.executable} -m nasset_mitsuba_renderer.render {{scene}} {{out}} {{spp}} --width {{width}} --height {{height}} --seed {{seed}}"
    res = subprocess.run([sys.executable, "-m", "nasset_sdk.cli", "conformance", "--renderer", tpl, "--cases", case, "--json",
                          "--workdir", str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=300)
    report = json.loads(res.stdout)
    assert res.returncode == 0 and report["ok"], res.stdout[-2000:] + res.stderr[-2000:]
