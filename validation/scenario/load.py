"""Loading: a file read strictly, validated by the schema, then by the whole-document
rules; every problem collected in one pass (the rules judge the part of a file that passed
the schema, ``partial``, and the rest of a file whose models failed).

Every load warns: ``load_scenario`` (``physval run``, ``pytest --physval``, ``sweep``, ...)
issues each warning of the rules as a ``ScenarioWarning`` placed at its line of the scene
file, which Python prints on stderr (``file:line: ScenarioWarning: field: message`` and the
YAML line) and pytest lists in its warnings summary; ``check_scenario`` returns them with the
errors, for ``physval check`` to print.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

from pydantic import (
    ValidationError,
)

from validation.bundled import BUNDLED_SCENARIOS, default_scenario_paths  # noqa: F401 (re-exported)
from validation.engine_api import declarations
from validation.scenario.checks import document_problems
from validation.scenario.engine_spec import EngineSpecError, parse_engine_spec
from validation.scenario.partial import validated_part, without_models
from validation.scenario.physics import initial_overlaps
from validation.scenario.problems import (
    Problem,
    ScenarioError,
    _found,
    _schema_problem,
    merged,
    path_text,
)
from validation.scenario.schema import (
    Scenario,
)
from validation.scenario.urdf import expand_models
from validation.scenario.yaml_source import (
    BYTES_PER_VALUE,
    MAX_BYTES,
    MAX_VALUES,
    SourceMap,
    YamlSourceError,
    read_yaml,
)


class ScenarioWarning(UserWarning):
    """A scene that loads but has a problem a run cannot show (a tolerance no reading can
    exceed): issued by ``load_scenario`` at the scene file's line."""


def _load(path: Path) -> tuple[Scenario | None, list[Problem]]:
    file = str(path)
    try:
        data, source = read_yaml(path)
    except YamlSourceError as error:
        return None, [Problem(file, path_text(error.path), error.message, error.line, error.column)]
    if not isinstance(data, dict):
        return None, [
            Problem(file, "", f"expected a mapping of scenario fields; got {_found(data)}", 1, 1)
        ]
    data = {**data, "source": file}
    if data.get("name") is None:
        data["name"] = path.stem
    data, found = expand_models(data, path)
    model_problems = [
        Problem(file, path_text(loc), message, *(source.locate(loc) or (None, None)))
        for loc, message in found
    ]
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as error:
        errors = error.errors(include_url=False)
        problems = merged([_schema_problem(e, data, file, source) for e in errors])
        part = validated_part(data, errors, models_failed=bool(model_problems))
        if part is None:
            problems += raw_engine_problems(data, file, source)
        else:  # the rules on what validated: every problem of the file in one pass
            said = set(problems)  # each said once
            problems += [
                p for p in document_problems(part.scenario, file, source, part) if p not in said
            ]
        problems = [p for p in problems + model_problems if not _filled_by_models(p, data)]
        return None, sorted(problems, key=lambda p: (p.line or 0, p.column or 0))
    if model_problems:  # the rules on the rest, the models' bodies and joints unknown
        return None, model_problems + document_problems(
            scenario, file, source, without_models(scenario)
        )
    problems = document_problems(scenario, file, source)
    return (None if any(not p.warning for p in problems) else scenario), problems


def _filled_by_models(problem: Problem, data: dict) -> bool:
    """A missing ``bodies`` in a scene whose ``models`` were refused: the models would have
    given it bodies (their own problems say what to fix)."""
    return problem.path == "bodies" and "bodies" not in data and bool(data.get("models"))


def raw_engine_problems(data: dict, file: str, source: SourceMap) -> list[Problem]:
    """The ``engines`` list's bad specs, found even when the rest of the file fails the schema
    (so every problem of a file shows in one pass); the whole-document rules check them again
    once the file is valid."""
    engines = data.get("engines")
    problems = []
    for i, text in enumerate(engines if isinstance(engines, list) else []):
        if not isinstance(text, str):
            continue  # the schema reports it
        try:
            parse_engine_spec(text)
        except EngineSpecError as error:
            position = source.locate(("engines", i))
            problems.append(Problem(file, f"engines[{i}]", str(error), *(position or (None, None))))
    return problems


