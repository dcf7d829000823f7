"""Engine specs: ``name`` or ``name(key=value, ...)``, parsed once and checked per engine.

The same strings work in a scenario's ``engines:`` list and on the command line
(``--engines "mini(gyroscopic=implicit),mujoco(integrator=RK4)"``). Each engine
declares its settings in ``ENGINE_OPTIONS``: a setting is either a tuple of
accepted words or a number type. Unknown engines and settings are errors that
name the nearest valid word.
"""

from __future__ import annotations

import difflib
import importlib.util
import math
import re
from dataclasses import dataclass, fields

from mini_engine.settings import CHOICES as MINI_CHOICES
from mini_engine.settings import Settings


class Count(int):
    """A setting that counts something (solver iterations): a whole number >= 1. Engines take
    a non-positive count silently (MuJoCo's -5 iterations make a scene unstable, PyBullet's -1
    falls back to 50), so it is refused here, in every engine's spec."""


Option = tuple[str, ...] | type
"""Accepted values of one setting: a tuple of words, ``Count``, or ``int``/``float``/``bool``."""


def _mini_options() -> dict[str, Option]:
    """Every field of ``mini_engine.Settings`` except dt (the scene's), typed from its default."""
    options: dict[str, Option] = {}
    for item in fields(Settings):
        if item.name == "dt":
            continue
        default = getattr(Settings(), item.name)
        kind = type(default)
        if item.name.endswith("iterations"):
            kind = Count
        options[item.name] = MINI_CHOICES.get(item.name, kind)
    return options


ENGINE_OPTIONS: dict[str, dict[str, Option]] = {
    "mini": _mini_options(),
    "mujoco": {
        "profile": ("matched", "defaults"),
        "integrator": ("Euler", "RK4", "implicit", "implicitfast"),
        "solver": ("auto", "Newton", "CG", "PGS"),
        "cone": ("pyramidal", "elliptic"),
        "restitution": ("damper", "soft"),
        "iterations": Count,
    },
    "pybullet": {
        "profile": ("matched", "defaults"),
        "bodies": ("maximal", "multibody"),
        "solver_iterations": Count,
    },
    "rapier": {
        "profile": ("matched", "defaults"),
        "gyroscopic": ("on", "off"),
        "ccd": ("on", "off"),
        "friction_model": ("simplified", "coulomb"),
        "solver_iterations": Count,
    },
}
"""Settings each engine accepts in a spec (the adapters read them; Rapier's meanings are in
``validation.engines.rapier.declaration.OPTIONS``)."""

OPTIONAL_ENGINES: dict[str, tuple[str, str]] = {
    "rapier": ("rapier3d", 'pip install "physval[rapier]"'),
}
"""Engines whose package is an optional extra: name -> (the module it imports, the install
command). Naming one that is not installed is a spec error, one line with that command,
found without importing the engine."""

DEFAULT_ENGINES = ("mini", "mujoco", "pybullet")

_SPEC = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:\((.*)\))?\s*$")


class EngineSpecError(ValueError):
    """An engine spec that names an unknown engine or setting, or a bad value."""


@dataclass(frozen=True)
class EngineSpec:
    """A parsed engine spec: the engine's name and its settings in the order written."""

    name: str
    settings: tuple[tuple[str, str | int | float | bool], ...] = ()

    @property
    def label(self) -> str:
        """The canonical spelling, ``name`` or ``name(k=v, ...)``; used as the engine column."""
        if not self.settings:
            return self.name
        inner = ", ".join(f"{key}={value}" for key, value in self.settings)
        return f"{self.name}({inner})"

    def as_dict(self) -> dict[str, str | int | float | bool]:
        return dict(self.settings)

    def __str__(self) -> str:
        return self.label


def _suggest(word: str, choices) -> str:
    """``; did you mean 'X'?`` for the closest choice, case aside (``rk4`` -> ``RK4``)."""
    by_lower = {choice.lower(): choice for choice in choices}
    close = difflib.get_close_matches(word.lower(), list(by_lower), n=1, cutoff=0.6)
    return f"; did you mean {by_lower[close[0]]!r}?" if close else ""


