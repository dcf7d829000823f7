"""The model tiers of a scene with robot models (issue 36): is it the model or the solver?

Each tier is one metric row per (scene, engine), computed in the worker that ran the engine,
against the reference side alone (physval's own reading of the model file, the joint tree and
its algorithms in ``validation.reference.articulated``), never against another engine:

1. ``model_fields`` (``model_fields``): what the engine holds after loading, each model
   link's mass, centre of mass and world inertia (its ``ModelReport``) and each model joint's
   type, anchor, axis, limits, damping, armature and friction (its ``JointReport``), against
   the scene's (a joint's friction against the model file's, ``ModelLayout.frictions``: the
   scene's joints have none). Every field is a relative difference on its own physical scale
   (the ``*_SCALE`` and ``*_FLOOR`` constants below); the row's value is the largest, its
   message names the link or joint and the field.
2. ``fk_error`` (``fk_error``): every model link's pose at the initial configuration and at
   ``RANDOM_STATES`` seeded random joint states (``probe_states``) against the reference's
   forward kinematics.
3. ``mass_matrix_error`` and ``bias_force_error``: M(q) and the bias forces b(q, ν) (gravity
   and velocity products, M ν̇ + b = τ) at the same states against the composite-rigid-body
   and Newton-Euler algorithms of the reference side, from the engine's ``model_probe`` when
   it has one. An engine without it (mini, Rapier, plugins) is loaded again at each state
   (``urdf.with_joint_state``): its observed poses give ``fk_error``, and two steps with no
   applied torque give the bias by a one-step finite difference (``_finite_difference``,
   stated in the row), its M only where ``joint_report`` carries M(q0) (Rapier) and no row
   otherwise.
4. The trajectory tier is the recording's: ``joint_divergence`` and ``agreement_time``
   across engines (``validation.measure.metrics``), ``energy_drift``, ``joint_violation``.

The tiers are defined only for scenes with ``models`` (``validation.scenario.definability``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from validation.engines.base import JointReport, ModelProbe, ModelReport
from validation.engines.joint_parity import expected_report
from validation.engines.reference import dynamic_bodies, reference_report
from validation.measure.measurement import Measurement
from validation.measure.resolution import FLOAT32_UNIT_ROUNDOFF
from validation.measure.tier_scales import (
    FINITE_DIFFERENCE,
    LIMIT_FLOOR,
    MODEL_METRICS,
    PROBE_SPEED,
    RANDOM_STATES,
    REACH_FLOOR,
    TIERS,
    TYPE_DIFFERENCE,
)
from validation.reference.articulated import (
    AXIS_TYPES,
    JointTree,
    Loads,
    bias_forces,
    forward_kinematics,
    initial_velocities,
    joint_coordinates,
    joint_forces,
    mass_matrix,
)
from validation.reference.rotation import quat_to_matrix
from validation.scenario.compiled import CompiledScene, compile_scene
from validation.scenario.urdf import ModelLayout, with_joint_state

__all__ = ["TIERS", "model_fields", "probe_tiers"]

SCALE_FLOOR = 1e-12
"""The smallest scale a tier's difference is divided by, in the scale's SI unit (a joint's
inertia for its armature, the largest entry of M or b): below it a scale is round-off (a joint
with no inertia, a bias at rest without gravity), and the difference is read as absolute."""

PROBE_SEED = 36
"""The seed of the probed states (issue 36): the same states in every engine and run."""

LIMIT_MARGIN = 0.1
"""Fraction of a limited joint's range left out at each end: probed states stay clear of the
stops, so the two steps of a finite difference never reach a limit."""

CONTINUOUS_RANGE = math.pi
"""rad: an unlimited hinge's angle is drawn in ±this."""

SLIDE_RANGE = 0.1
"""m: an unlimited slider's travel is drawn in ±this."""

UNIT_ROUNDOFF = {"float64": 2.0**-53, "float32": FLOAT32_UNIT_ROUNDOFF}
"""Half an ulp, relative, per declared precision (``engine_api.PRECISIONS``): how finely an
engine's observed poses, and the joint coordinates read from them, are resolved."""


# --- tier 1: the fields the engine holds ---------------------------------------------------


