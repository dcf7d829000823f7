"""A baseline's row that a run lacks is ``missing`` and fails the run (exit 1, the rows named)
unless its engine was left out of ``--engines`` on purpose: an engine that reads
``not_installed`` or is absent now must not pass the nightly silently."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest
from tiny_project import shell, tiny_project

from validation.contract import BASELINE_FILE, EXIT_FAILED, EXIT_OK, SWEEP_ORDER
from validation.nightly.baseline import classify

ABSENT = "ghost"
"""An engine the baseline has rows of and this machine does not (uninstalled, or renamed)."""


@pytest.fixture(scope="module")
def nightly(tmp_path_factory) -> Path:
    """A folder with the scene and a baseline of its mini rows plus the same rows of
    ``ABSENT``."""
    folder = tiny_project(tmp_path_factory.mktemp("missing"))
    first = shell("physval run --out first --jobs 1 --history none", folder)
    assert first.returncode == EXIT_OK, first.stdout + first.stderr
    saved = shell("physval baseline save first --to mini.csv", folder)
    assert saved.returncode == EXIT_OK, saved.stderr
    mini = pd.read_csv(folder / "mini.csv", dtype=str, keep_default_na=False)
    pd.concat([mini, mini.assign(engine=ABSENT)]).to_csv(folder / "baseline.csv", index=False)
    return folder


def test_rows_of_an_absent_engine_are_missing_and_fail_the_run(nightly):
    run = shell(
        "physval run --baseline baseline.csv --out absent --history none --junit junit.xml",
        nightly,
    )
    assert run.returncode == EXIT_FAILED, run.stdout + run.stderr
    assert f"fall · {ABSENT} (" in run.stdout, run.stdout
    comparison = pd.read_csv(nightly / "absent" / BASELINE_FILE)
    missing = comparison[comparison["baseline"] == "missing"]
    assert set(missing["engine"]) == {ABSENT} and len(missing) > 0, comparison
    case = ET.parse(nightly / "junit.xml").find(f".//testcase[@name='{ABSENT}']")
    assert case is not None and case.find("failure") is not None, "a failing JUnit case"
    assert f"{len(missing)} row(s) missing" in case.find("failure").get("message")


def test_an_engine_left_out_of_engines_is_absent_on_purpose(nightly):
    run = shell(
        "physval run --engines mini --baseline baseline.csv --out chosen --history none", nightly
    )
    assert run.returncode == EXIT_OK, run.stdout + run.stderr
    comparison = pd.read_csv(nightly / "chosen" / BASELINE_FILE)
    assert "missing" not in set(comparison["baseline"]), comparison
    assert "missing against the baseline" not in run.stdout


def test_a_not_installed_engine_asked_for_leaves_its_rows_missing():
    row = {"scenario": "fall", "engine": "rapier", "metric": "status", "status": "not_installed"}
    before = pd.DataFrame(
        [{"scenario": "fall", "engine": "rapier", "metric": "energy_drift", "scene_sha256": "s"}]
    )
    _, asked = classify([row], before, {"fall": "s"}, ["rapier"])
    _, left_out = classify([row], before, {"fall": "s"}, ["mini"])
    assert [r["metric"] for r in asked] == ["energy_drift"] and left_out == []


def test_the_sweep_rows_of_a_run_that_did_not_sweep_are_not_missing():
    drift = {"scenario": "fall", "engine": "mini", "metric": "energy_drift", "scene_sha256": "s"}
    order = {**drift, "metric": f"{SWEEP_ORDER}.energy_drift"}
    status = {"scenario": "fall", "engine": "mini", "metric": "status"}
    _, swept = classify([status], pd.DataFrame([drift, order]), {"fall": "s"}, swept=True)
    _, unswept = classify([status], pd.DataFrame([drift, order]), {"fall": "s"}, swept=False)
    assert [r["metric"] for r in swept] == [drift["metric"], order["metric"]], swept
    assert [r["metric"] for r in unswept] == [drift["metric"]], unswept
