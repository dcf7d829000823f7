"""Where a command's wall time went: ``physval run --timings``.

A ``PhaseClock`` adds up the wall seconds of named phases in the order they first ran
(``PHASES``); the jobs phase also has each job kind's worker seconds (``run`` and
``sweep``: the time the workers spent in them, summed over the workers, so on 2 workers it
can be twice the phase's wall time). It measures, it decides nothing: no result depends on
it.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

PHASES = ("imports", "planning", "jobs", "write", "report", "publish", "history")
"""The phases of ``physval run``, in the order they run (``docs/commands.md``)."""


@dataclass
class PhaseClock:
    """Wall seconds per phase, and worker seconds per job kind.

    Attributes:
        seconds: phase -> s of wall time, in the order the phases first ran.
        worker_seconds: job kind -> s the workers spent in jobs of that kind.
        worker_jobs: job kind -> how many jobs of that kind ran.
        shown: whether the command prints ``text()`` at its end (``--timings``).
        began: ``time.perf_counter()`` when the clock was made.
    """

    shown: bool = False
    seconds: dict[str, float] = field(default_factory=dict)
    worker_seconds: dict[str, float] = field(default_factory=dict)
    worker_jobs: dict[str, int] = field(default_factory=dict)
    began: float = field(default_factory=time.perf_counter)

    @contextlib.contextmanager
    def phase(self, name: str) -> Iterator[None]:
        """Time the block as (part of) phase ``name``, also when it raises."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start

    def job(self, kind: str, seconds: float) -> None:
        """One finished job of ``kind`` that took ``seconds`` in its worker."""
        self.worker_seconds[kind] = self.worker_seconds.get(kind, 0.0) + seconds
        self.worker_jobs[kind] = self.worker_jobs.get(kind, 0) + 1

    def text(self) -> str:
        """``timings: planning 0.4 s, jobs 61.2 s (run: 121 jobs, 98.0 s; sweep: ...), ...``."""
        parts = []
        for name, seconds in self.seconds.items():
            part = f"{name} {seconds:.2f} s"
            if name == "jobs" and self.worker_seconds:
                kinds = "; ".join(
                    f"{kind}: {self.worker_jobs[kind]} jobs, {total:.1f} s"
                    for kind, total in self.worker_seconds.items()
                )
                part += f" ({kinds} of worker time)"
            parts.append(part)
        total = time.perf_counter() - self.began
        return f"timings: {', '.join(parts)}; total {total:.2f} s"
