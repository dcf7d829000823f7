"""The float32 resolution floor: a float32 engine's row whose error is what float32 rounding
alone reaches passes by it and is marked so in its message and the report (never for a float64
engine, never for a row beyond the floor)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from validation.cli import main
from validation.measure.resolution import (
    FLOAT32_UNIT_ROUNDOFF,
    RESOLUTION_MARK,
    resolution_floor,
    resolution_note,
)

REPOSITORY = Path(__file__).resolve().parent.parent


def test_the_floor_counts_every_rounding_of_a_carried_value():
    # 1,500 steps x 4 substeps, each rounding 3.5 m/s by up to half an ulp
    floor = resolution_floor("velocity_at.ball", 3.5037, 3.5037, 1500, 4)
    assert floor == pytest.approx(1500 * 4 * FLOAT32_UNIT_ROUNDOFF * 3.5037), floor


def test_a_constant_increment_summed_in_float32_reaches_but_stays_within_the_floor():
    """What the floor bounds, measured: x += v·h in float32, 6,000 times (a body moving at
    3.5 m/s, 1,500 steps of 4 substeps of 0.25 ms), against the exact sum."""
    steps, substeps, speed, h = 1500, 4, 3.5, 2.5e-4
    position = np.float32(0.0)
    for _ in range(steps * substeps):
        position = np.float32(position + np.float32(speed * h))
    exact = steps * substeps * speed * h
    error = abs(float(position) - exact)
    floor = resolution_floor("position_at.ball", float(position), exact, steps, substeps)
    assert 0 < error <= floor, (error, floor)


@pytest.mark.parametrize(
    ("metric", "error", "marked"),
    [
        ("velocity_at.ball", 1e-4, True),
        ("velocity_at.ball", 1e-2, False),  # beyond what rounding reaches: physics
        ("energy_drift", 5e-7, True),
        ("energy_drift", 5e-6, False),
        ("restitution_error", 1e-9, False),  # no floor for an impact's e
        ("flips.box", 1.0, False),
    ],
)
def test_only_errors_within_the_floor_are_marked(metric, error, marked):
    note = resolution_note(metric, 3.5, 3.5, error, 1500, 4)
    assert note.startswith(RESOLUTION_MARK) is marked, note


@pytest.mark.skipif(
    importlib.util.find_spec("rapier3d") is None,
    reason='rapier3d is not installed (pip install "physval[rapier]")',
)
def test_a_float32_engines_rows_are_marked_and_a_float64_engines_are_not(tmp_path):
    out = tmp_path / "out"
    code = main(
        ["run", str(REPOSITORY / "scenarios/formulas/projectile.yaml"), "--engines",
         "mini,rapier", "--out", str(out), "--history", "none", "--baseline", "none",
         "--jobs", "1"]
    )  # fmt: skip
    assert code in (0, 1)
    rows = pd.read_csv(out / "results.csv", keep_default_na=False).set_index(["engine", "metric"])
    rapier = rows.loc[("rapier", "velocity_at.ball")]
    assert rapier["status"] == "ok" and rapier["message"].startswith(RESOLUTION_MARK), dict(
        rapier
    )  # within the float32 band: passes, marked (test_precision_band.py)
    marked = rows[rows["message"].str.startswith(RESOLUTION_MARK)]
    assert set(marked.index.get_level_values("engine")) == {"rapier"}, marked
    report = (out / "report.html").read_text()
    assert 'class="f32"' in report
