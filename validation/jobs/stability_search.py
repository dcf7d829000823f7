"""``physval stability``: the largest stable step of a scene in an engine, by bracketing and
bisection over runs that the stability checks judge."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.files import csv_written, write_table
from validation.jobs.executor import BackendError, run_jobs
from validation.jobs.output import check_file_destination, check_room, locked
from validation.jobs.plan import BadInputError, Plan, expected_cost, plan_run
from validation.measure.runner import run_engine
from validation.scenario import MAX_STEPS, Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import EngineSpec
from validation.scenario.schema import scene_at

BISECTION_RATIO = 1.02
"""The bisection stops when the unstable and stable steps are within 2 % of each other."""

MAX_BISECTIONS = 40


@dataclass(frozen=True)
class StabilityLimit:
    """The largest stable step of one scene in one engine (``None`` bounds: not bracketed)."""

    scenario: str
    engine: str
    stable_dt: float | None
    unstable_dt: float | None
    reason: str
    status: str = "ok"
    """``ok`` when the engine ran (stable, unstable or both found); else the run status that
    kept it from saying anything: ``error`` (it could not load or run the scene) or
    ``model_mismatch``."""

    def sentence(self) -> str:
        """The finding in plain words, as the report prints it."""
        if self.stable_dt is None and self.unstable_dt is None:
            return f"{self.engine} was not run on {self.scenario}: {self.reason}"
        if self.stable_dt is None:
            return f"{self.engine} is unstable at every dt tried on {self.scenario} (down to {self.unstable_dt:.3g} s): {self.reason}"
        if self.unstable_dt is None:
            return f"{self.engine} is stable on {self.scenario} up to the largest dt tried ({self.stable_dt:.3g} s)"
        return (
            f"{self.engine} is unstable above dt = {self.unstable_dt:.3g} s on {self.scenario} "
            f"(stable at {self.stable_dt:.3g} s): {self.reason}"
        )


def largest_stable_dt(
    is_stable: Callable[[float], tuple[bool, str]], start: float, lowest: float, highest: float
) -> tuple[float | None, float | None, str]:
    """Bracket and bisect (geometric) the step where ``is_stable(dt)`` turns false.

    Returns (largest stable dt, smallest unstable dt, the unstable run's reason); a bound is
    None when no dt in [lowest, highest] was stable (or unstable).
    """
    stable, unstable, reason = None, None, ""
    dt = start
    ok, why = is_stable(dt)
    while True:  # bracket by factors of 2
        if ok:
            stable = dt
            if dt >= highest:
                return stable, None, ""
            dt = min(dt * 2.0, highest)
        else:
            unstable, reason = dt, why
            if dt <= lowest:
                return None, unstable, reason
            dt = max(dt / 2.0, lowest)
        if stable is not None and unstable is not None:
            break
        ok, why = is_stable(dt)
    for _ in range(MAX_BISECTIONS):
        if unstable / stable <= BISECTION_RATIO:
            break
        middle = math.sqrt(stable * unstable)
        ok, why = is_stable(middle)
        if ok:
            stable = middle
        else:
            unstable, reason = middle, why
    return stable, unstable, reason


SEARCH_DOWN = 16.0
"""The bisection looks for a stable step down to the scene's dt / 16. Each halving doubles
the cost of a probe, and a scheme that is unstable 16 times below the author's step is
unstable for the scene's purposes (explicit Euler on an undamped spring grows as
exp(ω² dt t): at any fixed dt it explodes given time, so "every dt tried" is the finding)."""

SEARCH_COST_RUNS = 2 * SEARCH_DOWN + MAX_BISECTIONS
"""A search's expected cost in runs at the scene's dt (its job's cost, from which its default
time limit is derived, ``executor.time_limit``): the bracketing probes down to dt /
``SEARCH_DOWN`` sum to under 2 x ``SEARCH_DOWN`` runs, each bisection about one more."""

SEARCH_UP_FRACTION = 0.1
"""... and for an unstable one up to a tenth of the scene's duration."""

