"""Whole-document rules: checks that need the whole scenario, run after the schema.

Each rule is one function in ``RULES``: it reads the validated ``Scenario`` and yields
``(location, message)`` for every problem, the location being the field path it is reported
at (``("bodies", 2, "name")``). ``document_problems`` runs them all and places each problem
at its line and column.
"""

from __future__ import annotations

import difflib
import fnmatch
from collections.abc import Callable, Iterator

import numpy as np

from validation.scenario.engine_spec import EngineSpecError, parse_engine_spec
from validation.scenario.physics import body_inertia, symmetry_frame
from validation.scenario.problems import Problem, path_text
from validation.scenario.schema import ANY_METRIC, MAX_STEPS, METRIC_NAMES, BodySpec, Scenario
from validation.scenario.yaml_source import SourceMap

Location = tuple[str | int, ...]
Found = Iterator[tuple[Location, str]]

RESERVED_NAMES = ("world", "ground")
"""Names that mean the world frame (springs) and the ground plane (pairs): no body may take them."""


def _hint(name: str, choices: list[str]) -> str:
    close = difflib.get_close_matches(name, choices, n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def unique_body_names(scenario: Scenario) -> Found:
    """Body names are unique and not reserved."""
    first: dict[str, int] = {}
    for i, body in enumerate(scenario.bodies):
        if body.name in first:
            yield (
                ("bodies", i, "name"),
                f"duplicate body name {body.name!r} (also bodies[{first[body.name]}])",
            )
        first.setdefault(body.name, i)
        if body.name in RESERVED_NAMES:
            yield ("bodies", i, "name"), f"{body.name!r} is reserved; choose another name"


def _reference(scenario: Scenario, name: str, loc: Location, extra: tuple[str, ...]) -> Found:
    names = [b.name for b in scenario.bodies]
    if name not in names and name not in extra:
        alternatives = f"{' or ' + ' or '.join(repr(e) for e in extra) if extra else ''}"
        yield (
            loc,
            f"expected a body name{alternatives}; got {name!r}{_hint(name, [*names, *extra])}",
        )


def spring_ends(scenario: Scenario) -> Found:
    """A spring joins two different bodies, or a body and the world."""
    for i, spring in enumerate(scenario.springs):
        yield from _reference(scenario, spring.a, ("springs", i, "a"), ())
        yield from _reference(scenario, spring.b, ("springs", i, "b"), ("world",))
        if spring.a == spring.b:
            yield ("springs", i, "b"), "a spring needs two different ends"


def pair_bodies(scenario: Scenario) -> Found:
    """A pair override names two bodies, or a body and the ground (when there is one)."""
    ground = ("ground",) if scenario.ground else ()
    for i, pair in enumerate(scenario.pairs):
        yield from _reference(scenario, pair.a, ("pairs", i, "a"), ())
        yield from _reference(scenario, pair.b, ("pairs", i, "b"), ground)


def expectations(scenario: Scenario) -> Found:
    """Each expectation names a body, has a metric name of its own and a time within the run."""
    metrics = set(METRIC_NAMES)
    for i, expectation in enumerate(scenario.expect):
        yield from _reference(scenario, expectation.body, ("expect", i, "body"), ())
        if expectation.metric in metrics:
            yield ("expect", i, "name"), f"metric name {expectation.metric!r} is already taken"
        metrics.add(expectation.metric)
        if getattr(expectation, "time", 0.0) > scenario.duration:
            yield (
                ("expect", i, "time"),
                f"expected a time within the run (<= {scenario.duration} s)",
            )


def finite_inertia(body: BodySpec) -> np.ndarray | None:
    """The body's inertia (``physics.body_inertia``), or None when it overflows a float."""
    try:
        with np.errstate(over="raise", invalid="raise"):
            inertia = body_inertia(body)
    except (OverflowError, FloatingPointError):
        return None
    return inertia if np.isfinite(inertia).all() else None


def finite_mass_properties(scenario: Scenario) -> Found:
    """A body's derived mass properties are finite numbers (a radius of 1e200 m squares past
    the largest float: every engine would get an infinite inertia)."""
    for i, body in enumerate(scenario.bodies):
        if finite_inertia(body) is None:
            yield (
                ("bodies", i),
                f"the inertia of {body.name!r} (mass x size²) overflows a float; expected a "
                "size and a mass whose inertia is finite",
            )


def precession_needs_a_symmetry_axis(scenario: Scenario) -> Found:
    """``precession_rate`` is defined about a symmetry axis: the body needs two equal moments."""
    names = {b.name: b for b in scenario.bodies}
    for i, expectation in enumerate(scenario.expect):
        body = names.get(expectation.body)
        if expectation.kind != "precession_rate" or body is None:
            continue
        inertia = finite_inertia(body)
        if inertia is not None and symmetry_frame(inertia) is None:
            yield (
                ("expect", i, "body"),
                f"precession_rate needs a body with two equal principal moments (a symmetry "
                f"axis); {body.name!r} has three different ones",
            )


def engine_specs(scenario: Scenario) -> Found:
    """Engine specs parse and are not listed twice."""
    labels: set[str] = set()
    for i, text in enumerate(scenario.engines):
        try:
            label = parse_engine_spec(text).label
        except EngineSpecError as error:
            yield ("engines", i), str(error)
            continue
        if label in labels:
            yield ("engines", i), f"engine {label!r} is listed twice"
        labels.add(label)


def check_names(scenario: Scenario) -> Found:
    """A ``checks`` entry names a metric of this scene; a per-engine key names one of its engines."""
    metrics = sorted({*METRIC_NAMES, *(e.metric for e in scenario.expect)})
    labels = set()
    for text in scenario.engines:
        try:
            labels.add(parse_engine_spec(text).label)
        except EngineSpecError:
            continue  # reported by engine_specs
    for metric, tolerance in scenario.checks.items():
        if metric not in metrics:
            hint = (
                _hint(metric, metrics).removeprefix("; ") or f"expected one of {', '.join(metrics)}"
            )
            yield ("checks", metric), f"unknown metric {metric!r}; {hint}"
        for key in tolerance if isinstance(tolerance, dict) else ():
            if key != "default" and key not in labels:
                yield (
                    ("checks", metric, key),
                    f"expected 'default' or an engine of this scene ({', '.join(sorted(labels))}); got {key!r}",
                )


STATUS_METRIC = "status"
"""The metric of the row a run failure (unstable, error, model_mismatch) writes."""


def known_findings(scenario: Scenario) -> Found:
    """A known finding names a valid engine spec and a metric of this scene, ``status``, ``*``, or
    a pattern that matches one of them."""
    metrics = sorted({*METRIC_NAMES, *(e.metric for e in scenario.expect), STATUS_METRIC})
    for i, finding in enumerate(scenario.known):
        try:
            parse_engine_spec(finding.engine)
        except EngineSpecError as error:
            yield ("known", i, "engine"), str(error)
        if finding.metric != ANY_METRIC and not fnmatch.filter(metrics, finding.metric):
            hint = _hint(finding.metric, metrics).removeprefix("; ")
            yield (
                ("known", i, "metric"),
                f"unknown metric {finding.metric!r}; {hint or 'expected a metric of this scene'}"
                f" or {ANY_METRIC!r}",
            )


def sweep_steps(scenario: Scenario) -> Found:
    """A scene's sweep names valid, distinct engine specs and steps within ``MAX_STEPS``."""
    if scenario.sweep is None:
        return
    for i, text in enumerate(scenario.sweep.engines or ()):
        try:
            parse_engine_spec(text)
        except EngineSpecError as error:
            yield ("sweep", "engines", i), str(error)
    for i, dt in enumerate(scenario.sweep.dt):
        if dt > scenario.duration:
            yield (
                ("sweep", "dt", i),
                f"expected a step <= duration ({scenario.duration} s); got {dt}",
            )
        elif scenario.duration / dt > MAX_STEPS:
            yield (
                ("sweep", "dt", i),
                f"{scenario.duration / dt:.3g} steps; at most {MAX_STEPS} are allowed",
            )
    if len(set(scenario.sweep.dt)) < len(scenario.sweep.dt):
        yield ("sweep", "dt"), "expected distinct steps (an order is fitted through them)"


def loads_on_moving_bodies(scenario: Scenario) -> Found:
    """An applied force or torque acts on a body that can move (a fixed body would ignore it)."""
    for i, body in enumerate(scenario.bodies):
        for field in ("force", "torque"):
            if body.fixed and any(getattr(body, field)):
                yield (
                    ("bodies", i, field),
                    f"expected no {field} on a fixed body (it never moves); got {list(getattr(body, field))}",
                )


def step_count(scenario: Scenario) -> Found:
    """At least one step, at most ``MAX_STEPS``."""
    if scenario.duration < scenario.dt:
        yield ("duration",), f"expected duration >= dt ({scenario.dt} s); got {scenario.duration} s"
    if scenario.duration / scenario.dt > MAX_STEPS:
        yield (
            ("duration",),
            f"{scenario.duration / scenario.dt:.3g} steps (duration / dt); at most {MAX_STEPS} are allowed",
        )


RULES: tuple[Callable[[Scenario], Found], ...] = (
    unique_body_names,
    finite_mass_properties,
    spring_ends,
    pair_bodies,
    expectations,
    precession_needs_a_symmetry_axis,
    loads_on_moving_bodies,
    known_findings,
    sweep_steps,
    engine_specs,
    check_names,
    step_count,
)
"""Every whole-document rule, in the order their problems are listed."""


def document_problems(scenario: Scenario, file: str, source: SourceMap) -> list[Problem]:
    """Every problem the rules find, each placed at its field's line and column."""
    return [
        Problem(file, path_text(loc), message, *(source.locate(loc) or (None, None)))
        for rule in RULES
        for loc, message in rule(scenario)
    ]