def _warn(problem: Problem) -> None:
    """``problem`` as a ``ScenarioWarning`` at its line of the scene file."""
    field = f"{problem.path}: " if problem.path else ""
    warnings.warn_explicit(
        f"{field}{problem.message}", ScenarioWarning, problem.file, problem.line or 0
    )


def load_scenario(path: str | Path) -> Scenario:
    """The validated scenario at ``path``; raises ``ScenarioError`` listing every problem,
    and issues each warning as a ``ScenarioWarning``."""
    scenario, problems = _load(Path(path))
    if scenario is None:
        raise ScenarioError(problems)
    for problem in problems:
        _warn(problem)
    return scenario


def validate_scenario(path: str | Path) -> tuple[Scenario | None, list[Problem]]:
    """The scenario (or None) and its problems, without the check for overlaps at t = 0
    (``check_scenario`` adds it): that check only ever warns, so whether a file is valid is
    decided here (``physval list``, which shows no warning, stops here)."""
    return _load(Path(path))


def check_scenario(path: str | Path) -> tuple[Scenario | None, list[Problem]]:
    """The scenario (or None) and all its problems, warnings included (overlaps at t = 0)."""
    scenario, problems = validate_scenario(path)
    if scenario is not None:
        problems += [
            Problem(str(path), f"bodies[{i}]", message, *(None, None), warning=True)
            for i, message in initial_overlaps(scenario)
        ]
    return scenario, problems


SCENARIO_SUFFIXES = (".yaml", ".yml")


def _folder_files(folder: Path) -> list[Path]:
    """The scenario files below ``folder``, sorted, following symlinked folders; each real
    folder is read once, so a link back up (a loop) or a second link to a folder adds nothing."""
    found: list[Path] = []
    seen: set[tuple[int, int]] = set()
    for top, folders, names in os.walk(folder, followlinks=True):
        here = os.stat(top)
        if (here.st_dev, here.st_ino) in seen:
            folders[:] = []
            continue
        seen.add((here.st_dev, here.st_ino))
        found += [Path(top) / n for n in names if Path(n).suffix in SCENARIO_SUFFIXES]
    return sorted(found)


def scenario_files(paths: list[str | Path]) -> list[Path]:
    """Every ``*.yaml``/``*.yml`` file named or found (recursively, symlinked folders followed
    once) under the folders, sorted per folder; a file reached twice is listed once."""
    files: list[Path] = []
    seen: set[str] = set()
    for item in map(Path, paths):
        for file in _folder_files(item) if item.is_dir() else [item]:
            real = os.path.realpath(file)
            if real not in seen:
                seen.add(real)
                files.append(file)
    return files


def _describe_engines(engines: dict) -> None:
    """The ``engines`` list's items: a spec of an installed engine (the name by pattern, the
    options each engine declares in the description), read from the declarations."""
    found = declarations()
    names = "|".join(re.escape(name) for name in found)
    options = "; ".join(
        f"{name}({', '.join(o.name for o in declaration.options) or 'no options'})"
        for name, declaration in found.items()
    )
    engines["items"] = {
        "type": "string",
        "pattern": rf"^\s*({names})\s*(\(.*\))?\s*$",
        "description": f"an engine spec name or name(key=value, ...); installed: {options}",
    }


def json_schema() -> dict:
    """The JSON Schema of the format (for editors: the YAML language server)."""
    schema = Scenario.model_json_schema()
    schema["properties"].pop("source", None)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "physval scenario, version 1"
    _describe_engines(schema["properties"]["engines"])
    # bodies or models: a scene of models alone gets its bodies from their files at load
    schema["required"] = [name for name in schema["required"] if name != "bodies"]
    schema["anyOf"] = [{"required": ["bodies"]}, {"required": ["models"]}]
    schema["description"] = (
        f"A physval scene. The file may have at most {MAX_BYTES} bytes and expand to at most "
        f"{MAX_VALUES} values, the size cap over {BYTES_PER_VALUE} bytes a value (plain values "
        "cannot expand, so any scene that fits the file fits the cap; YAML aliases count at "
        "every use). Large scenes (10,000+ bodies) are plain body lists written by a script."
    )
    return schema
