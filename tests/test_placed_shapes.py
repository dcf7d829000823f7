"""Placed shapes on the reference side: a shape's ``offset`` and ``orientation`` in its body
give its pose (body pose ∘ placement) to the contact finder, to the bounding radii and so to
every measurement that reads contacts (penetration, impacts, the overlap check); mini_engine,
whose bodies carry their shape at the centre of mass, declares no ``placed_shapes``.
"""

from __future__ import annotations

import numpy as np
import pytest

from validation.engines.base import Snapshot
from validation.measure.recording import record
from validation.measure.runner import run_engine
from validation.reference import contacts
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.physics import initial_overlaps

ROUND_OFF = 1e-12
"""m. Composing two exact rotations and an offset costs a few ulps of metre-scale values."""

SINK = 0.002
"""m, how far each scene below puts its shape into the ground (depth to find)."""


def scene(folder, shape: str, position, orientation=(1, 0, 0, 0), extra: str = "") -> object:
    path = folder / "placed.yaml"
    path.write_text(
        f"""dt: 0.001
duration: 0.01
ground: {{}}
bodies:
  - name: link
    shape: {shape}
    mass: 1.0
    inertia: [0.01, 0.02, 0.03]
    position: {list(position)}
    orientation: {list(orientation)}
{extra}"""
    )
    return path


QUARTER_Z = [float(np.sqrt(0.5)), 0.0, 0.0, float(np.sqrt(0.5))]
"""A quarter turn about z (w x y z): body x -> world y."""

QUARTER_X = [float(np.sqrt(0.5)), float(np.sqrt(0.5)), 0.0, 0.0]
"""A quarter turn about x: shape y -> body z."""


def contact_of(path) -> contacts.Found:
    compiled = compile_scene(load_scenario(path))
    start = compiled.start
    return compiled.contacts(start.pos[:1], start.quat[:1], 1e-6)


def test_a_placed_box_touches_the_ground_under_its_offset_pose(tmp_path):
    """The body turned a quarter about z, the box 0.5 m out along body x (world +y) and turned
    a quarter about x (its 0.1 m half extent now vertical): its face centre is the contact,
    0.1 - SINK above the ground's plane puts it SINK deep."""
    shape = (
        "{type: box, half_extents: [0.3, 0.1, 0.05], offset: [0.5, 0, 0], "
        f"orientation: {QUARTER_X}}}"
    )
    found = contact_of(scene(tmp_path, shape, (1.0, 2.0, 0.1 - SINK), QUARTER_Z))
    assert found.depth.size == 1
    assert found.depth[0] == pytest.approx(SINK, abs=ROUND_OFF)
    np.testing.assert_allclose(found.point[0], (1.0, 2.5, -SINK / 2), atol=ROUND_OFF)


def test_an_unplaced_box_at_the_same_body_pose_touches_under_its_centre(tmp_path):
    """The control: without the placement the box's half height is 0.05, so at 0.1 - SINK it
    is 0.048 m clear of the ground and nothing touches."""
    shape = "{type: box, half_extents: [0.3, 0.1, 0.05]}"
    path = scene(tmp_path, shape, (1.0, 2.0, 0.1 - SINK), QUARTER_Z)
    assert contact_of(path).depth.size == 0


def test_a_placed_sphere_is_found_where_it_is_not_where_its_body_is(tmp_path):
    """A sphere 2 m off its body's centre of mass touches a second body there (the broad
    phase must see it there too) and the bounding radius about the centre of mass grows by
    the offset; the overlap check at t = 0 names the pair."""
    other = """  - name: ball
    shape: {type: sphere, radius: 0.1}
    mass: 1.0
    position: [2.0, 0, 1.19]
"""
    shape = "{type: sphere, radius: 0.1, offset: [2.0, 0, 0]}"
    path = scene(tmp_path, shape, (0.0, 0.0, 1.0), extra=other)
    compiled = compile_scene(load_scenario(path))
    np.testing.assert_allclose(compiled.bound_radius[:2], [2.1, 0.1], atol=ROUND_OFF)
    found = contact_of(path)
    assert list(zip(found.body_a, found.body_b, strict=True)) == [(0, 1)]
    assert found.depth[0] == pytest.approx(0.01, abs=ROUND_OFF)
    np.testing.assert_allclose(found.point[0], (2.0, 0.0, 1.095), atol=ROUND_OFF)
    assert [message for _, message in initial_overlaps(load_scenario(path))] == [
        "'link' and 'ball' overlap by 0.01 m at t = 0 (intended for deep-penetration scenes)"
    ]


