"""``physval list``: what this installation can run and measure, and ``physval --version``.

Three sections: the scenes (name, file, engines), the engines (version and the options a spec
takes), and the metrics and expectation kinds with their one-line definitions (the report's
legend). It reads the scene files and the installed packages' metadata; it imports no engine.
"""

from __future__ import annotations

import sys
import textwrap
from dataclasses import fields
from pathlib import Path

from mini_engine.settings import Settings
from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.measure.definitions import EXPECTATION_DEFINITIONS, METRIC_DEFINITIONS
from validation.scenario.engine_spec import ENGINE_OPTIONS, Count, Option
from validation.scenario.load import check_scenario, scenario_files
from validation.versions import version_of

LIST_WIDTH = 100
"""Columns of every line ``physval list`` prints (a CI log, a standard terminal)."""

NAME_WIDTH = 30
"""The name column of the scenes and definitions tables; longer names push their text over."""

ENGINE_DISTRIBUTIONS = {
    "mini": "physval",
    "mujoco": "mujoco",
    "pybullet": "pybullet",
    "rapier": "rapier3d",
}
"""The installed distribution whose version is each engine's version (mini ships with physval)."""


def _row(name: str, text: str) -> list[str]:
    """``name`` then ``text`` wrapped under itself, every line within ``LIST_WIDTH``."""
    head = f"  {name:<{NAME_WIDTH}} "
    return textwrap.wrap(
        text,
        LIST_WIDTH,
        initial_indent=head if len(head) <= NAME_WIDTH + 3 else f"  {name} ",
        subsequent_indent=" " * (NAME_WIDTH + 3),
        break_on_hyphens=False,
    ) or [head.rstrip()]


def _option_text(key: str, option: Option, default: object | None) -> str:
    """``gyroscopic: none|explicit|implicit (default none)`` and the like."""
    if isinstance(option, tuple):
        accepted = "|".join(option)
    elif option is Count:
        accepted = "a whole number >= 1"
    else:
        accepted = {bool: "true|false", int: "an integer", float: "a number"}.get(option, "?")
    shown = (
        ""
        if default is None
        else f" (default {str(default).lower() if isinstance(default, bool) else default})"
    )
    return f"{key}: {accepted}{shown}"


def _defaults(engine: str) -> dict[str, object]:
    """The options' defaults where the engine states them (mini's ``Settings``); MuJoCo's and
    PyBullet's depend on the spec's ``profile``."""
    if engine != "mini":
        return {}
    return {item.name: getattr(Settings(), item.name) for item in fields(Settings)}


def engine_lines() -> list[str]:
    lines = ["engines (an option is written name(key=value, ...), e.g. mini(gyroscopic=implicit)):"]
    for engine, options in ENGINE_OPTIONS.items():
        defaults = _defaults(engine)
        version = f"{ENGINE_DISTRIBUTIONS[engine]} {version_of(ENGINE_DISTRIBUTIONS[engine])}"
        lines += _row(engine, version)
        for key, option in options.items():
            lines += _row("", _option_text(key, option, defaults.get(key)))
    return lines


def _shown(file: Path, roots: list[Path]) -> str:
    """A scene file as its path below the folder it was found in (the whole path otherwise)."""
    for root in roots:
        if root.is_dir() and file.is_relative_to(root):
            return str(file.relative_to(root))
    return str(file)


def scene_lines(paths: list[Path]) -> tuple[list[str], list[str]]:
    """The scenes section, and one line per file that does not load (shown by ``check``)."""
    files = scenario_files(paths)
    lines, broken = [f"scenes ({len(files)}, in {', '.join(map(str, paths))}):"], []
    for file in files:
        scenario, problems = check_scenario(file)
        if scenario is None:
            broken.append(f"{file}: does not load ({len(problems)} problems: physval check {file})")
            continue
        lines += _row(scenario.name, f"{_shown(file, paths)}: {', '.join(scenario.engines)}")
    return lines, broken


def definition_lines() -> list[str]:
    lines = ["metrics (the checks a scene's `checks:` can name):"]
    for name, text in METRIC_DEFINITIONS.items():
        lines += _row(name, text)
    lines.append("expectation kinds (an `expect:` entry's kind; its metric is <kind>.<body>):")
    for name, text in EXPECTATION_DEFINITIONS.items():
        lines += _row(name, text)
    return lines


def list_main(paths: list[Path]) -> int:
    """Print the three sections; 0, or 2 (with one line each) when a path does not exist or a
    scene file does not load."""
    missing = [path for path in paths if not path.exists()]
    if missing:
        for path in missing:
            print(f"{path}: no such file or folder", file=sys.stderr)
        return EXIT_BAD_INPUT
    scenes, broken = scene_lines(paths)
    print("\n".join([*scenes, *engine_lines(), *definition_lines()]))
    for line in broken:
        print(line, file=sys.stderr)
    return EXIT_BAD_INPUT if broken else EXIT_OK
