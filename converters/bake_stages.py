"""Stages every baker shares: rendering the views of a resumable dataset, and training with a progress bar.

Both keep what is done on Ctrl-C (views on disk, the training checkpoint) and say how to resume.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable


def progress_bar(**kw):
    """A tqdm bar (``disable=True`` for quiet runs)."""
    from tqdm.auto import tqdm

    return tqdm(**kw)


def render_views(store, views: int, val_views: int, render_one: Callable[[str, int], dict], *, desc: str,
                 work: Path, quiet: bool, say: Callable[..., None]) -> None:
    """Render and save every training and held-out view ``store`` lacks; ``render_one(split, i)`` -> arrays."""
    jobs = [("train", i) for i in range(views)] + [("val", i) for i in range(val_views)]
    todo = [j for j in jobs if not store.has(*j)]
    if len(todo) < len(jobs):
        say(f"resuming: {len(jobs) - len(todo)} of {len(jobs)} views already in {work}")
    bar = progress_bar(total=len(jobs), initial=len(jobs) - len(todo), desc=desc, unit="view", disable=quiet)
    try:
        for split, i in todo:
            store.save(split, i, render_one(split, i))
            bar.update(1)
    except KeyboardInterrupt:
        say(f"\ninterrupted; the dataset so far is kept in {work} -- rerun with --resume {work}")
        raise
    finally:
        bar.close()


def train_with_progress(run: Callable[[Callable], object], *, total: int, desc: str, work: Path, quiet: bool,
                        say: Callable[..., None]):
    """``run(progress)`` with a bar over ``total`` epochs; ``progress(epoch, loss, val_psnr)`` updates it."""
    bar = progress_bar(total=total, desc=desc, unit="epoch", disable=quiet)
    last = {"psnr": float("nan")}

    def progress(epoch, loss, val_psnr):
        if math.isfinite(val_psnr):
            last["psnr"] = val_psnr
        bar.n = epoch + 1
        bar.set_postfix(loss=f"{loss:.3g}", val_psnr=f"{last['psnr']:.2f}")
        bar.refresh()

    try:
        return run(progress)
    except KeyboardInterrupt:
        say(f"\ninterrupted; dataset and training state kept in {work} -- rerun with --resume {work}")
        raise
    finally:
        bar.close()
