"""``physval run``: every scene in every engine, measured, compared, written as a report.

The run folder (``reports/latest/`` by default, plus a timestamped copy under
``reports/runs/``) holds ``results.csv`` (the record), ``series.csv``, ``impacts.csv``,
``provenance.json`` and ``report.html`` (rendered from the others). It is assembled in a
staging folder next to its destination and moved into place at the end, so an
interrupted run never leaves a half-written report (``validation.jobs.output``). Every
finished job is committed to the run's journal as it finishes (``validation.jobs.journal``),
so that ``physval run --resume DIR`` finishes a killed run without redoing those jobs.
"""

from __future__ import annotations

import dataclasses
import datetime as dt_module
import hashlib
import json
import os
import platform
import subprocess
import sys
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
    SWEEP_FILE,
)
from validation.files import write_atomically, write_table
from validation.jobs.executor import BackendError, run_jobs
from validation.jobs.journal import Journal, JournalError
from validation.jobs.memory import check_memory
from validation.jobs.nightly_run import (
    NightlyOptions,
    against_baseline,
    nightly_options,
    outcome_summary,
    record_history,
    run_selection,
    scene_hashes,
    sweep_result_rows,
    write_ci_files,
)
from validation.jobs.output import Output, claim
from validation.jobs.plan import BadInputError, Plan, expected_cost, plan_run
from validation.jobs.sweep import (
    lost_sweep_job,
    reference_problems,
    sweep_cost,
    sweep_job,
    with_cross_checks,
)
from validation.jobs.terminal import Progress, summary
from validation.measure.comparator import COLUMNS, compare_scene, measure_run
from validation.measure.definitions import MAX_SAMPLES, MAX_SERIES_POINTS
from validation.measure.metrics import Measurement
from validation.measure.runner import EngineRun, run_engine
from validation.nightly.baseline import exit_failed
from validation.nightly.known import apply_known
from validation.report.render import render_report
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec


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
    """One (scene, engine spec): the run and its own metrics (in a worker process), as the run
    keeps it (and journals it): the recording's trajectory holds what divergence compares
    across engines, positions over time (``recording.KEEP``); the series, impacts and every
    metric stay whole."""
    scene, spec = job
    run = run_engine(scene, spec, _sample_every(scene), keep="positions")
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


def _sweep_work(plan: Plan) -> list[tuple]:
    """The scenes' own sweeps (``sweep:``) as sweep jobs, cross-checks included."""
    return with_cross_checks(plan.sweeps)


JOB_KINDS = {"run": run_job, "sweep": sweep_job}
"""Job kind -> the function a worker runs: a (scene, engine) run, or one scene's dt sweep."""


def _do(job: tuple[str, tuple]) -> object:
    """One tagged job (``kind, payload``) in a worker process."""
    kind, payload = job
    return JOB_KINDS[kind](payload)


def _cost(job: tuple[str, tuple]) -> float:
    """A tagged job's expected cost (``plan.expected_cost``): a run at its scene's dt, or a
    sweep over its grid."""
    kind, payload = job
    if kind == "sweep":
        return sweep_cost(payload)
    scene, _ = payload
    return expected_cost(scene.scenario)


def _lost(job: tuple[str, tuple], message: str) -> object:
    """The result recorded for a job the cluster lost (``executor.run_jobs``): an engine run
    with status ``error``, or the sweep's error rows."""
    kind, payload = job
    if kind == "sweep":
        return lost_sweep_job(payload, message)
    scene, spec = payload
    return EngineRun(scene.name, spec.label, "error", message), []


@dataclasses.dataclass
class Executed:
    """What the jobs of a run gave, in plan order.

    Attributes:
        rows: result rows with the scenes' known findings applied. series: series frames.
        impacts: impact rows. runs: the engine runs. sweep_rows: the scenes' sweep rows.
    """

    rows: list[dict]
    series: list[pd.DataFrame]
    impacts: list[dict]
    runs: list[EngineRun]
    sweep_rows: list[dict]


def execute(
    plan: Plan,
    jobs: int = 1,
    journal: Journal | None = None,
    done: dict | None = None,
    scheduler: str | None = None,
) -> Executed:
    """Run every (scene, engine) and every scene's sweep on ``jobs`` workers (or on the Dask
    cluster at ``scheduler``), all in plan order whatever order the jobs finished in.
    ``done``: the results already finished (``journal.finished()``), not run again; with a
    ``journal``, each new result is committed to it as it finishes (sweeps after the runs,
    indexed after them), in this process whatever the backend. A job the cluster lost gets
    its error rows in this run but is not committed: the cluster failed, not the job, so a
    ``--resume`` of this run (killed later) runs it again."""
    work = [("run", job) for job in plan.jobs] + [("sweep", job) for job in _sweep_work(plan)]
    done = dict(done or {})
    todo = [index for index in range(len(work)) if index not in done]
    lost_jobs: list[tuple] = []  # the cluster lost them: their error rows are not journaled

    def lost(job: tuple, message: str) -> object:
        lost_jobs.append(job)
        return _lost(job, message)

    def finished(position: int, result) -> None:
        index = todo[position]
        if journal is not None and not any(work[index] is job for job in lost_jobs):
            journal.append(index, result)  # a lost job is run again by --resume
        done[index] = result
        progress.advance(f"{work[index][1][0].name} · {_label(work[index][1][1])}")

    with Progress(len(todo)) as progress:
        run_jobs(_do, [work[index] for index in todo], jobs, finished, scheduler, lost, _cost)
    rows, series, impacts, all_runs = [], [], [], []
    position = 0
    for scene, specs in plan.scenes:
        results = [done[index] for index in range(position, position + len(specs))]
        position += len(specs)
        runs = [run for run, _ in results]
        measured = [measured for _, measured in results]
        rows += apply_known(compare_scene(scene, runs, measured), scene.scenario)
        for run in runs:
            if run.recording is not None:
                series.append(_series_rows(scene, run))
                impacts += _impact_rows(scene, run)
        all_runs += runs
    sweep_rows = [row for index in range(position, len(work)) for row in done[index]]
    return Executed(rows, series, impacts, all_runs, sweep_rows)


