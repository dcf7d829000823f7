"""The scene's joints: the rules they must keep, and the one tree built from them.

A scene states every body's pose and velocity at t = 0, as without joints, and each joint's
anchor and axis in the world frame at t = 0; physval derives the joint coordinates from them.
The rules (each yields ``(location, message)`` like ``validation.scenario.checks``):

- ``joint_references``: names unique, parent a body or ``world``, child a body that is not
  fixed and not the parent;
- ``joint_tree_shape``: each body the child of one joint at most, and no loop (the cycle named,
  until loop closures are built);
- ``joint_axes``: hinge and slider state an axis, ball and fixed do not; limits only on hinge
  and slider;
- ``joints_hold_at_start``: the stated velocities are ones the joints allow (the anchor moves
  alike as a point of both bodies; a hinge's bodies turn relative to each other only about its
  axis, a slider's not at all and slide only along it; a fixed joint's not at all), to
  ``JOINT_STATE_TOLERANCE``, the violation named.

``joint_tree(scenario)`` builds the reference side's ``JointTree``
(``validation.reference.articulated``) once: the structure every engine adapter and the
reference read.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from validation.reference.articulated import WORLD, JointTree, StatedJoint, build_tree
from validation.reference.rotation import cross
from validation.scenario.physics import body_inertia
from validation.scenario.schema import AXIS_JOINT_TYPES, Scenario

Location = tuple[str | int, ...]
Found = Iterator[tuple[Location, str]]

WORLD_NAME = "world"
"""A joint's ``parent`` that is the world."""

JOINT_STATE_TOLERANCE = 1e-9
"""m/s and rad/s, relative to the scene's largest stated speed (absolute when all are at rest):
a stated velocity the joints do not allow by more than round-off is a typo, refused."""


def joint_references(scenario: Scenario) -> Found:
    """Joint names are unique; parents and children name bodies; a child is movable and not
    its own parent."""
    bodies = {body.name: body for body in scenario.bodies}
    seen: set[str] = set()
    for k, joint in enumerate(scenario.joints):
        if joint.name in seen:
            yield ("joints", k, "name"), f"expected a unique joint name; {joint.name!r} is taken"
        seen.add(joint.name)
        if joint.parent != WORLD_NAME and joint.parent not in bodies:
            yield ("joints", k, "parent"), _unknown(joint.parent, [*bodies, WORLD_NAME])
        if joint.child not in bodies:
            yield ("joints", k, "child"), _unknown(joint.child, list(bodies))
        elif bodies[joint.child].fixed:
            yield ("joints", k, "child"), f"expected a body that can move; {joint.child!r} is fixed"
        if joint.child == joint.parent:
            yield (
                ("joints", k, "child"),
                f"expected a body other than the parent; got {joint.child!r}",
            )


def _unknown(name: str, choices: list[str]) -> str:
    return f"expected one of {sorted(choices)}; got {name!r}"


def joint_tree_shape(scenario: Scenario) -> Found:
    """Each body is the child of one joint at most, and the joints form no loop."""
    parent_of: dict[str, str] = {}
    for k, joint in enumerate(scenario.joints):
        if joint.child in parent_of:
            yield (
                ("joints", k, "child"),
                f"expected each body to be the child of one joint; {joint.child!r} already hangs "
                f"from {parent_of[joint.child]!r} (loop closures are not supported yet)",
            )
            continue
        parent_of[joint.child] = joint.parent
    reported: set[str] = set()
    for k, joint in enumerate(scenario.joints):
        cycle = _cycle_from(joint.child, parent_of)
        if cycle and not reported & set(cycle):
            reported |= set(cycle)
            yield (
                ("joints", k, "parent"),
                f"expected a tree; the joints close a loop {' -> '.join([*cycle, cycle[0]])} "
                "(loop closures are not supported yet)",
            )


def _cycle_from(body: str, parent_of: dict[str, str]) -> list[str]:
    """The loop ``body`` is on when followed up its parents, or [] when it reaches the world."""
    path: list[str] = []
    while body in parent_of and body not in path:
        path.append(body)
        body = parent_of[body]
    return path[path.index(body) :] if body in path else []