@dataclass(frozen=True)
class Difference:
    """One field of one model item: ``item`` ("link arm/lbr_iiwa_link_3", "joint arm/j2"),
    ``field`` ("inertia"), the relative ``value`` and how it was shown (``detail``)."""

    item: str
    field: str
    value: float
    detail: str = ""

    def message(self) -> str:
        extra = f"; {self.detail}" if self.detail else ""
        return f"{self.item}: {self.field} differs by {self.value:.2e} (relative{extra})"


def model_reach(scene: CompiledScene, layout: ModelLayout) -> float:
    """m, the largest distance of the model's link centres from its base at t = 0, at least
    ``REACH_FLOOR``."""
    index = {body.name: k for k, body in enumerate(scene.scenario.bodies)}
    centres = scene.start.pos[0][[index[name] for name in layout.bodies]]
    distances = np.linalg.norm(centres - np.asarray(layout.spec.position), axis=1)
    return max(REACH_FLOOR, float(distances.max(initial=0.0)))


def _link_differences(
    scene: CompiledScene, engine: ModelReport, reaches: dict[str, float]
) -> list[Difference]:
    """Mass (relative to the link's), centre of mass (to the model's reach) and world inertia
    (to the link's largest principal moment) of every model body."""
    expected = reference_report(scene)
    found = []
    for row, body in enumerate(dynamic_bodies(scene)):
        name = scene.scenario.bodies[body].name
        layout = scene.model_of(name)
        if layout is None:
            continue
        inertia = np.asarray(expected.inertia_world[row])
        moment = float(np.linalg.eigvalsh(inertia).max())
        item = f"link {name}"
        found += [
            _difference(item, "mass", engine.mass[row], expected.mass[row], expected.mass[row]),
            _difference(
                item, "centre of mass", engine.com[row], expected.com[row], reaches[layout.name]
            ),
            _difference(item, "inertia", engine.inertia_world[row], inertia, moment),
        ]
    return found


def _difference(item: str, field: str, engine, expected, scale: float) -> Difference:
    """The largest |engine - expected| entry relative to ``scale``; a non-finite engine value
    is a wholly wrong one (infinite)."""
    engine, expected = np.asarray(engine, dtype=float), np.asarray(expected, dtype=float)
    if not np.isfinite(engine).all():
        return Difference(item, field, math.inf, "not finite")
    value = float(np.abs(engine - expected).max(initial=0.0)) / max(scale, SCALE_FLOOR)
    return Difference(item, field, value)


def scene_joint_report(scene: CompiledScene) -> JointReport:
    """The reference side's ``JointReport`` with the fields tier 1 compares beyond the gate's:
    each joint's stated limits (NaN where unlimited), damping, armature 0 (physval's joints
    have none) and friction: a model joint's in its file (``ModelLayout.friction``), 0 for
    the scene's own joints."""
    joints = scene.scenario.joints
    limits = np.array(
        [j.limits if j.limits is not None else (math.nan, math.nan) for j in joints], dtype=float
    ).reshape(-1, 2)
    report = expected_report(scene)
    return JointReport(
        report.types,
        report.anchors,
        report.axes,
        report.mass_matrix,
        limits=limits,
        damping=np.array([j.damping for j in joints], dtype=float),
        armature=np.zeros(len(joints)),
        friction=np.array([_file_friction(scene, j.name) for j in joints], dtype=float),
    )


def _file_friction(scene: CompiledScene, joint: str) -> float:
    layout = scene.model_of(joint)
    return 0.0 if layout is None else layout.friction(joint)