def _convert(engine: str, key: str, raw: str, option: Option) -> str | int | float | bool:
    if isinstance(option, tuple):
        if raw not in option:
            raise EngineSpecError(
                f"{engine} setting {key!r}: expected one of {', '.join(option)}; got {raw!r}"
                + _suggest(raw, option)
            )
        return raw
    if option is Count:
        if not re.fullmatch(r"[+-]?[0-9]+", raw) or int(raw) < 1:
            raise EngineSpecError(
                f"{engine} setting {key!r}: expected a whole number >= 1; got {raw!r}"
            )
        return int(raw)
    if option is bool:
        lowered = raw.lower()
        if lowered not in ("true", "false"):
            raise EngineSpecError(f"{engine} setting {key!r}: expected true or false; got {raw!r}")
        return lowered == "true"
    try:
        value = option(raw)
    except ValueError:
        raise EngineSpecError(
            f"{engine} setting {key!r}: expected {'an integer' if option is int else 'a number'}; got {raw!r}"
        ) from None
    if isinstance(value, float) and not math.isfinite(value):
        raise EngineSpecError(f"{engine} setting {key!r}: expected a finite number; got {raw!r}")
    return value


def parse_engine_spec(text: str) -> EngineSpec:
    """Parse and check ``text`` such as ``mini(gyroscopic=implicit, solver_iterations=20)``."""
    match = _SPEC.match(text) if isinstance(text, str) else None
    if match is None:
        raise EngineSpecError(f"expected an engine spec like name or name(key=value); got {text!r}")
    name, inner = match.group(1), match.group(2)
    if name not in ENGINE_OPTIONS:
        raise EngineSpecError(
            f"unknown engine {name!r}; expected one of {', '.join(ENGINE_OPTIONS)}"
            + _suggest(name, ENGINE_OPTIONS)
        )
    _check_installed(name)
    options = ENGINE_OPTIONS[name]
    settings: list[tuple[str, str | int | float | bool]] = []
    for part in [p for p in (inner or "").split(",") if p.strip()]:
        key, sep, raw = (s.strip() for s in part.partition("="))
        if not sep or not key or not raw:
            raise EngineSpecError(f"{name}: expected key=value; got {part.strip()!r}")
        if key not in options:
            raise EngineSpecError(
                f"{name} has no setting {key!r}; expected one of {', '.join(options)}"
                + _suggest(key, options)
            )
        if any(key == seen for seen, _ in settings):
            raise EngineSpecError(f"{name}: setting {key!r} given twice")
        settings.append((key, _convert(name, key, raw, options[key])))
    if name == "mini":  # the engine's own validation, so that values are checked once here
        try:
            Settings(**dict(settings))
        except ValueError as error:
            raise EngineSpecError(f"mini: {error}") from None
    return EngineSpec(name, tuple(settings))


def _check_installed(name: str) -> None:
    """An ``EngineSpecError`` naming the install command when an optional engine's package
    is missing (``OPTIONAL_ENGINES``; ``find_spec`` reads the path, nothing is imported)."""
    if name not in OPTIONAL_ENGINES:
        return
    module, command = OPTIONAL_ENGINES[name]
    if importlib.util.find_spec(module) is None:
        raise EngineSpecError(
            f"engine {name!r} needs the {module} package, not installed: {command}"
        )


def split_engine_list(text: str) -> list[str]:
    """Split a command-line list ``"mini(a=1, b=2), mujoco"`` at the top-level commas."""
    parts, depth, current = [], 0, []
    for char in text:
        if char == "," and depth == 0:
            parts.append("".join(current))
            current = []
            continue
        depth += {"(": 1, ")": -1}.get(char, 0)
        current.append(char)
    parts.append("".join(current))
    return [p.strip() for p in parts if p.strip()]
