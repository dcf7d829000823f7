"""Where the bundled scene library is, with nothing else imported: the commands' default
paths, needed before a command knows whether it will load a scene at all."""

from __future__ import annotations

from pathlib import Path

BUNDLED_SCENARIOS = (Path(__file__).resolve().parent / "library").resolve()
"""The scene library shipped with physval: ``scenarios/`` of the checkout, which
``validation/library`` links to, so that a wheel carries it inside the package (the link is
followed when the wheel is built: ``package-data`` of pyproject.toml)."""


def default_scenario_paths() -> list[Path]:
    """``./scenarios`` when run from a checkout, else the bundled library (what ``physval``
    commands and ``pytest --physval`` run when given no paths)."""
    local = Path("scenarios")
    return [local if local.is_dir() else BUNDLED_SCENARIOS]
