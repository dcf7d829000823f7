"""The library's power, in CI: a few sabotaged mini engines, each flagged by the scenes that
catch it (``validation/engines/sabotage.py``; the whole set is ``benchmarks/mutation_score.py``).

Each case runs ``physval run --engines mini`` (the sabotages are in mini) on the few bundled
scenes that catch one sabotage, with ``PHYSVAL_SABOTAGE`` set, and asserts that the run fails with new failures in
those scenes (the failure message names the scenes that caught it and the rows); the same
scenes unsabotaged are clean, ``--jobs 2`` workers inherit the sabotage and mark every mini row
in its engine version and no other engine's, an unknown name is one line
and exit 2 before any work, and every replacement is undone when a sabotage's block ends.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import BUNDLED_SCENARIOS, main
from validation.contract import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from validation.engines.sabotage import SABOTAGE_VARIABLE, SABOTAGES, VERSION_MARK
from validation.nightly.baseline import FAILING

pytestmark = pytest.mark.sabotage

ROOT = Path(__file__).resolve().parents[1]

CAUGHT_BY: dict[str, tuple[str, ...]] = {
    "gravity_low": ("formulas/projectile_between_steps.yaml",),
    "torque_ignored": ("rotation/constant_torque_spin_up.yaml",),
    "restitution_threshold": ("stiff/slow_bounce_below_threshold.yaml",),
    "sphere_box_normal_flipped": ("stiff/impact_100ms_thin_box.yaml",),
    "world_inertia_transposed": ("contact/box_drop_edge.yaml",),
    "clock_ahead": ("formulas/projectile_between_steps.yaml",),
    "torque_in_body_frame": ("rotation/tilted_box_off_axis_torque.yaml",),
    "restitution_mix_min": ("contact/unequal_contact_values.yaml",),
    "friction_mix_min": ("contact/unequal_contact_values.yaml",),
    "damper_without_spin": ("stiff/damped_torsion_off_centre_anchors.yaml",),
}
"""Sabotage -> bundled scenes that catch it plainly (measured by the benchmark; each of them
runs in well under a second per engine)."""

CAUGHT_IN: dict[str, str] = {"torque_in_body_frame": "mini(gyroscopic=implicit)"}
"""Sabotage -> the mini spec its scenes catch it in, where plain ``mini`` cannot: the documented
law (no gyroscopic term) already fails the tilted box's angular momentum, a known finding
whatever its size."""

SCENES = sorted({scene for scenes in CAUGHT_BY.values() for scene in scenes})
"""Every scene of the subset, for the clean run."""

SHOWN = ["scenario", "engine", "metric", "error", "tolerance", "status", "outcome", "message"]
"""Columns printed in a failure message."""


def run(
    tmp_path: Path, scenes, monkeypatch, sabotage: str | None = None, engines: str | None = "mini"
) -> tuple[int, pd.DataFrame]:
    """``physval run SCENES --jobs 1 [--engines ENGINES]`` in this process (the adapters read
    the environment); ``engines`` None: each scene's own."""
    if sabotage:
        monkeypatch.setenv(SABOTAGE_VARIABLE, sabotage)
    else:
        monkeypatch.delenv(SABOTAGE_VARIABLE, raising=False)
    out = tmp_path / (sabotage or "clean")
    arguments = ["run", *(str(BUNDLED_SCENARIOS / s) for s in scenes), "--jobs", "1"]
    arguments += ["--engines", engines] if engines else []
    code = main([*arguments, "--out", str(out), "--baseline", "none", "--history", "none"])
    return code, pd.read_csv(out / "results.csv", keep_default_na=False)


def new_failures(results: pd.DataFrame) -> pd.DataFrame:
    return results[results["outcome"].isin(FAILING)]


