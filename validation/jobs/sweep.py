"""``physval sweep``: error against run time over a timestep sweep, for any scene and engine.

For each scene, engine spec and dt the sweep records the scene's error against its
best available reference, the wall time of stepping alone, steps per second, the
real-time factor and the status (unstable points are kept, never dropped). References,
in order of preference, named in every row's ``expected_kind``:

1. ``analytic``: the ballistic trajectory (``position_error``) where nothing touches and
   no spring acts, else the scene's first analytic expectation;
2. ``engine:mujoco(integrator=RK4)@<dt>``: for scenes without contact, MuJoCo's RK4 at a
   tenth of the smallest swept step (4th order: far below the first-order errors swept);
3. ``self:<spec>@<dt>``: the same engine at a quarter of the smallest swept step, as Erez,
   Tassa and Todorov do: the run is cut into ``SEGMENTS`` segments; each segment restarts
   both the swept step and the fine step from the fine run's state at its start, and the
   error is the mean over segments of the largest centre-of-mass distance at the segment's
   end, so chaotic divergence of two whole runs is not counted as error.

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
from validation.jobs.executor import run_jobs
from validation.jobs.plan import BadInputError, plan_run
from validation.measure.metrics import Context, measure
from validation.measure.runner import EngineRun, run_engine
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

DEFAULT_ENGINES = (
    "mini, mini(gyroscopic=explicit), mini(gyroscopic=implicit), mini(integrator=explicit_euler), "
    "mujoco, mujoco(integrator=implicitfast), mujoco(integrator=RK4), pybullet"
)
"""What a sweep compares unless ``--engines`` says otherwise: the documented formulas and
their named options against MuJoCo's three integrators and PyBullet, so the plots show what
the documented engine costs in accuracy against what the reference engines do."""


class GridError(ValueError):
    """A --dt grid that cannot be read."""


def parse_dt_grid(text: str) -> list[float]:
    """``"1e-1:1e-5:9"`` -> 9 log-spaced steps from 0.1 to 1e-5 s; ``"1e-3,5e-4"`` -> a list."""
    try:
        if ":" in text:
            start, stop, count = text.split(":")
            values = np.logspace(
                math.log10(float(start)), math.log10(float(stop)), int(count)
            ).tolist()
        else:
            values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise GridError(
            f"--dt: expected START:STOP:COUNT or a comma list of seconds; got {text!r}"
        ) from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise GridError(f"--dt: expected positive finite steps; got {text!r}")
    return values


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
    if not _can_touch(scenario) and not scenario.springs:
        return Reference("analytic:position_error")
    if scenario.expect:
        return Reference(f"analytic:{scenario.expect[0].metric}")
    if not _can_touch(scenario):
        dt = max(smallest_dt / REFINE_REFERENCE, scenario.duration / MAX_STEPS)
        fine = _run(scene_at(scenario, dt), parse_engine_spec(HIGH_ACCURACY), _every(scenario, dt))
        return Reference(f"engine:{HIGH_ACCURACY}@{dt!r}", fine, dt)
    dt = max(smallest_dt / REFINE_SELF, scenario.duration / MAX_STEPS)
    fine = _run(scene_at(scenario, dt), spec, _every(scenario, dt))
    return Reference(f"self:{spec.label}@{dt!r}", fine, dt)


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


def _end_position(scenario: Scenario, spec: EngineSpec) -> np.ndarray | None:
    run = _run(scenario, spec, max(1, scenario.steps))
    if run.status != "ok" or run.recording is None:
        return None
    return run.recording.trajectory.pos[-1]


def _position_at(scenario: Scenario, spec: EngineSpec, time: float) -> np.ndarray | None:
    """Body positions (n, 3) at ``time``, interpolated between the run's per-step samples."""
    run = _run(scenario, spec, 1)
    if run.status != "ok" or run.recording is None:
        return None
    traj = run.recording.trajectory
    return np.stack(
        [
            [np.interp(time, traj.t, traj.pos[:, b, a]) for a in range(3)]
            for b in range(traj.pos.shape[1])
        ]
    )


