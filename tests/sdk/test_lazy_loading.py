"""Opening an asset for evaluation reads none of its optional components' bytes.

The asset has a test-only kind with a ~64 MB optional component. A child process reads the
crate with pread (``USDC_USE_PREAD=1``, instead of mmap) so ``rchar`` in /proc/self/io counts the
bytes USD actually read; opening + evaluating with load='required' is compared with load='all'
+ reading the optional tensor."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

KIND_SRC = textwrap.dedent('''
    import numpy as np
    from nasset_sdk.kinds import ComponentSpec, KindContract, NetworkSpec, TensorSpec, register_kind, KINDS

    class LazyTestKind(KindContract):
        id = "lazytest"
        variants = ("surface",)

        def components(self, variant):
            return {
                "core": ComponentSpec(True, "evaluation", {"grid": TensorSpec(("R", "C"), "r,c")},
                                      {"decoder": NetworkSpec((("x", "C"),), (("y", "3"),))}),
                "prt": ComponentSpec(False, "prt", {"coeffs": TensorSpec(("N", "9"), "n,coeff")}),
            }

    if "lazytest" not in KINDS:
        register_kind(LazyTestKind())
''')

CHILD = textwrap.dedent('''
    import json, sys
    import numpy as np
    exec(sys.argv[3])
    from nasset_sdk import Asset
    def rchar():
        with open("/proc/self/io") as fh:
            return int(next(l for l in fh if l.startswith("rchar")).split()[1])
    from nasset_sdk.safeopen import ensure_safe
    before = rchar()
    ensure_safe(sys.argv[1])  # the guarded probe every reader runs first, in a child of its own (counted when reaped)
    probe_bytes = rchar() - before
    before = rchar()
    asset = Asset.open(sys.argv[1], load=sys.argv[2])  # probed above: opened without a second probe
    opened = rchar() - before
    asset.check_runtime("core", "decoder")  # the networks' runtime probe: a child's interpreter start-up, not counted
    before = rchar()
    grid = np.asarray(asset.tensor("core", "grid"), np.float32)
    y = asset.session("core", "decoder", intra_threads=1).run(None, {"x": grid[:4]})[0]
    if sys.argv[2] == "all":
        total = float(np.asarray(asset.tensor("prt", "coeffs"), np.float32).sum())
    print(json.dumps({"bytes": opened + rchar() - before, "probe_bytes": probe_bytes, "y": float(y.sum())}))
''')



@pytest.fixture(scope="module")
def lazy_asset(tmp_path_factory):
    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.examples import example_builder
    from nasset_sdk.kinds import KINDS
    from nasset_sdk.networks import random_mlp

    exec(KIND_SRC, {})
    try:
        rng = np.random.default_rng(0)
        b = AssetBuilder("lazytest")
        b.set_geometry(example_builder("rna", size="tiny").geometry)
        core = b.component("core", required=True, purpose="evaluation")
        core.add_tensor("grid", rng.normal(size=(16, 8)), dtype="float32")
        core.add_network("decoder", random_mlp(rng, [8, 16, 3]))
        rows = (64 << 20) // (9 * 4)  # ~64 MB of float32
        prt = b.component("prt", required=False, purpose="prt")
        prt.add_tensor("coeffs", rng.normal(size=(rows, 9)).astype(np.float32), dtype="float32")
        b.provenance = {"generator": "test"}
        path = b.write(tmp_path_factory.mktemp("lazy") / "lazy.usdc")
        example_builder("rna", size="tiny").write(path.parent / "tiny.usdc")
        yield path, rows * 9 * 4
    finally:
        KINDS.pop("lazytest", None)


def _read_bytes(path, load):
    env = dict(os.environ, USDC_USE_PREAD="1", PXR_WORK_THREAD_LIMIT="1")
    r = subprocess.run([sys.executable, "-c", CHILD, str(path), load, KIND_SRC], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_required_only_reads_far_less_than_optional(lazy_asset):
    path, prt_bytes = lazy_asset
    file_bytes = path.stat().st_size
    req = _read_bytes(path, "required")
    full = _read_bytes(path, "all")
    print(f"\nlazy loading: file {file_bytes / 1e6:.1f} MB, optional prt tensor {prt_bytes / 1e6:.1f} MB; "
          f"bytes read (rchar, incl. Python/USD startup files after import): required {req['bytes'] / 1e6:.2f} MB, "
          f"all {full['bytes'] / 1e6:.2f} MB")
    assert req["y"] == full["y"]  # same evaluation either way
    assert full["bytes"] > 0.9 * prt_bytes, "pread accounting did not see the optional tensor being read"
    assert req["bytes"] < 0.05 * prt_bytes, f"required-only open read {req['bytes']} bytes"
    # the probe maps the file: it reads array headers, never the optional tensor (its own bytes: interpreter start-up)
    tiny = _probe_bytes(path.parent / "tiny.usdc")
    assert req["probe_bytes"] - tiny < 0.05 * prt_bytes, f"the probe read {req['probe_bytes']} bytes ({tiny} for a tiny asset)"


def _probe_bytes(path) -> int:
    code = ("from nasset_sdk.safeopen import ensure_safe\n"
            "def rchar():\n    return int(next(l for l in open('/proc/self/io') if l.startswith('rchar')).split()[1])\n"
            f"b = rchar(); ensure_safe({str(path)!r}); print(rchar() - b)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, USDC_USE_PREAD="1", PXR_WORK_THREAD_LIMIT="1"))
    assert r.returncode == 0, r.stderr[-2000:]
    return int(r.stdout.split()[-1])
