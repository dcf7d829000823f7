"""The scenario format (version 1): schema, loader, and problems that name file, line and field.

A scenario is a YAML file; SI units, world frame, z up, quaternions w x y z.
``load_scenario(path)`` returns a frozen, validated ``Scenario`` with every default
filled in, or raises ``ScenarioError`` carrying *every* problem found, each as
``file:line:column: field.path: what was expected; what was found``.

Schema: pydantic models (``extra="forbid"``, numbers strict and finite), so the
JSON Schema that editors use (``physval schema``) comes from the same source as the
loader. Checks that need the whole document (unique names, references between
fields, engine specs, step limits) run after the schema and report in the same form.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
    field_validator,
)

import mini_engine.model as _model
from validation.engine_spec import DEFAULT_ENGINES, EngineSpec, EngineSpecError, parse_engine_spec
from validation.yaml_source import SourceMap, YamlSourceError, read_yaml

FORMAT_VERSION = 1

MAX_STEPS = 5_000_000
"""Largest duration / dt a scenario may ask for: 50 s at dt = 1e-5, or about an hour of
mini_engine time for a one-body scene. Longer runs are a typo (dt: 1e-7) more often than not."""

# One definition each, shared with mini_engine's model builder: an orientation within 1e-6
# of unit norm is normalised, an inertia within 1e-9 (relative) of symmetric is symmetrised.
UNIT_QUATERNION_TOLERANCE = _model.UNIT_QUATERNION_TOLERANCE
SYMMETRY_TOLERANCE = _model.SYMMETRY_TOLERANCE

METRIC_NAMES = (
    "energy_drift",
    "angular_momentum_drift",
    "linear_momentum_drift",
    "position_error",
    "velocity_error",
    "restitution_error",
    "penetration_max",
    "divergence",
)
"""The metrics a ``checks`` entry may name besides the scene's own expectations (issue 5)."""

# --- field types -------------------------------------------------------------------------

Finite = Annotated[float, Strict(), AllowInfNan(False)]
Positive = Annotated[float, Strict(), AllowInfNan(False), Field(gt=0)]
NonNegative = Annotated[float, Strict(), AllowInfNan(False), Field(ge=0)]
UnitInterval = Annotated[float, Strict(), AllowInfNan(False), Field(ge=0, le=1)]
Vec3 = tuple[Finite, Finite, Finite]
PositiveVec3 = tuple[Positive, Positive, Positive]
Name = Annotated[str, Strict(), Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SphereShape(_Strict):
    """A solid sphere."""

    type: Literal["sphere"]
    radius: Positive = Field(description="m")


class BoxShape(_Strict):
    """A solid box; half extents along the body axes."""

    type: Literal["box"]
    half_extents: PositiveVec3 = Field(description="m, (hx, hy, hz)")


class CapsuleShape(_Strict):
    """A solid capsule along body z: a cylinder of 2*half_length plus two hemispheres."""

    type: Literal["capsule"]
    radius: Positive = Field(description="m")
    half_length: Positive = Field(description="m, half the cylinder's length")


ShapeSpec = Annotated[SphereShape | BoxShape | CapsuleShape, Field(discriminator="type")]


def _inertia_matrix(value: Any) -> np.ndarray:
    """3 principal moments or a symmetric 3x3 -> (3, 3), or ValueError saying what was expected."""
    expected = "3 positive moments [Ixx, Iyy, Izz] or a symmetric 3x3 matrix, kg·m²"
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"expected {expected}; got {value!r}") from None
    if any(isinstance(v, bool | str) for v in np.asarray(value, dtype=object).ravel()):
        raise ValueError(f"expected {expected}; got {value!r}")
    if array.shape == (3,):
        array = np.diag(array)
    if array.shape != (3, 3) or not np.isfinite(array).all():
        raise ValueError(f"expected {expected}; got {value!r}")
    if np.abs(array - array.T).max() > SYMMETRY_TOLERANCE * np.abs(array).max():
        raise ValueError(f"expected a symmetric matrix; got {array.tolist()}")
    array = 0.5 * (array + array.T)  # the accepted round-off asymmetry removed, once, here
    moments = np.linalg.eigvalsh(array)
    if moments.min() <= 0:
        raise ValueError(
            f"expected positive definite (principal moments > 0); got {moments.tolist()}"
        )
    a, b, c = sorted(moments)
    if a + b < c * (1 - SYMMETRY_TOLERANCE):
        raise ValueError(
            f"principal moments {moments.tolist()} break the triangle inequality "
            "(A + B >= C): no rigid body has them"
        )
    return array


