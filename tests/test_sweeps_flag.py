"""``physval run --sweeps on|off``: a run of named scenes skips their dt sweeps (the authoring
loop), the bare nightly run of the whole library runs them, and the flag overrides both."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

import validation.cli as cli
from validation.cli import BUNDLED_SCENARIOS, main
from validation.contract import PROVENANCE_FILE, RESULTS_FILE, SWEEP_FILE

PROJECTILE = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"
"""One sphere in flight, whose file declares a dt sweep (``sweep: {dt: [...]}``)."""

QUIET = ["--engines", "mini", "--jobs", "1", "--baseline", "none", "--history", "none"]


def swept(out: Path) -> bool:
    """Whether the run folder holds the scene's sweep: its rows, sweep.csv and the selection
    that says so; asserts the three agree."""
    rows = pd.read_csv(out / RESULTS_FILE)
    has_rows = bool(rows["metric"].str.startswith("sweep_").any())
    selection = json.loads((out / PROVENANCE_FILE).read_text())["selection"]
    assert has_rows == (out / SWEEP_FILE).is_file() == selection["sweeps"], (has_rows, selection)
    return has_rows


@pytest.fixture
def bare_library(monkeypatch):
    """A bare ``physval run`` whose bundled library is the projectile alone."""
    monkeypatch.setattr(cli, "default_scenario_paths", lambda: [PROJECTILE])


def test_a_named_scene_does_not_sweep(tmp_path):
    assert main(["run", str(PROJECTILE), *QUIET, "--out", str(tmp_path / "run")]) == 0
    assert not swept(tmp_path / "run")


def test_the_bare_library_run_sweeps(tmp_path, bare_library):
    assert main(["run", *QUIET, "--out", str(tmp_path / "run")]) == 0
    assert swept(tmp_path / "run")


def test_sweeps_on_sweeps_a_named_scene(tmp_path):
    out = tmp_path / "run"
    assert main(["run", str(PROJECTILE), *QUIET, "--sweeps", "on", "--out", str(out)]) == 0
    assert swept(out)


def test_sweeps_off_and_only_skip_the_sweeps_of_the_bare_run(tmp_path, bare_library):
    assert main(["run", *QUIET, "--sweeps", "off", "--out", str(tmp_path / "off")]) == 0
    assert not swept(tmp_path / "off")
    assert main(["run", *QUIET, "--only", "projectile", "--out", str(tmp_path / "only")]) == 0
    assert not swept(tmp_path / "only")


def test_resume_refuses_sweeps(tmp_path, capsys):
    assert main(["run", "--resume", str(tmp_path / "x"), "--sweeps", "on"]) == 2
    assert "--sweeps" in capsys.readouterr().err
