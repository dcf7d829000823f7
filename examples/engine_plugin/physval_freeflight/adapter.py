"""The freeflight engine behind physval's adapter protocol.

Translation is exact: with gravity g and a constant force F, x(t) = x0 + v0 t + ½ a t² and
v(t) = v0 + a t, a = g + F/m. Rotation: the angular momentum about the centre of mass is
exact too, L(t) = L0 + τ t for a constant world torque τ; the orientation follows
q̇ = ½ [0, ω] ⊗ q with ω = I_world(q)⁻¹ L, integrated by RK4 (or a first-order exponential
map, option ``rotation``). The state is kept in physval's conventions already (world frame,
centre of mass, quaternions w x y z), so the boundary needs no conversion.
"""

from __future__ import annotations

import importlib.metadata

import numpy as np

from validation.engines.base import CompiledScene, EngineSpec, ModelReport, Provenance, Snapshot


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """(n, 3, 3) body-to-world rotations of unit quaternions (n, 4) w x y z."""
    w, x, y, z = np.moveaxis(quat, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(n, 4) Hamilton products p ⊗ q, w x y z."""
    pw, pv, qw, qv = p[:, :1], p[:, 1:], q[:, :1], q[:, 1:]
    return np.hstack(
        [pw * qw - np.sum(pv * qv, 1, keepdims=True), pw * qv + qw * pv + np.cross(pv, qv)]
    )


def exp_map(rotation_vector: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions of rotation vectors (n, 3) rad."""
    angle = np.linalg.norm(rotation_vector, axis=1, keepdims=True)
    safe = np.where(angle > 0, angle, 1.0)
    return np.hstack([np.cos(angle / 2), np.sin(angle / 2) * rotation_vector / safe])


class FreeFlightAdapter:
    """freeflight as a physval ``EngineAdapter`` (one instance per run)."""

    def __init__(self, spec: EngineSpec):
        self.spec = spec
        settings = spec.as_dict()
        self.rotation = str(settings.get("rotation", "rk4"))
        self.substeps = int(settings.get("substeps", 1))
        self.loaded = False

    def load(self, scene: CompiledScene) -> None:
        """The scene's bodies at t = 0 (centres of mass, world frame), its masses, body-frame
        inertias, gravity and loads."""
        start = scene.start
        self.dt, self.steps_taken = scene.scenario.dt, 0
        self.mass = np.asarray(scene.mass, dtype=float)
        self.inertia_body = np.asarray(scene.inertia, dtype=float)
        self.acceleration = np.asarray(scene.gravity)[None] + scene.force / self.mass[:, None]
        self.torque = np.asarray(scene.torque, dtype=float)
        self.gravity, self.force = np.asarray(scene.gravity), np.asarray(scene.force)
        self.pos0, self.vel0 = start.pos[0].copy(), start.vel[0].copy()
        self.quat = start.quat[0].copy()
        self.momentum0 = np.einsum("nij,nj->ni", self._inertia_world(self.quat), start.ang_vel[0])
        self.loaded = True

    def _inertia_world(self, quat: np.ndarray) -> np.ndarray:
        rot = quat_to_matrix(quat)
        return rot @ self.inertia_body @ rot.transpose(0, 2, 1)

    def _omega(self, quat: np.ndarray, time: float) -> np.ndarray:
        """(n, 3) rad/s, world: I_world(q)⁻¹ L(t)."""
        momentum = self.momentum0 + self.torque * time
        return np.linalg.solve(self._inertia_world(quat), momentum[..., None])[..., 0]

    def _rotate(self, quat: np.ndarray, time: float, h: float) -> np.ndarray:
        if self.rotation == "exponential":
            return quat_multiply(exp_map(self._omega(quat, time) * h), quat)

        def rate(q: np.ndarray, t: float) -> np.ndarray:
            omega = self._omega(q / np.linalg.norm(q, axis=1, keepdims=True), t)
            return 0.5 * quat_multiply(np.hstack([np.zeros((len(q), 1)), omega]), q)

        k1 = rate(quat, time)
        k2 = rate(quat + 0.5 * h * k1, time + 0.5 * h)
        k3 = rate(quat + 0.5 * h * k2, time + 0.5 * h)
        k4 = rate(quat + h * k3, time + h)
        return quat + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def advance(self, steps: int) -> None:
        """``steps`` steps of dt: the orientation integrated, the rest evaluated exactly."""
        h = self.dt / self.substeps
        for _ in range(steps):
            for sub in range(self.substeps):
                time = self.steps_taken * self.dt + sub * h
                quat = self._rotate(self.quat, time, h)
                self.quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
            self.steps_taken += 1

    def observe(self) -> Snapshot:
        time = self.steps_taken * self.dt
        return Snapshot(
            time,
            self.pos0 + self.vel0 * time + 0.5 * self.acceleration * time**2,
            self.quat.copy(),
            self.vel0 + self.acceleration * time,
            self._omega(self.quat, time),
        )

    def model_report(self) -> ModelReport:
        """Masses, centres of mass and world inertias as this engine holds them; the energy
        (kinetic, gravitational -m g·x and applied-force -F·x potentials) and momenta of its
        state (angular about the system's centre of mass)."""
        state = self.observe()
        inertia = self._inertia_world(state.quat)
        spin = np.einsum("nij,nj->ni", inertia, state.ang_vel)
        energy = (
            0.5 * np.einsum("n,ni,ni->", self.mass, state.vel, state.vel)
            + 0.5 * np.einsum("ni,ni->", state.ang_vel, spin)
            - np.einsum("n,ni,i->", self.mass, state.pos, self.gravity)
            - np.einsum("ni,ni->", self.force, state.pos)
        )
        centre = np.einsum("n,ni->i", self.mass, state.pos) / self.mass.sum()
        orbital = np.einsum("n,ni->i", self.mass, np.cross(state.pos - centre, state.vel))
        return ModelReport(
            mass=self.mass.copy(),
            com=state.pos,
            inertia_world=inertia,
            energy=float(energy),
            linear_momentum=np.einsum("n,ni->i", self.mass, state.vel),
            angular_momentum=orbital + spin.sum(axis=0),
        )

    def provenance(self) -> Provenance:
        return Provenance(
            engine="freeflight",
            version=importlib.metadata.version("physval-freeflight"),
            settings={"rotation": self.rotation, "substeps": self.substeps},
            notes=["exact ballistic translation; angular momentum exact, orientation integrated"],
        )

    def close(self) -> None:
        """Nothing outside Python to release; the arrays go with the adapter."""
        self.loaded = False
