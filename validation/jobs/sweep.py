"""``physval sweep``: error against run time over a timestep sweep, for any scene and engine.

For each scene, engine spec and dt the sweep records two errors that see the whole state
(``SWEEP_METRICS``): ``position_error``, the largest distance over time and bodies of a
centre of mass from the reference's, and ``orientation_error``, the largest rotation angle
|log(R_refᵀ R)| between a body's orientation and the reference's; with the wall time of
stepping alone, steps per second, the real-time factor, the status (unstable points are
kept, never dropped) and the scene's own metrics at that dt (one column each). References,
named in every row's ``expected_kind``:

1. ``dop853``: for scenes where nothing can touch, the Newton–Euler equations integrated by
   SciPy's DOP853 at rtol 1e-12 (``validation.measure.newton_euler``), independent of every
   engine. MuJoCo's RK4 at a tenth of the smallest step is run as a cross-check of it (row
   ``reference_cross_check``);
2. ``analytic:<expectation>``: scenes that can touch and state an expectation: its error
   (the expectation constrains a position or a velocity, not an orientation);
3. ``self:<spec>@<dt>``: the same engine at a quarter of the smallest swept step, as Erez,
   Tassa and Todorov do: the run is cut into ``SEGMENTS`` segments; each segment restarts
   both the swept step and the fine step from the fine run's state at its start, and the
   error is the mean over segments of the largest distance (angle) at the segment's end, so
   chaotic divergence of two whole runs is not counted as error.

A curve that is zero at every dt says the reference cannot see that motion (a body whose
centre never moves, an orientation no analytic expectation constrains): its points carry
the note ``IDENTICALLY_ZERO`` and the page prints it instead of a curve.

Stepping time: a separate pass per point: load, ``WARMUP_STEPS``, then the median of
``REPEATS`` blocks of ``BLOCK_STEPS`` (recording and observation excluded).
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.engines.registry import create_adapter
from validation.files import write_table
from validation.jobs.executor import BackendError, run_jobs
from validation.jobs.output import check_folder_destination, check_room, locked
from validation.jobs.plan import (
    BadInputError,
    expected_cost,
    plan_run,
    step_ratio,
    steps_in_range,
)
from validation.measure.metrics import Context, measure
from validation.measure.runner import EngineRun, run_engine
from validation.reference.newton_euler import reference_motion
from validation.reference.rotation import rotation_angle
from validation.report.sweep_page import render_sweep
from validation.scenario import MAX_STEPS, Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import EngineSpec, parse_engine_spec
from validation.scenario.schema import scene_at

WARMUP_STEPS = 20
BLOCK_STEPS = 100
REPEATS = 5
"""Timing: after 20 warm-up steps, the median of 5 blocks of 100 steps (or of the whole run
when it is shorter), so one slow block on a shared machine does not move the point."""

SAMPLES = 500
"""Trajectory samples per point: enough for the metrics, cheap to keep."""

REFINE_SELF = 4.0
REFINE_REFERENCE = 10.0
SEGMENTS = 4

HIGH_ACCURACY = "mujoco(integrator=RK4)"
"""The cross-check of the DOP853 reference: MuJoCo's RK4 at a tenth of the smallest step."""

SWEEP_METRICS = ("position_error", "orientation_error")
"""The two errors of every sweep point (module docstring), defined once (and in the legend)."""

SCENE_METRIC_PREFIX = "scene:"
"""Columns of a sweep row holding the scene's own metrics at that dt (``scene:energy_drift``)."""

IDENTICALLY_ZERO = "identically zero at every dt: the reference cannot see this motion"
"""The note of a curve that measures nothing."""

ROUND_OFF_ERROR = 1e-9
"""m or rad. A curve whose every point is below this is at round-off: the scheme is exact on
the scene (RK4 on a constant load), and a slope fitted through round-off means nothing. A
double-precision state of metre size accumulates about 1e5 steps x 2.2e-16 = 2e-11 over a
sweep's longest run; the smallest truncation error a library sweep resolves (first order,
dt = 1e-4) is about 1e-5."""

