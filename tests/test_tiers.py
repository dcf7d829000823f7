"""The model tiers of issue 36 (``validation.measure.tiers``): each tier's row is near zero for an
engine that holds the scene's model and computes its dynamics, and names the link, joint or
entry when that quantity is broken; a native model difference is a row, not a refusal; the rows
reach results.csv through ``physval run`` and survive a resumed run."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from validation.cli import main
from validation.engines.base import ModelProbe
from validation.engines.frames import matrix_to_quat
from validation.engines.parity import Mismatch
from validation.engines.reference import dynamic_bodies
from validation.engines.registry import create_adapter
from validation.engines.sabotage import SABOTAGE_VARIABLE, SABOTAGES
from validation.measure import runner
from validation.measure.comparator import compare_scene, measure_run
from validation.measure.definitions import METRIC_DEFINITIONS, TIERS
from validation.measure.runner import model_owned, run_engine
from validation.measure.tiers import (
    _loads,
    model_fields,
    probe_states,
    probe_tiers,
    scene_joint_report,
)
from validation.reference.articulated import bias_forces, forward_kinematics, mass_matrix
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.load import load_scenario
from validation.scenario.schema import METRIC_NAMES

KUKA = "pkg:pybullet_data/kuka_iiwa/model.urdf"

ARM = f"""\
description: the Kuka iiwa of pybullet_data swinging from a pose under gravity
dt: 0.001
duration: 0.05
engines: [mini, rapier]
models:
  - name: arm
    file: {KUKA}
    joint_positions: {{arm/lbr_iiwa_joint_2: 0.5, arm/lbr_iiwa_joint_4: -0.7}}