def _joint_differences(
    scene: CompiledScene, engine: JointReport, reaches: dict[str, float]
) -> list[Difference]:
    """Type, anchor (relative to the model's reach), axis (|Δ unit vector|), limits (relative
    to max(|limit|, ``LIMIT_FLOOR``)), damping (relative to ``damping_scale``), armature
    (relative to the joint's diagonal of M(q0)) and friction (relative to ``friction_scale``;
    an engine that reports none holds none: 0) of every model joint the engine reports."""
    expected = scene_joint_report(scene)
    friction = np.zeros(len(expected.types)) if engine.friction is None else engine.friction
    inertia = _joint_inertia(scene)
    found = []
    for k, joint in enumerate(scene.scenario.joints):
        layout = scene.model_of(joint.name)
        if layout is None:
            continue
        item = f"joint {joint.name}"
        if engine.types[k] != expected.types[k]:
            detail = f"engine {engine.types[k]}, reference {expected.types[k]}"
            found.append(Difference(item, "type", TYPE_DIFFERENCE, detail))
        found.append(
            _difference(
                item, "anchor", engine.anchors[k], expected.anchors[k], reaches[layout.name]
            )
        )
        found.append(_difference(item, "axis", engine.axes[k], expected.axes[k], 1.0))
        if engine.limits is not None:
            found.append(_limits(item, engine.limits[k], expected.limits[k]))
        if engine.damping is not None:
            scale = damping_scale(scene, expected.damping[k], inertia.get(joint.name, 0.0))
            found.append(
                _difference(item, "damping", engine.damping[k], expected.damping[k], scale)
            )
        if engine.armature is not None:
            scale = inertia.get(joint.name, 0.0)
            found.append(_difference(item, "armature", engine.armature[k], 0.0, scale))
        scale = friction_scale(scene, expected.friction[k], inertia.get(joint.name, 0.0))
        found.append(_friction(item, friction[k], expected.friction[k], scale))
    return found


def _friction(item: str, engine: float, stated: float, scale: float) -> Difference:
    """The friction difference, its message showing both values (a dropped friction reads
    "engine 0, file 1")."""
    shown = f"engine {float(engine):.6g}, file {float(stated):.6g}"
    return replace(_difference(item, "friction", engine, stated, scale), detail=shown)


def friction_scale(scene: CompiledScene, stated: float, inertia: float) -> float:
    """N·m or N: a friction difference is relative to the file's friction (a dropped one
    differs by 1), or, where the file states none, to the torque that would stop the joint
    turning at ``PROBE_SPEED`` over the run (M_kk · PROBE_SPEED / t_end), as ``damping_scale``
    judges an engine's own default by what it would do to the run."""
    return abs(float(stated)) if stated else inertia * PROBE_SPEED / scene.scenario.duration


def damping_scale(scene: CompiledScene, stated: float, inertia: float) -> float:
    """N·m·s/rad or N·s/m: a damping difference is relative to the stated damping (a dropped
    one differs by 1), or, where the file states none, to the joint's inertia over the run's
    duration (M_kk / t_end, the damping that would take away the joint's rate over the run):
    an engine's own default damping is judged by what it would do to the run."""
    return abs(float(stated)) if stated else inertia / scene.scenario.duration


def _joint_inertia(scene: CompiledScene) -> dict[str, float]:
    """Each hinge's and slider's diagonal entry of the reference M(q0) (kg·m² or kg)."""
    tree = scene.joint_tree
    if tree is None:
        return {}
    matrix = mass_matrix(tree, tree.zero())
    return {
        joint.name: float(matrix[joint.v_slice.start, joint.v_slice.start])
        for joint in tree.joints
        if joint.type in AXIS_TYPES
    }


def _limits(item: str, engine: np.ndarray, expected: np.ndarray) -> Difference:
    """Both bounds, each relative to max(|bound|, ``LIMIT_FLOOR``); a bound on one side only is
    ``TYPE_DIFFERENCE``."""
    engine, expected = np.asarray(engine, dtype=float), np.asarray(expected, dtype=float)
    if np.isnan(engine).all() and np.isnan(expected).all():
        return Difference(item, "limits", 0.0)
    if np.isnan(engine).any() or np.isnan(expected).any():
        shown = f"engine {engine.tolist()}, reference {expected.tolist()}"
        return Difference(item, "limits", TYPE_DIFFERENCE, shown)
    scale = np.maximum(np.abs(expected), LIMIT_FLOOR)
    return Difference(item, "limits", float((np.abs(engine - expected) / scale).max()))


def model_fields(
    scene: CompiledScene, engine: ModelReport, joints: JointReport | None
) -> Measurement:
    """Tier 1: the largest relative difference over every field of every model link and joint
    between what the engine holds (its reports at load) and the scene; the message names the
    worst."""
    reaches = {layout.name: model_reach(scene, layout) for layout in scene.models}
    found = _link_differences(scene, engine, reaches)
    if joints is not None:
        found += _joint_differences(scene, joints, reaches)
    worst = max(found, key=lambda d: d.value)
    return Measurement("model_fields", worst.value, 0.0, "analytic", worst.value, worst.message())


