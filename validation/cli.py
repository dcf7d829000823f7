"""The ``physval`` command: one sub-command per job, picked from a registry.

Exit codes: 0 all good, 1 checks failed (for ``run``, later), 2 bad input (a
scenario, a flag, a value). Bad input prints one line per problem naming the
file, line, field and what was expected, and never a traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.scenario import check_scenario, json_schema, scenario_files

BUNDLED_SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
"""The library shipped with the project (the repository's scenarios/ folder)."""


def default_scenario_paths() -> list[Path]:
    """``./scenarios`` when run from a checkout, else the bundled library."""
    local = Path("scenarios")
    return [local if local.is_dir() else BUNDLED_SCENARIOS]


def command_check(args: argparse.Namespace) -> int:
    """Validate scenario files and folders; print every problem; 0 if all are valid, else 2."""
    paths = args.paths or default_scenario_paths()
    missing = [p for p in paths if not Path(p).exists()]
    if missing:
        for path in missing:
            print(f"{path}: no such file or folder", file=sys.stderr)
        return EXIT_BAD_INPUT
    files = scenario_files(paths)
    if not files:
        print(f"{', '.join(map(str, paths))}: no .yaml files found", file=sys.stderr)
        return EXIT_BAD_INPUT
    invalid = warnings = 0
    for file in files:
        scenario, problems = check_scenario(file)
        invalid += scenario is None
        warnings += sum(p.warning for p in problems)
        for problem in problems:
            print(problem, file=sys.stderr if not problem.warning else sys.stdout)
    valid = len(files) - invalid
    print(f"{len(files)} files: {valid} valid, {invalid} invalid, {warnings} warnings")
    return EXIT_OK if invalid == 0 else EXIT_BAD_INPUT


def command_run(args: argparse.Namespace) -> int:
    """Run scenes in engines, measure, compare, write the report; 0 passed, 1 failed, 2 bad input."""
    from validation.run import run_main

    return run_main(
        args.paths or default_scenario_paths(),
        args.engines,
        args.out,
        args.dt,
        args.only,
        args.argv,
    )


def command_report(args: argparse.Namespace) -> int:
    """Re-render report.html of a run folder from its files, without re-running."""
    try:
        from validation.report import report_command
    except ImportError:
        print("physval report: the HTML renderer is not installed", file=sys.stderr)
        return EXIT_BAD_INPUT
    return report_command(args.folder)


def command_stability(args: argparse.Namespace) -> int:
    """Largest stable dt per scene and engine, by bisection; writes stability.csv."""
    from validation.run import BadInputError, plan_run, write_table
    from validation.stability import stability_limit

    try:
        plan = plan_run(args.paths or default_scenario_paths(), args.engines, None, args.only)
    except BadInputError as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    limits = [stability_limit(scenario, spec) for scenario, specs in plan.scenes for spec in specs]
    for limit in limits:
        print(limit.sentence())
    rows = [{**limit.__dict__, "sentence": limit.sentence()} for limit in limits]
    write_table(rows, args.out or Path("reports") / "stability.csv")
    return EXIT_OK


def command_sweep(args: argparse.Namespace) -> int:
    """Error against run time over a dt sweep; writes sweep.csv and sweep.html."""
    from validation.run import BadInputError, plan_run, write_table
    from validation.sweep import DEFAULT_ENGINES, GridError, parse_dt_grid, run_sweep
    from validation.sweep_report import render_sweep

    try:
        grid = parse_dt_grid(args.dt)
        engines = args.engines or DEFAULT_ENGINES
        plan = plan_run(args.paths or default_scenario_paths(), engines, None, args.only)
    except (BadInputError, GridError) as error:
        print(error, file=sys.stderr)
        return EXIT_BAD_INPUT
    jobs = [(scenario, spec, grid) for scenario, specs in plan.scenes for spec in specs]
    rows = run_sweep(jobs, args.jobs)
    out = args.out or Path("reports") / "sweep"
    out.mkdir(parents=True, exist_ok=True)
    write_table(rows, out / "sweep.csv")
    render_sweep(rows, out / "sweep.html")
    print(f"{len(rows)} rows -> {out / 'sweep.csv'}, {out / 'sweep.html'}")
    return EXIT_OK


def command_schema(args: argparse.Namespace) -> int:
    """Print the JSON Schema of the scenario format (for editors)."""
    print(json.dumps(json_schema(), indent=2))
    return EXIT_OK


COMMANDS: dict[str, tuple[Callable[[argparse.Namespace], int], str]] = {
    "run": (command_run, "run scenes in engines and write results.csv and report.html"),
    "report": (command_report, "re-render report.html of a run folder"),
    "stability": (command_stability, "find the largest stable dt per scene and engine"),
    "sweep": (command_sweep, "error against run time over a timestep sweep"),
    "check": (command_check, "validate scenario files and folders (default: the bundled library)"),
    "schema": (command_schema, "print the JSON Schema of the scenario format"),
}


def parser() -> argparse.ArgumentParser:
    root = argparse.ArgumentParser(
        prog="physval", description="Reference-validated rigid-body physics harness."
    )
    sub = root.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (_, help_text) in COMMANDS.items():
        command = sub.add_parser(name, help=help_text, description=help_text)
        ARGUMENTS.get(name, lambda _: None)(command)
    return root


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number of seconds > 0; got {text!r}"
        ) from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0; got {text!r}")
    return value


def _scene_selection(command: argparse.ArgumentParser) -> None:
    """PATHS, --engines and --only: which scenes in which engines (run, sweep, stability)."""
    command.add_argument(
        "paths", nargs="*", type=Path, metavar="PATHS", help="scenario files or folders"
    )
    command.add_argument("--engines", metavar="SPECS", help='e.g. "mini, mujoco(integrator=RK4)"')
    command.add_argument("--only", metavar="GLOB", help="only scenes whose name or path matches")


def _run_arguments(command: argparse.ArgumentParser) -> None:
    _scene_selection(command)
    command.add_argument(
        "--out", type=Path, metavar="DIR", help="run folder (default reports/latest)"
    )
    command.add_argument(
        "--dt", type=_positive_seconds, metavar="SECONDS", help="override every scene's dt"
    )


def _stability_arguments(command: argparse.ArgumentParser) -> None:
    _scene_selection(command)
    command.add_argument(
        "--out", type=Path, metavar="FILE", help="CSV (default reports/stability.csv)"
    )


def _sweep_arguments(command: argparse.ArgumentParser) -> None:
    _scene_selection(command)
    command.add_argument("--out", type=Path, metavar="DIR", help="folder (default reports/sweep)")
    command.add_argument(
        "--dt",
        default="1e-2:1e-4:5",
        metavar="GRID",
        help="START:STOP:COUNT (log-spaced) or a comma list (default 1e-2:1e-4:5)",
    )
    command.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel processes")


ARGUMENTS = {
    "run": _run_arguments,
    "sweep": _sweep_arguments,
    "stability": _stability_arguments,
    "report": lambda c: c.add_argument("folder", type=Path, metavar="DIR"),
    "check": lambda c: c.add_argument("paths", nargs="*", type=Path, metavar="PATHS"),
}
"""Sub-command -> a function adding its arguments."""


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parser().parse_args(argv)
    args.argv = argv
    return COMMANDS[args.command][0](args)


if __name__ == "__main__":
    sys.exit(main())
