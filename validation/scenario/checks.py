"""Whole-document rules: checks that need the whole scenario, run after the schema.

Each rule is one function that reads the validated ``Scenario`` and yields ``(location,
message)`` for every problem, the location being the field path it is reported at
(``("bodies", 2, "name")``). ``document_problems`` runs them in three phases and places each
problem at its line and column:

1. ``RULES``: the document's own consistency (names, references, specs, steps); errors.
2. ``SCENE_RULES``, once those of the scene itself hold (all but ``ANNOTATION_RULES``): what
   the scene can define (``definability``): a check or a known finding on a metric the scene
   cannot define is an error.
3. ``WARNING_RULES``, alike: what loads but cannot do its job: a tolerance no reading can
   exceed.

A file that failed the schema is judged on its validated part (``partial``).
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Callable, Iterator

import numpy as np

from validation.reference.rotation import rotation_angle
from validation.scenario.compiled import compile_scene
from validation.scenario.definability import UNDEFINED_WHEN, Traits, scene_traits, why_undefined
from validation.scenario.engine_spec import EngineSpecError, parse_engine_spec
from validation.scenario.joints import JOINT_RULES
from validation.scenario.partial import Partial
from validation.scenario.physics import (
    body_inertia,
    pair_rule,
    symmetry_frame,
    unmeasured_pairs,
)
from validation.scenario.problems import Problem, path_text
from validation.scenario.schema import (
    ANY_METRIC,
    AXIS_JOINT_TYPES,
    JOINT_EXPECTATION_MODELS,
    MAX_STEPS,
    METRIC_NAMES,
    BodySpec,
    Scenario,
    Tolerance,
)
from validation.scenario.suggest import closest, did_you_mean
from validation.scenario.yaml_source import SMALLEST_NORMAL, SourceMap

Location = tuple[str | int, ...]
Found = Iterator[tuple[Location, str]]

WHOLE_STEPS = 1e-9
"""Relative to the step count. A duration within this of a whole number of steps is that
number: decimal durations and steps round to about 1e-16 relative each (0.6 / 0.001 =
599.9999999999999), while this lets through at most 0.005 of a step at ``MAX_STEPS`` (6e-7 of
a step at 600 steps: 0.6004 s at 1 ms is 0.4 of one)."""


def whole_steps(duration: float, dt: float) -> str | None:
    """Why a run of ``duration`` s at step ``dt`` s would not end at its duration (a run takes
    whole steps: it would stop short of it, or past it), or None when it is a whole number of
    steps."""
    count = duration / dt
    nearest = round(count)
    if abs(count - nearest) <= WHOLE_STEPS * max(nearest, 1):
        return None
    below, above = int(np.floor(count)), int(np.ceil(count))
    return (
        f"expected a whole number of steps of dt {dt} s; duration {duration} s is {count:.6g} "
        f"steps ({below} steps end at {below * dt:.6g} s, {above} at {above * dt:.6g} s)"
    )


RESERVED_NAMES = ("world", "ground")
"""Names that mean the world frame (springs) and the ground plane (pairs): no body may take them."""


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
            f"expected a body name{alternatives}; got {name!r}{did_you_mean(name, [*names, *extra])}",
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
    """Each expectation names its subject (a body, or a joint for ``JOINT_EXPECTATION_MODELS``),
    has a metric name of its own and a time within the run."""
    metrics = set(METRIC_NAMES)
    joints = [joint.name for joint in scenario.joints]
    for i, expectation in enumerate(scenario.expect):
        if isinstance(expectation, JOINT_EXPECTATION_MODELS):
            if expectation.joint not in joints:
                yield (
                    ("expect", i, "joint"),
                    f"expected a joint name; got {expectation.joint!r}"
                    f"{did_you_mean(expectation.joint, joints) if joints else ' (the scene has no joints)'}",
                )
        else:
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
    """The body's inertia (``physics.body_inertia``), or None when it overflows a float or
    underflows (a subnormal moment: its inverse, which every engine takes, is infinite)."""
    try:
        with np.errstate(over="raise", invalid="raise", under="ignore"):
            inertia = body_inertia(body)
            smallest = float(np.linalg.eigvalsh(inertia).min())
    except (OverflowError, FloatingPointError, np.linalg.LinAlgError):
        return None
    finite = np.isfinite(inertia).all() and smallest >= SMALLEST_NORMAL
    return inertia if finite else None


def finite_mass_properties(scenario: Scenario) -> Found:
    """A body's derived mass properties are finite numbers (a radius of 1e200 m squares past
    the largest float: every engine would get an infinite inertia; a mass of 1e-307 kg a
    subnormal inertia whose inverse is infinite)."""
    for i, body in enumerate(scenario.bodies):
        if finite_inertia(body) is None:
            yield (
                ("bodies", i),
                f"the inertia of {body.name!r} (mass x size²) overflows or underflows a "
                "float; expected a size and a mass whose principal moments are finite and "
                f"at least {SMALLEST_NORMAL:.3g} kg·m² (SMALLEST_NORMAL)",
            )


LARGEST_SCALE = 1e150
"""The largest physical scale (a weight, a momentum, an energy, a reachable speed or
distance) a scene may imply, in SI units. The measurements square such values (norms, kinetic
energy) and sum them over bodies: 1e150 squares to 1e300 and 20,000 bodies of it sum to 2e304,
below the largest double 1.8e308; a scale beyond it turns rows into inf - inf = NaN, which no
tolerance can judge (a mass of 1e308 gave NaN rows marked ok)."""


def _motion_scales(body: BodySpec, inertia: np.ndarray, gravity: float, duration: float):
    """(field, what, value) of one moving body: the products of its values that its rows
    compute, at t = 0 and as far as its loads can take it in ``duration`` (a bound: constant
    acceleration, touching nothing)."""
    # NumPy floats: an overflow is inf (errstate ignores it), not Python's OverflowError
    mass, force = np.float64(body.mass), np.float64(math.hypot(*body.force))
    speed = np.float64(math.hypot(*body.velocity))
    spin = np.float64(math.hypot(*body.angular_velocity))
    acceleration = force / mass + gravity
    reach_speed = speed + acceleration * duration
    reach = math.hypot(*body.position) + speed * duration + acceleration * duration**2
    moment = float(np.linalg.eigvalsh(inertia).max())
    yield "mass", "mass x |gravity|", mass * gravity
    yield "force", "|force|", force
    yield "force", "|force| / mass", force / mass
    yield "torque", "|torque|", math.hypot(*body.torque)
    yield "velocity", "mass x |velocity|", mass * speed
    yield "velocity", "mass x |velocity|²", mass * speed**2
    yield "angular_velocity", "inertia x |angular velocity|²", moment * spin**2
    yield "position", "|position| reached in the run", reach
    yield "velocity", "mass x |velocity|² reached in the run", mass * reach_speed**2
    yield "position", "mass x |gravity| x |position| reached in the run", mass * gravity * reach


def bounded_scales(scenario: Scenario) -> Found:
    """The physical scales a scene implies stay below ``LARGEST_SCALE``, the field that makes
    each one named (a mass, force or gravity of 1e308 overflows every row it enters)."""
    gravity = math.hypot(*scenario.gravity)  # hypot does not overflow where its result fits
    if not gravity <= LARGEST_SCALE:
        yield (
            ("gravity",),
            f"expected |gravity| <= {LARGEST_SCALE:.0e} m/s² (LARGEST_SCALE); got {gravity:.3g}",
        )
        return
    for i, body in enumerate(scenario.bodies):
        inertia = finite_inertia(body)
        if body.fixed or inertia is None:
            continue  # a fixed body does not move; an unusable inertia is its own problem
        with np.errstate(over="ignore", invalid="ignore"):
            scales = list(_motion_scales(body, inertia, gravity, scenario.duration))
        for field, what, value in scales:
            if not value <= LARGEST_SCALE:
                size = "past the largest float" if np.isinf(value) else f"{value:.3g}"
                yield (
                    ("bodies", i, field),
                    f"{what} of {body.name!r} is {size}; expected values whose products stay "
                    f"below {LARGEST_SCALE:.0e} (LARGEST_SCALE): every row would overflow",
                )
                break
    for i, spring in enumerate(scenario.springs):
        if not spring.stiffness <= LARGEST_SCALE or not spring.damping <= LARGEST_SCALE:
            yield (
                ("springs", i),
                f"expected a stiffness and a damping below {LARGEST_SCALE:.0e} (LARGEST_SCALE); "
                f"got {spring.stiffness:.3g} N/m, {spring.damping:.3g} N·s/m",
            )


JOINT_VALUE_SHAPES = {
    "hinge": "a number (rad)",
    "slider": "a number (m)",
    "ball": "a vector [x, y, z] rad (its rotation vector)",
}
"""Joint type -> what its ``joint_position_at`` value is (a fixed joint has no coordinate)."""


def joint_expectations_fit_their_joint(scenario: Scenario) -> Found:
    """A joint's expectation fits its type: ``joint_position_at`` of a hinge or slider is a
    number, of a ball a vector [x, y, z] (its rotation vector), of a fixed joint nothing (no
    coordinate); ``period`` is of a hinge or slider (one coordinate)."""
    types = {joint.name: joint.type for joint in scenario.joints}
    for i, expectation in enumerate(scenario.expect):
        kind, joint_type = expectation.kind, types.get(getattr(expectation, "joint", None))
        if joint_type is None:
            continue  # a body's expectation, or an unknown joint (``expectations``)
        if kind == "period" and joint_type not in AXIS_JOINT_TYPES:
            yield (
                ("expect", i, "joint"),
                f"period is of one coordinate: expected a hinge or slider joint; "
                f"{expectation.joint!r} is a {joint_type} joint",
            )
        elif kind == "joint_position_at" and joint_type not in JOINT_VALUE_SHAPES:
            yield (
                ("expect", i, "joint"),
                f"expected a hinge, slider or ball joint; {expectation.joint!r} is a "
                f"{joint_type} joint (it has no coordinate)",
            )
        elif kind == "joint_position_at":
            vector = isinstance(expectation.value, tuple)
            if vector != (joint_type == "ball"):
                got = list(expectation.value) if vector else expectation.value
                yield (
                    ("expect", i, "value"),
                    f"{expectation.joint!r} is a {joint_type} joint: expected "
                    f"{JOINT_VALUE_SHAPES[joint_type]}; got {got}",
                )


def precession_needs_a_symmetry_axis(scenario: Scenario) -> Found:
    """``precession_rate`` is defined about a symmetry axis: the body needs two equal moments."""
    names = {b.name: b for b in scenario.bodies}
    for i, expectation in enumerate(scenario.expect):
        if expectation.kind != "precession_rate" or expectation.body not in names:
            continue
        body = names[expectation.body]
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


def _subject_exists(scenario: Scenario, expectation) -> bool:
    """Whether the body or joint an expectation is of exists in the scene."""
    if isinstance(expectation, JOINT_EXPECTATION_MODELS):
        return any(joint.name == expectation.joint for joint in scenario.joints)
    return any(body.name == expectation.body for body in scenario.bodies)


def metric_choices(scenario: Scenario, *extra: str) -> list[str]:
    """The metrics a mistyped metric name may be told to mean: the fixed ones and those of the
    expectations whose subject exists (``velocity_at.bal`` of a mistyped body is no metric to
    suggest: it spells the typo back)."""
    existing = (e.metric for e in scenario.expect if _subject_exists(scenario, e))
    return sorted({*METRIC_NAMES, *existing, *extra})


def _metric_hint(scenario: Scenario, metric: str, *extra: str) -> str:
    """What a mistyped metric name may mean: an existing metric (``did you mean 'X'?``), or
    the expectation whose own subject is mistyped, its metric named after that typo; or
    nothing."""
    orphans = {
        e.metric: i for i, e in enumerate(scenario.expect) if not _subject_exists(scenario, e)
    }
    close = closest(metric, [*metric_choices(scenario, *extra), *orphans])
    if close in orphans:
        subject = f"expect[{orphans[close]}]'s metric is {close!r}"
        return f"{subject}, named after a subject the scene does not have"
    return f"did you mean {close!r}?" if close else ""


def check_names(scenario: Scenario) -> Found:
    """A ``checks`` entry names a metric of this scene; a per-engine key names one of its engines."""
    known = {*METRIC_NAMES, *(e.metric for e in scenario.expect)}
    metrics = metric_choices(scenario)
    labels = set()
    for text in scenario.engines:
        try:
            labels.add(parse_engine_spec(text).label)
        except EngineSpecError:
            continue  # reported by engine_specs
    for metric, tolerance in scenario.checks.items():
        if metric not in known:  # a set: a list made ``check`` quadratic in the entries
            hint = _metric_hint(scenario, metric) or f"expected one of {', '.join(metrics)}"
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
            hint = _metric_hint(scenario, finding.metric, STATUS_METRIC)
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
        elif (fraction := whole_steps(scenario.duration, dt)) is not None:
            yield ("sweep", "dt", i), fraction
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
    """At least one step, at most ``MAX_STEPS``, and a whole number of them: the run's last
    observed state is at its duration, never short of an expectation's time."""
    if scenario.duration < scenario.dt:
        yield ("duration",), f"expected duration >= dt ({scenario.dt} s); got {scenario.duration} s"
    if scenario.duration / scenario.dt > MAX_STEPS:
        yield (
            ("duration",),
            f"{scenario.duration / scenario.dt:.3g} steps (duration / dt); at most {MAX_STEPS} are allowed",
        )
    elif scenario.duration >= scenario.dt and (
        fraction := whole_steps(scenario.duration, scenario.dt)
    ):
        yield ("duration",), fraction