# --- the probed states ---------------------------------------------------------------------


@dataclass(frozen=True)
class ProbeState:
    """One joint state of the tree (``q (nq,)``, ``nu (nv,)``, relative to t = 0) and the same
    state as the model files' joints (``positions``, ``velocities``: prefixed joint name ->
    the file's coordinate and rate, ``urdf.with_joint_state``'s arguments)."""

    q: np.ndarray
    nu: np.ndarray
    positions: dict[str, float]
    velocities: dict[str, float]


def _model_joints(scene: CompiledScene) -> dict[str, tuple[ModelLayout, str]]:
    """Scene joint name -> (its model, its file joint) of every model hinge and slider."""
    owned = {}
    for layout in scene.models:
        for name, file_joint in zip(layout.joints, layout.file_joints, strict=True):
            if file_joint is not None:
                owned[name] = (layout, file_joint)
    return owned


def _drawn(rng: np.random.Generator, joint_type: str, limits) -> float:
    """A coordinate inside ``limits`` (``LIMIT_MARGIN`` clear of each stop) or, unlimited,
    within ``CONTINUOUS_RANGE`` or ``SLIDE_RANGE``."""
    if limits is None:
        reach = CONTINUOUS_RANGE if joint_type == "hinge" else SLIDE_RANGE
        return float(rng.uniform(-reach, reach))
    lower, upper = limits
    margin = LIMIT_MARGIN * (upper - lower)
    return float(rng.uniform(lower + margin, upper - margin))


def probe_states(scene: CompiledScene) -> list[ProbeState]:
    """The initial state (q0, ν0 the stated rates) and ``RANDOM_STATES`` seeded random ones,
    in which every model hinge and slider takes a coordinate within its limits (``_drawn``)
    and a rate within ±``PROBE_SPEED``; every other coordinate keeps its initial value
    (``ValueError`` for a scene without joints: the probed rows say so)."""
    tree = scene.joint_tree
    if tree is None:
        raise ValueError("the scene has no joints: there is no joint state to probe")
    start = scene.start
    nu0, _ = initial_velocities(tree, start.vel[0], start.ang_vel[0])
    owned = _model_joints(scene)
    limits = {joint.name: joint.limits for joint in scene.scenario.joints}
    rng = np.random.default_rng(PROBE_SEED)
    states = [_state(tree, owned, tree.zero(), nu0)]
    for _ in range(RANDOM_STATES):
        q, nu = tree.zero(), nu0.copy()
        for joint in tree.joints:
            if joint.name in owned and joint.type in AXIS_TYPES:
                q[joint.q_slice.start] = _drawn(rng, joint.type, limits[joint.name])
                nu[joint.v_slice.start] = float(rng.uniform(-PROBE_SPEED, PROBE_SPEED))
        states.append(_state(tree, owned, q, nu))
    return states


def _state(tree: JointTree, owned, q: np.ndarray, nu: np.ndarray) -> ProbeState:
    positions, velocities = {}, {}
    for joint in tree.joints:
        if joint.name in owned and joint.type in AXIS_TYPES:
            layout, file_joint = owned[joint.name]
            key = f"{layout.name}/{file_joint}"
            positions[key] = layout.initial_position(file_joint) + float(q[joint.q_slice.start])
            velocities[key] = float(nu[joint.v_slice.start])
    return ProbeState(q, nu, positions, velocities)


# --- tiers 2 and 3 -------------------------------------------------------------------------


@dataclass(frozen=True)
class Probed:
    """What one probed state gave: the engine's model bodies' poses, and M and b where the
    engine gives them (``ModelProbe``'s fields); ``bias_band`` (N·m or N) the allowance of a
    finite-difference bias (``_finite_difference``), 0 for an engine's own."""

    pos: np.ndarray
    rot: np.ndarray
    mass_matrix: np.ndarray | None
    bias: np.ndarray | None
    bias_error: np.ndarray | None = None
    """(nv,) a finite difference's residual M q̈ + b - τ (replaces bias - b_ref)."""
    bias_reference: np.ndarray | None = None
    bias_band: float = 0.0


