"""Engines as plugins: found by the ``physval.engines`` entry points, a broken one a line naming
it while the others run, and the worked example (examples/engine_plugin) installed with pip and
run through a scene and the conformance suite."""

from __future__ import annotations

import csv
import importlib.util
import os
import shutil
import subprocess
import sys
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

from validation import engine_api
from validation.cli import main
from validation.engine_api import BUILTIN_ENGINES, ENTRY_POINT_GROUP, discover
from validation.scenario.engine_spec import EngineSpecError, parse_engine_spec

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "engine_plugin"
SCENES = ROOT / "scenarios"

BROKEN_PLUGINS = {
    "noimport": ("broken_noimport:DECLARATION", "raise ImportError('no solver here')\n"),
    "oldapi": (
        "broken_oldapi:DECLARATION",
        "from dataclasses import replace\n"
        "from validation.engines.mini.declaration import DECLARATION as MINI\n"
        "DECLARATION = replace(MINI, name='oldapi', api_version=0)\n",
    ),
    "notadecl": ("broken_notadecl:DECLARATION", "DECLARATION = {'name': 'notadecl'}\n"),
    "badshape": (
        "broken_badshape:DECLARATION",
        "from dataclasses import replace\n"
        "from validation.engine_api import Capabilities\n"
        "from validation.engines.mini.declaration import DECLARATION as MINI\n"
        "DECLARATION = replace(MINI, name='badshape', capabilities=Capabilities(shapes=('cone',)))\n",
    ),
}
"""Entry point name -> (value, module text) of a plugin broken in one way each."""

BROKEN_LINES = {
    "noimport": "does not load: ImportError: no solver here",
    "oldapi": "written for adapter API version 0; this physval has version 1",
    "notadecl": "expected an EngineDeclaration; got dict",
    "badshape": "unknown shape 'cone'",
}
"""What each broken plugin's line must say."""


def test_pyproject_registers_the_built_in_engines_as_any_plugin_does():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert project["project"]["entry-points"][ENTRY_POINT_GROUP] == BUILTIN_ENGINES


def test_every_built_in_declaration_is_well_formed_and_imports_no_engine():
    program = (
        "import sys\n"
        "from validation.engine_api import discover\n"
        "found = discover()\n"
        "assert not found.broken, found.broken\n"
        "print(sorted(found.engines))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mujoco', 'pybullet', 'rapier3d', 'pydrake')))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", program],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0, done.stderr
    engines, imported = done.stdout.splitlines()
    assert engines == str(sorted(BUILTIN_ENGINES)) and imported == "[]", done.stdout


@pytest.fixture
def broken_plugins(tmp_path, monkeypatch):
    """Four broken plugins installed as a distribution on sys.path (discovery re-read)."""
    info = tmp_path / "broken_plugins-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugins\nVersion: 1.0\n")
    lines = [f"[{ENTRY_POINT_GROUP}]"]
    for name, (value, text) in BROKEN_PLUGINS.items():
        lines.append(f"{name} = {value}")
        (tmp_path / f"{value.split(':')[0]}.py").write_text(text)
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    discover.cache_clear()
    yield tmp_path
    discover.cache_clear()


def test_a_broken_plugin_is_one_line_naming_it_and_the_others_still_load(broken_plugins):
    found = discover()
    assert list(found.engines) == list(BUILTIN_ENGINES)
    assert len(found.broken) == len(BROKEN_PLUGINS), found.broken
    for name, text in BROKEN_LINES.items():
        (line,) = [b for b in found.broken if b.startswith(f"engine plugin {name!r}")]
        assert text in line and "from broken-plugins" in line and "\n" not in line, line


def test_a_spec_naming_a_broken_plugin_says_it_is_broken(broken_plugins):
    with pytest.raises(
        EngineSpecError, match=r"engine 'noimport' is installed but broken: .*no solver here"
    ):
        parse_engine_spec("noimport")
    assert parse_engine_spec("mini").name == "mini"


