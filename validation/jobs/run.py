"""``physval run``: every scene in every engine, measured, compared, written as a report.

The run folder (``reports/latest/`` by default, plus a timestamped copy under
``reports/runs/``) holds ``results.csv`` (the record), ``series.csv``, ``impacts.csv``,
``provenance.json`` and ``report.html`` (rendered from the others). It is assembled in a
staging folder next to its destination and moved into place at the end, so an
interrupted run never leaves a half-written report.
"""

from __future__ import annotations

import datetime as dt_module
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from validation.contract import (
    BAD_STATUSES,
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    IMPACTS_COLUMNS,
    IMPACTS_FILE,
    PROVENANCE_FILE,
    RESULTS_FILE,
    SERIES_FILE,
)
from validation.jobs.executor import run_jobs
from validation.jobs.plan import BadInputError, Plan, plan_run
from validation.jobs.terminal import Progress, summary
from validation.measure.comparator import COLUMNS, compare_scene, measure_run
from validation.measure.metrics import Measurement
from validation.measure.runner import EngineRun, run_engine
from validation.report.render import render_report
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec

MAX_SAMPLES = 5000
"""Trajectory samples kept per run (series and plots): every step of the library's short
scenes, every k-th of long ones. Measuring sees every step whatever is kept."""

MAX_SERIES_POINTS = 1000
"""Points per (scene, engine) written to series.csv for the report's plots."""


