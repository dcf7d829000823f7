"""``physval sweep``: error against run time over a timestep sweep, for any scene and engine.

For each scene, engine spec and dt the sweep records two errors that see the whole state
(``SWEEP_METRICS``): ``position_error``, the largest distance over time and bodies of a
centre of mass from the reference's, and ``orientation_error``, the largest rotation angle
|log(R_refᵀ R)| between a body's orientation and the reference's; with the wall time of
stepping alone, steps per second, the real-time factor, the status (unstable points are
kept, never dropped) and the scene's own metrics at that dt (one column each). References,
named in every row's ``expected_kind``:

1. ``dop853``: for scenes where nothing can touch, the Newton–Euler equations integrated by
   SciPy's DOP853 at rtol 3e-14 (``validation.reference.newton_euler``), independent of every
   engine; a scene with joints in its joint tree's coordinates (the Lagrange equations of the
   tree, ``validation.reference.articulated``), at the same tolerance. MuJoCo's RK4 at a tenth of the smallest step is run as a cross-check of it (row
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

The convergence order (``fit_order``) is fitted over the curve's asymptotic range only, in
three phases:

1. Each point gets a role (``fit_role`` in sweep.csv, ``FIT_ROLES``). ``unmeasured``: no
   finite positive error (a failed point, a NaN, a zero). ``floor``: its floor exceeds
   ``FLOOR_SHARE`` (a tenth) of its error; the floor is the larger of the round-off of its
   n steps on a state of size L, n x ``ROUND_OFF_PER_STEP`` x L (L: the largest centre
   distance from the origin, ``state_size``; 2 rad for the unit quaternion), and the
   reference's own error (``reference_floor``): DOP853's cross-check difference where the
   check's own round-off cannot explain it (the cross-check job's value, which each of the
   scene's jobs also reads), the fine run's
   (dt_fine / dt)^p share of the point's error for a self reference (p = 1,
   ``SELF_REFERENCE_ORDER``), 0 for an analytic expectation. ``saturated``: its error
   exceeds ``SATURATION_SHARE`` (half) of the largest it can be: pi for an angle, the
   reference motion's ``motion_extent`` for a position (unknown, so never saturated, for an
   analytic expectation's error).
2. The asymptotic range (``asymptotic_range``): from the smallest dt with a usable point,
   the contiguous usable points in dt order (a floor-bound, saturated or failed point ends
   it), cut where the local slopes between neighbours stop agreeing: as long as they spread
   by at most ``SLOPE_SPREAD`` (half an order). Its points are ``fitted``; usable points
   beyond it are ``outside``.
3. The order is the least-squares slope of log(error) on log(dt) over that range, reported
   with the range (``fit_dt_min``, ``fit_dt_max``, ``fit_points`` and the message,
   ``FITTED_OVER``). With fewer than ``MIN_FIT_POINTS`` (3) points there is no order: the
   value is NaN, the status ``unsupported`` and the message starts ``NOT_ASYMPTOTIC``. A
   curve zero at every dt, or at round-off at every dt (every error within its own point's
   round-off, ``round_off``: the measured size of the quantity x epsilon x steps, the
   ``round_off`` column of sweep.csv and of the page's points), gets its note instead
   (``IDENTICALLY_ZERO``, ``AT_ROUND_OFF``; its points are ``unmeasured``, ``floor``).
"""

from __future__ import annotations

import itertools
import math
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.engine_api import declaration_of
from validation.engines.registry import create_adapter
from validation.files import csv_written, page_written, write_table
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
from validation.report.sweep_page import (
    FIT_ROLES,
    FITTED,
    FLOOR,
    OUTSIDE,
    SATURATED,
    UNMEASURED,
    render_sweep,
)
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

AT_ROUND_OFF = "at round-off at every dt: exact on this scene, no order"
"""How the note of a curve at round-off begins: every error within its own point's round-off
(``round_off``), so the scheme is exact on the scene (RK4 on a constant load) and a slope
fitted through round-off means nothing (drawn: exactness is a result; no order fitted). The
note goes on with the largest round-off, ``ROUND_OFF_NOTE``."""

