"""Whole-document rules: checks that need the whole scenario, run after the schema."""

from __future__ import annotations

import difflib

from validation.scenario.engine_spec import (
    EngineSpecError,
    parse_engine_spec,
)
from validation.scenario.problems import Problem, path_text
from validation.scenario.schema import (
    MAX_STEPS,
    METRIC_NAMES,
    Scenario,
)
from validation.scenario.yaml_source import SourceMap


def _cross_problems(scenario: Scenario, file: str, source: SourceMap) -> list[Problem]:
    """Checks that need the whole document; each reported at its own field."""
    problems: list[tuple[tuple[str | int, ...], str]] = []
    names: dict[str, int] = {}
    for i, body in enumerate(scenario.bodies):
        if body.name in names:
            problems.append(
                (
                    ("bodies", i, "name"),
                    f"duplicate body name {body.name!r} (also bodies[{names[body.name]}])",
                )
            )
        names.setdefault(body.name, i)
        if body.name in ("world", "ground"):
            problems.append(
                (("bodies", i, "name"), f"{body.name!r} is reserved; choose another name")
            )

    def known(name: str, loc: tuple[str | int, ...], extra: tuple[str, ...]) -> None:
        if name not in names and name not in extra:
            close = difflib.get_close_matches(name, [*names, *extra], n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            problems.append(
                (
                    loc,
                    f"expected a body name{' or ' + ' or '.join(repr(e) for e in extra) if extra else ''}; got {name!r}{hint}",
                )
            )

    for i, spring in enumerate(scenario.springs):
        known(spring.a, ("springs", i, "a"), ())
        known(spring.b, ("springs", i, "b"), ("world",))
        if spring.a == spring.b:
            problems.append((("springs", i, "b"), "a spring needs two different ends"))
    for i, pair in enumerate(scenario.pairs):
        known(pair.a, ("pairs", i, "a"), ())
        known(pair.b, ("pairs", i, "b"), ("ground",) if scenario.ground else ())
    metrics = set(METRIC_NAMES)
    for i, expectation in enumerate(scenario.expect):
        known(expectation.body, ("expect", i, "body"), ())
        if expectation.metric in metrics:
            problems.append(
                (("expect", i, "name"), f"metric name {expectation.metric!r} is already taken")
            )
        metrics.add(expectation.metric)
        if getattr(expectation, "time", 0.0) > scenario.duration:
            problems.append(
                (
                    ("expect", i, "time"),
                    f"expected a time within the run (<= {scenario.duration} s)",
                )
            )
    engine_labels: set[str] = set()
    for i, text in enumerate(scenario.engines):
        try:
            label = parse_engine_spec(text).label
        except EngineSpecError as error:
            problems.append((("engines", i), str(error)))
            continue
        if label in engine_labels:
            problems.append((("engines", i), f"engine {label!r} is listed twice"))
        engine_labels.add(label)
    for metric, tolerance in scenario.checks.items():
        if metric not in metrics:
            close = difflib.get_close_matches(metric, sorted(metrics), n=1, cutoff=0.5)
            hint = (
                f"did you mean {close[0]!r}?"
                if close
                else f"expected one of {', '.join(sorted(metrics))}"
            )
            problems.append((("checks", metric), f"unknown metric {metric!r}; {hint}"))
        if isinstance(tolerance, dict):
            for key in tolerance:
                if key != "default" and key not in engine_labels:
                    problems.append(
                        (
                            ("checks", metric, key),
                            f"expected 'default' or an engine of this scene ({', '.join(sorted(engine_labels))}); got {key!r}",
                        )
                    )
    if scenario.duration < scenario.dt:
        problems.append(
            (("duration",), f"expected duration >= dt ({scenario.dt} s); got {scenario.duration} s")
        )
    if scenario.duration / scenario.dt > MAX_STEPS:
        problems.append(
            (
                ("duration",),
                f"{scenario.duration / scenario.dt:.3g} steps (duration / dt); at most {MAX_STEPS} are allowed",
            )
        )
    return [
        Problem(file, path_text(loc), message, *(source.locate(loc) or (None, None)))
        for loc, message in problems
    ]
