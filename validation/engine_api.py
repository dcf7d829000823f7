"""What an engine declares, as data, and how physval finds the installed engines.

This module is the light half of the public adapter contract (``validation.engines.base``
re-exports it with the protocol and the records): an engine's ``EngineDeclaration`` names
its options, its capabilities and its adapter class, and imports nothing of the engine, so
that ``physval check``, ``physval list``, spec parsing and the JSON Schema read every
installed engine without importing MuJoCo, PyBullet or a plugin's solver.

Discovery. Every engine, the built-in three included, is an entry point of the group
``physval.engines`` (``ENTRY_POINT_GROUP``): its name is the engine's name and its value an
``EngineDeclaration`` object (``package.declaration:DECLARATION``). ``discover`` loads them
once per process. A plugin that fails (it does not import, it is not a declaration, it was
written for another ``API_VERSION``, its declaration is inconsistent, its name is taken) is
one line in ``Discovery.broken`` naming it, and every other engine still runs. A built-in
engine whose entry point is missing from the installed metadata (an editable install made
before the entry points existed) is loaded from ``BUILTIN_ENGINES``, the same values.
"""

from __future__ import annotations

import functools
import importlib
import importlib.metadata
import importlib.util
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

API_VERSION = 1
"""The adapter contract's version. A declaration states the version it was written for;
discovery refuses any other (the contract changes incompatibly only with a new number)."""

ENTRY_POINT_GROUP = "physval.engines"
"""The entry point group engines register under (``[project.entry-points."physval.engines"]``)."""

BUILTIN_ENGINES: dict[str, str] = {
    "mini": "validation.engines.mini.declaration:DECLARATION",
    "mujoco": "validation.engines.mujoco.declaration:DECLARATION",
    "pybullet": "validation.engines.pybullet.declaration:DECLARATION",
    "rapier": "validation.engines.rapier.declaration:DECLARATION",
    "drake": "validation.engines.drake.declaration:DECLARATION",
}
"""The built-in engines' entry points, exactly as physval's pyproject.toml registers them;
used only for a built-in whose entry point the installed metadata lacks."""

ENGINE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
"""An engine's (and an option's) name: a spec word, ``name(key=value)``."""


class Count(int):
    """A setting that counts something (solver iterations): a whole number >= 1. Engines take
    a non-positive count silently (MuJoCo's -5 iterations make a scene unstable, PyBullet's -1
    falls back to 50), so it is refused here, in every engine's spec."""


OPTION_TYPES = (str, Count, int, float, bool)
"""The types an option can have; ``str`` options list their accepted words in ``choices``."""


@dataclass(frozen=True)
class EngineOption:
    """One setting an engine spec can carry: ``name(key=value)``.

    Attributes:
        name: the key, a spec word.
        type: one of ``OPTION_TYPES``; ``str`` takes one of ``choices``.
        choices: the accepted words of a ``str`` option (empty otherwise).
        default: the value used when a spec omits the key, or None when it depends on
            another option (a ``profile``); ``meaning`` then says on what.
        meaning: one line: what the option changes.
        example: a valid value other than the default for a number option, which the
            conformance suite writes to check that the option reaches the provenance (a word
            option's other choices are used instead).
    """

    name: str
    type: type
    meaning: str
    choices: tuple[str, ...] = ()
    default: object | None = None
    example: object | None = None

    @property
    def accepted(self) -> tuple[str, ...] | type:
        """The option as spec parsing reads it: the words, or the number type."""
        return self.choices if self.type is str else self.type


BASE_SHAPES = ("sphere", "box", "capsule")
"""The shapes of the first adapter contract: an engine that declares no ``shapes`` builds
these (``Capabilities.shapes``' default), so an adapter written before cylinders (a plugin) is
never asked to build one."""

SHAPES = (*BASE_SHAPES, "cylinder")
"""Every body shape of the scenario format (capability words): a cylinder only where a
declaration names it."""

MODEL_LOADERS = ("native", "physval")
"""How an engine gets a scene's ``models`` (issue 36): ``native``, its own loader reads the file
(MuJoCo's compiler, PyBullet's ``loadURDF``/``loadMJCF``, Drake's ``Parser``), so what each
loader makes of the file is judged; ``physval``, the bodies and joints physval expanded the file
into, so only the solver differs."""

