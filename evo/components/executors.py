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

**Lost work is run again.** The pool and Ray tell a lost evaluation (its worker process
killed by a signal or the OOM killer, its Ray node or worker gone, its result lost from
the object store) from a failed one (an exception in the evaluation, unstable physics, a
timeout: ``evaluate`` returns those as outcomes). A lost evaluation is submitted again,
with the same arguments and so the same seed, up to ``retries`` times, each time with
one line on stderr; after that its future raises :class:`EvaluationLost`, which the
run records as a ``failed`` row. The resubmission happens behind the future the caller
holds, so the evolution loop sees one evaluation in flight throughout (and a resumed run
evaluates it again like any robot in flight). When a pool worker dies, Python's
``ProcessPoolExecutor`` fails every evaluation in flight on the pool: each worker
reports which evaluation it starts, so only the one whose worker died spends a retry,
the others are resubmitted for free.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

T = TypeVar("T")

DEFAULT_RETRIES = 3
"""Resubmissions of a lost evaluation (Ray's own default ``max_retries`` for tasks): a
preempted node or one OOM kill costs nothing, a robot that kills its worker every time
costs four attempts before it is recorded ``failed``."""


def set_threads(threads: int) -> None:
    """Limit this process to ``threads`` compute threads (torch, BLAS, OpenMP)."""
    import torch

    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(threads)
    torch.set_num_threads(threads)


class EvalExecutor(Protocol):
    """What the evolution loop needs from an executor."""

    workers: int

    def submit(self, fn: Callable[..., T], /, *args: Any) -> Future[T]: ...

    def restart(self) -> None: ...

    def shutdown(self) -> None: ...

    def terminate(self) -> None: ...


@dataclass
class SerialExecutor(Executor):
    """Runs every evaluation in this process when it is submitted.

    No retries: an evaluation that kills its process ends the run (``resume=``
    continues it).

    Attributes:
        threads: Compute threads of this process.
    """

    threads: int = 1
    workers: int = field(default=1, init=False)  # one at a time; no config key

    def __post_init__(self) -> None:
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
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


# ---------------------------------------------------------------- lost work, run again


class EvaluationLost(RuntimeError):
    """An evaluation lost on every attempt (its worker or node died each time)."""


@dataclass(frozen=True, slots=True)
class Loss:
    """Why an attempt was lost, and whether it spends one of the evaluation's retries
    (not when another evaluation's worker broke the pool under it)."""

    cause: str
    counts: bool = True


def _label(fn: Callable[..., Any], args: tuple[Any, ...]) -> str:
    """``robot-ab12 (birth 3)`` for an evaluation, else the function's name."""
    first = args[0] if args else None
    name, birth = getattr(first, "name", None), getattr(first, "birth", None)
    return f"{name} (birth {birth})" if name is not None else getattr(fn, "__name__", "task")


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


@dataclass
class Resubmitter:
    """Runs ``fn(*args)`` through ``launch`` and launches it again while ``lost`` says an
    attempt was lost, at most ``retries`` times; the caller holds one future throughout.

    Attributes:
        launch: Starts one attempt; returns its future and a token naming the attempt.
        lost: The :class:`Loss` of a finished attempt (its future, token and error), or
            None when the error is the evaluation's own (or there is none).
        retries: Resubmissions allowed per evaluation.
        log: Where the one line per resubmission goes.
    """

    launch: Callable[[Callable[..., Any], tuple[Any, ...]], tuple[Future[Any], int]]
    lost: Callable[[Future[Any], int, BaseException], Loss | None]
    retries: int
    log: Callable[[str], None] = _stderr
    closing: bool = False

    def submit(self, fn: Callable[..., T], args: tuple[Any, ...]) -> Future[T]:
        self.closing = False
        outer: Future[T] = Future()
        self._attempt(outer, fn, args, 0)
        return outer

    def _attempt(self, outer: Future[Any], fn: Callable[..., Any], args: tuple[Any, ...],
                 spent: int) -> None:
        try:
            inner, token = self.launch(fn, args)
        except Exception as err:  # noqa: BLE001 - handed to the caller through the future
            outer.set_exception(err)
            return
        inner.add_done_callback(lambda done: self._done(done, token, outer, fn, args, spent))

    def _done(self, inner: Future[Any], token: int, outer: Future[Any],
              fn: Callable[..., Any], args: tuple[Any, ...], spent: int) -> None:
        if inner.cancelled():
            outer.cancel()
            return
        error = inner.exception()
        loss = self.lost(inner, token, error) if error is not None else None
        if error is None:
            outer.set_result(inner.result())
        elif loss is None or self.closing:
            outer.set_exception(error)
        elif spent < self.retries or not loss.counts:
            spent += loss.counts
            note = f"retry {spent} of {self.retries}" if loss.counts else "no retry spent"
            self.log(f"evaluation of {_label(fn, args)} lost ({loss.cause}); submitted again "
                     f"with the same seed ({note})")
            self._attempt(outer, fn, args, spent)
        else:
            outer.set_exception(EvaluationLost(
                f"lost {spent + 1} time(s), the last because {loss.cause} "
                f"(executor.retries = {self.retries})"))