def test_list_and_run_go_on_past_broken_plugins(broken_plugins, tmp_path, capsys):
    assert main(["list", str(SCENES / "formulas" / "projectile.yaml")]) == 0
    captured = capsys.readouterr()
    assert "  mini " in captured.out and "  pybullet " in captured.out
    assert sum(line.startswith("engine plugin ") for line in captured.err.splitlines()) == 4, (
        captured.err
    )
    out = tmp_path / "run"
    code = main(
        [
            "run",
            str(SCENES / "formulas" / "projectile.yaml"),
            "--engines",
            "mini",
            "--out",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr()
    assert "engine plugin 'noimport'" in capsys.readouterr().err


def test_a_name_taken_twice_keeps_the_first(tmp_path, monkeypatch):
    info = tmp_path / "impostor-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: impostor\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nmini = validation.engines.pybullet.declaration:DECLARATION\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    discover.cache_clear()
    try:
        found = discover()
    finally:
        discover.cache_clear()
    assert found.engines["mini"].adapter.endswith("MiniAdapter")
    (line,) = found.broken
    assert "'mini'" in line and "taken" in line, line


# --- the worked example --------------------------------------------------------------------


def _pip_install(source: Path, target: Path) -> subprocess.CompletedProcess:
    """The example's ``source`` (a copy: the build leaves nothing in the repository) installed
    into ``target`` (no dependencies: physval and numpy are here); offline when setuptools and
    wheel are installed, else pip builds it in isolation."""
    offline = all(importlib.util.find_spec(m) for m in ("setuptools", "wheel"))
    command = [
        sys.executable,
        "-m",
        "pip",
        "install",
        "--quiet",
        "--no-deps",
        "--target",
        str(target),
        str(source),
    ]
    if offline:
        command.insert(4, "--no-build-isolation")
    return subprocess.run(command, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory):
    source = tmp_path_factory.mktemp("source") / "engine_plugin"
    shutil.copytree(
        EXAMPLE, source, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__")
    )
    target = tmp_path_factory.mktemp("plugin")
    done = _pip_install(source, target)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (target / "physval_freeflight").is_dir()
    return target


def _physval(plugin_path: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(plugin_path), str(ROOT)])}
    return subprocess.run(
        [sys.executable, "-m", "validation.entry", *args],
        capture_output=True,
        text=True,
        env=environment,
        cwd=cwd,
        timeout=600,
    )


