"""The ``physval`` command: one sub-command per job, picked from a registry.

Exit codes (``validation.contract``): 0 all good; 1 (``run`` only) a regression or a new
failure (a failed check, an unstable run, a model mismatch, an engine error that is not a
known finding of its scene); 2 bad input (a scenario, a flag, a value). Bad input prints one line per problem naming the
file, line, field and what was expected, and never a traceback.

Each command imports what it uses when it runs, so ``physval check`` pays for the scene
loader only, and ``physval --help`` for nothing but argparse (``tests/test_architecture.py``
checks which packages each light command imports).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

from validation import signals
from validation.bundled import (  # BUNDLED_SCENARIOS: tests and scripts import it from here
    BUNDLED_SCENARIOS,  # noqa: F401
    default_scenario_paths,
)
from validation.contract import BASELINE_ACTION_NAMES, CONFORMANCE_CHECKS, EXIT_BAD_INPUT, EXIT_OK


def _package_paths_problem(args: argparse.Namespace) -> str | None:
    """``--package-path NAME=DIR`` flags set where ``package://NAME`` resolves, before any scene
    loads; the one line that refuses a bad flag, or None."""
    from validation.jobs.plan import BadInputError, use_package_paths

    try:
        use_package_paths(args.package_path)
    except BadInputError as error:
        return str(error)
    return None


def command_check(args: argparse.Namespace) -> int:
    """Validate scenario files and folders; print every problem; 0 if all are valid, else 2."""
    from validation.jobs.check import check_main

    problem = _package_paths_problem(args)
    if problem:
        print(problem, file=sys.stderr)
        return EXIT_BAD_INPUT
    return check_main(args.paths or default_scenario_paths())


def command_run(args: argparse.Namespace) -> int:
    """Run scenes in engines, measure, compare, write the report; 0 passed, 1 failed, 2 bad input."""
    from validation.jobs.phases import PhaseClock

    clock = PhaseClock(shown=args.timings)
    with clock.phase("imports"):  # the harness, NumPy, pandas, ...: not paid by a light command
        from validation.jobs.output import fresh_subfolder
        from validation.jobs.run import DEFAULT_OUT, RESUME_ALONE, run_main

    selection = (args.paths, args.engines, args.dt, args.only, args.out, args.baseline)
    selection += (args.new_folder, args.package_path, args.sweeps)
    if args.resume is not None and any(selection):
        print(
            f"--resume {args.resume}: {RESUME_ALONE}; give only --jobs, --scheduler and the "
            "killed run's --junit and --history",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    problem = _package_paths_problem(args)
    if problem:
        print(problem, file=sys.stderr)
        return EXIT_BAD_INPUT
    return run_main(
        args.paths or default_scenario_paths(),
        args.engines,
        fresh_subfolder(args.out or DEFAULT_OUT) if args.new_folder else args.out,
        args.dt,
        args.only,
        args.argv,
        args.jobs,
        args.resume,
        args.baseline,
        args.junit,
        args.history,
        args.scheduler,
        clock,
        args.job_timeout,
        sweeps=SWEEPS[args.sweeps] if args.sweeps else _whole_library(args),
        summary_file=args.summary,
    )


def _whole_library(args: argparse.Namespace) -> bool:
    """Whether ``physval run`` runs the whole bundled library (no PATHS, no --only): the
    nightly run, which sweeps by default; a run of named scenes is the authoring loop."""
    return not args.paths and args.only is None


SWEEPS = {"on": True, "off": False}
"""``--sweeps``: whether a run runs its scenes' sweeps (default ``_whole_library``: on for the
bare nightly run of the whole library, off for a run of named scenes, the authoring loop)."""


def command_sim2sim(args: argparse.Namespace) -> int:
    """One model file in every engine, tier by tier; the first disagreeing tier per pair."""
    from validation.jobs.sim2sim import sim2sim_main

    return sim2sim_main(
        args.model,
        args.engines,
        args.out,
        args.package_path,
        args.duration,
        args.dt,
        args.argv,
        args.jobs,
        args.job_timeout,
        args.scheduler,
    )


def command_report(args: argparse.Namespace) -> int:
    """Re-render report.html of a run folder from its files, without re-running."""
    from validation.report.render import report_command

    return report_command(args.folder)


def command_stability(args: argparse.Namespace) -> int:
    """Largest stable dt per scene and engine, by bisection; writes stability.csv."""
    from validation.jobs.stability_search import stability_main

    return stability_main(
        args.paths or default_scenario_paths(),
        args.engines,
        args.only,
        args.out,
        args.jobs,
        args.scheduler,
        args.job_timeout,
    )


def command_sweep(args: argparse.Namespace) -> int:
    """Error against run time over a dt sweep; writes sweep.csv and sweep.html."""
    from validation.jobs.sweep import sweep_main

    return sweep_main(
        args.paths or default_scenario_paths(),
        args.engines,
        args.only,
        args.dt,
        args.jobs,
        args.out,
        args.scheduler,
        args.job_timeout,
    )


def command_history(args: argparse.Namespace) -> int:
    """Trend, steps and regressions of every recorded series; writes history.html."""
    from validation.nightly.history_page import history_main

    return history_main(args.db, args.last, args.only, args.out, args.selection)


def command_compare(args: argparse.Namespace) -> int:
    """The rows that moved beyond noise between two runs; writes compare.csv and compare.html."""
    from validation.nightly.compare import compare_main

    return compare_main(args.run_a, args.run_b, args.db, args.out, args.selection)


def command_baseline(args: argparse.Namespace) -> int:
    """Save a run's rows as the baseline later runs are classified against."""
    from validation.nightly.baseline import baseline_main

    return baseline_main(args.action, args.run_dir, args.to)


