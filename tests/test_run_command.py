"""``physval run`` end to end: real scenes in the three engines, files, exit codes, statuses."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.measure.comparator import COLUMNS

TWO_PASSING_SCENES = [
    BUNDLED_SCENARIOS / "formulas" / "head_on_ratio_10.yaml",
    BUNDLED_SCENARIOS / "rotation" / "torque_free_symmetric_top.yaml",
]


def test_two_bundled_scenes_in_three_engines(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "run",
            *map(str, TWO_PASSING_SCENES),
            "--engines",
            "mini(gyroscopic=implicit), mujoco, pybullet",
            "--out",
            str(out),
        ]
    )
    printed = capsys.readouterr().out
    results = pd.read_csv(out / "results.csv")
    assert list(results.columns) == list(COLUMNS)
    assert set(results["engine"]) == {"mini(gyroscopic=implicit)", "mujoco", "pybullet"}
    assert set(results["scenario"]) == {"head_on_ratio_10", "torque_free_symmetric_top"}
    shown = ["scenario", "engine", "metric", "error", "tolerance", "passed", "status", "message"]
    not_ok = results[results["status"] != "ok"]
    assert not_ok.empty, f"rows not ok:\n{not_ok[shown].to_string()}"
    checked = results[results["tolerance"].notna()]
    not_passed = checked[checked["passed"] != True]  # noqa: E712 (a column of objects)
    assert not_passed.empty, f"checks that did not pass:\n{not_passed[shown].to_string()}"
    per_run = checked.groupby(["scenario", "engine"]).size()
    assert len(per_run) == 2 * 3, f"every scene x engine must carry checks:\n{per_run}"
    assert code == 0, (code, results[shown].to_string())
    assert {"precession_rate.top", "velocity_after_impact.light_e05"} <= set(checked["metric"])
    provenance = json.loads((out / "provenance.json").read_text())
    assert set(provenance["engines"]) == {"mini(gyroscopic=implicit)", "mujoco", "pybullet"}
    assert provenance["git_commit"] and provenance["command"].startswith("physval run")
    assert (out / "series.csv").exists() and (out / "impacts.csv").exists()
    assert "head_on_ratio_10" in printed
    assert not list(tmp_path.glob(".run-staging-*")), "a staging folder was left behind"


def scene_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    return path


def test_a_failed_check_exits_1(tmp_path):
    path = scene_file(
        tmp_path,
        """\
dt: 0.001
duration: 0.5
bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]
checks: {position_error: 1.0e-6}   # semi-implicit Euler is off by g·dt·t/2 = 2.5 mm
""",
    )
    assert main(["run", str(path), "--engines", "mini", "--out", str(tmp_path / "out")]) == 1
    row = pd.read_csv(tmp_path / "out" / "results.csv").set_index("metric").loc["position_error"]
    assert row["status"] == "failed" and not row["passed"], row
    assert row["error"] == pytest.approx(9.81 * 0.001 * 0.5 / 2, rel=1e-6)


def test_an_exploding_scene_gives_an_unstable_row_and_the_run_completes(tmp_path):
    path = scene_file(
        tmp_path,
        """\
dt: 0.001
duration: 2.0
gravity: [0, 0, 0]
engines: ["mini(integrator=explicit_euler)", mini]   # ω·dt = 1: explicit grows 2x per step
bodies: [{name: m, shape: {type: sphere, radius: 0.01}, mass: 1.0, position: [0.01, 0, 0]}]
springs: [{a: m, b: world, stiffness: 1.0e6, rest_length: 0.0}]
""",
    )
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 1
    results = pd.read_csv(tmp_path / "out" / "results.csv")
    statuses = results.groupby("engine")["status"].agg(set)
    assert "unstable" in statuses["mini(integrator=explicit_euler)"], statuses
    assert "unstable" not in statuses["mini"], statuses


def exit_code(argv: list[str]) -> int:
    """``main``'s exit code, whether it returns it or argparse exits with it."""
    try:
        return main(argv)
    except SystemExit as stop:
        return int(stop.code)