def _loads(scene: CompiledScene) -> Loads:
    """What pushes the tree besides its joints (the reference motion's loads)."""
    return Loads(scene.gravity, scene.springs, scene.force, scene.torque)


def _model_bodies(scene: CompiledScene) -> list[int]:
    index = {body.name: k for k, body in enumerate(scene.scenario.bodies)}
    return [index[name] for layout in scene.models for name in layout.bodies]


def fk_error(
    scene: CompiledScene, states: list[ProbeState], probed: list[Probed], how: str
) -> Measurement:
    """Tier 2: over the probed states and model links, max(|Δ centre|, rotation angle × the
    model's reach) (m) against the reference's forward kinematics."""
    tree, bodies = scene.joint_tree, _model_bodies(scene)
    reach = max(model_reach(scene, layout) for layout in scene.models)
    worst, where = -1.0, ""
    for k, (state, got) in enumerate(zip(states, probed, strict=True)):
        pose = forward_kinematics(tree, state.q)
        for body in bodies:
            offset = float(np.linalg.norm(got.pos[body] - pose.pos[body]))
            turned = rotation_angle(pose.rot[body].T @ got.rot[body]) * reach
            value = offset if not offset < turned else turned
            if not value <= worst:
                worst = value
                field = "centre" if not offset < turned else "orientation x reach"
                where = (
                    f"at configuration {k + 1} of {len(states)}, link "
                    f"{scene.scenario.bodies[body].name}: {field} off by {value:.2e} m ({how})"
                )
    return Measurement("fk_error", worst, 0.0, "analytic", worst, where)


def rotation_angle(relative: np.ndarray) -> float:
    """The angle (rad) of the rotation matrix ``relative`` (3, 3), from its sine and cosine
    together: accurate to round-off at small angles, where the arccosine of the trace alone
    loses half the digits (1e-8 rad read for 1e-16)."""
    sine = 0.5 * np.linalg.norm(
        [
            relative[2, 1] - relative[1, 2],
            relative[0, 2] - relative[2, 0],
            relative[1, 0] - relative[0, 1],
        ]
    )
    cosine = 0.5 * (np.trace(relative) - 1.0)
    return float(np.arctan2(sine, cosine))


def mass_matrix_error(
    scene: CompiledScene, states: list[ProbeState], probed: list[Probed], how: str
) -> Measurement | None:
    """Tier 3: max over the probed states of max |ΔM| / max |M_ref| (relative), None when the
    engine gave no M."""
    tree = scene.joint_tree
    worst, where = -1.0, ""
    for k, (state, got) in enumerate(zip(states, probed, strict=True)):
        if got.mass_matrix is None:
            continue
        expected = mass_matrix(tree, state.q)
        difference = np.abs(np.asarray(got.mass_matrix, dtype=float) - expected)
        value = float(difference.max()) / max(float(np.abs(expected).max()), SCALE_FLOOR)
        if not value <= worst:
            worst = value
            row, column = np.unravel_index(int(np.nanargmax(difference)), difference.shape)
            where = (
                f"at configuration {k + 1} of {len(states)}, M[{row},{column}] "
                f"({_coordinate(tree, row)}, {_coordinate(tree, column)}): "
                f"engine {got.mass_matrix[row][column]:.6g}, reference "
                f"{expected[row, column]:.6g} ({how})"
            )
    if worst < 0.0:
        return None
    return Measurement("mass_matrix_error", worst, 0.0, "analytic", worst, where)


