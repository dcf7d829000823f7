"""Every physical law of mini_engine is written once: a bug in it shows on every path.

Two copies of one law hide a bug in one of them from every scene that runs the other (gravity
was computed in ``forces`` and again in ``workspace``: a spring scene and a free scene took
different copies). Each law here is checked twice: by sabotaging its one definition and seeing
every path through ``step`` move, and by reading the source for a second place that reads the
law's inputs.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import numpy as np
import pytest

import mini_engine.forces as forces
from mini_engine import Body, Settings, Sphere, Spring, build_model, step

MINI = Path(forces.__file__).resolve().parent

LAW_INPUTS = {
    "gravity": ("forces.py", "model.py", "quantities.py"),
    "body_force": ("forces.py", "model.py"),
    "body_torque": ("forces.py", "model.py"),
    "spring_stiffness": ("forces.py", "model.py"),
    "spring_damping": ("forces.py", "model.py"),
}
"""Model field -> the only mini_engine modules that may read it: ``forces`` (the laws of
gravity, springs and constant loads), ``model`` (where it is built and copied) and, for
gravity, ``quantities`` (the potential energy -m g·x: another law, the energy's)."""


def _attribute_reads(path: Path) -> set[str]:
    return {
        node.attr
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Attribute)
    }


@pytest.mark.parametrize("field", list(LAW_INPUTS))
def test_a_law_s_inputs_are_read_in_its_own_module_only(field):
    readers = sorted(path.name for path in MINI.glob("*.py") if field in _attribute_reads(path))
    extra = [name for name in readers if name not in LAW_INPUTS[field]]
    assert not extra, f"model.{field} is read in {extra}: a second copy of its law? ({readers})"


def _sabotage(monkeypatch, law, replacement) -> None:
    """Replace the function ``law`` by ``replacement`` in every mini_engine module that holds
    it (its definition and every ``from ... import`` of it): the one law, wherever it is used."""
    for name, module in list(sys.modules.items()):
        if name.startswith("mini_engine") and getattr(module, law.__name__, None) is law:
            monkeypatch.setattr(module, law.__name__, replacement)


def _fall(with_spring: bool) -> np.ndarray:
    """The position after 50 steps of a 1 kg ball pushed by 2 N, under gravity, on a weak
    spring to a second ball or not: the spring path and the constant-load path of ``step``."""
    bodies = [
        Body(Sphere(0.1), mass=1.0, position=(0.0, 0.0, 1.0), force=(2.0, 0.0, 0.0)),
        Body(Sphere(0.1), mass=1.0, position=(1.0, 0.0, 1.0)),
    ]
    springs = [Spring(0, 1, stiffness=1e-3, rest_length=1.0)] if with_spring else []
    model, state = build_model(bodies, springs)
    for _ in range(50):
        state, _ = step(model, state, Settings(dt=1e-3))
    return np.array(state.pos[0])


@pytest.mark.parametrize("with_spring", [False, True], ids=["constant loads", "springs"])
def test_sabotaged_gravity_moves_every_path(monkeypatch, with_spring):
    """Gravity 1 % low in its one definition: both paths of ``step`` (the workspace's constant
    acceleration, and the per-step loads with springs) must fall slower."""
    honest = _fall(with_spring)
    weak = forces.gravity_acceleration

    def one_percent_low(model):
        return 0.99 * weak(model)

    _sabotage(monkeypatch, weak, one_percent_low)
    sabotaged = _fall(with_spring)
    drop = 1.0 - honest[2]
    moved = sabotaged[2] - honest[2]
    assert moved == pytest.approx(0.01 * drop, rel=1e-6), (
        f"1 % less gravity moved z by {moved:.3g} m of a {drop:.3g} m drop"
    )


@pytest.mark.parametrize("with_spring", [False, True], ids=["constant loads", "springs"])
def test_sabotaged_applied_force_moves_every_path(monkeypatch, with_spring):
    honest = _fall(with_spring)
    real = forces.constant_loads

    def doubled(model):
        force, torque = real(model)
        return 2.0 * force, torque

    _sabotage(monkeypatch, real, doubled)
    sabotaged = _fall(with_spring)
    pushed = honest[0]
    assert sabotaged[0] == pytest.approx(2.0 * pushed, rel=1e-3), (sabotaged[0], pushed)
