"""Every row can fail: a tolerance no reading can exceed warns at every load, and a check (or a
known finding) on a metric the scene cannot define is a load error naming why; the
definability rule and the metrics agree on every library scene."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.measure.definitions import TIERS
from validation.reference.rotation import rotation_angle
from validation.scenario import (
    Scenario,
    ScenarioError,
    check_scenario,
    load_scenario,
    scenario_files,
)
from validation.scenario.schema import EXPECTATION_MODELS, METRIC_NAMES

MODEL_TIER_METRICS = tuple(
    m for tier in TIERS for m in tier if m not in ("energy_drift", "joint_violation")
)
"""The model tiers' own metrics (issue 36): defined only for a scene with models."""

FIX = (
    "give the row its physical tolerance and declare the gap under known: with its measured reason"
)

SPINNING_BOX = """\
description: a box spun near its intermediate axis
dt: 0.01
duration: 1.0
gravity: [0, 0, 0]
engines: [mini, "mini(gyroscopic=implicit)"]
bodies:
  - name: box
    shape: {type: box, half_extents: [0.3, 0.2, 0.1]}
    mass: 1.0
    angular_velocity: [0.05, 10.0, 0.05]
"""

TOP = SPINNING_BOX.replace("[0.3, 0.2, 0.1]", "[0.15, 0.15, 0.05]")
"""An axisymmetric plate instead (precession_rate needs a symmetry axis)."""