def _label(spec: EngineSpec | None) -> str:
    return "sweep cross-check" if spec is None else spec.label


def write_run(folder: Path, rows, series, impacts, provenance: dict) -> None:
    """The record files of one run into ``folder`` (which must exist), each fsync'd."""
    write_atomically(
        folder / RESULTS_FILE, pd.DataFrame(rows, columns=list(COLUMNS)).to_csv(index=False)
    )
    frames = [f for f in series if not f.empty]
    if frames:
        write_atomically(
            folder / SERIES_FILE, pd.concat(frames, ignore_index=True).to_csv(index=False)
        )
    write_atomically(
        folder / IMPACTS_FILE,
        pd.DataFrame(impacts, columns=list(IMPACTS_COLUMNS)).to_csv(index=False),
    )
    write_atomically(folder / PROVENANCE_FILE, json.dumps(provenance, indent=2, default=str))


def render_html(folder: Path, shown_as: Path) -> str:
    """Render report.html (naming ``shown_as``, where it is published); returns a note instead
    of failing the run when rendering fails (results.csv is the record; ``physval report
    DIR`` can render it again later)."""
    try:
        render_report(folder, shown_as=shown_as)
    except Exception as error:  # a rendering bug must not lose the run's record
        return f"report.html not rendered ({type(error).__name__}: {error}); try physval report"
    return ""


DEFAULT_OUT = Path("reports") / "latest"
"""Where a run without ``--out`` publishes (and keeps a copy under ``reports/runs/``)."""

RESUME_ALONE = "--resume takes the run's scenes, engines, --dt, --only and --out from its journal"
"""Why --resume refuses other selection flags (only --jobs may change)."""


def job_fingerprints(plan: Plan) -> list[dict]:
    """Per job, in plan order (runs, then sweeps): its scene, engine and a hash of the
    validated scene (without its file path) and engine spec, so a resumption can tell that it
    plans the same work."""
    found = []
    jobs = [(s.scenario, spec) for s, spec in plan.jobs]
    jobs += [(scenario, spec) for scenario, spec, _ in _sweep_work(plan)]
    for scenario, spec in jobs:
        text = scenario.model_dump_json(exclude={"source"}) + "|" + _label(spec)
        digest = hashlib.sha256(text.encode()).hexdigest()[:16]
        found.append({"scene": scenario.name, "engine": _label(spec), "fingerprint": digest})
    return found


@dataclasses.dataclass(frozen=True)
class RunRequest:
    """What a run was asked for: the journal's header holds it, so --resume can plan again."""

    paths: list[str]
    engines: str | None
    dt: float | None
    only: str | None
    out: str | None
    argv: list[str]
    cwd: str
    baseline: str | None = None
    junit: str | None = None
    history: str | None = None

    def plan(self) -> Plan:
        """The plan, paths taken from the run's working directory (as given when it is this
        one, so that ``--only`` matches paths as it did); the scenes' sweeps checked."""
        here = Path.cwd() == Path(self.cwd)
        paths = [Path(p) if here else Path(self.cwd) / p for p in self.paths]
        plan = plan_run(paths, self.engines, self.dt, self.only)
        problems = reference_problems(plan.sweeps)
        if problems:
            raise BadInputError("\n".join(problems).replace("--dt:", "sweep.dt:"))
        return plan

    def nightly(self) -> NightlyOptions:
        """The nightly flags, checked (``nightly_run.nightly_options``)."""
        return nightly_options(self.baseline, self.junit, self.history, self.destination)

    @property
    def destination(self) -> Path:
        return DEFAULT_OUT if self.out is None else Path(self.out)


def _header(request: RunRequest, plan: Plan) -> dict:
    return {
        "request": dataclasses.asdict(request),
        "git_commit": _git_commit(),
        "jobs": job_fingerprints(plan),
    }