def measured_contacts(scenario: Scenario) -> Found:
    """Every pair of bodies that can touch has a contact the reference side can measure
    (``validation.reference.contacts.PAIRS``: a cylinder against a capsule, a box or a
    cylinder has no closed form yet)."""
    bodies = scenario.bodies
    for i, j in unmeasured_pairs(scenario):
        where, other = (i, j) if bodies[i].shape.type == "cylinder" else (j, i)
        first, second = bodies[where], bodies[other]
        yield (
            ("bodies", where, "shape"),
            f"{first.name!r} and {second.name!r} can touch: a {first.shape.type} that can "
            f"touch a {second.shape.type} is not measured yet (keep them apart with "
            "collides: false on one, or fix both)",
        )


Rule = Callable[[Scenario], Found]

RULES: tuple[Rule, ...] = (
    unique_body_names,
    finite_mass_properties,
    bounded_scales,
    spring_ends,
    *JOINT_RULES,
    pair_bodies,
    expectations,
    joint_expectations_fit_their_joint,
    precession_needs_a_symmetry_axis,
    loads_on_moving_bodies,
    measured_contacts,
    known_findings,
    sweep_steps,
    engine_specs,
    check_names,
    step_count,
)
"""Every whole-document rule, in the order their problems are listed."""


# --- phase 2: what the scene can define ---------------------------------------------------


