"""Per-step cost of every library scene in each of its engines, in one run, as mini/MuJoCo ratios.

For every scene of the bundled library (``scenarios/``) and each engine spec its run expands
to (the scene's ``engines:`` list, as ``validation.jobs.plan`` expands it), plus the default
``mini``, ``mujoco`` and ``pybullet`` specs where the scene does not list them (so that every
scene has a ratio), the scene is built and stepped the way a job does it: the spec's adapter
(``validation.engines.registry``) loads the compiled scene, and its ``advance`` steps it
through the scene's whole duration in blocks of the recording's sample interval. Only the
stepping is timed (no parity gate, no recording, no metrics), per step; ``--mode job`` times
the whole job instead (``run_engine``: load, parity gate, recording with its observations
and stability checks, the job's own wall time over its steps). Specs the scene
cannot run (an engine whose declaration lacks a capability the scene needs, or one not
installed) are left out.

Prints the table sorted by the mini/MuJoCo ratio (the plain ``mini`` spec's per-step time
over the plain ``mujoco`` spec's, worst first) and writes
``benchmarks/results/library_cost.csv`` (every spec's time and its ratio to the scene's
plain ``mujoco``). Not a test: the machine is shared, so the ratios, measured in one run,
are what to compare, not the times.

    python benchmarks/library_cost.py [--only GLOB] [--engines mini,mujoco] [--clock cpu]
                                      [--mode step|job]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from validation.engine_api import declaration_of
from validation.engines.registry import create_adapter
from validation.jobs.plan import plan_run
from validation.jobs.run import _sample_every as sample_every
from validation.measure.runner import run_engine
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec, parse_engine_spec
from validation.scenario.needs import missing

LIBRARY = Path(__file__).resolve().parent.parent / "scenarios"
RESULTS = Path(__file__).parent / "results" / "library_cost.csv"

DEFAULT_SPECS = ("mini", "mujoco", "pybullet")
"""The engines every scene is timed in, listed or not: the ratio needs mini and MuJoCo."""

REFERENCE = "mujoco"
"""The spec every ratio divides by."""

TARGET_RATIO = 5.0
"""mini's per-step time may be at most this many times MuJoCo's on every library scene."""

CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
"""``--clock``: wall time, or this process's CPU time (steadier on a shared machine; every
engine steps single-threaded here)."""


def timed_specs(listed: list[EngineSpec]) -> list[EngineSpec]:
    """The scene's listed specs, then the ``DEFAULT_SPECS`` it does not list."""
    specs = list(listed)
    for text in DEFAULT_SPECS:
        spec = parse_engine_spec(text)
        if spec not in specs:
            specs.append(spec)
    return specs


def runnable(scene: CompiledScene, spec: EngineSpec) -> bool:
    """The spec's engine is installed and declares every capability the scene needs."""
    try:
        capabilities = declaration_of(spec.name).capabilities_of(spec.as_dict())
    except Exception:  # an engine that is not installed or not declared: left out
        return False
    return not missing(capabilities, scene.scenario)


def seconds_per_step(scene: CompiledScene, spec: EngineSpec, clock) -> tuple[float, int]:
    """Seconds per step of ``spec`` stepping ``scene`` through its duration, and the steps."""
    steps = scene.scenario.steps
    block = sample_every(scene)  # the recording advances in blocks of its sample interval
    adapter = create_adapter(spec)
    try:
        adapter.load(scene)
        done = 0
        with np.errstate(over="ignore", invalid="ignore"):
            start = clock()
            while done < steps:
                count = min(block, steps - done)
                adapter.advance(count)
                done += count
            elapsed = clock() - start
    finally:
        adapter.close()
    return elapsed / steps, steps


def job_seconds_per_step(scene: CompiledScene, spec: EngineSpec, clock) -> tuple[float, int]:
    """Seconds per step of the whole job of ``spec`` on ``scene`` (``run_engine`` as a run's
    job calls it: load, parity gate, recording), and the steps."""
    steps = scene.scenario.steps
    start = clock()
    run_engine(scene, spec, sample_every(scene), keep="positions")
    return (clock() - start) / steps, steps


MODES = {"step": seconds_per_step, "job": job_seconds_per_step}
"""``--mode``: what is timed, the adapter's stepping alone or the whole job."""


def measure(
    paths: list[Path], only: str | None, engines: set[str] | None, clock, timer=seconds_per_step
) -> pd.DataFrame:
    """One row per (scene, spec) timed by ``timer`` (a ``MODES`` value)."""
    plan = plan_run(paths, None, None, only)
    rows = []
    for scene, listed in plan.scenes:
        for spec in timed_specs(listed):
            if engines is not None and spec.label not in engines:
                continue
            if not runnable(scene, spec):
                continue
            cost, steps = timer(scene, spec, clock)
            rows.append(
                {
                    "scene": scene.name,
                    "engine": spec.label,
                    "steps": steps,
                    "bodies": len(scene.scenario.bodies),
                    "ms_per_step": cost * 1e3,
                }
            )
            print(f"  {scene.name:40s} {spec.label:40s} {cost * 1e3:9.4f} ms/step", flush=True)
    table = pd.DataFrame(rows)
    reference = table[table.engine == REFERENCE].set_index("scene").ms_per_step
    table["ratio_to_mujoco"] = table.ms_per_step / table.scene.map(reference)
    return table


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per scene: plain mini, plain MuJoCo and plain PyBullet ms/step and mini/MuJoCo, worst first."""
    wide = table.pivot(index="scene", columns="engine", values="ms_per_step")
    out = pd.DataFrame(
        {
            "mini_ms": wide.get("mini"),
            "mujoco_ms": wide.get("mujoco"),
            "pybullet_ms": wide.get("pybullet"),
        }
    )
    out["mini_over_mujoco"] = out.mini_ms / out.mujoco_ms
    out["over_target"] = out.mini_over_mujoco > TARGET_RATIO
    return out.sort_values("mini_over_mujoco", ascending=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", type=Path, default=[LIBRARY])
    parser.add_argument("--only", help="only scenes whose name or path matches this glob")
    parser.add_argument("--engines", help="comma-separated spec labels to time (default all)")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall")
    parser.add_argument("--mode", choices=sorted(MODES), default="step")
    parser.add_argument("--out", type=Path, default=None, help=f"default {RESULTS}")
    args = parser.parse_args()
    engines = None
    if args.engines:
        engines = {parse_engine_spec(t.strip()).label for t in args.engines.split(",")}
    table = measure(args.paths, args.only, engines, CLOCKS[args.clock], MODES[args.mode])
    table["numpy_version"] = np.__version__
    table["clock"], table["mode"] = args.clock, args.mode
    if args.out is None:
        args.out = RESULTS if args.mode == "step" else RESULTS.with_name("library_cost_job.csv")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    temporary = args.out.with_suffix(".tmp")
    table.to_csv(temporary, index=False)
    temporary.replace(args.out)
    with pd.option_context("display.width", 160, "display.max_rows", 500):
        print(summary(table).to_string(float_format=lambda v: f"{v:.4g}"))
    over = summary(table).over_target.sum()
    print(f"{over} scene(s) with mini > {TARGET_RATIO:g}x MuJoCo per step; results in {args.out}")


if __name__ == "__main__":
    main()
