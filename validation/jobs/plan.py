"""Planning: every scene loaded and validated, every flag checked, before any work starts."""

from __future__ import annotations

import fnmatch
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from validation.scenario import (
    MAX_STEPS,
    Scenario,
    ScenarioError,
    load_scenario,
    scenario_files,
    urdf,
)
from validation.scenario.compiled import CompiledScene, compile_scene
from validation.scenario.engine_spec import (
    EngineSpec,
    EngineSpecError,
    not_installed,
    parse_engine_spec,
    parse_installed_spec,
    split_engine_list,
)
from validation.scenario.problems import Problem, printable


@dataclass
class Plan:
    """What to run: validated scenes, each with its engine specs."""

    scenes: list[tuple[CompiledScene, list[EngineSpec]]]
    """Each scene compiled once, with the engine specs it runs in."""

    engines_replaced: bool = False
    """``--engines`` replaced every scene's engine list: its sweep's list too."""

    sweeping: bool = True
    """The scenes' own sweeps (``sweep:``) run (``--sweeps on``); off, ``sweeps`` is empty."""

    @property
    def jobs(self) -> list[tuple[CompiledScene, EngineSpec]]:
        """(scene, spec) in plan order: scenes in file order, specs in the scene's order."""
        return [(scene, spec) for scene, specs in self.scenes for spec in specs]

    @property
    def sweeps(self) -> list[tuple[Scenario, EngineSpec, list[float]]]:
        """(scenario, spec, dts) of the scenes that declare ``sweep:``, in plan order: the
        sweep's own engines, or the specs the scene runs in (always these when ``--engines``
        replaced the scenes' lists: a run in one engine sweeps that engine only), leaving out
        engines not installed here (the scene's own rows say ``not_installed``); none when
        the plan does not sweep (``sweeping``)."""
        if not self.sweeping:
            return []
        return [
            (scene.scenario, spec, list(scene.scenario.sweep.dt))
            for scene, specs in self.scenes
            if scene.scenario.sweep is not None
            for spec in (
                [parse_engine_spec(t) for t in scene.scenario.sweep.engines]
                if scene.scenario.sweep.engines and not self.engines_replaced
                else specs
            )
            if not not_installed(spec.name)
        ]


class BadInputError(ValueError):
    """User input that stops the run before anything is written (exit code 2): one line per
    problem, each printed with its control characters escaped (``printable``: a folder named
    with an escape sequence cannot drive the terminal that prints the refusal)."""

    def __str__(self) -> str:
        return "\n".join(printable(line) for line in super().__str__().split("\n"))


def step_ratio(duration: float, dt: float) -> float:
    """``duration / dt`` as a float, infinite where it overflows (``dt = 5e-324``)."""
    with np.errstate(over="ignore", divide="ignore"):
        return float(np.float64(duration) / np.float64(dt))


STEP_COST_PER_BODY = 0.04
"""A body's share of the cost of a step, relative to a step's fixed cost: mini (the engine
that dominates a run) steps one sphere in 0.2 ms and a 1,000-sphere pile in 8.6 ms
(``benchmarks/step_cost.py``), (8.6 - 0.2) / 1000 / 0.2 = 0.04."""


def expected_cost(scenario: Scenario, dts: list[float] | None = None) -> float:
    """A job's expected cost in fixed step costs: its steps at each of ``dts`` (default the
    scene's own dt) times (1 + ``STEP_COST_PER_BODY`` x bodies). It orders the work (the
    executor starts the longest jobs first); no result depends on it."""
    bodies = len(scenario.bodies)
    steps = sum(
        step_ratio(scenario.duration, dt)
        for dt in (dts or [scenario.dt])
        if steps_in_range(scenario.duration, dt)
    )
    return steps * (1.0 + STEP_COST_PER_BODY * bodies)


def steps_in_range(duration: float, dt: float) -> bool:
    """``duration / dt`` is 1 to ``MAX_STEPS`` steps, judged in floats before any integer is
    made of it (an infinite ratio is what ``round`` cannot convert)."""
    steps = step_ratio(duration, dt)
    return bool(math.isfinite(steps) and 0.5 <= steps <= MAX_STEPS)


