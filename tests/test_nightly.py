"""The nightly run's bookkeeping: known findings and baselines, on rows."""

from __future__ import annotations

import pandas as pd
import pytest

from validation.measure.noise import RELATIVE_NOISE
from validation.nightly.baseline import (
    baseline_table,
    classify,
    exit_failed,
    read_baseline,
)
from validation.nightly.known import apply_known
from validation.scenario import Scenario


def scene(known: list[dict]) -> Scenario:
    return Scenario.model_validate(
        {
            "name": "drop",
            "dt": 1e-3,
            "duration": 0.1,
            "engines": ["mini", "mujoco", "pybullet(profile=defaults)"],
            "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1}],
            "known": known,
        }
    )


def row(engine: str, metric: str, error: float, passed: bool | None, status: str = "ok") -> dict:
    if status == "ok" and passed is False:
        status = "failed"
    return {
        "scenario": "drop",
        "engine": engine,
        "metric": metric,
        "value": error,
        "error": error,
        "tolerance": 0.01,
        "passed": passed,
        "status": status,
        "engine_version": "1",
    }


REASON = "PyBullet's defaults profile damps the bounce (engines.md 2.4: e_apex 0.34)"


def test_a_known_failure_reads_known_and_a_known_pass_reads_fixed():
    findings = [
        {"engine": "pybullet(profile=defaults)", "metric": "energy_drift", "reason": REASON},
        {"engine": "mujoco", "metric": "*", "reason": "soft contacts (engines.md 1.2)"},
    ]
    rows = apply_known(
        [
            row("pybullet(profile=defaults)", "energy_drift", 0.5, False),
            row("pybullet(profile=defaults)", "restitution_error", 0.5, False),
            row("mujoco", "energy_drift", 0.001, True),
            row("mujoco", "status", 0.0, None, status="unstable"),
            row("mini", "energy_drift", 0.5, False),
        ],
        scene(findings),
    )
    outcomes = [(r["outcome"], bool(r["known"])) for r in rows]
    assert outcomes == [
        ("known", True),
        ("failed", False),  # another metric of the same engine is not covered
        ("fixed", True),
        ("known", True),  # '*' covers the run's own status row
        ("failed", False),
    ], outcomes
    assert not exit_failed(rows[:1]) and exit_failed(rows), "a known row must not fail the run"


def test_known_findings_are_checked_at_load_time(tmp_path):
    from validation.scenario import ScenarioError, load_scenario

    path = tmp_path / "bad.yaml"
    path.write_text(
        "dt: 0.001\nduration: 0.1\nbodies:\n  - {name: b, shape: {type: sphere, radius: 0.1}, mass: 1}\n"
        "known:\n  - {engine: 'mujoco(integrator=RK5)', metric: energy_drfit, reason: measured}\n"
        "  - {engine: mini, metric: energy_drift}\n"
    )
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    text = str(error.value)
    assert "known[1].reason" in text, text  # the reason is required
    path.write_text(path.read_text().replace("  - {engine: mini, metric: energy_drift}\n", ""))
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    text = str(error.value)
    assert "known[0].engine" in text and "known[0].metric" in text, text
    assert "did you mean 'energy_drift'" in text, text


def baseline_of(rows: list[dict], sha: str = "abc") -> pd.DataFrame:
    return baseline_table(pd.DataFrame(rows), {"drop": sha})


def classes(now: list[dict], before: pd.DataFrame, sha: str = "abc") -> list[str]:
    classified, missing = classify(now, before, {"drop": sha})
    return [r["baseline"] for r in classified] + [r["baseline"] for r in missing]


def test_rows_against_a_baseline():
    before = baseline_of(
        [
            row("mini", "energy_drift", 0.002, True),
            row("mini", "restitution_error", 0.004, True),
            row("mujoco", "energy_drift", 0.02, False),
            row("mujoco", "penetration_max", 0.001, True),
            row("pybullet", "energy_drift", 0.001, True),
        ]
    )
    now = [
        row("mini", "energy_drift", 0.002 * (1 + RELATIVE_NOISE / 2), True),  # within noise
        row("mini", "restitution_error", 0.004 * 1.03, True),  # 3 %: news
        row("mujoco", "energy_drift", 0.02, False),  # the same failure as yesterday
        row("mujoco", "penetration_max", 0.02, False),  # passed -> failed
        row("mini", "velocity_error", 0.0, True),  # a metric the baseline does not have
    ]
    found = classes(now, before)
    assert found == ["unchanged", "regressed", "unchanged", "regressed", "new", "missing"], found
    classified, _ = classify(now, before, {"drop": "abc"})
    assert exit_failed(classified)
    assert not exit_failed([classified[0], classified[2]]), "an unchanged failure is not news"


def test_a_changed_scene_is_not_a_regression():
    before = baseline_of([row("mini", "energy_drift", 0.002, True)], sha="old")
    assert classes([row("mini", "energy_drift", 0.5, False)], before, sha="new") == [
        "scene_changed"
    ]


def test_improvement_and_fixed(tmp_path):
    path = tmp_path / "baseline.csv"
    baseline_of([row("mujoco", "energy_drift", 0.02, False)]).to_csv(path, index=False)
    before = read_baseline(path)
    assert classes([row("mujoco", "energy_drift", 0.001, True)], before) == ["improved"]
    assert classes([row("mujoco", "energy_drift", 0.015, False)], before) == ["improved"]


def test_an_error_whose_sign_flipped_at_the_same_size_regressed(tmp_path):
    """Explicit instead of semi-implicit Euler on a projectile: |error| 4.905e-3 m both times,
    error_z -4.905e-3 then +4.905e-3. A scalar's sign the same way; a baseline saved before
    the signed columns existed compares the sizes alone."""
    low = {**row("mini", "position_at.ball", 4.905e-3, True), "error_x": 0.0, "error_y": 0.0}
    high = {**low, "error_z": 4.905e-3}
    low["error_z"] = -4.905e-3
    path = tmp_path / "baseline.csv"
    baseline_of([low]).to_csv(path, index=False)
    before = read_baseline(path)
    assert classes([high], before) == ["regressed"]
    assert classes([low], before) == ["unchanged"]
    gained = {**row("mini", "energy_drift", 1.9e-3, True), "signed_error": 1.9e-3}
    lost = {**gained, "signed_error": -1.9e-3}
    assert classes([gained], baseline_of([lost])) == ["regressed"]
    unsigned = baseline_of([row("mini", "position_at.ball", 4.905e-3, True)])
    unsigned = unsigned.drop(columns=["error_x", "error_y", "error_z", "signed_error"])
    unsigned.to_csv(path, index=False)
    assert classes([high], read_baseline(path)) == ["unchanged"]


def test_a_file_that_is_not_a_baseline_is_refused(tmp_path):
    path = tmp_path / "results.csv"
    path.write_text("scenario,engine\nx,y\n")
    with pytest.raises(ValueError, match="not a baseline"):
        read_baseline(path)


def test_a_finding_may_name_its_metrics_by_pattern():
    findings = [{"engine": "mujoco", "metric": "*velocity_after_impact.*", "reason": REASON}]
    rows = apply_known(
        [
            row("mujoco", "velocity_after_impact.a", 1.0, False),
            row("mujoco", "angular_velocity_after_impact.b", 1.0, False),
            row("mujoco", "restitution_error", 1.0, False),
        ],
        scene(findings),
    )
    assert [r["outcome"] for r in rows] == ["known", "known", "failed"], rows