SAMPLES_PER_PROBE = 200
"""Trajectory samples kept per probe run: stability is checked at every observation anyway."""


def stability_limit(scenario: Scenario, spec, search_down: float = SEARCH_DOWN) -> StabilityLimit:
    """The largest stable dt of ``scenario`` in the engine ``spec`` (any EngineSpec), searched
    between the scene's dt / ``search_down`` and a tenth of its duration."""

    def is_stable(dt: float) -> tuple[bool, str]:
        probe = scene_at(scenario, dt)
        run = run_engine(compile_scene(probe), spec, max(1, probe.steps // SAMPLES_PER_PROBE))
        if run.status in NOT_RUN:
            raise _NotRunError(run.status, run.message)
        return run.status == "ok", run.message

    lowest = max(scenario.dt / search_down, scenario.duration / MAX_STEPS)
    highest = max(scenario.dt, SEARCH_UP_FRACTION * scenario.duration)
    try:
        stable, unstable, reason = largest_stable_dt(is_stable, scenario.dt, lowest, highest)
    except _NotRunError as why:
        status, message = why.args
        return StabilityLimit(
            scenario.name or "", spec.label, None, None, f"{status}: {message}", status
        )
    return StabilityLimit(scenario.name or "", spec.label, stable, unstable, reason)


NOT_RUN = ("model_mismatch", "error", "unsupported", "not_installed")
"""Run statuses that say nothing of stability: the model failed the parity gate, the
engine raised (a model it cannot compile), it lacks a capability the scene needs, or its
package is not installed; reported as such, never as unstable."""


class _NotRunError(Exception):
    """The engine did not run the scene (``NOT_RUN``): its stability says nothing."""


def _limit_job(job: tuple[Scenario, EngineSpec]) -> StabilityLimit:
    return stability_limit(*job)


def _lost_limit(job: tuple[Scenario, EngineSpec], status: str, message: str) -> StabilityLimit:
    """The finding recorded for a job that gave none (``executor.run_jobs``: it crashed or
    timed out): not run."""
    scenario, spec = job
    return StabilityLimit(
        scenario.name or "", spec.label, None, None, f"{status}: {message}", status
    )


STABILITY_CSV = csv_written(
    "a physval stability.csv", [*(f.name for f in fields(StabilityLimit)), "sentence"]
)
"""How stability.csv begins: a file at ``--out`` that physval did not write is refused."""


def _scene_files(plan: Plan) -> tuple[Path, ...]:
    """The scene files a plan read (``--out`` never overwrites one)."""
    return tuple(Path(scene.scenario.source) for scene, _ in plan.scenes)


def stability_main(
    paths: list[Path],
    engines: str | None,
    only: str | None,
    out: Path | None,
    jobs: int = 1,
    scheduler: str | None = None,
    job_timeout: float | None = None,
) -> int:
    """``physval stability``: every limit printed as a sentence and written to stability.csv."""
    out = out or Path("reports") / "stability.csv"
    try:
        plan = plan_run(paths, engines, None, only)
        check_file_destination(out, STABILITY_CSV, _scene_files(plan))
        check_room(out)
    except BadInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    work = [(scene.scenario, spec) for scene, spec in plan.jobs]
    try:
        with locked(out):  # a second search on the same --out: exit 2 at once
            limits = run_jobs(
                _limit_job,
                work,
                jobs,
                None,
                scheduler,
                _lost_limit,
                lambda job: SEARCH_COST_RUNS * expected_cost(job[0]),  # the longest first
                job_timeout,
            )
            rows = [{**limit.__dict__, "sentence": limit.sentence()} for limit in limits]
            write_table(rows, out)  # atomically
    except (BackendError, BadInputError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    for limit in limits:
        print(limit.sentence())
    return EXIT_OK
