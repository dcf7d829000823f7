"""A tour of mini_engine against closed forms: the main job until ``physval run`` lands.

Runs a handful of scenes with the documented formulas and their named options,
compares each measured number with its closed form, prints a table and writes
``reports/tour/mini_engine_tour.csv`` (atomically). Exit code 0 when every
check passed, 1 otherwise.

    python examples/mini_engine_tour.py [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pandas as pd

from mini_engine import Body, Box, Plane, Settings, Sphere, Spring, build_model, step
from mini_engine.quantities import angular_momentum
from mini_engine.rotation import quat_to_matrix

G = 9.81
Row = dict[str, object]


def row(scene, setting, quantity, value, expected, tolerance) -> Row:
    error = abs(value - expected)
    return {
        "scene": scene,
        "setting": setting,
        "quantity": quantity,
        "value": value,
        "expected": expected,
        "error": error,
        "tolerance": tolerance,
        "passed": bool(error <= tolerance),
    }


def free_fall() -> Iterator[Row]:
    """Position error after 1 s against the parabola: -g·dt·t/2 (semi-implicit), +g·dt·t/2 (explicit)."""
    for integrator, sign in (("semi_implicit_euler", -1), ("explicit_euler", 1)):
        model, state = build_model([Body(Sphere(0.1), position=(0, 0, 10))])
        cfg = Settings(dt=1e-3, integrator=integrator)
        for _ in range(1000):
            state, _ = step(model, state, cfg)
        error = state.pos[0, 2] - (10 - 0.5 * G * state.time**2)
        yield row(
            "free_fall", integrator, "z_error_m", error, sign * G * 1e-3 * state.time / 2, 1e-9
        )


def bounce_ladder() -> Iterator[Row]:
    """Measured restitution of every impact of a sphere dropped on the ground from 1 m."""
    for e in (0.1, 0.5, 0.9, 1.0):
        model, state = build_model(
            [Body(Plane(), fixed=True), Body(Sphere(0.1), position=(0, 0, 1), restitution=e)]
        )
        worst = 0.0
        for _ in range(3000):
            state, report = step(model, state, Settings(dt=1e-3))
            if report.contacts.count and report.normal_velocity_before[0] < -0.05:
                measured = -report.normal_velocity_after[0] / report.normal_velocity_before[0]
                worst = max(worst, abs(measured - e))
        yield row("bounce_ladder", f"e={e}", "restitution_error", worst, 0.0, 1e-12)


def stiff_spring() -> Iterator[Row]:
    """Energy growth of an undamped k = 1e6 N/m oscillator over 400 steps (1 = bounded)."""
    for integrator, omega_dt, stable in (
        ("semi_implicit_euler", 1.9, True),
        ("semi_implicit_euler", 2.1, False),
        ("explicit_euler", 0.5, False),
    ):
        model, state = build_model(
            [Body(Sphere(0.01), position=(0.01, 0, 0))],
            springs=[Spring(0, None, stiffness=1e6)],
            gravity=(0, 0, 0),
        )
        cfg = Settings(dt=omega_dt / 1000.0, integrator=integrator)
        peak = 0.0
        for _ in range(400):
            state, _ = step(model, state, cfg)
            peak = max(peak, 0.5 * state.vel[0, 0] ** 2 + 0.5e6 * state.pos[0, 0] ** 2)
        growth = peak / 50.0  # initial energy: ½ k x0² = 50 J
        bounded = float(growth < 1e3)
        yield row(
            "stiff_spring", f"{integrator} w*dt={omega_dt}", "bounded", bounded, float(stable), 0
        )


def dzhanibekov() -> Iterator[Row]:
    """Flips of a box spun near its intermediate axis in 10 s (3 by RK4, engines.md 1.8)."""
    for gyroscopic, flips_expected in (("none", 0), ("explicit", 3), ("implicit", 3)):
        model, state = build_model(
            [
                Body(
                    Box((0.1, 0.1, 0.1)),
                    inertia=(0.016667, 0.033333, 0.043333),
                    angular_velocity=(0.05, 10.0, 0.05),
                )
            ],
            gravity=(0, 0, 0),
        )
        initial = angular_momentum(model, state)[0]
        cfg = Settings(dt=1e-3, gyroscopic=gyroscopic)
        sign, flips, drift = 1.0, 0, 0.0
        for _ in range(10_000):
            state, _ = step(model, state, cfg)
            omega_y = (quat_to_matrix(state.quat)[0].T @ state.ang_vel[0])[1]
            if np.sign(omega_y) != sign:
                flips, sign = flips + 1, np.sign(omega_y)
            drift = max(drift, np.linalg.norm(angular_momentum(model, state)[0] - initial))
        yield row("dzhanibekov", f"gyroscopic={gyroscopic}", "flips", flips, flips_expected, 0)
        yield row(
            "dzhanibekov",
            f"gyroscopic={gyroscopic}",
            "angular_momentum_drift",
            drift / np.linalg.norm(initial),
            0.0,
            0.02 if gyroscopic != "none" else np.inf,
        )


DEMONSTRATIONS: dict[str, Callable[[], Iterator[Row]]] = {
    "free_fall": free_fall,
    "bounce_ladder": bounce_ladder,
    "stiff_spring": stiff_spring,
    "dzhanibekov": dzhanibekov,
}


def write_atomically(table: pd.DataFrame, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    os.close(handle)
    table.to_csv(temporary, index=False)
    os.replace(temporary, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("reports/tour"), help="output folder")
    args = parser.parse_args(argv)
    rows = [r for demo in DEMONSTRATIONS.values() for r in demo()]
    table = pd.DataFrame(rows)
    write_atomically(table, args.out / "mini_engine_tour.csv")
    with pd.option_context("display.width", 140, "display.max_columns", 20):
        print(table.to_string(index=False))
    failed = int((~table["passed"]).sum())
    print(f"{len(table) - failed} passed, {failed} failed -> {args.out / 'mini_engine_tour.csv'}")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
