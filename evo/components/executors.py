"""Executors: where evaluations run (``conf/executor/``).

All three speak ``concurrent.futures``: ``submit(fn, *args)`` returns a ``Future``, so the
evolution loop waits on whichever finishes first, whatever runs it.

* ``SerialExecutor``: in this process, one at a time (debugging, exact reproducibility);
* ``LocalExecutor``: a pool of worker processes on this machine (the default);
* ``RayExecutor``: the same evaluation function as Ray tasks, locally or on a cluster
  (``pip install -e .[ray]``).

Each worker sets torch's and MuJoCo's thread counts so that ``workers x threads`` does
not oversubscribe the cores.

``shutdown`` ends an executor when the work is done; ``terminate`` stops it now (the run
was interrupted): evaluations in flight are stopped, not finished, and no worker
process outlives it (see :mod:`evo.interrupt`).
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

T = TypeVar("T")


def set_threads(threads: int) -> None:
    """Limit this process to ``threads`` compute threads (torch, BLAS, OpenMP)."""
    import torch

    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(threads)
    torch.set_num_threads(threads)


class EvalExecutor(Protocol):
    """What the evolution loop needs from an executor."""

    workers: int

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]: ...

    def restart(self) -> None: ...

    def shutdown(self) -> None: ...

    def terminate(self) -> None: ...


@dataclass
class SerialExecutor(Executor):
    """Runs every evaluation in this process when it is submitted.

    Attributes:
        threads: Compute threads of this process.
    """

    threads: int = 1
    workers: int = 1

    def __post_init__(self) -> None:
        if self.threads < 1 or self.workers != 1:
            raise ValueError(
                f"need threads >= 1 and workers == 1, got {self.threads}, {self.workers}"
            )
        set_threads(self.threads)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        future: Future[T] = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as err:  # noqa: BLE001 - handed to the caller through the future
            future.set_exception(err)
        return future

    def restart(self) -> None:
        """Nothing to restart."""

    def terminate(self) -> None:
        """Nothing runs in the background: an interrupt stops the evaluation itself."""


def _init_worker(threads: int, parent: int) -> None:
    from evo.interrupt import worker_init

    set_threads(threads)
    worker_init(parent)


@dataclass
class LocalExecutor:
    """A process pool (spawned workers, so no forked torch or MuJoCo state).

    Attributes:
        workers: Worker processes (0 = one per core).
        threads: Compute threads per worker.
    """

    workers: int = 0
    threads: int = 1

    def __post_init__(self) -> None:
        if self.workers < 0 or self.threads < 1:
            raise ValueError(
                f"need workers >= 0 and threads >= 1, got {self.workers}, {self.threads}"
            )
        self.workers = self.workers or os.cpu_count() or 1
        self._pool: ProcessPoolExecutor | None = None

    def _get(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                self.workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_worker,
                initargs=(self.threads, os.getpid()),
            )
        return self._pool

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        from evo.interrupt import guarded

        return self._get().submit(guarded, fn, *args)

    def restart(self) -> None:
        """Replace a broken pool (a worker died) with a fresh one; a healthy pool stays.

        Every evaluation in flight when a worker dies fails, and their futures may come
        back one at a time, each followed by a call here: by then the pool may already
        be a fresh one, running newer evaluations that must not be cancelled.
        """
        # ``_broken`` is set by ProcessPoolExecutor once a worker died (assume broken
        # should a future Python drop the attribute).
        if self._pool is not None and getattr(self._pool, "_broken", True):
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

    def shutdown(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def terminate(self, grace_s: float = 10.0) -> None:
        """Stop every worker now: SIGTERM (an evaluation closes its files and exits),
        then SIGKILL for any still alive after ``grace_s`` seconds."""
        if self._pool is None:
            return
        # The pool keeps its worker processes in ``_processes`` (CPython 3.9+).
        processes = list(getattr(self._pool, "_processes", {}).values())
        for process in processes:
            process.terminate()
        deadline = time.monotonic() + grace_s
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
                process.join()
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = None


@dataclass
class RayExecutor:
    """Ray tasks; connects to ``address`` (None starts a local Ray instance).

    Attributes:
        workers: Evaluations in flight at once (0 = the cluster's CPUs / threads).
        threads: CPUs (and compute threads) per evaluation.
        address: Ray cluster address, or None for a local instance.
    """

    workers: int = 0
    threads: int = 1
    address: str | None = None

    def __post_init__(self) -> None:
        import ray

        if not ray.is_initialized():
            ray.init(
                address=self.address,
                include_dashboard=False,
                log_to_driver=False,
                configure_logging=False,
            )
        cpus = int(ray.cluster_resources().get("CPU", 1))  # type: ignore[no-untyped-call]
        self.workers = self.workers or max(1, cpus // self.threads)
        self._remote = ray.remote(num_cpus=self.threads, max_retries=0)(_ray_call)
        self._refs: list[Any] = []

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        ref = self._remote.remote(self.threads, fn, *args)
        self._refs = [r for r in self._refs if not _ray_done(r)] + [ref]
        future: Future[T] = ref.future()
        return future

    def restart(self) -> None:
        """Ray replaces dead workers itself."""

    def shutdown(self) -> None:
        import ray

        ray.shutdown()

    def terminate(self) -> None:
        """Cancel every task in flight (its worker is killed), then disconnect."""
        import ray

        for ref in self._refs:
            ray.cancel(ref, force=True)
        self._refs = []
        ray.shutdown()


def _ray_done(ref: Any) -> bool:
    import ray

    ready, _ = ray.wait([ref], timeout=0)
    return bool(ready)


def _ray_call(threads: int, fn: Callable[..., T], *args: Any) -> T:
    set_threads(threads)
    return fn(*args)
