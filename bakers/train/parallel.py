"""Data-parallel training with torch's DistributedDataParallel, launched by ``torchrun`` (spec/bake.md#training-devices).

One process per device. ``torchrun --nproc_per_node=G`` starts the G processes and sets the
environment read here (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT); without it a trainer
runs in one process exactly as before. Every process holds the whole training set and draws the
same global batch (same seed); each takes its contiguous share of the batch, and DDP averages the
gradients. A rank's mean loss is weighted by ``world * share / batch`` so that the averaged gradient
is the gradient of the global batch's mean loss, also for a last batch that does not split evenly:
the processes take the optimiser steps one process would take on the full batches.
"""

from __future__ import annotations

import atexit
import os
from dataclasses import dataclass
from datetime import timedelta

from .common import pick_device

#: how long a process waits in a collective: the others wait there while rank 0 renders the dataset
WAIT = timedelta(hours=24)


@dataclass
class DataParallel:
    """This process's place in a data-parallel run: ``rank`` of ``world`` processes, its ``device``."""

    rank: int = 0
    world: int = 1
    device: object = None

    @property
    def is_main(self) -> bool:
        """True in the process that saves checkpoints and writes the asset (rank 0)."""
        return self.rank == 0

    def wrap(self, torch, model):
        """``model`` inside DistributedDataParallel (unchanged in one process)."""
        if self.world == 1:
            return model
        ids = [self.device.index] if self.device.type == "cuda" else None
        # find_unused_parameters: a step may leave parts unused (8dna far-field: flows 1-2)
        return torch.nn.parallel.DistributedDataParallel(model, device_ids=ids, find_unused_parameters=True)

    def share(self, idx):
        """This process's contiguous share of a global batch ``idx`` [B] (all of it in one process)."""
        if self.world == 1:
            return idx
        n = len(idx)
        lo, hi = n * self.rank // self.world, n * (self.rank + 1) // self.world
        return idx[lo:hi]

    def weight(self, share: int, batch: int) -> float:
        """Factor on a share's mean loss so DDP's gradient average is the global batch's mean-loss gradient."""
        return 1.0 if self.world == 1 else self.world * share / max(batch, 1)

    def mean(self, torch, value: float) -> float:
        """``value`` averaged over the processes (a logged loss; unchanged in one process)."""
        if self.world == 1:
            return value
        t = torch.tensor([float(value)], dtype=torch.float64, device=self.device if self.device.type == "cuda" else "cpu")
        torch.distributed.all_reduce(t)
        return float(t.item()) / self.world


    def from_main(self, torch, obj=None):
        """``obj`` of rank 0, in every process (waits until rank 0 sends it; ``obj`` itself in one process)."""
        if self.world == 1:
            return obj
        box = [obj if self.is_main else None]
        torch.distributed.broadcast_object_list(box, src=0)
        return box[0]


def data_parallel(torch, want: str = "auto") -> DataParallel:
    """This process's :class:`DataParallel`: from torchrun's environment (the process group is joined
    here: NCCL on CUDA, gloo on CPU; device cuda:LOCAL_RANK where CUDA is used), else one process on
    ``pick_device(want)``."""
    world = int(os.environ.get("WORLD_SIZE", "1") or 1)
    device = pick_device(torch, want)
    if world <= 1:
        return DataParallel(0, 1, device)
    rank, local = int(os.environ["RANK"]), int(os.environ.get("LOCAL_RANK", "0"))
    if device.type == "cuda":
        device = torch.device("cuda", local)
        torch.cuda.set_device(device)
    dist = torch.distributed
    if not dist.is_initialized():
        dist.init_process_group(backend="nccl" if device.type == "cuda" else "gloo", timeout=WAIT)
        atexit.register(_leave_group, dist)
    return DataParallel(rank, world, device)


#: how long a process leaving the group waits for the others at exit (:func:`_leave_group`)
LEAVE_WAIT = timedelta(seconds=60)


def _leave_group(dist) -> None:
    """Destroy the process group at exit while the interpreter is still whole, once every process has come
    to its exit. Left to interpreter finalisation, gloo's worker threads can still be joinable when they are
    destroyed, and the process aborts ("terminate called without an active exception", SIGABRT): a rank
    that finished its share and exited then took down rank 0 while it was writing the asset. Destroying
    the group while another rank was still working aborted the same way (about one torchrun launch in 20 of
    tests/bakers/test_train_parallel.py), hence the barrier first; a rank that never comes (it failed) is
    waited for :data:`LEAVE_WAIT` at most."""
    if not dist.is_initialized():
        return
    try:
        if dist.get_backend() == "gloo":
            dist.monitored_barrier(timeout=LEAVE_WAIT)
        else:
            dist.barrier()
    except Exception:  # noqa: BLE001 - a peer that failed or left: leave anyway
        pass
    dist.destroy_process_group()