# ---------------------------------------------------------------- the local pool


def _init_worker(threads: int, parent: int, started: Any) -> None:
    from evo.interrupt import worker_init

    set_threads(threads)
    worker_init(parent)
    global _started
    _started = started


_started: Any = None  # in a pool worker: where it says which attempt it starts


def _run_attempt(token: int, fn: Callable[..., T], *args: Any) -> T:
    """Say (to the parent) that this worker runs attempt ``token``, then run it."""
    from evo.interrupt import guarded

    if _started is not None:
        _started.put((token, os.getpid()))
    return guarded(fn, *args)


def _dead_workers(pool: ProcessPoolExecutor | None, wait_s: float = 2.0) -> dict[int, int]:
    """The pids and exit codes of ``pool``'s dead workers. A worker's pipes close a moment
    before the kernel lets its exit status be read, so wait until one shows."""
    processes = dict(getattr(pool, "_processes", None) or {})
    deadline = time.monotonic() + wait_s
    while True:
        dead = {pid: p.exitcode for pid, p in processes.items() if p.exitcode is not None}
        if dead or time.monotonic() > deadline:
            return dead
        time.sleep(0.005)


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        return f"its worker process was killed by {signal.Signals(-exitcode).name}"
    return f"its worker process died (exit code {exitcode})"


