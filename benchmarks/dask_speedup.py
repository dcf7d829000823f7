"""The Dask backend's speed-up: 16 sweep jobs on a LocalCluster of 2 workers
against ``--jobs 1``.

The jobs are those ``physval sweep`` sends: one (scene, engine) dt grid each, here 16
library scenes (the contact, formulas and rotation folders, the first 16 by path but
``LEFT_OUT``) in mini on a 3-point grid. The run also times the local process pool
(``--jobs 2``) as a control of what the machine gives at that moment, and says the best
speed-up these jobs allow (the total over the longest job, or over the workers). They run once serially in this process (``--jobs 1``) and once on
``--scheduler local --jobs 2`` (a ``distributed.LocalCluster`` of 2 single-thread worker
processes; its start-up and shut-down are counted: they are part of what a user waits for).
The rows of the two runs are checked to be the same (timing columns aside). Not a test:
wall-clock numbers depend on the machine, and on a shared machine on who else is using it
(expect close to 2x on 2 free cores).

    python benchmarks/dask_speedup.py [--scenes 16] [--dt 2e-3,1e-3,5e-4] [--workers 2]
                                      [--order longest_first|plan] [--scheduler ADDRESS]

Prints the figures and writes ``benchmarks/results/dask_speedup.csv``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import pandas as pd

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.executor import run_jobs
from validation.jobs.plan import plan_run
from validation.jobs.sweep import lost_sweep_job, parse_dt_grid, sweep_cost, sweep_job

FOLDERS = ("formulas", "rotation", "contact")
LEFT_OUT = ("box_stack",)
"""Scenes left out: box_stack's grid alone takes about 70 % of the others together (35 s of
50 s here), and one task cannot be split, so it would bound any speed-up at about 1.4x."""
TIMING = ["wall_time_s", "steps_per_second", "real_time_factor"]
RESULTS = Path(__file__).resolve().parent / "results" / "dask_speedup.csv"


def _jobs(count: int, grid: list[float]) -> list[tuple]:
    paths = sorted(
        p
        for folder in FOLDERS
        for p in (BUNDLED_SCENARIOS / folder).glob("*.yaml")
        if p.stem not in LEFT_OUT
    )
    plan = plan_run(paths[:count], "mini", None, None)
    return [(scene.scenario, spec, grid) for scene, spec in plan.jobs]


def _serial(jobs: list[tuple]) -> tuple[float, list[dict], list[float]]:
    """``--jobs 1`` (what ``run_jobs`` does with one worker), each job timed."""
    rows, seconds = [], []
    for job in jobs:
        start = time.perf_counter()
        rows += sweep_job(job)
        seconds.append(time.perf_counter() - start)
    return sum(seconds), rows, seconds


ORDERS = {"longest_first": sweep_cost, "plan": None}
"""``--order``: the jobs handed out longest first, as ``physval sweep`` does, or in plan
order (what the executor did before it knew a job's cost)."""


def _timed(
    jobs: list[tuple], workers: int, scheduler: str | None, order: str
) -> tuple[float, list[dict]]:
    start = time.perf_counter()
    found = run_jobs(sweep_job, jobs, workers, None, scheduler, lost_sweep_job, ORDERS[order])
    return time.perf_counter() - start, [row for rows in found for row in rows]


def _same(one: list[dict], two: list[dict]) -> None:
    pd.testing.assert_frame_equal(
        pd.DataFrame(one).drop(columns=TIMING, errors="ignore"),
        pd.DataFrame(two).drop(columns=TIMING, errors="ignore"),
        check_exact=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=16)
    parser.add_argument("--dt", default="2e-3,1e-3,5e-4")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--order", choices=sorted(ORDERS), default="longest_first")
    parser.add_argument(
        "--scheduler",
        default="local",
        help="'local' (a LocalCluster started and ended inside the timing) or the address of "
        "a running cluster (its workers already started: the steady state of a team's cluster)",
    )
    args = parser.parse_args()
    jobs = _jobs(args.scenes, parse_dt_grid(args.dt))
    load = os.getloadavg()[0]
    serial_s, serial, each = _serial(jobs)
    dask_s, dask = _timed(jobs, args.workers, args.scheduler, args.order)
    _same(serial, dask)
    processes_s, processes = _timed(jobs, args.workers, None, args.order)
    _same(serial, processes)
    bound = serial_s / max(serial_s / args.workers, max(each))
    rows = [
        ("--jobs 1", 1, serial_s),
        (f"--scheduler {args.scheduler} --jobs {args.workers}", args.workers, dask_s),
        (f"--jobs {args.workers} (local processes)", args.workers, processes_s),
    ]
    table = pd.DataFrame(
        [{"backend": b, "workers": w, "jobs": len(jobs), "wall_s": t} for b, w, t in rows]
    )
    table["speedup"] = serial_s / table["wall_s"]
    table["best_possible"] = [1.0, bound, bound]
    table["load_before"] = load
    print(
        f"{len(jobs)} sweep jobs (mini, dt {args.dt}, {args.order.replace('_', ' ')}), "
        f"{os.cpu_count()} cores, load average "
        f"{load:.2f} before; rows identical in all three; the longest job "
        f"{max(each):.1f} s of {serial_s:.1f} s"
    )
    print(table.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    print(
        f"Dask speed-up {serial_s / dask_s:.2f}x (at best {bound:.2f}x with these jobs on "
        f"{args.workers} free cores); a shared machine gives less: indicative"
    )
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(RESULTS, index=False)


if __name__ == "__main__":
    main()
