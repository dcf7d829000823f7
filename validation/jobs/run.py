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
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pydantic

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
    TRACE_COLUMNS,
    TRACE_FILE,
)
from validation.csv_safe import csv_text
from validation.engines.base import Trajectory
from validation.files import write_atomically, write_table
from validation.jobs.executor import BackendError, run_jobs
from validation.jobs.journal import HEADER_FILE, JobId, Journal, JournalError, Schema
from validation.jobs.memory import check_memory
from validation.jobs.nightly_run import (
    NightlyOptions,
    against_baseline,
    nightly_options,
    record_history,
    run_selection,
    scene_hashes,
    sweep_result_rows,
    write_ci_files,
)
from validation.jobs.output import Output, check_inside, claim
from validation.jobs.phases import PhaseClock
from validation.jobs.plan import BadInputError, Plan, expected_cost, plan_run
from validation.jobs.summary import check_summary_target, summary_markdown
from validation.jobs.sweep import (
    SWEEP_METRICS,
    lost_sweep_job,
    reference_problems,
    sweep_cost,
    sweep_job,
    with_cross_checks,
)
from validation.jobs.terminal import (
    SUMMARY_WIDTH,
    Progress,
    counts_lines,
    log_summary,
    news,
    packed_lines,
    summary,
)
from validation.measure.comparator import COLUMNS, compare_scene, measure_run
from validation.measure.definitions import MAX_KEPT_POSITIONS, MAX_SAMPLES, MAX_SERIES_POINTS
from validation.measure.metrics import Measurement
from validation.measure.recording import kept_samples
from validation.measure.runner import EngineRun, run_engine
from validation.measure.states import Series
from validation.nightly.baseline import exit_failed, missing_note
from validation.nightly.known import apply_known
from validation.redact import shown_argv, shown_command, shown_url
from validation.report.closed_form import expectation_records, trace_rows, traced
from validation.report.render import render_report
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec
from validation.scenario.problems import printable

STATE_NUMBERS = 13
"""Numbers of one body's kept state: position 3, quaternion 4, velocity 3, angular velocity 3."""

TRACE_FORMAT = "%.7g"
"""trace.csv's numbers: 7 significant digits, finer than the charts' narrowest axis
(``svgchart.MIN_RELATIVE_SPAN``, 1e-6 of the values); the rows keep every digit."""


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
    """impacts.csv's rows of one run: its kept impacts (``impact_log``), in closing order."""
    impacts = run.recording.impacts
    pairs = {(e.body_a, e.body_b) for e in impacts}
    lookup = {pair: scene.pair_value(*pair, "restitution") for pair in pairs}
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
        for event, requested in ((e, lookup[e.body_a, e.body_b]) for e in impacts)
    ]


def run_job(job: tuple[CompiledScene, EngineSpec]) -> tuple[EngineRun, list[Measurement]]:
    """One (scene, engine spec): the run and its own metrics (in a worker process), as the run
    keeps it (and journals it): the recording's trajectory holds what divergence compares
    across engines, positions over time (``recording.KEEP``); the series, impacts and every
    metric stay whole."""
    scene, spec = job
    run = run_engine(scene, spec, _sample_every(scene), keep="positions")
    return run, measure_run(scene, run)


def _positions_only(trajectory: Trajectory) -> Trajectory:
    """``trajectory`` with its times and positions, orientations and velocities dropped (zero
    width): 3 of its 13 numbers per body and sample, all that the run's files still need."""
    return dataclasses.replace(
        trajectory,
        quat=trajectory.quat[..., :0],
        vel=trajectory.vel[..., :0],
        ang_vel=trajectory.ang_vel[..., :0],
    )