def bias_force_error(
    scene: CompiledScene, states: list[ProbeState], probed: list[Probed], how: str
) -> Measurement | None:
    """Tier 3: max |Δb| at the probed state farthest beyond its band, relative to max |b_ref|
    over every probed state (one scale for the row: a state near equilibrium, where gravity's
    torques vanish, would otherwise divide round-off by round-off), None when the engine gave
    no bias; a finite difference's row carries that state's band, on the same scale."""
    tree = scene.joint_tree
    found = []
    for state, got in zip(states, probed, strict=True):
        if got.bias_error is not None:
            found.append((got.bias_error, got.bias_reference, got.bias_band))
        elif got.bias is not None:
            expected = bias_forces(tree, state.q, state.nu, _loads(scene))
            found.append((np.asarray(got.bias, dtype=float) - expected, expected, 0.0))
        else:
            found.append(None)
    if all(entry is None for entry in found):
        return None
    scale = max(
        max(float(np.abs(entry[1]).max(initial=0.0)) for entry in found if entry is not None),
        SCALE_FLOOR,
    )
    worst, where, band = -math.inf, "", 0.0
    for k, entry in enumerate(found):
        if entry is None:
            continue
        residual, _, state_band = entry
        value = float(np.abs(residual).max(initial=0.0)) / scale
        if not value - state_band / scale <= worst - band:
            worst, band = value, state_band / scale
            row = int(np.nanargmax(np.abs(residual)))
            where = (
                f"at configuration {k + 1} of {len(states)}, b[{row}] "
                f"({_coordinate(tree, row)}): off by {abs(residual[row]):.3g} of max |b| "
                f"{scale:.3g} ({how})"
            )
    if worst == -math.inf:
        return None
    return Measurement("bias_force_error", worst, 0.0, "analytic", worst, where, band=band)


def _coordinate(tree: JointTree, index: int) -> str:
    """The joint a velocity coordinate belongs to."""
    return next(j.name for j in tree.joints if j.v_slice.start <= index < j.v_slice.stop)


# --- how an engine is probed ----------------------------------------------------------------


def probe_with(adapter, scene: CompiledScene, states: list[ProbeState]) -> list[Probed]:
    """Each state through the engine's own ``model_probe(q, ν)``."""
    probed = []
    for state in states:
        found: ModelProbe = adapter.model_probe(state.q, state.nu)
        probed.append(
            Probed(
                np.asarray(found.pos, dtype=float),
                quat_to_matrix(np.asarray(found.quat, dtype=float)),
                found.mass_matrix,
                found.bias,
            )
        )
    return probed


def probe_by_loading(
    make_adapter: Callable[[], object],
    scene: CompiledScene,
    states: list[ProbeState],
    mass_matrix_q0: np.ndarray | None,
    precision: str,
) -> list[Probed]:
    """Each state as a scene of its own (``with_joint_state``), loaded in a fresh adapter
    (``make_adapter()``): its first observed poses, and the bias by ``_finite_difference``;
    M only at q0, where the engine's ``joint_report`` carried it (``mass_matrix_q0``)."""
    probed = []
    for k, state in enumerate(states):
        scenario = with_joint_state(scene.scenario, state.positions, state.velocities)
        adapter = make_adapter()
        try:
            adapter.load(compile_scene(scenario))
            snapshots = [adapter.observe()]
            for _ in range(2):
                adapter.advance(1)
                snapshots.append(adapter.observe())
        finally:
            adapter.close()
        pos = np.stack([s.pos for s in snapshots])
        rot = quat_to_matrix(np.stack([s.quat for s in snapshots]))
        residual, expected, band = _finite_difference(scene, pos, rot, precision)
        probed.append(
            Probed(
                pos[0],
                rot[0],
                mass_matrix_q0 if k == 0 else None,
                None,
                residual,
                expected,
                band,
            )
        )
    return probed


