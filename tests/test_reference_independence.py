"""The references do not move with the engine under test: a mistake planted in mini_engine's
formulas (a capsule inertia without its parallel-axis term, a spring law with twice the pull)
is caught by the parity gate or leaves the reference motion and the invariants unchanged,
while MuJoCo and PyBullet, given the reference's values, still pass."""

from __future__ import annotations

import sys

import numpy as np

import mini_engine.forces
from mini_engine.shapes import Capsule
from validation.cli import BUNDLED_SCENARIOS
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.measure.runner import run_engine
from validation.reference.newton_euler import reference_motion
from validation.scenario import Scenario, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

ENGINES = ("mini", "mujoco", "pybullet")

FREE_CAPSULE = {
    "name": "free_capsule",
    "dt": 1e-3,
    "duration": 0.01,
    "gravity": [0.0, 0.0, -9.81],
    "bodies": [
        {
            "name": "capsule",
            "shape": {"type": "capsule", "radius": 0.05, "half_length": 0.15},
            "mass": 1.0,
            "position": [0.0, 0.0, 1.0],
            "orientation": [0.9659258262890683, 0.25881904510252074, 0.0, 0.0],
            "angular_velocity": [1.0, 2.0, 0.5],
        }
    ],
}
"""The library's capsule (capsule_drop.yaml) without its stated inertia, tumbling in free
fall: every engine must take the solid capsule's inertia from its own shape formulas."""

STATED_CAPSULE_TRACE = 2.0 * 0.011943181818 + 0.001204545455
"""kg·m², the trace of the solid capsule's inertia as capsule_drop.yaml states it."""

STATED_DIGITS = 3e-12
"""kg·m², the rounding of those three stated moments (12 decimals each)."""

SPRING_SCENE = BUNDLED_SCENARIOS / "stiff" / "stiff_spring_oscillator.yaml"
"""A 1 kg bob on a 1e6 N/m spring to a world point (the reference is DOP853)."""

SPRING_SABOTAGE = 2.0
"""The planted spring-law mistake: every spring force, torque and energy twice the law's."""

OBSERVED_STEPS = 50
"""Steps of an engine compared with and without the spring sabotage (5 ms)."""


def capsule_without_parallel_axis(self: Capsule) -> np.ndarray:
    """The capsule inertia per kilogram with each cap's transverse moment left about its base
    (no ``L²/4 + 3 L r / 8`` parallel-axis part): the mistake the parity gate must catch."""
    r, length = self.radius, 2.0 * self.half_length
    cylinder, caps = np.pi * r**2 * length, 4.0 / 3.0 * np.pi * r**3
    m_cylinder, m_cap = cylinder / (cylinder + caps), 0.5 * caps / (cylinder + caps)
    axial = m_cylinder * r**2 / 2.0 + 2.0 * m_cap * (2.0 / 5.0) * r**2
    transverse = m_cylinder * (length**2 / 12.0 + r**2 / 4.0) + 2.0 * m_cap * (2.0 / 5.0) * r**2
    return np.diag([transverse, transverse, axial])


def sabotage_everywhere(monkeypatch, module, name: str, replacement) -> None:
    """Replace ``module.name`` in that module and in every loaded module that bound it by
    name (``from module import name``), so each user of the law gets the planted mistake."""
    original = getattr(module, name)
    for loaded in list(sys.modules.values()):
        if getattr(loaded, name, None) is original:
            monkeypatch.setattr(loaded, name, replacement)


def doubled(law):
    """``law`` with every array it returns multiplied by ``SPRING_SABOTAGE``."""

    def sabotaged(*args, **kwargs):
        result = law(*args, **kwargs)
        if isinstance(result, tuple):
            return tuple(SPRING_SABOTAGE * part for part in result)
        return SPRING_SABOTAGE * result

    return sabotaged