def _named_table_metrics(scenario: Scenario) -> bool:
    """Whether a check or a known finding names a metric of the definability table (only
    then is the scene compiled to read its traits)."""
    patterns = [f.metric for f in scenario.known if f.metric != ANY_METRIC]
    return any(m in UNDEFINED_WHEN for m in scenario.checks) or any(
        fnmatch.filter(UNDEFINED_WHEN, p) for p in patterns
    )


def checks_the_scene_defines(scenario: Scenario, traits: Traits) -> Found:
    """A ``checks`` entry names a metric this scene can define: else no row would ever be
    written, and the check would never run."""
    for metric in scenario.checks:
        why = why_undefined(metric, traits)
        if why is not None:
            yield (
                ("checks", metric),
                f"expected a metric this scene can define; {metric} is undefined here: {why} "
                "(no row would ever be written); remove the check",
            )


def known_findings_the_scene_defines(scenario: Scenario, traits: Traits) -> Found:
    """A known finding names a metric, or a pattern matching a metric, this scene can define
    (an entry that can only name undefined metrics would never match a row)."""
    always = [*(e.metric for e in scenario.expect), STATUS_METRIC]  # defined in every scene
    for i, finding in enumerate(scenario.known):
        pattern = finding.metric
        if pattern == ANY_METRIC or fnmatch.filter(always, pattern):
            continue
        undefined = {m: why_undefined(m, traits) for m in fnmatch.filter(UNDEFINED_WHEN, pattern)}
        if not undefined or any(why is None for why in undefined.values()):
            continue  # an unknown name (``known_findings``), or it matches a defined metric
        reasons = "; ".join(f"{m}: {why}" for m, why in undefined.items())
        yield (
            ("known", i, "metric"),
            f"expected a metric this scene can define; {pattern!r} names only undefined ones "
            f"({reasons}), so it would never match a row; remove the entry",
        )