ROUND_OFF_NOTE = " (each error within its round-off, size x {eps:.2g} x steps: at most {floor:.3g})"
"""The rest of the ``AT_ROUND_OFF`` note: the measured floor the errors were compared with."""

ROUND_OFF_PER_STEP = float(np.finfo(float).eps)
"""Relative rounding one step leaves on a coordinate: a double's machine epsilon, 2.2e-16. A
point of n steps on a state of size L carries up to n x 2.2e-16 x L of round-off (the
one-signed sum; 1e5 steps of a metre-size state give 2e-11). Measured:
MuJoCo RK4 on the projectile, exact but for rounding, sits at 0.14 to 0.26 of it (5 points,
1e-2 to 1e-4 s, L = 5.09 m)."""

METRE_SIZE_STATE = 1.0
"""m (or rad): the state size assumed for a row that does not carry ``state_size``."""

ORIENTATION_STATE_SIZE = 2.0
"""rad: the size the orientation state counts as in its round-off: a unit quaternion, rounded
by epsilon relative to 1 per step, which turns the rotation angle (twice the quaternion's
half-angle) by 2 epsilon."""

FLOOR_SHARE = 0.1
"""A point is floor-bound when its floor (round-off, or the reference's own error) exceeds a
tenth of its error. Below that share the error is within 10 % of the scheme's own, so a local
slope between two such points is within ln(1.1 / 0.9) / ln r of the scheme's order over a
grid step of ratio r: 0.29 for a halving, 0.17 over half a decade, inside ``SLOPE_SPREAD``;
nearer its floor a point could pass the floor's slope (0) for part of the scheme's."""

SELF_REFERENCE_ORDER = 1.0
"""The order p assumed for a self reference's own error, (dt_fine / dt)^p of the point's: 1,
the lowest order of a consistent scheme (and every contact scheme's); at a higher order the
fine run's share is smaller, so a point kept at p = 1 is kept at any order."""

LARGEST_ANGLE = math.pi
"""rad: the largest rotation angle |log(R_refᵀ R)| there is: an orientation error cannot grow
past it (a Dzhanibekov flip displaced in time reads pi whatever the displacement)."""

SATURATION_SHARE = 0.5
"""A point is saturated when its error exceeds half the largest it can be (``LARGEST_ANGLE``,
or the reference motion's extent for a position): two copies of a periodic motion of extent
2A whose phases differ by d are 2A sin(d/2) apart, whose local order in d is (d/2)cot(d/2):
0.91 at half the extent (d = pi/3), 0 at the full one; above half, the fit would measure
the bound and not the scheme."""

SLOPE_SPREAD = 0.5
"""The asymptotic range's local slopes (log-error against log-dt between neighbours) may
spread by at most this: two schemes' orders differ by at least 1 (1, 2, 4), so slopes within
half of that of each other belong to one order; a wider spread is a change of regime
(round-off, saturation, pre-asymptotic behaviour at large dt)."""

MIN_FIT_POINTS = 3
"""Points an order needs: two always lie on a line, so their slope cannot show that the
curve is straight there; three are the fewest whose local slopes can be checked against each
other."""

FIT_RULE = (
    "Orders are fitted over each curve's asymptotic range only: from the smallest dt, the "
    f"points whose local slopes agree (spread at most {SLOPE_SPREAD:g}), leaving out floor-bound "
    "points (the round-off of their steps, or the reference's own error, above "
    f"{FLOOR_SHARE:g} of the error) and saturated ones (an error above {SATURATION_SHARE:g} of "
    "the largest it can be: pi rad, or the reference motion's extent); with fewer than "
    f"{MIN_FIT_POINTS} points there is no order."
)
"""The fit in one paragraph, for the sweep page."""

FITTED_OVER_ACCURACY = "fitted over {points} points, accuracy {dt_min:.3g} to {dt_max:.3g}"
"""``FITTED_OVER`` of an accuracy sweep: the slope of log(error) on log(accuracy), 1 when the
error is proportional to the accuracy asked for."""

NOT_ASYMPTOTIC = "not in the asymptotic range"
"""The note (start of the message) of an order row with fewer than ``MIN_FIT_POINTS`` points
in its asymptotic range: its value is NaN, its status ``unsupported``."""