def kept_job(job: tuple[CompiledScene, EngineSpec]) -> tuple[EngineRun, list[Measurement]]:
    """``run_job`` as the run keeps it (and journals it), with the thin trace of the bodies
    the scene's expectations test (trace.csv, the report's closed-form charts): where the
    scene has such bodies and its whole states fit ``MAX_KEPT_POSITIONS`` numbers, the run
    keeps them, takes the trace, and keeps positions only (what divergence compares across
    engines); elsewhere (no expectation, or a scene too large) ``run_job``, no trace."""
    scene, spec = job
    if not traced(scene.scenario.expect) or not _states_fit(scene):
        return run_job(job)
    run = run_engine(scene, spec, _sample_every(scene))
    measured = measure_run(scene, run)
    if run.recording is not None:
        trajectory = run.recording.trajectory
        slim = _positions_only(trajectory)
        run = dataclasses.replace(
            run,
            recording=dataclasses.replace(run.recording, trajectory=slim),
            trace=_trace(job[0], run.engine, trajectory),
        )
    return run, measured


def _trace(scene: CompiledScene, engine: str, trajectory: Trajectory) -> dict[str, object] | None:
    """The thin trace of the bodies the scene's expectations test (trace.csv's rows), as
    columns of plain data (text lists, float arrays), so a journal record can hold it."""
    bodies = [body.name for body in scene.scenario.bodies]
    wanted = traced(scene.scenario.expect)
    frame = trace_rows(scene.name, engine, trajectory, bodies, wanted, scene)
    if frame.empty:
        return None
    return {
        column: frame[column].to_numpy(dtype=float)
        if pd.api.types.is_numeric_dtype(frame[column])
        else [str(text) for text in frame[column]]
        for column in TRACE_COLUMNS
    }


def _states_fit(scene: CompiledScene) -> bool:
    """Whether a run's whole kept states (13 numbers per body and sample) fit the budget of
    the positions it keeps (``MAX_KEPT_POSITIONS``): the library's scenes do; a 10,000-body
    scene does not, and keeps positions only from the start."""
    samples = kept_samples(scene.scenario.steps, _sample_every(scene))
    return samples * scene.count * STATE_NUMBERS <= MAX_KEPT_POSITIONS


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
        "command": shown_command(argv),
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


def _engine_notes(runs: list[EngineRun], scene: str) -> dict[str, list[str]]:
    """Engine spec -> the notes its adapter recorded for ``scene`` (how its numbers read:
    physval's own spring force law in PyBullet, MuJoCo's contact calibration), which the
    report shows next to the engine's rows in the scene's card."""
    return {
        run.engine: list(run.provenance.notes)
        for run in runs
        if run.scenario == scene and run.provenance is not None and run.provenance.notes
    }


def _sweep_work(plan: Plan) -> list[tuple]:
    """The scenes' own sweeps (``sweep:``) as sweep jobs, cross-checks included."""
    return with_cross_checks(plan.sweeps)


JOB_KINDS = {"run": kept_job, "sweep": sweep_job}
"""Job kind -> the function a worker runs: a (scene, engine) run, or one scene's dt sweep."""


SweepCell = str | bool | int | float | None
"""A cell of a sweep row (``sweep.sweep_job``)."""

JOURNAL_SCHEMA = Schema(
    results={"run": tuple[EngineRun, list[Measurement]], "sweep": list[dict[str, SweepCell]]},
    shapes={
        Trajectory: {"t": ("samples",), "pos": ("samples", "bodies", 3)},
        Series: {
            "t": ("samples",),
            "energy": ("samples",),
            "momentum": ("samples", 3),
            "angular_momentum": ("samples", 3),
            "com": ("samples", 3),
        },
    },
)
"""What a journal record of each job kind holds (``JOB_KINDS``'s results, read back as
these types and nothing else), and the shapes of its arrays: a trajectory's positions are
(samples, the scene's bodies, 3), the series one row of each quantity per sample."""


def _do(job: tuple[str, tuple]) -> object:
    """One tagged job (``kind, payload``) in a worker process."""
    kind, payload = job
    return JOB_KINDS[kind](payload)


