"""The parity gate of a scene with joints: the joints an engine built must be the scene's.

An engine that declares ``joints`` reports what it built (``JointReport``: each joint's type,
its anchor and axis in the world at t = 0, and, from an engine with joint coordinates, the
tree's mass matrix M(q0)); each is compared with what the reference side computes from the
scene alone (``CompiledScene.joint_tree``; M(q0) by ``articulated.mass_matrix``, the composite
rigid body matrix of the scene's solids, never an engine's). A difference is a ``Mismatch``
naming the joint and the field, as the body quantities of ``validation.engines.parity`` are,
and the run is ``model_mismatch``.
"""

from __future__ import annotations

import numpy as np

from validation.engines.base import JointReport
from validation.engines.parity import Mismatch
from validation.reference.articulated import mass_matrix
from validation.scenario.compiled import CompiledScene

JOINT_TOLERANCE = 1e-9
"""Relative to the scene's size (anchors: the largest stated distance from the origin, at
least 1 m; axes are unit): engines store a joint's frame in double precision, and a frame
written in the wrong body's coordinates is off by the size of the scene."""


def expected_report(scene: CompiledScene) -> JointReport:
    """The scene's joints as the reference side holds them: stated types, anchors and axes,
    and M(q0) of the joint tree."""
    joints = scene.scenario.joints
    return JointReport(
        types=tuple(j.type for j in joints),
        anchors=np.array([j.anchor for j in joints], dtype=float).reshape(-1, 3),
        axes=np.array([j.axis or (0.0, 0.0, 0.0) for j in joints], dtype=float).reshape(-1, 3),
        mass_matrix=mass_matrix(scene.joint_tree, scene.joint_tree.zero()),
    )


def compare_joints(
    adapter, scene: CompiledScene, tolerance: float = JOINT_TOLERANCE
) -> list[Mismatch]:
    """Every joint field the engine built differently from the scene (``tolerance`` relative,
    scaled by the engine's declared precision as the body quantities are); an engine that
    declares joints without ``joint_report`` is one mismatch saying so."""
    report = getattr(adapter, "joint_report", None)
    if report is None:
        return [_unreported("the adapter declares joints but has no joint_report()")]
    return compare_joint_report(report(), scene, tolerance)


def compare_joint_report(
    got: JointReport, scene: CompiledScene, tolerance: float = JOINT_TOLERANCE
) -> list[Mismatch]:
    """Every joint field of ``got`` (an engine's ``joint_report()``) that differs from the
    scene's (``compare_joints``); each mismatch's ``item`` is the joint's name."""
    want = expected_report(scene)
    names = [j.name for j in scene.scenario.joints]
    if len(got.types) != len(names):
        return [_unreported(f"reported {len(got.types)} joints; the scene has {len(names)}")]
    size = max(1.0, float(np.abs(want.anchors).max(initial=0.0)))
    mismatches = []
    for k, name in enumerate(names):
        if got.types[k] != want.types[k]:
            mismatches.append(_joint(name, "type", got.types[k], want.types[k], 1.0, tolerance))
        for field, label, scale in (("anchors", "anchor", size), ("axes", "axis", 1.0)):
            engine, scene_value = getattr(got, field)[k], getattr(want, field)[k]
            error = float(np.abs(np.asarray(engine) - scene_value).max()) / scale
            if not error <= tolerance:
                mismatches.append(_joint(name, label, engine, scene_value, error, tolerance))
    if got.mass_matrix is not None:
        mismatches += _mass_matrix(np.asarray(got.mass_matrix), want.mass_matrix, tolerance)
    return mismatches


def _mass_matrix(engine: np.ndarray, expected: np.ndarray, tolerance: float) -> list[Mismatch]:
    """M(q0) compared entry by entry, relative to its largest entry."""
    if engine.shape != expected.shape:
        return [
            Mismatch(
                "mass_matrix",
                None,
                engine.shape,
                expected.shape,
                np.inf,
                tolerance,
                problem=f"the engine reported shape {engine.shape}; expected {expected.shape}",
            )
        ]
    scale = float(np.abs(expected).max(initial=0.0)) or 1.0
    difference = np.abs(engine - expected)
    error = float(difference.max()) / scale
    if error <= tolerance:
        return []
    row, column = np.unravel_index(int(np.argmax(difference)), difference.shape)
    return [
        Mismatch(
            f"mass_matrix[{row}, {column}]",
            None,
            round(float(engine[row, column]), 12),
            round(float(expected[row, column]), 12),
            error,
            tolerance,
        )
    ]


def _joint(name: str, field: str, engine, expected, error: float, tolerance: float) -> Mismatch:
    def shown(value):
        return np.round(value, 12).tolist() if isinstance(value, np.ndarray) else value

    return Mismatch(
        f"joint {name!r} {field}", None, shown(engine), shown(expected), error, tolerance, item=name
    )


def _unreported(problem: str) -> Mismatch:
    return Mismatch("joints", None, None, None, np.inf, JOINT_TOLERANCE, problem=problem)
