"""``physval list`` and ``physval --version`` (validation.listing): everything a scene author can
name is listed with its definition, within 100 columns."""

from __future__ import annotations

import importlib.metadata
from dataclasses import replace

import pytest

from validation.cli import main
from validation.engine_api import FEATURES, SHAPES, Capabilities, declarations
from validation.engines.mini.declaration import DECLARATION as MINI
from validation.jobs.listing import LIST_WIDTH, _capability_text, version_of
from validation.measure.definitions import EXPECTATION_DEFINITIONS, METRIC_DEFINITIONS
from validation.scenario import BUNDLED_SCENARIOS
from validation.scenario.engine_spec import ENGINE_OPTIONS
from validation.scenario.load import scenario_files


def test_list_names_every_scene_engine_option_metric_and_expectation(capsys):
    assert main(["list", str(BUNDLED_SCENARIOS)]) == 0
    out = capsys.readouterr().out
    names = [
        line.split()[0] for line in out.splitlines() if line.startswith("  ") and line[2] != " "
    ]
    for file in scenario_files([BUNDLED_SCENARIOS]):
        assert file.stem in names, file
    words = " ".join(out.split())  # the lines wrap within LIST_WIDTH
    for engine, options in ENGINE_OPTIONS.items():
        assert engine in names, engine
        for key in options:
            assert f" {key}: " in out, (engine, key)
    for engine, declaration in declarations().items():
        assert (
            f"{declaration.distribution} {version_of(declaration.distribution)}: {declaration.summary}"
            in words
        )
        for option in declaration.options:
            assert f"{option.meaning}" in words, (engine, option.name)
        assert " ".join(_capability_text(declaration).split()) in words, engine
    for name in (*METRIC_DEFINITIONS, *EXPECTATION_DEFINITIONS):
        assert name in names, name
    assert f"mujoco {importlib.metadata.version('mujoco')}" in out
    assert f"pybullet {importlib.metadata.version('pybullet')}" in out
    assert max(len(line) for line in out.splitlines()) <= LIST_WIDTH


def test_list_of_a_scene_that_does_not_load_is_exit_2_naming_it(tmp_path, capsys):
    (tmp_path / "broken.yaml").write_text("dt: -1\n")
    assert main(["list", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "broken.yaml: does not load" in err and "physval check" in err, err


def test_version_names_physval_and_the_engines(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"physval {importlib.metadata.version('physval')} (mujoco "), out


def test_an_engine_with_every_capability_says_so_and_one_without_names_what_it_lacks():
    everything = Capabilities(shapes=SHAPES, features=frozenset(FEATURES))
    assert _capability_text(replace(MINI, capabilities=everything)).startswith(
        "supports every shape and scene feature"
    )
    text = _capability_text(replace(MINI, capabilities=Capabilities()))
    # the default names the first three shapes and the first contract's features only
    assert "lacks cylinder, joints, joint_limits" in text, text
