"""The library's power: does a nightly run catch every realistic bug in mini_engine?

For the bundled scenes (``scenarios/``; by default their mini specs only, ``--all-engines``
for every engine: the sabotages are in mini, so the other engines' rows cannot move but
through their ``divergence`` from mini):

1. **baseline**: ``physval run SCENES --jobs N --baseline none`` on the real engine, then
   ``physval baseline save`` of that run (it must have 0 new failures);
2. **false alarms**: ``--reruns`` (3) unchanged runs against that baseline: every row that
   reads ``regressed`` or is a new failure is a false alarm (target 0);
3. **one run per sabotage** (``validation/engines/sabotage.py``; ``PHYSVAL_SABOTAGE=<name>``
   in the run's environment, so every worker process inherits it) against the baseline, on the
   fast tier of scenes, then on the slow tier (``SLOW_SCENES``) only if the fast one caught
   nothing plainly. One run answers both questions: **caught plainly** = its failing rows that
   are not known findings (what a run without a baseline reports as new failures: the
   library's plain run has none), **caught by the baseline** = its rows that read
   ``regressed``. Every mini row must carry the sabotage's version mark.

Prints the catch table (sabotage, what it breaks, where, the scenes that caught it plainly and
by the baseline) and the total time, and writes ``benchmarks/results/mutation_score.csv``.
Target: every sabotage caught plainly or by the baseline, 0 false alarms. CPU heavy: about
4 library runs and a fifth of one per sabotage (a few minutes per library run on 2 cores).

The mini-only scene copies (``mini_only``) keep each scene's mini specs (the plain mini and its
variants: ``mini(gyroscopic=implicit)``, ...), their known findings and sweeps, and drop the
other engines, their findings and the ``divergence`` checks (a scene left with mini alone has
no second engine to diverge from; mini's variants diverge from mini by design).

    python benchmarks/mutation_score.py [--sabotages NAME ...] [--only GLOB] [--skip GLOB ...]
                                        [--jobs 2] [--reruns 3] [--all-engines]
                                        [--work DIR [--resume]]
"""

from __future__ import annotations

import argparse
import fnmatch
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from validation.engines.sabotage import SABOTAGE_VARIABLE, SABOTAGES, VERSION_MARK  # noqa: E402
from validation.nightly.baseline import FAILING  # noqa: E402
from validation.scenario.schema import DEFAULT_ENGINES  # noqa: E402

SCENES = ROOT / "scenarios"
"""The library: every bundled scene."""

RESULTS = ROOT / "benchmarks" / "results" / "mutation_score.csv"
"""Where the catch table is written."""

DEFAULT_RERUNS = 3
"""Unchanged reruns against the baseline that must raise no alarm (the target)."""

SHOWN_SCENES = 4
"""Scenes named per cell of the printed table (the CSV has them all)."""

SLOW_SCENES = (
    "simbenchmark_666_pile",
    "box_stack",
    "deep_initial_penetration",
    "gazebo_boxes_complex",
    "gazebo_boxes_simple",
    "dzhanibekov_box",
    "stable_major_axis_spin",
    "torque_free_symmetric_top",
)
"""Scenes whose mini jobs took 10 s or more together in a library run on this 2-core machine
(measured: 84, 29, 38, 20, 6, 18, 16 and 10 s of 264 s for all mini jobs): the slow tier. A
sabotage runs in the fast tier (the other scenes, 43 s) and in the slow tier only when the
fast tier caught nothing plainly, so the catch table costs about a fifth of full runs; its
plainly-caught rows then name the fast tier's catching scenes only."""


# --- the scenes ---------------------------------------------------------------------------


def is_mini(spec: str) -> bool:
    """Whether an engine spec (``mini``, ``mini(gyroscopic=implicit)``) is one of mini's."""
    return spec.split("(")[0].strip() == "mini"


def library_copy(source: Path, target: Path, skip: list[str], all_engines: bool) -> None:
    """A copy of every scene under ``source`` in ``target`` but those whose path matches a
    ``skip`` glob, with mini's specs only (``mini_only``) unless ``all_engines``."""
    for path in sorted(source.rglob("*.yaml")):
        if any(fnmatch.fnmatch(str(path.relative_to(source)), glob) for glob in skip):
            continue
        scene = yaml.safe_load(path.read_text())
        if not all_engines:
            scene = mini_only(scene)
        if scene is None:
            continue
        copy = target / path.relative_to(source)
        copy.parent.mkdir(parents=True, exist_ok=True)
        copy.write_text(yaml.safe_dump(scene, sort_keys=False, allow_unicode=True))