@pytest.mark.parametrize("sabotage", sorted(CAUGHT_BY))
def test_each_sabotage_is_flagged_by_its_scenes(sabotage, tmp_path, monkeypatch, capsys):
    engines = CAUGHT_IN.get(sabotage, "mini")
    code, results = run(tmp_path, CAUGHT_BY[sabotage], monkeypatch, sabotage, engines)
    capsys.readouterr()
    failing = new_failures(results)
    caught = sorted(set(failing["scenario"]))
    expected = sorted(Path(s).stem for s in CAUGHT_BY[sabotage])
    assert caught == expected, (
        f"{sabotage} ({SABOTAGES[sabotage].what}) was caught by {caught or 'no scene'}, "
        f"expected {expected}; its new failures:\n{failing[SHOWN].to_string()}"
    )
    assert code == EXIT_FAILED, f"{sabotage}: exit {code} with new failures in {caught}"


def test_the_same_scenes_unsabotaged_are_clean(tmp_path, monkeypatch, capsys):
    code, results = run(tmp_path, SCENES, monkeypatch)
    capsys.readouterr()
    failing = new_failures(results)
    assert failing.empty, f"new failures without a sabotage:\n{failing[SHOWN].to_string()}"
    assert code == EXIT_OK
    assert not results["engine_version"].str.contains(VERSION_MARK, regex=False).any()


def test_workers_inherit_the_sabotage_and_mark_every_mini_row(tmp_path):
    """``--jobs 2``: forkserver workers, started by a fresh process with the variable set; the
    scene's own engines, of which only mini's rows are marked and fail."""
    out = tmp_path / "run"
    scene = BUNDLED_SCENARIOS / "stiff" / "slow_bounce_below_threshold.yaml"
    environment = {**os.environ, SABOTAGE_VARIABLE: "restitution_threshold"}
    environment["PYTHONPATH"] = str(ROOT)
    command = [sys.executable, "-m", "validation.entry", "run", str(scene), "--jobs", "2"]
    command += ["--out", str(out), "--baseline", "none", "--history", "none"]
    done = subprocess.run(command, cwd=tmp_path, env=environment, capture_output=True, text=True)
    results = pd.read_csv(out / "results.csv", keep_default_na=False)
    mini = results["engine"].str.startswith("mini")
    marked = results["engine_version"].str.endswith(VERSION_MARK + "restitution_threshold")
    assert mini.any() and (~mini).any(), set(results["engine"])
    assert (marked == mini).all(), results.loc[marked != mini, ["engine", "engine_version"]]
    failing = new_failures(results)
    assert set(failing["engine"]) == {"mini"}, failing[SHOWN].to_string()
    assert done.returncode == EXIT_FAILED, done.stderr


def test_an_unknown_sabotage_is_one_line_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(SABOTAGE_VARIABLE, "gravity_lo")
    out = tmp_path / "run"
    code = main(["run", str(BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"), "--out", str(out)])
    error = capsys.readouterr().err.strip()
    assert code == EXIT_BAD_INPUT
    assert error.count("\n") == 0 and SABOTAGE_VARIABLE in error and "'gravity_lo'" in error, error
    assert "gravity_low" in error, error
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", sorted(SABOTAGES))
def test_a_sabotage_replaces_only_inside_its_block(name):
    sabotage = SABOTAGES[name]
    sites = sabotage._sites
    assert sites, f"{name} replaces nothing"

    def current(holder, attribute, key):
        return holder[key] if attribute is None else getattr(holder, attribute)

    with sabotage.active():
        inside = [current(h, a, k) is r for h, a, o, r, k in sites]
    after = [current(h, a, k) is o for h, a, o, r, k in sites]
    assert all(inside), f"{name}: not every site replaced inside the block"
    assert all(after), f"{name}: not every site restored after the block"


def test_pytest_physval_refuses_an_unknown_sabotage(tmp_path):
    scene = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"
    environment = {**os.environ, SABOTAGE_VARIABLE: "no_such_bug", "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "--physval", str(scene)]
    done = subprocess.run(command, cwd=tmp_path, env=environment, capture_output=True, text=True)
    errors = [line for line in done.stderr.splitlines() if SABOTAGE_VARIABLE in line]
    assert done.returncode == pytest.ExitCode.USAGE_ERROR, (done.stdout, done.stderr)
    assert len(errors) == 1 and "'no_such_bug'" in errors[0], done.stderr
