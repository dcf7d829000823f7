"""The authoring loop's wall time: what a scene author waits for after saving a scene.

Two commands, each run as a subprocess the way an author types it (the interpreter, the
imports, planning, the jobs in their isolated workers, the run folder, report.html and the
history record), wall clock from start to exit, the median of ``REPEATS``:

1. ``physval run SMALL_SCENE --engines mini``: one small scene (``SMALL_SCENE``, one sphere
   in flight) in one engine. Target ``SMALL_TARGET_S``.
2. ``physval run PROJECTILE``: the same scene in its six engines (mini, MuJoCo, MuJoCo RK4,
   PyBullet, Rapier, Drake; an engine not installed here is a ``not_installed`` row).
   Target ``PROJECTILE_TARGET_S``.

A run of named scenes skips their sweeps (``--sweeps`` defaults to off for them); each
command runs in a scratch folder (no ``baselines/default.csv`` is picked up) with ``--out``
inside it, so the history database is the default one next to it, as for an author.

``--tree PATH`` measures another checkout with the same interpreter (``PYTHONPATH=PATH``,
its own scene files): ``--tree /work/main`` gives the numbers before a change.

Run: ``PYTHONPATH=. python benchmarks/authoring_loop.py [--tree PATH] [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
"""This checkout (the default ``--tree``)."""

SMALL_SCENE = Path("scenarios") / "formulas" / "projectile.yaml"
"""The small scene: one sphere thrown in uniform gravity, 1,500 steps, nothing to touch."""

PROJECTILE = SMALL_SCENE
"""The projectile, in the six engines its file names (``engines:``)."""

SMALL_TARGET_S = 1.5
"""s, issue 37's target for one small scene in mini, wall clock."""

PROJECTILE_TARGET_S = 3.0
"""s, issue 37's target for the projectile in its six engines, wall clock."""

REPEATS = 5
"""Runs of each command; the median is reported (a shared machine's slow seconds are
outliers, not the loop's cost)."""


def wall_time(tree: Path, arguments: list[str]) -> float:
    """s of wall clock of ``physval run ARGUMENTS --out SCRATCH/run`` in a subprocess, in a
    scratch folder; raises when the command does not exit 0 or 1 (a run that failed to run
    measures nothing)."""
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    with tempfile.TemporaryDirectory(prefix="physval-loop-") as scratch:
        command = [sys.executable, "-m", "validation.entry", "run", *arguments]
        command += ["--out", str(Path(scratch) / "run")]
        start = time.perf_counter()
        done = subprocess.run(
            command, cwd=scratch, env=environment, capture_output=True, text=True, check=False
        )
        seconds = time.perf_counter() - start
    if done.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(command)} exited {done.returncode}: {done.stderr.strip()}")
    return seconds


def median_time(tree: Path, arguments: list[str], repeats: int) -> float:
    """The median of ``repeats`` wall times of the command (``wall_time``)."""
    return statistics.median(wall_time(tree, arguments) for _ in range(repeats))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=HERE, help="checkout to measure")
    parser.add_argument("--repeats", type=int, default=REPEATS, help="runs of each command")
    args = parser.parse_args(argv)
    tree = args.tree.resolve()
    cases = [
        (
            f"physval run {SMALL_SCENE} --engines mini",
            [str(tree / SMALL_SCENE), "--engines", "mini"],
            SMALL_TARGET_S,
        ),
        (f"physval run {PROJECTILE} (six engines)", [str(tree / PROJECTILE)], PROJECTILE_TARGET_S),
    ]
    print(f"tree {tree}; median of {args.repeats} subprocess wall times")
    met = True
    for name, arguments, target in cases:
        seconds = median_time(tree, arguments, args.repeats)
        verdict = "meets" if seconds <= target else "MISSES"
        met &= seconds <= target
        print(f"{name:<62} {seconds:6.2f} s  (target <= {target:g} s: {verdict})")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
