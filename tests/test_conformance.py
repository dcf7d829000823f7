"""The adapter contract's conformance suite (``physval conformance``): the built-in adapters
pass it, and each check fails on an adapter broken in the way it guards against."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from validation import engine_api
from validation.cli import main
from validation.engines.base import Snapshot
from validation.engines.mini.adapter import MiniAdapter
from validation.jobs.conformance import CHECKS, run_conformance

BUILT_IN = (
    "mini",
    "mujoco",
    "pybullet",
    "rapier",
    "drake",
    "drake(profile=continuous)",
    "mini(gyroscopic=implicit)",
    "mujoco(integrator=RK4)",
)
"""The built-in engines (and two non-default specs) that must keep the contract."""


@pytest.mark.parametrize("spec", BUILT_IN)
def test_the_built_in_adapters_pass_every_check(spec):
    results = run_conformance(spec)
    assert [r.name for r in results] == list(CHECKS)
    failed = {r.name: r.problems for r in results if not r.passed}
    assert failed == {}, failed


def _only(spec: str, check: str):
    (result,) = run_conformance(spec, [check])
    return result


def _observed(transform):
    """A mini ``observe`` whose snapshot goes through ``transform(snapshot)``."""
    original = MiniAdapter.observe
    return lambda self: transform(original(self))


def test_frames_fails_on_a_quaternion_read_x_y_z_w(monkeypatch):
    monkeypatch.setattr(
        MiniAdapter,
        "observe",
        _observed(lambda s: replace(s, quat=s.quat[:, [1, 2, 3, 0]])),
    )
    result = _only("mini", "frames")
    assert not result.passed and "quat: largest error" in result.problems[0], result


def test_frames_fails_on_a_body_frame_angular_velocity(monkeypatch):
    from validation.reference.rotation import quat_to_matrix

    def body_frame(s: Snapshot) -> Snapshot:
        return replace(s, ang_vel=np.einsum("nji,nj->ni", quat_to_matrix(s.quat), s.ang_vel))

    monkeypatch.setattr(MiniAdapter, "observe", _observed(body_frame))
    result = _only("mini", "frames")
    assert not result.passed and "ang_vel" in result.problems[0], result


def test_parity_fails_on_a_mass_off_by_a_millionth(monkeypatch):
    original = MiniAdapter.model_report
    monkeypatch.setattr(
        MiniAdapter,
        "model_report",
        lambda self: replace(original(self), mass=original(self).mass * (1 + 1e-6)),
    )
    result = _only("mini", "parity")
    assert not result.passed and "mass of body 0" in result.problems[0], result


def test_advance_fails_when_advance_n_is_not_n_steps(monkeypatch):
    original = MiniAdapter.advance
    monkeypatch.setattr(
        MiniAdapter, "advance", lambda self, n: original(self, n if n == 1 else n - 1)
    )
    result = _only("mini", "advance")
    assert not result.passed and "advance(200) vs 200 x advance(1)" in result.problems[0], result


def test_observe_fails_when_observing_nudges_the_state(monkeypatch):
    original = MiniAdapter.observe

    def nudging(self):
        snapshot = original(self)
        self.state.vel[:] *= 1 + 1e-12
        return snapshot

    monkeypatch.setattr(MiniAdapter, "observe", nudging)
    result = _only("mini", "observe")
    assert not result.passed and "observing after every step" in result.problems[0], result


def test_determinism_fails_on_a_run_that_differs_by_round_off(monkeypatch):
    original = MiniAdapter.advance
    runs = iter(range(10**6))

    def drifting(self, n):
        original(self, n)
        self.state.pos[:] += next(runs) * 1e-16

    monkeypatch.setattr(MiniAdapter, "advance", drifting)
    result = _only("mini", "determinism")
    assert not result.passed and "a second run" in result.problems[0], result


def test_close_fails_when_the_engine_is_kept(monkeypatch):
    kept = []
    leak = 4 * 1024 * 1024  # bytes a cycle, 8x the allowance
    monkeypatch.setattr(MiniAdapter, "close", lambda self: kept.append(np.ones(leak // 8)))
    result = _only("mini", "close")
    assert not result.passed and "close() does not free the engine" in result.problems[0], result


def test_provenance_fails_on_an_option_it_drops(monkeypatch):
    original = MiniAdapter.provenance

    def dropping(self):
        found = original(self)
        found.settings.pop("warm_start")
        return found

    monkeypatch.setattr(MiniAdapter, "provenance", dropping)
    result = _only("mini", "provenance")
    assert result.problems == ("mini(warm_start=false): provenance settings have no 'warm_start'",)


def test_capabilities_fails_on_a_capability_declared_but_not_built(monkeypatch):
    original = MiniAdapter.load

    def no_springs(self, scene):
        if scene.scenario.springs:
            raise NotImplementedError("springs")
        original(self, scene)

    monkeypatch.setattr(MiniAdapter, "load", no_springs)
    result = _only("mini", "capabilities")
    assert result.problems == ("springs (declared): error: NotImplementedError: springs",), result


def test_a_capability_declared_missing_is_refused_without_building_the_engine(monkeypatch):
    found = engine_api.discover()
    mini = found.engines["mini"]
    lacking = replace(
        mini,
        capabilities=replace(mini.capabilities, features=mini.capabilities.features - {"springs"}),
    )
    monkeypatch.setattr(
        engine_api, "discover", lambda: replace(found, engines={**found.engines, "mini": lacking})
    )
    original = MiniAdapter.load

    def load(self, scene):
        assert not scene.scenario.springs, "a spring scene reached the engine"
        original(self, scene)

    monkeypatch.setattr(MiniAdapter, "load", load)
    result = _only("mini", "capabilities")
    refused = result.detail.split("refused ")[1].split(", ")
    assert result.passed and "springs" in refused, result


def test_conformance_exit_codes(monkeypatch, capsys):
    assert main(["conformance", "mini", "--only", "declaration", "--only", "frames"]) == 0
    out = capsys.readouterr().out
    assert "conformance of mini: 2 of 2 checks pass" in out, out
    assert main(["conformance", "nosuch"]) == 2
    assert "unknown engine 'nosuch'" in capsys.readouterr().err
    assert main(["conformance", "mini(gyroscopic=wrong)"]) == 2
    assert "expected one of none, explicit, implicit" in capsys.readouterr().err
    assert main(["conformance", "mini", "--only", "nothing"]) == 2
    assert "--only nothing: expected checks of declaration" in capsys.readouterr().err
    monkeypatch.setattr(
        MiniAdapter, "observe", _observed(lambda s: replace(s, quat=s.quat[:, [1, 2, 3, 0]]))
    )
    assert main(["conformance", "mini", "--only", "frames"]) == 1
    out = capsys.readouterr().out
    assert "FAIL frames" in out and "(failing: frames)" in out, out


def test_the_pytest_option_runs_one_test_per_check(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "--physval-conformance",
            "mini",
            "-k",
            "declaration or frames or provenance",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "3 passed" in done.stdout, done.stdout


def test_the_fixture_is_run_conformance(tmp_path):
    (tmp_path / "test_engine.py").write_text(
        "def test_mini(physval_conformance):\n"
        "    (result,) = physval_conformance('mini', ['declaration'])\n"
        "    assert result.passed and result.name == 'declaration'\n"
    )
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_engine.py"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and "1 passed" in done.stdout, done.stdout + done.stderr