FITTED_OVER = "fitted over {points} points, dt {dt_min:.3g} to {dt_max:.3g} s"
"""The message of a fitted order row: the asymptotic range it used (also in ``fit_dt_min``,
``fit_dt_max``, ``fit_points``), then the points left out, by role."""

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
    for scenario, spec, dts in jobs:
        if spec is not None and error_controlled(spec):
            continue  # swept over its accuracy at the scene's dt (``accuracy_sweep``)
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
    accuracy: dict[str, float] = field(default_factory=dict)
    """Sweep metric -> the reference's own error where it is known at every dt (DOP853: its
    cross-check difference); a self reference's depends on the point (``reference_floor``)."""
    spec: EngineSpec | None = None
    """The fine run's spec where it is not the swept one (an accuracy sweep's self reference:
    the same engine at a finer accuracy); None: the swept spec."""


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
        return Reference("dop853", accuracy=cross_check_accuracy(scenario, smallest_dt))
    if scenario.expect:
        return Reference(f"analytic:{scenario.expect[0].metric}")
    dt = smallest_dt / REFINE_SELF  # within MAX_STEPS: ``reference_problems``
    fine = _run(scene_at(scenario, dt), spec, _every(scenario, dt))
    return Reference(f"self:{spec.label}@{dt!r}", fine, dt)


_CROSS_CHECKS: dict[tuple[str, float], list[dict]] = {}
"""The cross-checks this process has run, by (scene, smallest step). A DOP853 scene's
cross-check is a job of its own, and each of its (scene, engine) jobs also needs it (the
reference's accuracy bounds what the order fit can resolve): a worker runs it at most once
per scene and grid."""


def cross_check(scenario: Scenario, smallest_dt: float) -> list[dict]:
    """The DOP853 reference against MuJoCo's RK4 at a tenth of the smallest step: the largest
    position and orientation differences over the run (a row for each, ``of`` names it); run
    once per process (``_CROSS_CHECKS``), a copy of the rows returned."""
    key = (scenario.model_dump_json(), smallest_dt)
    if key not in _CROSS_CHECKS:
        _CROSS_CHECKS[key] = _run_cross_check(scenario, smallest_dt)
    return [dict(row) for row in _CROSS_CHECKS[key]]


def cross_check_accuracy(scenario: Scenario, smallest_dt: float) -> dict[str, float]:
    """Sweep metric -> the DOP853 reference's accuracy as its cross-check measures it: the
    difference, where the check's own round-off (``error_floor`` of its row: ten times the
    steps of the finest point) cannot explain it. There it is the reference's error (MuJoCo
    RK4 at a tenth of the smallest step being the more accurate of the two, the premise of
    the check; the 10 s Dzhanibekov box at DOP853's former rtol 1e-12: 2.9e-7 rad, and rtol
    1e-14 differed from it by 2.8e-7, hence today's rtol 3e-14). At or below it the check resolves nothing finer than its own
    rounding and the reference is trusted: 0 (a 2 s flip: difference 4.5e-11, the check's
    round-off 8.9e-11, DOP853's own error 7e-12). Empty when the check did not run to the end."""
    return {
        row["of"]: row["error"] if row["error"] > error_floor(row) else 0.0
        for row in cross_check(scenario, smallest_dt)
        if row["status"] == "ok"
    }


def _run_cross_check(scenario: Scenario, smallest_dt: float) -> list[dict]:
    dt = smallest_dt / REFINE_REFERENCE  # within MAX_STEPS: ``reference_problems``
    row = {
        "scenario": scenario.name,
        "engine": HIGH_ACCURACY,
        "dt": dt,
        "metric": "reference_cross_check",
        "expected_kind": "dop853",
    }
    probe = scene_at(scenario, dt)
    row["steps"] = probe.steps
    run = _run(probe, parse_engine_spec(HIGH_ACCURACY), _every(scenario, dt))
    if run.recording is None or run.status != "ok":
        return [
            {**row, "of": m, "status": run.status, "message": run.message} for m in SWEEP_METRICS
        ]
    errors, _ = _against_motion(compile_scene(scenario), run.recording.trajectory)
    sizes = state_sizes(run.recording.trajectory.pos)
    return [
        {
            **row,
            "of": m,
            "value": errors[m],
            "error": errors[m],
            "state_size": sizes[m],
            "status": "ok",
            "message": "MuJoCo RK4 against the DOP853 reference",
        }
        for m in SWEEP_METRICS
    ]