"""

ROUND_OFF = 1e-12
"""Relative (or m for fk_error, on a 1.3 m arm): what an engine holding exactly the scene's model
differs from it by in double precision (measured: 4e-16 for mini's fields and poses)."""

MINI_BIAS = 1.5e-3
"""Relative: mini's one-step finite-difference bias on the posed Kuka at rates of 1 rad/s
measured 7.1e-4 at dt = 1 ms (6.4e-4 at 0.5 ms: mini's joint impulses with their Baumgarte
bias, not the difference's O(dt), which its band 2.9e-4 covers); twice that bounds it, and a
gravity 1 % low gives 1e-2."""


def arm_scene(tmp_path: Path, text: str = ARM):
    path = tmp_path / "arm.yaml"
    path.write_text(text)
    return compile_scene(load_scenario(path))


def by_metric(rows) -> dict:
    return {row.metric: row for row in rows}


def test_the_tiers_are_metrics_in_their_order():
    """The issue's names, in the order the report's card reads them."""
    model, kinematics, dynamics, trajectory = TIERS
    assert (model, kinematics) == (("model_fields",), ("fk_error",))
    assert dynamics == ("mass_matrix_error", "bias_force_error")
    assert trajectory == ("joint_divergence", "agreement_time", "energy_drift", "joint_violation")
    for tier in TIERS:
        for metric in tier:
            assert metric in METRIC_DEFINITIONS and metric in METRIC_NAMES, metric


# --- tier 1 ----------------------------------------------------------------------------------


def test_the_planted_inertial_frame_is_named_at_tier_one_and_the_run_goes_on(tmp_path, monkeypatch):
    """The sabotaged mini reads the arm natively from a copy of the URDF whose third link's
    inertial frame is turned 0.5 rad: not refused, tier 1 names the link and the field, the
    poses (tier 2) are the scene's, the dynamics (tier 3) are not."""
    scene = arm_scene(tmp_path)
    monkeypatch.setenv(SABOTAGE_VARIABLE, "inertial_frame_rotated")
    run = run_engine(scene, parse_engine_spec("mini"))
    assert run.status == "ok", run.message
    rows = by_metric(run.tiers)
    fields = rows["model_fields"]
    assert fields.message.startswith("link arm/lbr_iiwa_link_3: inertia differs by "), fields
    assert fields.value > 0.1, fields
    assert rows["fk_error"].value < ROUND_OFF, rows["fk_error"]
    assert rows["bias_force_error"].value > 5 * MINI_BIAS, rows["bias_force_error"]
    monkeypatch.delenv(SABOTAGE_VARIABLE)
    control = by_metric(run_engine(scene, parse_engine_spec("mini")).tiers)
    assert control["model_fields"].value < ROUND_OFF, control["model_fields"]


def test_a_model_difference_read_by_physval_is_still_refused(tmp_path, monkeypatch):
    """The same difference from an engine that builds the model from physval's reading is a
    model_mismatch, as before: the scene was not what it ran."""
    scene = arm_scene(tmp_path)
    name = "inertial_frame_rotated"
    monkeypatch.setitem(SABOTAGES, name, dataclasses.replace(SABOTAGES[name], loader=None))
    monkeypatch.setenv(SABOTAGE_VARIABLE, name)
    run = run_engine(scene, parse_engine_spec("mini"))
    assert run.status == "model_mismatch", run.status
    assert "inertia_world of body 2" in run.message and run.tiers == [], run.message


def test_only_the_models_own_differences_let_a_native_run_go_on(tmp_path):
    """A model link's or joint's difference, M(q0), and the totals beside them are the model's;
    a body of the scene's own, a total alone, or an unusable report still refuse."""
    scene = arm_scene(
        tmp_path,
        ARM + "bodies:\n  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, "
        "position: [3, 0, 0]}\n",
    )
    rows = [scene.scenario.bodies[k].name for k in dynamic_bodies(scene)]
    link, ball = rows.index("arm/lbr_iiwa_link_3"), rows.index("ball")

    def mismatch(quantity, body=None, **more):
        return Mismatch(quantity, body, 1.0, 2.0, 1.0, **more)

    owned = [
        mismatch("inertia_world", link),
        mismatch("joint 'arm/lbr_iiwa_joint_2' axis", item="arm/lbr_iiwa_joint_2"),
        mismatch("mass_matrix[2, 3]"),
        mismatch("energy"),
    ]
    refused = [mismatch("mass", ball), mismatch("com", problem="shape (3,)")]
    assert model_owned(scene, owned + refused) == (owned, refused)
    assert model_owned(scene, [mismatch("energy")]) == ([], [mismatch("energy")])


FIELD_BREAKS = {
    "mass": (
        lambda model, joints: (_scaled(model, "mass", 4, 1.1), joints),
        "link arm/lbr_iiwa_link_5: mass differs by 1.00e-01",
    ),
    "centre of mass": (
        lambda model, joints: (_shifted(model, 6, 0.013), joints),
        "link arm/lbr_iiwa_link_7: centre of mass differs by ",
    ),
    "axis": (
        lambda model, joints: (model, _joint_field(joints, "axes", 3, lambda a: -a)),
        "joint arm/lbr_iiwa_joint_4: axis differs by 2.00e+00",
    ),
    "type": (
        lambda model, joints: (model, dataclasses.replace(joints, types=("slider",) * 7)),
        "joint arm/lbr_iiwa_joint_1: type differs by 1.00e+00 (relative; engine slider",
    ),
    "limits": (
        lambda model, joints: (model, _joint_field(joints, "limits", 5, lambda a: a * 0.5)),
        "joint arm/lbr_iiwa_joint_6: limits differs by ",
    ),
    "damping": (
        lambda model, joints: (model, _joint_field(joints, "damping", 1, lambda a: 0.0 * a)),
        "joint arm/lbr_iiwa_joint_2: damping differs by 1.00e+00",
    ),
}
"""Field -> (how the engine's reports are broken, how the row's message starts)."""


def _scaled(model, field, row, factor):
    values = np.array(getattr(model, field), dtype=float)
    values[row] *= factor
    return dataclasses.replace(model, **{field: values})


def _shifted(model, row, distance):
    com = np.array(model.com, dtype=float)
    com[row, 0] += distance
    return dataclasses.replace(model, com=com)


def _joint_field(joints, field, row, change):
    values = np.array(getattr(joints, field), dtype=float)
    values[row] = change(values[row])
    return dataclasses.replace(joints, **{field: values})


@pytest.mark.parametrize("field", sorted(FIELD_BREAKS))
def test_model_fields_names_the_link_or_joint_and_the_field_that_differs(tmp_path, field):
    scene = arm_scene(tmp_path)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(scene)
    model, joints = adapter.model_report(), adapter.joint_report()
    exact = model_fields(scene, model, joints)
    assert exact.value < ROUND_OFF, exact
    breaks, message = FIELD_BREAKS[field]
    broken = model_fields(scene, *breaks(model, joints))
    assert broken.message.startswith(message), broken.message
    assert broken.value >= 1e-2, broken


def test_the_reference_joint_report_carries_the_files_limits_and_damping(tmp_path):
    report = scene_joint_report(arm_scene(tmp_path))
    assert report.damping.tolist() == [0.5] * 7 and report.armature.tolist() == [0.0] * 7
    assert report.limits[0].tolist() == pytest.approx([-2.96705972839, 2.96705972839])


# --- tiers 2 and 3 -----------------------------------------------------------------------------


class ReferenceProbe:
    """mini with a ``model_probe`` that answers with the reference side's own values, broken at
    one place when ``broken`` says so (a link offset, an entry of M, an entry of b)."""

    def __init__(self, scene, broken: str = "", fail: bool = False):
        self.scene, self.broken, self.fail = scene, broken, fail

    def model_probe(self, q, nu) -> ModelProbe:
        if self.fail:
            raise RuntimeError("the engine cannot be set to a joint state")
        tree = self.scene.joint_tree
        pose = forward_kinematics(tree, q)
        pos, matrix = pose.pos.copy(), mass_matrix(tree, q)
        bias = bias_forces(tree, q, nu, _loads(self.scene))
        if self.broken == "fk":
            pos[4, 2] += 1e-3
        if self.broken == "mass_matrix":
            matrix[2, 3] = matrix[3, 2] = matrix[2, 3] * 1.05 + 1e-3
        if self.broken == "bias":
            bias[1] += 0.5
        quat = np.array([matrix_to_quat(rotation) for rotation in pose.rot])
        return ModelProbe(pos, quat, matrix, bias)


PROBE_BREAKS = {
    "fk": ("fk_error", ("link arm/lbr_iiwa_link_5: centre off by 1.00e-03 m",)),
    "mass_matrix": ("mass_matrix_error", ("arm/lbr_iiwa_joint_3", "arm/lbr_iiwa_joint_4")),
    "bias": ("bias_force_error", ("b[1] (arm/lbr_iiwa_joint_2): off by 0.5",)),
}
"""What ``ReferenceProbe`` breaks -> the row that must find it and what its message names."""


@pytest.mark.parametrize("broken", sorted(PROBE_BREAKS))
def test_each_probed_tier_finds_its_quantity_broken_and_only_that(tmp_path, broken):
    scene = arm_scene(tmp_path)
    exact = by_metric(probe_tiers(scene, ReferenceProbe(scene), None, None))
    assert set(exact) == {"fk_error", "mass_matrix_error", "bias_force_error"}
    assert all(row.value < ROUND_OFF for row in exact.values()), exact
    rows = by_metric(probe_tiers(scene, ReferenceProbe(scene, broken), None, None))
    metric, named = PROBE_BREAKS[broken]
    assert rows[metric].value > 1e-4, rows[metric]
    assert all(part in rows[metric].message for part in named), rows[metric].message
    assert "model_probe" in rows[metric].message
    assert all(row.value < ROUND_OFF for name, row in rows.items() if name != metric), rows


def test_the_probed_states_are_seeded_and_within_the_limits(tmp_path):
    scene = arm_scene(tmp_path)
    states, again = probe_states(scene), probe_states(scene)
    assert len(states) == 5 and all(
        np.array_equal(a.q, b.q) for a, b in zip(states, again, strict=True)
    )
    assert np.array_equal(states[0].q, scene.joint_tree.zero())
    limits = np.array([j.limits for j in scene.scenario.joints])
    for state in states[1:]:
        assert np.all(state.q > limits[:, 0]) and np.all(state.q < limits[:, 1])
        assert np.all(np.abs(state.nu) <= 1.0) and np.abs(state.nu).max() > 0.1
    assert states[1].positions["arm/lbr_iiwa_joint_2"] == pytest.approx(0.5 + states[1].q[1])


def test_mini_by_finite_difference_gives_the_references_poses_and_bias(tmp_path, monkeypatch):
    """mini has no model_probe: the scene loaded at each state gives the reference's poses
    exactly and its bias within MINI_BIAS; with gravity 1 % low the bias is found."""
    scene = arm_scene(tmp_path)
    spec = parse_engine_spec("mini")
    rows = by_metric(run_engine(scene, spec).tiers)
    assert set(rows) == {"model_fields", "fk_error", "bias_force_error"}, rows
    assert rows["fk_error"].value < ROUND_OFF, rows["fk_error"]
    bias = rows["bias_force_error"]
    assert bias.value < MINI_BIAS and "(one-step finite difference)" in bias.message, bias
    assert 0 < bias.band < bias.value, bias
    monkeypatch.setenv(SABOTAGE_VARIABLE, "gravity_low")
    low = by_metric(run_engine(scene, spec).tiers)["bias_force_error"]
    assert low.value > 5 * MINI_BIAS and low.value > low.band, low


def test_rapier_gives_its_mass_matrix_at_q0_and_mini_none(tmp_path):
    scene = arm_scene(tmp_path)
    rows = by_metric(run_engine(scene, parse_engine_spec("rapier")).tiers)
    matrix = rows["mass_matrix_error"]
    assert matrix.value < 1e-5 and "configuration 1 of 5" in matrix.message, matrix
    assert "joint_report M(q0)" in matrix.message


def test_a_failing_probe_is_a_nan_row_never_a_failed_job(tmp_path, monkeypatch):
    scene = arm_scene(tmp_path)

    def probing(spec):
        adapter = create_adapter(spec)
        adapter.model_probe = ReferenceProbe(scene, fail=True).model_probe
        return adapter

    monkeypatch.setattr(runner, "create_adapter", probing)
    run = run_engine(scene, parse_engine_spec("mini"))
    assert run.status == "ok", run.message
    rows = by_metric(run.tiers)
    for metric in ("fk_error", "mass_matrix_error", "bias_force_error"):
        assert math.isnan(rows[metric].value), rows[metric]
        assert "not computed: RuntimeError: the engine cannot be set" in rows[metric].message
    assert rows["model_fields"].value < ROUND_OFF
    assert [m.metric for m in measure_run(scene, run)][-4:] == [m.metric for m in run.tiers]


# --- the trajectory tier -----------------------------------------------------------------------


def test_joint_divergence_and_agreement_time_find_a_pair_that_parts(tmp_path, monkeypatch):
    text = ARM.replace("[mini, rapier]", '[mini, "mini(gyroscopic=implicit)"]')
    scene = arm_scene(tmp_path, text + "checks: {joint_divergence: 1.0e-4}\n")
    first = run_engine(scene, parse_engine_spec("mini"))
    same = run_engine(scene, parse_engine_spec("mini(gyroscopic=implicit)"))
    monkeypatch.setenv(SABOTAGE_VARIABLE, "gravity_low")
    parted = run_engine(scene, parse_engine_spec("mini(gyroscopic=implicit)"))
    close = {r["metric"]: r for r in compare_scene(scene, [first, same])}
    apart = {r["metric"]: r for r in compare_scene(scene, [first, parted])}
    assert close["joint_divergence"]["passed"], close["joint_divergence"]
    assert close["agreement_time"]["value"] == pytest.approx(0.05), close["agreement_time"]
    assert not apart["joint_divergence"]["passed"], apart["joint_divergence"]
    assert apart["joint_divergence"]["message"].startswith("joint arm/lbr_iiwa_joint_")
    assert "rad from mini" in apart["joint_divergence"]["message"]
    assert 0 < apart["agreement_time"]["value"] < 0.05, apart["agreement_time"]
    assert "leaves the band 0.0001 of mini" in apart["agreement_time"]["message"]


# --- through physval run -----------------------------------------------------------------------


def test_the_tier_rows_reach_results_through_physval_run(tmp_path):
    scene = tmp_path / "arm.yaml"
    scene.write_text(ARM + "checks: {model_fields: 1.0e-5, joint_divergence: 0.01}\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--jobs", "1"]) == 0
    rows = pd.read_csv(tmp_path / "out" / "results.csv")
    found = {(r.engine, r.metric) for r in rows.itertuples()}
    for engine in ("mini", "rapier"):
        for metric in ("model_fields", "fk_error", "bias_force_error"):
            assert (engine, metric) in found, (engine, metric)
    assert ("rapier", "mass_matrix_error") in found and ("mini", "mass_matrix_error") not in found
    assert {("rapier", "joint_divergence"), ("rapier", "agreement_time")} <= found
    fields = rows[rows.metric == "model_fields"]
    assert fields.passed.all(), fields[["engine", "value", "message"]]


