"""Ctrl-C at any moment: a stop signal sent to a ``physval run``'s whole process group after
each of a series of delays, and what the run printed.

A terminal's Ctrl-C reaches every process of the foreground group (the run, multiprocessing's
fork server and resource tracker, the workers, anything an import starts on the side), so a
signal at an unlucky moment used to end in a second process's traceback. The tests stop a run
at chosen moments (``tests/test_jobs.py``, ``tests/test_stop_signals.py``); this sweeps the
moments from the first import to the published report, to find the ones nobody chose:

    python benchmarks/stop_moments.py [--from 0.1] [--to 8] [--step 0.2] [--signal INT]
                                      [--load N]

``--load N`` runs N busy processes meanwhile (a loaded CI runner stretches every phase, so
moments that last microseconds on an idle machine last long enough to be hit). Each delay is a
line: the exit code, the lines printed on stderr that are not progress lines, and ``OK`` when
the run either finished (exit 0 or 1) or printed exactly one line and exited 128 + the signal,
with no traceback; else ``BAD`` and the stderr. Exit code 1 if any delay was ``BAD``.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.terminal import message_lines

SCENES = [
    BUNDLED_SCENARIOS / "formulas" / "projectile.yaml",
    BUNDLED_SCENARIOS / "rotation" / "torque_free_symmetric_top.yaml",
    BUNDLED_SCENARIOS / "contact" / "box_drop_flat.yaml",
    BUNDLED_SCENARIOS / "rotation" / "dzhanibekov_box.yaml",
]
"""Four short scenes in all three engines: about 8 s of work, every phase of a run in it."""

RUN_TIMEOUT_S = 300
"""s a stopped (or finished) run may take to end before the sweep gives up on it."""

FINISHED = (0, 1)
"""Exit codes of a run the signal came too late for (it had finished)."""


def _busy(stop) -> None:
    while not stop.is_set():
        sum(range(10_000))


def _physval() -> str:
    return str(Path(sys.executable).with_name("physval"))


def stop_after(delay_s: float, signum: int, folder: Path) -> tuple[bool, str]:
    """Start a run in ``folder``, send ``signum`` to its group after ``delay_s``: (OK?, line)."""
    command = [_physval(), "run", *map(str, SCENES), "--engines", "mini,mujoco,pybullet"]
    command += ["--out", str(folder / "out"), "--jobs", "2", "--baseline", "none"]
    command += ["--history", "none"]
    run = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=folder,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )
    time.sleep(delay_s)
    with contextlib.suppress(ProcessLookupError):  # it finished already
        os.killpg(run.pid, signum)
    _, stderr = run.communicate(timeout=RUN_TIMEOUT_S)
    lines = message_lines(stderr)
    stopped = run.returncode == 128 + signum and len(lines) == 1
    ok = "Traceback" not in stderr and (run.returncode in FINISHED or stopped)
    line = f"{delay_s:6.2f} s  exit {run.returncode:3d}  {len(lines)} line(s)  "
    return ok, line + ("OK" if ok else "BAD\n" + stderr)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="start", type=float, default=0.1)
    parser.add_argument("--to", dest="end", type=float, default=8.0)
    parser.add_argument("--step", type=float, default=0.2)
    parser.add_argument("--signal", default="INT", choices=["INT", "TERM", "HUP"])
    parser.add_argument("--load", type=int, default=0, help="busy processes meanwhile")
    arguments = parser.parse_args()
    signum = int(signal.Signals["SIG" + arguments.signal])
    stop = multiprocessing.Event()
    load = [multiprocessing.Process(target=_busy, args=(stop,)) for _ in range(arguments.load)]
    for process in load:
        process.start()
    bad = 0
    try:
        count = round((arguments.end - arguments.start) / arguments.step) + 1
        for index in range(count):
            delay_s = arguments.start + index * arguments.step
            folder = Path(tempfile.mkdtemp(prefix="physval-stop-"))
            try:
                ok, line = stop_after(delay_s, signum, folder)
            finally:
                shutil.rmtree(folder, ignore_errors=True)
            bad += not ok
            print(line, flush=True)
    finally:
        stop.set()
        for process in load:
            process.join()
    print(f"{bad} BAD of {count} moments (SIG{arguments.signal}, load {arguments.load})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
