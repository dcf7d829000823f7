"""The spread of every library row under a perturbed initial state: what the noise rule's floors
are derived from (``validation.measure.noise``).

One machine's runs are bit-identical, so a baseline saved on the machine that compares against it
sees no noise at all; another machine (CPU, BLAS, compiler, thread count) rounds differently,
and a scene amplifies that round-off as far as its dynamics do. This benchmark stands in for
another machine: it runs the library once as it is, then ``--repeats`` times with every moving
body's initial position moved by ``--perturbation`` metres (default 1e-12 m, some 10^4 ulps of
a metre-scale position: more than one machine's round-off differs from another's in one step),
each time in another seeded direction. The perturbation is applied here, to the loaded scenes
before they are compiled; the library and ``physval run`` never perturb anything.

Per row it reports the spread ``max |x_k - x_0|`` over the perturbed runs ``k`` of the number
the noise rule judges (the error, or the value of a row that has no error) and its relative
spread (over ``max |x|``), then per scene the largest relative spread and the largest absolute
spread of rows whose number is 0 or tiny (``TINY``).

    python benchmarks/noise_spread.py [--engines mini] [--repeats 2] [--perturbation 1e-12]
                                      [--spin] [--only GLOB] [--jobs 2] [--tag SUFFIX]

Prints the per-scene table and writes ``benchmarks/results/noise_spread.csv`` (per row) and
``benchmarks/results/noise_spread_scenes.csv`` (per scene), each name ending in ``--tag``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from validation.cli import BUNDLED_SCENARIOS
from validation.jobs.nightly_run import sweep_result_rows
from validation.jobs.plan import Plan, plan_run
from validation.jobs.run import execute
from validation.scenario.compiled import compile_scene

RESULTS = Path(__file__).resolve().parent / "results"
KEY = ["scenario", "engine", "metric"]

TINY = 1e-9
"""A judged number below this (in its SI unit) is read as 'zero up to round-off': its spread is
an absolute one (what ``noise.ABSOLUTE_NOISE`` covers), not a relative one."""


def _moved(vector, size: float, rng: np.random.Generator) -> tuple[float, ...]:
    direction = rng.normal(size=3)
    moved = np.asarray(vector, dtype=float) + size * direction / np.linalg.norm(direction)
    return tuple(float(x) for x in moved)


def perturbed(plan: Plan, size: float, seed: int, spin: bool = False) -> Plan:
    """``plan`` with every moving body's initial position moved by ``size`` m in a random
    direction (seeded), and with ``spin`` its angular velocity by ``size`` rad/s too (a
    position alone leaves a free body's rotation untouched), each scene compiled again."""
    rng = np.random.default_rng(seed)
    scenes = []
    for scene, specs in plan.scenes:
        scenario = scene.scenario
        bodies = []
        for body in scenario.bodies:
            if body.fixed:
                bodies.append(body)
                continue
            update = {"position": _moved(body.position, size, rng)}
            if spin:
                update["angular_velocity"] = _moved(body.angular_velocity, size, rng)
            bodies.append(body.model_copy(update=update))
        scenes.append((compile_scene(scenario.model_copy(update={"bodies": bodies})), specs))
    return Plan(scenes)


def library_rows(plan: Plan, jobs: int) -> pd.DataFrame:
    """Every row a nightly ``physval run`` of ``plan`` writes (the sweeps' rows included)."""
    executed = execute(plan, jobs)
    rows = pd.DataFrame([*executed.rows, *sweep_result_rows(executed.sweep_rows)])
    judged = rows["error"].astype(float).where(rows["error"].notna(), rows["value"])
    return rows.assign(judged=judged.astype(float))[[*KEY, "value", "error", "judged"]]


def spread(base: pd.DataFrame, others: list[pd.DataFrame]) -> pd.DataFrame:
    """Per row: the plain run's judged number, the largest |change| over the perturbed runs,
    its relative size, and whether the row changed class (finite / inf / NaN)."""
    table = base.set_index(KEY)
    changes, scales, kinds = [], [], []
    for other in others:
        x = other.set_index(KEY)["judged"].reindex(table.index)
        with np.errstate(invalid="ignore"):
            changes.append(
                np.where(
                    np.isfinite(x) & np.isfinite(table["judged"]),
                    np.abs(x - table["judged"]),
                    np.nan,
                )
            )
        scales.append(np.maximum(np.abs(x), np.abs(table["judged"])))
        kinds.append(np.isfinite(x) != np.isfinite(table["judged"]))
    absolute = np.nanmax(np.vstack(changes), axis=0) if others else np.nan
    scale = np.nanmax(np.vstack(scales), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        relative = np.where(scale > TINY, absolute / scale, np.nan)
    return table.assign(
        spread=absolute,
        relative=relative,
        tiny=scale <= TINY,
        class_changed=np.any(np.vstack(kinds), axis=0),
    ).reset_index()


def per_scene(rows: pd.DataFrame) -> pd.DataFrame:
    """Per scene: rows, the largest relative spread (and its row), the largest absolute spread
    of tiny rows, rows whose class (finite / inf / NaN) changed."""
    found = []
    for scene, group in rows.groupby("scenario", sort=True):
        relative = group["relative"].dropna()
        tiny = group.loc[group["tiny"], "spread"].dropna()
        worst = group.loc[relative.idxmax()] if len(relative) else None
        found.append(
            {
                "scenario": scene,
                "rows": len(group),
                "max_relative": float(relative.max()) if len(relative) else np.nan,
                "worst_row": "" if worst is None else f"{worst['engine']} {worst['metric']}",
                "max_absolute_tiny": float(tiny.max()) if len(tiny) else np.nan,
                "class_changed": int(group["class_changed"].sum()),
            }
        )
    return pd.DataFrame(found).sort_values("max_relative", ascending=False, na_position="last")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--engines", default="mini")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--perturbation", type=float, default=1e-12)
    parser.add_argument("--only", default=None)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--spin", action="store_true", help="perturb angular velocities too")
    parser.add_argument("--tag", default="", help="suffix of the result files")
    args = parser.parse_args()
    start = time.perf_counter()
    plan = plan_run([BUNDLED_SCENARIOS], args.engines, None, args.only)
    base = library_rows(plan, args.jobs)
    others = [
        library_rows(perturbed(plan, args.perturbation, seed, args.spin), args.jobs)
        for seed in range(1, args.repeats + 1)
    ]
    rows = spread(base, others)
    scenes = per_scene(rows)
    RESULTS.mkdir(exist_ok=True)
    rows.to_csv(RESULTS / f"noise_spread{args.tag}.csv", index=False)
    scenes.to_csv(RESULTS / f"noise_spread_scenes{args.tag}.csv", index=False)
    with pd.option_context("display.width", 200, "display.max_rows", 200):
        print(scenes.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    finite = rows["relative"].dropna()
    print(
        f"{len(rows)} rows, engines {args.engines}, perturbation {args.perturbation:g} m x "
        f"{args.repeats}: median relative spread {finite.median():.3g}, max {finite.max():.3g}; "
        f"max absolute spread of tiny rows {rows.loc[rows['tiny'], 'spread'].max():.3g}; "
        f"{int(rows['class_changed'].sum())} rows changed class; "
        f"{time.perf_counter() - start:.0f} s"
    )


if __name__ == "__main__":
    main()