@dataclass
class LocalExecutor:
    """A process pool (spawned workers, so no forked torch or MuJoCo state).

    Attributes:
        workers: Worker processes (0 = one per core).
        threads: Compute threads per worker (workers x threads should not exceed the
            cores).
        retries: Resubmissions, with the same seed, of an evaluation whose worker
            process died (e.g. OOM-killed); after them, a ``failed`` row (module
            docstring).
    """

    workers: int = 0
    threads: int = 1
    retries: int = DEFAULT_RETRIES

    def __post_init__(self) -> None:
        if self.workers < 0 or self.threads < 1 or self.retries < 0:
            raise ValueError(f"need workers >= 0, threads >= 1 and retries >= 0, got "
                             f"{self.workers}, {self.threads}, {self.retries}")
        self.workers = self.workers or os.cpu_count() or 1
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.RLock()
        self._started = multiprocessing.get_context("spawn").SimpleQueue()
        self._tokens = itertools.count()
        self._where: dict[int, int] = {}  # attempt token -> pid of the worker running it
        self._ran: set[int] = set()  # pids of workers that started an attempt
        self._pool_of: dict[int, ProcessPoolExecutor] = {}  # attempt token -> its pool
        self._resubmit = Resubmitter(self._launch, self._lost, self.retries)

    def _get(self) -> ProcessPoolExecutor:
        """The pool; a new one when there is none or the current one is broken."""
        with self._lock:
            if self._pool is not None and getattr(self._pool, "_broken", False):
                self._pool = None  # it shuts itself down
            if self._pool is None:
                self._pool = ProcessPoolExecutor(
                    self.workers,
                    mp_context=multiprocessing.get_context("spawn"),
                    initializer=_init_worker,
                    initargs=(self.threads, os.getpid(), self._started),
                )
                # Launch every worker at the first submit, before the pool's manager
                # thread starts watching them: a worker spawned later (the default for
                # spawned pools) is not watched, so its death would go unnoticed until
                # another evaluation returns.
                self._pool._safe_to_dynamically_spawn_children = False  # type: ignore[attr-defined]
            return self._pool

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        return self._resubmit.submit(fn, args)

    def _launch(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[Future[Any], int]:
        with self._lock:  # a resubmission racing terminate() starts no pool after it
            if self._resubmit.closing:
                raise RuntimeError("the executor was stopped")
            token, pool = next(self._tokens), self._get()
            self._pool_of[token] = pool
            return pool.submit(_run_attempt, token, fn, *args), token

    def _lost(self, future: Future[Any], token: int, error: BaseException) -> Loss | None:
        """A broken pool lost the attempt; it counts when its own worker died (or when
        no worker can be blamed)."""
        with self._lock:
            pool = self._pool_of.pop(token, None)
            while not self._started.empty():
                started, pid = self._started.get()
                self._where[started] = pid
                self._ran.add(pid)
            pid = self._where.pop(token, None)
        if not isinstance(error, BrokenProcessPool):
            return None
        dead = _dead_workers(pool)
        if pid in dead:
            return Loss(_death(dead[pid]))
        # Another attempt's worker died (the pool broke under this one): no retry spent.
        blamed = bool(set(dead) & self._ran)
        return Loss("a worker process of the pool died", counts=not blamed)

    def restart(self) -> None:
        """Replace a broken pool (a worker died) with a fresh one; a healthy pool stays."""
        with self._lock:
            if self._pool is not None and getattr(self._pool, "_broken", True):
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = None

    def shutdown(self) -> None:
        self._resubmit.closing = True
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def terminate(self, grace_s: float = 5.0) -> None:
        """Stop every worker now: SIGTERM (an evaluation closes its files and exits),
        then SIGKILL for any still alive after ``grace_s`` seconds."""
        self._resubmit.closing = True
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is None:
            return
        # The pool keeps its worker processes in ``_processes`` (CPython 3.9+).
        processes = list((getattr(pool, "_processes", None) or {}).values())
        for process in processes:
            process.terminate()
        deadline = time.monotonic() + grace_s
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
                process.join()
        pool.shutdown(wait=False, cancel_futures=True)


# ---------------------------------------------------------------- Ray


@dataclass
class RayExecutor:
    """Ray tasks; connects to ``address`` (None starts a local Ray instance).

    Attributes:
        workers: Evaluations in flight at once (0 = the cluster's CPUs / threads).
        threads: CPUs (and compute threads) per evaluation.
        address: Ray cluster address (e.g. ``"auto"``), or None to start a local
            instance.
        retries: Resubmissions, with the same seed, of an evaluation whose Ray worker or
            node was lost; after them, a ``failed`` row.
    """

    workers: int = 0
    threads: int = 1
    address: str | None = None
    retries: int = DEFAULT_RETRIES

    def __post_init__(self) -> None:
        import ray

        if self.workers < 0 or self.threads < 1 or self.retries < 0:
            raise ValueError(f"need workers >= 0, threads >= 1 and retries >= 0, got "
                             f"{self.workers}, {self.threads}, {self.retries}")
        if not ray.is_initialized():
            ray.init(
                address=self.address,
                include_dashboard=False,
                log_to_driver=False,
                configure_logging=False,
            )
        cpus = int(ray.cluster_resources().get("CPU", 1))  # type: ignore[no-untyped-call]
        self.workers = self.workers or max(1, cpus // self.threads)
        # Ray retries nothing itself: the resubmissions are ours, so each is logged.
        self._remote = ray.remote(num_cpus=self.threads, max_retries=0)(_ray_call)
        self._refs: list[Any] = []
        self._resubmit = Resubmitter(self._launch, _ray_loss, self.retries)

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        return self._resubmit.submit(fn, args)

    def _launch(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[Future[Any], int]:
        ref = self._remote.remote(self.threads, fn, *args)
        self._refs = [r for r in self._refs if not _ray_done(r)] + [ref]
        future: Future[Any] = ref.future()
        return future, 0

    def restart(self) -> None:
        """Ray replaces dead workers itself."""

    def shutdown(self) -> None:
        import ray

        self._resubmit.closing = True
        ray.shutdown()

    def terminate(self) -> None:
        """Cancel every task in flight (its worker is killed), then disconnect."""
        import ray

        self._resubmit.closing = True
        for ref in self._refs:
            ray.cancel(ref, force=True)
        self._refs = []
        ray.shutdown()


def _ray_loss(future: Future[Any], token: int, error: BaseException) -> Loss | None:
    """Ray's own failures (a worker or node lost, an object lost from the store, the
    memory monitor's kill) lose the attempt; an error raised by the task does not."""
    import ray.exceptions as rex

    if isinstance(error, rex.RayTaskError | rex.TaskCancelledError | rex.GetTimeoutError):
        return None
    if isinstance(error, rex.RayError):
        return Loss(f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}")
    return None


def _ray_done(ref: Any) -> bool:
    import ray

    ready, _ = ray.wait([ref], timeout=0)
    return bool(ready)


def _ray_call(threads: int, fn: Callable[..., T], *args: Any) -> T:
    set_threads(threads)
    return fn(*args)