AT_ROUND_OFF = f"at round-off (<= {ROUND_OFF_ERROR:g}) at every dt: exact on this scene, no order"
"""The note of a curve at round-off (drawn: exactness is a result; no order fitted)."""

DEFAULT_ENGINES = (
    "mini, mini(gyroscopic=explicit), mini(gyroscopic=implicit), mini(integrator=explicit_euler), "
    "mujoco, mujoco(integrator=implicitfast), mujoco(integrator=RK4), pybullet"
)
"""What a sweep compares unless ``--engines`` says otherwise: the documented formulas and
their named options against MuJoCo's three integrators and PyBullet, so the plots show what
the documented engine costs in accuracy against what the reference engines do."""


MAX_GRID_POINTS = 200
"""Steps a --dt grid may have: every point is a run of every scene in every engine (plus its
timing pass), so 200 points of the library already take hours; the default grid has 5."""

NO_REFERENCE = "none: every dt out of range"
"""The reference of a (scene, engine) none of whose points can run: nothing is compared."""


class GridError(ValueError):
    """A --dt grid that cannot be read."""


def _grid_values(text: str) -> list[float]:
    if ":" not in text:
        values = [float(part) for part in text.split(",") if part.strip()]
        if len(values) > MAX_GRID_POINTS:
            raise GridError(
                f"--dt: {len(values)} steps; at most {MAX_GRID_POINTS} (MAX_GRID_POINTS)"
            )
        return values
    start, stop, count = text.split(":")
    points = int(count)
    if not 1 <= points <= MAX_GRID_POINTS:
        raise GridError(
            f"--dt: expected a COUNT of 1 to {MAX_GRID_POINTS} (MAX_GRID_POINTS); got {points}"
        )
    low, high = float(start), float(stop)
    if not (math.isfinite(low) and math.isfinite(high) and low > 0 and high > 0):
        raise GridError(f"--dt: expected positive finite steps; got {text!r}")
    return np.logspace(math.log10(low), math.log10(high), points).tolist()


def parse_dt_grid(text: str) -> list[float]:
    """``"1e-1:1e-5:9"`` -> 9 log-spaced steps from 0.1 to 1e-5 s; ``"1e-3,5e-4"`` -> a list;
    at most ``MAX_GRID_POINTS`` (checked before the grid is made)."""
    try:
        values = _grid_values(text)
    except ValueError as error:
        if isinstance(error, GridError):
            raise
        raise GridError(
            f"--dt: expected START:STOP:COUNT or a comma list of seconds; got {text!r}"
        ) from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise GridError(f"--dt: expected positive finite steps; got {text!r}")
    return values


def runnable(scenario: Scenario, dts: list[float]) -> list[float]:
    """The steps of ``dts`` at which ``scenario`` has 1 to ``MAX_STEPS`` steps."""
    return [dt for dt in dts if steps_in_range(scenario.duration, dt)]


def reference_problems(jobs: list[tuple[Scenario, EngineSpec, list[float]]]) -> list[str]:
    """Each scene whose reference run (the same engine at a quarter of the smallest runnable
    step, or MuJoCo RK4 at a tenth of it for the DOP853 cross-check) would exceed
    ``MAX_STEPS``: refused before any work rather than run for hours."""
    problems = []
    for scenario, _, dts in jobs:
        steps = runnable(scenario, dts)
        if not steps:
            continue
        touch = _can_touch(scenario)
        if touch and scenario.expect:
            continue  # an analytic reference: nothing is run
        refine = REFINE_SELF if touch else REFINE_REFERENCE
        if not steps_in_range(scenario.duration, min(steps) / refine):
            problem = (
                f"--dt: {scenario.name}'s reference at {min(steps)!r} s / {refine:g} would take "
                f"{step_ratio(scenario.duration * refine, min(steps)):.3g} steps; at most {MAX_STEPS} "
                "(MAX_STEPS): give a larger smallest step"
            )
            if problem not in problems:
                problems.append(problem)
    return problems