SceneRule = Callable[[Scenario, Traits], Found]

SCENE_RULES: tuple[SceneRule, ...] = (checks_the_scene_defines, known_findings_the_scene_defines)
"""Rules that read the compiled scene's traits (run once the document rules hold)."""


# --- phase 3: tolerances that cannot fail -------------------------------------------------


def _norm(expectation) -> float:
    return float(np.linalg.norm(expectation.value))


def _size(expectation) -> float:
    return abs(float(expectation.value))


def _smallest(expectation) -> float:
    return min((abs(v) for v in expectation.value if v != 0.0), default=0.0)


def _turn(expectation) -> float:
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    return float(rotation_angle(np.asarray(expectation.value, dtype=float), identity))


EXPECTED_SIZE: dict[str, Callable] = {
    "velocity_after_impact": _norm,
    "position_at": _norm,
    "velocity_at": _norm,
    "angular_velocity_at": _norm,
    "angular_velocity_after_impact": _norm,
    "orientation_at": _turn,
    "bounce_heights": _smallest,
    "flip_times": _smallest,
    "impact_times": _smallest,
    "precession_rate": _size,
    "flips": _size,
    "energy_at": _size,
    "joint_position_at": _norm,
    "period": _size,
}
"""Expectation kind -> |expected| of its row: the error a reading of zero (an engine that did
nothing: no flip, no precession, no turn) would have. A vector's norm; an orientation's angle
from the identity (the row compares angles); a list's smallest non-zero entry (each entry must
be able to fail)."""