def statuses(scenario: Scenario) -> dict[str, tuple[str, str]]:
    """Engine -> (status, message) of ``run_engine`` (the parity gate first) on the scene."""
    scene = compile_scene(scenario)
    runs = {name: run_engine(scene, parse_engine_spec(name)) for name in ENGINES}
    return {name: (run.status, run.message) for name, run in runs.items()}


def test_mini_without_the_capsule_parallel_axis_term_fails_the_parity_gate(monkeypatch):
    scenario = Scenario.model_validate(FREE_CAPSULE)
    honest = statuses(scenario)
    assert all(status == "ok" for status, _ in honest.values()), honest
    monkeypatch.setattr(Capsule, "unit_inertia", capsule_without_parallel_axis)
    sabotaged = statuses(scenario)
    mini_status, mini_message = sabotaged["mini"]
    assert mini_status == "model_mismatch" and "inertia_world" in mini_message, sabotaged
    others = {name: sabotaged[name] for name in ENGINES if name != "mini"}
    assert all(status == "ok" for status, _ in others.values()), others
    # the gate's expected inertia is still the exact solid capsule's: its trace (a rotation
    # keeps it) is that of capsule_drop.yaml's stated moments, to their 12 decimals
    trace = float(np.trace(reference_report(compile_scene(scenario)).inertia_world[0]))
    assert abs(trace - STATED_CAPSULE_TRACE) <= STATED_DIGITS, (trace, STATED_CAPSULE_TRACE)


def engine_positions(scenario: Scenario, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Engine -> (OBSERVED_STEPS, n, 3) m, the positions after each step."""
    positions = {}
    for name in names:
        adapter = create_adapter(parse_engine_spec(name))
        adapter.load(compile_scene(scenario))
        rows = []
        for _ in range(OBSERVED_STEPS):
            adapter.advance(1)
            rows.append(adapter.observe().pos)
        adapter.close()
        positions[name] = np.stack(rows)
    return positions


def reference_values(scenario: Scenario) -> tuple[np.ndarray, float, float]:
    """The DOP853 positions over the first 5 ms (m), the scene's energy invariant at its
    stated start (J) and the parity gate's expected energy (J)."""
    scene = compile_scene(scenario)
    times = np.linspace(0.0, OBSERVED_STEPS * scenario.dt, OBSERVED_STEPS + 1)
    fields = ("position", "orientation", "velocity", "angular_velocity")
    start = [np.array([[getattr(b, f) for b in scenario.bodies]], dtype=float) for f in fields]
    energy = float(scene.energy(*start)[0])
    return reference_motion(scene, times).pos, energy, reference_report(scene).energy


def test_a_sabotaged_spring_law_moves_mini_but_not_the_references(monkeypatch):
    """DOP853, the energy invariant, the gate's expected energy and PyBullet (whose springs
    the adapter applies by the reference's law) stay bit for bit where they were."""
    scenario = load_scenario(SPRING_SCENE)
    honest_motion, honest_energy, honest_expected = reference_values(scenario)
    honest_engines = engine_positions(scenario, ("mini", "pybullet"))
    for law in ("spring_forces", "spring_energies"):
        sabotage_everywhere(
            monkeypatch, mini_engine.forces, law, doubled(getattr(mini_engine.forces, law))
        )
    motion, energy, expected = reference_values(scenario)
    engines = engine_positions(scenario, ("mini", "pybullet"))
    moved = float(np.abs(engines["mini"] - honest_engines["mini"]).max())
    assert moved > 1e-5, f"the sabotage did not reach mini: its positions moved by {moved} m"
    shift = float(np.abs(motion - honest_motion).max())
    assert shift == 0.0, f"the DOP853 reference moved by {shift} m with mini's spring law"
    pybullet_shift = float(np.abs(engines["pybullet"] - honest_engines["pybullet"]).max())
    assert pybullet_shift == 0.0, (
        f"PyBullet, driven by the reference's law, moved {pybullet_shift} m"
    )
    assert (energy, expected) == (honest_energy, honest_expected), (
        f"energy {energy} J (honest {honest_energy}), parity expectation {expected} J "
        f"(honest {honest_expected})"
    )