def command_list(args: argparse.Namespace) -> int:
    """List the scenes, the engines with their versions and options, the metrics."""
    from validation.jobs.listing import list_main

    return list_main(args.paths or default_scenario_paths())


def command_conformance(args: argparse.Namespace) -> int:
    """Check an engine adapter against the adapter contract; 0 all pass, 1 one fails, 2 bad input."""
    from validation.jobs.conformance import conformance_main

    return conformance_main(args.engine, args.only, args.job_timeout)


def command_schema(args: argparse.Namespace) -> int:
    """Print the JSON Schema of the scenario format (for editors)."""
    from validation.scenario import json_schema

    print(json.dumps(json_schema(), indent=2))
    return EXIT_OK


COMMANDS: dict[str, tuple[Callable[[argparse.Namespace], int], str]] = {
    "run": (command_run, "run scenes in engines and write results.csv and report.html"),
    "sim2sim": (
        command_sim2sim,
        "one URDF or MJCF model in every engine, judged tier by tier: the first tier where "
        "each engine pair disagrees",
    ),
    "report": (command_report, "re-render report.html of a run folder"),
    "stability": (command_stability, "find the largest stable dt per scene and engine"),
    "sweep": (command_sweep, "error against run time over a timestep sweep"),
    "check": (command_check, "validate scenario files and folders (default: the bundled library)"),
    "schema": (command_schema, "print the JSON Schema of the scenario format"),
    "conformance": (
        command_conformance,
        "check an engine adapter against the adapter contract (the boundary, not the physics)",
    ),
    "list": (
        command_list,
        "the scenes, the engines with their versions and options, the metrics and expectations",
    ),
    "history": (command_history, "history.html: every metric's trend over the recorded runs"),
    "compare": (command_compare, "the rows that moved beyond noise between two runs"),
    "baseline": (
        command_baseline,
        "save a run's rows as a baseline: baseline save RUN_DIR --to FILE",
    ),
}


class _VersionAction(argparse.Action):
    """``--version``: the versions, read only when asked for (they come from the installed
    packages' metadata)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="show the versions and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from validation.versions import version_text

        print(version_text())
        parser.exit()


def _environment_problem(args: argparse.Namespace) -> str | None:
    """What the environment lacks or gets wrong for this command, checked before any work:
    an unknown ``PHYSVAL_SABOTAGE`` (``validation.engines.sabotage``), a ``--scheduler``
    without Dask installed."""
    from validation.engines.sabotage import SabotageError, chosen

    try:
        chosen()
    except SabotageError as error:
        return str(error)
    if getattr(args, "scheduler", None) is not None:
        from validation.jobs.dask_backend import distributed_missing

        return distributed_missing()
    return None


def parser() -> argparse.ArgumentParser:
    root = argparse.ArgumentParser(
        prog="physval", description="Reference-validated rigid-body physics harness."
    )
    root.add_argument("--version", action=_VersionAction)
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


def _package_path_argument(command: argparse.ArgumentParser) -> None:
    """--package-path NAME=DIR (repeatable): where a model's package://NAME resolves."""
    command.add_argument(
        "--package-path",
        action="append",
        metavar="NAME=DIR",
        help="resolve a model's package://NAME/... inside DIR (repeatable; DIR must exist)",
    )