def _timed(job: tuple[str, tuple]) -> tuple[float, object]:
    """``(seconds, result)``: ``_do(job)`` and the wall seconds it took in its worker
    (``--timings``; the seconds never reach a record)."""
    start = time.perf_counter()
    result = _do(job)
    return time.perf_counter() - start, result


def _cost(job: tuple[str, tuple]) -> float:
    """A tagged job's expected cost (``plan.expected_cost``): a run at its scene's dt, or a
    sweep over its grid."""
    kind, payload = job
    if kind == "sweep":
        return sweep_cost(payload)
    scene, _ = payload
    return expected_cost(scene.scenario)


def _lost(job: tuple[str, tuple], status: str, message: str) -> object:
    """The result recorded for a job that gave none (``executor.run_jobs``: it crashed or
    timed out): an engine run with that status, or the sweep's rows of it."""
    kind, payload = job
    if kind == "sweep":
        return lost_sweep_job(payload, status, message)
    return lost_run(payload, status, message)


def lost_run(
    job: tuple[CompiledScene, EngineSpec], status: str, message: str
) -> tuple[EngineRun, list[Measurement]]:
    """A (scene, engine) run that gave no result (``executor.run_jobs``): its ``status``
    (``crashed``, ``timed_out``) and why, nothing measured."""
    scene, spec = job
    return EngineRun(scene.name, spec.label, status, message), []


@dataclasses.dataclass
class Executed:
    """What the jobs of a run gave, in plan order.

    Attributes:
        rows: result rows with the scenes' known findings applied. series: series frames.
        impacts: impact rows. runs: the engine runs. sweep_rows: the scenes' sweep rows.
        traces: trace frames (the bodies under test).
    """

    rows: list[dict]
    series: list[pd.DataFrame]
    impacts: list[dict]
    runs: list[EngineRun]
    sweep_rows: list[dict]
    traces: list[pd.DataFrame] = dataclasses.field(default_factory=list)


def execute(
    plan: Plan,
    jobs: int = 1,
    journal: Journal | None = None,
    done: dict | None = None,
    scheduler: str | None = None,
    clock: PhaseClock | None = None,
    job_timeout: float | None = None,
) -> Executed:
    """Run every (scene, engine) and every scene's sweep on ``jobs`` workers (or on the Dask
    cluster at ``scheduler``), all in plan order whatever order the jobs finished in.
    ``done``: the results already finished (``journal.finished()``), not run again; with a
    ``journal``, each new result is committed to it as it finishes (sweeps after the runs,
    indexed after them), in this process whatever the backend. A job that crashed, timed out
    (``job_timeout``: ``--job-timeout``, ``executor.time_limit``) or that the cluster lost
    gets its rows in this run but is not committed: an out-of-memory kill or a loaded
    machine may not happen again, so a ``--resume`` of this run (killed later) runs it
    again. ``clock``: where each job's worker seconds are added up (``PhaseClock.job``)."""
    work = [("run", job) for job in plan.jobs] + [("sweep", job) for job in _sweep_work(plan)]
    ids = job_ids(plan)
    done = dict(done or {})
    todo = [index for index in range(len(work)) if index not in done]
    lost_jobs: list[tuple] = []  # crashed, timed out or lost: their rows are not journaled

    def lost(job: tuple, status: str, message: str) -> tuple[float, object]:
        lost_jobs.append(job)
        return 0.0, _lost(job, status, message)

    def finished(position: int, timed: tuple[float, object]) -> None:
        seconds, result = timed
        index = todo[position]
        if clock is not None:
            clock.job(work[index][0], seconds)
        if journal is not None and not any(work[index] is job for job in lost_jobs):
            journal.append(ids[index], result)  # a lost job is run again by --resume
        done[index] = result
        kind, payload = work[index]
        scene, spec = payload[0], payload[1]
        progress.advance(
            f"{scene.name} · {_label(spec)}" + (" sweep" if kind == "sweep" and spec else ""),
            _how_it_ended(work[index][0], result),
        )

    with Progress(len(todo)) as progress:
        run_jobs(
            _timed,
            [work[index] for index in todo],
            jobs,
            finished,
            scheduler,
            lost,
            _cost,
            job_timeout,
        )
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
    traces = [pd.DataFrame(run.trace) for run in all_runs if isinstance(run.trace, dict)]
    return Executed(rows, series, impacts, all_runs, sweep_rows, traces)


