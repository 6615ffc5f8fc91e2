"""Corruption fuzz of a valid .usdc: byte flips, random runs, zeroed runs and truncations (seeded,
time-bounded). Every outcome is a report whose findings carry catalogue codes, or a typed
NassetError; usd-core runs in the probe child first, so a crash there cannot take this process down."""

from __future__ import annotations

import random
import time

import pytest

from nasset_sdk import Asset
from nasset_sdk.errors import CODES, NassetError
from nasset_sdk.examples import example_builder
from nasset_sdk.safeopen import probe
from nasset_sdk.validate import validate_file

BUDGET_S = 20.0
MIN_ITERATIONS = 15


def _mutate(rng: random.Random, data: bytes) -> tuple[str, bytes]:
    b = bytearray(data)
    n = len(b)
    mode = rng.choice(["flip", "flips", "header", "tail", "zero_run", "truncate"])
    if mode == "truncate":
        return mode, bytes(b[: rng.randrange(n)])
    if mode == "flip":
        j = rng.randrange(n)
        b[j] ^= 1 << rng.randrange(8)
    elif mode == "flips":
        for _ in range(32):
            b[rng.randrange(n)] = rng.randrange(256)
    elif mode == "header":  # bootstrap + first structural section
        j = rng.randrange(0, min(n, 128))
        b[j] ^= 1 << rng.randrange(8)
    elif mode == "tail":  # table of contents and structural sections live at the end
        j = rng.randrange(max(0, n - 2048), n - 8)
        b[j:j + 8] = rng.randbytes(8)
    else:
        j = rng.randrange(n - 64)
        b[j:j + 64] = bytes(64)
    return mode, bytes(b)


def _assert_valid_means_intact(path, good_path, what):
    """A corrupted file the validator accepts may differ from the original only in tensor values (tensors carry no
    digest): same structure (kind, components, tensor shapes and dtypes, network bytes) and it evaluates finite."""
    import numpy as np

    a, g = Asset.open(path, probe=True), Asset.open(good_path)
    a.load("all")
    g.load("all")
    assert (a.kind, a.variant, sorted(a.components())) == (g.kind, g.variant, sorted(g.components())), what
    for c in g.components():
        assert sorted(a.tensor_refs(c)) == sorted(g.tensor_refs(c)), what
        for n in g.tensor_refs(c):
            ta, tg = a.tensor(c, n), g.tensor(c, n)
            assert (ta.shape, ta.dtype) == (tg.shape, tg.dtype), (what, c, n)
        assert sorted(a.network_refs(c)) == sorted(g.network_refs(c)), what
        for n in g.network_refs(c):
            assert a.network_bytes(c, n) == g.network_bytes(c, n), (what, c, n)
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.5, 0.5, (32, 3)).astype(np.float32)
    d = rng.normal(size=(4, 32, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    for out in a.evaluator().evaluate(x, d[0], d[1], d[2]):
        assert np.isfinite(out).all(), what


def test_corruption_fuzz(tmp_path):
    good_path = example_builder("rna", size="tiny", seed=7).write(tmp_path / "good.usdc")
    good = good_path.read_bytes()
    rng = random.Random(20240611)
    outcomes: dict[str, int] = {}
    t0 = time.perf_counter()
    i = 0
    while i < MIN_ITERATIONS or time.perf_counter() - t0 < BUDGET_S:
        mode, data = _mutate(rng, good)
        path = tmp_path / f"fuzz_{i:04d}.usdc"  # a fresh name: no layer cached under it
        path.write_bytes(data)
        try:
            report = validate_file(path, probe_timeout=15)
        except NassetError as exc:  # typed errors are an acceptable outcome
            key = f"raised:{exc.code}"
        else:
            for f in report.findings:
                assert f.code in CODES and f.severity in ("error", "warning", "info"), f
            assert "CHECK_FAILED" not in report.codes(), f"{path} ({mode}): {report.format_text()}"
            key = "valid" if report.ok else "+".join(sorted(report.codes("error")))
            if report.ok:
                _assert_valid_means_intact(path, good_path, f"{path} ({mode})")
        outcomes[key] = outcomes.get(key, 0) + 1
        path.unlink()
        i += 1
    print(f"\nfuzz: {i} corruptions in {time.perf_counter() - t0:.1f} s: {outcomes}")
    assert i >= MIN_ITERATIONS


def test_probe_catches_a_crashing_file(tmp_path):
    """A flip in the crate's first structural section crashed usd-core 26.11 with SIGSEGV when read."""
    good = example_builder("rna", size="tiny", seed=0).write(tmp_path / "good.usdc").read_bytes()
    bad = bytearray(good)
    bad[89] ^= 0x28
    path = tmp_path / "bad.usdc"
    path.write_bytes(bytes(bad))
    result = probe(path, level="full", timeout=30)
    assert not result.ok and result.status in ("crashed", "error", "timeout")
    print(f"\nprobe of the flipped file: {result.status} {result.detail} in {result.seconds:.2f} s")
    with pytest.raises(NassetError) as info:
        Asset.open(path, probe=True)
    assert info.value.code == "FILE_UNREADABLE" and str(path) in str(info.value)
    report = validate_file(path)
    assert report.codes() == {"FILE_UNREADABLE"}


def test_probe_passes_valid_file_and_cost(tmp_path):
    path = example_builder("rna", size="small", seed=0).write(tmp_path / "good.usdc")
    times = []
    for level in ("layer", "full"):
        r = probe(path, level=level, timeout=60)
        assert r.ok, r
        times.append(r.seconds)
    asset = Asset.open(path, probe=True)
    assert asset.kind == "rna"
    print(f"\nprobe cost ({path.stat().st_size} B file): layer {times[0]:.2f} s, full {times[1]:.2f} s")
