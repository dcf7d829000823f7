"""The nightly run end to end: known findings, a baseline, regressions injected into
mini_engine, JUnit XML and the history, through ``physval run`` in subprocesses."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from validation.contract import BASELINE_FILE, EXIT_FAILED, EXIT_OK, RESULTS_FILE

SPIN = """\
description: a free box spinning about its major axis, no gravity (energy and L exact in mini)
dt: 0.001
duration: 0.5
gravity: [0, 0, 0]
engines: [mini, mujoco]
bodies:
  - {name: spinner, shape: {type: box, half_extents: [0.2, 0.1, 0.05]}, mass: 1.0,
     angular_velocity: [0, 0, 5.0]}
checks:
  # loose on purpose: the injected 1 %/s regression (0.5 % in 0.5 s) still passes them, so only
  # the baseline's noise rule can see it
  energy_drift: 0.05
  angular_momentum_drift: 0.05
"""

DROP = """\
description: a ball dropped onto the ground, e = 1 (energy kept but for the O(dt) impact gain)
dt: 0.001
duration: 0.6
engines: [mini, mujoco]
ground: {restitution: 1.0}
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 1.0],
     restitution: 1.0}
checks:
  restitution_error: 0.01
  # deliberately impossible for mini: a known finding
  penetration_max: {default: 0.01, mini: 1.0e-12}
  # passes in mujoco: a known finding that is fixed
  energy_drift: 0.1
known:
  - {engine: mini, metric: penetration_max, reason: "no position correction (formulas.md 4)"}
  - {engine: mujoco, metric: energy_drift, reason: "the damper recipe's e (engines.md 1.7)"}
