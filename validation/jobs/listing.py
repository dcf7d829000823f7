"""``physval list``: what this installation can run and measure, and ``physval --version``.

Three sections: the scenes (name, file, engines), the engines (every installed one, built-in
or plugin: its version, what it is, its capabilities and the options a spec takes, from its
declaration), and the metrics and expectation kinds with their one-line definitions (the
report's legend). It reads the scene files, the installed packages' metadata and the engines'
declarations; it imports no engine (a broken engine plugin is one line on stderr, printed by
``physval``'s entry).
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.engine_api import FEATURES, SHAPES, Count, EngineDeclaration, EngineOption, discover
from validation.measure.definitions import EXPECTATION_DEFINITIONS, METRIC_DEFINITIONS
from validation.scenario.load import scenario_files, validate_scenario
from validation.versions import version_of

LIST_WIDTH = 100
"""Columns of every line ``physval list`` prints (a CI log, a standard terminal)."""

NAME_WIDTH = 30
"""The name column of the scenes and definitions tables; longer names push their text over."""


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


ACCEPTED_TEXT = {
    Count: "a whole number >= 1",
    bool: "true|false",
    int: "an integer",
    float: "a number",
}
"""How a number option's accepted values read (a word option lists its words)."""


def _option_text(option: EngineOption) -> str:
    """``gyroscopic: none|explicit|implicit (default none): the gyroscopic term ...``."""
    accepted = "|".join(option.choices) if option.type is str else ACCEPTED_TEXT[option.type]
    default = option.default
    shown = (
        ""
        if default is None
        else f" (default {str(default).lower() if isinstance(default, bool) else default})"
    )
    return f"{option.name}: {accepted}{shown}: {option.meaning}"


def _capability_text(declaration: EngineDeclaration) -> str:
    """``supports sphere, box, ...; lacks springs; integrators ...; float64, fixed steps``."""
    capabilities = declaration.capabilities
    lacking = [w for w in (*SHAPES, *FEATURES) if w not in capabilities.supported]
    parts = ["supports every shape and scene feature"]
    if lacking:
        has = [w for w in (*SHAPES, *FEATURES) if w in capabilities.supported]
        parts = [f"supports {', '.join(has) or 'nothing'}", f"lacks {', '.join(lacking)}"]
    if capabilities.integrators:
        parts.append(f"integrators {', '.join(capabilities.integrators)}")
    parts.append(f"{capabilities.precision}, {capabilities.stepping} steps")
    return "; ".join(parts)


def engine_lines() -> list[str]:
    """Every installed engine: its distribution and version, summary, capabilities, options."""
    lines = ["engines (an option is written name(key=value, ...), e.g. mini(gyroscopic=implicit)):"]
    for name, declaration in discover().engines.items():
        version = f"{declaration.distribution} {version_of(declaration.distribution)}"
        lines += _row(name, f"{version}: {declaration.summary}")
        lines += _row("", _capability_text(declaration))
        for option in declaration.options:
            lines += _row("", _option_text(option))
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
        scenario, problems = validate_scenario(file)  # valid or not; the warnings are check's
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