def write(tmp_path: Path, text: str, name: str = "scene.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def warned(path: Path) -> list:
    """The warnings ``check_scenario`` reports for ``path`` (the scene must load)."""
    scenario, problems = check_scenario(path)
    assert scenario is not None, [str(p) for p in problems]
    return [p for p in problems if p.warning]


# --- a tolerance no reading can exceed warns ----------------------------------------------


def test_a_flip_tolerance_of_the_expected_count_warns_naming_line_metric_spec_numbers_and_fix(
    tmp_path,
):
    """The documented law's flips.box read 0 against 3 and passed on a tolerance of 3."""
    text = SPINNING_BOX + (
        "expect:\n  - {kind: flips, body: box, axis: y, value: 3}\n"
        "checks:\n  flips.box: {mini: 3}\n"
    )
    path = write(tmp_path, text)
    (problem,) = warned(path)
    assert (problem.line, problem.column) == (14, 15), problem
    assert problem.path == "checks.flips.box.mini", problem
    message = str(problem)
    assert message.startswith(f"{path}:14:15: warning: checks.flips.box.mini:"), message
    for part in ("|expected| = 3 of flips.box", "got 3 for mini", FIX):
        assert part in message, message


def test_every_load_issues_the_warning_at_the_scene_line(tmp_path):
    """``load_scenario`` (physval run, the pytest plugin) warns too, as a ScenarioWarning
    placed at the YAML line, not only ``physval check``."""
    text = TOP + (
        "expect:\n  - {kind: precession_rate, body: box, value: 8.0}\n"
        "checks:\n  precession_rate.box: {default: 0.01, mini: 8.1}\n"
    )
    path = write(tmp_path, text)
    from validation.scenario import ScenarioWarning

    with pytest.warns(ScenarioWarning) as caught:
        load_scenario(path)
    (record,) = caught.list
    assert (record.filename, record.lineno) == (str(path), 14), record
    assert "precession_rate.box.mini" in str(record.message), record.message
    assert "got 8.1 for mini" in str(record.message) and FIX in str(record.message)


def test_physval_check_prints_the_warning_and_exits_0(tmp_path, capsys):
    text = SPINNING_BOX + (
        "expect:\n  - {kind: flips, body: box, axis: y, value: 3}\nchecks:\n  flips.box: 3\n"
    )
    path = write(tmp_path, text)
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{path}:14:3: warning: checks.flips.box:" in out, out
    assert "got 3 for mini, mini(gyroscopic=implicit)" in out, out
    assert "1 file: 1 valid, 0 invalid, 1 warning" in out, out


PYTEST = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider"]
"""pytest as a user runs it (collecting is loading: the warning needs no engine run)."""


def test_the_pytest_plugin_lists_the_warning(tmp_path):
    """``pytest --physval`` collects the scene and lists the warning in its summary."""
    text = SPINNING_BOX + (
        "expect:\n  - {kind: flips, body: box, axis: y, value: 3}\n"
        "checks:\n  flips.box: {mini: 3}\n"
    )
    write(tmp_path, text, "frozen.yaml")
    result = subprocess.run(
        [*PYTEST, "--physval", "frozen.yaml", "--collect-only", "-q"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "frozen.yaml:14: ScenarioWarning: checks.flips.box.mini:" in result.stdout, result.stdout


@pytest.mark.parametrize(
    ("expect", "checks"),
    [
        # a physical tolerance below the expected magnitude
        ("{kind: flips, body: box, axis: y, value: 3}", "flips.box: 0"),
        ("{kind: precession_rate, body: box, value: 8.0}", "precession_rate.box: 0.01"),
        # controls: the expected value is 0 ("no flip", "nothing turns")
        ("{kind: flips, body: box, axis: y, value: 0}", "flips.box: 1"),
        (
            "{kind: angular_velocity_at, body: box, time: 1.0, value: [0, 0, 0]}",
            "angular_velocity_at.box: 1.0",
        ),
        # conserved drifts, expected 0
        ("{kind: flips, body: box, axis: y, value: 3}", "energy_drift: 1.0"),
        ("{kind: flips, body: box, axis: y, value: 3}", "angular_momentum_drift: 2.0"),
    ],
)
def test_physical_tolerances_controls_and_conserved_drifts_do_not_warn(tmp_path, expect, checks):
    text = (
        TOP if "precession" in expect else SPINNING_BOX
    ) + f"expect:\n  - {expect}\nchecks:\n  {checks}\n"
    assert warned(write(tmp_path, text)) == []


def test_a_default_that_no_spec_takes_does_not_warn_and_one_that_some_take_names_them(tmp_path):
    head = SPINNING_BOX + "expect:\n  - {kind: flips, body: box, axis: y, value: 3}\n"
    unused = head + 'checks:\n  flips.box: {default: 5, mini: 0, "mini(gyroscopic=implicit)": 0}\n'
    assert warned(write(tmp_path, unused)) == []
    used = head + "checks:\n  flips.box: {default: 5, mini: 0}\n"
    (problem,) = warned(write(tmp_path, used))
    assert problem.path == "checks.flips.box.default"
    assert "got 5 for mini(gyroscopic=implicit)" in problem.message, problem.message


BALL_ON_GROUND = """\
description: balls dropped on the ground
dt: 0.001
duration: 1.0
engines: [mini]
ground: {restitution: 0.5}
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 1], restitution: 0.005}
"""


def test_restitution_tolerances_are_judged_against_the_smallest_requested_e(tmp_path):
    """One ball on a ground of e = 0.5 (max rule: 0.5; no ball-ball pair exists): 0.01 is a
    check. A second ball of e = 0.005 makes a ball-ball pair of 0.005: 0.01 then cannot fail."""
    one = BALL_ON_GROUND + "checks:\n  restitution_error: 0.01\n"
    assert warned(write(tmp_path, one)) == []
    two = (
        BALL_ON_GROUND
        + "  - {name: other, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 2],"
        " restitution: 0.005}\nchecks:\n  restitution_error: 0.01\n"
    )
    (problem,) = warned(write(tmp_path, two))
    assert "|expected| = 0.005 of restitution_error" in problem.message, problem.message
    overridden = two.replace("checks:", "pairs: [{a: ball, b: other, restitution: 0.3}]\nchecks:")
    assert warned(write(tmp_path, overridden)) == [], "the only ball-ball pair states 0.3"


def test_every_expectation_kind_has_an_expected_magnitude():
    from validation.scenario.checks import EXPECTED_SIZE

    kinds = {model.model_fields["kind"].annotation.__args__[0] for model in EXPECTATION_MODELS}
    assert set(EXPECTED_SIZE) == kinds


# --- a metric the scene cannot define is a load error -------------------------------------

FREE_BALL = """\
description: a ball in free flight
dt: 0.01
duration: 1.0
engines: [mini, mujoco]
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0}
"""
SECOND_BALL = "  - {name: other, shape: {type: sphere, radius: 0.1}, mass: 2.0, position: [5, 0, 0]"
WORLD_HINGE = (
    "joints: [{name: pin, type: hinge, parent: world, child: ball, anchor: [0, 0, 0.5], "
    "axis: [0, 1, 0]}]\n"
)
BALL_JOINT = "joints: [{name: link, type: ball, parent: ball, child: other, anchor: [2.5, 0, 0]}]\n"

ARM = """\
description: the Kuka arm of pybullet_data, hanging from its fixed base
dt: 0.01
duration: 1.0
engines: [mini, rapier]
models:
  - {name: arm, file: "pkg:pybullet_data/kuka_iiwa/model.urdf"}
"""

UNDEFINED = {
    "restitution where nothing can touch": (
        FREE_BALL,
        "restitution_error",
        "nothing in the scene can touch",
    ),
    "penetration where nothing can touch": (
        FREE_BALL,
        "penetration_max",
        "nothing in the scene can touch",
    ),
    "position error where bodies can touch": (
        FREE_BALL + "ground: {}\n",
        "position_error",
        "bodies can touch",
    ),
    "velocity error where a spring acts": (
        FREE_BALL.replace("engines", "gravity: [0, 0, 0]\nengines")
        + "springs: [{a: ball, b: world, stiffness: 10}]\n",
        "velocity_error",
        "a spring acts",
    ),
    "linear momentum with a ground": (
        FREE_BALL + "ground: {}\n",
        "linear_momentum_drift",
        "a ground, a fixed body, a spring or a joint to the world",
    ),
    "linear momentum with a fixed body": (
        FREE_BALL + SECOND_BALL + ", fixed: true}\n",
        "linear_momentum_drift",
        "a ground, a fixed body, a spring or a joint to the world",
    ),
    "angular momentum with a world spring": (
        FREE_BALL + "springs: [{a: ball, b: world, stiffness: 10}]\n",
        "angular_momentum_drift",
        "a ground, a fixed body, a spring or a joint to the world",
    ),
    "linear momentum with a joint to the world": (
        FREE_BALL + WORLD_HINGE,
        "linear_momentum_drift",
        "a ground, a fixed body, a spring or a joint to the world",
    ),
    "position error where a joint acts": (
        FREE_BALL + SECOND_BALL + "}\n" + BALL_JOINT,
        "position_error",
        "joints hold the bodies",
    ),
    "energy with a damped joint": (
        FREE_BALL + WORLD_HINGE.replace("axis: [0, 1, 0]}", "axis: [0, 1, 0], damping: 0.1}"),
        "energy_drift",
        "a damped joint dissipates energy",
    ),
    "joint violation without joints": (FREE_BALL, "joint_violation", "the scene has no joints"),
    "angular momentum where g + F/m differs": (
        FREE_BALL + SECOND_BALL + ", force: [1, 0, 0]}\n",
        "angular_momentum_drift",
        "g + F/m differs between bodies",
    ),
    "energy under an applied torque": (
        FREE_BALL.replace("mass: 1.0}", "mass: 1.0, torque: [0, 0, 1]}"),
        "energy_drift",
        "an applied torque does work with no potential",
    ),
    "energy with a damped spring": (
        FREE_BALL + "springs: [{a: ball, b: world, stiffness: 10, damping: 1}]\n",
        "energy_drift",
        "a damped spring dissipates energy",
    ),
    "divergence with a single engine": (
        FREE_BALL.replace("[mini, mujoco]", "[mini]"),
        "divergence",
        "the scene lists one engine",
    ),
    **{
        f"{metric} without models": (FREE_BALL, metric, "the scene has no models")
        for metric in MODEL_TIER_METRICS
    },
    "agreement time without a joint_divergence band": (
        ARM,
        "agreement_time",
        "its band is the scene's joint_divergence tolerance",
    ),
}


@pytest.mark.parametrize("case", sorted(UNDEFINED))
def test_a_check_on_an_undefined_metric_is_a_load_error_naming_why(tmp_path, case):
    scene, metric, why = UNDEFINED[case]
    path = write(tmp_path, scene + f"checks:\n  {metric}: 0.01\n")
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    (problem,) = caught.value.problems
    line = scene.count("\n") + 2
    assert str(problem).startswith(f"{path}:{line}:3: checks.{metric}: "), str(problem)
    assert why in problem.message and f"{metric} is undefined here" in problem.message, problem


def test_the_same_checks_load_where_the_scene_defines_them(tmp_path):
    """Controls: every metric of the table loads on a scene that defines it."""
    free = (
        FREE_BALL
        + "checks:\n"
        + "".join(
            f"  {m}: 0.01\n"
            for m in METRIC_NAMES
            if m not in ("restitution_error", "penetration_max", "joint_violation")
            and m not in MODEL_TIER_METRICS
        )
    )
    load_scenario(write(tmp_path, free))
    tiers = "".join(f"  {m}: 0.01\n" for m in MODEL_TIER_METRICS)
    load_scenario(write(tmp_path, ARM + "checks:\n" + tiers, "arm.yaml"))
    jointed = FREE_BALL + SECOND_BALL + "}\n" + BALL_JOINT + "checks: {joint_violation: 0.01}\n"
    load_scenario(write(tmp_path, jointed, "jointed.yaml"))
    touching = FREE_BALL + "ground: {}\nchecks: {restitution_error: 0.01, penetration_max: 0.01}\n"
    load_scenario(write(tmp_path, touching, "touching.yaml"))


def test_physval_check_exits_2_naming_the_reason_without_traceback(tmp_path):
    path = write(tmp_path, FREE_BALL + "checks:\n  restitution_error: 0.01\n")
    result = subprocess.run(
        [sys.executable, "-m", "validation.cli", "check", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2, result
    assert "Traceback" not in result.stderr, result.stderr
    expected = f"{path}:8:3: checks.restitution_error: expected a metric this scene can define"
    assert expected in result.stderr and "nothing in the scene can touch" in result.stderr


@pytest.mark.parametrize(
    ("metric", "error"),
    [
        ("linear_momentum_drift", True),  # a ground: undefined
        ("*_momentum_drift", True),  # matches only undefined metrics
        ("*_drift", False),  # energy_drift is defined
        ("penetration_max", False),
        ("*", False),
        ("status", False),
    ],
)
def test_a_known_finding_on_an_undefined_metric_is_a_load_error(tmp_path, metric, error):
    text = FREE_BALL + (
        f'ground: {{}}\nknown:\n  - {{engine: mini, metric: "{metric}", reason: measured}}\n'
    )
    path = write(tmp_path, text)
    if not error:
        load_scenario(path)
        return
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    (problem,) = caught.value.problems
    assert problem.path == "known[0].metric" and problem.line == 9, problem
    assert "a ground, a fixed body, a spring or a joint to the world" in problem.message, problem


# --- the library --------------------------------------------------------------------------

LIBRARY = scenario_files([BUNDLED_SCENARIOS])
OVERLAP_WARNING = "overlap by"
"""The one warning the library means: stiff/deep_initial_penetration's 4 cm overlap at t = 0."""


def test_the_library_warns_only_at_its_intended_overlap(capsys):
    assert main(["check", str(BUNDLED_SCENARIOS)]) == 0, capsys.readouterr().err
    lines = [line for line in capsys.readouterr().out.splitlines() if ": warning: " in line]
    assert len(lines) == 1, lines
    assert "deep_initial_penetration.yaml" in lines[0] and OVERLAP_WARNING in lines[0], lines


LISTS = ("bounce_heights", "flip_times", "impact_times")


def magnitude(expectation) -> float:
    """|expected| as the row reads it, stated apart from the loader's table: an orientation's
    turn from the identity, a list's smallest non-zero entry, a vector's norm, a number's size."""
    value = expectation.value
    if expectation.kind == "orientation_at":
        return float(rotation_angle(np.array(value), np.array([1.0, 0.0, 0.0, 0.0])))
    if expectation.kind in LISTS:
        return min((abs(v) for v in value if v), default=0.0)
    return float(np.linalg.norm(value))


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_library_tolerance_is_below_its_expected_magnitude(path):
    """Every spec's tolerance of a non-zero expectation is below its magnitude: an engine that
    never flips, precesses or moves fails it (a known finding then says so)."""
    scenario = load_scenario(path)
    loose = [
        f"{e.metric} for {spec.label}: tolerance {tolerance} >= |expected| {magnitude(e):.6g}"
        for e in scenario.expect
        for spec in scenario.engine_specs
        if (tolerance := scenario.tolerance(e.metric, spec.label)) is not None
        and 0.0 < magnitude(e) <= tolerance
    ]
    assert not loose, loose


AGREEMENT_STEPS = 500
"""Steps each library scene runs for the agreement test (definability is static: a shorter
run changes only which impacts happen, which the test allows for)."""


def _short(scenario: Scenario) -> Scenario:
    duration = min(scenario.duration, AGREEMENT_STEPS * scenario.dt)
    data = {**scenario.model_dump(), "duration": duration, "sweep": None}
    return Scenario.model_validate({**data, "source": scenario.source})


ACROSS_ENGINES = {"divergence", "joint_divergence", "agreement_time"}
"""The metrics the comparator measures against the scene's reference engine."""

AGREEMENT_ENGINES = ("mini", "mujoco")
"""The engine each library scene runs in for the agreement test: mini, or MuJoCo for a scene
mini cannot represent (a cylinder: ``cylinder_rolls_down_incline``)."""


@pytest.mark.slow
def test_the_rule_and_the_metrics_agree_on_every_library_scene():
    """For each library scene run in mini (MuJoCo where mini cannot represent it:
    ``AGREEMENT_ENGINES``), the metrics ``measure`` emits are exactly those the
    definability rule says the scene defines (``ACROSS_ENGINES`` are the comparator's, against
    a second engine), except ``restitution_error``, which also needs an impact in the run, and
    ``mass_matrix_error``, which mini (no joint coordinates, no M) never gives."""
    from validation.jobs.run import run_job
    from validation.scenario.compiled import compile_scene
    from validation.scenario.definability import defined_metrics, scene_traits
    from validation.scenario.engine_spec import parse_engine_spec

    mismatches, impacts_seen = [], 0
    for path in LIBRARY:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = compile_scene(_short(load_scenario(path)))
        for engine in AGREEMENT_ENGINES:
            run, measured = run_job((scene, parse_engine_spec(engine)))
            if run.status != "unsupported":
                break
        assert run.recording is not None, f"{path.stem}: {run.status}"
        emitted = {m.metric for m in measured} & set(METRIC_NAMES)
        defined = defined_metrics(scene_traits(scene)) - ACROSS_ENGINES - {"mass_matrix_error"}
        if not run.recording.impacts:
            defined.discard("restitution_error")
        impacts_seen += "restitution_error" in emitted
        if emitted != defined:
            mismatches.append(f"{path.stem}: emitted {sorted(emitted)}, rule {sorted(defined)}")
    assert not mismatches, "\n".join(mismatches)
    assert impacts_seen >= 5, "too few scenes had an impact to exercise restitution_error"
