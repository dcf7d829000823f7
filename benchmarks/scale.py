"""Scenes of 1,000 to 10,000 bodies in every engine: wall time and peak memory.

Scene (``sphere_grid``): N spheres (r = 0.05 m, 1 kg, e = 0.5, frictionless) on a square
grid of ``LAYERS`` layers, ``SPACING`` apart (1 cm gaps), the lowest layer 5 cm above the
ground: it lands at t = 0.10 s and bounces into the layer above, so both sphere-ground and
sphere-sphere impacts happen within the 0.3 s at dt = 2e-3 s (150 steps).

Each (N, engine) runs in its own child process (this file with ``--worker``), the way
``physval run`` runs a job: the scene file written as YAML, loaded and validated
(``load_scenario``), compiled (``compile_scene``), then ``run_job`` (the parity gate, the
recording with every state observed and measured, the metrics). The child reports its
phases' wall times; the parent reads the child's peak RSS from ``os.wait4`` (the
``resource.getrusage`` record of that one child). For MuJoCo it also reports the MJCF's
size, its explicit ``<pair>`` count and the time to build it.

Prints a table and writes ``benchmarks/results/scale.csv``. Not a test: wall-clock numbers
depend on the machine and its load (2 shared cores here).

    python benchmarks/scale.py [--sizes 1000 4000 10000] [--engines mini mujoco pybullet rapier drake]

The duration axis (``--durations``): the same grids run for each duration at dt = 1e-3 s,
peak RSS per (N, duration, engine), against the targets of ``DURATION_TARGETS_MB`` (10,000
spheres for 5 s within 2 GB, 1,000 for 30 s within 1 GB); writes
``benchmarks/results/scale_duration.csv``.

    python benchmarks/scale.py --sizes 200 1000 --durations 1 5 --engines mini
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

SIZES = (1_000, 4_000, 10_000)
ENGINES = (
    "mini",
    "mujoco",
    "pybullet",
    *(("rapier",) if importlib.util.find_spec("rapier3d") is not None else ()),
    *(("drake",) if importlib.util.find_spec("pydrake") is not None else ()),
)
"""Every engine by default; Rapier only when ``rapier3d`` is installed (the ``rapier`` extra),
Drake only when ``pydrake`` is (the ``drake`` extra)."""
RADIUS = 0.05
"""m, every sphere's radius."""
SPACING = 0.11
"""m between neighbouring centres: 1 cm gaps, so neighbours touch only once a layer bounces."""
LAYERS = 4
"""Layers of the grid: 10,000 spheres make a 50 x 50 x 4 block, 5.5 m square."""
LOWEST = 0.10
"""m, the lowest layer's centre height: 5 cm of free fall, landing at t = 0.10 s at 0.99 m/s."""
DT = 2e-3
DURATION = 0.3
"""s: the measured duration (150 steps)."""
TARGET_RSS_MB = 2_000
"""The target: each engine at 10,000 spheres within 2 GB of peak RSS."""
RESULTS = Path(__file__).parent / "results" / "scale.csv"
MEMORY_RESULTS = Path(__file__).parent / "results" / "scale_memory.csv"
DURATION_RESULTS = Path(__file__).parent / "results" / "scale_duration.csv"
DURATION_DT = 1e-3
"""s: the step of the duration axis (``--durations``), the measurement of memory
bounded by the work (5,000 steps for 5 s)."""
DURATION_TARGETS_MB = {(10_000, 5.0): 2_000, (1_000, 30.0): 1_000}
"""(spheres, s) -> MB of peak RSS the duration axis must stay within, every engine."""
MEMORY_DT = 1e-4
"""s: item 4's step, so that 2,000,000 steps (200 s) stay under the scene format's MAX_STEPS."""


