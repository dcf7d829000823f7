"""``collides: false``: a body that takes part in no contact, in every engine and on the
reference side (a model's links with ``collisions: false`` are such bodies)."""

from __future__ import annotations

from pathlib import Path

import pytest

from validation.measure.runner import run_engine
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import not_installed, parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.needs import scene_needs

ENGINES = ("mini", "mujoco", "pybullet", "drake", "rapier")

RADIUS = 0.1
"""m, both spheres."""

DURATION = 0.5
"""s: a free fall of g t² / 2 = 1.23 m, twelve radii below the ground."""

RESTING = 0.02
"""m: how far the colliding sphere may sink or bounce on the ground in any engine (its
soft-contact depth is millimetres; a sphere that fell through would be 1.2 m down)."""


def scene(folder: Path, ghost_collides: bool = False) -> Path:
    """A sphere resting on the ground, and a second sphere ("ghost") overlapping it that
    collides with nothing unless ``ghost_collides``."""
    path = folder / "ghost.yaml"
    path.write_text(
        f"""dt: 0.001
duration: {DURATION}
engines: {list(ENGINES)}
ground: {{}}
bodies:
  - name: resting
    shape: {{type: sphere, radius: {RADIUS}}}
    mass: 1.0
    position: [0, 0, {RADIUS}]
  - name: ghost
    shape: {{type: sphere, radius: {RADIUS}}}
    mass: 1.0
    position: [0, 0, {1.5 * RADIUS}]
    collides: {"true" if ghost_collides else "false"}
"""
    )
    return path


@pytest.mark.parametrize("engine", ENGINES)
def test_a_non_colliding_body_falls_through_the_ground_and_the_other_body(tmp_path, engine):
    if not_installed(engine):
        pytest.skip(not_installed(engine))
    compiled = compile_scene(load_scenario(scene(tmp_path)))
    run = run_engine(compiled, parse_engine_spec(engine))
    assert run.status == "ok", (engine, run.status, run.message)
    pos = run.recording.trajectory.pos[-1]
    fallen = 1.5 * RADIUS - 0.5 * 9.81 * DURATION**2
    assert pos[1][2] == pytest.approx(fallen, abs=RESTING), (engine, "ghost", pos[1][2])
    assert abs(pos[0][2] - RADIUS) <= RESTING, (engine, "resting", pos[0][2])


def test_the_reference_side_and_the_needs_leave_it_out(tmp_path):
    apart = compile_scene(load_scenario(scene(tmp_path)))
    together = compile_scene(load_scenario(scene(tmp_path, ghost_collides=True)))
    # the ghost (shape 1) is excluded against the resting sphere (0) and the ground (2)
    assert {tuple(p) for p in apart.shapes.excluded} == {(0, 1), (1, 2)}
    assert together.shapes.excluded.size == 0
    assert "non_colliding" in scene_needs(apart.scenario)
    assert "non_colliding" not in scene_needs(together.scenario)


def test_nothing_can_touch_when_no_body_collides(tmp_path):
    path = scene(tmp_path)
    path.write_text(
        path.read_text().replace(
            "mass: 1.0\n    position: [0, 0, 0.1]",
            "mass: 1.0\n    position: [0, 0, 0.1]\n    collides: false",
        )
    )
    compiled = compile_scene(load_scenario(path))
    assert not compiled.can_touch
    assert "contacts" not in scene_needs(compiled.scenario)