MODEL_LOADER_OPTION = EngineOption(
    "model_loader",
    str,
    "native: the engine's own loader reads a scene's models; physval: physval's reading of them",
    MODEL_LOADERS,
    "native",
)
"""The option of engines with a native loader (MuJoCo, PyBullet, Drake); an engine without
it builds models from physval's reading (mini, Rapier, plugins)."""


def model_loader(engine: str, settings: dict) -> str:
    """The loader an engine spec chooses: its ``model_loader`` setting, else its declaration's
    default, else ``physval`` (an engine without the option)."""
    if "model_loader" in settings:
        return str(settings["model_loader"])
    options = {option.name: option for option in declaration_of(engine).options}
    option = options.get(MODEL_LOADER_OPTION.name)
    return str(option.default) if option is not None else "physval"


BASE_FEATURES: dict[str, str] = {
    "ground": "a static ground plane",
    "tilted_ground": "a ground plane whose normal is not +z",
    "contacts": "contacts: a ground, or two or more bodies that may touch",
    "fixed_bodies": "static (fixed) bodies",
    "springs": "spring-dampers between two bodies or a body and the world",
    "loads": "constant applied forces and torques (world frame)",
    "restitution": "a coefficient of restitution e > 0 on a contact",
    "friction": "Coulomb friction μ > 0 on a contact",
}
"""The features of the first adapter contract: an engine that declares no ``features`` has
these (``Capabilities.features``' default)."""

JOINT_FEATURES: dict[str, str] = {
    "joints": "joints (hinge, slider, ball, fixed) between bodies or a body and the world",
    "joint_limits": "lower and upper limits on a hinge or slider",
}
"""Features added with joints: an engine has them only where its declaration names them, so
an adapter written before them (a plugin) is never asked to build a joint it cannot."""

MODEL_FEATURES: dict[str, str] = {
    "non_colliding": "bodies that take part in no contact (collides: false: a model's links "
    "with collisions: false)",
    "placed_shapes": "shapes placed off the centre of mass or turned from the body axes "
    "(a shape's offset and orientation: a model's collision shapes)",
}
"""Features of scenes with robot models (issue 36), claimed only where a declaration names
them (an engine that ignored ``collides: false`` would collide what the scene keeps apart)."""

FEATURES: dict[str, str] = {**BASE_FEATURES, **JOINT_FEATURES, **MODEL_FEATURES}
"""Every scene feature an engine may lack, with its meaning (``validation.scenario.needs``
says which a scene uses). Shapes are capabilities too, named as in ``SHAPES``."""

PRECISIONS = ("float64", "float32")
"""The floating-point type an engine computes in; it sets the parity gate's tolerance
(``validation.engines.parity.PRECISION_TOLERANCE``)."""

STEPPING = ("fixed", "error_controlled")
"""``fixed``: ``advance(n)`` takes n steps of the scene's dt. ``error_controlled``: the engine
chooses its own steps to a stated accuracy and ``advance(n)`` reaches the time n·dt (dt is
the observation interval); ``advance(n)`` then equals n × ``advance(1)`` only to that
accuracy (``Capabilities.advance_tolerance``)."""


@dataclass(frozen=True)
class Capabilities:
    """What an engine can represent, as data: a scene needing anything else is not run in it
    (its rows are ``unsupported``, with the reason), never approximated silently.

    Attributes:
        shapes: the body shapes it builds (of ``SHAPES``; default ``BASE_SHAPES``).
        features: the scene features it represents (keys of ``FEATURES``; default
            ``BASE_FEATURES``, joints only where named).
        integrators: the time integration schemes it offers, as its options name them
            (shown by ``physval list``; a scene never requires one).
        precision: one of ``PRECISIONS``.
        stepping: one of ``STEPPING``.
        advance_tolerance: relative; how closely ``advance(n)`` must equal n × ``advance(1)``
            (0: exactly, a fixed-step engine repeats the same arithmetic; an error-controlled
            engine states its accuracy).
        substeps: state updates per scene step (1 unless the engine substeps); a float32
            engine's rows count steps × substeps roundings in their resolution floor
            (``validation.measure.resolution``).
    """

    shapes: tuple[str, ...] = BASE_SHAPES
    features: frozenset[str] = frozenset(BASE_FEATURES)
    integrators: tuple[str, ...] = ()
    precision: str = "float64"
    stepping: str = "fixed"
    advance_tolerance: float = 0.0
    substeps: int = 1

    @property
    def supported(self) -> frozenset[str]:
        """Every capability word it has: its shapes and its features."""
        return frozenset(self.shapes) | self.features


