"""A small but complete synthetic run folder, for the report's tests (and the CLI's).

``write_synthetic_run(run_dir)`` writes results.csv, series.csv, impacts.csv, trace.csv and
provenance.json with the columns ``physval run`` writes: 2 scenes × 3 engines, with
one failed row, one unstable run, one model_mismatch run, rows without a tolerance,
an unsupported row, a known finding with its reason, rows identically zero without a
tolerance, time series (one ending in non-finite values), impacts, and the traces of the
bodies under test (the ball's z and v_z, the box's body-frame ω) with the scenes'
expectations and descriptions in provenance.json.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

SCENES = ("bounce_ladder", "dzhanibekov_box")
ENGINES = ("mini(gyroscopic=implicit)", "mujoco", "pybullet")
"""Engine spec labels, the reference engine first."""

FAILED = ("bounce_ladder", "mujoco", "restitution_error")
UNSTABLE = ("dzhanibekov_box", "pybullet")
MODEL_MISMATCH = ("bounce_ladder", "pybullet")
KNOWN_REASON = "mujoco's <Euler> integrator damps the flip (measured: one flip fewer)"
"""The reason of the scene's known finding (with markup: the report must escape it)."""
MISMATCH_MESSAGE = "restitution of ball–ground: scenario 0.5, engine 0.45 <clamped>"
"""Carries markup on purpose: the report must escape it."""

PROVENANCE = {
    "command": "physval run scenarios/formulas/bounce_ladder.yaml --out reports/latest",
    "git_commit": "00d4e6e5c1d2b3a4f5e6d7c8b9a0f1e2d3c4b5a6",
    "created": "2025-11-24T21:00:00+00:00",
    "machine": {
        "platform": "Linux-6.1.0-x86_64-with-glibc2.36",
        "python": "3.11.9",
        "processor": "x86_64",
        "cpus": 2,
        "numpy": "2.4.6",
    },
    "scenes": {
        "bounce_ladder": {
            "file": "scenarios/formulas/bounce_ladder.yaml",
            "sha256": "0" * 64,
            "description": "A ball dropped from 1.1 m bounces <twice> with e = 0.5.",
            "expect": [
                {
                    "kind": "bounce_heights",
                    "body": "ball",
                    "metric": "bounce_heights.ball",
                    "value": [0.35, 0.1625],
                },
                {
                    "kind": "velocity_at",
                    "body": "ball",
                    "metric": "velocity_at.ball",
                    "time": 0.2,
                    "value": [0.0, 0.0, -1.962],
                },
            ],
        },
        "dzhanibekov_box": {
            "file": "scenarios/rotation/dzhanibekov_box.yaml",
            "sha256": "1" * 64,
            "description": "A box spun about its intermediate axis flips every 0.9 s.",
            "expect": [
                {"kind": "flips", "body": "box", "metric": "flips.box", "axis": "y", "value": 3},
            ],
        },
    },
    "engines": {
        "mini(gyroscopic=implicit)": {
            "engine": "mini",
            "version": "0.1.0",
            "settings": {"gyroscopic": "implicit", "integrator": "semi_implicit_euler"},
            "notes": ["the documented engine"],
        },
        "mujoco": {
            "engine": "mujoco",
            "version": "3.3.7",
            "settings": {"integrator": "Euler", "cone": "pyramidal"},
            "notes": ["soft contacts: restitution set through solref"],
        },
        "pybullet": {
            "engine": "pybullet",
            "version": "3.2.7",
            "settings": {"profile": "matched"},
            "notes": [],
        },
    },
}


def _row(scene, engine, metric, value, expected, kind, error, tolerance, status="", message=""):
    passed = None if tolerance is None else bool(error <= tolerance)
    if not status:
        status = "failed" if passed is False else "ok"
    dt, steps = (0.001, 2000) if scene == SCENES[0] else (0.0005, 8000)
    return {
        "scenario": scene,
        "engine": engine,
        "metric": metric,
        "value": value,
        "expected": expected,
        "expected_kind": kind,
        "error": error,
        "tolerance": tolerance,
        "passed": passed,
        "status": status,
        "dt": dt,
        "steps": steps,
        "wall_time_s": 0.25,
        "engine_version": PROVENANCE["engines"][engine]["version"],
        "settings": json.dumps(PROVENANCE["engines"][engine]["settings"], sort_keys=True),
        "message": message,
    }


def _status_row(scene, engine, status, message):
    row = _row(scene, engine, "status", None, None, "", None, None, status, message)
    row["error"] = None
    return row


