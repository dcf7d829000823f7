"""Problems: one thing wrong in a scenario file, as ``file:line:column: field: message``,
with pydantic's errors translated into that form (and a "did you mean")."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from validation.scenario.schema import (
    EXPECTATION_MODELS,
    BodySpec,
    BoxShape,
    CapsuleShape,
    CylinderShape,
    GroundSpec,
    PairSpec,
    Scenario,
    SphereShape,
    SpringSpec,
)
from validation.scenario.suggest import did_you_mean
from validation.scenario.yaml_source import SourceMap

UNPRINTABLE = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")
"""Characters a line of text must not print raw: C0 and C1 controls (a newline would split
one message into two lines, ESC starts a sequence that drives the terminal), Unicode's line
separators, and the surrogates a file name's undecodable bytes become."""


def printable(text: object) -> str:
    """``text`` with every ``UNPRINTABLE`` character written as its Python escape (``\\n``,
    ``\\x1b``, ``\\udcff``): a folder or file name printed in a terminal, a log or a one-line
    message stays on its line and says exactly what it is."""
    return UNPRINTABLE.sub(lambda found: repr(found.group())[1:-1], str(text))


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
        return printable(f"{where}:{kind}{field} {self.message}")


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


UNION_MEMBER = re.compile(r"[\[\]\-,]|^(float|int|str|bool|list|dict|tuple)$")
"""How pydantic names the member of a plain union in an error's location
(``constrained-float``, ``dict[str,constrained-float]``): not a field of the file."""


def _is_union_member(node: Any, part: str | int) -> bool:
    return isinstance(part, str) and not _has(node, part) and bool(UNION_MEMBER.search(part))


def _clean_loc(data: Any, loc: tuple) -> tuple[str | int, ...]:
    """Drop what pydantic adds to a location that is not a field: the tag of a tagged
    union (``shape.sphere.radius`` -> ``shape.radius``), the member of a plain union
    (``checks.x.constrained-float`` -> ``checks.x``) and validator names."""
    clean: list[str | int] = []
    node = data
    for part in loc:
        if isinstance(part, str) and part.startswith("function-"):
            continue
        if _is_union_member(node, part):
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


_SHAPES = {
    "sphere": SphereShape,
    "box": BoxShape,
    "capsule": CapsuleShape,
    "cylinder": CylinderShape,
}
_EXPECTATIONS = {
    model.model_fields["kind"].annotation.__args__[0]: model for model in EXPECTATION_MODELS
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


SHAPE_EXAMPLE = (
    "{type: sphere, radius: 0.1}, {type: box, half_extents: [0.1, 0.1, 0.1]}, "
    "{type: capsule, radius: 0.05, half_length: 0.2} or "
    "{type: cylinder, radius: 0.05, half_length: 0.2}"
)
TOLERANCE_EXAMPLE = "a number such as 1.0e-3, or per engine: {default: 1.0e-3, mujoco: 1.0e-6}"
MAPPING_HINTS = {
    ("bodies", "#", "shape"): f"a mapping such as {SHAPE_EXAMPLE}",
    ("ground",): "a mapping such as {normal: [0, 0, 1], restitution: 0.5, friction: 0.3} "
    "(leave ground out for a scene with no ground)",
    ("checks", "*"): TOLERANCE_EXAMPLE,
    ("sweep",): "a mapping such as {dt: [4.0e-3, 2.0e-3, 1.0e-3]}",
}
"""What a field that takes a mapping (or a choice of forms) expects, in the file's own syntax:
said instead of pydantic's type names when a value has the wrong form."""

MAPPING_ERRORS = ("model_type", "model_attributes_type", "dict_type")
"""pydantic's error types for "a mapping was expected here"."""


def _hint_at(loc: tuple) -> str | None:
    """The ``MAPPING_HINTS`` entry of a location (indices as ``#``, a ``checks`` key as ``*``)."""
    pattern = tuple("#" if isinstance(p, int) else p for p in loc)
    if len(pattern) == 2 and pattern[0] == "checks":
        pattern = ("checks", "*")
    return MAPPING_HINTS.get(pattern)


def _text_number_hint(value: Any) -> str:
    """A hint when a number was written as text (quoted): the usual YAML slip."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        return f" (a quoted string: write {value.strip()} without quotes)"
    return ""


def _expected(error: dict, loc: tuple) -> str:
    """What the field expects, in plain words: the location's hint for a value of the wrong
    form, else pydantic's words."""
    hint = _hint_at(loc)
    if hint and (error["type"] in MAPPING_ERRORS or loc[:1] == ("checks",)):
        return hint
    return error["msg"].removeprefix("Input should be ").lower()


def _schema_problem(error: dict, data: Any, file: str, source: SourceMap) -> Problem:
    """One pydantic error as a ``Problem`` with the field path, expectation and found value."""
    loc = _clean_loc(data, error["loc"])
    kind = error["type"]
    found = _found(error.get("input"))
    if kind == "extra_forbidden":
        key = loc[-1]
        allowed = _allowed_keys(data, loc[:-1])
        hint = did_you_mean(str(key), allowed) or f"; expected one of {', '.join(allowed)}"
        message = f"unknown field {key!r}{hint}"
    elif kind == "missing":
        message = "required field is missing"
    elif kind == "union_tag_invalid":
        context = error["ctx"]
        loc = (*loc, context["discriminator"].strip("'"))
        tags = re.findall(r"'([^']*)'", context["expected_tags"])
        message = f"expected one of {context['expected_tags']}; got {context['tag']!r}"
        message += did_you_mean(context["tag"], tags)
    elif kind == "union_tag_not_found":
        message = f"required field {error['ctx']['discriminator']} is missing"
    elif kind == "value_error":
        message = str(error["ctx"]["error"]) if "ctx" in error else error["msg"]
    else:
        message = f"expected {_expected(error, loc)}; got {found}"
        message += _text_number_hint(error.get("input"))
    position = source.locate(loc)
    return Problem(file, path_text(loc), message, *(position or (None, None)))


def merged(problems: list[Problem]) -> list[Problem]:
    """One problem per place: the errors pydantic gives for each member of a union at one
    field (a tolerance that is neither a number nor a mapping) said once."""
    by_place: dict[tuple, Problem] = {}
    for problem in problems:
        place = (problem.file, problem.path, problem.line, problem.column, problem.warning)
        first = by_place.get(place)
        if first is None:
            by_place[place] = problem
        elif problem.message != first.message and problem.message not in first.message:
            by_place[place] = replace(first, message=f"{first.message}; {problem.message}")
    return list(by_place.values())
