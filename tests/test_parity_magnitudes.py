"""The parity gate judges each quantity against its physical magnitude
(``validation.engines.parity.Magnitudes``, ``validation.engines.reference.magnitudes``): a
total that cancels in the scene (two bodies moving apart) is held to what its terms round
off at the engine's precision, not to an absolute floor; a real model error is still caught."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.engines.parity import ABSOLUTE_FLOOR, PRECISION_TOLERANCE, compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.engines.sabotage import SABOTAGE_VARIABLE
from validation.scenario import Scenario, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

FLOAT32_EPSILON = float(np.finfo(np.float32).eps)
"""1.19e-7: one rounding of a float32 engine (the round-off of the issue's Rapier report)."""

SPEED, SPIN = 2.0, 5.0
"""m/s and rad/s: the two bodies fly apart along x and spin against each other about z."""


def cancelling_scene() -> Scenario:
    """Two equal boxes moving and spinning apart: zero linear and angular momentum."""
    bodies = [
        {
            "name": name,
            "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
            "mass": 1.5,
            "position": [side, 0.0, 1.0],
            "velocity": [side * SPEED, 0.0, 0.0],
            "angular_velocity": [0.0, 0.0, side * SPIN],
        }
        for name, side in (("left", -1.0), ("right", 1.0))
    ]
    return Scenario.model_validate(
        {"name": "apart", "dt": 0.001, "duration": 0.01, "gravity": [0, 0, 0], "bodies": bodies}
    )


def rounded(report, **offsets):
    """``report`` with ``offsets`` added to its quantities (an engine's readback)."""
    return dataclasses.replace(
        report, **{q: np.asarray(getattr(report, q)) + d for q, d in offsets.items()}
    )


def test_the_magnitudes_of_cancelling_totals_are_their_terms_sizes():
    expected = reference_report(compile_scene(cancelling_scene()))
    np.testing.assert_allclose(expected.linear_momentum, 0.0, atol=1e-15)
    np.testing.assert_allclose(expected.angular_momentum, 0.0, atol=1e-15)
    assert expected.magnitudes.linear_momentum == pytest.approx(2 * 1.5 * SPEED)
    inertia_z = 1.5 * (0.2**2 + 0.1**2) / 3  # a box's Izz, m (a² + b²) / 3 of half-extents
    spin = 2 * inertia_z * SPIN
    orbital = 0.0  # they move along the line of their centres
    assert expected.magnitudes.angular_momentum == pytest.approx(orbital + spin)


@pytest.mark.parametrize("quantity", ["linear_momentum", "angular_momentum"])
def test_a_float32_rounding_of_a_cancelling_total_is_no_mismatch(quantity):
    """The issue's case: 1.2e-7 kg·m/s of rounding on a zero total (then relative error
    0.119 against the absolute floor; now ~1e-8 of Σ m |v|)."""
    expected = reference_report(compile_scene(cancelling_scene()))
    engine = rounded(expected, **{quantity: np.array([FLOAT32_EPSILON, 0.0, 0.0])})
    assert compare(engine, expected, PRECISION_TOLERANCE["float32"]) == []


def test_a_float32_rounding_of_an_energy_that_cancels_is_no_mismatch():
    """A body below the origin rising at the speed that makes its energy zero
    (``½ m v² = -m g z``): a rounding of its height is judged against |m g z|."""
    scene = Scenario.model_validate(
        {
            "name": "rising",
            "dt": 0.001,
            "duration": 0.01,
            "bodies": [
                {
                    "name": "ball",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 2.0,
                    "position": [0.0, 0.0, -5.0],
                    "velocity": [0.0, 0.0, float(np.sqrt(2 * 9.81 * 5.0))],
                }
            ],
        }
    )
    expected = reference_report(compile_scene(scene))
    assert abs(expected.energy) < 1e-12
    potential = 2.0 * 9.81 * 5.0  # J, |m g z|, and as much kinetic energy
    engine = rounded(expected, energy=FLOAT32_EPSILON * potential)
    assert compare(engine, expected, PRECISION_TOLERANCE["float32"]) == []


def test_a_dropped_spin_term_in_a_cancelling_total_is_still_a_mismatch():
    """One body's ``I ω`` left out of the angular momentum: half the magnitude, a model error
    at either precision."""
    expected = reference_report(compile_scene(cancelling_scene()))
    dropped = np.array([0.0, 0.0, expected.magnitudes.angular_momentum / 2])
    for precision in ("float32", "float64"):
        found = compare(
            rounded(expected, angular_momentum=dropped), expected, PRECISION_TOLERANCE[precision]
        )
        assert [m.quantity for m in found] == ["angular_momentum"]
        assert found[0].relative_error == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("sabotage", "scene"),
    [
        ("box_inertia_swapped", "contact/box_drop_edge.yaml"),
        ("world_inertia_transposed", "contact/box_drop_edge.yaml"),
        ("capsule_no_parallel_axis", "rotation/capsule_precession.yaml"),
    ],
)
def test_sabotaged_inertias_are_still_model_mismatches(sabotage, scene, monkeypatch):
    """mini with an inertia bug (``validation.engines.sabotage``) fails the gate, at its own
    precision and at a float32 engine's."""
    monkeypatch.setenv(SABOTAGE_VARIABLE, sabotage)
    compiled = compile_scene(load_scenario(BUNDLED_SCENARIOS / scene))
    adapter = create_adapter(parse_engine_spec("mini"))
    try:
        adapter.load(compiled)
        report = adapter.model_report()
    finally:
        adapter.close()
    for precision in ("float64", "float32"):
        found = compare(report, reference_report(compiled), PRECISION_TOLERANCE[precision])
        assert "inertia_world" in {m.quantity for m in found}, (sabotage, precision)


@pytest.mark.skipif(
    importlib.util.find_spec("rapier3d") is None,
    reason='rapier3d is not installed (pip install "physval[rapier]")',
)
def test_rapier_passes_the_gate_on_a_head_on_pair():
    """Rapier itself (float32) on two cars closing head-on, 1300 kg at 8.2 m/s and 1000 kg at
    -10.66 m/s: p = -1.8e-12 kg·m/s of decimal round-off, Rapier's readback 5.6e-4 kg·m/s of
    float32 rounding. Against the absolute floor that read relative error 555; against the
    21,320 kg·m/s the cars carry it is 2.6e-8."""
    scene = compile_scene(
        Scenario.model_validate(
            {
                "name": "head_on",
                "dt": 0.001,
                "duration": 0.01,
                "gravity": [0, 0, 0],
                "bodies": [
                    {
                        "name": name,
                        "shape": {"type": "box", "half_extents": [2.0, 1.0, 0.7]},
                        "mass": mass,
                        "position": [x, 0.0, 1.0],
                        "velocity": [speed, 0.0, 0.0],
                    }
                    for name, mass, x, speed in (
                        ("a", 1300.0, -5.0, 8.2),
                        ("b", 1000.0, 5.0, -10.66),
                    )
                ],
            }
        )
    )
    adapter = create_adapter(parse_engine_spec("rapier"))
    try:
        adapter.load(scene)
        report = adapter.model_report()
    finally:
        adapter.close()
    expected = reference_report(scene)
    assert abs(report.linear_momentum[0]) > 1e3 * ABSOLUTE_FLOOR  # the rounding is there
    assert compare(report, expected, PRECISION_TOLERANCE["float32"]) == []
    assert expected.magnitudes.linear_momentum == pytest.approx(21320.0)
