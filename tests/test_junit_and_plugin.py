"""CI integration (issue 12 item 5): the JUnit XML of result rows, and the pytest plugin.

The scenes are tiny on purpose (0.1 s, mini and MuJoCo RK4): a throw that passes, the same
throw with a tolerance semi-implicit Euler cannot meet (mini fails, RK4 passes), the same
again with that failure declared known, and a spring mini cannot integrate at its step
(unstable).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from validation.jobs.plan import plan_run
from validation.jobs.run import run_job
from validation.measure.comparator import compare_scene
from validation.nightly.junit import write_junit
from validation.nightly.known import apply_known

THROW = """\
description: A ball thrown up and sideways for 0.1 s; RK4 is exact, semi-implicit Euler g·t·dt/2 low.
dt: 1.0e-3
duration: 0.1
engines: [mini, "mujoco(integrator=RK4)"]
bodies:
  - name: ball
    shape: {type: sphere, radius: 0.1}
    mass: 1.0
    position: [0.0, 0.0, 1.0]
    velocity: [3.0, 0.0, 8.0]
expect:
  # x(0.1) = (3·0.1, 0, 1 + 8·0.1 - 9.81·0.01/2)
  - {kind: position_at, body: ball, time: 0.1, value: [0.3, 0.0, 1.750950]}
"""

EULER_ERROR = "semi-implicit Euler lands g·t·dt/2 = 0.49 mm low at 0.1 s (engines.md 1.6)"

SCENES = {
    # Euler's 0.49 mm is within 1 mm
    "throw": THROW + 'checks:\n  position_at.ball: {default: 1.0e-3, "mujoco(integrator=RK4)": 1.0e-9}\n',
    # ... and not within 1e-12 m
    "tight": THROW + 'checks:\n  position_at.ball: {default: 1.0e-12, "mujoco(integrator=RK4)": 1.0e-9}\n',
    "known_tight": THROW
    + 'checks:\n  position_at.ball: {default: 1.0e-12, "mujoco(integrator=RK4)": 1.0e-9}\n'
    + f'known:\n  - {{engine: mini, metric: position_at.ball, reason: "{EULER_ERROR}"}}\n',
}
"""Name -> YAML of the plugin's scenes: per (scene, spec) passed, except tight · mini (failed)
and known_tight · mini (known)."""

UNSTABLE_SPRING = """\
description: omega = 1000 rad/s at dt = 3 ms (omega·dt = 3 > 2); semi-implicit Euler blows up.
dt: 3.0e-3
duration: 0.1
gravity: [0.0, 0.0, 0.0]
engines: [mini]
bodies:
  - name: bob
    shape: {type: sphere, radius: 0.01}
    mass: 1.0
    position: [0.001, 0.0, 0.0]
springs:
  - {a: bob, b: world, anchor_b: [-0.1, 0.0, 0.0], stiffness: 1.0e6, rest_length: 0.1}
"""


def write_scenes(folder: Path, scenes: dict[str, str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in scenes.items():
        (folder / f"{name}.yaml").write_text(text)
    return folder


def judged_rows(folder: Path) -> list[dict]:
    """What ``physval run`` computes for the folder, with the known findings applied."""
    rows = []
    for scene, specs in plan_run([folder], None, None, None).scenes:
        done = [run_job((scene, spec)) for spec in specs]
        compared = compare_scene(scene, [run for run, _ in done], [found for _, found in done])
        rows += apply_known(compared, scene.scenario)
    return rows


@pytest.fixture(scope="module")
def rows(tmp_path_factory) -> list[dict]:
    folder = tmp_path_factory.mktemp("scenes")
    return judged_rows(write_scenes(folder, {**SCENES, "spring": UNSTABLE_SPRING}))


def expected_counts(rows: list[dict]) -> dict[str, int]:
    """The cases of the rows, counted from the rows alone (not by the writer's code)."""
    cases: dict[tuple, set[str]] = {}
    for row in rows:
        cases.setdefault((row["scenario"], row["engine"]), set()).add(row["outcome"])
    bad = {"failed", "unstable", "model_mismatch", "error"}
    return {
        "tests": len(cases),
        "failures": sum("failed" in found for found in cases.values()),
        "errors": sum(bool(found & (bad - {"failed"})) for found in cases.values()),
        "skipped": sum("known" in found and not found & bad for found in cases.values()),
    }


def suite_counts(root: ET.Element) -> dict[str, int]:
    suite = root.find("testsuite")
    return {key: int(suite.get(key)) for key in ("tests", "failures", "errors", "skipped")}


def test_junit_counts_are_the_cases_of_the_rows(rows, tmp_path):
    path = tmp_path / "ci" / "junit.xml"
    write_junit(rows, path)
    root = ET.parse(path).getroot()
    assert suite_counts(root) == expected_counts(rows)
    # the scenes were written to give exactly one case of each kind
    assert suite_counts(root) == {"tests": 7, "failures": 1, "errors": 1, "skipped": 1}
    cases = {(c.get("classname"), c.get("name")) for c in root.iter("testcase")}
    assert cases == {(row["scenario"], row["engine"]) for row in rows}
    assert [p.name for p in path.parent.iterdir()] == ["junit.xml"], "a temporary file was left"


def test_junit_failure_error_and_skipped_carry_the_rows(rows, tmp_path):
    path = tmp_path / "junit.xml"
    write_junit(rows, path)
    case = {(c.get("classname"), c.get("name")): c for c in ET.parse(path).getroot().iter("testcase")}
    failure = case["tight", "mini"].find("failure")
    failed = next(r for r in rows if r["scenario"] == "tight" and r["outcome"] == "failed")
    assert failed["metric"] == "position_at.ball"
    for shown in ("position_at.ball", f"value={failed['value']:.6g}", "tolerance=1e-12"):
        assert shown in failure.text, (shown, failure.text)
    assert failed["message"] in failure.text
    assert "position_at.ball" in failure.get("message")
    error = case["spring", "mini"].find("error")
    assert error is not None and error.get("type") == "unstable", ET.tostring(case["spring", "mini"])
    assert case["spring", "mini"].find("failure") is None
    skipped = case["known_tight", "mini"].find("skipped")
    assert skipped is not None and skipped.get("message") == EULER_ERROR
    assert case["known_tight", "mini"].find("failure") is None
    assert list(case["throw", "mujoco(integrator=RK4)"]) == [], "a passing case has no children"


def test_junit_reads_a_results_csv_like_the_rows(rows, tmp_path):
    """results.csv read back (NaN for empty cells, passed as text) gives the same file."""
    csv = tmp_path / "results.csv"
    pd.DataFrame(rows).to_csv(csv, index=False)
    write_junit(rows, tmp_path / "from_rows.xml")
    write_junit(pd.read_csv(csv), tmp_path / "from_csv.xml")
    assert (tmp_path / "from_csv.xml").read_text() == (tmp_path / "from_rows.xml").read_text()


def test_junit_without_known_findings_applied_counts_every_bad_row(rows, tmp_path):
    """Rows straight from the comparator (no ``outcome`` column): the known row fails."""
    raw = [{k: v for k, v in row.items() if k not in ("outcome", "known")} for row in rows]
    write_junit(raw, tmp_path / "junit.xml")
    counted = suite_counts(ET.parse(tmp_path / "junit.xml").getroot())
    assert counted == {"tests": 7, "failures": 2, "errors": 1, "skipped": 0}
