"""``physval sim2sim MODEL_FILE`` (issue 36): a model file, the Kuka of pybullet_data or a
user's own URDF, becomes a scene in the run folder, runs through ``physval run``'s machinery
and prints the first disagreeing tier per engine pair; every bad input is one line and exit 2
before any work. ``--package-path NAME=DIR`` on run, check and sim2sim."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from validation.cli import main
from validation.contract import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, RESULTS_FILE, SCENE_FILE
from validation.engine_api import MODEL_LOADER_OPTION, declarations
from validation.engines.sabotage import SABOTAGE_VARIABLE
from validation.jobs import sim2sim
from validation.scenario import load_scenario, urdf
from validation.scenario.engine_spec import not_installed

KUKA = "pkg:pybullet_data/kuka_iiwa/model.urdf"
MJCF = "pkg:pybullet_data/mjcf/inverted_double_pendulum.xml"
SHORT = ["--duration", "0.05", "--jobs", "1"]
"""A 50-step swing: the tests check the command's plumbing, not the physics."""

ARM_URDF = """<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0 0 0.15"/><mass value="1.0"/>
      <inertia ixx="0.008" iyy="0.008" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <link name="fore">
    <inertial><origin xyz="0 0 0.1"/><mass value="0.5"/>
      <inertia ixx="0.002" iyy="0.002" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.05"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="5"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="{lower}" upper="2.5" effort="10" velocity="5"/>
  </joint>
</robot>
"""


def arm(folder: Path, lower: float = -2.5, name: str = "arm.urdf") -> Path:
    """A user's two-link arm: shoulder and elbow hinges about y; the elbow's lower limit
    ``lower``."""
    path = folder / name
    path.write_text(ARM_URDF.format(lower=lower))
    return path