def sphere_grid(count: int, duration: float = DURATION, dt: float = DT) -> dict:
    """The benchmark scene of ``count`` spheres run for ``duration`` s at ``dt``, as the YAML
    document's mapping."""
    side = math.ceil(math.sqrt(count / LAYERS))
    bodies = []
    for k in range(count):
        layer, rest = divmod(k, side * side)
        i, j = divmod(rest, side)
        position = [
            round(i * SPACING, 6),
            round(j * SPACING, 6),
            round(LOWEST + layer * SPACING, 6),
        ]
        bodies.append(
            {
                "name": f"s{k}",
                "shape": {"type": "sphere", "radius": RADIUS},
                "mass": 1.0,
                "position": position,
                "restitution": 0.5,
            }
        )
    return {
        "name": f"sphere_grid_{count}",
        "description": "benchmarks/scale.py: a grid of spheres dropping onto the ground",
        "dt": dt,
        "duration": duration,
        "engines": list(ENGINES),
        "ground": {"restitution": 0.5},
        "bodies": bodies,
    }


def ball_drop(steps: int) -> dict:
    """Item 4's scene: one ball dropped from 1 m onto the ground (e = 0.5: it bounces, then
    rests), run for ``steps`` steps of ``MEMORY_DT``."""
    return {
        "name": f"ball_drop_{steps}",
        "dt": MEMORY_DT,
        "duration": steps * MEMORY_DT,
        "engines": list(ENGINES),
        "ground": {"restitution": 0.5},
        "bodies": [
            {
                "name": "ball",
                "shape": {"type": "sphere", "radius": 0.1},
                "mass": 1.0,
                "position": [0.0, 0.0, 1.0],
                "restitution": 0.5,
            }
        ],
    }


def worker(count: int, engine: str, folder: Path, stem: str = "sphere_grid") -> dict:
    """One (N, engine) job in this process; its phases' wall times and what it found."""
    from validation.jobs.run import run_job
    from validation.scenario import load_scenario
    from validation.scenario.compiled import compile_scene
    from validation.scenario.engine_spec import parse_engine_spec

    path = folder / f"{stem}_{count}.yaml"
    start = time.perf_counter()
    scenario = load_scenario(path)
    scene = compile_scene(scenario)
    loaded = time.perf_counter()
    spec = parse_engine_spec(engine)
    extra: dict[str, object] = {}
    if engine == "mujoco":
        from validation.engines.mujoco.adapter import MujocoAdapter
        from validation.engines.mujoco.mjcf import build_mjcf

        built = time.perf_counter()
        xml, plan, _ = build_mjcf(scenario, MujocoAdapter(spec).settings)
        extra = {
            "mjcf_build_s": round(time.perf_counter() - built, 3),
            "mjcf_mb": round(len(xml.encode()) / 1e6, 2),
            "explicit_pairs": len(plan.pairs),
            "touching_pairs": plan.touching_pairs,
        }
        del xml
    ran = time.perf_counter()
    run, measured = run_job((scene, spec))
    done = time.perf_counter()
    return {
        "bodies": len(scenario.bodies),
        "steps": scenario.steps,
        "engine": engine,
        "status": run.status,
        "message": run.message[:120],
        "load_s": round(loaded - start, 2),
        "job_s": round(done - ran, 2),
        "impacts": run.recording.impact_count if run.recording else 0,
        "kept_impacts": len(run.recording.impacts) if run.recording else 0,
        "metrics": len(measured),
        **extra,
    }


def measure(count: int, engine: str, folder: Path, stem: str = "sphere_grid") -> dict:
    """``worker`` in a child process; its peak RSS from ``os.wait4``."""
    start = time.perf_counter()
    child = subprocess.Popen(
        [sys.executable, __file__, "--worker", str(count), engine, str(folder), stem],
        stdout=subprocess.PIPE,
        text=True,
    )
    output = child.stdout.read()
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    row = {"bodies": count, "engine": engine, "status": f"crashed ({child.returncode})"}
    lines = output.strip().splitlines()
    if child.returncode == 0 and lines:
        row = json.loads(lines[-1])
    row["wall_s"] = round(time.perf_counter() - start, 2)
    row["peak_rss_mb"] = round(usage.ru_maxrss / 1024, 1)  # Linux: kilobytes
    return row