def segment_error(scenario: Scenario, spec: EngineSpec, dt: float, reference: Reference) -> float:
    """Mean over segments of the end-of-segment COM distance between ``dt`` and the fine step,
    both restarted from the fine run's state at the segment's start."""
    fine = reference.run.recording.trajectory
    fine_dt = reference.dt
    length = scenario.duration / SEGMENTS
    errors = []
    for k in range(SEGMENTS):
        sample = int(np.argmin(np.abs(fine.t - k * length)))
        coarse = restarted(scenario, fine, sample, dt, length)
        coarse_end = _end_position(coarse, spec)
        end_time = coarse.steps * coarse.dt  # compare both at exactly this time
        fine_end = _position_at(
            restarted(scenario, fine, sample, fine_dt, end_time + fine_dt), spec, end_time
        )
        if coarse_end is None or fine_end is None:
            return math.inf
        errors.append(float(np.linalg.norm(coarse_end - fine_end, axis=1).max()))
    return float(np.mean(errors))


def point_error(
    scenario: Scenario, spec: EngineSpec, run: EngineRun, reference: Reference
) -> float:
    """The error of one sweep point against ``reference`` (units of the reference's metric)."""
    if reference.kind.startswith("analytic:"):
        metric = reference.kind.split(":", 1)[1]
        found = [
            m
            for m in measure(Context(compile_scene(scenario), run.recording))
            if m.metric == metric
        ]
        return found[0].error if found else math.nan
    if reference.run is None or reference.run.status != "ok":
        return math.nan  # an unstable or failed reference measures nothing (see its message)
    if reference.kind.startswith("self:"):
        return segment_error(scenario, spec, scenario.dt, reference)
    mine, theirs = run.recording.trajectory, reference.run.recording.trajectory
    error = 0.0
    for body in range(mine.pos.shape[1]):  # the reference interpolated at this run's samples
        theirs_at = np.stack(
            [np.interp(mine.t, theirs.t, theirs.pos[:, body, a]) for a in range(3)], axis=1
        )
        error = max(error, float(np.linalg.norm(mine.pos[:, body] - theirs_at, axis=1).max()))
    return error


def sweep_point(scenario: Scenario, spec: EngineSpec, dt: float, reference: Reference) -> dict:
    """One row: the scene at ``dt`` in ``spec``."""
    probe = scene_at(scenario, dt)
    row = {
        "scenario": scenario.name,
        "engine": spec.label,
        "dt": dt,
        "steps": probe.steps,
        "metric": "sweep_error",
        "expected_kind": reference.kind,
    }
    if probe.steps < 1 or probe.steps > MAX_STEPS:
        return {**row, "status": "unsupported", "message": f"{probe.steps} steps is out of range"}
    run = _run(probe, spec, _every(probe, dt))
    seconds = stepping_seconds(probe, spec) if run.status == "ok" else math.nan
    error = point_error(probe, spec, run, reference) if run.recording is not None else math.nan
    return {
        **row,
        "value": error,
        "error": error,
        "status": run.status,
        "wall_time_s": seconds,
        "steps_per_second": probe.steps / seconds if seconds > 0 else math.nan,
        "real_time_factor": probe.duration / seconds if seconds > 0 else math.nan,
        "engine_version": run.provenance.version if run.provenance else "",
        "message": run.message,
    }


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
    """Every dt of one (scene, engine) pair, plus its fitted convergence order."""
    scenario, spec, dts = job
    reference = choose_reference(scenario, spec, min(dts))
    rows = [sweep_point(scenario, spec, dt, reference) for dt in dts]
    order = convergence_order(rows)
    rows.append(
        {
            "scenario": scenario.name,
            "engine": spec.label,
            "metric": "convergence_order",
            "value": order,
            "expected_kind": reference.kind,
            "status": "ok" if np.isfinite(order) else "unsupported",
        }
    )
    return rows


def run_sweep(jobs: list[tuple[Scenario, EngineSpec, list[float]]], workers: int) -> list[dict]:
    """All jobs through the executor (one (scene, engine) dt grid per job: a job is worth
    shipping to a worker); rows in job order."""
    return [row for rows in run_jobs(sweep_scene, jobs, workers) for row in rows]


def sweep_main(
    paths: list[Path], engines: str | None, only: str | None, dt: str, jobs: int, out: Path | None
) -> int:
    """``physval sweep``: the sweep of every planned (scene, engine); sweep.csv and sweep.html."""
    try:
        grid = parse_dt_grid(dt)
        plan = plan_run(paths, engines or DEFAULT_ENGINES, None, only)
    except (BadInputError, GridError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    rows = run_sweep([(scene.scenario, spec, grid) for scene, spec in plan.jobs], jobs)
    out = out or Path("reports") / "sweep"
    out.mkdir(parents=True, exist_ok=True)
    write_table(rows, out / "sweep.csv")
    render_sweep(rows, out / "sweep.html")
    print(f"{len(rows)} rows -> {out / 'sweep.csv'}, {out / 'sweep.html'}")
    return EXIT_OK
