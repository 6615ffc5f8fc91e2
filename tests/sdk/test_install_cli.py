"""Install and CLI behaviour a pipeline meets first: a core install without the extras (every missing package named
at once), ``--version``, file modes from the umask, and typed errors instead of tracebacks."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tomllib
from pathlib import Path

import pytest

from nasset_sdk.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _nasset(*argv, env=None, site=None, cwd=None):
    """Run the ``nasset`` CLI in a fresh interpreter; ``site``: the only site folder it sees (``python -S``)."""
    code = "import sys\n"
    if site is not None:
        code += f"import site; site.addsitedir({str(site)!r})\n"
    code += "from nasset_sdk.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    cmd = [sys.executable] + (["-S"] if site is not None else []) + ["-c", code, *map(str, argv)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env, cwd=cwd)


@pytest.fixture(scope="module")
def core_site(tmp_path_factory):
    """A site folder holding every installed package except those of the render, bench, train and mitsuba extras:
    a core install (plus the dev tools)."""
    real = Path(sysconfig.get_paths()["purelib"])
    site = tmp_path_factory.mktemp("core_site")
    hidden = ("embreex", "scipy", "torch", "mitsuba", "drjit")
    for entry in real.iterdir():
        if not entry.name.lower().startswith(hidden):
            (site / entry.name).symlink_to(entry)
    return site


def test_core_install_reads_validates_and_names_every_missing_package(core_site, tmp_path):
    asset = tmp_path / "a.usdc"
    assert main(["example", "-o", str(asset), "--size", "tiny"]) == 0
    probe = subprocess.run([sys.executable, "-S", "-c", f"import site; site.addsitedir({str(core_site)!r}); import embreex"],
                           capture_output=True, text=True, timeout=120)
    assert probe.returncode != 0, "the core site must not see embreex"
    for verb in (["validate", asset], ["inspect", asset]):
        r = _nasset(*verb, site=core_site)
        assert r.returncode == 0, r.stderr
    r = _nasset("render", asset, "-o", tmp_path / "o.exr", "--spp", "1", "--width", "8", "--height", "8", site=core_site)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "[EXTRA_MISSING]" in r.stderr and "embreex" in r.stderr and "nasset-sdk[render]" in r.stderr
    r = _nasset("bench", "neupress", "--quick", "-o", tmp_path / "b", site=core_site)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "embreex, scipy" in r.stderr and "nasset-sdk[render,bench]" in r.stderr  # both at once, not one per run
    assert not (tmp_path / "o.exr").exists()


def test_extras_are_the_pyproject_table():
    from nasset_sdk.extras import extra_packages

    table = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = " ".join(table["dependencies"])
    assert "embreex" not in core and "scipy" not in core
    for extra, reqs in table["optional-dependencies"].items():
        names = [r.split(">")[0].split("=")[0].split("<")[0].strip() for r in reqs]
        assert extra_packages(extra) == names, extra


def test_version_flag(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"nasset {version}"


@pytest.mark.parametrize("mask", [0o022, 0o027])
def test_written_files_follow_the_umask(tmp_path, mask):
    import numpy as np

    from nasset_sdk.images import write_exr

    old = os.umask(mask)
    try:
        assert main(["example", "-o", str(tmp_path / "a.usdc"), "--size", "tiny"]) == 0
        write_exr(tmp_path / "i.exr", np.ones((2, 2, 3)))
        with open(tmp_path / "plain", "w"):  # what a plain open() gives under this umask
            pass
    finally:
        os.umask(old)
    want = 0o666 & ~mask
    assert (tmp_path / "plain").stat().st_mode & 0o777 == want
    for name in ("a.usdc", "i.exr"):
        assert (tmp_path / name).stat().st_mode & 0o777 == want, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.usdc", "i.exr", "plain"]  # no temp files left


def test_example_unknown_size_is_a_usage_error(tmp_path, capsys):
    assert main(["example", "-o", str(tmp_path / "a.usdc"), "--size", "huge"]) == 2
    err = capsys.readouterr().err
    assert "[USAGE]" in err and "huge" not in err.split("[USAGE]")[0] and "tiny" in err
    assert not (tmp_path / "a.usdc").exists()


def test_render_zero_width_is_a_usage_error(tmp_path, capsys):
    assert main(["example", "-o", str(tmp_path / "a.usdc"), "--size", "tiny"]) == 0
    assert main(["render", str(tmp_path / "a.usdc"), "-o", str(tmp_path / "o.exr"), "--width", "0", "--quiet"]) == 2
    assert "[USAGE]" in capsys.readouterr().err


def test_bake_missing_scene_says_file_not_found(core_site, tmp_path):
    """Without torch and mitsuba: a missing scene is reported as such, an existing one lists every missing package."""
    r = _nasset("bake", tmp_path / "nosuch.xml", "--asset", "obj", "--kind", "rna", "-o", tmp_path / "a.usdc", site=core_site)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "[CONVERT_SCENE_MISSING]" in r.stderr and "nosuch.xml" in r.stderr and "torch" not in r.stderr
    (tmp_path / "scene.xml").write_text('<scene version="3.0.0"/>')
    r = _nasset("bake", tmp_path / "scene.xml", "--asset", "obj", "--kind", "rna", "-o", tmp_path / "a.usdc", site=core_site)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "[EXTRA_MISSING]" in r.stderr and "torch, mitsuba, scipy" in r.stderr


def test_convert_scene_example_failure_leaves_nothing(tmp_path):
    out = tmp_path / "work"
    out.mkdir()
    r = _nasset("convert-scene", "--example", "-o", out / "scene.usda", "--replace", f"shell={tmp_path / 'missing.usdc'}",
                cwd=out)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert list(out.iterdir()) == []
