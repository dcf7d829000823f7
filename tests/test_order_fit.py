"""The sweep's convergence order is fitted over the asymptotic range only: floor-bound and
saturated points are left out, and too few points give a note, not a number.

The curves are sweep rows as ``sweep_scene`` makes them, on the default grid 1e-2:1e-4:5 (dt
1e-2, 10^-2.5, 1e-3, 10^-3.5, 1e-4 s: half a decade apart); the errors are the issue's and
ones measured by ``physval sweep`` on the bundled scenes (named at each test).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from validation.jobs import sweep

GRID = np.logspace(-2, -4, 5).tolist()
"""s: the sweep's default grid, coarsest first (as ``parse_dt_grid("1e-2:1e-4:5")``)."""

ONE_SECOND = 1.0
"""s: the duration of the issue's scene (its step counts: 100 to 10,000)."""

METRE = 1.0
"""m: the issue's state size (a metre-size state)."""

FOURTH_ORDER_TOLERANCE = 0.01
"""On three points equally spaced in log dt the least-squares slope is the end points',
ln(1.03e-7 / 1.03e-11) / ln(100) = 4 exactly; the issue's errors have three digits (each
within 0.5 %), which moves it by at most 2 x 0.005 / ln(100) = 0.002."""

FIRST_ORDER_TOLERANCE = 0.02
"""A first-order curve measured by a sweep: the Dzhanibekov box's explicit gyroscopic term,
local slopes 1.001 and 1.006 between its three unsaturated points; 0.02 leaves room for the
max-over-time sampling of the errors."""


def curve(errors, metric="position_error", duration=ONE_SECOND, **columns):
    """Sweep rows of one curve on ``GRID`` (status ok), with the fit's per-point columns."""
    return [
        {
            "metric": metric,
            "dt": dt,
            "error": error,
            "status": "ok" if np.isfinite(error) else "unstable",
            "steps": round(duration / dt),
            **columns,
        }
        for dt, error in zip(GRID, errors, strict=True)
    ]


def test_rk4_fits_fourth_order_above_the_round_off_floor():
    """The issue: RK4 errors 1.03e-7, 1.04e-9, 1.03e-11, then 3.5e-12 and 3.7e-12 at round-off
    (5 and 1.7 times their round-off n x 2.2e-16 x 1 m): order 4 over the first three, not the 2.27 of a slope
    through all five."""
    rows = curve([1.03e-7, 1.04e-9, 1.03e-11, 3.5e-12, 3.7e-12], state_size=METRE)
    order = sweep.convergence_order(rows)
    assert abs(order - 4.0) < FOURTH_ORDER_TOLERANCE, f"fitted order {order:.4f}, expected 4"
    fit = sweep.fit_order(rows)
    assert (fit.dt_min, fit.dt_max, fit.points) == (pytest.approx(1e-3), pytest.approx(1e-2), 3), (
        fit
    )
    assert fit.roles == ["fitted"] * 3 + ["floor"] * 2, fit.roles
    assert "fitted over 3 points, dt 0.001 to 0.01 s" in fit.note, fit.note


def test_a_curve_saturating_at_pi_fits_only_its_unsaturated_points():
    """The Dzhanibekov box (10 s) with the explicit gyroscopic term, measured: the flips are
    displaced, 2.6 and 3.14 rad at the two largest steps; the slope through all five was
    0.84."""
    rows = curve([3.14, 2.6, 0.803, 0.252, 0.0796], metric="orientation_error")
    order = sweep.convergence_order(rows)
    assert abs(order - 1.0) < FIRST_ORDER_TOLERANCE, f"fitted order {order:.4f}, expected 1"
    fit = sweep.fit_order(rows)
    assert (fit.dt_min, fit.dt_max, fit.points) == (pytest.approx(1e-4), pytest.approx(1e-3), 3), (
        fit
    )
    assert fit.roles == ["saturated"] * 2 + ["fitted"] * 3, fit.roles