def memory_by_duration(step_counts: list[int], engines: list[str]) -> None:
    """Item 4: peak RSS of the one-ball drop at each step count, per engine; flat when the
    memory is bounded by the scene and not by the duration."""
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for steps in step_counts:
            (folder / f"ball_drop_{steps}.yaml").write_text(yaml.safe_dump(ball_drop(steps)))
        for engine in engines:
            for steps in step_counts:
                rows.append(measure(steps, engine, folder, "ball_drop"))
                print(json.dumps(rows[-1]), flush=True)
    table = pd.DataFrame(rows)
    RESULTS.parent.mkdir(exist_ok=True)
    table.to_csv(MEMORY_RESULTS, index=False)
    shown = ["engine", "steps", "status", "job_s", "impacts", "peak_rss_mb"]
    print(table[shown].to_string(index=False))
    print(f"wrote {MEMORY_RESULTS}")


def memory_by_work(sizes: list[int], durations: list[float], engines: list[str]) -> None:
    """The duration axis: peak RSS of the sphere grid of each size run for each duration at
    ``DURATION_DT``, every case in its own child process; flat in the duration when the
    memory is bounded by the work, not by bodies x samples."""
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for duration in durations:
            stem = f"sphere_grid_{duration:g}s"
            for count in sizes:
                scene = sphere_grid(count, duration, DURATION_DT)
                path = folder / f"{stem}_{count}.yaml"
                path.write_text(yaml.safe_dump(scene, default_flow_style=None))
        for duration in durations:
            for count in sizes:
                for engine in engines:
                    row = measure(count, engine, folder, f"sphere_grid_{duration:g}s")
                    row["duration_s"] = duration
                    target = DURATION_TARGETS_MB.get((count, duration))
                    row["target_mb"] = target
                    row["within"] = None if target is None else row["peak_rss_mb"] <= target
                    rows.append(row)
                    print(json.dumps(rows[-1]), flush=True)
    table = pd.DataFrame(rows)
    RESULTS.parent.mkdir(exist_ok=True)
    table.to_csv(DURATION_RESULTS, index=False)
    shown = ["bodies", "duration_s", "engine", "status", "job_s", "peak_rss_mb", "target_mb"]
    print(table[[c for c in shown if c in table]].to_string(index=False))
    print(f"wrote {DURATION_RESULTS}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--engines", nargs="+", default=list(ENGINES))
    parser.add_argument(
        "--memory-steps",
        type=int,
        nargs="+",
        help="instead: item 4, the one-ball drop at these step counts (e.g. 200000 2000000)",
    )
    parser.add_argument(
        "--durations",
        type=float,
        nargs="+",
        help="instead: the duration axis, each --sizes grid run for these durations (s) at "
        f"dt = {DURATION_DT:g} s, e.g. --sizes 1000 10000 --durations 5 30",
    )
    parser.add_argument("--worker", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        count, engine, folder, stem = args.worker
        print(json.dumps(worker(int(count), engine, Path(folder), stem)))
        return
    if args.memory_steps:
        memory_by_duration(args.memory_steps, args.engines)
        return
    if args.durations:
        memory_by_work(args.sizes, args.durations, args.engines)
        return
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for count in args.sizes:
            path = folder / f"sphere_grid_{count}.yaml"
            path.write_text(yaml.safe_dump(sphere_grid(count), default_flow_style=None))
            for engine in args.engines:
                rows.append(measure(count, engine, folder))
                print(json.dumps(rows[-1]), flush=True)
    table = pd.DataFrame(rows)
    RESULTS.parent.mkdir(exist_ok=True)
    table.to_csv(RESULTS, index=False)
    shown = [
        c
        for c in (
            "bodies",
            "engine",
            "status",
            "wall_s",
            "load_s",
            "job_s",
            "peak_rss_mb",
            "mjcf_build_s",
            "mjcf_mb",
            "explicit_pairs",
        )
        if c in table
    ]
    print(table[shown].to_string(index=False))
    worst = table.loc[table.bodies == max(args.sizes), "peak_rss_mb"].max()
    print(f"largest N: worst peak RSS {worst} MB (target {TARGET_RSS_MB} MB); wrote {RESULTS}")


if __name__ == "__main__":
    main()