def mini_only(scene: dict) -> dict | None:
    """The scene with mini's specs only (module docstring); None without a mini spec."""
    engines = [e for e in scene.get("engines", DEFAULT_ENGINES) if is_mini(e)]
    if not engines:
        return None
    scene["engines"] = engines
    known = [
        k
        for k in scene.get("known", [])
        if is_mini(k["engine"]) and k.get("metric") != "divergence"
    ]
    scene.pop("known", None)
    if known:
        scene["known"] = known
    checks = scene.get("checks", {})
    checks.pop("divergence", None)
    for metric, tolerance in checks.items():
        if isinstance(tolerance, dict):
            checks[metric] = {k: v for k, v in tolerance.items() if k == "default" or k in engines}
    sweep = scene.get("sweep")
    if sweep and sweep.get("engines"):
        sweep["engines"] = [e for e in sweep["engines"] if is_mini(e)]
        if not sweep["engines"]:
            scene.pop("sweep")
    return scene


# --- running the library --------------------------------------------------------------------


def physval(*arguments: str, sabotage: str | None = None, cwd: Path) -> int:
    """``physval ARGUMENTS`` in a subprocess (this checkout's code), with the sabotage in its
    environment; returns the exit code (0 clean, 1 regressed or new failure, 2 bad input)."""
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    environment.pop(SABOTAGE_VARIABLE, None)
    if sabotage:
        environment[SABOTAGE_VARIABLE] = sabotage
    command = [sys.executable, "-m", "validation.entry", *arguments]
    done = subprocess.run(command, cwd=cwd, env=environment, capture_output=True, text=True)
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(arguments)} exited {done.returncode}: {done.stderr.strip()}")
    return done.returncode


def run_library(
    paths: list[Path], out: Path, args, baseline: Path | None, sabotage: str | None = None
) -> pd.DataFrame:
    """One library run of the scene files ``paths`` into ``out``; its results.csv (with
    ``--resume``, a finished run already in ``out`` is read instead)."""
    if not (args.resume and (out / "results.csv").exists()):
        selection = ["--only", args.only] if args.only else []
        physval(
            "run",
            *map(str, paths),
            *selection,
            "--jobs",
            str(args.jobs),
            "--out",
            str(out),
            "--baseline",
            str(baseline) if baseline else "none",
            "--history",
            "none",
            sabotage=sabotage,
            cwd=out.parent,
        )
    return pd.read_csv(out / "results.csv", keep_default_na=False)


def tiers(scenes: Path) -> tuple[list[Path], list[Path]]:
    """The copied scene files split into the fast tier and the slow one (``SLOW_SCENES``)."""
    files = sorted(scenes.rglob("*.yaml"))
    slow = [f for f in files if f.stem in SLOW_SCENES]
    return [f for f in files if f.stem not in SLOW_SCENES], slow


def sabotaged_runs(name: str, fast, slow, work: Path, args, baseline: Path):
    """A sabotage's results: the fast tier, then the slow one only if the fast tier caught
    nothing plainly; and whether the slow tier ran."""
    results = run_library(fast, work / name, args, baseline, sabotage=name)
    if len(new_failures(results)) or not slow:
        return results, False
    more = run_library(slow, work / f"{name}-slow", args, baseline, sabotage=name)
    return pd.concat([results, more], ignore_index=True), True


def new_failures(results: pd.DataFrame) -> pd.DataFrame:
    """Failing rows that are not known findings (what a plain run reports as new failures)."""
    return results[results["outcome"].isin(FAILING)]


def regressions(results: pd.DataFrame) -> pd.DataFrame:
    """Rows that read ``regressed`` against the baseline."""
    return results[results["baseline"] == "regressed"]


def scenes_of(rows: pd.DataFrame) -> list[str]:
    return sorted(set(rows["scenario"]))