def test_the_finder_places_each_state_by_its_own_body_pose():
    """Batched states: the placement turns with the body (a quarter turn about y carries the
    offset (0, 0, -0.5) to (-0.5, 0, 0) and lifts the capsule's end)."""
    shapes = contacts.Shapes(
        kind=np.array([contacts.CAPSULE, contacts.PLANE]),
        size=np.array([(0.1, 0.2, 0.0), (0.0, 0.0, 0.0)]),
        fixed=np.array([False, True]),
        offset=np.array([(0.0, 0.0, -0.5), (0.0, 0.0, 0.0)]),
    )
    pos = np.array([[[0.0, 0.0, 0.8 - SINK], [0, 0, 0]], [[0.0, 0.0, 0.1 - SINK], [0, 0, 0]]])
    quarter_y = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    rot = np.stack([np.stack([np.eye(3)] * 2), np.stack([quarter_y, np.eye(3)])])
    found = contacts.find_contacts(shapes, pos, rot, 1e-6)
    assert found.observation.tolist() == [0, 1]
    np.testing.assert_allclose(found.depth, [SINK, SINK], atol=ROUND_OFF)
    np.testing.assert_allclose(found.point[0], (0.0, 0.0, -SINK / 2), atol=ROUND_OFF)
    np.testing.assert_allclose(found.point[1], (-0.5, 0.0, -SINK / 2), atol=ROUND_OFF)


@pytest.mark.parametrize(
    ("shape", "word", "reason"),
    [
        (
            "{type: box, half_extents: [0.1, 0.1, 0.1], offset: [0.1, 0, 0]}",
            "placed_shapes",
            "body 'link''s shape sits off its centre of mass",
        ),
        (
            "{type: cylinder, radius: 0.1, half_length: 0.1}",
            "cylinder",
            "body 'link' is a cylinder",
        ),
    ],
)
def test_mini_cannot_represent_a_placed_shape_or_a_cylinder(tmp_path, shape, word, reason):
    compiled = compile_scene(load_scenario(scene(tmp_path, shape, (0, 0, 0.5))))
    run = run_engine(compiled, parse_engine_spec("mini"))
    assert run.status == "unsupported", (run.status, run.message)
    assert f"{word} ({reason})" in run.message, run.message


class _Held:
    """A scripted engine that holds every body at its starting pose (the measurement, not
    any engine, is under test): ``advance`` only moves the clock."""

    def __init__(self, scene):
        self.scene, self.time = scene, 0.0

    def advance(self, steps: int) -> None:
        self.time += steps * self.scene.scenario.dt

    def observe(self) -> Snapshot:
        start = self.scene.start
        still = np.zeros_like(start.vel[0])
        return Snapshot(self.time, start.pos[0], start.quat[0], still, still)


def test_penetration_max_reads_the_shape_at_its_placed_pose(tmp_path):
    """The body turned a quarter about x (body y -> world z), its box 0.05 m along body -y:
    the box hangs 0.05 m below the centre of mass, SINK into the ground; unplaced it would be
    0.048 m clear of it."""
    shape = "{type: box, half_extents: [0.1, 0.1, 0.1], offset: [0, -0.05, 0]}"
    path = scene(tmp_path, shape, (0.0, 0.0, 0.15 - SINK), QUARTER_X)
    compiled = compile_scene(load_scenario(path))
    recording = record(_Held(compiled), compiled)
    assert recording.penetration_max == pytest.approx(SINK, abs=ROUND_OFF)


def test_a_small_shape_far_off_its_centre_of_mass_sinking_through_is_deep_penetration(tmp_path):
    """A 0.1 m sphere 2 m below its body's centre of mass, 0.12 m into the ground: more than
    its own radius (``stability.PENETRATION_FRACTION``), though less than the body's 2.1 m
    bounding radius about its centre of mass: the overlap is judged against the shape."""
    shape = "{type: sphere, radius: 0.1, offset: [0, 0, -2.0]}"
    path = scene(tmp_path, shape, (0.0, 0.0, 2.0 + 0.1 - 0.12))
    compiled = compile_scene(load_scenario(path))
    recording = record(_Held(compiled), compiled)
    assert recording.unstable.startswith("deep_penetration"), recording.unstable
