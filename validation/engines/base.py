"""The public adapter contract (version ``API_VERSION``): what an engine adapter implements,
the records it returns, and the declaration that tells physval about it.

An engine joins physval as a package that registers an ``EngineDeclaration`` under the entry
point group ``physval.engines`` (``docs/adapters.md``; ``examples/engine_plugin`` is a
complete one). Everything an adapter author needs is importable from this module.

The declaration (``validation.engine_api``, re-exported here) is data and imports nothing of
the engine: the options a spec may carry (``EngineOption``: name, type, choices, default,
meaning), the capabilities (``Capabilities``: shapes, scene features such as springs, loads,
restitution, friction, tilted ground; integrators, precision, stepping) and the adapter's
``module:Class``. A scene that needs a capability the engine lacks is not run in it: its rows
are ``unsupported`` with the reason, never a silent approximation.

The adapter (``EngineAdapter``) turns a ``CompiledScene`` into one engine's model, advances
it, and reads the state back. Conventions, all at the adapter's boundary and nowhere else:

- units: SI (m, kg, s, N, rad); inertias in kg·m²;
- frames: one right-handed world frame, gravity as the scene states it (usually -z);
  positions, velocities and angular velocities in the world frame; a body's frame has its
  origin at its centre of mass and the scene's axes (``BodySpec.orientation`` at t = 0);
- quaternions: unit, scalar first (w, x, y, z), rotating the body frame into the world;
- body order: the scene's ``bodies`` list, fixed bodies included (at rest); the ground plane
  is never a body of a snapshot;
- time: ``advance(n)`` moves the state on by n·dt (the scene's dt): n fixed steps for a
  ``fixed`` engine, the time n·dt at its stated accuracy for an ``error_controlled`` one;
  ``advance(n)`` equals n × ``advance(1)`` (exactly, or to ``advance_tolerance``), observing
  never changes the run, and the same scene and spec give the same states on every rerun;
- provenance: ``Provenance.settings`` holds every option the spec sets, under its name (or
  ``spec.<name>`` where the engine's own settings use the same name), with the value used.

``physval conformance ENGINE_SPEC`` checks an adapter against these rules.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from validation.engine_api import (
    API_VERSION,
    ENTRY_POINT_GROUP,
    FEATURES,
    SHAPES,
    Capabilities,
    Count,
    EngineDeclaration,
    EngineOption,
)
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec

__all__ = [
    "API_VERSION",
    "ENTRY_POINT_GROUP",
    "FEATURES",
    "SHAPES",
    "Capabilities",
    "CompiledScene",
    "Count",
    "EngineAdapter",
    "EngineDeclaration",
    "EngineOption",
    "EngineSpec",
    "JointReport",
    "ModelReport",
    "Provenance",
    "Snapshot",
    "StoppedEarlyError",
    "Trajectory",
]


@dataclass(frozen=True)
class Snapshot:
    """The scene's bodies at one instant (n bodies, scenario order).

    Attributes:
        time: s since the start.
        pos: (n, 3) m, world frame, centres of mass.
        quat: (n, 4) unit quaternions w x y z, body (scenario) frame to world.
        vel: (n, 3) m/s, world frame, centre-of-mass velocities.
        ang_vel: (n, 3) rad/s, world frame.
    """

    time: float
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray


@dataclass(frozen=True)
class Trajectory:
    """Observed states of one run (s states, n scene bodies, scenario order).

    Attributes:
        t: (s,) s. pos: (s, n, 3) m, world, centres of mass. quat: (s, n, 4) w x y z.
        vel: (s, n, 3) m/s, world. ang_vel: (s, n, 3) rad/s, world.
    """

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray

    @staticmethod
    def stack(snapshots: list[Snapshot]) -> Trajectory:
        return Trajectory(
            t=np.array([s.time for s in snapshots]),
            pos=np.stack([s.pos for s in snapshots]),
            quat=np.stack([s.quat for s in snapshots]),
            vel=np.stack([s.vel for s in snapshots]),
            ang_vel=np.stack([s.ang_vel for s in snapshots]),
        )

    def __len__(self) -> int:
        return int(self.t.size)

    def take(self, index) -> Trajectory:
        """The states at ``index`` (an int array or a slice)."""
        return Trajectory(
            *(a[index] for a in (self.t, self.pos, self.quat, self.vel, self.ang_vel))
        )

    @staticmethod
    def concat(*parts: Trajectory) -> Trajectory:
        """One trajectory of consecutive parts."""
        fields = ("t", "pos", "quat", "vel", "ang_vel")
        return Trajectory(*(np.concatenate([getattr(p, f) for p in parts]) for f in fields))


class StoppedEarlyError(Exception):
    """Raised by an adapter's ``advance_observed`` when the engine raised part of the way
    through: ``states`` are the states observed before it, the engine's own exception is the
    ``__cause__``. The recorder measures them, as it would have step by step: if one of them
    had failed the checks that failure is the run's finding, else the engine's exception is
    (an ``error`` row with the engine's message)."""

    def __init__(self, states: Trajectory):
        super().__init__(f"the engine raised after {len(states)} observed steps")
        self.states = states


@dataclass(frozen=True)
class ModelReport:
    """What an engine built, read back from the engine itself after loading (parity gate).

    Attributes:
        mass: (n,) kg.
        com: (n, 3) m, world frame.
        inertia_world: (n, 3, 3) kg·m², world frame, about each centre of mass.
        energy: J, kinetic + gravitational potential + spring energy at t = 0.
        linear_momentum: (3,) kg·m/s.
        angular_momentum: (3,) kg·m²/s, about the system's centre of mass.
    """

    mass: np.ndarray
    com: np.ndarray
    inertia_world: np.ndarray
    energy: float
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray


@dataclass(frozen=True)
class JointReport:
    """The joints an engine built, read back from the engine itself after loading (the parity
    gate of a scene with joints), in the scene's joint order.

    Attributes:
        types: each joint's type in the scene's words (hinge, slider, ball, fixed).
        anchors: (j, 3) m, world frame at t = 0: each joint's point as the engine holds it.
        axes: (j, 3) unit, world frame at t = 0 (hinge, slider; zeros for ball and fixed).
        mass_matrix: (nv, nv) the tree's mass matrix M(q0) from the engine's own computation,
            in the coordinates of ``CompiledScene.joint_tree`` (its ν: a hinge's or slider's
            rate, a ball's spin relative to its parent in the parent's frame, a floating root's
            v and ω in the world frame), or None for an engine that holds no joint coordinates
            (maximal coordinates: mini).
    """

    types: tuple[str, ...]
    anchors: np.ndarray
    axes: np.ndarray
    mass_matrix: np.ndarray | None = None
    limits: np.ndarray | None = None
    """(j, 2) rad or m, relative to t = 0 as the scene states them (lower <= 0 <= upper);
    NaN rows for joints without limits; None: not reported (model tier 1 then skips limits)."""
    damping: np.ndarray | None = None
    """(j,) N·m·s/rad or N·s/m; None: not reported."""
    armature: np.ndarray | None = None
    """(j,) kg·m² or kg, the reflected inertia added to a joint's diagonal of M; None: not
    reported (physval's scenes have none: 0)."""
    friction: np.ndarray | None = None
    """(j,) N·m or N, the joint's dry (Coulomb) friction the engine holds (MuJoCo's
    ``frictionloss``); None: not reported, read as 0 by the ``model_fields`` tier (physval's
    scene joints have no friction, so an engine built from them holds none)."""


@dataclass(frozen=True)
class ModelProbe:
    """A jointed scene's bodies and dynamics at one joint state, as the engine computes them
    (the model tiers 2 and 3, ``validation.measure.tiers``); optional ``model_probe``.

    Attributes:
        pos: (n, 3) m, world frame: every scene body's centre of mass.
        quat: (n, 4) w x y z, every scene body's orientation (the scene's body axes).
        mass_matrix: (nv, nv) M(q) in ``CompiledScene.joint_tree``'s coordinates, or None
            when the engine does not expose it.
        bias: (nv,) the bias forces C(q, ν)ν + g(q) in the same coordinates (sign: M ν̇ +
            bias = τ, MuJoCo's ``qfrc_bias``), or None when the engine does not expose it.
    """

    pos: np.ndarray
    quat: np.ndarray
    mass_matrix: np.ndarray | None = None
    bias: np.ndarray | None = None


@dataclass
class Provenance:
    """Enough to reproduce a run: the engine's version and its full effective settings."""

    engine: str
    version: str
    settings: dict[str, object] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


class EngineAdapter(Protocol):
    """One engine behind one small interface (Solver2D's pattern: one file per engine).

    Constructed with the parsed ``EngineSpec`` only (its settings already checked against the
    declaration); ``load`` is called once, then ``model_report`` (the parity gate), then
    ``advance``/``observe`` (or ``advance_observed``), ``provenance``, and always ``close``,
    also after an exception.
    """

    spec: EngineSpec

    def load(self, scene: CompiledScene) -> None:
        """Build the engine's model of the compiled scene at its scenario's dt."""

    def model_report(self) -> ModelReport:
        """Masses, centres of mass, world inertias and invariants as the engine holds them."""

    def advance(self, steps: int) -> None:
        """Advance ``steps`` fixed steps."""

    # Optional: ``advance_observed(steps) -> Trajectory``, the state after each of ``steps``
    # steps, for engines whose per-step observation costs more than their step (MuJoCo,
    # PyBullet). Without it the recording calls ``advance(1)`` and ``observe()`` per step.
    # An engine that refuses to step on from a non-finite state (Drake raises) returns the
    # states up to and including that one: the run is then ``unstable`` at that time, with
    # the states before it measured, as a step-by-step recording would find it. An engine
    # that raises otherwise part of the way through raises ``StoppedEarlyError`` from its error.

    # Optional: ``precision``, ``"float64"`` (the default) or ``"float32"``: the floating-point
    # type the engine computes in, which sets the parity gate's tolerance
    # (``validation.engines.parity.PRECISION_TOLERANCE``; Rapier's bindings are float32).

    # Required of an engine that declares ``joints``: ``joint_report() -> JointReport``, the
    # joints it built (``validation.engines.joint_parity`` compares them with the scene's).

    # Optional: ``model_probe(q, nu) -> ModelProbe``, the engine set to the joint state (q, ν)
    # of ``CompiledScene.joint_tree``'s coordinates (relative to t = 0) without stepping, and
    # its bodies, M(q) and bias read back (the model tiers). Without it the tiers load the
    # scene again at each probed state and take M and the bias from one-step finite
    # differences (stated as such in the row). Called after ``load``; the engine may be left
    # at the probed state (the runner loads the scene again before recording).

    def observe(self) -> Snapshot:
        """The current state, in the scene's conventions."""

    def provenance(self) -> Provenance:
        """Version and effective settings."""

    def close(self) -> None:
        """Release the engine (PyBullet clients, for example); idempotent."""
