"""The comparator's own lines (``validation.measure.comparator``): the pass test of a row and
the judgement of a ``divergence`` row against its pair of engines."""

from __future__ import annotations

import pandas as pd

from validation.cli import BUNDLED_SCENARIOS, main
from validation.contract import EXIT_FAILED, EXIT_OK
from validation.engines.sabotage import SABOTAGE_VARIABLE
from validation.measure.comparator import _row, judge_divergence
from validation.measure.measurement import Measurement
from validation.measure.runner import EngineRun
from validation.nightly.baseline import FAILING
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene

TOLERANCE = 0.01
"""The restitution tolerance of the test scene (any number: the rows below sit around it)."""

BAND = 0.02
"""The row's discretization band (``Measurement.band``): larger than the tolerance, so a row
inside the band alone passes only when the pass test adds it."""


def bouncing_scene() -> Scenario:
    return Scenario.model_validate(
        {
            "name": "bounce",
            "dt": 0.001,
            "duration": 0.1,
            "ground": {"restitution": 0.5},
            "bodies": [
                {
                    "name": "ball",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "position": [0, 0, 0.5],
                    "restitution": 0.5,
                }
            ],
            "checks": {"restitution_error": TOLERANCE},
        }
    )


def restitution_row(error: float) -> dict:
    scene = compile_scene(bouncing_scene())
    result = Measurement("restitution_error", 0.5 + error, 0.5, "analytic", error, band=BAND)
    return _row(scene, EngineRun("bounce", "mini", "ok"), result, "ok")


def test_a_row_within_its_restitution_band_passes():
    """``error <= tolerance + band``: the band is the physics' O(dt) allowance (derived, never
    a tolerance), so an error beyond the tolerance but within tolerance + band passes."""
    row = restitution_row(TOLERANCE + 0.5 * BAND)
    assert row["band"] == BAND
    assert row["passed"] is True and row["status"] == "ok"


def test_a_row_beyond_tolerance_and_band_fails():
    row = restitution_row(TOLERANCE + 1.5 * BAND)
    assert row["passed"] is False and row["status"] == "failed"


def scene_rows(**failing: list[str]) -> list[dict]:
    """One scene's rows of mini (the reference) and mujoco: a passing ``position_at`` row
    each, its metrics in ``failing[engine]`` failed, and mujoco's failed divergence row."""
    rows = []
    for engine in ("mini", "mujoco"):
        for metric in ["position_at", *failing.get(engine, [])]:
            bad = metric != "position_at"
            rows.append(
                {
                    "engine": engine,
                    "metric": metric,
                    "passed": not bad,
                    "status": "failed" if bad else "ok",
                    "message": "",
                }
            )
    divergence = {"engine": "mujoco", "metric": "divergence", "passed": False, "status": "failed"}
    return [*rows, {**divergence, "message": "0.1 m at 1.5 s"}]


def judged(**failing: list[str]) -> dict:
    return judge_divergence(scene_rows(**failing), "mini")[-1]


def test_a_divergence_from_a_reference_off_its_closed_forms_is_not_judged():
    """mini (the reference) misses its own closed forms, mujoco meets its: the divergence is
    mini's, so mujoco's row does not fail."""
    row = judged(mini=["velocity_at", "energy_drift"])
    assert row["passed"] is None and row["status"] == "ok"
    assert row["message"].startswith("not judged: mini is off its own closed forms")
    assert "velocity_at, energy_drift" in row["message"]


def test_a_divergence_of_an_engine_off_its_closed_forms_fails_it():
    for failing in ({"mujoco": ["velocity_at"]}, {"mujoco": ["velocity_at"], "mini": ["x"]}):
        row = judged(**failing)
        assert row["passed"] is False and row["status"] == "failed"
        assert row["message"].startswith("mujoco is off its own closed forms (velocity_at)")


def test_a_divergence_of_a_pair_on_its_closed_forms_fails_on_the_pair():
    row = judged()
    assert row["passed"] is False and row["status"] == "failed"
    assert "the pair mujoco and mini diverge" in row["message"]


def run_projectile(out, baseline: str = "none") -> tuple[int, pd.DataFrame]:
    """``physval run`` of the projectile (its divergence checked) in mini, MuJoCo, PyBullet."""
    scene = BUNDLED_SCENARIOS / "formulas/projectile.yaml"
    arguments = ["run", str(scene), "--engines", "mini,mujoco,pybullet", "--jobs", "1"]
    code = main([*arguments, "--out", str(out), "--baseline", baseline, "--history", "none"])
    return code, pd.read_csv(out / "results.csv", keep_default_na=False)


def test_a_bug_in_the_reference_engine_fails_the_reference_alone(tmp_path, monkeypatch):
    """``PHYSVAL_SABOTAGE=gravity_low`` (mini's gravity 1 % low) on the projectile, whose
    divergence is checked: mini fails its closed forms; MuJoCo and PyBullet, 0.11 m from mini
    at 1.5 s, get no failing row for mini's bug."""
    monkeypatch.setenv(SABOTAGE_VARIABLE, "gravity_low")
    code, results = run_projectile(tmp_path / "run")
    failing = results[results["outcome"].isin(FAILING)]
    assert code == EXIT_FAILED
    assert set(failing["engine"]) == {"mini"}, failing[["engine", "metric", "message"]]
    diverged = results[results["metric"] == "divergence"]
    error, tolerance = (pd.to_numeric(diverged[c]) for c in ("error", "tolerance"))
    assert len(diverged) == 2 and (error > tolerance).all(), diverged[["error", "tolerance"]]
    assert diverged["message"].str.startswith("not judged: mini is off").all()


def test_against_a_baseline_the_reference_bug_moves_the_divergence_rows_with_it(
    tmp_path, monkeypatch
):
    """The same bug against a clean baseline: mini's rows regress; MuJoCo's and PyBullet's
    divergence rows (passed, now not judged) moved with their reference, ``reference_moved``,
    and their engines have no news of their own."""
    monkeypatch.delenv(SABOTAGE_VARIABLE, raising=False)
    assert run_projectile(tmp_path / "clean")[0] == EXIT_OK
    baseline = tmp_path / "baseline.csv"
    assert main(["baseline", "save", str(tmp_path / "clean"), "--to", str(baseline)]) == EXIT_OK
    monkeypatch.setenv(SABOTAGE_VARIABLE, "gravity_low")
    code, results = run_projectile(tmp_path / "sabotaged", str(baseline))
    assert code == EXIT_FAILED
    others = results[results["engine"] != "mini"]
    diverged = others[others["metric"] == "divergence"]
    assert set(diverged["baseline"]) == {"reference_moved"}
    assert set(others["baseline"]) <= {"unchanged", "reference_moved"}
    assert not others["outcome"].isin(FAILING).any()  # no new failure of theirs
    assert "regressed" in set(results[results["engine"] == "mini"]["baseline"])
