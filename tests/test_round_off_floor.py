"""A sweep curve is "at round-off" only when every error is within its own point's measured
round-off (the quantity's size x epsilon x steps), never below a fixed cutoff: clean fourth-order
convergence at 1e-10 is an order, not round-off (issue 34, item 9). The floor is on the page."""

from __future__ import annotations

import math

import numpy as np
import pytest

from validation.jobs import sweep
from validation.report.sweep_page import render_sweep

HALVINGS = [1e-2 / 2**k for k in range(4)]
"""s: a grid of halvings, 1e-2 to 1.25e-3."""

RK4_ERRORS = [2.7e-10 / 16**k for k in range(4)]
"""m: the issue's MuJoCo RK4 curve, 2.7e-10 down to 6.6e-14, 16x per halving (order 4)."""

STATE_SIZE = 1.0
"""m: a metre-size state: round-off 100 to 800 steps x 2.2e-16 x 1 m = 2.2e-14 to 1.8e-13."""

ORDER_TOLERANCE = 1e-9
"""The errors are exact powers of 16 per halving: the slope is 4 to round-off."""


def curve(errors, size=STATE_SIZE, duration=1.0) -> list[dict]:
    return [
        {
            "metric": "position_error",
            "dt": dt,
            "error": error,
            "status": "ok",
            "steps": round(duration / dt),
            "state_size": size,
        }
        for dt, error in zip(HALVINGS, errors, strict=True)
    ]


def test_clean_fourth_order_below_a_nanometre_is_an_order_not_round_off():
    rows = curve(RK4_ERRORS)
    fit = sweep.fit_order(rows)
    assert not fit.note.startswith(sweep.AT_ROUND_OFF), fit.note
    assert fit.order == pytest.approx(4.0, abs=ORDER_TOLERANCE), fit
    # the smallest step's 6.6e-14 is within ten times its round-off (1.8e-13): left out
    assert fit.roles == ["fitted"] * 3 + ["floor"], fit.roles


def test_errors_within_their_round_off_are_at_round_off_and_the_note_says_how_much():
    """MuJoCo RK4 on the projectile, exact but for rounding: 0.14 to 0.26 of its round-off."""
    rows = curve([0.2 * sweep.round_off(r) for r in curve(RK4_ERRORS)])
    fit = sweep.fit_order(rows)
    assert math.isnan(fit.order)
    assert fit.note.startswith(sweep.AT_ROUND_OFF), fit.note
    largest = max(sweep.round_off(r) for r in rows)
    assert f"at most {largest:.3g}" in fit.note, fit.note
    assert set(fit.roles) == {"floor"}


def test_the_round_off_scales_with_the_quantitys_size():
    """The same errors on a state a million times larger are round-off there."""
    assert not sweep.fit_order(curve(RK4_ERRORS)).note.startswith(sweep.AT_ROUND_OFF)
    huge = sweep.fit_order(curve(RK4_ERRORS, size=1e6))
    assert huge.note.startswith(sweep.AT_ROUND_OFF), huge.note


def test_the_page_lists_each_points_round_off(tmp_path):
    rows = curve(RK4_ERRORS)
    fit = sweep.mark_points(rows)
    assert [r["round_off"] for r in rows] == [sweep.round_off(r) for r in rows]
    assert rows[0]["round_off"] == pytest.approx(100 * np.finfo(float).eps)
    table = [
        {
            **r,
            "scenario": "rk4",
            "engine": "mujoco(integrator=RK4)",
            "expected_kind": "analytic",
            "wall_time_s": 1.0,
        }
        for r in rows
    ]
    table.append(
        {
            "scenario": "rk4",
            "engine": "mujoco(integrator=RK4)",
            "metric": "convergence_order",
            "of": "position_error",
            "expected_kind": "analytic",
            **sweep.fit_row(fit),
        }
    )
    page = render_sweep(table, tmp_path / "sweep.html").read_text()
    assert "round_off" in page
    assert f"{rows[-1]['round_off']:.4g}" in page