def requested_restitutions(scenario: Scenario) -> set[float]:
    """Every restitution the scene requests of a pair that can touch (two bodies not both
    fixed, or a moving body and the ground): the ``pairs`` entry's, else the pair rule of the
    two bodies' values. Counted per class of bodies with equal (restitution, fixed), so the
    cost is the classes', not the pairs'."""
    classes: dict[tuple, list[str]] = {}
    for body in scenario.bodies:
        classes.setdefault((body.restitution, body.fixed), []).append(body.name)
    if scenario.ground is not None:
        classes[(scenario.ground.restitution, True, "ground")] = ["ground"]
    class_of = {name: key for key, names in classes.items() for name in names}
    stated: dict[frozenset, float] = {}
    for pair in scenario.pairs:
        if pair.restitution is not None and pair.a != pair.b:
            stated.setdefault(frozenset((pair.a, pair.b)), pair.restitution)
    found: set[float] = set()
    covered: dict[frozenset, int] = {}
    for names, value in stated.items():
        first, second = (class_of[n] for n in names)
        if not (first[1] and second[1]):
            found.add(value)
            key = frozenset((first, second))
            covered[key] = covered.get(key, 0) + 1
    keys = list(classes)
    for i, first in enumerate(keys):
        for second in keys[i:]:
            count = len(classes[first])
            pairs = count * (count - 1) // 2 if first == second else count * len(classes[second])
            if (first[1] and second[1]) or pairs <= covered.get(frozenset((first, second)), 0):
                continue  # both fixed, or every such pair has its own value
            found.add(pair_rule("restitution", first[0], second[0], None))
    return found


def _expected_size(scenario: Scenario, metric: str, expected: dict) -> float:
    """|expected| of the rows of ``metric``: 0 for a conserved drift, a control (nothing
    turns, no penetration) or a comparison with another engine, which do not warn.
    ``expected`` maps each expectation's metric to it (built once per document: a map per
    check made ``check`` quadratic in the ``checks`` entries)."""
    if metric == "restitution_error":  # each impact is judged against its pair's e
        return min((e for e in requested_restitutions(scenario) if e > 0.0), default=0.0)
    if metric not in expected:
        return 0.0
    return EXPECTED_SIZE[expected[metric].kind](expected[metric])


