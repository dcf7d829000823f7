"""The signals a terminal or a CI runner sends to stop a command, all handled like Ctrl-C.

A CI runner cancelling or timing out a job sends SIGTERM (GitHub Actions, GitLab, systemd,
``timeout``), a closed terminal SIGHUP, Ctrl-C SIGINT. Each stops physval the same way: every
worker (process pool or cluster) is stopped, finished jobs stay in the run's journal, one
line is printed and the exit code is 128 + the signal's number (the shell's convention:
130, 143, 129). ``install`` makes SIGTERM and SIGHUP raise ``Stopped`` (a
``KeyboardInterrupt``, so every path that ends a Ctrl-C ends them too); worker processes
ignore all three (``ignore_in_worker``), since the main process stops them.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from validation.contract import INTERRUPTED_MESSAGE

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a command cleanly (SIGINT raises KeyboardInterrupt by itself)."""

SIGNAL_EXIT_BASE = 128
"""The exit code of a command stopped by signal N is 128 + N (130 for SIGINT, 143 SIGTERM)."""


class Stopped(KeyboardInterrupt):
    """The command was stopped by a signal other than SIGINT (``signum``)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class Interrupted(Exception):  # noqa: N818 (a user action, not an error)
    """Ctrl-C, or a stop signal (``signum``), that ended a run of jobs: every worker has been
    stopped (``validation.jobs.executor`` raises it). An ``Exception``, so that each layer's
    clean-up runs on the way out; the commands turn it into the one line."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise_stopped(signum: int, _frame) -> None:
    raise Stopped(signum)


def install() -> None:
    """SIGTERM and SIGHUP raise ``Stopped`` in the main thread from now on."""
    for signum in STOP_SIGNALS:
        if signum != signal.SIGINT:
            signal.signal(signum, _raise_stopped)


def ignore_in_worker() -> None:
    """A worker process ignores every stop signal: the main process stops its workers."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold every stop signal until the block ends, then stop as it would have: for the
    moments a stop must not split, such as a process pool spawning its workers (a worker
    started but not yet registered could not be stopped, and printed a traceback once this
    process had gone). Python runs signal handlers in the main thread whichever thread the
    signal reaches, so the held signal is recorded by a handler, not blocked by a mask.
    Outside the main thread (a job on a Dask worker's thread) it holds nothing: only the main
    thread can set handlers, and it alone receives the signals."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {
        signum: signal.signal(signum, lambda number, _frame: held.append(number))
        for signum in STOP_SIGNALS
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if held:
        raise KeyboardInterrupt if held[0] == signal.SIGINT else Stopped(held[0])


def signal_number(stop: BaseException) -> int:
    """The signal that stopped the command: ``Stopped``'s, else SIGINT (Ctrl-C)."""
    return int(getattr(stop, "signum", signal.SIGINT))


def stop_message(signum: int) -> str:
    """The one line a stopped command prints."""
    if signum == signal.SIGINT:
        return INTERRUPTED_MESSAGE
    return f"stopped by {signal.Signals(signum).name}: " + INTERRUPTED_MESSAGE.split(": ", 1)[1]


def exit_code(signum: int) -> int:
    return SIGNAL_EXIT_BASE + signum