@dataclass(frozen=True)
class EngineDeclaration:
    """An engine, declared without importing it.

    Attributes:
        name: the engine's spec name (``mujoco``), the entry point's name.
        api_version: the ``API_VERSION`` it was written for.
        adapter: ``module:Class`` of its ``EngineAdapter``, imported on first use; the class
            takes the ``EngineSpec`` and nothing else.
        distribution: the installed distribution whose version is the engine's version.
        summary: one line: what the engine is.
        options: the settings a spec may carry.
        capabilities: what it can represent.
        check_settings: the engine's own validation of a spec's settings (a dict), raising
            ``ValueError`` with one line for values the types alone cannot refuse; or None.
        capabilities_for: the capabilities under a spec's settings (a dict), for an engine
            whose options change them (a discrete and an error-controlled profile); None:
            ``capabilities`` whatever the spec. ``capabilities`` is what ``physval list``
            shows.
        requires: the modules the adapter imports that may be missing (an optional extra);
            a spec naming the engine while one is missing is refused with ``install``,
            found without importing anything (``importlib.util.find_spec``).
        install: the command that installs what ``requires`` names.
    """

    name: str
    api_version: int
    adapter: str
    distribution: str
    summary: str
    options: tuple[EngineOption, ...] = ()
    capabilities: Capabilities = field(default_factory=Capabilities)
    check_settings: Callable[[dict[str, object]], None] | None = None
    capabilities_for: Callable[[dict[str, object]], Capabilities] | None = None
    requires: tuple[str, ...] = ()
    install: str = ""

    def missing(self) -> tuple[str, ...]:
        """The modules of ``requires`` that are not installed (none imported to find out)."""
        return tuple(module for module in self.requires if importlib.util.find_spec(module) is None)

    def capabilities_of(self, settings: dict[str, object]) -> Capabilities:
        """The capabilities of the spec with these ``settings``."""
        if self.capabilities_for is None:
            return self.capabilities
        return self.capabilities_for(settings)

    def option(self, key: str) -> EngineOption | None:
        return next((o for o in self.options if o.name == key), None)

    def load_adapter(self) -> type:
        """The adapter class (imports the engine)."""
        module_name, _, class_name = self.adapter.partition(":")
        return getattr(importlib.import_module(module_name), class_name)


def declaration_problems(declaration: object) -> list[str]:
    """Why ``declaration`` is not a usable ``EngineDeclaration`` (empty if it is)."""
    if not isinstance(declaration, EngineDeclaration):
        return [f"expected an EngineDeclaration; got {type(declaration).__name__}"]
    if declaration.api_version != API_VERSION:
        return [
            f"written for adapter API version {declaration.api_version!r}; "
            f"this physval has version {API_VERSION}"
        ]
    problems = []
    if not isinstance(declaration.name, str) or not ENGINE_NAME.match(declaration.name):
        problems.append(f"name {declaration.name!r} is not a spec word")
    if not re.fullmatch(r"[\w.]+:[\w]+", str(declaration.adapter)):
        problems.append(f"adapter {declaration.adapter!r} is not module:Class")
    for option in declaration.options:
        problems += [f"option {option.name!r}: {p}" for p in _option_problems(option)]
    names = [option.name for option in declaration.options]
    problems += [
        f"option {n!r} declared twice" for n in sorted({n for n in names if names.count(n) > 1})
    ]
    problems += _capability_problems(declaration.capabilities)
    return problems


def _option_problems(option: EngineOption) -> list[str]:
    if not isinstance(option.name, str) or not ENGINE_NAME.match(option.name):
        return ["not a spec word"]
    if option.type not in OPTION_TYPES:
        return [f"type {option.type!r} is not one of str, Count, int, float, bool"]
    if option.type is str and not option.choices:
        return ["a word option without choices"]
    if option.type is str and option.default is not None and option.default not in option.choices:
        return [f"default {option.default!r} is not one of its choices"]
    if not isinstance(option.meaning, str) or not option.meaning.strip():
        return ["no meaning"]
    return []