"""

ENERGY_PER_SECOND = 0.01
"""The injected regression: mini gains 1 % of kinetic energy per second on the spinner."""

INJECTED = textwrap.dedent(
    f"""
    import sys
    import numpy as np
    import validation.engines.mini.adapter as adapter
    from mini_engine.model import State
    original = adapter.step
    def step(model, state, settings):
        new, report = original(model, state, settings)
        if "spinner" not in model.body_name:
            return new, report
        gain = np.sqrt(1.0 + {ENERGY_PER_SECOND} * settings.dt)  # KE grows by 1 % per second
        return State(new.pos, new.quat, new.vel * gain, new.ang_vel * gain, new.time,
                     new.contact_memory), report
    adapter.step = step
    from validation.cli import main
    sys.exit(main(sys.argv[1:]))
    """
)


PLAIN = "import sys; from validation.cli import main; sys.exit(main(sys.argv[1:]))"
"""``physval`` itself, in a subprocess."""


@pytest.fixture
def scenes(tmp_path: Path) -> Path:
    folder = tmp_path / "scenes"
    folder.mkdir()
    (folder / "spin.yaml").write_text(SPIN)
    (folder / "drop.yaml").write_text(DROP)
    return folder


def physval(*args: str, injected: bool = False) -> subprocess.CompletedProcess:
    command = [sys.executable, "-c", INJECTED if injected else PLAIN]
    return subprocess.run(
        [*command, *args], capture_output=True, text=True, timeout=300, check=False
    )


def run(
    scenes: Path, out: Path, *extra: str, injected: bool = False
) -> subprocess.CompletedProcess:
    return physval("run", str(scenes), "--out", str(out), "--jobs", "1", *extra, injected=injected)


def results(folder: Path) -> pd.DataFrame:
    return pd.read_csv(folder / RESULTS_FILE, keep_default_na=False)


def test_known_findings_keep_the_run_green_and_read_known_or_fixed(scenes, tmp_path):
    done = run(scenes, tmp_path / "r0", "--history", "none")
    assert done.returncode == EXIT_OK, done.stdout + done.stderr
    table = results(tmp_path / "r0").set_index(["scenario", "engine", "metric"])
    assert table.loc[("drop", "mini", "penetration_max"), "outcome"] == "known"
    assert table.loc[("drop", "mujoco", "energy_drift"), "outcome"] == "fixed"
    assert "no position correction" in table.loc[("drop", "mini", "penetration_max"), "known"]
    assert "news (no baseline): 0 new failures, 1 fixed, 1 known" in done.stdout, done.stdout


def test_a_baseline_flags_an_injected_regression_on_exactly_its_rows(scenes, tmp_path):
    first = run(scenes, tmp_path / "r1", "--history", "none")
    assert first.returncode == EXIT_OK, first.stderr
    baseline = tmp_path / "baseline.csv"
    saved = physval("baseline", "save", str(tmp_path / "r1"), "--to", str(baseline))
    assert saved.returncode == EXIT_OK, saved.stderr
    # no false alarm: reruns of the unchanged tree against it
    for k in range(3):
        again = run(scenes, tmp_path / f"same{k}", "--baseline", str(baseline), "--history", "none")
        assert again.returncode == EXIT_OK, again.stdout + again.stderr
        classes = set(results(tmp_path / f"same{k}")["baseline"])
        assert classes == {"unchanged"}, classes
    # the injected regression: 1 %/s of energy on the spinner in mini
    broken = run(
        scenes, tmp_path / "broken", "--baseline", str(baseline), "--history", "none", injected=True
    )
    assert broken.returncode == EXIT_FAILED, broken.stdout + broken.stderr
    table = results(tmp_path / "broken")
    regressed = set(
        map(tuple, table[table["baseline"] == "regressed"][["scenario", "engine", "metric"]].values)
    )
    assert regressed == {
        ("spin", "mini", "energy_drift"),
        ("spin", "mini", "angular_momentum_drift"),
    }, regressed
    assert (tmp_path / "broken" / BASELINE_FILE).is_file()
    page = (tmp_path / "broken" / "report.html").read_text()
    assert "Regressions since the baseline: 2" in page, "the report leads with the news"


def test_a_changed_scene_reads_scene_changed_not_regressed(scenes, tmp_path):
    assert run(scenes, tmp_path / "r1", "--history", "none").returncode == EXIT_OK
    baseline = tmp_path / "baseline.csv"
    physval("baseline", "save", str(tmp_path / "r1"), "--to", str(baseline))
    spin = scenes / "spin.yaml"
    spin.write_text(spin.read_text().replace("[0, 0, 5.0]", "[0, 0, 6.0]"))
    done = run(scenes, tmp_path / "r2", "--baseline", str(baseline), "--history", "none")
    assert done.returncode == EXIT_OK, done.stdout + done.stderr
    table = results(tmp_path / "r2")
    assert set(table[table["scenario"] == "spin"]["baseline"]) == {"scene_changed"}
    assert set(table[table["scenario"] == "drop"]["baseline"]) == {"unchanged"}


def test_junit_counts_equal_the_run_and_the_history_records_it(scenes, tmp_path):
    junit = tmp_path / "physval.xml"
    done = run(scenes, tmp_path / "r1", "--junit", str(junit))
    assert done.returncode == EXIT_OK, done.stderr
    table = results(tmp_path / "r1")
    cases = table.groupby(["scenario", "engine"])
    suite = ET.parse(junit).getroot().find("testsuite")
    assert int(suite.get("tests")) == cases.ngroups
    skipped = sum(
        1
        for _, rows in cases
        if (rows["outcome"] == "known").any()
        and not rows["outcome"].isin(["failed", "unstable", "error", "model_mismatch"]).any()
    )
    assert int(suite.get("skipped")) == skipped == 1, ET.tostring(suite)
    assert int(suite.get("failures")) == 0
    assert (tmp_path / "history.sqlite").is_file(), "the default history sits next to --out"
    assert "history run 1" in done.stdout


def test_bad_nightly_flags_exit_2_before_any_work(scenes, tmp_path):
    (tmp_path / "notes.xml").write_text("<mine/>\n")
    for flags, says in (
        (["--baseline", str(tmp_path / "absent.csv")], "--baseline"),
        (["--junit", str(tmp_path / "notes.xml")], "--junit"),  # not physval's: never replaced
        (["--junit", str(tmp_path / "notes.xml" / "x.xml")], "--junit"),
    ):
        done = run(scenes, tmp_path / "out", *flags)
        assert done.returncode == 2, done.stderr
        assert says in done.stderr and "Traceback" not in done.stderr, done.stderr
        assert not (tmp_path / "out").exists(), "nothing is written before the flags are checked"


def test_a_scene_sweep_runs_with_the_scene(tmp_path):
    folder = tmp_path / "scenes"
    folder.mkdir()
    sweep = "sweep: {dt: [0.004, 0.002, 0.001], engines: [mini, mujoco]}\n"
    (folder / "spin.yaml").write_text(
        SPIN.replace("angular_velocity: [0, 0, 5.0]", "angular_velocity: [0.1, 5.0, 0.1]") + sweep
    )
    done = run(folder, tmp_path / "r1", "--history", "none", "--sweeps", "on")
    assert done.returncode == EXIT_OK, done.stdout + done.stderr
    table = results(tmp_path / "r1").set_index(["engine", "metric"])
    order = table.loc[("mini", "sweep_order.orientation_error"), "value"]
    assert abs(float(order)) < 0.3, f"the documented law does not converge on a tumble: {order}"
    assert (tmp_path / "r1" / "sweep.csv").is_file()
    page = (tmp_path / "r1" / "report.html").read_text()
    assert "Error against run time: orientation_error" in page