def _how_it_ended(kind: str, result) -> str:
    """A finished job's ending for its progress line: a run's status and engine time, a sweep's
    worst status (``ok`` when every point ran) and its number of rows."""
    if kind == "sweep":
        statuses = {str(row.get("status", "ok")) for row in result}
        status = next((s for s in BAD_STATUSES if s in statuses), "ok")
        return f"{status} {len(result)} sweep rows"
    run, _ = result
    return f"{run.status} {run.wall_time_s:.1f} s"


def _label(spec: EngineSpec | None) -> str:
    return "sweep cross-check" if spec is None else spec.label


def write_run(folder: Path, rows, series, impacts, provenance: dict, traces=()) -> None:
    """The record files of one run into ``folder`` (which must exist), each fsync'd."""
    write_atomically(folder / RESULTS_FILE, csv_text(pd.DataFrame(rows, columns=list(COLUMNS))))
    frames = [f for f in series if not f.empty]
    if frames:
        write_atomically(folder / SERIES_FILE, csv_text(pd.concat(frames, ignore_index=True)))
    write_atomically(
        folder / IMPACTS_FILE,
        csv_text(pd.DataFrame(impacts, columns=list(IMPACTS_COLUMNS))),
    )
    write_atomically(folder / PROVENANCE_FILE, json.dumps(provenance, indent=2, default=str))
    traced_frames = [f for f in traces if not f.empty]
    if traced_frames:
        write_atomically(
            folder / TRACE_FILE,
            pd.concat(traced_frames, ignore_index=True)[list(TRACE_COLUMNS)].to_csv(
                index=False, float_format=TRACE_FORMAT
            ),
        )


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

RESUME_ALONE = (
    "--resume takes the run's scenes, engines, --dt, --only, --sweeps, --baseline and --out from "
    "its journal"
)
"""Why --resume refuses other selection flags (only --jobs and --scheduler may change; the
files it writes besides DIR, --junit and --history, are given again)."""


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


def job_ids(plan: Plan) -> list[JobId]:
    """Each job of the plan, in plan order, as its journal record names it."""
    kinds = ["run"] * len(plan.jobs) + ["sweep"] * len(_sweep_work(plan))
    bodies = [len(s.scenario.bodies) for s, _ in plan.jobs]
    bodies += [len(scenario.bodies) for scenario, _, _ in _sweep_work(plan)]
    return [
        JobId(index, kind, found["scene"], found["engine"], found["fingerprint"], count)
        for index, (kind, found, count) in enumerate(
            zip(kinds, job_fingerprints(plan), bodies, strict=True)
        )
    ]


@dataclasses.dataclass(frozen=True)
class RunRequest:
    """What a run was asked for: the journal's header holds it, so --resume can plan again."""

    __pydantic_config__ = pydantic.ConfigDict(strict=True, extra="forbid")  # header.json

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
    sweeps: bool = True  # a journal written before --sweeps existed: its runs swept

    def plan(self) -> Plan:
        """The plan, paths taken from the run's working directory (as given when it is this
        one, so that ``--only`` matches paths as it did); the scenes' sweeps checked."""
        here = Path.cwd() == Path(self.cwd)
        paths = [Path(p) if here else Path(self.cwd) / p for p in self.paths]
        plan = plan_run(paths, self.engines, self.dt, self.only, self.sweeps)
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
    """The journal's header; the command line and the history URL with their passwords masked
    (a killed run's staging folder may be cached or uploaded; --resume is given --history
    again, and uses that one)."""
    kept = dataclasses.replace(
        request,
        argv=shown_argv(request.argv),
        history=None if request.history is None else shown_url(request.history),
    )
    return {
        "request": dataclasses.asdict(kept),
        "git_commit": _git_commit(),
        "jobs": job_fingerprints(plan),
    }