def _tolerance_entries(scenario: Scenario, metric: str, tolerance: Tolerance) -> Iterator:
    """(location, tolerance, the engine specs it applies to) of one ``checks`` entry."""
    labels = [spec.label for spec in scenario.engine_specs]
    if not isinstance(tolerance, dict):
        yield ("checks", metric), tolerance, labels
        return
    for key, value in tolerance.items():
        specs = [key] if key != "default" else [x for x in labels if x not in tolerance]
        if specs:
            yield ("checks", metric, key), value, specs


FIX = (
    "give the row its physical tolerance and declare the gap under known: with its measured reason"
)
"""What a tolerance that cannot fail should become (the library's convention, scenarios/README.md)."""


def tolerances_can_fail(scenario: Scenario) -> Found:
    """A check's tolerance is below |expected|: else a reading of zero, an engine that did
    nothing, passes it. Controls (expected 0) and conserved drifts do not warn."""
    expected = {e.metric: e for e in scenario.expect}
    for metric, tolerance in scenario.checks.items():
        size = _expected_size(scenario, metric, expected)
        if size <= 0.0:
            continue
        for loc, value, specs in _tolerance_entries(scenario, metric, tolerance):
            if value >= size:
                yield (
                    loc,
                    f"expected a tolerance below |expected| = {size:.6g} of {metric}; got "
                    f"{value:.6g} for {', '.join(specs)}: a reading of 0 (an engine that did "
                    f"nothing) passes; {FIX}",
                )


WARNING_RULES: tuple[Rule, ...] = (tolerances_can_fail,)
"""Rules whose problems are warnings: the scene loads, but a row cannot do its job."""


def _place(file: str, source: SourceMap, found: Found, warning: bool = False) -> list[Problem]:
    return [
        Problem(file, path_text(loc), message, *(source.locate(loc) or (None, None)), warning)
        for loc, message in found
    ]


def _scene_problems(scenario: Scenario, file: str, source: SourceMap) -> list[Problem]:
    if not _named_table_metrics(scenario):
        return []
    traits = scene_traits(compile_scene(scenario))
    return [p for rule in SCENE_RULES for p in _place(file, source, rule(scenario, traits))]


ANNOTATION_RULES = frozenset(
    {
        expectations,
        joint_expectations_fit_their_joint,
        precession_needs_a_symmetry_axis,
        known_findings,
        sweep_steps,
        check_names,
    }
)
"""The rules of what is measured and judged (expectations, known findings, the sweep, the
checks), not of the scene itself: the scene rules and warnings read a consistent scene
whatever these find, so they run alongside (every problem of a file in one pass)."""


def document_problems(
    scenario: Scenario, file: str, source: SourceMap, partial: Partial | None = None
) -> list[Problem]:
    """Every problem the rules find, each placed at its field's line and column: the
    document rules' errors and, when the scene itself is consistent, the scene rules' errors
    and the warnings. ``partial``: ``scenario`` is the validated part of a file that failed
    the schema; a reference to what was left out is not reported, and the scene rules wait
    for a whole scene."""
    found = {rule: list(rule(scenario)) for rule in RULES}
    if partial is not None:  # placed in the file; a reference to what was left out is not one
        found = {
            rule: [
                (partial.in_file(loc), message)
                for loc, message in found[rule]
                if not partial.refers_to_left_out(loc)
            ]
            for rule in RULES
        }
    problems = [p for rule in RULES for p in _place(file, source, found[rule])]
    scene_broken = any(found[rule] for rule in RULES if rule not in ANNOTATION_RULES)
    if scene_broken or (partial is not None and not partial.whole_scene):
        return problems  # the scene rules and warnings read a consistent scene
    return (
        problems
        + _scene_problems(scenario, file, source)
        + [p for rule in WARNING_RULES for p in _place(file, source, rule(scenario), warning=True)]
    )
