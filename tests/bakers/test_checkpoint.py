"""Training checkpoints (bakers/train/common.TorchCheckpoint): a matching one resumes, and one whose tensors do not
fit the model (a preset's network changed under the same settings) starts the bake fresh instead of failing half
loaded."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from nasset_bakers.train.common import TorchCheckpoint  # noqa: E402


def _parts(width):
    torch.manual_seed(width)
    model = torch.nn.Sequential(torch.nn.Linear(2, width), torch.nn.ReLU(), torch.nn.Linear(width, 1))
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=10)
    return model, opt, sched


def _train(model, opt, sched, steps=3):
    for _ in range(steps):
        loss = model(torch.ones(4, 2)).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()


def test_a_matching_checkpoint_resumes_and_another_shape_starts_fresh(tmp_path):
    key = {"train": {"size": "small", "steps": 10}}
    model, opt, sched = _parts(8)
    _train(model, opt, sched)
    TorchCheckpoint(tmp_path / "state.pt", key).save({"model": model.state_dict(), "opt": opt.state_dict(),
                                                      "sched": sched.state_dict(), "step": 3})
    same, opt2, sched2 = _parts(8)
    state = TorchCheckpoint(tmp_path / "state.pt", key).restore(same, opt2, sched2)
    assert state["step"] == 3 and sched2.last_epoch == 3
    assert all(torch.equal(a, b) for a, b in zip(same.state_dict().values(), model.state_dict().values(), strict=True))

    wider, opt3, sched3 = _parts(16)  # same key, other network: before, load_state_dict raised a size mismatch
    fresh = [v.clone() for v in wider.state_dict().values()]
    assert TorchCheckpoint(tmp_path / "state.pt", key).restore(wider, opt3, sched3) is None
    assert all(torch.equal(a, b) for a, b in zip(wider.state_dict().values(), fresh, strict=True)) and sched3.last_epoch == 0

    other, opt4, sched4 = _parts(8)  # another key: not this bake's either
    assert TorchCheckpoint(tmp_path / "state.pt", {"train": {"size": "hq"}}).restore(other, opt4, sched4) is None