def test_the_example_plugin_is_listed_with_its_version(plugin_path, tmp_path):
    done = _physval(plugin_path, "list", str(SCENES / "formulas" / "projectile.yaml"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "  freeflight                     physval-freeflight 0.1.0: " in done.stdout, done.stdout
    words = " ".join(done.stdout.split())  # the lines wrap within 100 columns
    # a plugin that names no shapes builds the first three: never asked for a cylinder
    assert "supports sphere, box, capsule, loads; lacks cylinder, ground" in words, words
    assert "lacks cylinder, ground, tilted_ground, contacts, fixed_bodies, springs" in words, words
    assert " rotation: rk4|exponential (default rk4): orientation update" in words, words


def test_the_example_plugin_passes_the_conformance_suite(plugin_path, tmp_path):
    done = _physval(plugin_path, "conformance", "freeflight(substeps=2)", cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "conformance of freeflight(substeps=2): 9 of 9 checks pass" in done.stdout, done.stdout
    assert "refused cylinder, ground, tilted_ground, contacts, fixed_bodies, springs" in (
        done.stdout
    ), done.stdout
    # declared no shapes: built and judged as the first three, never as a cylinder
    assert "ran sphere, box, capsule, loads;" in done.stdout, done.stdout
    assert "parity: rotated sphere, box, capsule with" in done.stdout, done.stdout


TOSS = """\
dt: 1.0e-3
duration: 0.5
engines: [freeflight]
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, velocity: [3.0, 0.0, 8.0],
     angular_velocity: [0.0, 4.0, 0.0]}
expect:
  # x(0.5) = (3·0.5, 0, 8·0.5 - 9.81·0.125)
  - {kind: position_at, body: ball, time: 0.5, value: [1.5, 0.0, 2.77375]}
checks:
  position_at.ball: 1.0e-9  # freeflight's translation is exact: round-off only
"""
"""A tossed ball: free flight, the example engine's whole world."""


def test_the_example_plugin_runs_a_scene_and_refuses_contact_as_unsupported(plugin_path, tmp_path):
    (tmp_path / "toss.yaml").write_text(TOSS)
    scenes = [tmp_path / "toss.yaml", SCENES / "contact" / "box_drop_flat.yaml"]
    out = tmp_path / "run"
    done = _physval(
        plugin_path,
        "run",
        *map(str, scenes),
        "--engines",
        "freeflight",
        "--out",
        str(out),
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    with (out / "results.csv").open() as file:
        rows = list(csv.DictReader(file))
    (flight,) = [r for r in rows if r["scenario"] == "toss" and r["metric"] == "position_at.ball"]
    assert flight["status"] == "ok" and flight["passed"] == "True", flight
    (refused,) = [r for r in rows if r["scenario"] == "box_drop_flat"]
    assert refused["status"] == "unsupported" and refused["passed"] == "", refused
    assert refused["message"].startswith(
        "freeflight cannot represent: ground (the scene has a ground)"
    )


def test_engine_api_names_the_builtins_it_falls_back_to():
    """The fallback table is only for built-ins the installed metadata lacks: each names a
    declaration module next to its adapter."""
    for name, value in BUILTIN_ENGINES.items():
        module = value.split(":")[0]
        assert module == f"validation.engines.{name}.declaration"
        assert engine_api.declaration_of(name).adapter.startswith(
            f"validation.engines.{name}.adapter:"
        )


# --- what a scene needs ----------------------------------------------------------------------


def test_each_capability_scene_needs_its_capability_and_a_lone_body_needs_no_contact():
    from validation.jobs.conformance import CAPABILITY_SCENES, frames_scene
    from validation.scenario.needs import scene_needs

    for word, build in CAPABILITY_SCENES.items():
        assert word in scene_needs(build()), word
    lone = frames_scene("box")
    assert set(scene_needs(lone)) == {"box"}, scene_needs(lone)


def test_a_lone_body_with_restitution_and_friction_needs_neither():
    """A coefficient acts only on a contact: a lone body in the air never uses it."""
    from validation.scenario import Scenario
    from validation.scenario.needs import scene_needs

    body = {
        "name": "b",
        "shape": {"type": "sphere", "radius": 0.1},
        "mass": 1.0,
        "restitution": 0.5,
        "friction": 0.4,
    }
    alone = Scenario.model_validate({"dt": 1e-3, "duration": 0.1, "bodies": [body]})
    assert set(scene_needs(alone)) == {"sphere"}
    grounded = Scenario.model_validate({**alone.model_dump(), "ground": {}})
    needs = scene_needs(grounded)
    assert needs["restitution"] == "body 'b' has restitution 0.5", needs
    assert needs["friction"] == "body 'b' has friction 0.4", needs


def test_the_json_schema_names_the_installed_engines():
    import jsonschema

    from validation.scenario import json_schema

    schema = json_schema()
    scene = {
        "dt": 1e-3,
        "duration": 0.1,
        "bodies": [{"name": "b", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0}],
    }
    jsonschema.validate({**scene, "engines": ["mini(gyroscopic=implicit)", "pybullet"]}, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**scene, "engines": ["bullet"]}, schema)
    described = schema["properties"]["engines"]["items"]["description"]
    assert (
        "mujoco(profile, integrator, solver, cone, restitution, iterations, model_loader)"
        in described
    )


def test_capabilities_can_depend_on_the_spec(monkeypatch):
    """An engine whose options change what it represents (a profile without springs) declares
    ``capabilities_for``; the runner asks it per spec."""
    from validation.jobs.conformance import CAPABILITY_SCENES
    from validation.measure.runner import run_engine
    from validation.scenario.compiled import compile_scene

    found = discover()
    mini = found.engines["mini"]

    def capabilities_for(settings):
        if settings.get("gyroscopic") == "implicit":
            return replace(mini.capabilities, features=mini.capabilities.features - {"springs"})
        return mini.capabilities

    varying = replace(mini, capabilities_for=capabilities_for)
    monkeypatch.setattr(
        engine_api, "discover", lambda: replace(found, engines={**found.engines, "mini": varying})
    )
    scene = compile_scene(CAPABILITY_SCENES["springs"]())
    assert run_engine(scene, parse_engine_spec("mini")).status == "ok"
    refused = run_engine(scene, parse_engine_spec("mini(gyroscopic=implicit)"))
    assert refused.status == "unsupported" and "springs (1 spring(s)" in refused.message, (
        refused.message
    )
