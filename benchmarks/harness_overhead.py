"""What the harness costs on top of the engines' own stepping, per engine, as a ratio.

For each engine (mini, MuJoCo, PyBullet) on the same library scenes (``SCENES``):

1. **whole run**: ``python -m validation.cli run SCENES --engines ENGINE --out TMP`` in a
   subprocess, wall clock (loading, the parity gate, recording with observations and the
   impact detector, metrics, the comparison, the report files), on copies of the scenes
   without their ``sweep:`` (``unswept``): the run itself.
2. **start-up**: the same command on ``STARTUP_SCENE``, one sphere in free fall for one
   step, written to a temporary file: the interpreter, the imports, the engine's own
   import and a (nearly empty) report, none of which grows with the scenes.
3. **stepping only**: each scene loaded, its adapter created and loaded, then
   ``adapter.advance(scenario.steps)`` timed once for the whole duration at the scene's
   dt; the sum over the scenes.

``ratio = (whole - startup) / stepping``; the total is the sum over engines of
``whole - startup`` over the sum of ``stepping``. Target: total <= 1.25.

A scene's ``sweep:`` asks for more engine work than its run: the scene again at every step
of the sweep, and a reference for the order fit (DOP853 and its MuJoCo RK4 cross-check
where nothing can touch). So the sweeps get rows of their own (``engine`` ``ENGINE
sweeps``), never mixed into the run's ratio:

4. **sweeps**: the whole run of the scenes as they are, less the whole run of step 1: what
   the sweeps add to a run.
5. **sweep stepping**: ``advance`` alone of each swept scene at each step of its sweep (the
   engine under test: ``--engines`` replaces a sweep's engines), summed. The rest of a
   sweep's time is the harness's: references, per-point metrics, the order fits.

Each measurement is the median of ``REPEATS`` (the repeats are interleaved engine by
engine, so slow minutes on a shared machine hit every engine alike).

``--tree PATH`` benchmarks another checkout with the same interpreter and packages: every
subprocess gets ``PYTHONPATH=PATH`` and the scenes are PATH's own files; the stepping-only
timing then runs in a subprocess too (this file with ``--stepping-worker``), and imports
the harness's names from the current layout or, failing that, the old one (modules
``validation.scenario``, ``validation.engine_spec``, ``validation.engines``). The
subprocesses run in a scratch folder, not in PATH, so nothing (MuJoCo's MUJOCO_LOG.TXT,
for one) is written into the checkout being measured.

Prints a table and writes ``benchmarks/results/harness_overhead-<tree folder name>.csv``.
Not a test: wall-clock numbers depend on the machine and on its load.

    python benchmarks/harness_overhead.py [--tree PATH] [--scenes FILE ...] [--repeats N]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

HERE_TREE = Path(__file__).resolve().parents[1]
"""The checkout this file belongs to: the default ``--tree``."""

SCENES = (
    "scenarios/formulas/projectile.yaml",
    "scenarios/formulas/bounce_ladder.yaml",
    "scenarios/contact/box_stack.yaml",
    "scenarios/contact/box_drop_flat.yaml",
    "scenarios/rotation/dzhanibekov_box.yaml",
    "scenarios/stiff/stiff_spring_oscillator.yaml",
)
"""Paths relative to the tree: free flight, bounces, resting and dropped boxes, a long
free rotation (10 000 steps) and a stiff spring at dt = 1e-4: 21 000 steps in all, a whole
run of 13 to 26 s per engine on this machine (mini's stepping alone about 16 s)."""

ENGINES = ("mini", "mujoco", "pybullet")
"""Engine specs, as ``--engines`` takes them; each engine's default (matched) profile."""

REPEATS = 3
"""Median of 3: one invocation takes about 4 minutes on the shared 2-core machine when it is
quiet (6 when another job is busy), while a single whole run can be 50 % off under load."""

STARTUP_SCENE = """\
description: start-up probe of benchmarks/harness_overhead.py, one sphere in free fall, one step
dt: 0.001
duration: 0.001
engines: [mini]
bodies:
  - name: ball
    shape: {type: sphere, radius: 0.1}
    mass: 1.0
    position: [0.0, 0.0, 1.0]
"""
"""The trivial workload whose whole run is the start-up: valid in the old and the new
layout; touches nothing, so the impact detector and the metrics have nothing to do."""

RUN_EXIT_CODES = (0, 1)
"""``physval run`` exits 1 when some check failed: still a whole run (PyBullet fails some of
these scenes by design); 2 (bad input) or a crash stops the benchmark."""

SUBPROCESS_TIMEOUT = 600.0
"""s; a whole run of ``SCENES`` takes about 13 to 50 s."""

TARGET_RATIO = 1.25
"""Total (whole - startup) / stepping, the target."""

RESULTS = Path(__file__).parent / "results"


# --- stepping only, in this process (or in a worker subprocess for another tree) -------------


def _harness_api():
    """``(load_scenario, parse_engine_spec, create_adapter)`` from the current layout, or
    from the old one (``validation.scenario`` a module, ``validation.engine_spec``,
    ``create_adapter`` in ``validation/engines/__init__.py``)."""
    from validation.scenario import load_scenario  # package now, module before: same name

    try:
        from validation.scenario.engine_spec import parse_engine_spec
    except ImportError:
        from validation.engine_spec import parse_engine_spec
    try:
        from validation.engines.registry import create_adapter
    except ImportError:
        from validation.engines import create_adapter
    return load_scenario, parse_engine_spec, create_adapter


def _load_adapter(create_adapter, spec, scenario):
    """A loaded adapter for ``scenario``: compiled first in the current layout (``load``
    takes a ``CompiledScene``), the scenario itself in the old one."""
    try:
        from validation.scenario.compiled import compile_scene
    except ImportError:
        loadable = scenario
    else:
        loadable = compile_scene(scenario)
    adapter = create_adapter(spec)
    adapter.load(loadable)
    return adapter


def _advance_seconds(create_adapter, spec, scenario) -> float:
    """Seconds of one ``advance`` over the whole of ``scenario``."""
    adapter = _load_adapter(create_adapter, spec, scenario)
    try:
        start = time.perf_counter()
        adapter.advance(scenario.steps)
        return time.perf_counter() - start
    finally:
        adapter.close()


def _swept(scenario) -> list:
    """The scene at each step of its ``sweep:`` (none without one, or in a layout without
    sweeps); steps out of the sweep's range are left out, as the sweep leaves them."""
    sweep = getattr(scenario, "sweep", None)
    if sweep is None:
        return []
    from validation.jobs.plan import steps_in_range
    from validation.scenario.schema import scene_at

    return [scene_at(scenario, dt) for dt in sweep.dt if steps_in_range(scenario.duration, dt)]


def stepping_seconds(scenes: list[Path], engine: str, sweeps: bool = False) -> float:
    """Seconds spent in ``advance`` alone, summed over ``scenes``, one run of each; with
    ``sweeps``, over each scene at every step of its sweep instead."""
    load_scenario, parse_engine_spec, create_adapter = _harness_api()
    spec = parse_engine_spec(engine)
    total = 0.0
    for path in scenes:
        scenario = load_scenario(path)
        for scene in _swept(scenario) if sweeps else [scenario]:
            total += _advance_seconds(create_adapter, spec, scene)
    return total


def unswept(scenes: list[Path], folder: Path) -> list[Path]:
    """Copies of ``scenes`` in ``folder`` without their ``sweep:`` (same file names; the
    benchmark's scenes name no other file)."""
    folder.mkdir()
    copies = []
    for path in scenes:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
        document.pop("sweep", None)
        copy = folder / path.name
        copy.write_text(yaml.safe_dump(document, sort_keys=False), encoding="utf-8")
        copies.append(copy)
    return copies


# --- subprocesses --------------------------------------------------------------------------------


def _environment(tree: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(tree)}


def _run(command: list[str], tree: Path, scratch: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        command,
        cwd=scratch,
        env=_environment(tree),
        capture_output=True,
        text=True,
        timeout=SUBPROCESS_TIMEOUT,
        check=False,
    )


def _cli_run_prefix(tree: Path, scratch: Path) -> list[str]:
    """``python -m validation.cli run``, plus ``--jobs 1`` where that tree's CLI has it."""
    found = _run([sys.executable, "-m", "validation.cli", "run", "--help"], tree, scratch)
    if found.returncode != 0:
        raise RuntimeError(f"validation.cli run --help failed in {tree}:\n{found.stderr}")
    jobs = ["--jobs", "1"] if "--jobs" in found.stdout else []
    return [sys.executable, "-m", "validation.cli", "run", *jobs]


def whole_run_seconds(
    prefix: list[str], scenes: list[Path], engine: str, tree: Path, scratch: Path
) -> float:
    """Wall-clock seconds of one ``physval run`` of ``scenes`` in ``engine``."""
    out = Path(tempfile.mkdtemp(prefix="run-", dir=scratch))
    command = [*prefix, *map(str, scenes), "--engines", engine, "--out", str(out / "report")]
    start = time.perf_counter()
    done = _run(command, tree, scratch)
    seconds = time.perf_counter() - start
    if done.returncode not in RUN_EXIT_CODES or not (out / "report" / "results.csv").exists():
        raise RuntimeError(f"{' '.join(command)} exited {done.returncode}:\n{done.stderr}")
    return seconds


def worker_stepping_seconds(
    scenes: list[Path], engine: str, tree: Path, scratch: Path, sweeps: bool = False
) -> float:
    """``stepping_seconds`` in a subprocess that imports ``tree``'s harness."""
    command = [sys.executable, __file__, "--stepping-worker", engine, "--scenes", *map(str, scenes)]
    command += ["--sweeps"] if sweeps else []
    done = _run(command, tree, scratch)
    if done.returncode != 0:
        raise RuntimeError(f"stepping worker for {engine} in {tree} failed:\n{done.stderr}")
    return float(json.loads(done.stdout.strip().splitlines()[-1])["seconds"])


# --- the table -----------------------------------------------------------------------------------


KINDS = ("startup", "whole", "stepping", "swept_whole", "sweep_stepping")
"""The measurements of one engine in one repeat (module docstring, steps 1 to 5)."""


def _row(engine: str, whole: float, startup: float, stepping: float) -> dict:
    return {
        "engine": engine,
        "whole_s": whole,
        "startup_s": startup,
        "stepping_s": stepping,
        "harness_s": whole - startup - stepping,
        "ratio": (whole - startup) / stepping if stepping > 0 else float("nan"),
    }


def _total(rows: list[dict], engine: str) -> dict:
    whole, startup, stepping = (
        sum(r[k] for r in rows) for k in ("whole_s", "startup_s", "stepping_s")
    )
    return _row(engine, whole, startup, stepping)


def _rows(samples: dict[str, dict[str, list[float]]]) -> list[dict]:
    """The runs' rows (each engine, then ``total``: the target's), then the sweeps' (a
    sweep's start-up is the run's, already taken off: 0)."""
    runs, sweeps = [], []
    for engine, kinds in samples.items():
        median = {k: statistics.median(v) for k, v in kinds.items()}
        recorded = {f"{k}_samples": " ".join(f"{v:.3f}" for v in kinds[k]) for k in kinds}
        run = _row(engine, median["whole"], median["startup"], median["stepping"])
        runs.append({**run, **recorded})
        if median["sweep_stepping"] > 0:
            added = median["swept_whole"] - median["whole"]
            sweeps.append(_row(f"{engine} sweeps", added, 0.0, median["sweep_stepping"]))
    sweep_total = [_total(sweeps, "sweeps total")] if sweeps else []
    return [*runs, _total(runs, "total"), *sweeps, *sweep_total]


def _measure(engine: str, runs: dict[str, list[Path]], context: dict) -> dict[str, float]:
    """One repeat of ``KINDS`` for ``engine``; ``runs`` names the scene lists (``probe``,
    ``unswept``, ``scenes``), ``context`` the tree, scratch folder and CLI prefix."""
    tree, scratch, prefix = context["tree"], context["scratch"], context["prefix"]

    def whole(scenes: list[Path]) -> float:
        return whole_run_seconds(prefix, scenes, engine, tree, scratch)

    def stepping(sweeps: bool) -> float:
        if tree == HERE_TREE:
            return stepping_seconds(runs["scenes"], engine, sweeps)
        return worker_stepping_seconds(runs["scenes"], engine, tree, scratch, sweeps)

    return {
        "startup": whole(runs["probe"]),
        "whole": whole(runs["unswept"]),
        "stepping": stepping(False),
        "swept_whole": whole(runs["scenes"]),
        "sweep_stepping": stepping(True),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=HERE_TREE, help="checkout to benchmark")
    parser.add_argument(
        "--scenes", nargs="+", default=list(SCENES), help="scene files (relative to the tree)"
    )
    parser.add_argument("--engines", nargs="+", default=list(ENGINES))
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--stepping-worker", metavar="ENGINE", help=argparse.SUPPRESS)
    parser.add_argument("--sweeps", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stepping_worker:  # a subprocess of another tree's run: PYTHONPATH is that tree
        seconds = stepping_seconds(
            [Path(s) for s in args.scenes], args.stepping_worker, args.sweeps
        )
        print(json.dumps({"seconds": seconds}))
        return

    tree = args.tree.resolve()
    scenes = [s if s.is_absolute() else tree / s for s in map(Path, args.scenes)]
    missing = [str(s) for s in scenes if not s.is_file()]
    if missing:
        parser.error(f"no such scene file: {', '.join(missing)}")
    if tree == HERE_TREE:
        sys.path.insert(0, str(tree))
    began = time.perf_counter()
    samples = {e: {k: [] for k in KINDS} for e in args.engines}
    with tempfile.TemporaryDirectory(prefix="harness_overhead-") as name:
        scratch = Path(name)
        probe = scratch / "startup_probe.yaml"
        probe.write_text(STARTUP_SCENE)
        runs = {"probe": [probe], "unswept": unswept(scenes, scratch / "unswept"), "scenes": scenes}
        context = {"tree": tree, "scratch": scratch, "prefix": _cli_run_prefix(tree, scratch)}
        for repeat in range(args.repeats):
            for engine in args.engines:
                for kind, seconds in _measure(engine, runs, context).items():
                    samples[engine][kind].append(seconds)
                print(
                    f"repeat {repeat + 1}/{args.repeats} {engine}: "
                    + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in samples[engine].items()),
                    file=sys.stderr,
                )
    table = pd.DataFrame(_rows(samples))
    table["tree"], table["scenes"], table["repeats"] = str(tree), len(scenes), args.repeats
    table["cli_prefix"] = " ".join(context["prefix"][1:])
    results = RESULTS / f"harness_overhead-{tree.name}.csv"
    results.parent.mkdir(parents=True, exist_ok=True)
    temporary = results.with_suffix(".tmp")
    table.to_csv(temporary, index=False)
    temporary.replace(results)
    shown = table[["engine", "whole_s", "startup_s", "stepping_s", "harness_s", "ratio"]]
    print(f"tree {tree}: {len(scenes)} scenes, median of {args.repeats}")
    print(shown.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    total = table.loc[table["engine"] == "total", "ratio"].iloc[0]
    verdict = "meets" if total <= TARGET_RATIO else "misses"
    print(
        f"total ratio of the runs {total:.2f} {verdict} the target <= {TARGET_RATIO}; "
        f"{time.perf_counter() - began:.0f} s; results in {results}"
    )


if __name__ == "__main__":
    main()