@dataclass(frozen=True)
class Reference:
    """What a sweep point's error is measured against."""

    kind: str
    run: EngineRun | None = None
    dt: float | None = None
    """s, the reference run's step (engine and self-consistency references)."""


def stepping_seconds(scenario: Scenario, spec: EngineSpec) -> float:
    """Wall time (s) of the stepping alone for the whole run, from a separate timed pass."""
    adapter = create_adapter(spec)
    try:
        adapter.load(compile_scene(scenario))
        warmup = min(WARMUP_STEPS, scenario.steps // (REPEATS + 1))
        adapter.advance(warmup)
        block = max(1, min(BLOCK_STEPS, (scenario.steps - warmup) // REPEATS))
        samples = []
        for _ in range(REPEATS):
            start = time.perf_counter()
            adapter.advance(block)
            samples.append((time.perf_counter() - start) / block)
        return statistics.median(samples) * scenario.steps
    finally:
        adapter.close()


def _can_touch(scenario: Scenario) -> bool:
    return compile_scene(scenario).can_touch


def _run(scenario: Scenario, spec: EngineSpec, sample_every: int) -> EngineRun:
    """``run_engine`` on a derived scene (another dt, a restart), compiled here."""
    return run_engine(compile_scene(scenario), spec, sample_every)


def choose_reference(scenario: Scenario, spec: EngineSpec, smallest_dt: float) -> Reference:
    """The best reference this scene offers (module docstring)."""
    if not _can_touch(scenario):
        return Reference("dop853")
    if scenario.expect:
        return Reference(f"analytic:{scenario.expect[0].metric}")
    dt = smallest_dt / REFINE_SELF  # within MAX_STEPS: ``reference_problems``
    fine = _run(scene_at(scenario, dt), spec, _every(scenario, dt))
    return Reference(f"self:{spec.label}@{dt!r}", fine, dt)


def cross_check(scenario: Scenario, smallest_dt: float) -> list[dict]:
    """The DOP853 reference against MuJoCo's RK4 at a tenth of the smallest step: the largest
    position and orientation differences over the run (a row for each, ``of`` names it)."""
    dt = smallest_dt / REFINE_REFERENCE  # within MAX_STEPS: ``reference_problems``
    row = {
        "scenario": scenario.name,
        "engine": HIGH_ACCURACY,
        "dt": dt,
        "metric": "reference_cross_check",
        "expected_kind": "dop853",
    }
    run = _run(scene_at(scenario, dt), parse_engine_spec(HIGH_ACCURACY), _every(scenario, dt))
    if run.recording is None or run.status != "ok":
        return [
            {**row, "of": m, "status": run.status, "message": run.message} for m in SWEEP_METRICS
        ]
    errors = _against_motion(compile_scene(scenario), run.recording.trajectory)
    return [
        {
            **row,
            "of": m,
            "value": errors[m],
            "error": errors[m],
            "status": "ok",
            "message": "MuJoCo RK4 against the DOP853 reference",
        }
        for m in SWEEP_METRICS
    ]


def _against_motion(scene, trajectory) -> dict[str, float]:
    """Both sweep errors of ``trajectory`` against the DOP853 motion at its own times."""
    reference = reference_motion(scene, trajectory.t)
    return {
        "position_error": float(np.linalg.norm(trajectory.pos - reference.pos, axis=2).max()),
        "orientation_error": float(rotation_angle(trajectory.quat, reference.quat).max()),
    }


def _every(scenario: Scenario, dt: float) -> int:
    return max(1, round(scenario.duration / dt) // SAMPLES)


def restarted(scenario: Scenario, trajectory, sample: int, dt: float, duration: float) -> Scenario:
    """The scene started from ``trajectory``'s state at ``sample``, run for ``duration`` at ``dt``."""
    data = scenario.model_dump()
    for i, body in enumerate(data["bodies"]):
        body["position"] = trajectory.pos[sample, i].tolist()
        quat = trajectory.quat[sample, i]
        body["orientation"] = (quat / np.linalg.norm(quat)).tolist()
        body["velocity"] = trajectory.vel[sample, i].tolist()
        body["angular_velocity"] = trajectory.ang_vel[sample, i].tolist()
    data.update(dt=dt, duration=duration, source=scenario.source)
    return Scenario.model_validate(data)


def _end_state(scenario: Scenario, spec: EngineSpec) -> tuple[np.ndarray, np.ndarray] | None:
    run = _run(scenario, spec, max(1, scenario.steps))
    if run.status != "ok" or run.recording is None:
        return None
    return run.recording.trajectory.pos[-1], run.recording.trajectory.quat[-1]


def _state_at(scenario: Scenario, spec: EngineSpec, time: float):
    """Positions (n, 3) at ``time`` interpolated between the run's per-step samples, and the
    orientations (n, 4) of the sample nearest to it."""
    run = _run(scenario, spec, 1)
    if run.status != "ok" or run.recording is None:
        return None
    traj = run.recording.trajectory
    pos = np.stack(
        [
            [np.interp(time, traj.t, traj.pos[:, b, a]) for a in range(3)]
            for b in range(traj.pos.shape[1])
        ]
    )
    return pos, traj.quat[int(np.argmin(np.abs(traj.t - time)))]


def segment_error(
    scenario: Scenario, spec: EngineSpec, dt: float, reference: Reference
) -> dict[str, float]:
    """Mean over segments of the end-of-segment distance and rotation angle between ``dt`` and
    the fine step, both restarted from the fine run's state at the segment's start."""
    fine = reference.run.recording.trajectory
    length = scenario.duration / SEGMENTS
    positions, angles = [], []
    for k in range(SEGMENTS):
        sample = int(np.argmin(np.abs(fine.t - k * length)))
        coarse = restarted(scenario, fine, sample, dt, length)
        coarse_end = _end_state(coarse, spec)
        end_time = coarse.steps * coarse.dt  # compare both at exactly this time
        fine_end = _state_at(
            restarted(scenario, fine, sample, reference.dt, end_time + reference.dt),
            spec,
            end_time,
        )
        if coarse_end is None or fine_end is None:
            return dict.fromkeys(SWEEP_METRICS, math.inf)
        positions.append(float(np.linalg.norm(coarse_end[0] - fine_end[0], axis=1).max()))
        angles.append(float(rotation_angle(coarse_end[1], fine_end[1]).max()))
    return {
        "position_error": float(np.mean(positions)),
        "orientation_error": float(np.mean(angles)),
    }


def point_errors(
    scenario: Scenario, spec: EngineSpec, run: EngineRun, reference: Reference
) -> dict[str, float]:
    """Both sweep errors of one point against ``reference`` (NaN where it cannot say)."""
    if reference.kind == "dop853":
        return _against_motion(compile_scene(scenario), run.recording.trajectory)
    if reference.kind.startswith("analytic:"):
        metric = reference.kind.split(":", 1)[1]
        found = [m for m in _scene_metrics(scenario, run) if m.metric == metric]
        position = found[0].error if found else math.nan
        return {"position_error": position, "orientation_error": math.nan}
    if reference.run is None or reference.run.status != "ok":
        return dict.fromkeys(SWEEP_METRICS, math.nan)  # an unstable reference measures nothing
    return segment_error(scenario, spec, scenario.dt, reference)


def _scene_metrics(scenario: Scenario, run: EngineRun) -> list:
    return measure(Context(compile_scene(scenario), run.recording))


def sweep_point(
    scenario: Scenario, spec: EngineSpec, dt: float, reference: Reference
) -> list[dict]:
    """The rows of the scene at ``dt`` in ``spec``: one per sweep metric, each with the
    scene's own metrics at that dt as columns."""
    common = {
        "scenario": scenario.name,
        "engine": spec.label,
        "dt": dt,
        "expected_kind": reference.kind,
    }
    if not steps_in_range(scenario.duration, dt):
        steps = step_ratio(scenario.duration, dt)
        message = f"{steps:.3g} steps (duration / dt) is out of range: 1 to {MAX_STEPS}"
        return [
            {**common, "steps": steps, "metric": m, "status": "unsupported", "message": message}
            for m in SWEEP_METRICS
        ]
    probe = scene_at(scenario, dt)
    common["steps"] = probe.steps
    run = _run(probe, spec, _every(probe, dt))
    seconds = stepping_seconds(probe, spec) if run.status == "ok" else math.nan
    errors = (
        point_errors(probe, spec, run, reference)
        if run.recording is not None
        else dict.fromkeys(SWEEP_METRICS, math.nan)
    )
    own = (
        {f"{SCENE_METRIC_PREFIX}{m.metric}": m.value for m in _scene_metrics(probe, run)}
        if run.recording is not None
        else {}
    )
    timing = {
        "status": run.status,
        "wall_time_s": seconds,
        "steps_per_second": probe.steps / seconds if seconds > 0 else math.nan,
        "real_time_factor": probe.duration / seconds if seconds > 0 else math.nan,
        "engine_version": run.provenance.version if run.provenance else "",
        "message": run.message,
    }
    return [
        {**common, "metric": m, "value": errors[m], "error": errors[m], **timing, **own}
        for m in SWEEP_METRICS
    ]


def convergence_order(rows: list[dict]) -> float:
    """Least-squares slope of log(error) against log(dt) over the stable, non-zero points."""
    points = [
        (r["dt"], r["error"])
        for r in rows
        if r.get("status") == "ok" and np.isfinite(r.get("error", np.nan)) and r["error"] > 0
    ]
    if len(points) < 2:
        return math.nan
    dts, errors = np.log(np.array(points)).T
    return float(np.polyfit(dts, errors, 1)[0])


def sweep_scene(job: tuple[Scenario, EngineSpec, list[float]]) -> list[dict]:
    """Every dt of one (scene, engine) pair, plus each sweep metric's fitted convergence
    order (or the note that the curve is identically zero)."""
    scenario, spec, dts = job
    steps = runnable(scenario, dts)
    reference = choose_reference(scenario, spec, min(steps)) if steps else Reference(NO_REFERENCE)
    rows = [row for dt in dts for row in sweep_point(scenario, spec, dt, reference)]
    for metric in SWEEP_METRICS:
        mine = [r for r in rows if r["metric"] == metric]
        measured = [
            r for r in mine if r.get("status") == "ok" and np.isfinite(r.get("error", np.nan))
        ]
        zero = bool(measured) and all(r["error"] == 0.0 for r in measured)
        exact = bool(measured) and not zero and all(r["error"] <= ROUND_OFF_ERROR for r in measured)
        for r in mine if zero else ():
            r["message"] = IDENTICALLY_ZERO
        order = math.nan if exact else convergence_order(mine)
        note = IDENTICALLY_ZERO if zero else AT_ROUND_OFF if exact else ""
        rows.append(
            {
                "scenario": scenario.name,
                "engine": spec.label,
                "metric": "convergence_order",
                "of": metric,
                "value": order,
                "expected_kind": reference.kind,
                "status": "ok" if np.isfinite(order) else "unsupported",
                "message": note,
            }
        )
    return rows


def sweep_job(job: tuple[Scenario, EngineSpec | None, list[float]]) -> list[dict]:
    """One (scene, engine) dt grid, or (engine None) the cross-check of a scene's reference."""
    scenario, spec, dts = job
    return cross_check(scenario, min(runnable(scenario, dts))) if spec is None else sweep_scene(job)


def sweep_cost(job: tuple[Scenario, EngineSpec | None, list[float]]) -> float:
    """A sweep job's expected cost (``plan.expected_cost`` over its grid): the executor
    starts the longest grids first."""
    scenario, _, dts = job
    return expected_cost(scenario, dts)


def lost_sweep_job(
    job: tuple[Scenario, EngineSpec | None, list[float]], message: str
) -> list[dict]:
    """The rows of a sweep job the cluster lost (``executor.run_jobs``): status ``error`` at
    every dt of the grid and for each fitted order, per sweep metric (one row per metric for
    a cross-check), so the lost job is seen where its rows would be."""
    scenario, spec, dts = job
    if spec is None:
        common = {"engine": HIGH_ACCURACY, "metric": "reference_cross_check"}
        dt = min(runnable(scenario, dts)) / REFINE_REFERENCE
        points = [{"dt": dt, "of": m} for m in SWEEP_METRICS]
    else:
        common = {"engine": spec.label}
        points = [{"dt": dt, "metric": m} for dt in dts for m in SWEEP_METRICS]
        points += [{"metric": "convergence_order", "of": m} for m in SWEEP_METRICS]
    return [
        {"scenario": scenario.name, **common, **point, "status": "error", "message": message}
        for point in points
    ]


def run_sweep(
    jobs: list[tuple[Scenario, EngineSpec, list[float]]],
    workers: int,
    scheduler: str | None = None,
) -> list[dict]:
    """All jobs through the executor (one (scene, engine) dt grid per job: a job is worth
    shipping to a worker), plus one cross-check per scene with a DOP853 reference; rows in
    job order. ``scheduler``: on that Dask cluster (``executor.run_jobs``)."""
    found = run_jobs(
        sweep_job,
        with_cross_checks(jobs),
        workers,
        None,
        scheduler,
        lost_sweep_job,
        sweep_cost,
    )
    return [row for rows in found for row in rows]


def with_cross_checks(
    jobs: list[tuple[Scenario, EngineSpec, list[float]]],
) -> list[tuple[Scenario, EngineSpec | None, list[float]]]:
    """The jobs, then one cross-check job (engine None) per scene with a DOP853 reference."""
    scenes = {id(scenario): (scenario, dts) for scenario, _, dts in jobs}
    checks = [
        (s, None, dts) for s, dts in scenes.values() if not _can_touch(s) and runnable(s, dts)
    ]
    return [*jobs, *checks]


def sweep_main(
    paths: list[Path],
    engines: str | None,
    only: str | None,
    dt: str,
    jobs: int,
    out: Path | None,
    scheduler: str | None = None,
) -> int:
    """``physval sweep``: the sweep of every planned (scene, engine); sweep.csv and sweep.html."""
    try:
        grid = parse_dt_grid(dt)
        plan = plan_run(paths, engines or DEFAULT_ENGINES, None, only)
        work = [(scene.scenario, spec, grid) for scene, spec in plan.jobs]
        problems = reference_problems(work)
        if problems:
            raise BadInputError("\n".join(problems))
        out = out or Path("reports") / "sweep"
        check_folder_destination(out)
        check_room(out)
    except (BadInputError, GridError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        with locked(out):  # a second sweep on the same --out: exit 2 at once
            rows = run_sweep(work, jobs, scheduler)
            out.mkdir(parents=True, exist_ok=True)
            write_table(rows, out / "sweep.csv")  # each file written atomically
            render_sweep(rows, out / "sweep.html")
    except (BackendError, BadInputError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"{len(rows)} rows -> {out / 'sweep.csv'}, {out / 'sweep.html'}")
    return EXIT_OK
