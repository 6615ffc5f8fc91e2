"""The view-rendering stage of a bake on a Ray cluster: ``nasset bake ... --workers N [--cluster ADDRESS]``.

spec/bake.md#cluster. Each worker is a Ray actor that builds the bake's view renderer once (it loads
the source scene in its own process, through the same factory the single-process bake uses) and
renders the views it is handed one at a time. The driver saves every finished view into the same
dataset folder as a single-process bake (``DatasetDir``: atomic per-view files), so ``--resume``
works unchanged, and a view's samples depend only on (seed, split, view index): a bake on N workers
writes the same dataset as on one.

Faults: a worker that dies (its process killed, its node lost) is restarted by Ray (it rebuilds its
scene) and the view it held is handed out again, to whichever worker is free first. Ctrl-C on the
driver keeps every view already saved. Ray is the optional extra ``nasset-sdk[cluster]``.
"""

from __future__ import annotations

import importlib
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from nasset_sdk.errors import UsageError, error

#: times one view is handed out before the bake gives up on it (a view that kills every worker)
MAX_ATTEMPTS = 3


@dataclass(frozen=True)
class ViewSource:
    """How a worker builds ``render_one(split, i) -> dict of arrays``: ``factory`` ("module:function")
    called with ``kwargs`` (picklable: paths, ids, settings dataclasses) in the worker's process."""

    factory: str
    kwargs: dict = field(default_factory=dict)

    def build(self) -> Callable[[str, int], dict]:
        module, _, name = self.factory.partition(":")
        return getattr(importlib.import_module(module), name)(**self.kwargs)


def require_ray(local: bool = True):
    """The ``ray`` module, or CONVERT_BACKEND saying how to install the extra. ``local``: a cluster on
    this machine only, whose processes then bind and talk on the loopback address alone (Ray's
    single-machine mode; set before Ray is first imported)."""
    if local and "ray" not in sys.modules:
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
        # Ray runs its workers at nice 15; a bake's workers are its main work, as in one process
        os.environ.setdefault("RAY_worker_niceness", "0")
    try:
        import ray
    except ImportError:
        raise error("CONVERT_BACKEND", "--workers needs Ray, which is not installed: pip install 'nasset-sdk[cluster]'") from None
    return ray


def check_workers(workers, cluster) -> None:
    """Before a bake starts: UsageError for a worker count below 1 or a cluster address without
    --workers; CONVERT_BACKEND when Ray is missing or nothing listens at the cluster's address."""
    if workers is None:
        if cluster:
            raise UsageError("--cluster needs --workers N")
        return
    if int(workers) < 1:
        raise UsageError(f"--workers must be >= 1, got {workers}")
    require_ray(local=not cluster)
    if cluster:
        probe_address(cluster)


def probe_address(address: str, timeout: float = 5.0) -> None:
    """CONVERT_BACKEND at once when nothing listens at ``address`` ("[ray://]host:port"); Ray itself
    would retry for a minute before failing. Other forms ("auto") are left to Ray."""
    import socket

    hostport = address.split("://", 1)[-1]
    host, sep, port = hostport.rpartition(":")
    if not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as exc:
        raise error("CONVERT_BACKEND", f"cannot reach the Ray cluster at {address}: {exc.strerror or exc}") from None


def connect(ray, address: str | None) -> bool:
    """Join the cluster at ``address`` or start a local one; True when this call started Ray (and must stop it)."""
    if ray.is_initialized():
        return False
    opts = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
    # actors run in fresh processes: they must import the project as the driver does
    runtime_env = {"env_vars": {"PYTHONPATH": os.pathsep.join(p for p in (str(Path.cwd()), os.environ.get("PYTHONPATH", "")) if p)}}
    if address:
        probe_address(address)
    try:
        if address:
            ray.init(address=address, runtime_env=runtime_env, **opts)
        else:
            ray.init(runtime_env=runtime_env, **opts)
    except (ConnectionError, TimeoutError, RuntimeError, ValueError) as exc:
        raise error("CONVERT_BACKEND", f"cannot reach the Ray cluster at {address or 'local'}: "
                    f"{str(exc).strip().splitlines()[0][:200] if str(exc).strip() else type(exc).__name__}") from None
    return True


def _worker_class(ray):
    # a dead worker is restarted (it rebuilds its scene) and the job it held is run again there
    @ray.remote(num_cpus=1, max_restarts=MAX_ATTEMPTS, max_task_retries=-1)
    class ViewWorker:
        """One worker: the scene loaded once, then jobs (views, sampler shards) on demand."""

        def __init__(self, source: ViewSource, threads: int) -> None:
            if threads:
                os.environ["OMP_NUM_THREADS"] = str(threads)
            self.pid, self.node = os.getpid(), ray.get_runtime_context().get_node_id()
            self.render_one, self.failed = None, None
            try:
                self.render_one = source.build()
            except Exception as exc:  # noqa: BLE001 - e.g. the renderer missing on this node: the first job raises it
                self.failed = exc

        def render(self, *job):
            if self.failed is not None:  # the driver re-raises it: the typed error of one process, not a dead worker
                raise self.failed
            t = time.perf_counter()
            out = self.render_one(*job)
            return out, {"pid": self.pid, "node": self.node, "seconds": time.perf_counter() - t}

        def close(self) -> None:
            close = getattr(self.render_one, "close", None)  # e.g. the Cycles rig's temporary folder
            if close is not None:
                close()

    return ViewWorker