class BodySpec(_Strict):
    """One rigid body."""

    name: Name = Field(description="unique in the scene")
    shape: ShapeSpec
    mass: Positive = Field(description="kg")
    inertia: list[Any] | None = Field(
        default=None,
        description="kg·m², body frame about the centre of mass: [Ixx, Iyy, Izz] or a full 3x3; "
        "default: the solid shape",
    )
    position: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m, world frame, centre of mass")
    orientation: tuple[Finite, Finite, Finite, Finite] = Field(
        default=(1.0, 0.0, 0.0, 0.0), description="unit quaternion w x y z, body to world"
    )
    velocity: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m/s, world frame, centre of mass")
    angular_velocity: Vec3 = Field(default=(0.0, 0.0, 0.0), description="rad/s, world frame")
    restitution: UnitInterval = 0.0
    friction: NonNegative = Field(default=0.0, description="Coulomb μ; 0 is frictionless")
    fixed: Annotated[bool, Strict()] = Field(default=False, description="a static body")

    @field_validator("inertia")
    @classmethod
    def _check_inertia(cls, value: list[Any] | None) -> list[Any] | None:
        if value is not None:
            _inertia_matrix(value)
        return value

    @field_validator("orientation")
    @classmethod
    def _unit_quaternion(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        norm = math.sqrt(sum(v * v for v in value))
        if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
            raise ValueError(
                f"expected a unit quaternion w x y z (norm within {UNIT_QUATERNION_TOLERANCE} of 1); "
                f"got norm {norm:.9g}"
            )
        return tuple(v / norm for v in value)

    @cached_property
    def inertia_matrix(self) -> np.ndarray | None:
        """(3, 3) kg·m² body frame, or None for the solid shape's."""
        return None if self.inertia is None else _inertia_matrix(self.inertia)


class GroundSpec(_Strict):
    """A static infinite plane z = 0 with normal +z."""

    restitution: UnitInterval = 0.0
    friction: NonNegative = 0.0


class SpringSpec(_Strict):
    """A linear spring-damper between two bodies, or a body and a world point."""

    a: Name = Field(description="a body name")
    b: Name = Field(description="a body name, or 'world'")
    anchor_a: Vec3 = Field(default=(0.0, 0.0, 0.0), description="m, in a's body frame")
    anchor_b: Vec3 = Field(
        default=(0.0, 0.0, 0.0), description="m, in b's body frame (world: a point)"
    )
    stiffness: NonNegative = Field(description="N/m")
    damping: NonNegative = Field(default=0.0, description="N·s/m")
    rest_length: NonNegative | None = Field(
        default=None,
        description="m; default: the anchors' distance at t = 0 (the spring starts at rest)",
    )


class PairSpec(_Strict):
    """Contact values for one pair that replace the mixing rules."""

    a: Name
    b: Name = Field(description="a body name, or 'ground'")
    restitution: UnitInterval | None = None
    friction: NonNegative | None = None


# --- analytic expectations ---------------------------------------------------------------


class _Expectation(_Strict):
    name: Name | None = Field(default=None, description="metric name; default '<kind>.<body>'")
    body: Name

    @property
    def metric(self) -> str:
        return self.name or f"{self.kind}.{self.body}"


class VelocityAfterImpact(_Expectation):
    """Centre-of-mass velocity of ``body`` just after its first impact (closed-form collision)."""

    kind: Literal["velocity_after_impact"]
    value: Vec3 = Field(description="m/s, world frame")


class PositionAt(_Expectation):
    """Centre-of-mass position of ``body`` at ``time``."""

    kind: Literal["position_at"]
    time: NonNegative = Field(description="s")
    value: Vec3 = Field(description="m, world frame")


class VelocityAt(_Expectation):
    """Centre-of-mass velocity of ``body`` at ``time``."""

    kind: Literal["velocity_at"]
    time: NonNegative = Field(description="s")
    value: Vec3 = Field(description="m/s, world frame")


class BounceHeights(_Expectation):
    """Apex heights of the centre of mass after successive bounces (e² h for a drop)."""

    kind: Literal["bounce_heights"]
    value: list[Positive] = Field(min_length=1, description="m")


class PrecessionRate(_Expectation):
    """Body-frame precession rate of a torque-free axisymmetric body: (I3 - I1)/I1 · ω3."""

    kind: Literal["precession_rate"]
    value: Finite = Field(description="rad/s")


class Flips(_Expectation):
    """How often a body spun near its intermediate axis flips over the run (Dzhanibekov)."""

    kind: Literal["flips"]
    axis: Literal["x", "y", "z"] = Field(default="y", description="body axis whose sign flips")
    value: Annotated[int, Strict(), Field(ge=0)]


Expectation = Annotated[
    VelocityAfterImpact | PositionAt | VelocityAt | BounceHeights | PrecessionRate | Flips,
    Field(discriminator="kind"),
]

Tolerance = NonNegative | dict[str, NonNegative]


class Scenario(_Strict):
    """A scene, version 1. Defaults are the documented ones below each field."""

    version: Literal[1] = FORMAT_VERSION
    name: Name | None = Field(default=None, description="default: the file name without .yaml")
    description: str = Field(default="", description="what the scene stresses and why")
    dt: Positive = Field(description="s, the fixed step")
    duration: Positive = Field(description="s, >= dt")
    gravity: Vec3 = Field(default=(0.0, 0.0, -9.81), description="m/s², world frame")
    ground: GroundSpec | None = Field(default=None, description="the static plane z = 0, normal +z")
    engines: list[Annotated[str, Strict()]] = Field(
        default=list(DEFAULT_ENGINES),
        min_length=1,
        description="engine specs, e.g. mini(gyroscopic=implicit)",
    )
    bodies: list[BodySpec] = Field(min_length=1)
    springs: list[SpringSpec] = []
    pairs: list[PairSpec] = Field(default=[], description="per-pair restitution/friction overrides")
    expect: list[Expectation] = Field(default=[], description="analytic expectations")
    checks: dict[str, Tolerance] = Field(
        default={},
        description="tolerance per metric: one number, or {default: x, <engine spec>: y} "
        "(an engine entry applies to exactly that spec as written in engines)",
    )
    source: str = Field(default="", exclude=True, description="the file it was loaded from")

    @property
    def steps(self) -> int:
        return round(self.duration / self.dt)

    @cached_property
    def engine_specs(self) -> tuple[EngineSpec, ...]:
        return tuple(parse_engine_spec(text) for text in self.engines)

    def body(self, name: str) -> BodySpec:
        return next(b for b in self.bodies if b.name == name)

    def tolerance(self, metric: str, engine: str) -> float | None:
        """The tolerance of ``metric`` for the engine spec labelled ``engine``, or None.

        A per-engine entry applies to exactly that spec (``mini`` is the plain mini, not
        ``mini(gyroscopic=explicit)``); every other spec takes ``default``.
        """
        value = self.checks.get(metric)
        if value is None or isinstance(value, float | int):
            return value
        return value.get(engine, value.get("default"))


# --- problems ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """One thing wrong (or, with ``warning``, suspicious) in a scenario file."""

    file: str
    path: str
    message: str
    line: int | None = None
    column: int | None = None
    warning: bool = False

    def __str__(self) -> str:
        where = self.file + (f":{self.line}:{self.column}" if self.line else "")
        field = f" {self.path}:" if self.path else ""
        kind = " warning:" if self.warning else ""
        return f"{where}:{kind}{field} {self.message}"


class ScenarioError(ValueError):
    """A scenario that cannot be loaded; ``problems`` holds every reason."""

    def __init__(self, problems: list[Problem]):
        super().__init__("\n".join(str(p) for p in problems))
        self.problems = problems


def path_text(loc: tuple[str | int, ...]) -> str:
    """``("bodies", 1, "shape", "radius")`` -> ``bodies[1].shape.radius``."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _found(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _has(node: Any, part: str | int) -> bool:
    return (isinstance(node, dict) and part in node) or (
        isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)
    )


def _clean_loc(data: Any, loc: tuple) -> tuple[str | int, ...]:
    """Drop what pydantic adds to a location that is not a field: the tag of a tagged
    union (``shape.sphere.radius`` -> ``shape.radius``) and validator names."""
    clean: list[str | int] = []
    node = data
    for part in loc:
        if isinstance(part, str) and part.startswith("function-"):
            continue
        if (
            isinstance(node, dict)
            and not _has(node, part)
            and part in (node.get("type"), node.get("kind"))
        ):
            continue
        clean.append(part)
        node = node[part] if _has(node, part) else None
    return tuple(clean)


def _node_at(data: Any, loc: tuple) -> Any:
    for part in loc:
        data = data[part] if _has(data, part) else None
    return data


_SHAPES = {"sphere": SphereShape, "box": BoxShape, "capsule": CapsuleShape}
_EXPECTATIONS = {
    model.model_fields["kind"].annotation.__args__[0]: model
    for model in (VelocityAfterImpact, PositionAt, VelocityAt, BounceHeights, PrecessionRate, Flips)
}
_MODEL_AT = {
    (): lambda node: Scenario,
    ("bodies", "#"): lambda node: BodySpec,
    ("bodies", "#", "shape"): lambda node: _SHAPES.get(node.get("type")),
    ("ground",): lambda node: GroundSpec,
    ("springs", "#"): lambda node: SpringSpec,
    ("pairs", "#"): lambda node: PairSpec,
    ("expect", "#"): lambda node: _EXPECTATIONS.get(node.get("kind")),
}
"""Which schema model validates the mapping at a location (for "did you mean")."""


def _allowed_keys(data: Any, loc: tuple) -> list[str]:
    pattern = tuple("#" if isinstance(p, int) else p for p in loc)
    node = _node_at(data, loc)
    chooser = _MODEL_AT.get(pattern)
    model = chooser(node if isinstance(node, dict) else {}) if chooser else None
    return [k for k in model.model_fields if k != "source"] if model else []


def _schema_problem(error: dict, data: Any, file: str, source: SourceMap) -> Problem:
    """One pydantic error as a ``Problem`` with the field path, expectation and found value."""
    loc = _clean_loc(data, error["loc"])
    kind = error["type"]
    found = _found(error.get("input"))
    if kind == "extra_forbidden":
        key = loc[-1]
        allowed = _allowed_keys(data, loc[:-1])
        close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.5)
        hint = (
            f"; did you mean {close[0]!r}?" if close else f"; expected one of {', '.join(allowed)}"
        )
        message = f"unknown field {key!r}{hint}"
    elif kind == "missing":
        message = "required field is missing"
    elif kind == "union_tag_invalid":
        context = error["ctx"]
        loc = (*loc, context["discriminator"].strip("'"))
        message = f"expected one of {context['expected_tags']}; got {context['tag']!r}"
    elif kind == "union_tag_not_found":
        message = f"required field {error['ctx']['discriminator']} is missing"
    elif kind == "value_error":
        message = str(error["ctx"]["error"]) if "ctx" in error else error["msg"]
    else:
        message = f"expected {error['msg'].removeprefix('Input should be ').lower()}; got {found}"
    position = source.locate(loc)
    return Problem(file, path_text(loc), message, *(position or (None, None)))


def _cross_problems(scenario: Scenario, file: str, source: SourceMap) -> list[Problem]:
    """Checks that need the whole document; each reported at its own field."""
    problems: list[tuple[tuple[str | int, ...], str]] = []
    names: dict[str, int] = {}
    for i, body in enumerate(scenario.bodies):
        if body.name in names:
            problems.append(
                (
                    ("bodies", i, "name"),
                    f"duplicate body name {body.name!r} (also bodies[{names[body.name]}])",
                )
            )
        names.setdefault(body.name, i)
        if body.name in ("world", "ground"):
            problems.append(
                (("bodies", i, "name"), f"{body.name!r} is reserved; choose another name")
            )

    def known(name: str, loc: tuple[str | int, ...], extra: tuple[str, ...]) -> None:
        if name not in names and name not in extra:
            close = difflib.get_close_matches(name, [*names, *extra], n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            problems.append(
                (
                    loc,
                    f"expected a body name{' or ' + ' or '.join(repr(e) for e in extra) if extra else ''}; got {name!r}{hint}",
                )
            )

    for i, spring in enumerate(scenario.springs):
        known(spring.a, ("springs", i, "a"), ())
        known(spring.b, ("springs", i, "b"), ("world",))
        if spring.a == spring.b:
            problems.append((("springs", i, "b"), "a spring needs two different ends"))
    for i, pair in enumerate(scenario.pairs):
        known(pair.a, ("pairs", i, "a"), ())
        known(pair.b, ("pairs", i, "b"), ("ground",) if scenario.ground else ())
    metrics = set(METRIC_NAMES)
    for i, expectation in enumerate(scenario.expect):
        known(expectation.body, ("expect", i, "body"), ())
        if expectation.metric in metrics:
            problems.append(
                (("expect", i, "name"), f"metric name {expectation.metric!r} is already taken")
            )
        metrics.add(expectation.metric)
        if getattr(expectation, "time", 0.0) > scenario.duration:
            problems.append(
                (
                    ("expect", i, "time"),
                    f"expected a time within the run (<= {scenario.duration} s)",
                )
            )
    engine_labels: set[str] = set()
    for i, text in enumerate(scenario.engines):
        try:
            label = parse_engine_spec(text).label
        except EngineSpecError as error:
            problems.append((("engines", i), str(error)))
            continue
        if label in engine_labels:
            problems.append((("engines", i), f"engine {label!r} is listed twice"))
        engine_labels.add(label)
    for metric, tolerance in scenario.checks.items():
        if metric not in metrics:
            close = difflib.get_close_matches(metric, sorted(metrics), n=1, cutoff=0.5)
            hint = (
                f"did you mean {close[0]!r}?"
                if close
                else f"expected one of {', '.join(sorted(metrics))}"
            )
            problems.append((("checks", metric), f"unknown metric {metric!r}; {hint}"))
        if isinstance(tolerance, dict):
            for key in tolerance:
                if key != "default" and key not in engine_labels:
                    problems.append(
                        (
                            ("checks", metric, key),
                            f"expected 'default' or an engine of this scene ({', '.join(sorted(engine_labels))}); got {key!r}",
                        )
                    )
    if scenario.duration < scenario.dt:
        problems.append(
            (("duration",), f"expected duration >= dt ({scenario.dt} s); got {scenario.duration} s")
        )
    if scenario.duration / scenario.dt > MAX_STEPS:
        problems.append(
            (
                ("duration",),
                f"{scenario.duration / scenario.dt:.3g} steps (duration / dt); at most {MAX_STEPS} are allowed",
            )
        )
    return [
        Problem(file, path_text(loc), message, *(source.locate(loc) or (None, None)))
        for loc, message in problems
    ]


def _load(path: Path) -> tuple[Scenario | None, list[Problem]]:
    file = str(path)
    try:
        data, source = read_yaml(path)
    except YamlSourceError as error:
        return None, [Problem(file, "", error.message, error.line, error.column)]
    if not isinstance(data, dict):
        return None, [
            Problem(file, "", f"expected a mapping of scenario fields; got {_found(data)}", 1, 1)
        ]
    data = {**data, "source": file}
    if data.get("name") is None:
        data["name"] = path.stem
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as error:
        problems = [_schema_problem(e, data, file, source) for e in error.errors(include_url=False)]
        return None, sorted(problems, key=lambda p: (p.line or 0, p.column or 0))
    problems = _cross_problems(scenario, file, source)
    return (None if problems else scenario), problems


def load_scenario(path: str | Path) -> Scenario:
    """The validated scenario at ``path``; raises ``ScenarioError`` listing every problem."""
    scenario, problems = _load(Path(path))
    if scenario is None:
        raise ScenarioError(problems)
    return scenario


def check_scenario(path: str | Path) -> tuple[Scenario | None, list[Problem]]:
    """The scenario (or None) and all its problems, warnings included (overlaps at t = 0)."""
    scenario, problems = _load(Path(path))
    if scenario is not None:
        from validation.mini_scene import initial_overlaps

        problems += [
            Problem(str(path), f"bodies[{i}]", message, *(None, None), warning=True)
            for i, message in initial_overlaps(scenario)
        ]
    return scenario, problems


def scenario_files(paths: list[str | Path]) -> list[Path]:
    """Every ``*.yaml``/``*.yml`` file named or found (recursively) under the folders, sorted."""
    files: list[Path] = []
    for item in map(Path, paths):
        if item.is_dir():
            files += sorted(p for p in item.rglob("*") if p.suffix in (".yaml", ".yml"))
        else:
            files.append(item)
    return files


def json_schema() -> dict:
    """The JSON Schema of the format (for editors: the YAML language server)."""
    schema = Scenario.model_json_schema()
    schema["properties"].pop("source", None)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "physval scenario, version 1"
    return schema