class _JobFingerprint(pydantic.BaseModel):
    """One job of a journal's header (``job_fingerprints``)."""

    model_config = pydantic.ConfigDict(strict=True, extra="forbid")
    scene: str
    engine: str
    fingerprint: str


class _Header(pydantic.BaseModel):
    """A journal's header (``_header``), as ``--resume`` accepts it: every field of its type,
    no other field."""

    model_config = pydantic.ConfigDict(strict=True, extra="forbid")
    request: RunRequest
    git_commit: str
    jobs: list[_JobFingerprint]
    journal_version: int


def _read_header(journal: Journal) -> _Header:
    """The journal's header, every field checked; ``BadInputError`` naming the first wrong
    one."""
    try:
        return _Header.model_validate_json(json.dumps(journal.header))
    except pydantic.ValidationError as error:
        first = error.errors()[0]
        field = ".".join(str(part) for part in first["loc"]) or "header"
        raise BadInputError(
            f"{journal.folder / HEADER_FILE}: {field}: {first['msg']} (not a run's journal "
            "this version can resume)"
        ) from None


def _resumed(
    journal: Journal, destination: Path, junit: str | None, history: str | None
) -> tuple[RunRequest, Plan]:
    """The request and plan of the journal's run, checked to be the same work and code, and
    as it may run now: its paths checked as a fresh run's flags are, writing only to
    ``destination`` (``--resume DIR``) and to the ``junit`` and ``history`` given on this
    command line (``_writes_only``)."""
    header = _read_header(journal)
    request = _writes_only(
        header.request, journal.folder / HEADER_FILE, destination, junit, history
    )
    plan = request.plan()
    if header.model_dump()["jobs"] != job_fingerprints(plan):
        raise BadInputError(
            f"--resume: the scenes or engines changed since the killed run "
            f"({' '.join(shown_argv(request.argv)) or 'physval run'}); run it again without --resume"
        )
    if header.git_commit != _git_commit():
        raise BadInputError(
            f"--resume: the code changed since the killed run (commit "
            f"{header.git_commit}, now {_git_commit()}); run it again"
        )
    return request, plan


def _writes_only(
    request: RunRequest, header: Path, destination: Path, junit: str | None, history: str | None
) -> RunRequest:
    """The journal's ``request`` as the resumed run executes it: its ``out`` must be
    ``destination``, its JUnit file and history database those given again on this command
    line (a journal never names a file to write); relative paths taken from its ``cwd``,
    which must be an absolute folder. ``BadInputError`` naming the header's field otherwise."""
    cwd = Path(request.cwd)
    if not cwd.is_absolute() or not cwd.is_dir():
        raise BadInputError(
            f"{header}: request.cwd: expected an existing absolute folder; got {request.cwd!r}"
        )
    named = (cwd / (DEFAULT_OUT if request.out is None else Path(request.out))).resolve()
    if named != destination.resolve():
        raise BadInputError(
            f"{header}: request.out: the journal is of a run on {named}, not --resume {destination}"
        )
    if _resolved(cwd, request.junit) != _resolved(Path.cwd(), junit):
        raise BadInputError(
            f"{header}: request.junit: the killed run wrote JUnit XML to {request.junit!r}; "
            f"a resumed run writes only what its own command line names: give --junit "
            f"{_resolved(cwd, request.junit) or 'none'} again"
            if junit is None
            else f"--junit {junit}: the killed run's was {request.junit!r} ({header}); give the same"
        )
    if (request.history or "default") != (shown_url(history) if history else "default"):
        raise BadInputError(
            f"--history: differs from the killed run's ({header}: request.history; "
            "default: next to --out); a resumed run records only where its own command line "
            "says: give the same --history again"
        )
    baseline = request.baseline
    if baseline not in (None, "none"):
        baseline = str(cwd / baseline)
    return dataclasses.replace(
        request, out=str(destination), junit=junit, baseline=baseline, history=history
    )