def results_rows() -> list[dict]:
    """The rows of results.csv."""
    bounce, spin = SCENES
    mini, mujoco, pybullet = ENGINES
    return [
        _row(bounce, mini, "energy_drift", 0.002, 0.0, "conserved", 0.002, 0.01),
        _row(bounce, mini, "restitution_error", 1e-9, 0.5, "analytic", 1e-9, 0.01),
        _row(bounce, mini, "bounce_heights.ball", 0.001, 0.0, "analytic", 0.001, 0.005),
        _row(bounce, mini, "penetration_max", 2e-4, None, "", None, None),
        _row(bounce, mini, "velocity_at.ball", 1.962, 1.962, "analytic", 1e-6, 1e-3),
        _row(bounce, mini, "linear_momentum_drift", 0.0, None, "", None, None),
        _row(bounce, mujoco, "linear_momentum_drift", 0.0, None, "", None, None),
        _row(bounce, mujoco, "energy_drift", 0.004, 0.0, "conserved", 0.004, 0.01),
        _row(bounce, mujoco, "restitution_error", 0.08, 0.5, "analytic", 0.08, 0.01),
        _row(bounce, mujoco, "bounce_heights.ball", 0.004, 0.0, "analytic", 0.004, 0.005),
        _row(bounce, mujoco, "divergence", 0.012, None, f"engine:{mini}", None, None),
        _status_row(bounce, pybullet, "model_mismatch", MISMATCH_MESSAGE),
        _row(spin, mini, "energy_drift", 1e-4, 0.0, "conserved", 1e-4, None),  # no tolerance
        _row(spin, mini, "angular_momentum_drift", 2e-5, 0.0, "conserved", 2e-5, 1e-3),
        _row(spin, mini, "flips.box", 3.0, 3.0, "analytic", 0.0, 0.5),
        _row(spin, mujoco, "energy_drift", 3e-4, 0.0, "conserved", 3e-4, 1e-3),
        _row(spin, mujoco, "angular_momentum_drift", 5e-4, 0.0, "conserved", 5e-4, 1e-3),
        {
            **_row(spin, mujoco, "flips.box", 2.0, 3.0, "analytic", 1.0, 0.5),
            "outcome": "known",
            "known": KNOWN_REASON,
        },
        _row(spin, mujoco, "divergence", 0.03, None, f"engine:{mini}", None, None),
        _row(
            spin,
            mujoco,
            "precession_rate.box",
            None,
            1.2,
            "analytic",
            None,
            None,
            "unsupported",
            "no symmetric axis",
        ),
        _status_row(spin, pybullet, "unstable", "state non-finite at t = 0.412 s"),
    ]


def series_frame() -> pd.DataFrame:
    """series.csv: a bouncing ball (mini, mujoco) and a spinning box (mini, mujoco, pybullet
    until it explodes, with a final non-finite sample)."""
    frames = []
    t = np.linspace(0.0, 2.0, 401)
    for engine, loss in zip(ENGINES[:2], (0.0, 0.02), strict=True):
        vz = -9.81 * (t % 0.45) + 2.2
        frames.append(
            pd.DataFrame(
                {
                    "scenario": SCENES[0],
                    "engine": engine,
                    "t": t,
                    "energy": 9.81 * np.exp(-loss * t * 5) - 0.3 * np.floor(t / 0.45),
                    "px": 0.0,
                    "py": 0.0,
                    "pz": vz,
                    "Lx": 0.0,
                    "Ly": 0.0,
                    "Lz": 0.0,
                }
            )
        )
    t = np.linspace(0.0, 4.0, 801)
    for engine, drift in zip(ENGINES, (1e-4, 3e-4, 0.2), strict=True):
        stop = t.size if engine != ENGINES[2] else 104
        tt = t[:stop]
        frame = pd.DataFrame(
            {
                "scenario": SCENES[1],
                "engine": engine,
                "t": tt,
                "energy": 5.0 * (1 + drift * tt * (1 + np.sin(3 * tt))),
                "px": 0.0,
                "py": 0.0,
                "pz": 0.0,
                "Lx": 0.3 * np.cos(2.0 * tt) * (1 + drift * tt),
                "Ly": 0.3 * np.sin(2.0 * tt) * (1 + drift * tt),
                "Lz": 0.4 * (1 + drift * tt),
            }
        )
        if engine == ENGINES[2]:
            frame.loc[frame.index[-1], ["energy", "Lx", "Ly", "Lz"]] = [
                np.inf,
                np.nan,
                np.nan,
                np.inf,
            ]
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def impacts_frame() -> pd.DataFrame:
    """impacts.csv: three bounces of the ball in mini (e exact) and mujoco (e low)."""
    rows = []
    for engine, measured in zip(ENGINES[:2], (0.5, 0.42), strict=True):
        v = 4.43
        for k in range(3):
            rows.append(
                {
                    "scenario": SCENES[0],
                    "engine": engine,
                    "body_a": "ball",
                    "body_b": "ground",
                    "time": 0.45 + 0.9 * k,
                    "e_requested": 0.5,
                    "e_measured": measured,
                    "normal_velocity_before": -v,
                    "normal_velocity_after": measured * v,
                }
            )
            v *= measured
    return pd.DataFrame(rows)


def trace_frame() -> pd.DataFrame:
    """trace.csv: the ball's position and velocity (mini, mujoco), the box's body-frame ω."""
    frames = []
    t = np.linspace(0.0, 2.0, 201)
    for engine in ENGINES[:2]:
        z = 1.1 - 4.905 * t**2
        for quantity, values in (("pos", z), ("vel", -9.81 * t)):
            frames.append(
                pd.DataFrame(
                    {
                        "scenario": SCENES[0],
                        "engine": engine,
                        "body": "ball",
                        "quantity": quantity,
                        "t": t,
                        "x": 0.0,
                        "y": 0.0,
                        "z": values,
                    }
                )
            )
    t = np.linspace(0.0, 4.0, 201)
    for engine in ENGINES[:2]:
        frames.append(
            pd.DataFrame(
                {
                    "scenario": SCENES[1],
                    "engine": engine,
                    "body": "box",
                    "quantity": "body_ang_vel",
                    "t": t,
                    "x": 0.1,
                    "y": 5.0 * np.cos(1.7 * t),
                    "z": 0.1,
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


def write_synthetic_run(run_dir: Path) -> Path:
    """Write results.csv, series.csv, impacts.csv, trace.csv and provenance.json into
    ``run_dir``."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(results_rows()).to_csv(run_dir / "results.csv", index=False)
    series_frame().to_csv(run_dir / "series.csv", index=False)
    impacts_frame().to_csv(run_dir / "impacts.csv", index=False)
    trace_frame().to_csv(run_dir / "trace.csv", index=False)
    (run_dir / "provenance.json").write_text(json.dumps(PROVENANCE, indent=2))
    return run_dir