def named(scenes: list[str]) -> str:
    if not scenes:
        return "-"
    shown = ", ".join(scenes[:SHOWN_SCENES])
    more = len(scenes) - SHOWN_SCENES
    return f"{len(scenes)}: {shown}" + (f" +{more}" if more > 0 else "")


# --- the benchmark --------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sabotages", nargs="*", choices=sorted(SABOTAGES), default=None)
    parser.add_argument("--only", default=None, help="only scenes matching (physval run --only)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--reruns", type=int, default=DEFAULT_RERUNS)
    parser.add_argument("--all-engines", action="store_true", help="every engine of each scene")
    parser.add_argument(
        "--skip", action="append", default=[], metavar="GLOB", help="leave out scenes (path glob)"
    )
    parser.add_argument("--work", type=Path, default=None, help="folder for the runs (kept)")
    parser.add_argument(
        "--resume", action="store_true", help="reuse the finished runs already in --work"
    )
    args = parser.parse_args()
    names = args.sabotages if args.sabotages is not None else list(SABOTAGES)
    work = args.work or Path(tempfile.mkdtemp(prefix="mutation-score-"))
    work.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    scenes = work / "scenes"
    library_copy(SCENES, scenes, args.skip, args.all_engines)
    physval("check", str(scenes), cwd=work)
    fast, slow = tiers(scenes)
    base = run_library([scenes], work / "base", args, None)
    print(f"baseline: {len(base)} rows, {len(new_failures(base))} new failures", flush=True)
    if len(new_failures(base)):
        print(new_failures(base)[["scenario", "engine", "metric"]].to_string(), file=sys.stderr)
    baseline = work / "baseline.csv"
    physval("baseline", "save", str(work / "base"), "--to", str(baseline), cwd=work)

    alarms: list[int] = []

    def rerun() -> None:  # one unchanged run against the baseline: its alarms are false
        results = run_library([scenes], work / f"rerun{len(alarms)}", args, baseline)
        alarms.append(len(regressions(results)) + len(new_failures(results)))
        print(f"rerun {len(alarms)}: {alarms[-1]} false alarms", flush=True)

    if args.reruns:  # one before the sabotages, the others after (a long run shows both early)
        rerun()
    table = []
    for name in names:
        results, slow_ran = sabotaged_runs(name, fast, slow, work, args, baseline)
        measured = results[results["engine"].str.startswith("mini") & (results["steps"] != "")]
        unmarked = ~measured["engine_version"].str.endswith(VERSION_MARK + name)
        if unmarked.any():
            raise SystemExit(f"{name}: {int(unmarked.sum())} mini rows without the sabotage mark")
        plain, regressed = scenes_of(new_failures(results)), scenes_of(regressions(results))
        sabotage = SABOTAGES[name]
        table.append(
            {
                "sabotage": name,
                "breaks": sabotage.what,
                "where": sabotage.where,
                "caught": bool(plain or regressed),
                "plain_rows": len(new_failures(results)),
                "plain_scenes": " ".join(plain),
                "baseline_rows": len(regressions(results)),
                "baseline_scenes": " ".join(regressed),
                "slow_tier": slow_ran,
            }
        )
        print(f"{name:26} plain {named(plain):60} baseline {named(regressed)}", flush=True)

    while len(alarms) < args.reruns:
        rerun()

    frame = pd.DataFrame(table)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(RESULTS, index=False)
    print()
    print("| sabotage | breaks | caught plainly (scenes) | caught by baseline (scenes) |")
    print("|---|---|---|---|")
    for row in table:
        print(
            f"| {row['sabotage']} | {row['breaks']} | {named(row['plain_scenes'].split())} "
            f"| {named(row['baseline_scenes'].split())} |"
        )
    caught = int(frame["caught"].sum()) if table else 0
    plainly = int((frame["plain_rows"] > 0).sum()) if table else 0
    by_baseline = int((frame["baseline_rows"] > 0).sum()) if table else 0
    print(
        f"\ncaught {caught} of {len(table)} (plainly {plainly}, by the baseline {by_baseline}); "
        f"false alarms on {args.reruns} unchanged reruns: {alarms}; "
        f"total {time.perf_counter() - start:.0f} s; runs in {work}; table in {RESULTS}"
    )
    return 0 if caught == len(table) and not any(alarms) else 1


if __name__ == "__main__":
    sys.exit(main())