def _capability_problems(capabilities: object) -> list[str]:
    if not isinstance(capabilities, Capabilities):
        return [f"capabilities: expected Capabilities; got {type(capabilities).__name__}"]
    problems = [f"unknown shape {s!r}" for s in capabilities.shapes if s not in SHAPES]
    problems += [f"unknown feature {f!r}" for f in sorted(capabilities.features - set(FEATURES))]
    if capabilities.precision not in PRECISIONS:
        problems.append(
            f"precision {capabilities.precision!r} is not one of {', '.join(PRECISIONS)}"
        )
    if capabilities.stepping not in STEPPING:
        problems.append(f"stepping {capabilities.stepping!r} is not one of {', '.join(STEPPING)}")
    tolerance = capabilities.advance_tolerance
    if not isinstance(tolerance, int | float) or not math.isfinite(tolerance) or tolerance < 0:
        problems.append(f"advance_tolerance {tolerance!r} is not a finite number >= 0")
    return problems


@dataclass(frozen=True)
class Discovery:
    """The installed engines: ``engines`` by name (built-ins first, then plugins by name) and
    one line per broken plugin (``broken``, by name in ``broken_names``)."""

    engines: Mapping[str, EngineDeclaration]
    broken: tuple[str, ...] = ()
    broken_names: Mapping[str, str] = field(default_factory=dict)


def _distribution_of(entry: importlib.metadata.EntryPoint) -> str:
    dist = getattr(entry, "dist", None)
    return dist.metadata["Name"] if dist is not None else "?"


def _load(name: str, value: str, source: str) -> tuple[EngineDeclaration | None, str]:
    """The declaration at ``value`` (``module:attribute``), or None and the one-line reason."""
    where = f"engine plugin {name!r} ({value}, from {source})"
    try:
        entry = importlib.metadata.EntryPoint(name, value, ENTRY_POINT_GROUP)
        declaration = entry.load()
    except Exception as error:  # a plugin's import error is its line, not physval's crash
        return None, f"{where}: does not load: {type(error).__name__}: {error}"
    problems = declaration_problems(declaration)
    if not problems and declaration.name != name:
        problems = [f"declares the name {declaration.name!r}, registered as {name!r}"]
    if problems:
        return None, f"{where}: {'; '.join(problems)}"
    return declaration, ""


PHYSVAL = "physval"
"""The distribution whose entry points are the built-in engines: they come first, so a plugin
cannot take a built-in's name."""


def _registered() -> list[tuple[str, str, str]]:
    """(name, value, distribution) of every entry point of the group, plus the built-ins the
    installed metadata lacks; physval's own first (in ``BUILTIN_ENGINES`` order), then the
    plugins by name."""
    found = [
        (entry.name, entry.value, _distribution_of(entry))
        for entry in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    ]
    own = {name for name, _, source in found if source == PHYSVAL}
    found += [(n, v, PHYSVAL) for n, v in BUILTIN_ENGINES.items() if n not in own]
    order = list(BUILTIN_ENGINES)

    def key(entry: tuple[str, str, str]) -> tuple:
        name, _, source = entry
        return (source != PHYSVAL, order.index(name) if name in order else len(order), name)

    return sorted(found, key=key)


@functools.cache
def discover() -> Discovery:
    """Every installed engine, loaded once per process (``Discovery``)."""
    engines: dict[str, EngineDeclaration] = {}
    sources: dict[str, str] = {}
    broken: list[str] = []
    broken_names: dict[str, str] = {}
    for name, value, source in _registered():
        if name in engines:
            line = (
                f"engine plugin {name!r} ({value}, from {source}): the name is taken by "
                f"{sources[name]}; ignored"
            )
            broken.append(line)
            continue
        declaration, problem = _load(name, value, source)
        if declaration is None:
            broken.append(problem)
            broken_names.setdefault(name, problem)
            continue
        engines[name], sources[name] = declaration, source
    return Discovery(engines, tuple(broken), broken_names)


def declarations() -> Mapping[str, EngineDeclaration]:
    """Name -> declaration of every engine that loaded."""
    return discover().engines


def declaration_of(name: str) -> EngineDeclaration:
    """The declaration of an installed engine (``KeyError`` for an unknown name)."""
    return discover().engines[name]