def _against_motion(scene, trajectory) -> tuple[dict[str, float], np.ndarray]:
    """Both sweep errors of ``trajectory`` against the DOP853 motion at its own times, and
    that motion's centre positions (samples, bodies, 3)."""
    reference = reference_motion(scene, trajectory.t)
    errors = {
        "position_error": float(np.linalg.norm(trajectory.pos - reference.pos, axis=2).max()),
        "orientation_error": float(rotation_angle(trajectory.quat, reference.quat).max()),
    }
    return errors, reference.pos


def motion_extent(positions: np.ndarray) -> float:
    """m: the largest diagonal over bodies of the box a centre sweeps out over the run
    (``positions``: samples, bodies, 3): 2A for an oscillation of amplitude A, the range of a
    throw; the largest a position error between two runs of the motion can be while both keep
    to its region."""
    return float(np.linalg.norm(np.ptp(positions, axis=0), axis=-1).max())


def state_sizes(positions: np.ndarray) -> dict[str, float]:
    """Sweep metric -> the size of the state whose rounding its error accumulates
    (``ROUND_OFF_PER_STEP``): for a position the largest distance of a centre from the origin
    over the run (``positions``: samples, bodies, 3), m; ``ORIENTATION_STATE_SIZE``."""
    return {
        "position_error": float(np.linalg.norm(positions, axis=-1).max()),
        "orientation_error": ORIENTATION_STATE_SIZE,
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
            reference.spec or spec,
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
) -> tuple[dict[str, float], float]:
    """Both sweep errors of one point against ``reference`` (NaN where it cannot say), and the
    ``motion_extent`` of the reference's motion (NaN: the reference has no trajectory)."""
    if reference.kind == "dop853":
        errors, motion = _against_motion(compile_scene(scenario), run.recording.trajectory)
        return errors, motion_extent(motion)
    if reference.kind.startswith("analytic:"):
        metric = reference.kind.split(":", 1)[1]
        found = [m for m in _scene_metrics(scenario, run) if m.metric == metric]
        position = found[0].error if found else math.nan
        return {"position_error": position, "orientation_error": math.nan}, math.nan
    if reference.run is None or reference.run.status != "ok":
        # an unstable reference measures nothing
        return dict.fromkeys(SWEEP_METRICS, math.nan), math.nan
    errors = segment_error(scenario, spec, scenario.dt, reference)
    return errors, motion_extent(reference.run.recording.trajectory.pos)


def reference_floor(reference: Reference, dt: float, errors: dict[str, float]) -> dict[str, float]:
    """Sweep metric -> the reference's own error at a point of step ``dt``: for a self
    reference the fine run's, (dt_fine / dt)^p of the point's for a scheme of order p, taken
    at p = ``SELF_REFERENCE_ORDER``; else the reference's known accuracy (DOP853: its
    cross-check), 0 where none is known (an analytic expectation is exact)."""
    if reference.kind.startswith("self:") and reference.dt:
        share = (reference.dt / dt) ** SELF_REFERENCE_ORDER
        return {m: errors[m] * share for m in SWEEP_METRICS}
    return {m: reference.accuracy.get(m, 0.0) for m in SWEEP_METRICS}


