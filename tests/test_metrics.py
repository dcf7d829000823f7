"""Metrics against hand-computed cases, and the comparator's pass / fail / no-tolerance rows."""

from __future__ import annotations

import numpy as np
import pytest

from validation.contract import NIGHTLY_COLUMNS
from validation.measure.comparator import COLUMNS, compare_scene
from validation.measure.metrics import METRICS, Context, measure
from validation.measure.recording import ImpactEvent, Trajectory, measure_trajectory
from validation.measure.runner import EngineRun
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene

G = 9.81


def scene(**extra) -> Scenario:
    data = {
        "name": "hand",
        "dt": 0.1,
        "duration": 1.0,
        "bodies": [
            {
                "name": "b",
                "shape": {"type": "sphere", "radius": 0.1},
                "mass": 2.0,
                "velocity": [1.0, 0.0, 0.0],
            }
        ],
    }
    return Scenario.model_validate({**data, **extra})


def trajectory(pos, vel) -> Trajectory:
    """One sphere, identity orientation, no spin; ``pos``/``vel`` are (s, 3)."""
    pos, vel = np.asarray(pos, float)[:, None, :], np.asarray(vel, float)[:, None, :]
    samples = pos.shape[0]
    quat = np.tile([1.0, 0, 0, 0], (samples, 1, 1))
    return Trajectory(np.arange(samples) * 0.1, pos, quat, vel, np.zeros_like(vel))


def recorded(scenario, states: Trajectory, impacts=()) -> Context:
    """The context of ``states`` measured as a run is (``measure_trajectory``); ``impacts``
    replaces the detected ones when given."""
    scene = compile_scene(scenario)
    recording = measure_trajectory(scene, states)
    if impacts:
        recording.impacts = list(impacts)
    return Context(scene, recording)


def context(scenario, pos, vel, impacts=()) -> Context:
    return recorded(scenario, trajectory(pos, vel), impacts)


def test_energy_drift_by_hand():
    """m = 2 kg, no gravity: speeds 1, 1, 1.1 m/s give E = 1, 1, 1.21 J: ΔE = 0.21 J over
    E_scale = the largest internal energy (no gravity: no weight term). One free body has no
    kinetic energy about its centre of mass (no spin); its centre of mass's change of motion,
    ½ m |v(t) - v(0)|², is 0, 2, 0.01 J (v turns from x to y): E_scale = 2 J."""
    ctx = context(scene(gravity=[0, 0, 0]), [[0, 0, 0]] * 3, [[1, 0, 0], [0, 1, 0], [1.1, 0, 0]])
    result = METRICS["energy_drift"](ctx)
    assert result.value == pytest.approx(0.21 / 2.0) and result.error == result.value
    assert result.signed == pytest.approx((0.21 / 2.0,)), "energy gained: a positive sign"
    # value the measured drift, expected its target 0, error the difference
    assert result.expected == 0.0 and result.expected_kind == "conserved"
    assert "0.21 J" in result.message and "E_scale 2 J" in result.message, result.message


def test_energy_drift_scale_is_kinetic_plus_weight_times_size():
    """A 2 kg sphere of radius 0.1 m at rest under gravity, sinking 1 mm: ΔE = -m·g·0.001 over
    E_scale = m·g·r (nothing moves): -0.01, whatever the height it rests at."""
    for height in (0.0, 1000.0):
        pos = [[0, 0, height], [0, 0, height - 1e-3]]
        ctx = context(scene(), pos, [[0, 0, 0]] * 2)
        result = METRICS["energy_drift"](ctx)
        assert result.value == pytest.approx(0.01) and result.signed == pytest.approx((-0.01,))


