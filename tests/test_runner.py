"""run_engine: a mismatching model, a crashing engine and an exploding one become statuses."""

from __future__ import annotations

import pytest

from validation.engines.mujoco import mjcf as mujoco_engine
from validation.measure.runner import run_engine
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

BALL = {
    "name": "drop",
    "dt": 0.001,
    "duration": 0.2,
    "ground": {"restitution": 0.5},
    "bodies": [
        {
            "name": "ball",
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "position": [0, 0, 0.2],
            "restitution": 0.5,
        }
    ],
}


@pytest.mark.parametrize("engine", ["mini", "mujoco", "pybullet"])
def test_every_engine_runs_a_bounce_to_the_end(engine):
    run = run_engine(
        compile_scene(Scenario.model_validate(BALL)), parse_engine_spec(engine), sample_every=10
    )
    assert run.status == "ok", run.message
    assert run.recording.trajectory.t[-1] == pytest.approx(0.2)
    assert len(run.recording.impacts) >= 1, "no impact recorded"
    assert abs(run.recording.impacts[0].restitution - 0.5) < 0.01, run.recording.impacts[0]
    assert run.provenance is not None and run.provenance.version


def test_wrong_inertia_gives_a_model_mismatch_naming_the_quantity(monkeypatch):
    right = mujoco_engine.body_inertia
    monkeypatch.setattr(mujoco_engine, "body_inertia", lambda body: right(body) * (1.0 + 1e-6))
    run = run_engine(compile_scene(Scenario.model_validate(BALL)), parse_engine_spec("mujoco"))
    assert run.status == "model_mismatch", run.status
    assert "inertia_world of body 0" in run.message and run.recording is None, run.message


@pytest.mark.parametrize("crash_at", [1, 57])
def test_a_crashing_engine_becomes_an_error_row(crash_at, monkeypatch):
    """mini_engine's step raising on its first step, or part of the way through a batch of
    observed steps (whose earlier states pass every check): an ``error`` row with the
    engine's own message."""
    from validation.engines.mini import adapter as mini

    calls = {"steps": 0}
    stepped = mini.step

    def explode(*args, **kwargs):
        calls["steps"] += 1
        if calls["steps"] >= crash_at:
            raise RuntimeError("solver fell over")
        return stepped(*args, **kwargs)

    monkeypatch.setattr(mini, "step", explode)
    run = run_engine(compile_scene(Scenario.model_validate(BALL)), parse_engine_spec("mini"))
    assert run.status == "error" and run.message == "RuntimeError: solver fell over", run
    assert calls["steps"] == crash_at, calls


def test_an_exploding_engine_becomes_an_unstable_row_and_stops_early():
    """Explicit Euler on an undamped k = 1e6 spring grows by (1 + (ω dt)²) per step: at
    ω dt = 2 it overflows to inf within a few hundred steps."""
    scene = {
        "name": "boom",
        "dt": 0.002,
        "duration": 10.0,
        "gravity": [0, 0, 0],
        "bodies": [
            {
                "name": "m",
                "shape": {"type": "sphere", "radius": 0.01},
                "mass": 1.0,
                "position": [0.01, 0, 0],
            }
        ],
        "springs": [{"a": "m", "b": "world", "stiffness": 1.0e6, "rest_length": 0.0}],
    }
    run = run_engine(
        compile_scene(Scenario.model_validate(scene)),
        parse_engine_spec("mini(integrator=explicit_euler)"),
        100,
    )
    assert run.status == "unstable", run.status
    # every state is checked: the speed passes 100x the scene's scale (1.1e3 m/s) first,
    # about 7 steps in, before the energy passes a million times its scale
    assert run.message.startswith("speed_limit"), run.message
    assert run.recording.trajectory.t[-1] < 0.1, "the run must stop at the explosion"


def test_an_engine_that_raises_right_after_a_measured_batch_keeps_its_message(monkeypatch):
    """Step by step (an adapter without ``advance_observed``), an exception on the first
    step after a full batch was measured leaves nothing pending: the row is the engine's
    ``error``, not a failure of the recorder on an empty batch."""
    from validation.engines.mini import adapter as mini
    from validation.measure import recording

    monkeypatch.delattr(mini.MiniAdapter, "advance_observed")
    scene = compile_scene(Scenario.model_validate({**BALL, "duration": 1.0}))
    size = recording.batch_size(scene)
    calls = {"steps": 0}
    stepped = mini.step

    def explode(*args, **kwargs):
        calls["steps"] += 1
        if calls["steps"] == size:  # the first step after the first batch (the start + size - 1)
            raise RuntimeError("solver fell over")
        return stepped(*args, **kwargs)

    monkeypatch.setattr(mini, "step", explode)
    run = run_engine(scene, parse_engine_spec("mini"))
    assert run.status == "error" and run.message == "RuntimeError: solver fell over", run