def _sim2sim_arguments(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "model",
        metavar="MODEL_FILE",
        help="a URDF (.urdf) or MJCF (.xml) file: a path, or pkg:PACKAGE/path inside an "
        "installed Python package (pkg:pybullet_data/kuka_iiwa/model.urdf)",
    )
    command.add_argument(
        "--engines",
        nargs="+",
        metavar="SPEC",
        help="engine specs (default: every installed engine with joints, native loaders first)",
    )
    command.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="run folder (default reports/sim2sim), as physval run's --out; it also holds the "
        "scene written for the model (scene.yaml)",
    )
    _package_path_argument(command)
    command.add_argument(
        "--duration", type=_positive_seconds, metavar="SECONDS", help="the swing (default 1 s)"
    )
    command.add_argument(
        "--dt", type=_positive_seconds, metavar="SECONDS", help="the step (default 1 ms)"
    )
    _jobs_argument(command)


def _run_arguments(command: argparse.ArgumentParser) -> None:
    _scene_selection(command)
    _package_path_argument(command)
    command.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="run folder (default reports/latest): a new path, an empty folder or an earlier "
        "run folder, which the run replaces whole; anything else is refused",
    )
    command.add_argument(
        "--new-folder",
        action="store_true",
        help="publish into a new subfolder of --out (DIR/run-<stamp>-<id>) instead of "
        "replacing DIR: for a folder that holds other things",
    )
    command.add_argument(
        "--resume",
        type=Path,
        metavar="DIR",
        help="finish the killed run whose --out was DIR, without redoing its finished jobs",
    )
    command.add_argument(
        "--dt", type=_positive_seconds, metavar="SECONDS", help="override every scene's dt"
    )
    command.add_argument(
        "--baseline",
        metavar="FILE",
        help="classify every row against this baseline (default baselines/default.csv when "
        "the working folder has one; 'none': no comparison)",
    )
    command.add_argument("--junit", metavar="FILE", help="also write JUnit XML here")
    command.add_argument(
        "--summary",
        type=Path,
        metavar="FILE",
        help="also write the run's summary in Markdown here (e.g. $GITHUB_STEP_SUMMARY)",
    )
    command.add_argument(
        "--history",
        metavar="URL",
        help="record the run in this history database (default sqlite:///<the --out "
        "folder's parent>/history.sqlite; 'none': not recorded)",
    )
    command.add_argument(
        "--sweeps",
        choices=sorted(SWEEPS),
        help="run the scenes' dt sweeps (sweep:) too (default: on for a bare 'physval run', "
        "the nightly run of the whole library; off when PATHS or --only name scenes)",
    )
    command.add_argument(
        "--timings",
        action="store_true",
        help="print the wall time of each phase (planning, jobs, write, report, publish, "
        "history) on stderr at the end",
    )
    _jobs_argument(command)


def _positive_count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1; got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1; got {text!r}")
    return value


def _seconds_or_zero(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (0 <= value < float("inf")):
        raise argparse.ArgumentTypeError(
            f"expected a number of seconds >= 0 (0: no time limit); got {text!r}"
        )
    return value


def _job_timeout_argument(command: argparse.ArgumentParser) -> None:
    """--job-timeout: each job's time limit (run, sweep, stability, conformance)."""
    from validation.jobs.executor import JOB_TIMEOUT_FACTOR, JOB_TIMEOUT_FLOOR_S

    command.add_argument(
        "--job-timeout",
        type=_seconds_or_zero,
        metavar="SECONDS",
        help="each job's time limit, for its engine's import, advance and close alike: a job "
        "past it is stopped and its row is timed_out (exit 1); default: "
        f"{JOB_TIMEOUT_FACTOR:g} x the job's expected time (from its steps and bodies), at "
        f"least {JOB_TIMEOUT_FLOOR_S:g} s; 0: no limit",
    )


def _jobs_argument(command: argparse.ArgumentParser) -> None:
    """--jobs, --scheduler and --job-timeout: where the jobs run (run, sweep, stability,
    sim2sim)."""
    _job_timeout_argument(command)
    command.add_argument(
        "--jobs",
        type=_positive_count,
        default=os.cpu_count() or 1,
        metavar="N",
        help="parallel worker processes (default: the machine's cores; with --scheduler "
        "local, the local cluster's workers)",
    )
    command.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the jobs on the Dask cluster whose scheduler is at ADDRESS "
        "(tcp://host:8786), or 'local' for a LocalCluster of --jobs processes; needs "
        'pip install -e ".[distributed]"',
    )