def _with_dt(scenario: Scenario, dt: float, file: Path) -> Scenario:
    """The scenario at ``--dt``; ``BadInputError`` when its step count is out of range."""
    if not steps_in_range(scenario.duration, dt):
        raise BadInputError(
            f"--dt {dt} for {printable(file)}: {step_ratio(scenario.duration, dt):.3g} steps (duration / dt) is out of range; "
            f"expected 1 to {MAX_STEPS} (MAX_STEPS)"
        )
    try:
        return Scenario.model_validate(
            {**scenario.model_dump(), "dt": dt, "source": scenario.source}
        )
    except ValueError as error:
        raise BadInputError(f"--dt {dt} for {printable(file)}: {error}") from None


def duplicate_problem(scenario: Scenario, file: Path, names: dict[str, Path]) -> Problem | None:
    """A problem when another file already has this scene's name (their rows would merge)."""
    other = names.setdefault(scenario.name, file)
    if other == file:
        return None
    message = f"{scenario.name!r} is also the name of {other}; expected a unique name"
    return Problem(str(file), "name", message)


def plan_run(
    paths: list[Path],
    engines: str | None,
    dt: float | None,
    only: str | None,
    sweeps: bool = True,
) -> Plan:
    """Load and validate everything first; raises ``BadInputError`` listing every problem.
    ``sweeps``: whether the scenes' own sweeps run (``Plan.sweeping``)."""
    problems: list[str] = []
    overrides: list[EngineSpec] | None = None
    if engines is not None:
        overrides = []
        for text in split_engine_list(engines) or [""]:
            try:
                spec = parse_installed_spec(text)
            except EngineSpecError as error:
                problems.append(f"--engines: {error}")
                continue
            if spec in overrides:
                problems.append(f"--engines: {spec.label!r} is listed twice")
            overrides.append(spec)
    if dt is not None and not (np.isfinite(dt) and dt > 0):
        problems.append(f"--dt: expected a number of seconds > 0; got {dt}")
    missing = [p for p in paths if not os.path.lexists(p)]  # a dangling link is read (refused)
    problems += [f"{printable(p)}: no such file or folder" for p in missing]
    scenes: list[tuple[CompiledScene, list[EngineSpec]]] = []
    names: dict[str, Path] = {}
    for file in scenario_files([p for p in paths if p not in missing]):
        try:
            scenario = load_scenario(file)
        except ScenarioError as error:
            problems += [str(p) for p in error.problems]
            continue
        if only and not (fnmatch.fnmatch(scenario.name, only) or fnmatch.fnmatch(str(file), only)):
            continue
        duplicate = duplicate_problem(scenario, file, names)
        if duplicate:
            problems.append(str(duplicate))
            continue
        if dt is not None and not problems:
            try:
                scenario = _with_dt(scenario, dt, file)
            except BadInputError as error:
                problems.append(str(error))
                continue
        scenes.append((compile_scene(scenario), overrides or list(scenario.engine_specs)))
    if not scenes and not problems:
        problems.append(f"no scenario matches {only!r}" if only else "no scenario files found")
    if problems:
        raise BadInputError("\n".join(problems))
    return Plan(scenes, engines_replaced=overrides is not None, sweeping=sweeps)


def package_paths(flags: list[str] | None) -> dict[str, str]:
    """``--package-path NAME=DIR`` flags as NAME -> DIR (absolute), checked: ``BadInputError``
    naming the first flag without ``=``, with an empty NAME, or whose DIR is not a folder."""
    found: dict[str, str] = {}
    for flag in flags or []:
        name, equals, folder = flag.partition("=")
        if not equals or not name.strip() or not folder:
            raise BadInputError(
                f"--package-path {flag}: expected NAME=DIR (a package name, '=', its folder)"
            )
        if not os.path.isdir(folder):
            raise BadInputError(f"--package-path {flag}: {folder} is not a folder")
        found[name.strip()] = os.path.abspath(folder)
    return found


def use_package_paths(flags: list[str] | None) -> None:
    """Set ``urdf.PACKAGE_PATHS`` (where ``package://NAME`` resolves) from the flags, before any
    scene is loaded; ``BadInputError`` as ``package_paths``."""
    urdf.PACKAGE_PATHS.clear()
    urdf.PACKAGE_PATHS.update(package_paths(flags))
