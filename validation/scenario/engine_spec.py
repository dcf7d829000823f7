"""Engine specs: ``name`` or ``name(key=value, ...)``, parsed once and checked per engine.

The same strings work in a scenario's ``engines:`` list and on the command line
(``--engines "mini(gyroscopic=implicit),mujoco(integrator=RK4)"``). Each installed engine
declares its settings as data (``validation.engine_api.EngineDeclaration.options``): a
setting is either a tuple of accepted words or a number type. Unknown engines and settings
are errors that name the nearest valid word. Nothing here imports an engine.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from validation.engine_api import Count, declarations, discover
from validation.scenario.suggest import did_you_mean

Option = tuple[str, ...] | type
"""Accepted values of one setting: a tuple of words, ``Count``, or ``int``/``float``/``bool``."""


class _EngineOptions(Mapping[str, dict[str, Option]]):
    """Engine name -> {setting: accepted values}, read from the installed engines'
    declarations when first used (discovery reads the installed metadata once)."""

    def _table(self) -> dict[str, dict[str, Option]]:
        return {
            name: {option.name: option.accepted for option in declaration.options}
            for name, declaration in declarations().items()
        }

    def __getitem__(self, name: str) -> dict[str, Option]:
        return self._table()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(declarations())

    def __len__(self) -> int:
        return len(declarations())


ENGINE_OPTIONS: Mapping[str, dict[str, Option]] = _EngineOptions()
"""Settings each installed engine accepts in a spec (the adapters read them)."""

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


def _convert(engine: str, key: str, raw: str, option: Option) -> str | int | float | bool:
    if isinstance(option, tuple):
        if raw not in option:
            raise EngineSpecError(
                f"{engine} setting {key!r}: expected one of {', '.join(option)}; got {raw!r}"
                + did_you_mean(raw, option)
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
    engines = declarations()
    if name not in engines:
        broken = discover().broken_names.get(name)
        if broken:
            raise EngineSpecError(f"engine {name!r} is installed but broken: {broken}")
        raise EngineSpecError(
            f"unknown engine {name!r}; expected one of {', '.join(engines)}"
            + did_you_mean(name, engines)
        )
    declaration = engines[name]
    options = {option.name: option.accepted for option in declaration.options}
    settings: list[tuple[str, str | int | float | bool]] = []
    for part in [p for p in (inner or "").split(",") if p.strip()]:
        key, sep, raw = (s.strip() for s in part.partition("="))
        if not sep or not key or not raw:
            raise EngineSpecError(f"{name}: expected key=value; got {part.strip()!r}")
        if key not in options:
            raise EngineSpecError(
                f"{name} has no setting {key!r}; expected one of {', '.join(options)}"
                + did_you_mean(key, options)
            )
        if any(key == seen for seen, _ in settings):
            raise EngineSpecError(f"{name}: setting {key!r} given twice")
        settings.append((key, _convert(name, key, raw, options[key])))
    if declaration.check_settings is not None:  # the engine's own validation, checked once here
        try:
            declaration.check_settings(dict(settings))
        except ValueError as error:
            raise EngineSpecError(f"{name}: {error}") from None
        except Exception as error:  # a plugin's broken check: its line, not a traceback
            raise EngineSpecError(
                f"{name}: the engine's check_settings raised {type(error).__name__}: {error}"
            ) from None
    try:  # a plugin's capabilities_for, called by planning and every run: once here first
        declaration.capabilities_of(dict(settings))
    except Exception as error:
        raise EngineSpecError(
            f"{name}: the engine's capabilities_for raised {type(error).__name__}: {error}"
        ) from None
    return EngineSpec(name, tuple(settings))


def not_installed(name: str) -> str | None:
    """Why the engine ``name`` cannot run here (its package is missing, with the install
    line), or None when it can. A scene may name such an engine (its rows are
    ``not_installed``); a command line that names one is refused (``parse_installed_spec``)."""
    declaration = declarations()[name]
    missing = declaration.missing()
    if not missing:
        return None
    return f"engine {name!r} needs the {', '.join(missing)} package, not installed: " + (
        declaration.install
    )


def parse_installed_spec(text: str) -> EngineSpec:
    """``parse_engine_spec``, refusing an engine whose package is not installed: what a
    command line names must run."""
    spec = parse_engine_spec(text)
    reason = not_installed(spec.name)
    if reason:
        raise EngineSpecError(reason)
    return spec


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