def _stability_arguments(command: argparse.ArgumentParser) -> None:
    _scene_selection(command)
    _jobs_argument(command)
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
    _jobs_argument(command)


def _conformance_arguments(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "engine", metavar="ENGINE_SPEC", help="e.g. mujoco or mini(gyroscopic=implicit)"
    )
    command.add_argument(
        "--only",
        action="append",
        metavar="CHECK",
        help=f"run only this check (repeatable): {', '.join(CONFORMANCE_CHECKS)}",
    )
    _job_timeout_argument(command)


def _db_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--db", metavar="URL", help="history database URL or SQLite file (reports/history.sqlite)"
    )


def _history_arguments(command: argparse.ArgumentParser) -> None:
    _db_argument(command)
    command.add_argument("--last", type=_positive_count, metavar="N", help="only the last N runs")
    command.add_argument("--only", metavar="GLOB", help="only scenes whose name matches")
    command.add_argument(
        "--selection",
        metavar="KEY",
        help="the runs of one selection (what a run was asked to run: paths, --only, --engines, "
        "--dt, sweeps): 'latest' the latest run's (default), 'all' every run, 'unrecorded' the "
        "runs recorded before selections were, or a key as this command prints them",
    )
    command.add_argument(
        "--out", type=Path, metavar="FILE", help="page (default history.html next to the database)"
    )


def _compare_arguments(command: argparse.ArgumentParser) -> None:
    command.add_argument("run_a", metavar="RUN_A", help="run folder or history run id (before)")
    command.add_argument("run_b", metavar="RUN_B", help="run folder or history run id (after)")
    _db_argument(command)
    command.add_argument(
        "--selection",
        metavar="RULE",
        help="'shared' (default): every row when both runs have one selection, else only the "
        "(scene, engine) pairs both ran; 'all': every row of both runs",
    )
    command.add_argument("--out", type=Path, metavar="DIR", help="folder (default reports/compare)")


def _baseline_arguments(command: argparse.ArgumentParser) -> None:
    command.add_argument("action", choices=sorted(BASELINE_ACTION_NAMES), help="what to do")
    command.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run folder")
    command.add_argument("--to", type=Path, metavar="FILE", required=True, help="the baseline file")


ARGUMENTS = {
    "run": _run_arguments,
    "sweep": _sweep_arguments,
    "stability": _stability_arguments,
    "report": lambda c: c.add_argument("folder", type=Path, metavar="DIR"),
    "check": lambda c: (
        c.add_argument("paths", nargs="*", type=Path, metavar="PATHS"),
        _package_path_argument(c),
    ),
    "sim2sim": _sim2sim_arguments,
    "list": lambda c: c.add_argument("paths", nargs="*", type=Path, metavar="PATHS"),
    "conformance": _conformance_arguments,
    "history": _history_arguments,
    "compare": _compare_arguments,
    "baseline": _baseline_arguments,
}
"""Sub-command -> a function adding its arguments."""


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    signals.install()  # SIGTERM and SIGHUP stop a command as Ctrl-C does
    args = parser().parse_args(argv)
    args.argv = argv
    try:
        problem = _environment_problem(args)
        if problem:
            print(problem, file=sys.stderr)
            return EXIT_BAD_INPUT
        from validation.engine_api import discover  # the declarations only, never an engine

        for line in discover().broken:  # one line per broken engine plugin; the others run
            print(line, file=sys.stderr)
        return COMMANDS[args.command][0](args)
    except (signals.Interrupted, KeyboardInterrupt) as stop:  # also signals.Stopped
        signum = signals.signal_number(stop)
        print(signals.stop_message(signum), file=sys.stderr)
        return signals.exit_code(signum)


if __name__ == "__main__":
    sys.exit(main())