def _resumed(journal: Journal) -> tuple[RunRequest, Plan]:
    """The request and plan of the journal's run, checked to be the same work and code."""
    try:
        request = RunRequest(**journal.header["request"])
    except (KeyError, TypeError) as error:
        raise BadInputError(f"{journal.folder}: not a run's journal ({error})") from None
    plan = request.plan()
    if job_fingerprints(plan) != journal.header.get("jobs"):
        raise BadInputError(
            f"--resume: the scenes or engines changed since the killed run "
            f"({' '.join(request.argv) or 'physval run'}); run it again without --resume"
        )
    if journal.header.get("git_commit") != _git_commit():
        raise BadInputError(
            f"--resume: the code changed since the killed run (commit "
            f"{journal.header.get('git_commit')}, now {_git_commit()}); run it again"
        )
    return request, plan


def _finish(
    output: Output,
    journal: Journal,
    plan: Plan,
    request: RunRequest,
    jobs: int,
    scheduler: str | None = None,
) -> int:
    """Run what the journal lacks, write and publish the run folder; the exit code."""
    options = request.nightly()
    done = journal.finished()
    resumed = len(done)
    executed = execute(plan, jobs, journal, done, scheduler)  # Ctrl-C: Interrupted
    rows = executed.rows + _sweep_rows(plan, executed)
    provenance = _provenance(executed.runs, request.argv)
    provenance["scenes"] = hashes = scene_hashes(plan)
    provenance["selection"] = run_selection(
        request.paths, request.cwd, request.only, request.engines, request.dt, plan
    )
    if resumed:
        total = len(plan.jobs) + len(_sweep_work(plan))
        provenance["resumed"] = {"jobs_from_journal": resumed, "jobs_run": total - resumed}
    rows, compared = against_baseline(rows, options, hashes, output.run_folder)
    write_run(output.run_folder, rows, executed.series, executed.impacts, provenance)
    if executed.sweep_rows:
        write_table(executed.sweep_rows, output.run_folder / SWEEP_FILE)
    write_ci_files(rows, options)
    note = render_html(output.run_folder, shown_as=output.destination)
    output.publish()
    if request.out is None:  # the default run also keeps a copy with a unique stamp
        output.keep_history()
    recorded = record_history(output.destination, options)
    print(summary(rows, color=sys.stdout.isatty()))
    bad = sum(row["status"] in BAD_STATUSES for row in rows)
    notes = [n for n in (outcome_summary(rows), compared, recorded, note) if n]
    print(
        (
            f"{resumed} of {len(plan.jobs) + len(_sweep_work(plan))} jobs from the journal; "
            if resumed
            else ""
        )
        + f"{len(rows)} rows, {bad} failed or unstable -> {output.destination / RESULTS_FILE}"
        + "".join(f"; {n}" for n in notes)
    )
    if note:  # the record is published, but the page a reader opens is not: never exit 0
        return EXIT_BAD_INPUT
    return EXIT_FAILED if exit_failed(rows) else EXIT_OK


def _sweep_rows(plan: Plan, executed: Executed) -> list[dict]:
    """The scenes' sweeps as result rows, each scene's known findings applied."""
    found = sweep_result_rows(executed.sweep_rows)
    rows = []
    for scene, _ in plan.scenes:
        rows += apply_known([r for r in found if r["scenario"] == scene.name], scene.scenario)
    return rows


def run_main(
    paths: list[Path],
    engines: str | None,
    out: Path | None,
    dt: float | None,
    only: str | None,
    argv: list[str],
    jobs: int = 1,
    resume: Path | None = None,
    baseline: str | None = None,
    junit: str | None = None,
    history: str | None = None,
    scheduler: str | None = None,
) -> int:
    """The whole job (on the Dask cluster at ``scheduler`` when given); returns the exit code (0 nothing regressed and no new failure: every
    failing row is a known finding or, against a baseline, failed there too; 1 a regression
    or a new failure; 2 bad input, a refused output folder, or an output that failed while
    writing)."""
    try:
        if resume is not None:
            return _resume_main(resume, jobs, scheduler)
        request = RunRequest(
            [str(p) for p in paths],
            engines,
            dt,
            only,
            None if out is None else str(out),
            argv,
            os.getcwd(),
            baseline,
            junit,
            history,
        )
        request.nightly()  # the flags checked before any work
        plan = request.plan()
        if scheduler is None:  # on a cluster the workers' memory is the cluster's
            check_memory(plan, jobs, _sample_every)
        with claim(request.destination) as output:
            journal = Journal.create(output.journal_folder, _header(request, plan))
            return _finish(output, journal, plan, request, jobs, scheduler)
    except (BadInputError, BackendError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:  # a full disk, a folder made read-only mid-run
        print(
            f"cannot write the run: {error}; the finished jobs are kept in its journal "
            "(physval run --resume DIR finishes it)",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT


def _resume_main(destination: Path, jobs: int, scheduler: str | None = None) -> int:
    with claim(destination, resume=True) as output:
        try:
            journal = Journal.open(output.journal_folder)
        except JournalError as error:
            raise BadInputError(f"--resume {destination}: {error}") from None
        request, plan = _resumed(journal)
        if scheduler is None:
            check_memory(plan, jobs, _sample_every)
        return _finish(output, journal, plan, request, jobs, scheduler)