def _sample_every(scene: CompiledScene) -> int:
    return max(1, -(-scene.scenario.steps // MAX_SAMPLES))


def _series_rows(scene: CompiledScene, run: EngineRun) -> pd.DataFrame:
    series = run.recording.series
    keep = np.unique(
        np.linspace(0, series.t.size - 1, min(series.t.size, MAX_SERIES_POINTS)).astype(int)
    )
    frame = pd.DataFrame(
        {
            "t": series.t[keep],
            "energy": series.energy[keep],
            **{f"p{axis}": series.momentum[keep, i] for i, axis in enumerate("xyz")},
            **{f"L{axis}": series.angular_momentum[keep, i] for i, axis in enumerate("xyz")},
        }
    )
    frame.insert(0, "engine", run.engine)
    frame.insert(0, "scenario", scene.name)
    return frame


def _impact_rows(scene: CompiledScene, run: EngineRun) -> list[dict]:
    return [
        {
            "scenario": scene.name,
            "engine": run.engine,
            "body_a": event.body_a,
            "body_b": event.body_b,
            "time": event.time_start,
            "e_requested": requested,
            "e_measured": event.restitution,
            "normal_velocity_before": event.normal_velocity_before,
            "normal_velocity_after": event.normal_velocity_after,
            "delta_e": event.restitution - requested,
            "band": event.band(requested),
        }
        for event, requested in (
            (e, scene.pair_value(e.body_a, e.body_b, "restitution")) for e in run.recording.impacts
        )
    ]


def run_job(job: tuple[CompiledScene, EngineSpec]) -> tuple[EngineRun, list[Measurement]]:
    """One (scene, engine spec): the run and its own metrics (in a worker process)."""
    scene, spec = job
    run = run_engine(scene, spec, _sample_every(scene))
    return run, measure_run(scene, run)


def _git_commit() -> str:
    try:
        found = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
            cwd=Path(__file__).resolve().parent,
        )
        return found.stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def _provenance(runs: list[EngineRun], argv: list[str]) -> dict:
    engines = {}
    for run in runs:
        if run.provenance is not None and run.engine not in engines:
            p = run.provenance
            engines[run.engine] = {
                "engine": p.engine,
                "version": p.version,
                "settings": p.settings,
                "notes": p.notes,
            }
    return {
        "command": " ".join(["physval", *argv]),
        "git_commit": _git_commit(),
        "created": dt_module.datetime.now(dt_module.UTC).isoformat(timespec="seconds"),
        "machine": {
            "platform": platform.platform(),
            "python": platform.python_version(),
            "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(),
            "numpy": np.__version__,
        },
        "engines": engines,
    }


def execute(
    plan: Plan, jobs: int = 1
) -> tuple[list[dict], list[pd.DataFrame], list[dict], list[EngineRun]]:
    """Run every (scene, engine) on ``jobs`` workers; returns rows, series frames, impact rows
    and the runs, all in plan order whatever order the jobs finished in."""
    work = plan.jobs
    with Progress(len(work)) as progress:
        done = run_jobs(
            run_job,
            work,
            jobs,
            lambda index, _: progress.advance(f"{work[index][0].name} · {work[index][1].label}"),
        )
    rows, series, impacts, all_runs = [], [], [], []
    position = 0
    for scene, specs in plan.scenes:
        results = done[position : position + len(specs)]
        position += len(specs)
        runs = [run for run, _ in results]
        rows += compare_scene(scene, runs, [measured for _, measured in results])
        for run in runs:
            if run.recording is not None:
                series.append(_series_rows(scene, run))
                impacts += _impact_rows(scene, run)
        all_runs += runs
    return rows, series, impacts, all_runs


def write_run(folder: Path, rows, series, impacts, provenance: dict) -> None:
    """The record files of one run into ``folder`` (which must exist)."""
    results = pd.DataFrame(rows, columns=list(COLUMNS))
    results.to_csv(folder / RESULTS_FILE, index=False)
    frames = [f for f in series if not f.empty]
    if frames:
        pd.concat(frames, ignore_index=True).to_csv(folder / SERIES_FILE, index=False)
    pd.DataFrame(
        impacts,
        columns=list(IMPACTS_COLUMNS),
    ).to_csv(folder / IMPACTS_FILE, index=False)
    (folder / PROVENANCE_FILE).write_text(json.dumps(provenance, indent=2, default=str))


def publish(stage: Path, destination: Path) -> None:
    """Move the finished ``stage`` folder to ``destination``, replacing an older run."""
    destination.parent.mkdir(parents=True, exist_ok=True)
    old = None
    if destination.exists():
        old = destination.with_name(f".{destination.name}.old-{os.getpid()}")
        os.replace(destination, old)
    os.replace(stage, destination)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def render_html(folder: Path) -> str:
    """Render report.html; returns a note instead of failing the run when rendering fails
    (results.csv is the record; ``physval report DIR`` can render it again later)."""
    try:
        render_report(folder)
    except Exception as error:  # a rendering bug must not lose the run's record
        return f"report.html not rendered ({type(error).__name__}: {error}); try physval report"
    return ""


def run_main(
    paths: list[Path],
    engines: str | None,
    out: Path | None,
    dt: float | None,
    only: str | None,
    argv: list[str],
    jobs: int = 1,
) -> int:
    """The whole job; returns the exit code (0 all passed, 1 any failed or unstable, 2 bad input)."""
    try:
        plan = plan_run(paths, engines, dt, only)
    except BadInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    rows, series, impacts, runs = execute(plan, jobs)  # Ctrl-C: Interrupted, nothing published
    destination = out or Path("reports") / "latest"
    destination.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{destination.name}-staging-", dir=destination.parent))
    try:
        write_run(stage, rows, series, impacts, _provenance(runs, argv))
        note = render_html(stage)
        publish(stage, destination)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    if out is None:  # the default run also keeps a timestamped copy
        stamp = dt_module.datetime.now(dt_module.UTC).strftime("%Y%m%d-%H%M%S")
        shutil.copytree(destination, destination.parent / "runs" / stamp, dirs_exist_ok=True)
    print(summary(rows, color=sys.stdout.isatty()))
    bad = sum(row["status"] in BAD_STATUSES for row in rows)
    print(
        f"{len(rows)} rows, {bad} failed or unstable -> {destination / RESULTS_FILE}"
        + (f"; {note}" if note else "")
    )
    return EXIT_FAILED if bad else EXIT_OK
