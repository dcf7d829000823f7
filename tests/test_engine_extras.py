"""An engine whose extra is not installed (Rapier without rapier3d, Drake without pydrake):
what the user sees. Runs on any machine: the installed declaration is given a ``requires`` no
machine has, so nothing here needs the engine itself."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from validation.cli import main
from validation.contract import BAD_STATUSES
from validation.engine_api import discover
from validation.scenario.engine_spec import EngineSpecError, parse_installed_spec

NOT_INSTALLED = ("physval_no_such_module",)
"""A declared ``requires`` as a machine without the engine's package sees it."""

EXTRAS = [
    pytest.param("rapier", "rapier(profile=defaults)", id="rapier"),
    pytest.param("drake", "drake(profile=continuous)", id="drake"),
]
"""(engine, a spec of it): each engine physval ships behind an extra of the engine's name."""

PROJECTILE = Path(__file__).resolve().parent.parent / "scenarios/formulas/projectile.yaml"


def _without_package(monkeypatch, engine: str) -> None:
    """The installed declaration of ``engine``, requiring a module that no machine has."""
    engines = discover().engines
    monkeypatch.setitem(engines, engine, replace(engines[engine], requires=NOT_INSTALLED))


def _install_line(engine: str) -> str:
    return f'pip install "physval[{engine}]"'


@pytest.mark.parametrize(("engine", "spec"), EXTRAS)
def test_naming_an_engine_without_its_package_is_a_spec_error_with_the_install_line(
    monkeypatch, engine, spec
):
    _without_package(monkeypatch, engine)
    with pytest.raises(EngineSpecError) as error:
        parse_installed_spec(spec)
    assert _install_line(engine) in str(error.value), error.value


@pytest.mark.parametrize(("engine", "spec"), EXTRAS)
def test_a_run_naming_an_engine_without_its_package_is_one_line_and_exit_2(
    monkeypatch, tmp_path, capsys, engine, spec
):
    _without_package(monkeypatch, engine)
    code = main(
        ["run", str(PROJECTILE), "--engines", spec, "--out", str(tmp_path / "out"),
         "--history", "none", "--baseline", "none"]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and _install_line(engine) in lines[0], err


@pytest.mark.parametrize(("engine", "spec"), EXTRAS)
def test_a_scene_naming_an_engine_without_its_package_gets_not_installed_rows(
    monkeypatch, tmp_path, capsys, engine, spec
):
    """A scene's ``engines:`` may name an engine that is not installed here (the library names
    rapier and drake): the other engines run, its row says ``not_installed`` with the install
    line, the run passes and the terminal says how to install it."""
    _without_package(monkeypatch, engine)
    scene_file = tmp_path / "projectile.yaml"
    scene_file.write_text(
        f'dt: 0.001\nduration: 0.5\nengines: [mini, "{spec}"]\n'
        "bodies: [{name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0,"
        " position: [0, 0, 1], velocity: [1, 0, 2]}]\n"
        "expect: [{kind: velocity_at, body: ball, time: 0.5, value: [1.0, 0.0, -2.905]}]\n"
        "checks: {velocity_at.ball: 1.0e-9}\n"
    )
    out = tmp_path / "out"
    code = main(["run", str(scene_file), "--out", str(out), "--history", "none",
                 "--baseline", "none", "--jobs", "1"])  # fmt: skip
    printed = capsys.readouterr().out
    rows = pd.read_csv(out / "results.csv", keep_default_na=False)
    absent = rows[rows["engine"] == spec]
    assert code == 0, printed
    assert list(absent["status"]) == ["not_installed"], absent.to_dict("records")
    assert _install_line(engine) in absent["message"].iloc[0], absent["message"].iloc[0]
    mini = rows[rows["engine"] == "mini"]
    assert (mini["status"] == "ok").any() and not mini["status"].isin(BAD_STATUSES).any(), mini[
        ["metric", "status"]
    ].to_dict("records")
    line = f"{engine} not installed: 1 scene not run in it ({_install_line(engine)})"
    assert line in printed, printed