@pytest.mark.parametrize(
    "arguments",
    [
        ["--engines", "mujocoo"],
        ["--dt", "0"],
        ["--dt", "abc"],
        ["--only", "no_such_scene*"],
        ["missing.yaml"],
    ],
)
def test_bad_input_exits_2_and_writes_nothing(tmp_path, arguments, capsys):
    out = tmp_path / "out"
    paths = [] if arguments == ["missing.yaml"] else [str(TWO_PASSING_SCENES[0])]
    assert exit_code(["run", *paths, *arguments, "--out", str(out)]) == 2
    assert not out.exists(), "bad input must not write a report"
    assert "Traceback" not in capsys.readouterr().err


def test_an_exploded_trajectory_gives_rows_not_a_traceback(tmp_path):
    """k = 1e40 N/m: the state overflows; metrics on what was recorded must not crash."""
    path = scene_file(
        tmp_path,
        """\
dt: 0.001
duration: 0.5
ground: {}
bodies:
  - {name: a, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 0.5]}
  - {name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [1, 0, 0.5]}
springs: [{a: a, b: world, anchor_b: [0, 0, 1.0], stiffness: 1.0e40}]
engines: [mini]
""",
    )
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 1
    results = pd.read_csv(tmp_path / "out" / "results.csv")
    assert "unstable" in set(results["status"]), results


def test_null_name_and_duplicate_engines(tmp_path, capsys):
    path = scene_file(
        tmp_path,
        "name: null\ndt: 0.001\nduration: 0.01\nbodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]\n",
    )
    assert (
        main(
            [
                "run",
                str(path),
                "--only",
                "scene*",
                "--engines",
                "mini",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 0
    )
    assert (
        exit_code(["run", str(path), "--engines", "mini, mini", "--out", str(tmp_path / "p")]) == 2
    )
    assert "listed twice" in capsys.readouterr().err


def test_a_report_that_cannot_be_rendered_is_exit_2_with_the_record_published(
    tmp_path, capsys, monkeypatch
):
    """results.csv is the record and is published, but a run whose report.html could not be
    written never exits 0 (it did: the page a reader opens was silently missing)."""
    import validation.jobs.run as run_module

    def broken(*_args, **_kwargs):
        raise ValueError("Unknown format code 'g' for object of type 'str'")

    monkeypatch.setattr(run_module, "render_report", broken)
    out = tmp_path / "run"
    scene = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"
    code = main(
        [
            "run",
            str(scene),
            "--engines",
            "mini",
            "--jobs",
            "1",
            "--out",
            str(out),
            "--baseline",
            "none",
            "--history",
            "none",
        ]
    )
    printed = capsys.readouterr().out
    assert code == 2, printed
    assert (out / "results.csv").exists() and not (out / "report.html").exists()
    assert "report.html not rendered" in printed and "physval report" in printed, printed


def test_timings_name_every_phase_in_order_and_change_no_record(tmp_path, capsys):
    """``--timings`` prints one line on stderr naming each phase of ``phases.PHASES`` in
    order, each with its seconds, and the run's job kinds with their counts; results.csv is
    the one a run without it writes (but for its wall times)."""
    from validation.jobs.phases import PHASES

    path = scene_file(
        tmp_path,
        """\
dt: 0.001
duration: 0.05
bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]
""",
    )
    common = ["run", str(path), "--engines", "mini", "--history", "none", "--jobs", "1"]
    assert main([*common, "--out", str(tmp_path / "plain")]) == 0
    assert "timings:" not in capsys.readouterr().err
    assert main([*common, "--out", str(tmp_path / "timed"), "--timings"]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("timings:")]
    assert len(lines) == 1, lines
    shown = re.findall(r"(\w+) \d+\.\d\d s", re.sub(r"\(.*?\)", "", lines[0]))
    assert shown == [*PHASES, "total"], lines[0]
    assert "run: 1 jobs" in lines[0], lines[0]
    plain, timed = (
        pd.read_csv(tmp_path / name / "results.csv").drop(columns="wall_time_s")
        for name in ("plain", "timed")
    )
    pd.testing.assert_frame_equal(plain, timed)