WRITE_FAILS = """
import errno
import validation.jobs.run as run
def disk_full(*_):
    raise OSError(errno.ENOSPC, "No space left on device")
run.write_run = disk_full
"""
"""Injected into a run: its jobs finish (and are journaled), its files cannot be written."""

NO_ENGINE = """
import validation.jobs.run as run
def refused(payload):
    raise AssertionError("a resumed run must read its finished jobs from the journal")
run.JOB_KINDS["run"] = refused
"""
"""Injected into the resumed run: no job may run again."""


def physval(*arguments: str, cwd: Path, code: str = "") -> subprocess.CompletedProcess:
    script = f"import sys\n{code}\nfrom validation.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", script, *arguments],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_a_resumed_run_keeps_the_tier_rows_from_its_journal(tmp_path):
    (tmp_path / "arm.yaml").write_text(ARM)
    failed = physval(
        "run", "arm.yaml", "--out", "out", "--jobs", "1", cwd=tmp_path, code=WRITE_FAILS
    )
    assert failed.returncode == 2 and "--resume" in failed.stderr, failed.stderr
    resumed = physval("run", "--resume", "out", "--jobs", "1", cwd=tmp_path, code=NO_ENGINE)
    assert resumed.returncode == 0, resumed.stderr
    whole = physval("run", "arm.yaml", "--out", "whole", "--jobs", "1", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr
    columns = ["engine", "metric", "value", "band", "message"]
    tiers = [
        "model_fields",
        "fk_error",
        "mass_matrix_error",
        "bias_force_error",
        "joint_divergence",
    ]
    kept = pd.read_csv(tmp_path / "out" / "results.csv")
    again = pd.read_csv(tmp_path / "whole" / "results.csv")
    kept, again = (t[t.metric.isin(tiers)][columns].reset_index(drop=True) for t in (kept, again))
    assert len(kept) == 8, kept
    pd.testing.assert_frame_equal(kept, again)
