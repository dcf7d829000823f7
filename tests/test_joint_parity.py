"""The parity gate of a scene with joints (``validation.engines.joint_parity``): each engine's
joint types, anchors, axes and, where the engine has joint coordinates, its mass matrix M(q0)
against the reference side's own computation from the scene's solids.

A correct engine passes on every library joint scene (MuJoCo's ``mj_fullM``, carried into the
tree's coordinates, equals the composite-rigid-body M to round-off); a joint written wrong into
the engine's model is named by joint and field before any step.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import validation.engines.mujoco.mjcf as mjcf
from validation.engines.base import JointReport
from validation.engines.joint_parity import compare_joints, expected_report
from validation.engines.registry import create_adapter
from validation.measure.runner import run_engine
from validation.scenario import load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

JOINT_SCENES = sorted((Path(__file__).resolve().parents[1] / "scenarios" / "joints").glob("*.yaml"))

ROUND_OFF = 1e-12
"""Relative: M(q0) is a few dozen products of the scene's masses, lengths and inertias."""


def loaded(engine: str, scene):
    adapter = create_adapter(parse_engine_spec(engine))
    adapter.load(scene)
    return adapter


@pytest.mark.parametrize("path", JOINT_SCENES, ids=lambda p: p.stem)
def test_mujocos_mass_matrix_is_the_composite_rigid_body_one(path):
    scene = compile_scene(load_scenario(path))
    adapter = loaded("mujoco", scene)
    try:
        got = adapter.joint_report()
    finally:
        adapter.close()
    want = expected_report(scene)
    scale = np.abs(want.mass_matrix).max()
    assert np.allclose(got.mass_matrix, want.mass_matrix, rtol=0, atol=ROUND_OFF * scale), (
        got.mass_matrix,
        want.mass_matrix,
    )
    assert got.types == want.types, got.types
    assert np.allclose(got.anchors, want.anchors, atol=ROUND_OFF), got.anchors
    assert np.allclose(got.axes, want.axes, atol=ROUND_OFF), got.axes


@pytest.mark.parametrize("path", JOINT_SCENES, ids=lambda p: p.stem)
def test_minis_joints_are_the_scenes(path):
    scene = compile_scene(load_scenario(path))
    assert compare_joints(loaded("mini", scene), scene) == []


PENDULUM = Path(__file__).resolve().parents[1] / "scenarios" / "joints" / "compound_pendulum.yaml"


def _mismatch_of(monkeypatch, attribute: str, change) -> str:
    original = getattr(mjcf, attribute)
    monkeypatch.setattr(mjcf, attribute, change(original))
    run = run_engine(compile_scene(load_scenario(PENDULUM)), parse_engine_spec("mujoco"))
    assert run.status == "model_mismatch", (run.status, run.message)
    return run.message


def test_an_axis_written_the_wrong_way_is_named(monkeypatch):
    def flipped(original):
        def attributes(scenario, joint):
            written = original(scenario, joint)
            written["axis"] = " ".join(str(-float(v)) for v in written["axis"].split())
            return written

        return attributes

    message = _mismatch_of(monkeypatch, "_joint_attributes", flipped)
    assert "joint 'pivot' axis" in message, message


def test_an_anchor_in_the_wrong_frame_is_named_with_the_mass_matrix(monkeypatch):
    """The anchor written twice as far from the child's centre (-2 R0ᵀ r0): the bar swings
    about a point 1 m from its centre, so the anchor and M(q0) (I_O) both differ."""

    def misplaced(original):
        def attributes(scenario, joint):
            written = original(scenario, joint)
            written["pos"] = mjcf._fmt(-2.0 * joint.rotation.T @ joint.offset)
            return written

        return attributes

    message = _mismatch_of(monkeypatch, "_joint_attributes", misplaced)
    assert "joint 'pivot' anchor" in message and "mass_matrix" in message, message


class _Silent:
    """An adapter that declares joints and builds nothing it can report."""


def test_an_engine_declaring_joints_without_a_report_is_a_mismatch():
    scene = compile_scene(load_scenario(PENDULUM))
    mismatches = compare_joints(_Silent(), scene)
    assert len(mismatches) == 1 and "no joint_report()" in str(mismatches[0]), mismatches


class _Reporting:
    def __init__(self, report: JointReport):
        self.report = report

    def joint_report(self) -> JointReport:
        return self.report


def test_a_mass_matrix_entry_off_is_named_by_its_row_and_column():
    scene = compile_scene(load_scenario(PENDULUM))
    want = expected_report(scene)
    off = want.mass_matrix.copy()
    off[0, 0] *= 1.0 + 1e-6
    report = JointReport(want.types, want.anchors, want.axes, off)
    mismatches = compare_joints(_Reporting(report), scene)
    assert [m.quantity for m in mismatches] == ["mass_matrix[0, 0]"], mismatches
    wrong_shape = JointReport(want.types, want.anchors, want.axes, np.zeros((2, 2)))
    assert "shape" in str(compare_joints(_Reporting(wrong_shape), scene)[0])
