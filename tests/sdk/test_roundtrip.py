"""Every registered kind's example asset round-trips bit-exactly; writes are atomic; OpenUSD's own
validators report no errors on a written asset."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import nasset_sdk
from nasset_sdk import Asset
from nasset_sdk.errors import NassetError
from nasset_sdk.examples import example_builder
from nasset_sdk.networks import make_session


def _configs():
    for kind, contract in sorted(nasset_sdk.KINDS.items()):
        for variant in contract.variants:
            for qv in (False, True):
                yield pytest.param(kind, variant, qv, id=f"{kind}-{variant}-{'qv' if qv else 'plain'}")


@pytest.mark.parametrize("kind,variant,quality_variants", list(_configs()))
def test_roundtrip_bit_identical(tmp_path, kind, variant, quality_variants):
    builder = example_builder(kind, variant=variant, size="tiny", seed=5, quality_variants=quality_variants)
    path = builder.write(tmp_path / "a.usdc")
    rng = np.random.default_rng(0)
    for name, levels in builder.components.items():
        for quality, data in levels.items():
            asset = Asset.open(path, load="none", quality={name: quality} if quality else None)
            asset.load([name])
            for tname, (arr, dtype, _layout) in data.tensors.items():
                got = asset.tensor(name, tname)
                assert got.dtype == np.dtype(dtype) and got.shape == arr.shape
                assert got.tobytes() == arr.tobytes(), f"{name}/{tname} differs"
            for nname, blob in data.networks.items():
                assert asset.network_bytes(name, nname) == blob
                ref = make_session(blob, intra_threads=1)
                sess = asset.session(name, nname, intra_threads=1)
                feeds = {i.name: rng.normal(size=(17, i.shape[1])).astype(np.float32) for i in ref.get_inputs()}
                for a, b in zip(ref.run(None, feeds), sess.run(None, feeds), strict=True):
                    assert np.array_equal(a, b)


def test_atomic_write_failure_leaves_target_untouched(tmp_path, monkeypatch):
    target = tmp_path / "a.usdc"
    example_builder("rna", size="tiny", seed=1).write(target)
    before = target.read_bytes()

    def boom(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(NassetError) as info:
        example_builder("rna", size="tiny", seed=2).write(target)
    assert info.value.code == "WRITE_FAILED" and str(target) in str(info.value)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.usdc"], "temporary file left behind"
    fresh = tmp_path / "new.usdc"
    with pytest.raises(NassetError):
        example_builder("rna", size="tiny", seed=2).write(fresh)
    assert not fresh.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.usdc"]


CHILD_WRITE = """
import sys
from nasset_sdk.examples import example_builder
b = example_builder("rna", size="hq", seed=3)
print("ready", flush=True)
b.write(sys.argv[1])
"""


def test_killed_writer_never_leaves_a_partial_target(tmp_path):
    target = tmp_path / "a.usdc"
    example_builder("rna", size="tiny", seed=1).write(target)
    before = target.read_bytes()
    proc = subprocess.Popen([sys.executable, "-c", CHILD_WRITE, str(target)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not any(p.name.startswith(".a.tmp-") for p in tmp_path.iterdir()):
        if proc.poll() is not None:
            break
        time.sleep(0.0005)
    writing = proc.poll() is None and any(p.name.startswith(".a.tmp-") for p in tmp_path.iterdir())
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert writing, "the kill did not land while the writer was writing its temporary file"
    data = target.read_bytes()
    if data != before:  # the rename happened before the kill: then it is the complete new asset
        from nasset_sdk.validate import validate_file

        assert validate_file(target).ok
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != "a.usdc"]
    assert data != before or leftovers, "killed before the rename, yet no temporary file is left: the kill missed the write"
    # a SIGKILLed writer cannot remove its temporary: it is a hidden sibling, never the target
    assert all(n.startswith(".a.tmp-") for n in leftovers), leftovers


@pytest.mark.parametrize("kind", sorted(nasset_sdk.KINDS))
def test_usd_validators_report_no_errors(tmp_path, kind):
    from pxr import Usd, UsdValidation

    path = example_builder(kind, size="tiny", seed=1, quality_variants=True).write(tmp_path / "a.usdc")
    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    ctx = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    errors = [e for e in ctx.Validate(stage) if e.GetType() == UsdValidation.ValidationErrorType.Error]
    assert not errors, [f"{e.GetName()}: {e.GetMessage()}" for e in errors]