def fit_facts(
    run: EngineRun, reference: Reference, dt: float, errors: dict[str, float], extent: float
) -> dict[str, dict]:
    """Sweep metric -> what the order fit needs to know of one point beyond its error
    (``fit_order``): ``state_size`` (the size whose rounding it accumulates), ``motion_extent``
    (position only: how large the error can grow) and ``reference_floor``."""
    floors = reference_floor(reference, dt, errors)
    sizes = (
        state_sizes(run.recording.trajectory.pos)
        if run.recording is not None
        else dict.fromkeys(SWEEP_METRICS, math.nan)
    )
    extents = {"position_error": extent, "orientation_error": math.nan}  # an angle's is pi
    return {
        m: {"state_size": sizes[m], "motion_extent": extents[m], "reference_floor": floors[m]}
        for m in SWEEP_METRICS
    }


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
    errors, extent = (
        point_errors(probe, spec, run, reference)
        if run.recording is not None
        else (dict.fromkeys(SWEEP_METRICS, math.nan), math.nan)
    )
    facts = fit_facts(run, reference, dt, errors, extent)
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
        {**common, "metric": m, "value": errors[m], "error": errors[m], **timing, **facts[m], **own}
        for m in SWEEP_METRICS
    ]


def round_off(row: dict) -> float:
    """The round-off one point's error carries: its ``steps`` x ``ROUND_OFF_PER_STEP`` x the
    measured size of its quantity, ``state_size`` (``METRE_SIZE_STATE`` when the row does not
    say)."""
    return float(
        row.get("steps", 0.0) * ROUND_OFF_PER_STEP * row.get("state_size", METRE_SIZE_STATE)
    )


def error_floor(row: dict) -> float:
    """The error below which one point cannot resolve the scheme's (module docstring): its
    ``round_off``, or its ``reference_floor``, the larger."""
    return float(np.nanmax([round_off(row), row.get("reference_floor", 0.0), 0.0]))


def saturation_error(row: dict) -> float:
    """The error above which one point is saturated: ``SATURATION_SHARE`` of the largest its
    metric can be (an angle: pi; a position: the reference motion's ``motion_extent``);
    infinite where that is not known (an analytic expectation's error)."""
    largest = (
        LARGEST_ANGLE if row.get("metric") == "orientation_error" else row.get("motion_extent")
    )
    if largest is None or not np.isfinite(largest):
        return math.inf
    return SATURATION_SHARE * largest


def point_role(row: dict) -> str:
    """``UNMEASURED``, ``FLOOR``, ``SATURATED``, or ``FITTED`` for a point the fit may use."""
    error = row.get("error", math.nan)
    if row.get("status") != "ok" or not (np.isfinite(error) and error > 0):
        return UNMEASURED
    if error_floor(row) > FLOOR_SHARE * error:
        return FLOOR
    if error > saturation_error(row):
        return SATURATED
    return FITTED


def consistent_points(log_dt: np.ndarray, log_error: np.ndarray) -> int:
    """How many points, from the first, have local slopes (between neighbours) that spread by
    at most ``SLOPE_SPREAD``."""
    slopes = np.diff(log_error) / np.diff(log_dt)
    spread = np.fmax.accumulate(slopes) - np.fmin.accumulate(slopes)
    consistent = np.isfinite(slopes) & (spread <= SLOPE_SPREAD)
    return 1 + (consistent.size if consistent.all() else int(np.argmin(consistent)))


def asymptotic_range(rows: list[dict], roles: list[str], grid: str = "dt") -> list[int]:
    """Indices of the points to fit: from the smallest ``grid`` value (dt, or the accuracy of
    an accuracy sweep) whose point is usable, the contiguous usable points (by it) whose local
    slopes are consistent; empty when fewer than ``MIN_FIT_POINTS``."""

    def usable(i: int) -> bool:
        return roles[i] == FITTED

    by_dt = sorted(range(len(rows)), key=lambda i: rows[i][grid])
    run = list(itertools.takewhile(usable, itertools.dropwhile(lambda i: not usable(i), by_dt)))
    if not run:
        return []
    log_dt, log_error = np.log([[rows[i][grid], rows[i]["error"]] for i in run]).T
    fitted = run[: consistent_points(log_dt, log_error)]
    return fitted if len(fitted) >= MIN_FIT_POINTS else []


@dataclass(frozen=True)
class OrderFit:
    """One curve's fitted order and the points it rests on.

    Attributes:
        order: the least-squares slope of log(error) on log(dt) over the asymptotic range;
            NaN when there is none (``note`` says why).
        roles: each row's ``FIT_ROLES`` entry, in the rows' order.
        dt_min, dt_max: s, the fitted range (NaN without a fit). points: how many it holds.
        note: the order row's message: the range, or why there is no order.
    """

    order: float
    roles: list[str]
    dt_min: float = math.nan
    dt_max: float = math.nan
    points: int = 0
    note: str = ""


