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
inside it, so the history database is the default one next to it, as for an author. Beside
the wall time, the CPU seconds (user + system) of the command and its worker processes: on a
loaded machine the wall time grows with the other work, the CPU seconds much less.

``--tree PATH`` measures another checkout with the same interpreter (``PYTHONPATH=PATH``,
its own scene files); ``--before PATH`` measures PATH too, the two interleaved run by run (a
slow minute of a shared machine hits both alike): ``--before /work/main`` gives the numbers
before a change.

Run: ``PYTHONPATH=. python benchmarks/authoring_loop.py [--tree PATH] [--before PATH]
[--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import resource
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


def timed(tree: Path, arguments: list[str]) -> tuple[float, float]:
    """(s of wall clock, CPU s) of ``physval run ARGUMENTS --out SCRATCH/run`` in a
    subprocess, in a scratch folder, its workers' CPU included; raises when the command does
    not exit 0 or 1 (a run that failed to run measures nothing)."""
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    with tempfile.TemporaryDirectory(prefix="physval-loop-") as scratch:
        command = [sys.executable, "-m", "validation.entry", "run", *arguments]
        command += ["--out", str(Path(scratch) / "run")]
        before = _cpu_of_children()
        start = time.perf_counter()
        done = subprocess.run(
            command, cwd=scratch, env=environment, capture_output=True, text=True, check=False
        )
        seconds = time.perf_counter() - start
        cpu = _cpu_of_children() - before
    if done.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(command)} exited {done.returncode}: {done.stderr.strip()}")
    return seconds, cpu


def _cpu_of_children() -> float:
    """CPU s (user + system) of this process's finished children and what they waited for
    (the command's worker processes)."""
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    return used.ru_utime + used.ru_stime


def cases(tree: Path) -> list[tuple[str, list[str], float]]:
    """(name, ``physval run`` arguments, target s) of the two commands in ``tree``."""
    return [
        (
            f"physval run {SMALL_SCENE} --engines mini",
            [str(tree / SMALL_SCENE), "--engines", "mini"],
            SMALL_TARGET_S,
        ),
        (f"physval run {PROJECTILE} (six engines)", [str(tree / PROJECTILE)], PROJECTILE_TARGET_S),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=HERE, help="checkout to measure")
    parser.add_argument("--before", type=Path, help="another checkout, measured interleaved")
    parser.add_argument("--repeats", type=int, default=REPEATS, help="runs of each command")
    args = parser.parse_args(argv)
    trees = {"": args.tree.resolve()}
    if args.before is not None:
        trees = {"before": args.before.resolve(), "after": args.tree.resolve()}
    for label, tree in trees.items():
        print(f"{label or 'tree'}: {tree}")
    print(f"median of {args.repeats} subprocess runs each; wall clock against the target, CPU s")
    met = True
    for position in range(len(cases(args.tree))):
        found: dict[str, list[tuple[float, float]]] = {label: [] for label in trees}
        for _ in range(args.repeats):
            for label, tree in trees.items():
                found[label].append(timed(tree, cases(tree)[position][1]))
        for label, tree in trees.items():
            name, _, target = cases(tree)[position]
            wall = statistics.median(w for w, _ in found[label])
            cpu = statistics.median(c for _, c in found[label])
            met &= wall <= target or label == "before"
            verdict = "meets" if wall <= target else "MISSES"
            shown = f"{label} " if label else ""
            print(
                f"{shown}{name:<62} {wall:6.2f} s wall (target <= {target:g} s: {verdict}), "
                f"{cpu:5.2f} s CPU"
            )
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
