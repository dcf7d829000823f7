"""The parity gate and the observation contract cannot be fooled: a model report with a NaN,
a body too many or too few, or a wrong shape is a ``model_mismatch`` row naming the field; an
observed state of the wrong shape is an ``error`` row naming it: for one-body scenes and
larger ones alike."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from validation.bundled import BUNDLED_SCENARIOS
from validation.engines.mini.adapter import MiniAdapter
from validation.engines.parity import compare
from validation.engines.reference import reference_report
from validation.measure.runner import run_engine
from validation.scenario import load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

SCENES = {
    "one body": BUNDLED_SCENARIOS / "formulas" / "projectile.yaml",
    "two bodies": BUNDLED_SCENARIOS / "formulas" / "head_on_ratio_1.yaml",
}


@pytest.fixture(params=list(SCENES), scope="module")
def scene(request):
    return compile_scene(load_scenario(SCENES[request.param]))


def _one_more(values: np.ndarray) -> np.ndarray:
    return np.concatenate([values, values[:1]])


SABOTAGED_REPORTS = {
    "all NaN": (
        lambda r: replace(
            r,
            **{
                q: np.full(np.shape(getattr(r, q)), np.nan)
                for q in ("mass", "com", "inertia_world", "linear_momentum", "angular_momentum")
            },
            energy=np.nan,
        ),
        "mass of body 0: the engine reported",
    ),
    "NaN energy": (
        lambda r: replace(r, energy=float("nan")),
        "energy: the engine reported 1 non-finite",
    ),
    "a body too many": (
        lambda r: replace(
            r,
            mass=_one_more(r.mass),
            com=_one_more(r.com),
            inertia_world=_one_more(r.inertia_world),
        ),
        "mass: the engine reported shape",
    ),
    "a body too few": (lambda r: replace(r, mass=r.mass[:-1]), "mass: the engine reported shape"),
    "a flat com": (lambda r: replace(r, com=r.com.ravel()), "com: the engine reported shape"),
    "text for a momentum": (
        lambda r: replace(r, linear_momentum="zero"),
        "linear_momentum: the engine reported not numbers",
    ),
}
"""Name -> (what the engine's model report becomes, the start of the gate's message)."""


@pytest.mark.parametrize("sabotage", list(SABOTAGED_REPORTS))
def test_a_model_report_that_cannot_be_compared_is_a_model_mismatch(scene, sabotage, monkeypatch):
    change, message = SABOTAGED_REPORTS[sabotage]
    original = MiniAdapter.model_report
    monkeypatch.setattr(MiniAdapter, "model_report", lambda self: change(original(self)))
    run = run_engine(scene, parse_engine_spec("mini"))
    assert run.status == "model_mismatch", (run.status, run.message)
    assert run.message.startswith(message), run.message
    assert run.recording is None


def test_the_gate_passes_the_engine_as_it_is(scene):
    """The control: the same scenes pass the gate and run without the sabotage."""
    adapter = MiniAdapter(parse_engine_spec("mini"))
    adapter.load(scene)
    assert compare(adapter.model_report(), reference_report(scene)) == []
    assert run_engine(scene, parse_engine_spec("mini")).status == "ok"


def _with_a_body_too_many(states):
    extra = {
        name: np.concatenate([getattr(states, name), getattr(states, name)[..., :1, :]], axis=-2)
        for name in ("pos", "quat", "vel", "ang_vel")
    }
    return replace(states, **extra)


def test_observed_states_of_the_wrong_body_count_are_an_error_naming_the_field(scene, monkeypatch):
    """An engine that observes one body more than the scene has: an ``error`` row naming the
    field and both shapes, not a run measured by broadcasting."""
    observe, advance_observed = MiniAdapter.observe, MiniAdapter.advance_observed
    monkeypatch.setattr(MiniAdapter, "observe", lambda self: _with_a_body_too_many(observe(self)))
    monkeypatch.setattr(
        MiniAdapter,
        "advance_observed",
        lambda self, n: _with_a_body_too_many(advance_observed(self, n)),
    )
    run = run_engine(scene, parse_engine_spec("mini"))
    assert run.status == "error", (run.status, run.message)
    bodies = scene.count
    assert "observed pos has shape" in run.message and f", {bodies + 1}, 3)" in run.message
    assert "expected (" in run.message and f", {bodies}, 3)" in run.message, run.message