def _finite_difference(scene: CompiledScene, pos: np.ndarray, rot: np.ndarray, precision: str):
    """The engine's bias from three observed states two steps apart with no applied torque:
    the joint coordinates read from the poses (``articulated.joint_coordinates``), q̈ their
    second difference / dt², and the residual of the reference's equation at the middle
    state, ``M_ref(q1) q̈ + b_ref(q1, ν) + d ν`` (zero for an engine whose dynamics is the
    reference's), ν the central difference (q2 - q0) / 2dt.

    The band: an integrator of order one reads the velocity terms at an end of the step, not
    in its middle (semi-implicit Euler's q̈ is the acceleration at ν_back = (q1 - q0) / dt;
    MuJoCo's implicit damping reads d ν at ν_fwd = (q2 - q1) / dt), so each of b's velocity
    terms and the damping may sit anywhere between the two readings: per coordinate, the
    largest change of b_ref and of d ν from ν to either, added (they need not cancel), O(dt),
    relative like the error. To it is added what the engine's ``precision`` cannot resolve:
    coordinates read to ``UNIT_ROUNDOFF`` × (1 + |q|) each, whose second difference is off by
    up to 4 of them / dt², times each row of |M_ref| (a float32 engine's bias is noise at
    small dt; a float64 engine's term is round-off). Returns (residual (nv,), b_ref (nv,),
    band), the band in N·m or N like the residual (``bias_force_error`` scales both). A tree with a ball or free joint has no such difference (``ValueError``)."""
    tree = scene.joint_tree
    if any(joint.type in ("ball", "free") for joint in tree.joints):
        raise ValueError(f"a {FINITE_DIFFERENCE} needs hinges and sliders only")
    dt = scene.scenario.dt
    coordinates = joint_coordinates(tree, pos, rot)
    q = np.zeros((3, tree.nq))
    for joint in tree.joints:
        if joint.type in AXIS_TYPES:
            q[:, joint.q_slice.start] = coordinates[joint.name]
    acceleration = (q[2] - 2.0 * q[1] + q[0]) / dt**2
    central = (q[2] - q[0]) / (2.0 * dt)
    ends = ((q[1] - q[0]) / dt, (q[2] - q[1]) / dt)
    loads = _loads(scene)
    expected, matrix = bias_forces(tree, q[1], central, loads), mass_matrix(tree, q[1])
    residual = matrix @ acceleration + expected - joint_forces(tree, central)
    bias_spread = np.max([np.abs(bias_forces(tree, q[1], nu, loads) - expected) for nu in ends], 0)
    damping_spread = np.max([np.abs(joint_forces(tree, nu - central)) for nu in ends], axis=0)
    resolution = 4.0 * UNIT_ROUNDOFF[precision] * (1.0 + np.abs(q).max()) / dt**2
    unresolved = np.abs(matrix).sum(axis=1) * resolution
    band = (bias_spread + damping_spread + unresolved).max(initial=0.0)
    return residual, expected, float(band)


def not_computed(name: str, error: Exception) -> Measurement:
    """The NaN row of a tier that raised, its message carrying the exception."""
    message = f"not computed: {type(error).__name__}: {error}"
    return Measurement(name, math.nan, None, "analytic", math.nan, message)


def guarded(name: str, compute: Callable[[], Measurement | None]) -> Measurement | None:
    """A tier's row, or a NaN row whose message carries the exception: a probe that fails
    is the row's finding, never the job's crash."""
    try:
        return compute()
    except Exception as error:  # reported in the row's message
        return not_computed(name, error)


def probe_tiers(
    scene: CompiledScene,
    adapter,
    make_adapter: Callable[[], object],
    mass_matrix_q0: np.ndarray | None,
    precision: str = "float64",
) -> list[Measurement]:
    """Tiers 2 and 3 of a scene with models: the probed states through the engine's
    ``model_probe`` when it has one, else each loaded afresh (``probe_by_loading``; the
    engine's declared ``precision`` sets what its finite difference resolves); every failure a
    NaN row naming it."""
    try:
        states = probe_states(scene)
        if hasattr(adapter, "model_probe"):
            probed, how = probe_with(adapter, scene, states), PROBED_BY["model_probe"]
        else:
            probed = probe_by_loading(make_adapter, scene, states, mass_matrix_q0, precision)
            how = PROBED_BY["loading"]
    except Exception as error:  # the probe's failure is every probed row's finding
        return [not_computed(name, error) for name in MODEL_METRICS[1:]]
    rows = [
        guarded("fk_error", lambda: fk_error(scene, states, probed, how["fk_error"])),
        guarded(
            "mass_matrix_error",
            lambda: mass_matrix_error(scene, states, probed, how["mass_matrix_error"]),
        ),
        guarded(
            "bias_force_error",
            lambda: bias_force_error(scene, states, probed, how["bias_force_error"]),
        ),
    ]
    return [row for row in rows if row is not None]


PROBED_BY: dict[str, dict[str, str]] = {
    "model_probe": dict.fromkeys(MODEL_METRICS[1:], "the engine's model_probe"),
    "loading": {
        "fk_error": "a fresh load at each configuration",
        "mass_matrix_error": "the engine's joint_report M(q0)",
        "bias_force_error": FINITE_DIFFERENCE,
    },
}
"""How each probed row was computed, by how the engine is probed: the end of its message."""
