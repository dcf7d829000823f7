"""Trajectories and impact events, derived from observed states the same way for every engine."""

from __future__ import annotations

import numpy as np
import pytest

from validation.engines.registry import create_adapter
from validation.measure.recording import record
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

MINI_EVENT_RESTITUTION = 1e-6
"""Absolute. mini_engine resolves an impact in one semi-implicit step, for which carrying
both velocities to the impulse centroid is exact; what is left is round-off of the
observed velocities (measured 5e-9 down to 0.004 m/s impacts)."""


def ladder(e: float) -> Scenario:
    return Scenario.model_validate(
        {
            "name": "ladder",
            "dt": 0.001,
            "duration": 1.5,
            "ground": {"restitution": e},
            "bodies": [
                {
                    "name": "ball",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0, 0, 0.6],
                    "restitution": e,
                },
                {
                    "name": "cube",
                    "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
                    "mass": 2.0,
                    "position": [2, 0, 0.6],
                    "restitution": e,
                },
            ],
        }
    )


@pytest.mark.parametrize("e", [0.1, 0.5, 0.9, 1.0])
def test_impact_events_measure_the_requested_restitution(e):
    scenario = ladder(e)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    recording = record(adapter, compile_scene(scenario), sample_every=10)
    bodies = {event.body_b for event in recording.impacts}
    assert bodies == {"ball", "cube"}, f"impacts of {bodies}"
    assert all(event.body_a == "ground" for event in recording.impacts)
    # With e = 0.1 the second bounce (0.03 m/s) cannot clear the 84 µm overlap the first impact
    # left (no position correction, as documented): the contact persists, gravity re-engages
    # it and the event aggregates several impulses (measured e = 0.58). Clean impacts only.
    clean = recording.impacts[:2] if e < 0.5 else recording.impacts
    errors = [abs(event.restitution - e) for event in clean]
    assert max(errors) < MINI_EVENT_RESTITUTION, f"worst |e - {e}| = {max(errors):.3e}"
    first = recording.impacts[0]
    assert np.allclose(first.normal, [0, 0, 1]), first.normal
    assert first.normal_velocity_before < 0 < first.normal_velocity_after


def test_every_state_is_observed_and_the_trajectory_keeps_the_samples():
    """Measuring sees every state (full time resolution); only every 25th is kept."""
    scenario = Scenario.model_validate(
        {
            "name": "fly",
            "dt": 0.001,
            "duration": 0.1,
            "bodies": [{"name": "b", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0}],
        }
    )
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    observed = {"start": 0, "steps": []}
    observe, advance_observed = adapter.observe, adapter.advance_observed

    def counting_observe():
        observed["start"] += 1
        return observe()

    def counting_steps(steps):
        states = advance_observed(steps)
        observed["steps"] += states.t.tolist()
        return states

    adapter.observe, adapter.advance_observed = counting_observe, counting_steps
    recording = record(adapter, compile_scene(scenario), sample_every=25)
    assert recording.trajectory.t.tolist() == pytest.approx([0.0, 0.025, 0.05, 0.075, 0.1])
    assert recording.trajectory.pos.shape == (5, 1, 3)
    every_step = pytest.approx([0.001 * (k + 1) for k in range(scenario.steps)])
    assert observed["start"] == 1 and observed["steps"] == every_step, observed
    assert recording.impacts == []


def test_spinning_oblique_impact_is_measured_along_the_impulse_direction():
    """Spinning spheres meeting off-centre: arms and normal frozen at first contact keep
    ω × r out of the normal speed (with per-observation geometry this read 0.80058)."""
    from validation.cli import BUNDLED_SCENARIOS
    from validation.scenario import load_scenario

    scenario = load_scenario(BUNDLED_SCENARIOS / "formulas" / "oblique_impact_spin.yaml")
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    (event,) = record(adapter, compile_scene(scenario)).impacts
    assert abs(event.restitution - 0.8) < MINI_EVENT_RESTITUTION, f"e = {event.restitution:.9f}"


@pytest.mark.parametrize("speed", [1.0, 0.3, 0.1])
def test_a_plastic_impact_measures_e_zero(speed):
    """e = 0 on the ground: the event closes while the ball rests, at exactly e = 0 (the
    resting steps after the impulse are the support cancelling gravity, not the impact)."""
    scenario = Scenario.model_validate(
        {
            "name": "plastic",
            "dt": 0.001,
            "duration": 0.3,
            "ground": {},
            "bodies": [
                {
                    "name": "b",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0, 0, 0.15],
                    "velocity": [0, 0, -speed],
                }
            ],
        }
    )
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    (event,) = record(adapter, compile_scene(scenario)).impacts
    assert abs(event.restitution) < MINI_EVENT_RESTITUTION, f"e = {event.restitution:.3e}"


def _short_batches(adapter, non_finite: bool):
    """``adapter.advance_observed`` cut after half of its first batch, the last state kept
    made non-finite or not: what an engine that refuses to go on hands the recorder."""
    observed = adapter.advance_observed

    def short(steps):
        states = observed(steps).take(slice(0, steps // 2))
        if non_finite:
            states.pos[-1] = np.nan
        return states

    adapter.advance_observed = short


@pytest.mark.parametrize("non_finite", [True, False])
def test_a_batch_that_ends_early_is_unstable_only_at_a_non_finite_state(non_finite):
    """A short batch ending at a non-finite state is an explosion at that state's time, the
    states before it measured; a short batch of finite states is an engine error, never a
    run silently shorter than its scene."""
    scenario = ladder(0.5)
    adapter = create_adapter(parse_engine_spec("mujoco"))
    adapter.load(compile_scene(scenario))
    _short_batches(adapter, non_finite)
    try:
        if not non_finite:
            with pytest.raises(RuntimeError, match="stopped after"):
                record(adapter, compile_scene(scenario))
            return
        recording = record(adapter, compile_scene(scenario))
    finally:
        adapter.close()
    assert recording.unstable.startswith("non_finite"), recording.unstable
    assert 0.0 < recording.trajectory.t[-1] < scenario.duration, recording.trajectory.t[-1]


class _StepByStep:
    """An adapter seen through the base protocol only (no ``advance_observed``): the
    recorder then steps and observes one step at a time."""

    def __init__(self, adapter):
        self.adapter = adapter

    def advance(self, steps: int) -> None:
        self.adapter.advance(steps)

    def observe(self):
        return self.adapter.observe()


def test_observed_batches_measure_what_step_by_step_measures_bit_for_bit():
    """The recorder's two paths measure the same batches: a running sum over the states (the
    precession rate's least squares) and every kept sample are the same bits either way."""
    from pathlib import Path

    from validation.scenario import load_scenario

    library = Path(__file__).resolve().parent.parent / "scenarios"
    scene = compile_scene(load_scenario(library / "rotation/torque_free_symmetric_top.yaml"))
    recordings = []
    for wrap in (lambda adapter: adapter, _StepByStep):
        adapter = create_adapter(parse_engine_spec("mini(gyroscopic=implicit)"))
        adapter.load(scene)
        recordings.append(record(wrap(adapter), scene, sample_every=10))
        adapter.close()
    batched, stepwise = recordings
    assert [m.value for m in batched.expectations] == [m.value for m in stepwise.expectations], (
        [m.value for m in batched.expectations],
        [m.value for m in stepwise.expectations],
    )
    assert np.array_equal(batched.trajectory.ang_vel, stepwise.trajectory.ang_vel)