def _resolved(cwd: Path, path: str | None) -> Path | None:
    return None if path is None else (cwd / path).resolve()


def _finish(
    output: Output,
    journal: Journal,
    plan: Plan,
    request: RunRequest,
    jobs: int,
    scheduler: str | None = None,
    keep_copy: bool | None = None,
    clock: PhaseClock | None = None,
    job_timeout: float | None = None,
    extra_files: dict[str, str] | None = None,
    summary_file: Path | None = None,
) -> int:
    """Run what the journal lacks, write and publish the run folder; the exit code.
    ``keep_copy``: also keep a stamped copy (default: when the run has no ``--out``).
    ``clock``: the clock that times the phases (printed on stderr at the end when it is
    ``shown``: ``--timings``). ``job_timeout``: ``--job-timeout``. ``extra_files``: name ->
    text, written into the run folder with the record. ``summary_file``: ``--summary``."""
    clock = PhaseClock() if clock is None else clock
    with clock.phase("planning"):
        options = request.nightly()
        done = _journaled(journal, plan)
    resumed = len(done)
    with clock.phase("jobs"):
        executed = execute(plan, jobs, journal, done, scheduler, clock, job_timeout)  # Ctrl-C
    with clock.phase("write"):
        rows, comparison = _written(output, plan, request, executed, options, resumed)
        for name, text in (extra_files or {}).items():
            write_atomically(output.run_folder / name, text)
    with clock.phase("report"):
        note = render_html(output.run_folder, shown_as=output.destination)
    with clock.phase("publish"):
        output.publish()
        if request.out is None if keep_copy is None else keep_copy:  # with a unique stamp
            output.keep_history()
    with clock.phase("history"):
        recorded = record_history(output.destination, options)
    _print_summary(rows, comparison, options.baseline)
    if summary_file is not None:
        write_atomically(summary_file, summary_markdown(rows, comparison))
    lacked = missing_note(comparison)
    if lacked:
        print(lacked)
    total = len(plan.jobs) + len(_sweep_work(plan))
    journaled = f"{resumed} of {total} jobs from the journal" if resumed else ""
    written = f"{len(rows)} rows -> {printable(output.destination / RESULTS_FILE)}"
    print(
        "\n".join(
            packed_lines(
                [n for n in (journaled, written, recorded, note) if n], SUMMARY_WIDTH, "", "; "
            )
        )
    )
    if clock.shown:
        print(clock.text(), file=sys.stderr)
    if note:  # the record is published, but the page a reader opens is not: never exit 0
        return EXIT_BAD_INPUT
    return EXIT_FAILED if exit_failed(rows, comparison) else EXIT_OK


def _print_summary(rows: list[dict], comparison: object, baseline: object) -> None:
    """The run's summary on stdout: the rich matrix, the headline and the news on a terminal,
    within its width; in a log (a
    CI's), the failing and new rows one per line and the compact matrix
    (``terminal.log_summary``)."""
    if sys.stdout.isatty():
        width = shutil.get_terminal_size().columns
        print(summary(rows, width=width, color=True))
        print("\n".join(counts_lines(rows, comparison, width)))
        print(news(rows, comparison, baseline, width))
    else:
        print(log_summary(rows, comparison, baseline))


