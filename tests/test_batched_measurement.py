"""Batched measuring gives the impacts and overlaps that state-by-state measuring gave.

The fixture ``fixtures/per_observation_impacts.csv`` was recorded on the last main that
measured every observed state on its own (``fixtures/record_per_observation.py``): every
impact event and each run's ``penetration_max`` on ten contact scenes of the library, in
mini, MuJoCo and PyBullet. Today the observed states of a batch are measured in one
collision call; the events, their restitution and the deepest overlap must not change.

Five events were re-recorded (issue 34, item 13) when the measurement got its own contact
finder (``validation.reference.contacts``): where several points of a pair are deepest
together (a box landing on its edge or flat), the contact point is now their centroid, the
patch centre, instead of whichever corner mini_engine's narrow phase listed first. The arm
of a spinning box's normal velocity moved with it: box_drop_edge in mini (e 1 - 1e-9 instead
of 1 + 4e-16, three events), in PyBullet (first event, e 0.777 instead of 1.634), box_drop_flat
in PyBullet (first event, e 0.343 instead of 0.292). Every other event, and every overlap,
is unchanged.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS
from validation.measure.runner import run_engine
from validation.scenario import load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

FIXTURE = pd.read_csv(Path(__file__).parent / "fixtures" / "per_observation_impacts.csv")
SCENES = {path.stem: path for path in BUNDLED_SCENARIOS.rglob("*.yaml")}

TIME_TOLERANCE = 1e-12
"""s. Event times are observation times (multiples of dt summed by the engine): identical
unless an event moved by a whole step, which is what this test is for."""

VELOCITY_TOLERANCE = 1e-9
"""m/s. Normal velocities are the same observed velocities projected on the same frozen
normal; only the order of floating-point sums differs (measured <= 9e-12 on the library)."""

RESTITUTION_TOLERANCE = 1e-9
"""Dimensionless: the ratio of two velocities each within ``VELOCITY_TOLERANCE`` of ~1 m/s."""

PENETRATION_TOLERANCE = 1e-12
"""m. The deepest overlap is one narrow-phase depth, computed from the same poses."""


def _measured(scene_name: str, engine: str):
    scene = compile_scene(load_scenario(SCENES[scene_name]))
    run = run_engine(scene, parse_engine_spec(engine), 1)
    assert run.recording is not None, run.message
    return run.recording


CASES = sorted(set(zip(FIXTURE.scenario, FIXTURE.engine, strict=True)))


@pytest.fixture
def recorded_engine_settings(monkeypatch):
    """The engines as the fixture was recorded: PyBullet's matched profile has since set
    ``contactSlop`` to 0 and ``solverResidualThreshold`` to 0, and put a box under the scene
    instead of a plane (physics changes, not measuring ones), so the fixture's runs use
    Bullet's own defaults and a GEOM_PLANE again."""
    from dataclasses import replace

    from validation.engines.pybullet.adapter import PROFILES

    matched = PROFILES["matched"]
    world = dict(matched.world)
    del world["contactSlop"], world["solverResidualThreshold"]
    monkeypatch.setitem(PROFILES, "matched", replace(matched, world=world, ground="plane"))


@pytest.mark.parametrize(("scene_name", "engine"), CASES, ids=[f"{s}-{e}" for s, e in CASES])
@pytest.mark.usefixtures("recorded_engine_settings")
def test_batched_measurement_matches_the_per_observation_fixture(scene_name, engine):
    recorded = FIXTURE[(FIXTURE.scenario == scene_name) & (FIXTURE.engine == engine)]
    expected = recorded[recorded.kind == "impact"]
    recording = _measured(scene_name, engine)
    found = [
        (
            e.body_a,
            e.body_b,
            e.time_start,
            e.time_impulse,
            e.restitution,
            e.normal_velocity_before,
            e.normal_velocity_after,
        )
        for e in recording.impacts
    ]
    assert len(found) == len(expected), (
        f"{len(found)} impacts, {len(expected)} in the fixture: "
        f"{[(a, b, round(t, 6)) for a, b, t, *_ in found]}"
    )
    for got, (_, want) in zip(found, expected.iterrows(), strict=True):
        assert (got[0], got[1]) == (want.body_a, want.body_b), (got, want.to_dict())
        assert abs(got[2] - want.time_start) <= TIME_TOLERANCE, (got[2], want.time_start)
        assert abs(got[3] - want.time_impulse) <= TIME_TOLERANCE, (got[3], want.time_impulse)
        assert abs(got[4] - want.e_measured) <= RESTITUTION_TOLERANCE, (got[4], want.e_measured)
        velocities = np.array(got[5:]) - [want.normal_velocity_before, want.normal_velocity_after]
        assert np.abs(velocities).max() <= VELOCITY_TOLERANCE, (got[5:], want.to_dict())
    penetration = recorded[recorded.kind == "penetration_max"].e_measured.to_numpy()
    assert recording.penetration_max is not None
    assert abs(recording.penetration_max - penetration[0]) <= PENETRATION_TOLERANCE, (
        recording.penetration_max,
        penetration[0],
    )


BATCH_SIZES = (256, 7)
"""The default batch, and a small one that puts batch boundaries inside impacts."""


def test_impacts_do_not_depend_on_how_the_states_are_batched(monkeypatch):
    """49 balls bouncing at once (simultaneous impacts), measured in batches of 256 and of 7
    states: the same events in the same order, bit for bit."""
    from validation.measure import recording as recording_module

    scene = compile_scene(load_scenario(SCENES["simbenchmark_bouncing_7x7"]))
    states = run_engine(scene, parse_engine_spec("mini"), 1).recording.trajectory
    measured = []
    for size in BATCH_SIZES:
        monkeypatch.setattr(recording_module, "BATCH_OBSERVATIONS", size)
        measured.append(recording_module.measure_trajectory(scene, states))
    first, second = measured
    assert len(first.impacts) > 49, f"only {len(first.impacts)} impacts"
    assert first.impacts == second.impacts, next(
        (a, b) for a, b in zip(first.impacts, second.impacts, strict=False) if a != b
    )
    assert first.penetration_max == second.penetration_max