def _left_out(roles: list[str]) -> str:
    """``"2 floor, 1 saturated"``: the points not fitted, by role (``FIT_ROLES`` order)."""
    return ", ".join(f"{roles.count(r)} {r}" for r in FIT_ROLES if r != FITTED and r in roles)


def _whole_curve_note(rows: list[dict]) -> str:
    """``IDENTICALLY_ZERO`` or the ``AT_ROUND_OFF`` note when every measured point says so
    (an error within its own ``round_off``), else ""."""
    measured = [r for r in rows if r.get("status") == "ok" and np.isfinite(r.get("error", np.nan))]
    if measured and all(r["error"] == 0.0 for r in measured):
        return IDENTICALLY_ZERO
    if measured and all(r["error"] <= round_off(r) for r in measured):
        largest = max(round_off(r) for r in measured)
        return AT_ROUND_OFF + ROUND_OFF_NOTE.format(eps=ROUND_OFF_PER_STEP, floor=largest)
    return ""


def fit_order(rows: list[dict], grid: str = "dt") -> OrderFit:
    """The convergence order of one curve (the rows of one scene, engine and sweep metric)
    over its asymptotic range (module docstring), with each point's role in the fit; the
    slope of log(error) on log(``grid``): dt, or the accuracy of an accuracy sweep."""
    roles = [point_role(r) for r in rows]
    whole = _whole_curve_note(rows)
    if whole:  # at round-off every measured point is floor-bound; zero ones are unmeasured
        return OrderFit(math.nan, [FLOOR if r == FITTED else r for r in roles], note=whole)
    fitted = asymptotic_range(rows, roles, grid)
    roles = [FITTED if i in fitted else OUTSIDE if r == FITTED else r for i, r in enumerate(roles)]
    left_out = _left_out(roles)
    if not fitted:
        detail = f"fewer than {MIN_FIT_POINTS} points" + (f"; {left_out}" if left_out else "")
        return OrderFit(math.nan, roles, note=f"{NOT_ASYMPTOTIC} ({detail})")
    dts, errors = np.array([[rows[i][grid], rows[i]["error"]] for i in fitted]).T
    order = float(np.polyfit(np.log(dts), np.log(errors), 1)[0])
    over = FITTED_OVER if grid == "dt" else FITTED_OVER_ACCURACY
    note = over.format(points=len(fitted), dt_min=dts.min(), dt_max=dts.max())
    return OrderFit(
        order,
        roles,
        float(dts.min()),
        float(dts.max()),
        len(fitted),
        note + (f" ({left_out} left out)" if left_out else ""),
    )


def convergence_order(rows: list[dict]) -> float:
    """The fitted convergence order of one curve (``fit_order``); NaN outside the asymptotic
    range."""
    return fit_order(rows).order


def order_row(scenario: Scenario, spec: EngineSpec, reference: Reference, metric: str) -> dict:
    """The ``convergence_order`` row of one curve without its fit (``fit_row`` adds it)."""
    return {
        "scenario": scenario.name,
        "engine": spec.label,
        "metric": "convergence_order",
        "of": metric,
        "expected_kind": reference.kind,
    }


def fit_row(fit: OrderFit) -> dict:
    """The fit's columns of a ``convergence_order`` row: the order (status ``unsupported``
    without one, as for a curve out of range), the range and the note."""
    return {
        "value": fit.order,
        "status": "ok" if np.isfinite(fit.order) else "unsupported",
        "message": fit.note,
        "fit_dt_min": fit.dt_min,
        "fit_dt_max": fit.dt_max,
        "fit_points": fit.points,
    }