class WorkerPool:
    """``workers`` Ray actors, each holding what ``source`` builds, kept between batches of jobs.

    A context manager: entering joins the cluster at ``address`` (default: starts a local one) and
    starts the actors; leaving closes and kills them (and stops a Ray this pool started). ``summary``:
    per worker process ``{pid: {"node", "jobs", "seconds"}}`` over every batch run."""

    def __init__(self, source: ViewSource, *, workers: int, address: str | None, say: Callable[..., None],
                 threads: int = 1) -> None:
        self.source, self.workers, self.address, self.say, self.threads = source, int(workers), address, say, threads
        self.summary: dict = {}
        self.actors: list = []
        self.alive: list[bool] = []  # False once Ray gave up restarting a worker
        self.ray = None
        self._started = False

    def __enter__(self) -> WorkerPool:
        self.ray = require_ray(local=not self.address)
        self._started = connect(self.ray, self.address)
        Worker = _worker_class(self.ray)
        self.actors = [Worker.remote(self.source, self.threads) for _ in range(self.workers)]
        self.alive = [True] * len(self.actors)
        return self

    def __exit__(self, *exc) -> None:
        ray = self.ray
        try:
            ray.get([a.close.remote() for a, ok in zip(self.actors, self.alive, strict=True) if ok], timeout=30)
        except Exception:  # noqa: BLE001 - cleanup of workers being torn down; their results are saved or not
            pass
        for a in self.actors:
            ray.kill(a, no_restart=True)
        if self._started:
            ray.shutdown()

    def run(self, todo: list[tuple], on_result: Callable[[tuple, object], None], on_started=None) -> None:
        """Run every job of ``todo`` (the arguments of the source's function) and hand each result to
        ``on_result(job, out)`` in the driver, in the order they finish. A job whose worker died is run
        again (by the restarted worker or another); CONVERT_DATASET once workers were lost for good
        ``MAX_ATTEMPTS`` times on one job or none is left. ``on_started(actors)``: called once every
        worker holds its first job (tests kill one then)."""
        ray, actors, alive = self.ray, self.actors, self.alive
        attempts: dict = {}  # job -> workers that were lost for good while holding it
        queue = list(todo)
        running: dict = {}  # object ref -> (actor index, job)

        def hand_out(k: int) -> None:
            if queue and alive[k]:
                job = queue.pop(0)
                running[actors[k].render.remote(*job)] = (k, job)

        for k in range(len(actors)):
            hand_out(k)
        if on_started is not None:
            on_started(actors)
        while running:
            done, _ = ray.wait(list(running), num_returns=1)
            ref = done[0]
            k, job = running.pop(ref)
            try:
                out, info = ray.get(ref)
            except ray.exceptions.RayActorError:  # the worker died more often than Ray restarts it
                alive[k] = False
                attempts[job] = attempts.get(job, 0) + 1
                if attempts[job] >= MAX_ATTEMPTS or not any(alive):
                    raise error("CONVERT_DATASET", f"job {job} could not be run: the workers died "
                                f"({attempts[job]} lost for good); the results saved so far are kept") from None
                self.say(f"worker lost for good while running job {job}; handing it to another")
                queue.insert(0, job)
                if not running:  # every other worker is idle: give it to the first live one
                    hand_out(alive.index(True))
                continue
            except ray.exceptions.RayTaskError as exc:  # the job itself raised: the same error as in one process
                cause = exc.cause if getattr(exc, "cause", None) is not None else exc
                raise cause from None
            on_result(job, out)
            w = self.summary.setdefault(info["pid"], {"node": info["node"], "jobs": 0, "seconds": 0.0})
            w["jobs"] += 1
            w["seconds"] += info["seconds"]
            hand_out(k)


def render_views_on_cluster(store, todo: list[tuple[str, int]], source: ViewSource, *, workers: int, address: str | None,
                            bar, say: Callable[..., None], threads: int = 1, on_started=None) -> dict:
    """Render ``todo`` views on ``workers`` actors and save each into ``store`` as it arrives.

    ``bar``: a progress bar updated per saved view; ``on_started(actors)``: called once every worker
    holds its first view (tests kill one then). Returns a per-worker summary ``{pid: {"jobs": n, "seconds": s}}``."""

    def save(job, out) -> None:
        store.save(*job, out)
        bar.update(1)

    with WorkerPool(source, workers=workers, address=address, say=say, threads=threads) as pool:
        pool.run(todo, save, on_started=on_started)
    return pool.summary
