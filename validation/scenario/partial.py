"""The part of a document that validated: a file that fails the schema with each failing
entry left out, so the whole-document rules still judge the rest and every problem of the
file shows in one pass (``load``).

What is left out, per schema error at a field path:

- an unknown field: that key (its own problem says which field was meant);
- a failing entry of a list (``bodies[2]``, ``expect[0]``) or of ``checks``: that entry;
- a failing optional top-level field (``gravity``, ``sweep``, ``ground``): the field, its
  default taken;
- anything else (a required top-level field such as ``dt``, a list that is not a list): the
  rules cannot run, as before.

The names a left-out entry declares (a body's, a joint's, an expectation's metric, the ground)
still exist as far as the rules' references go: a reference to one is not reported (the
entry's own problem is). When a part of the scene itself (``SCENE_FIELDS``) was left out, the
scene rules (definability) and the warnings wait: they would judge another scene.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from fnmatch import fnmatchcase
from typing import Any

from pydantic import ValidationError

from validation.scenario.problems import _EXPECTATIONS, _clean_loc
from validation.scenario.schema import Scenario

Location = tuple[str | int, ...]

ENTRY_FIELDS = ("bodies", "springs", "joints", "models", "pairs", "expect", "known", "engines")
"""Top-level lists whose failing entries are left out one by one."""

DROPPABLE_FIELDS = (
    "version",
    "name",
    "description",
    "gravity",
    "ground",
    "springs",
    "pairs",
    "checks",
    "known",
    "sweep",
)
"""Optional top-level fields left out (their default taken) when they fail as a whole: none
declares a name other fields refer to but the ground, whose name is then kept as left out."""

SCENE_FIELDS = frozenset(
    {"gravity", "ground", "engines", "bodies", "springs", "joints", "models", "pairs"}
)
"""The top-level fields the compiled scene and its traits read."""

STAND_IN_BODY = {"name": "stand-in", "shape": {"type": "sphere", "radius": 1.0}, "mass": 1.0}
"""A body the schema accepts, validated in place of a list all of whose bodies failed (the
format needs one) and then removed: the rules see no body."""


REFERENCE_FIELDS = frozenset({"body", "joint", "a", "b", "parent", "child", "metric"})
"""The fields that name a body, a joint or a metric (besides a ``checks`` key)."""


EVERY_NAME = "*"
"""A left-out name that stands for every name (a pattern): the bodies and joints of a model
that failed to expand, which nothing can list."""


@dataclass(frozen=True)
class Partial:
    """The validated part of a document, and what was left out of it."""

    scenario: Scenario
    names: frozenset[str]
    whole_scene: bool
    kept: dict[str, list[int]] = field(default_factory=dict)
    """List field -> the file's index of each entry kept (the part's indices are shifted)."""

    def in_file(self, loc: Location) -> Location:
        """``loc`` of the part as the file's field path (its list index as the file has it)."""
        if len(loc) > 1 and loc[0] in self.kept and isinstance(loc[1], int):
            return (loc[0], self.kept[loc[0]][loc[1]], *loc[2:])
        return loc

    def refers_to_left_out(self, loc: Location) -> bool:
        """Whether the field at ``loc`` names (or, a pattern, matches) something left out:
        a body, joint or expectation metric whose own entry failed the schema (of a mistyped
        kind: any metric of its subject)."""
        referred = [_value_at(self.scenario, loc)] if loc[-1] in REFERENCE_FIELDS else []
        if loc[:1] == ("checks",) and len(loc) > 1:
            referred.append(loc[1])  # a check is named by its key
        return any(
            isinstance(name, str)
            and any(fnmatchcase(gone, name) or fnmatchcase(name, gone) for gone in self.names)
            for name in referred
        )


def _value_at(scenario: Scenario, loc: Location) -> Any:
    node: Any = scenario
    for part in loc:
        if isinstance(part, int):
            node = node[part] if isinstance(node, list | tuple) and part < len(node) else None
        elif isinstance(node, dict):
            node = node.get(part)
        else:
            node = getattr(node, part, None)
    return node


def _declared_name(list_name: str, entry: Any) -> str | None:
    """The name an entry of the list ``list_name`` declares, if it reads as one."""
    if not isinstance(entry, dict):
        return None
    if list_name in ("bodies", "joints"):
        name = entry.get("name")
    elif list_name == "expect":
        subject, kind = entry.get("body", entry.get("joint")), entry.get("kind")
        kind = kind if kind in _EXPECTATIONS else "*"  # a mistyped kind: any of its subject's
        name = entry.get("name") or f"{kind}.{subject}"
    else:
        return None
    return name if isinstance(name, str) else None


def _delete(data: Any, loc: Location) -> None:
    *parents, key = loc
    for part in parents:
        data = data[part] if isinstance(data, dict | list) else None
    if isinstance(data, dict):
        data.pop(key, None)


def _validated(part: dict) -> Scenario | None:
    bodies = part.get("bodies")
    if isinstance(bodies, list) and not bodies:
        scenario = _validated({**part, "bodies": [STAND_IN_BODY]})
        return None if scenario is None else scenario.model_copy(update={"bodies": []})
    try:
        return Scenario.model_validate(part)
    except ValidationError:
        return None


def without_models(scenario: Scenario) -> Partial:
    """A valid document whose ``models`` failed to expand: their bodies and joints are
    missing, so no reference is judged, nor the scene."""
    return Partial(scenario, frozenset({EVERY_NAME}), whole_scene=False)


def validated_part(data: dict, errors: list[dict], models_failed: bool = False) -> Partial | None:
    """The document ``data`` without what failed (``errors``, pydantic's), validated; or
    None when what failed cannot be left out. ``models_failed``: see ``without_models``."""
    part = copy.deepcopy(data)
    unknown: list[Location] = []
    entries: set[tuple[str, str | int]] = set()
    dropped: set[str] = set()
    for error in errors:
        loc = _clean_loc(data, error["loc"])
        if not loc:
            return None
        if error["type"] == "extra_forbidden":
            unknown.append(loc)
        elif len(loc) > 1 and (
            (loc[0] in ENTRY_FIELDS and isinstance(loc[1], int)) or loc[0] == "checks"
        ):
            entries.add((loc[0], loc[1]))
        elif loc == ("bodies",) and error["type"] == "missing" and data.get("models"):
            part["bodies"] = []  # the models' bodies, had they expanded
        elif loc[0] in DROPPABLE_FIELDS:
            dropped.add(str(loc[0]))
        else:
            return None
    for loc in unknown:
        _delete(part, loc)
    names = {"ground"} if "ground" in dropped and data.get("ground") is not None else set()
    for name, key in entries:
        names.add(_declared_name(name, part[name][key]))
    kept: dict[str, list[int]] = {}
    for name in {name for name, _ in entries}:
        keys = {key for entry, key in entries if entry == name}
        if isinstance(part[name], list):
            kept[name] = [i for i in range(len(part[name])) if i not in keys]
            part[name] = [part[name][i] for i in kept[name]]
        else:
            part[name] = {k: v for k, v in part[name].items() if k not in keys}
    for name in dropped:
        part.pop(name, None)
    scenario = _validated(part)
    if scenario is None:
        return None
    touched = {str(loc[0]) for loc in unknown if len(loc) > 1} | dropped
    touched |= {name for name, _ in entries}
    if models_failed:
        return replace(without_models(scenario), kept=kept)
    whole = not touched & SCENE_FIELDS
    return Partial(scenario, frozenset(names - {None}), whole_scene=whole, kept=kept)