def joint_axes(scenario: Scenario) -> Found:
    """Hinge and slider state an axis; ball and fixed state none; limits only on an axis."""
    for k, joint in enumerate(scenario.joints):
        has_axis = joint.type in AXIS_JOINT_TYPES
        if has_axis and joint.axis is None:
            yield ("joints", k, "axis"), f"expected a unit axis [x, y, z] for a {joint.type}"
        if not has_axis and joint.axis is not None:
            yield ("joints", k, "axis"), f"expected no axis for a {joint.type} joint"
        if not has_axis and joint.limits is not None:
            yield ("joints", k, "limits"), f"expected no limits for a {joint.type} joint"
        if joint.damping > 0 and joint.type == "fixed":
            yield ("joints", k, "damping"), "expected no damping for a fixed joint (nothing moves)"


def joints_hold_at_start(scenario: Scenario) -> Found:
    """The stated velocities move each joint's anchor alike as a point of both bodies and turn
    or slide the child only as the joint allows."""
    bodies = {body.name: body for body in scenario.bodies}
    speeds = [abs(x) for b in scenario.bodies for x in (*b.velocity, *b.angular_velocity)]
    tolerance = JOINT_STATE_TOLERANCE * max([1.0, *speeds])  # a list: no body, no speed
    for k, joint in enumerate(scenario.joints):
        if joint.child not in bodies or (joint.parent != WORLD_NAME and joint.parent not in bodies):
            continue  # joint_references reports it
        parent = bodies.get(joint.parent)
        child = bodies[joint.child]
        anchor = np.array(joint.anchor)
        v_parent, w_parent = _point_velocity(parent, anchor)
        v_child, w_child = _point_velocity(child, anchor)
        slip, turn = v_child - v_parent, w_child - w_parent
        axis = np.zeros(3) if joint.axis is None else np.array(joint.axis)
        for what, violation in _violations(joint.type, slip, turn, axis):
            size = float(np.linalg.norm(violation))
            if size > tolerance:
                yield (
                    ("joints", k),
                    f"expected the bodies' stated velocities to keep the {joint.type} joint at "
                    f"t = 0; {what} is {size:.6g} ({np.round(violation, 9).tolist()})",
                )


def _point_velocity(body, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(velocity of ``point`` as a point of ``body``, its spin); the world's are zero."""
    if body is None:
        return np.zeros(3), np.zeros(3)
    spin = np.array(body.angular_velocity)
    arm = point - np.array(body.position)
    return np.array(body.velocity) + cross(spin, arm), spin


def _violations(kind: str, slip: np.ndarray, turn: np.ndarray, axis: np.ndarray):
    """(what, vector) for each motion the joint forbids at its anchor: the slip (m/s) and the
    relative spin (rad/s) of the child against the parent."""
    along = axis * float(slip @ axis)
    about = axis * float(turn @ axis)
    table = {
        "ball": [("the anchor's slip (m/s)", slip)],
        "hinge": [
            ("the anchor's slip (m/s)", slip),
            ("the spin off the axis (rad/s)", turn - about),
        ],
        "slider": [
            ("the slip off the axis (m/s)", slip - along),
            ("the relative spin (rad/s)", turn),
        ],
        "fixed": [("the anchor's slip (m/s)", slip), ("the relative spin (rad/s)", turn)],
    }
    return table[kind]


JOINT_RULES = (joint_references, joint_tree_shape, joint_axes, joints_hold_at_start)
"""The joint rules, in the order they report (``validation.scenario.checks.RULES``)."""


def joint_tree(scenario: Scenario) -> JointTree | None:
    """The reference side's ``JointTree`` of the scene's joints (None without joints): bodies
    in scenario order, each joint placed in its parent's frame at the stated poses."""
    if not scenario.joints:
        return None
    index = {body.name: k for k, body in enumerate(scenario.bodies)}
    stated = [
        StatedJoint(
            name=joint.name,
            type=joint.type,
            parent=WORLD if joint.parent == WORLD_NAME else index[joint.parent],
            child=index[joint.child],
            anchor=np.array(joint.anchor, dtype=float),
            axis=np.zeros(3) if joint.axis is None else np.array(joint.axis, dtype=float),
            damping=joint.damping,
        )
        for joint in scenario.joints
    ]
    return build_tree(
        stated,
        mass=np.array([body.mass for body in scenario.bodies], dtype=float),
        inertia=np.array([body_inertia(body) for body in scenario.bodies]),
        pos=np.array([body.position for body in scenario.bodies], dtype=float),
        quat=np.array([body.orientation for body in scenario.bodies], dtype=float),
        fixed=np.array([body.fixed for body in scenario.bodies], dtype=bool),
    )
