"""Data-parallel training (nasset_bakers.train.parallel): two processes launched by torchrun with the
gloo backend on CPU take the same optimiser steps as one process on the full batches.

The rna trainer itself runs in both: 601 samples in batches of 256 (the last, 89, splits 44 + 45)
for 2 epochs = 6 Adam steps. Tolerance: the weights agree to 1e-5 absolute (float32 gradients summed
in another order by the all-reduce, then normalised by Adam; measured 4e-7), while the steps moved
them by more than 1e-3.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from nasset_bakers.train import rna  # noqa: E402
from nasset_sdk.errors import NassetError, UsageError  # noqa: E402

N, BATCH, EPOCHS = 601, 256, 2
TOL = 1e-5
ROOT = Path(__file__).resolve().parents[2]


def _torchrun(*module_args: str, timeout: float = 120) -> None:
    """``torchrun --standalone --nproc_per_node=2 -m MODULE ARGS...`` from the repository root; it must exit 0."""
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nnodes=1", "--nproc_per_node=2", "-m", *module_args]
    run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    assert run.returncode == 0, run.stderr[-3000:]


def _data(n: int, seed: int, fiber: bool = False) -> dict:
    """Random rna samples; ``fiber``: with the fiber variant's h in [-1, 1] (the Blender hair bake's input)."""
    rng = np.random.default_rng(seed)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    data = {"x": rng.uniform(-0.4, 0.4, (n, 3)), "n": unit(rng.normal(size=(n, 3))), "wo": unit(rng.normal(size=(n, 3))),
            "wi": unit(rng.normal(size=(n, 3))), "vis": rng.random(n) < 0.7, "rgb": rng.gamma(2.0, 0.2, (n, 3))}
    return {**data, "h": rng.uniform(-1.0, 1.0, n)} if fiber else data


def test_every_process_leaves_the_group_before_the_interpreter_finalises(tmp_path):
    """A torchrun process destroys its process group at exit, before interpreter finalisation (else
    gloo's threads can abort a rank that finished first: SIGABRT, and torchrun kills the others). An
    exit handler registered before the group is joined runs after the trainer's own and must find it gone."""
    script = tmp_path / "leave.py"
    script.write_text(
        "import atexit, os, pathlib\nimport torch\nimport torch.distributed as dist\n"
        "out = pathlib.Path(__file__).with_name('rank' + os.environ['RANK'])\n"
        "atexit.register(lambda: out.write_text(str(dist.is_initialized())))\n"
        "from nasset_bakers.train.parallel import data_parallel\n"
        "dp = data_parallel(torch, 'cpu')\n"
        "t = torch.ones(1)\ndist.all_reduce(t)\nassert dp.world == 2 and t.item() == 2.0\n")
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nnodes=1", "--nproc_per_node=2", str(script)]
    run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    assert [(tmp_path / f"rank{r}").read_text() for r in (0, 1)] == ["False", "False"]  # initialised: "True"


class _Last:
    """A checkpoint that keeps the last state saved (the weights before the planes are frozen)."""

    state = None

    def restore(self, model, opt, sched):
        return None

    def save(self, state: dict) -> None:
        self.state = {k: v.detach().cpu().clone() for k, v in state["model"].items()}


def _train(fiber: bool = False) -> dict:
    settings = rna.TrainSettings(size="tiny", epochs=EPOCHS, batch=BATCH, device="cpu", seed=4)
    last = _Last()
    rna.train(_data(N, 1, fiber), _data(64, 2, fiber), ((-0.5,) * 3, (0.5,) * 3), settings, checkpoint=last)
    return last.state


@pytest.mark.parametrize("fiber", [False, True], ids=["surface", "fiber"])
def test_two_gloo_processes_take_the_single_process_steps(tmp_path, fiber):
    """Surface (Mitsuba and Blender meshes) and fiber (Blender hair: the h input) rna training."""
    out = tmp_path / "rank0.pt"
    _torchrun("tests.bakers.test_train_parallel", str(out), *(["fiber"] if fiber else []))
    ddp = torch.load(out, weights_only=True)
    one = _train(fiber)
    assert sorted(ddp) == sorted(one)
    init = _init(fiber)
    keys = [k for k in one if one[k].numel()]
    diff = max(float((ddp[k] - one[k]).abs().max()) for k in keys)
    moved = max(float((one[k] - init[k]).abs().max()) for k in keys)
    print(f"max |DDP - one process| {diff:.2e}, largest weight change {moved:.2e}")
    assert diff <= TOL and moved > 1e-3, (diff, moved)  # equal steps, and steps that moved the weights


def _init(fiber: bool = False) -> dict:
    settings = rna.TrainSettings(size="tiny", epochs=EPOCHS, batch=BATCH, device="cpu", seed=4)
    return rna.build_model(settings.size, init_std=settings.init_std, seed=settings.seed, fiber=fiber).state_dict()


def _train_neupress() -> dict:
    """The neupress appearance network: 601 samples in batches of 256, 2 epochs (6 Adam steps)."""
    from nasset_bakers.train.neupress import NeupressTrainSettings, train_appearance

    settings = NeupressTrainSettings(size="tiny", epochs=EPOCHS, batch=BATCH, device="cpu", seed=4)
    app = train_appearance(_data(N, 1), _data(64, 2), ((-0.5,) * 3, (0.5,) * 3), settings)
    return {k: v.detach().cpu().clone() for k, v in app.model.state_dict().items()}


def test_two_gloo_processes_take_the_single_process_neupress_steps(tmp_path):
    """The neupress appearance trainer: as the rna one, against the untrained network's weights
    (same seed) for the size of the steps."""
    from nasset_bakers.train.neupress import SIZES, build_skip_mlp

    out = tmp_path / "rank0.pt"
    _torchrun("tests.bakers.test_train_parallel", str(out), "neupress")
    ddp = torch.load(out, weights_only=True)
    one = _train_neupress()
    assert sorted(ddp) == sorted(one)
    m, layers, hidden, *_ = SIZES["tiny"]
    torch.manual_seed(4)
    init = build_skip_mlp(2 * m, hidden, layers, 3).state_dict()
    diff = max(float((ddp[k] - one[k]).abs().max()) for k in one)
    moved = max(float((one[k] - init[k]).abs().max()) for k in one)
    print(f"neupress: max |DDP - one process| {diff:.2e}, largest weight change {moved:.2e}")
    assert diff <= TOL and moved > 1e-3, (diff, moved)


class _Tuples:
    """Random 8dna tuples served in batches from a seeded stream: every process draws the same ones."""

    refreshes = 0

    def __init__(self, seed: int = 3) -> None:
        self.rng = np.random.default_rng(seed)

    def next(self, n: int) -> dict:
        r = self.rng
        unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
        return {"xo": r.uniform(-0.4, 0.4, (n, 3)), "wo": unit(r.normal(size=(n, 3))), "ui": unit(r.normal(size=(n, 3))) * 0.5,
                "wi": unit(r.normal(size=(n, 3))), "beta": r.gamma(2.0, 0.3, (n, 3))}


def _train_8dna() -> dict:
    """The 8dna trainer: 6 steps of 301 tuples (the shares 150 + 151)."""
    from nasset_bakers.train import eightdna

    settings = eightdna.TrainSettings(size="tiny", steps=6, batch=301, device="cpu", seed=4)
    result = eightdna.train(_Tuples(), ((-0.5,) * 3, (0.5,) * 3), settings)
    return {k: v.detach().cpu().clone() for k, v in result.model.state_dict().items()}


def test_two_gloo_processes_take_the_single_process_8dna_steps(tmp_path):
    """The 8dna trainer on a tuple stream both processes draw alike (the buffer fills are
    deterministic): weights as one process's to TOL, against the untrained model for the steps' size."""
    from nasset_bakers.train import eightdna

    out = tmp_path / "rank0.pt"
    _torchrun("tests.bakers.test_train_parallel", str(out), "8dna")
    ddp = torch.load(out, weights_only=True)
    one = _train_8dna()
    assert sorted(ddp) == sorted(one)
    init = eightdna.build_model("tiny", init_std=eightdna.TrainSettings.init_std, seed=4).state_dict()
    keys = [k for k in one if one[k].numel() and one[k].is_floating_point()]
    diff = max(float((ddp[k] - one[k]).abs().max()) for k in keys)
    moved = max(float((one[k] - init[k]).abs().max()) for k in keys)
    print(f"8dna: max |DDP - one process| {diff:.2e}, largest weight change {moved:.2e}")
    assert diff <= TOL and moved > 1e-3, (diff, moved)


def test_device_names_are_checked():
    from nasset_bakers.train.common import pick_device

    assert pick_device(torch, "cpu").type == "cpu"
    assert pick_device(torch, "auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(UsageError):
        pick_device(torch, "gpu")
    if not torch.cuda.is_available():
        with pytest.raises(NassetError) as e:
            pick_device(torch, "cuda:0")
        assert e.value.code == "CONVERT_BACKEND" and "cuda:0" in str(e.value)


if __name__ == "__main__":  # one process of the torchrun launch above
    which = sys.argv[2:]
    state = (_train_neupress() if which == ["neupress"] else _train_8dna() if which == ["8dna"]
             else _train(fiber=which == ["fiber"]))
    if torch.distributed.get_rank() == 0:
        torch.save(state, sys.argv[1])


def test_8dna_bake_with_workers_under_torchrun_is_refused(monkeypatch, tmp_path):
    """Every process traces its own buffer fills: Ray workers per process are refused (USAGE)."""
    from nasset_sdk.cli import main

    monkeypatch.setenv("WORLD_SIZE", "2")
    assert main(["bake", "--example", "--kind", "8dna", "--size", "tiny", "--workers", "2", "-o", str(tmp_path / "a.usdc")]) == 2
    assert not list(tmp_path.iterdir())  # refused before any work


@pytest.mark.slow
def test_rna_bake_under_torchrun_writes_one_valid_asset(tmp_path):
    """``torchrun --nproc_per_node=2 -m nasset_sdk.cli bake ...`` on CPU: rank 0 renders the views,
    both train, rank 0 alone writes the asset, which validates."""
    pytest.importorskip("mitsuba")
    from nasset_sdk.validate import validate_file

    out = tmp_path / "a.usdc"
    _torchrun("nasset_sdk.cli", "bake", "--example", "--kind", "rna", "--size", "tiny", "--views", "2", "--res", "12",
              "--epochs", "2", "--device", "cpu", "-o", str(out), "--json", timeout=600)
    assert out.is_file() and validate_file(out, probe=False).ok
    assert sorted(p.name for p in tmp_path.glob("*.usdc")) == ["a.usdc"]


def _bake_twice(tmp_path, args: list[str]) -> float:
    """Bake ``args`` under torchrun (2 processes), resume that bake under torchrun (all epochs done:
    every process must start after the last one, or one waits for the others' gradients), then bake
    in this process on the views already rendered; the largest difference of the checkpointed
    weights. Checks that the torchrun bake wrote one valid asset."""
    from nasset_sdk.cli import main
    from nasset_sdk.validate import validate_file

    out, work = tmp_path / "a.usdc", tmp_path / "data"
    bake = ("nasset_sdk.cli", *args, "-o", str(out), "--resume", str(work))
    _torchrun(*bake)
    assert out.is_file() and validate_file(out, probe=False).ok
    assert sorted(p.name for p in tmp_path.glob("*.usdc")) == ["a.usdc"]
    ckpt = work / "train_state.pt"
    ddp = torch.load(ckpt, weights_only=True)["model"]
    _torchrun(*bake)  # resumed at the last epoch by every process (none waits; one that did would wait 24 h)
    ckpt.unlink()  # the one-process bake trains anew on the views already rendered
    assert main([*args, "-o", str(tmp_path / "one.usdc"), "--resume", str(work)]) == 0
    one = torch.load(ckpt, weights_only=True)["model"]
    assert sorted(ddp) == sorted(one)
    return max(float((ddp[k] - one[k]).abs().max()) for k in one if one[k].numel())


BAKE = ["--size", "tiny", "--views", "2", "--res", "12", "--epochs", "2", "--device", "cpu", "--quiet"]


def test_blender_hair_bake_under_torchrun_takes_the_single_process_steps(tmp_path):
    """``torchrun --nproc_per_node=2 ... bake --example blender-hair`` on CPU: rank 0 renders with
    Cycles and alone writes the asset; rank 1 reads the same dataset (fiber h included) and trains
    its share. Its checkpointed weights equal a one-process bake's to TOL (same dataset folder
    re-used, so the two trainings see the same samples)."""
    pytest.importorskip("bpy", reason="Blender bakes need the bpy wheel")
    diff = _bake_twice(tmp_path, ["bake", "--example", "blender-hair", "--kind", "rna", *BAKE])
    print(f"Blender hair bake: max |DDP - one process| {diff:.2e}")
    assert diff <= TOL, diff


def test_neupress_bake_under_torchrun_takes_the_single_process_steps(tmp_path):
    """The neupress example bake under torchrun: the appearance network trains data-parallel (rank 1
    reads rank 0's neupress dataset), the rest is rank 0's; weights as a one-process bake's to TOL."""
    pytest.importorskip("mitsuba")
    diff = _bake_twice(tmp_path, ["bake", "--example", "--kind", "neupress", *BAKE])
    print(f"neupress bake: max |DDP - one process| {diff:.2e}")
    assert diff <= TOL, diff


@pytest.mark.slow
def test_8dna_bake_under_torchrun_takes_the_single_process_steps(tmp_path):
    """The 8dna example bake under torchrun: rank 0 writes the example scene and traces the held-out
    tuples, every process fills its own buffer (deterministic shards) and trains its share; weights
    as a one-process bake's to TOL."""
    pytest.importorskip("mitsuba")
    diff = _bake_twice(tmp_path, ["bake", "--example", "--kind", "8dna", "--size", "tiny", "--epochs", "20", "--spp", "2",
                                  "--device", "cpu", "--quiet"])
    print(f"8dna bake: max |DDP - one process| {diff:.2e}")
    assert diff <= TOL, diff
