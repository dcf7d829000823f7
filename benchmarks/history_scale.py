"""The history store and history.html at a year of nightly runs: 365 runs x 1,000 rows.

Writes 365 synthetic run folders (results.csv + provenance.json, the columns ``physval run``
writes: 20 scenes x 5 engine specs x 10 metrics), records each with ``history.record_run`` (one
transaction each) into a fresh SQLite file, then times ``physval history`` rendering the whole
history into history.html (median of ``REPEATS``). Targets: rendering <= 5 s, database
<= 100 MB. The series are like the nightly's: most bit-identical from run to run, some noisy
(round-off across machines), MuJoCo's version changing at run 200 and moving a few of its
series, a few other series stepping at random runs, and the last run carrying baseline classes
(a few ``regressed``). Not a test: wall-clock numbers depend on the machine.

    python benchmarks/history_scale.py [--runs 365] [--keep DIR]

Prints the figures and writes ``benchmarks/results/history_scale.csv``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from validation.contract import PROVENANCE_FILE, RESULTS_COLUMNS, RESULTS_FILE
from validation.nightly.history import record_run
from validation.nightly.history_page import render_history

SCENES = tuple(f"group_{g}/scene_{s:02d}" for g in range(4) for s in range(5))
ENGINES = ("mini", "mini(gyroscopic=implicit)", "mujoco", "mujoco(integrator=RK4)", "pybullet")
METRICS = (
    "energy_drift",
    "momentum_drift",
    "angular_momentum_drift",
    "restitution_error",
    "penetration_max",
    "bounce_heights.ball",
    "position_at.ball",
    "velocity_after_impact.ball",
    "impact_times.ball",
    "cross_engine_divergence",
)
"""20 x 5 x 10 = 1,000 rows per run, names as long as the library's."""

NOISY_FRACTION = 0.1
"""Series that scatter by 0.1 % from run to run (runs from several machines)."""
STEPPING_FRACTION = 0.02
"""Series (beyond MuJoCo's version change) whose error steps by 5 % at a random run."""
VERSION_CHANGE_RUN = 200
"""Run at which MuJoCo 3.2.7 becomes 3.3.0 and moves a tenth of its series."""
REGRESSED_ROWS = 12
"""Rows of the last run whose baseline class is ``regressed``."""

TARGET_SECONDS, TARGET_MEGABYTES = 5.0, 100.0
REPEATS = 3
"""Median of 3 renderings (the shared 2-core machine varies by ~10 %)."""
RESULTS = Path(__file__).parent / "results" / "history_scale.csv"


def synthetic_errors(runs: int, rng: np.random.Generator) -> tuple[np.ndarray, list[dict]]:
    """errors (series, runs) and one dict of fixed columns per series."""
    keys = [
        {"scenario": s, "engine": e, "metric": m} for s in SCENES for e in ENGINES for m in METRICS
    ]
    base = 10.0 ** rng.uniform(-9, -2, len(keys))
    errors = np.repeat(base[:, None], runs, axis=1)
    noisy = rng.random(len(keys)) < NOISY_FRACTION
    errors[noisy] *= 1 + 1e-3 * rng.standard_normal((noisy.sum(), runs))
    for i in np.nonzero(rng.random(len(keys)) < STEPPING_FRACTION)[0]:
        errors[i, rng.integers(1, runs) :] *= 1.05
    mujoco = np.array([k["engine"].startswith("mujoco") for k in keys])
    moved_by_version = mujoco & (rng.random(len(keys)) < 0.1)
    errors[moved_by_version, min(VERSION_CHANGE_RUN, runs - 1) :] *= 1.03
    return errors, keys


def write_folders(root: Path, runs: int, rng: np.random.Generator) -> list[Path]:
    """One run folder per night, oldest first."""
    errors, keys = synthetic_errors(runs, rng)
    tolerance = np.where(rng.random(len(keys)) < 0.8, errors[:, 0] * 20, np.nan)
    folders = []
    for night in range(runs):
        mujoco_version = "3.3.0" if night >= VERSION_CHANGE_RUN else "3.2.7"
        versions = {e: (mujoco_version if e.startswith("mujoco") else "0.1.0") for e in ENGINES}
        table = pd.DataFrame(keys)
        table["value"] = errors[:, night] + 1.0
        table["expected"] = 1.0
        table["expected_kind"] = "analytic"
        table["error"] = errors[:, night]
        table["tolerance"] = tolerance
        table["passed"] = np.where(np.isnan(tolerance), None, errors[:, night] <= tolerance)
        table["status"] = "ok"
        table["dt"], table["steps"], table["wall_time_s"] = 1e-3, 2000, 0.2
        table["engine_version"] = [versions[e] for e in table["engine"]]
        table["settings"], table["message"], table["band"] = "{}", "", 0.0
        table = table.reindex(columns=list(RESULTS_COLUMNS))  # the rest (signed error, ...) empty
        if night == runs - 1:
            table["baseline"] = "unchanged"
            table.loc[rng.choice(len(table), REGRESSED_ROWS, replace=False), "baseline"] = (
                "regressed"
            )
        folder = root / f"run_{night:03d}"
        folder.mkdir()
        table.to_csv(folder / RESULTS_FILE, index=False)
        created = pd.Timestamp("2025-01-01T02:00:00Z") + pd.Timedelta(days=night)
        provenance = {
            "command": "physval run",
            "git_commit": f"{night:040x}",
            "created": created.isoformat(),
            "machine": {"platform": "Linux", "cpus": 2},
            "engines": {e: {"engine": e.split("(")[0], "version": v} for e, v in versions.items()},
        }
        (folder / PROVENANCE_FILE).write_text(json.dumps(provenance))
        folders.append(folder)
    return folders


def main() -> None:
    arguments = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    arguments.add_argument("--runs", type=int, default=365)
    arguments.add_argument("--keep", type=Path, help="keep the database and page in this folder")
    options = arguments.parse_args()
    root = Path(tempfile.mkdtemp(prefix="history-scale-"))
    try:
        folders = write_folders(root, options.runs, np.random.default_rng(12))
        database = root / "history.sqlite"
        url = f"sqlite:///{database}"
        start = time.perf_counter()
        for folder in folders:
            record_run(folder, url)
        record_seconds = (time.perf_counter() - start) / len(folders)
        page = root / "history.html"
        timings = []
        for _ in range(REPEATS):
            start = time.perf_counter()
            render_history(url, page)
            timings.append(time.perf_counter() - start)
        figures = {
            "runs": options.runs,
            "rows_per_run": len(SCENES) * len(ENGINES) * len(METRICS),
            "record_seconds_per_run": round(record_seconds, 4),
            "render_seconds": round(statistics.median(timings), 3),
            "render_target_seconds": TARGET_SECONDS,
            "database_megabytes": round(database.stat().st_size / 1e6, 2),
            "database_target_megabytes": TARGET_MEGABYTES,
            "page_megabytes": round(page.stat().st_size / 1e6, 2),
        }
        if options.keep:
            options.keep.mkdir(parents=True, exist_ok=True)
            shutil.copy(database, options.keep / database.name)
            shutil.copy(page, options.keep / page.name)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    for name, value in figures.items():
        print(f"{name:>28}: {value}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame([figures]).to_csv(RESULTS, index=False)
    print(f"-> {RESULTS}")


if __name__ == "__main__":
    main()