def mark_points(curve: list[dict], grid: str = "dt") -> OrderFit:
    """Fit one curve's order (``fit_order``) and mark its points in place: each one's role in
    the fit (``fit_role``) and its ``round_off`` (the page shows both); a curve zero at every
    dt gets the note on its points."""
    fit = fit_order(curve, grid)
    for row, role in zip(curve, fit.roles, strict=True):
        row["fit_role"] = role
        if "steps" in row:
            row["round_off"] = round_off(row)
        if fit.note == IDENTICALLY_ZERO:
            row["message"] = IDENTICALLY_ZERO
    return fit


def sweep_scene(job: tuple[Scenario, EngineSpec, list[float]]) -> list[dict]:
    """Every dt of one (scene, engine) pair, each point marked with its role in the fit
    (``fit_role``), plus each sweep metric's fitted convergence order (or the note saying why
    there is none)."""
    scenario, spec, dts = job
    if error_controlled(spec):
        return accuracy_sweep(scenario, spec, dts)
    steps = runnable(scenario, dts)
    reference = choose_reference(scenario, spec, min(steps)) if steps else Reference(NO_REFERENCE)
    rows = [row for dt in dts for row in sweep_point(scenario, spec, dt, reference)]
    for metric in SWEEP_METRICS:
        fit = mark_points([r for r in rows if r["metric"] == metric])
        rows.append({**order_row(scenario, spec, reference, metric), **fit_row(fit)})
    return rows


ACCURACY_OPTION = "accuracy"
"""The option an ``error_controlled`` engine's accuracy is set by (Drake's continuous profile,
``validation.engines.drake.declaration``): an accuracy sweep writes it at every point."""

ACCURACY_GRID = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
"""The accuracies an error-controlled spec is swept over. Such an engine picks its own steps
(dt is only the observation interval, ``engine_api.STEPPING``), so a dt sweep measures
nothing of it: the sweep varies what its error control is asked for instead, from Drake's
``SimulatorConfig`` default accuracy 1e-4 two decades either way, at the scene's dt."""

REFINE_ACCURACY = 100.0
"""An accuracy sweep's self reference: the same spec at the smallest accuracy / 100 (two
decades finer, so its own error is about 1 % of the finest point's when the error follows
the accuracy)."""

ACCURACY_REFERENCE_ORDER = 1.0
"""The order in the accuracy assumed for a self reference's own error: (a_fine / a)^1 of the
point's, the error proportional to the accuracy asked for."""


def error_controlled(spec: EngineSpec) -> bool:
    """Whether ``spec``'s capabilities say ``stepping: error_controlled``."""
    capabilities = declaration_of(spec.name).capabilities_of(spec.as_dict())
    return capabilities.stepping == "error_controlled"


def with_setting(spec: EngineSpec, key: str, value: object) -> EngineSpec:
    """``spec`` with ``key`` set to ``value`` (appended, or replacing a written one)."""
    kept = tuple((k, v) for k, v in spec.settings if k != key)
    return EngineSpec(spec.name, (*kept, (key, value)))


def without_setting(spec: EngineSpec, key: str) -> EngineSpec:
    return EngineSpec(spec.name, tuple((k, v) for k, v in spec.settings if k != key))


def accuracy_reference(scenario: Scenario, spec: EngineSpec, dts: list[float]) -> Reference:
    """``choose_reference`` for an accuracy sweep: DOP853 or the scene's expectation as for a
    dt sweep; else the same spec at the smallest accuracy / ``REFINE_ACCURACY``, at the
    scene's dt."""
    if not _can_touch(scenario) or scenario.expect:
        steps = runnable(scenario, dts) or [scenario.dt]
        return choose_reference(scenario, spec, min(steps))
    fine = with_setting(spec, ACCURACY_OPTION, min(ACCURACY_GRID) / REFINE_ACCURACY)
    run = _run(scenario, fine, _every(scenario, scenario.dt))
    return Reference(f"self:{fine.label}", run, scenario.dt, spec=fine)