def _written(
    output: Output,
    plan: Plan,
    request: RunRequest,
    executed: Executed,
    options: NightlyOptions,
    resumed: int,
) -> tuple[list[dict], object]:
    """The run's rows classified against the baseline, written with the record files
    (results, series, impacts, provenance, trace, sweep, the CI files); the rows and the
    baseline comparison."""
    rows = executed.rows + _sweep_rows(plan, executed)
    provenance = _provenance(executed.runs, request.argv)
    provenance["scenes"] = hashes = scene_hashes(plan)
    for scene, _ in plan.scenes:  # what a scene card says first, and its closed forms
        hashes[scene.name] = {
            **hashes[scene.name],
            "description": scene.scenario.description,
            "expect": expectation_records(scene.scenario.expect),
            "engine_notes": _engine_notes(executed.runs, scene.name),
        }
    provenance["selection"] = run_selection(
        request.paths, request.cwd, request.only, request.engines, request.dt, plan
    )
    if resumed:
        total = len(plan.jobs) + len(_sweep_work(plan))
        provenance["resumed"] = {"jobs_from_journal": resumed, "jobs_run": total - resumed}
    rows, comparison = against_baseline(
        rows, options, hashes, output.run_folder, provenance["selection"]
    )
    write_run(
        output.run_folder, rows, executed.series, executed.impacts, provenance, executed.traces
    )
    if executed.sweep_rows:
        write_table(executed.sweep_rows, output.run_folder / SWEEP_FILE)
    write_ci_files(rows, options, comparison)
    return rows, comparison


RUN_STATUSES = (
    "ok",
    "model_mismatch",
    "unstable",
    "error",
    "crashed",
    "timed_out",
    "unsupported",
    "not_installed",
)
"""An engine run's statuses (``validation.measure.runner``)."""

RECORDED_STATUSES = ("ok", "unstable")
"""Statuses of a run that has a recording."""

SWEEP_ROW_TEXT = ("scenario", "engine", "metric")
"""Cells every sweep row has, as text (``nightly_run.sweep_result_rows`` reads them)."""


def _journaled(journal: Journal, plan: Plan) -> dict:
    """Index -> result of the plan's jobs the journal holds, each checked to be of its job
    (``JournalError``, as ``BadInputError``, naming the record's file and field)."""
    ids = job_ids(plan)
    try:
        done = journal.finished(ids)
    except JournalError as error:
        raise BadInputError(f"--resume: {error}") from None
    for index, result in done.items():
        problem = RESULT_CHECKS[ids[index].kind](ids[index], result)
        if problem:
            raise BadInputError(f"--resume: {journal.record_path(ids[index])}: {problem}")
    return done


def _run_problem(job: JobId, result: tuple[EngineRun, list[Measurement]]) -> str:
    """What makes a run's record not its job's, or not a run that can be (empty if none)."""
    run, _ = result
    if (run.scenario, run.engine) != (job.scene, job.engine):
        return f"[1][0]: a run of {run.scenario} in {run.engine}; the plan's job {job.index} is {job.scene} in {job.engine}"
    if run.status not in RUN_STATUSES:
        return f"[1][0].status: expected one of {', '.join(RUN_STATUSES)}; got {run.status!r}"
    if (run.recording is not None) != (run.status in RECORDED_STATUSES):
        return f"[1][0].recording: a run of status {run.status} {'has' if run.recording is None else 'has no'} recording"
    return ""


def _sweep_problem(job: JobId, rows: list[dict]) -> str:
    """What makes a sweep's record not its job's (empty if none)."""
    for i, row in enumerate(rows):
        for key in SWEEP_ROW_TEXT:
            if not isinstance(row.get(key), str):
                return f"[1][{i}].{key}: expected text; got {row.get(key)!r}"
        if row["scenario"] != job.scene:
            return f"[1][{i}].scenario: expected {job.scene!r} (the plan's job {job.index}); got {row['scenario']!r}"
        needs = "of" if row["metric"] in ("convergence_order", "reference_cross_check") else "dt"
        if row["metric"] in SWEEP_METRICS or needs == "of":
            kind = str if needs == "of" else (int, float)
            if not isinstance(row.get(needs), kind) or isinstance(row.get(needs), bool):
                return f"[1][{i}].{needs}: missing or of the wrong type; got {row.get(needs)!r}"
    return ""


