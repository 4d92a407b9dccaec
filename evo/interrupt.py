"""Clean shutdown on SIGINT and SIGTERM, in the main process and in evaluation workers.

**Main process.** :func:`handle_signals` turns SIGINT and SIGTERM into an
:class:`Interrupted` exception raised where the main thread is (waiting for a result,
or training, with the serial executor), so ``finally`` blocks run: the executor
stops its workers, the recordings are closed, the lock is released. Code that must
not be cut in two (appending a result to the state and saving it) runs inside
:func:`critical`: a signal that arrives there is held back and raised when the block
ends, so the saved state is always one the run can resume from. A critical block is
meant to be short: one still running :data:`HOLD_S` seconds after the signal came is
cut there (a timer raises the interrupt anyway), so a run stops within seconds
wherever it is, even in long work wrongly inside a critical block (every state file
is written atomically, so a cut block still leaves a state the run resumes from). A
second signal while shutting down is ignored.

**Workers.** :func:`worker_init` makes an evaluation worker (a process of the local
pool) end with its parent: on Linux the kernel sends it SIGTERM when the parent dies
(``PR_SET_PDEATHSIG``), and everywhere a watchdog thread notices a new parent
process. SIGINT is ignored there (Ctrl-C reaches the whole process group; the main
process decides). SIGTERM inside an evaluation raises :class:`Interrupted` (held back
in a :func:`critical` block, as in the main process), so the evaluation's recorder
closes its files, and the worker then exits (:func:`guarded`); SIGTERM between
evaluations exits at once. A worker whose parent died and that is still alive
:data:`ORPHAN_GRACE_S` seconds later (its cleanup waits in C code, where no signal
handler runs) is ended (with its threads' tracebacks on stderr): no worker outlives its parent.
"""

from __future__ import annotations

import ctypes
import faulthandler
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any, TypeVar

T = TypeVar("T")

EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}
"""Exit code of a run ended by each signal (128 + the signal number)."""

HOLD_S = 3.0
"""Longest a critical block holds back a signal, seconds."""

ORPHAN_GRACE_S = 10.0
"""Longest a worker whose parent died spends closing its files before it exits anyway."""


class Interrupted(BaseException):  # noqa: N818 - like KeyboardInterrupt, not an error
    """SIGINT or SIGTERM arrived; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return EXIT_CODES.get(signal.Signals(self.signum), 128 + self.signum)


_held: list[int] = []  # signals that arrived inside a critical block
_depth = 0  # nesting of critical blocks
_raised: int | None = None  # the signal raised as Interrupted: ignore the next ones


def _interrupt(signum: int) -> Interrupted:
    global _raised
    _raised = signum
    return Interrupted(signum)


def raised() -> Interrupted | None:
    """A fresh :class:`Interrupted` when a signal has already been raised as one in this
    process, else None.

    Library code that cleans up while ``Interrupted`` unwinds it may fail and raise an
    ordinary exception in its place; code that records ordinary exceptions as results
    (a failed evaluation) asks this first and raises the interrupt instead.
    """
    return None if _raised is None else Interrupted(_raised)


def _hold(signum: int) -> None:
    """Hold ``signum`` back until the critical block ends, or :data:`HOLD_S` at most."""
    if not _held:
        signal.setitimer(signal.ITIMER_REAL, HOLD_S)
    _held.append(signum)


def _on_alarm(signum: int, frame: FrameType | None) -> None:
    """A critical block outlived :data:`HOLD_S` with a signal held: raise it now."""
    if _held and _raised is None:
        raise _interrupt(_held[0])


def _on_signal(signum: int, frame: FrameType | None) -> None:
    if _raised is not None:
        return
    if _depth:
        _hold(signum)
        return
    raise _interrupt(signum)


@contextmanager
def handle_signals() -> Iterator[None]:
    """Raise :class:`Interrupted` on SIGINT and SIGTERM inside the block (main thread)."""
    global _raised
    before = {s: signal.signal(s, _on_signal) for s in EXIT_CODES}
    before[signal.SIGALRM] = signal.signal(signal.SIGALRM, _on_alarm)
    _raised = None
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for s, handler in before.items():
            signal.signal(s, handler)
        _held.clear()
        _raised = None


@contextmanager
def critical() -> Iterator[None]:
    """Hold back SIGINT and SIGTERM until the block ends (then raise the first one)."""
    global _depth
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    if not _depth and _held:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signum = _held[0]
        _held.clear()
        if _raised is None:
            raise _interrupt(signum)


# ---------------------------------------------------------------- workers

_busy = False  # this worker is inside an evaluation


def _worker_signal(signum: int, frame: FrameType | None) -> None:
    if _busy and _depth:
        _hold(signum)
        return
    if _busy:
        raise _interrupt(signum)
    os._exit(EXIT_CODES.get(signal.Signals(signum), 128 + signum))


def worker_init(parent: int, grace_s: float = ORPHAN_GRACE_S) -> None:
    """Tie this worker process to its parent, PID ``parent`` (see the module docstring);
    orphaned, it spends at most ``grace_s`` seconds closing its files."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_signal)
    signal.signal(signal.SIGALRM, _on_alarm)
    try:  # Linux: SIGTERM from the kernel the moment the parent dies
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (AttributeError, OSError):
        pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(1.0)
        # A C-level timer (it needs no GIL) ends the process should the cleanup the
        # SIGTERM starts wait in C code, where no Python signal handler runs.
        faulthandler.dump_traceback_later(grace_s, exit=True)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def guarded(fn: Callable[..., T], *args: Any) -> T:
    """Run ``fn(*args)`` in a worker; when SIGTERM interrupts it, let its ``finally``
    blocks and context managers run (recordings are closed), then exit the worker."""
    global _busy
    _busy = True
    try:
        return fn(*args)
    except Interrupted as stop:
        os._exit(stop.exit_code)
    finally:
        _busy = False