def test_a_curve_at_pi_at_every_dt_has_no_order():
    """The Dzhanibekov box without the gyroscopic term (mini, measured): 3.14 rad at every dt;
    a slope through it (-1.5e-6) is not an order."""
    rows = curve([3.1416, 3.1415, 3.1416, 3.1415, 3.1416], metric="orientation_error")
    order = sweep.convergence_order(rows)
    assert math.isnan(order), f"fitted order {order} through saturated points"
    fit = sweep.fit_order(rows)
    assert fit.note.startswith(sweep.NOT_ASYMPTOTIC), fit.note
    assert fit.roles == ["saturated"] * 5, fit.roles


def test_errors_at_the_references_own_accuracy_have_no_order():
    """MuJoCo RK4 on the Dzhanibekov box (measured): 3.4e-6 at 1e-2 s, then 2.9e-7 at every
    step, which is the DOP853 reference's own error (its cross-check, MuJoCo RK4 at 1e-5 s,
    differs from it by 2.9e-7; DOP853 at rtol 1e-13 differs by 2.7e-7). The slope through all
    five was 0.44."""
    rows = curve(
        [3.41e-6, 3.13e-7, 2.89e-7, 2.88e-7, 2.89e-7],
        metric="orientation_error",
        duration=10.0,
        state_size=2.0,  # rad, as the sweep's orientation rows (``ORIENTATION_STATE_SIZE``)
        reference_floor=2.90e-7,
    )
    order = sweep.convergence_order(rows)
    assert math.isnan(order), f"fitted order {order} through the reference's own error"
    fit = sweep.fit_order(rows)
    assert fit.roles == ["outside"] + ["floor"] * 4, fit.roles
    assert fit.note.startswith(sweep.NOT_ASYMPTOTIC) and "4 floor" in fit.note, fit.note


def test_a_clean_first_order_curve_still_fits_one_over_every_point():
    """Semi-implicit Euler on the projectile (1.5 s, 5 m from the origin), measured: g t dt / 2
    = 7.36 dt m at every dt."""
    rows = curve(
        [7.36e-2, 2.33e-2, 7.36e-3, 2.33e-3, 7.36e-4],
        duration=1.5,
        state_size=5.0,
        motion_extent=5.6,
    )
    order = sweep.convergence_order(rows)
    assert abs(order - 1.0) < FIRST_ORDER_TOLERANCE, f"fitted order {order:.4f}, expected 1"
    fit = sweep.fit_order(rows)
    assert fit.points == 5 and fit.roles == ["fitted"] * 5, fit


def test_a_change_of_slope_ends_the_asymptotic_range():
    """First order at the three smallest steps, then the error grows faster (local slopes 2
    and 3: a scheme near its stability limit): the order is the small steps' 1, not a slope
    through the bend."""
    rows = curve([3e-1, 1e-2, 1e-3, 3.16e-4, 1e-4])
    order = sweep.convergence_order(rows)
    assert abs(order - 1.0) < FIRST_ORDER_TOLERANCE, f"fitted order {order:.4f}, expected 1"
    fit = sweep.fit_order(rows)
    assert fit.roles == ["outside"] * 2 + ["fitted"] * 3, fit.roles


@pytest.mark.parametrize(
    "errors",
    [
        # the stiff spring chain in mini (measured): unstable at the three largest steps;
        # the slope through the other two was -0.68
        [math.inf, math.inf, math.inf, 1.19e-4, 2.61e-4],
        # two first-order points: any two points lie on a line
        [math.nan, math.nan, math.nan, 3.16e-4, 1e-4],
    ],
    ids=["stiff_chain", "two_points"],
)
def test_fewer_than_three_usable_points_give_the_note_not_a_number(errors):
    rows = curve(errors)
    order = sweep.convergence_order(rows)
    assert math.isnan(order), f"fitted order {order} from fewer than 3 points"
    fit = sweep.fit_order(rows)
    assert fit.note.startswith(sweep.NOT_ASYMPTOTIC) and fit.points == 0, fit