RESULT_CHECKS = {"run": _run_problem, "sweep": _sweep_problem}
"""Job kind -> what makes a journaled result of it not its job's (``_journaled``)."""


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
    clock: PhaseClock | None = None,
    job_timeout: float | None = None,
    extra_files: dict[str, str] | None = None,
    sweeps: bool = True,
    raise_refusals: bool = False,
    summary_file: Path | None = None,
) -> int:
    """The whole job (on the Dask cluster at ``scheduler`` when given); returns the exit code (0 nothing regressed and no new failure: every
    failing row is a known finding or, against a baseline, failed there too; 1 a regression
    or a new failure; 2 bad input, a refused output folder, or an output that failed while
    writing). ``clock``: times the phases (``phases.PhaseClock``; printed on stderr at the
    end when it is ``shown``, ``--timings``). ``extra_files``: file name -> text, written into
    the run folder with the record (``RUN_FOLDER_FILES`` must name each: ``physval sim2sim``'s
    scene). ``sweeps``: whether the scenes' own sweeps run (``--sweeps``).
    ``raise_refusals``: raise a refusal (``BadInputError``, ``BackendError``, the write's
    ``OSError``) instead of printing it and returning 2 (``physval.run``).
    ``summary_file``: ``--summary FILE``, the run's Markdown summary (``jobs.summary``)."""
    clock = PhaseClock() if clock is None else clock
    try:
        check_summary_target(summary_file)
        if resume is not None:
            return _resume_main(
                resume, jobs, scheduler, junit, history, clock, job_timeout, summary_file
            )
        with clock.phase("planning"):
            request, plan = _planned(
                paths, engines, out, dt, only, argv, baseline, junit, history, sweeps
            )
            check_inside(request.destination, "--summary", summary_file)
            if scheduler is None:  # on a cluster the workers' memory is the cluster's
                check_memory(plan, jobs, _sample_every)
        with claim(request.destination) as output:
            with clock.phase("planning"):
                header = _header(request, plan)
                journal = Journal.create(output.journal_folder, header, JOURNAL_SCHEMA)
            return _finish(
                output,
                journal,
                plan,
                request,
                jobs,
                scheduler,
                clock=clock,
                job_timeout=job_timeout,
                extra_files=extra_files,
                summary_file=summary_file,
            )
    except (BadInputError, BackendError) as error:
        if raise_refusals:
            raise
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:  # a full disk, a folder made read-only mid-run
        if raise_refusals:
            raise
        print(
            f"cannot write the run: {error}; the finished jobs are kept in its journal "
            "(physval run --resume DIR finishes it)",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT


def _planned(paths, engines, out, dt, only, argv, baseline, junit, history, sweeps):
    """The run's request (its flags checked before any work) and its plan."""
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
        sweeps,
    )
    request.nightly()  # the flags checked before any work
    return request, request.plan()


def _resume_main(
    destination: Path,
    jobs: int,
    scheduler: str | None = None,
    junit: str | None = None,
    history: str | None = None,
    clock: PhaseClock | None = None,
    job_timeout: float | None = None,
    summary_file: Path | None = None,
) -> int:
    """``--resume DIR``: the journal read, its header checked and its request run writing only
    to DIR and to this command line's ``junit`` and ``history``, before any work."""
    with claim(destination, resume=True) as output:
        clock = PhaseClock() if clock is None else clock
        with clock.phase("planning"):
            try:
                journal = Journal.open(output.journal_folder, JOURNAL_SCHEMA)
            except JournalError as error:
                raise BadInputError(f"--resume {destination}: {error}") from None
            request, plan = _resumed(journal, destination, junit, history)
            if scheduler is None:
                check_memory(plan, jobs, _sample_every)
        keep_copy = journal.header["request"]["out"] is None
        return _finish(
            output,
            journal,
            plan,
            request,
            jobs,
            scheduler,
            keep_copy,
            clock,
            job_timeout,
            summary_file=summary_file,
        )