def accuracy_point(
    scenario: Scenario, spec: EngineSpec, accuracy: float, reference: Reference
) -> list[dict]:
    """``sweep_point`` at the scene's dt with ``spec`` at ``accuracy``: rows under the swept
    spec's label, with the ``accuracy`` column; a self reference's floor is its share
    (a_fine / a)^p of the error (``ACCURACY_REFERENCE_ORDER``)."""
    rows = sweep_point(
        scenario, with_setting(spec, ACCURACY_OPTION, accuracy), scenario.dt, reference
    )
    for row in rows:
        row["engine"] = spec.label
        row["accuracy"] = accuracy
        if reference.spec is not None:
            fine = float(reference.spec.as_dict()[ACCURACY_OPTION])
            row["reference_floor"] = row["error"] * (fine / accuracy) ** ACCURACY_REFERENCE_ORDER
    return rows


def accuracy_sweep(scenario: Scenario, spec: EngineSpec, dts: list[float]) -> list[dict]:
    """``sweep_scene`` for an error-controlled spec: every accuracy of ``ACCURACY_GRID`` at the
    scene's dt, error against run time, and each sweep metric's order in the accuracy."""
    base = without_setting(spec, ACCURACY_OPTION)
    if ACCURACY_OPTION not in {o.name for o in declaration_of(spec.name).options}:
        message = f"{spec.name} is error-controlled but has no {ACCURACY_OPTION!r} option to sweep"
        return [
            {
                "scenario": scenario.name,
                "engine": spec.label,
                "dt": scenario.dt,
                "metric": m,
                "status": "unsupported",
                "message": message,
            }
            for m in SWEEP_METRICS
        ]
    reference = accuracy_reference(scenario, base, dts)
    rows = [row for a in ACCURACY_GRID for row in accuracy_point(scenario, base, a, reference)]
    for metric in SWEEP_METRICS:
        fit = mark_points([r for r in rows if r["metric"] == metric], ACCURACY_OPTION)
        order = {**order_row(scenario, base, reference, metric), **fit_row(fit)}
        rows.append({**order, "fit_accuracy_min": fit.dt_min, "fit_accuracy_max": fit.dt_max})
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
    job: tuple[Scenario, EngineSpec | None, list[float]], status: str, message: str
) -> list[dict]:
    """The rows of a sweep job that gave none (``executor.run_jobs``: it crashed or timed
    out): ``status`` at every dt of the grid and for each fitted order, per sweep metric (one
    row per metric for a cross-check), so the lost job is seen where its rows would be."""
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
        {"scenario": scenario.name, **common, **point, "status": status, "message": message}
        for point in points
    ]


def run_sweep(
    jobs: list[tuple[Scenario, EngineSpec, list[float]]],
    workers: int,
    scheduler: str | None = None,
    job_timeout: float | None = None,
) -> list[dict]:
    """All jobs through the executor (one (scene, engine) dt grid per job: a job is worth
    shipping to a worker), plus one cross-check per scene with a DOP853 reference; rows in
    job order. ``scheduler``: on that Dask cluster; ``job_timeout``: ``--job-timeout``
    (``executor.run_jobs``)."""
    found = run_jobs(
        sweep_job,
        with_cross_checks(jobs),
        workers,
        None,
        scheduler,
        lost_sweep_job,
        sweep_cost,
        job_timeout,
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


SWEEP_OUTPUTS = {
    "sweep.csv": csv_written("a physval sweep.csv", ("scenario", "engine")),
    "sweep.html": page_written("a physval sweep page", "physval sweep"),
}
"""What ``physval sweep`` writes into its ``--out``, as it begins (``files.Written``): a file
there that physval did not write is refused, never overwritten."""


def sweep_main(
    paths: list[Path],
    engines: str | None,
    only: str | None,
    dt: str,
    jobs: int,
    out: Path | None,
    scheduler: str | None = None,
    job_timeout: float | None = None,
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
        check_folder_destination(out, SWEEP_OUTPUTS)
        check_room(out)
    except (BadInputError, GridError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        with locked(out):  # a second sweep on the same --out: exit 2 at once
            rows = run_sweep(work, jobs, scheduler, job_timeout)
            out.mkdir(parents=True, exist_ok=True)
            write_table(rows, out / "sweep.csv")  # each file written atomically
            render_sweep(rows, out / "sweep.html", FIT_RULE)
    except (BackendError, BadInputError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"{len(rows)} rows -> {out / 'sweep.csv'}, {out / 'sweep.html'}")
    return EXIT_OK