def test_energy_drift_is_absolute_when_the_scale_is_zero():
    """No gravity, no spring, at rest throughout: E_scale = 0, the drift is in J."""
    ctx = context(scene(gravity=[0, 0, 0]), [[0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    result = METRICS["energy_drift"](ctx)
    assert result.value == 0.0 and "absolute" in result.message


def test_ballistic_errors_are_zero_on_the_parabola_and_measure_an_offset():
    t = np.arange(11) * 0.1
    pos = np.stack([t, 0 * t, -0.5 * G * t**2], axis=1)
    vel = np.stack([np.ones_like(t), 0 * t, -G * t], axis=1)
    exact = context(scene(), pos, vel)
    assert METRICS["position_error"](exact).value == pytest.approx(0.0, abs=1e-12)
    assert METRICS["velocity_error"](exact).value == pytest.approx(0.0, abs=1e-12)
    shifted = context(scene(), pos + np.array([0.0, 0.0, 0.003]), vel)
    assert METRICS["position_error"](shifted).value == pytest.approx(0.003)


def test_linear_momentum_drift_follows_gravity_and_is_undefined_with_a_ground():
    t = np.arange(11) * 0.1
    vel = np.stack([np.ones_like(t), 0 * t, -G * t], axis=1)
    free = context(scene(), np.zeros((11, 3)), vel)
    assert METRICS["linear_momentum_drift"](free).value == pytest.approx(0.0, abs=1e-12)
    grounded = context(scene(ground={}), np.zeros((11, 3)), vel)
    assert METRICS["linear_momentum_drift"](grounded) is None
    assert METRICS["angular_momentum_drift"](grounded) is None
    assert METRICS["position_error"](grounded) is None, "bodies can touch the ground"


def test_restitution_error_is_the_worst_impact_and_undefined_without_impacts():
    ground = scene(ground={"restitution": 0.5})
    impacts = [
        ImpactEvent("ground", "b", 0.1, 0.2, 0.2, (0, 0, 1), -2.0, 1.0),  # e = 0.5
        ImpactEvent("ground", "b", 0.5, 0.6, 0.6, (0, 0, 1), -1.0, 0.45),  # e = 0.45
    ]
    ctx = context(ground, np.zeros((3, 3)), np.zeros((3, 3)), impacts)
    result = METRICS["restitution_error"](ctx)
    assert result.error == pytest.approx(0.05) and result.expected == 0.5
    assert result.value == pytest.approx(0.45), "value is the worst impact's measured e"
    assert result.band == 0.0, "events without an approach acceleration have no band"
    assert METRICS["restitution_error"](context(ground, np.zeros((3, 3)), np.zeros((3, 3)))) is None


def run_of(scenario, pos, vel) -> EngineRun:
    return EngineRun(
        scenario.name, "mini", "ok", recording=recorded(scenario, trajectory(pos, vel)).recording
    )


def test_comparator_rows_pass_fail_and_no_tolerance():
    t = np.arange(11) * 0.1
    pos = np.stack([t, 0 * t, -0.5 * G * t**2], axis=1)
    vel = np.stack([np.ones_like(t), 0 * t, -G * t], axis=1)
    checked = scene(
        checks={"position_error": 0.001, "velocity_error": {"default": 1e-9, "mini": 0.0}}
    )
    rows = compare_scene(
        compile_scene(checked), [run_of(checked, pos + np.array([0.0, 0.0, 0.003]), vel)]
    )
    by_metric = {row["metric"]: row for row in rows}
    assert set(rows[0]) == set(COLUMNS) - set(NIGHTLY_COLUMNS)  # added by the run's nightly phase
    assert (
        by_metric["position_error"]["passed"] is False
        and by_metric["position_error"]["status"] == "failed"
    )
    assert (
        by_metric["velocity_error"]["passed"] is True
        and by_metric["velocity_error"]["tolerance"] == 0.0
    )
    assert by_metric["energy_drift"]["passed"] is None, "no tolerance: passed must stay empty"
    assert "restitution_error" not in by_metric and "penetration_max" not in by_metric
    assert set(by_metric) <= set(METRICS) | {"divergence"}


def test_measure_lists_only_definable_metrics_for_a_free_body():
    ctx = context(scene(), np.zeros((3, 3)), np.tile([1.0, 0, 0], (3, 1)))
    names = {m.metric for m in measure(ctx)}
    assert names == {
        "energy_drift",
        "angular_momentum_drift",
        "linear_momentum_drift",
        "position_error",
        "velocity_error",
    }, names


def test_angular_momentum_drift_by_hand():
    """Two 2 kg spheres at x = ±1 m moving ±1 m/s along y: L about their centre = 4 kg·m²/s
    along z; moving them to ±1.1 m/s gives 4.4: ΔL = 0.4 over the scale, the largest sum of
    the bodies' own |L| over the run (2.2 + 2.2 = 4.4): drift 1/11."""
    two = scene(
        gravity=[0, 0, 0],
        bodies=[
            {
                "name": "a",
                "shape": {"type": "sphere", "radius": 0.1},
                "mass": 2.0,
                "position": [1, 0, 0],
            },
            {
                "name": "b",
                "shape": {"type": "sphere", "radius": 0.1},
                "mass": 2.0,
                "position": [-1, 0, 0],
            },
        ],
    )
    pos = np.array([[[1.0, 0, 0], [-1.0, 0, 0]]] * 2)
    vel = np.array([[[0, 1.0, 0], [0, -1.0, 0]], [[0, 1.1, 0], [0, -1.1, 0]]])
    traj = Trajectory(
        np.array([0.0, 0.1]), pos, np.tile([1.0, 0, 0, 0], (2, 2, 1)), vel, np.zeros_like(vel)
    )
    result = METRICS["angular_momentum_drift"](recorded(two, traj))
    assert result.value == pytest.approx(0.4 / 4.4) and result.expected == 0.0
    assert "without cancellation 4.4" in result.message, result.message


def test_penetration_max_is_the_deepest_overlap_over_the_samples():
    """A 0.1 m sphere at heights 0.2, 0.097, 0.099 m above the ground: 3 mm deepest."""
    grounded = scene(ground={})
    pos = [[0, 0, 0.2], [0, 0, 0.097], [0, 0, 0.099]]
    result = METRICS["penetration_max"](context(grounded, pos, np.zeros((3, 3))))
    assert result.value == pytest.approx(0.003)
    assert METRICS["penetration_max"](context(scene(), pos, np.zeros((3, 3)))) is None, (
        "nothing can touch"
    )


def test_divergence_is_the_largest_centre_of_mass_distance_to_the_reference():
    from validation.measure.metrics import divergence

    base = scene()
    reference = context(base, [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], np.zeros((3, 3)))
    other = context(base, [[0, 0, 0], [0.1, 0.004, 0], [0.2, 0, 0.002]], np.zeros((3, 3)))
    result = divergence(other, reference, "mini")
    assert result.value == pytest.approx(0.004) and result.expected_kind == "engine:mini"