def sim2sim_run(capsys, *args) -> tuple[int, str, str]:
    code = main(["sim2sim", *map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def verdict_lines(out: str) -> list[str]:
    return out.split(sim2sim.VERDICT_TITLE + "\n", 1)[1].splitlines()


TIER_LINE = re.compile(
    r"^(?P<a>\S+)(?: vs (?P<b>\S+))?: tier (?P<n>\d) \((?P<metric>\w+)\): "
    r"(?P<engine>\S+?)(?: \((?P<status>\w+)\))?: (?P<message>.*)$"
)


def assert_verdicts_follow_the_rows(out: Path, printed: str, engines: list[str]) -> None:
    """Each engine pair has one line, and it names the pair's first failed row in the tier
    order with that row's message, or says the pair agrees when neither has one (and both
    runs ended ok)."""
    rows = pd.read_csv(out / RESULTS_FILE, dtype=str, keep_default_na=False)
    failed = rows[rows["passed"] == "False"]
    order = [metric for tier in sim2sim.TIERS for metric in tier]
    lines = verdict_lines(printed)
    assert len(lines) == max(1, len(engines) * (len(engines) - 1) // 2), lines
    for line in lines:
        pair, _, verdict = line.partition(": ")
        a, _, b = pair.partition(" vs ")
        b = b or a  # one engine: its own verdict
        mine = failed[failed["engine"].isin([a, b]) & failed["metric"].isin(order)]
        runs = rows[rows["engine"].isin([a, b]) & (rows["metric"] == "status")]
        if verdict == sim2sim.AGREEING or verdict.startswith("no tier row failed"):
            assert mine.empty, (line, mine)
            assert runs.empty == (verdict == sim2sim.AGREEING), (line, runs)
            continue
        found = TIER_LINE.match(line)
        assert found, line
        first = min(order.index(m) for m in mine["metric"])
        assert order.index(found["metric"]) == first, (line, mine)
        row = mine[(mine["engine"] == found["engine"]) & (mine["metric"] == found["metric"])]
        assert found["message"] in set(row["message"]), (line, row)
        run = runs[runs["engine"] == found["engine"]]
        assert found["status"] == (None if run.empty else run.iloc[0]["status"]), (line, run)


def test_the_kuka_runs_in_mini_and_rapier_and_gets_a_verdict(tmp_path, capsys):
    out = tmp_path / "run"
    code, printed, _ = sim2sim_run(
        capsys, KUKA, "--engines", "mini", "rapier", "--out", out, *SHORT
    )
    assert code in (EXIT_OK, EXIT_FAILED)
    assert_verdicts_follow_the_rows(out, printed, ["mini", "rapier"])
    scene = load_scenario(out / SCENE_FILE)
    assert scene.engines == ["mini", "rapier"]
    assert [j.name for j in scene.joints] == [f"model/lbr_iiwa_joint_{i}" for i in range(1, 8)]
    model = scene.models[0]
    assert (model.name, model.file, model.fixed_base, model.collisions) == (
        "model",
        KUKA,
        True,
        False,
    )
    assert model.joint_positions == {}  # 0 is inside every limit of the Kuka
    assert set(model.joint_velocities.values()) == {sim2sim.SWING_VELOCITY}
    assert set(scene.checks) <= set(sim2sim.SIM2SIM_CHECKS) and "joint_violation" in scene.checks
    rows = pd.read_csv(out / RESULTS_FILE)
    assert set(rows["engine"]) == {"mini", "rapier"}
    assert set(rows["scenario"]) == {"sim2sim-model"}


def test_mujoco_and_pybullet_agree_on_the_kuka(tmp_path, capsys):
    """Two float64 engines in reduced coordinates, each reading the file with its own loader,
    hold the same arm and swing it alike."""
    out = tmp_path / "run"
    engines = ["mujoco", "pybullet"]
    code, printed, _ = sim2sim_run(capsys, KUKA, "--engines", *engines, "--out", out, *SHORT)
    assert code == EXIT_OK
    assert verdict_lines(printed) == ["mujoco vs pybullet: " + sim2sim.AGREEING]
    assert_verdicts_follow_the_rows(out, printed, engines)


def test_a_users_urdf_runs_without_yaml(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a relative path, as a user types it
    arm(tmp_path)
    engines = ["mujoco", "pybullet", "mini"]
    code, printed, _ = sim2sim_run(
        capsys, "arm.urdf", "--engines", *engines, "--out", "run", *SHORT
    )
    assert code in (EXIT_OK, EXIT_FAILED), printed
    assert verdict_lines(printed)[0] == "mujoco vs pybullet: " + sim2sim.AGREEING
    assert_verdicts_follow_the_rows(tmp_path / "run", printed, engines)
    scene = load_scenario(tmp_path / "run" / SCENE_FILE)
    assert scene.models[0].file == str(tmp_path / "arm.urdf")  # absolute: the scene moves
    assert [j.name for j in scene.joints] == ["arm/shoulder", "arm/elbow"]


def test_a_joint_whose_limits_exclude_zero_starts_mid_range(tmp_path, capsys):
    code, _, _ = sim2sim_run(
        capsys, arm(tmp_path, lower=0.5), "--engines", "mini", "--out", tmp_path / "run", *SHORT
    )
    assert code == EXIT_OK
    model = load_scenario(tmp_path / "run" / SCENE_FILE).models[0]
    assert model.joint_positions == {"arm/elbow": pytest.approx(1.5)}  # (0.5 + 2.5) / 2


def test_one_engine_gets_its_own_verdict(tmp_path, capsys):
    out = tmp_path / "run"
    code, printed, _ = sim2sim_run(capsys, KUKA, "--engines", "mujoco", "--out", out, *SHORT)
    assert code == EXIT_OK
    assert verdict_lines(printed) == ["mujoco: " + sim2sim.AGREEING]


def test_the_model_hangs_below_its_base(tmp_path, capsys):
    """The Kuka stands upright at zero (an unstable equilibrium, where engines part at once):
    the scene turns its base so that the centre of mass hangs straight below it."""
    out = tmp_path / "run"
    assert sim2sim_run(capsys, KUKA, "--engines", "mini", "--out", out, *SHORT)[0] == EXIT_OK
    scene = load_scenario(out / SCENE_FILE)
    masses = np.array([b.mass for b in scene.bodies])
    centre = masses @ np.array([b.position for b in scene.bodies]) / masses.sum()
    assert centre[2] < -0.3  # the arm's centre of mass, some 0.4 m from its base
    np.testing.assert_allclose(centre[:2], 0.0, atol=1e-12)


def test_checks_by_engine_name_apply_to_every_spec_of_the_engine():
    value = {"default": 1e-9, "mini": 5e-3}
    engines = ["mujoco", "mini", "mini(gyroscopic=implicit)"]
    assert sim2sim._tolerance(value, engines) == {
        "default": 1e-9,
        "mini": 5e-3,
        "mini(gyroscopic=implicit)": 5e-3,
    }
    assert sim2sim._tolerance(1e-4, engines) == 1e-4


def test_a_failed_tier_is_named_with_its_rows_message(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sim2sim.SIM2SIM_CHECKS, "joint_violation", 1e-12)  # mini's is ~1e-7
    out = tmp_path / "run"
    engines = ["mini", "mini(gyroscopic=implicit)"]
    code, printed, _ = sim2sim_run(capsys, KUKA, "--engines", *engines, "--out", out, *SHORT)
    assert code == EXIT_FAILED
    rows = pd.read_csv(out / RESULTS_FILE, dtype=str, keep_default_na=False)
    failed = rows[(rows["metric"] == "joint_violation") & (rows["passed"] == "False")]
    assert list(failed["engine"]) == engines
    expected = f"tier 4 (joint_violation): mini: {failed.iloc[0]['message']}"
    assert verdict_lines(printed) == [f"{' vs '.join(engines)}: {expected}"]
    assert_verdicts_follow_the_rows(out, printed, engines)


VERDICT_ROWS = pd.DataFrame(
    [
        ("mini", "joint_violation", False, "ok", "joint arm/j1 pulled apart"),
        ("rapier", "model_fields", False, "unstable", "link arm/l3: inertia differs"),
        ("rapier", "fk_error", True, "unstable", ""),
        ("rapier", "status", False, "unstable", "deep_penetration at t = 0.2 s"),
        ("drake", "model_fields", None, "unsupported", ""),
        ("drake", "status", None, "unsupported", "drake cannot represent: joints; ground"),
    ],
    columns=["engine", "metric", "passed", "status", "message"],
).assign(value_text="")
"""Rows of three engines: mini failed a tier-4 check; Rapier's run went unstable after its
tier-1 row failed; Drake could not run the model."""


def test_the_first_tier_wins_over_later_ones():
    rows = VERDICT_ROWS
    assert sim2sim.pair_verdict(rows, "mini", "rapier") == (
        "tier 1 (model_fields): rapier (unstable): link arm/l3: inertia differs"
    )
    assert sim2sim.pair_verdict(rows[rows["metric"] != "model_fields"], "mini", "rapier") == (
        "tier 4 (joint_violation): mini: joint arm/j1 pulled apart"
    )


def test_a_run_that_did_not_end_ok_is_no_agreement():
    rows = VERDICT_ROWS[VERDICT_ROWS["engine"] != "mini"]
    assert sim2sim.pair_verdict(rows[rows["metric"] != "model_fields"], "rapier", "drake") == (
        "no tier row failed, but rapier's run is unstable: deep_penetration at t = 0.2 s"
    )
    assert sim2sim.pair_verdict(rows[rows["engine"] == "drake"], "drake", "rapier") == (
        "no tier row failed, but drake's run is unsupported: drake cannot represent: joints "
        "(and 1 more in results.csv)"
    )


def test_the_scene_loads_with_physval_check(tmp_path, capsys):
    out = tmp_path / "run"
    assert sim2sim_run(capsys, KUKA, "--engines", "mini", "--out", out, *SHORT)[0] == EXIT_OK
    assert main(["check", str(out / SCENE_FILE)]) == EXIT_OK
    assert "1 valid, 0 invalid" in capsys.readouterr().out


def test_a_rerun_replaces_its_own_run_folder(tmp_path, capsys):
    out = tmp_path / "run"
    for _ in range(2):  # the scene file is one of a run folder's files
        assert sim2sim_run(capsys, KUKA, "--engines", "mini", "--out", out, *SHORT)[0] == EXIT_OK


SINGLE_LINK = (
    '<robot name="r"><link name="a"><inertial><mass value="1"/>'
    '<inertia ixx="1" iyy="1" izz="1"/></inertial></link></robot>'
)
FLOATING = (
    '<link name="b"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1"/></inertial>'
    '</link><joint name="j" type="floating"><parent link="a"/><child link="b"/></joint></robot>'
)

BAD_INPUTS = {
    "missing file": (["nowhere.urdf"], "nowhere.urdf: no such file"),
    "not a model": (["notes.txt"], "expected a URDF (.urdf) or MJCF (.xml) model file"),
    "unreadable": (["broken.urdf"], "broken.urdf: cannot be read"),
    "no package": (["pkg:no_such_package/x.urdf"], "no installed Python package"),
    "unknown engine": ([KUKA, "--engines", "nosuch"], "--engines:"),
    "engine twice": ([KUKA, "--engines", "mini", "mini"], "--engines: an engine is listed twice"),
    "package path syntax": ([KUKA, "--package-path", "robots"], "expected NAME=DIR"),
    "package path missing": ([KUKA, "--package-path", "r=/no/such/dir"], "is not a folder"),
    "no movable joint": (["single.urdf"], "single.urdf: has no movable joint"),
    "floating joint": (["floating.urdf"], "floating.urdf: cannot be read"),
    "dt beyond the swing": ([KUKA, "--dt", "0.5", "--duration", "0.1"], "--duration: expected"),
}


@pytest.mark.parametrize("case", BAD_INPUTS)
def test_bad_input_is_one_line_and_exit_2(case, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("not a robot")
    (tmp_path / "broken.urdf").write_text("<robot><link name='a'>")
    (tmp_path / "single.urdf").write_text(SINGLE_LINK)
    (tmp_path / "floating.urdf").write_text(SINGLE_LINK.replace("</robot>", FLOATING))
    args, expected = BAD_INPUTS[case]
    code, _, err = sim2sim_run(capsys, *args, "--out", "run", *SHORT)
    assert code == EXIT_BAD_INPUT
    assert len(err.strip().splitlines()) == 1 and expected in err, err
    assert "Traceback" not in err
    assert not (tmp_path / "run").exists()  # before any work


@pytest.mark.parametrize("command", ["run", "check"])
def test_package_path_is_checked_on_run_and_check(command, tmp_path, capsys):
    assert main([command, "--package-path", "nothing", str(tmp_path)]) == EXIT_BAD_INPUT
    assert capsys.readouterr().err.strip() == (
        "--package-path nothing: expected NAME=DIR (a package name, '=', its folder)"
    )


def test_package_path_sets_the_resolvers_folders(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(urdf, "PACKAGE_PATHS", {})
    (tmp_path / "robots").mkdir()
    out = tmp_path / "run"
    flags = ["--package-path", f"robots={tmp_path / 'robots'}", "--package-path", "x=."]
    assert sim2sim_run(capsys, KUKA, "--engines", "mini", "--out", out, *flags, *SHORT)[0] == 0
    expected = {"robots": str(tmp_path / "robots"), "x": str(Path.cwd())}
    assert dict(urdf.PACKAGE_PATHS) == expected


def test_the_default_engines_are_every_installed_engine_with_joints_native_loaders_first():
    engines = sim2sim.model_engines()
    installed = {
        name
        for name, declaration in declarations().items()
        if "joints" in declaration.capabilities.features and not not_installed(name)
    }
    assert set(engines) == installed and "mini" in engines
    native = [bool(declarations()[name].option(MODEL_LOADER_OPTION.name)) for name in engines]
    assert native == sorted(native, reverse=True), engines


def test_the_readmes_sim2sim_command_runs(tmp_path, capsys):
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    (line,) = [x for x in readme.splitlines() if x.strip().startswith("physval sim2sim pkg:")]
    argv = line.split("#", 1)[0].split()[1:]
    out = tmp_path / "run"
    code = main([*argv, "--engines", "mini", "--out", str(out), *SHORT])
    assert code == EXIT_OK
    assert (out / SCENE_FILE).is_file()
    assert sim2sim.VERDICT_TITLE in capsys.readouterr().out


def test_an_out_folder_of_the_users_is_refused_and_left_as_it_was(tmp_path, capsys):
    """``--out`` follows ``physval run``'s rules: a folder holding the user's files is not
    replaced (one line, exit 2, before any work), whatever the scene written for the model."""
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "chapter1.tex").write_text("precious")
    code, _, err = sim2sim_run(capsys, KUKA, "--engines", "mini", "--out", out, *SHORT)
    assert code == EXIT_BAD_INPUT
    assert err.strip().startswith(f"--out {out}:") and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == ["chapter1.tex"]
    assert (out / "chapter1.tex").read_text() == "precious"


def test_an_mjcf_model_runs(tmp_path, capsys):
    out = tmp_path / "run"
    engines = ["mujoco", "pybullet"]
    code, printed, _ = sim2sim_run(capsys, MJCF, "--engines", *engines, "--out", out, *SHORT)
    assert code in (EXIT_OK, EXIT_FAILED), printed
    assert_verdicts_follow_the_rows(out, printed, engines)
    scene = load_scenario(out / SCENE_FILE)
    assert scene.models[0].name == "inverted_double_pendulum"
    assert {j.type for j in scene.joints} >= {"slider", "hinge"}


def test_package_path_on_check_sets_the_resolvers_folders(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(urdf, "PACKAGE_PATHS", {})
    scene = tmp_path / "scene.yaml"
    scene.write_text(
        "dt: 0.01\nduration: 0.1\nbodies:\n  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0}\n"
    )
    assert main(["check", str(scene), "--package-path", f"robots={tmp_path}"]) == EXIT_OK
    assert dict(urdf.PACKAGE_PATHS) == {"robots": str(tmp_path)}


def test_package_path_finds_a_users_meshes(tmp_path, capsys, monkeypatch):
    """A URDF whose mesh is ``package://desc/...``, away from its package folder: one line
    naming the mesh and exit 2 without ``--package-path``, a run with it; ``physval check``
    of the scene it wrote likewise."""
    monkeypatch.setattr(urdf, "PACKAGE_PATHS", {})
    meshes = tmp_path / "ws" / "desc" / "meshes"
    meshes.mkdir(parents=True)
    (meshes / "fore.stl").write_text("solid fore\nendsolid fore\n")
    mesh = '<visual><geometry><mesh filename="package://desc/meshes/fore.stl"/></geometry></visual>'
    urdf_file = arm(tmp_path)
    urdf_file.write_text(
        urdf_file.read_text().replace('<link name="fore">', '<link name="fore">' + mesh)
    )
    args = [urdf_file, "--engines", "mini", "--out", tmp_path / "run", *SHORT]
    code, _, err = sim2sim_run(capsys, *args)
    assert code == EXIT_BAD_INPUT and len(err.strip().splitlines()) == 1
    assert "package://desc/meshes/fore.stl" in err and "Traceback" not in err
    code, printed, _ = sim2sim_run(
        capsys, *args, "--package-path", f"desc={tmp_path / 'ws' / 'desc'}"
    )
    assert code in (EXIT_OK, EXIT_FAILED), printed  # it ran
    assert_verdicts_follow_the_rows(tmp_path / "run", printed, ["mini"])
    scene = str(tmp_path / "run" / SCENE_FILE)  # physval check takes the same flag
    assert main(["check", scene]) == EXIT_BAD_INPUT
    assert main(["check", scene, "--package-path", f"desc={tmp_path / 'ws' / 'desc'}"]) == 0


def test_a_planted_model_difference_is_named_at_tier_one(tmp_path, capsys, monkeypatch):
    """The issue's planted difference through the command: mini, sabotaged to read the Kuka
    from a copy whose third link's inertial frame is turned (``inertial_frame_rotated``), is
    named at tier 1 by that link and "inertia" against MuJoCo; unsabotaged, they agree."""
    out = tmp_path / "run"
    args = [KUKA, "--engines", "mujoco", "mini", "--out", out, *SHORT]
    monkeypatch.setenv(SABOTAGE_VARIABLE, "inertial_frame_rotated")
    code, printed, _ = sim2sim_run(capsys, *args)
    assert code == EXIT_FAILED
    (line,) = verdict_lines(printed)
    assert line.startswith(
        "mujoco vs mini: tier 1 (model_fields): mini: link model/lbr_iiwa_link_3: inertia differs"
    ), line
    assert_verdicts_follow_the_rows(out, printed, ["mujoco", "mini"])
    monkeypatch.delenv(SABOTAGE_VARIABLE)
    code, printed, _ = sim2sim_run(capsys, *args)
    assert (code, verdict_lines(printed)) == (EXIT_OK, ["mujoco vs mini: " + sim2sim.AGREEING])
