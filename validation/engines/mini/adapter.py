"""The mini adapter: ``mini_engine`` with its ``Settings`` taken from the engine spec."""

from __future__ import annotations

import importlib.metadata
from dataclasses import replace

import numpy as np

from mini_engine import Settings, step
from mini_engine.joints import JOINT_TYPES, WORLD
from mini_engine.rotation import quat_to_matrix, world_inertia
from validation.engines.base import (
    JointReport,
    ModelReport,
    Provenance,
    Snapshot,
    StoppedEarlyError,
    Trajectory,
)
from validation.engines.mini.model import build_mini_model
from validation.engines.reference import scene_report
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec


class MiniAdapter:
    """mini_engine as an ``EngineAdapter``; the scene's bodies come first in its model."""

    def __init__(self, spec: EngineSpec):
        self.spec = spec

    def load(self, scene: CompiledScene) -> None:
        self.scene = scene
        self.settings = Settings(dt=scene.scenario.dt, **self.spec.as_dict())
        self.model, self.state = build_mini_model(scene.scenario)
        self.count = scene.count

    def model_report(self) -> ModelReport:
        """The model's own masses and world inertias, and the invariants of its state."""
        n, moving, state = self.count, self.scene.moving, self.state
        report = scene_report(
            self.scene, state.pos[:n], state.quat[:n], state.vel[:n], state.ang_vel[:n]
        )
        rot = quat_to_matrix(state.quat[:n])
        return replace(
            report,
            mass=self.model.body_mass[:n][moving].copy(),
            inertia_world=world_inertia(rot, self.model.body_inertia[:n])[moving],
        )

    def joint_report(self) -> JointReport:
        """The model's joints at the initial poses: each one's type, its anchor as a point of
        its parent (a world point for the world) and its axis as the parent carries it, its
        limits (NaN where it has none), damping and armature (mini has none: 0); no mass
        matrix (mini holds bodies, not joint coordinates)."""
        joints, state = self.model.joints, self.state
        rot = quat_to_matrix(state.quat)
        world = joints.body_a == WORLD
        parent = np.where(world, 0, joints.body_a)
        anchors = np.where(
            world[:, None],
            joints.anchor_a,
            state.pos[parent] + np.einsum("jik,jk->ji", rot[parent], joints.anchor_a),
        )
        axes = np.where(
            world[:, None], joints.axis_a, np.einsum("jik,jk->ji", rot[parent], joints.axis_a)
        )
        bounds = np.stack([joints.lower, joints.upper], axis=1)
        return JointReport(
            tuple(JOINT_TYPES[k] for k in joints.kind),
            anchors,
            axes,
            limits=np.where(np.isfinite(bounds), bounds, np.nan),
            damping=np.asarray(joints.damping, dtype=float).copy(),
            armature=np.zeros(joints.damping.shape),
        )

    def advance(self, steps: int) -> None:
        state = self.state
        for _ in range(steps):
            state, _ = step(self.model, state, self.settings)
        self.state = state

    def advance_observed(self, steps: int) -> Trajectory:
        """``steps`` steps, the scene bodies' state after each copied into one trajectory (the
        step-by-step ``advance(1)`` and ``observe()``, without a snapshot per step); it ends
        at the first state whose positions or velocities are not finite, which is not stepped
        on from (the recorder names it)."""
        n, model, settings = self.count, self.model, self.settings
        observed = Trajectory(np.empty(steps), *(np.empty((steps, n, k)) for k in (3, 4, 3, 3)))
        state, taken = self.state, 0
        try:
            while taken < steps:
                state, _ = step(model, state, settings)
                self.state = state
                observed.t[taken] = state.time
                observed.pos[taken] = state.pos[:n]
                observed.quat[taken] = state.quat[:n]
                observed.vel[taken] = state.vel[:n]
                observed.ang_vel[taken] = state.ang_vel[:n]
                taken += 1
                if not (
                    np.isfinite(observed.pos[taken - 1]).all()
                    and np.isfinite(observed.vel[taken - 1]).all()
                ):
                    break
        except Exception as error:
            raise StoppedEarlyError(observed.take(slice(0, taken))) from error
        return observed if taken == steps else observed.take(slice(0, taken))

    def observe(self) -> Snapshot:
        s, n = self.state, self.count
        return Snapshot(
            s.time, s.pos[:n].copy(), s.quat[:n].copy(), s.vel[:n].copy(), s.ang_vel[:n].copy()
        )

    def provenance(self) -> Provenance:
        return Provenance(
            engine="mini_engine",
            version=importlib.metadata.version("physval"),
            settings=self.settings.as_dict(),
            notes=["numpy " + np.__version__],
        )

    def close(self) -> None:
        """Nothing to release."""
