"""The MuJoCo adapter: the MJCF of ``mjcf`` compiled, stepped by ``mujoco.mj_step`` and read
back in the scene's conventions (see ``mjcf`` for the model and the state conversion).

MuJoCo's warnings never reach the working folder: while the adapter calls into MuJoCo, a
``mju_user_warning`` handler collects them (MuJoCo would otherwise print them and append
them to ``MUJOCO_LOG.TXT`` in the current directory); ``instability_warnings`` and
``provenance`` report what was collected."""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType

import numpy as np

from validation.engine_api import model_loader
from validation.engines.base import (
    JointReport,
    ModelProbe,
    ModelReport,
    Provenance,
    Snapshot,
    Trajectory,
)
from validation.engines.frames import matrix_to_quat
from validation.engines.mujoco.mjcf import (
    DEFAULT_SETTINGS,
    INERTIAL_ORIGIN_TOLERANCE,
    JOINT_WORDS,
    RESTITUTION_NOTES,
    build_mjcf,
    contact_note,
)
from validation.engines.mujoco.native import (
    body_offsets,
    compile_with_models,
    joint_friction,
    offset_quaternions,
    set_joint_state,
    without_models,
)
from validation.engines.reference import dynamic_bodies
from validation.reference.rotation import cross, quat_multiply, quat_to_matrix
from validation.scenario import Scenario
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec

NO_RENDERING = {"MUJOCO_GL": "disable"}
"""physval never renders: without this, ``import mujoco`` loads GLFW, whose import starts a
second Python to query the library's version; a Ctrl-C at that moment left that process
printing a BrokenPipeError traceback after the run's one line. A user's own ``MUJOCO_GL``
is kept."""


def _import_headless(name: str) -> ModuleType:
    """``import name`` with ``NO_RENDERING`` in the environment (unless already set)."""
    for variable, value in NO_RENDERING.items():
        os.environ.setdefault(variable, value)
    return importlib.import_module(name)


mujoco = _import_headless("mujoco")

# --- provenance helpers -------------------------------------------------------------------

INSTABILITY_WARNINGS = (
    "mjWARN_BADQACC",
    "mjWARN_BADQPOS",
    "mjWARN_BADQVEL",
    "mjWARN_CNSTRFULL",
    "mjWARN_CONTACTFULL",
)
"""MuJoCo warnings that mean the simulation broke down (it resets the state on bad
qacc/qpos/qvel, which would otherwise hide an explosion) or silently lost contacts."""

OPTION_ENUMS: dict[str, type] = {
    "integrator": mujoco.mjtIntegrator,
    "solver": mujoco.mjtSolver,
    "cone": mujoco.mjtCone,
    "jacobian": mujoco.mjtJacobian,
}
"""``m.opt`` fields that are enum codes; provenance also records their names."""


def _plain(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _flag_names(bits: int, enum: type) -> list[str]:
    """Names of the bits set in ``bits`` (``mjN...`` members are counts, not bits)."""
    return [
        name
        for name, flag in enum.__members__.items()
        if not name.startswith("mjN") and int(flag) and bits & int(flag) == int(flag)
    ]


def option_settings(model: mujoco.MjModel) -> dict[str, object]:
    """Every field of ``model.opt`` as plain Python values, enum and flag names added."""
    opt = model.opt
    fields = {
        name: _plain(getattr(opt, name))
        for name in dir(opt)
        if not name.startswith("_") and not callable(getattr(opt, name))
    }
    for name, enum in OPTION_ENUMS.items():
        if name in fields:
            fields[f"{name}_name"] = enum(fields[name]).name
    fields["disableflags_names"] = _flag_names(opt.disableflags, mujoco.mjtDisableBit)
    fields["enableflags_names"] = _flag_names(opt.enableflags, mujoco.mjtEnableBit)
    return fields


@contextmanager
def collected_warnings(sink: list[str]) -> Iterator[None]:
    """MuJoCo's warning messages appended to ``sink`` instead of printed and logged to
    ``MUJOCO_LOG.TXT``; the previous handler (process-wide) is restored afterwards."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(sink.append)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


# --- the adapter --------------------------------------------------------------------------


FRICTION_IN_IMPACTS = (
    "friction in impacts is not honoured under restitution=damper: the sliding-friction rows "
    "stay soft (solreffriction 0.02 s), so a one-step impact gets almost no friction impulse "
    "(measured: a ball at 3 m/s across, 2 m/s down, μ = 0.3, e = 0.5 leaves at 2.914 m/s "
    "where rigid Coulomb impulse theory gives 2.143; with backspin 0.857 against 0.100). A "
    "stiff friction damper (solreffriction 0 -1/dt) gets sliding impacts right (2.140) but "
    "launches a backspinning ball (vz 1.425 for e·v = 1.0; pyramidal cones worse, 2.009); "
    "impratio and noslip_iterations change nothing measurable. No setting gives both: for "
    "friction-dominated impacts read mujoco(restitution=soft), whose friction is right and "
    "whose e is not"
)
"""The limit of the damper calibration with friction, measured as written; listed in the provenance of every run whose scene has frictional pairs."""


def _slid(m, d, jid: int) -> float:
    """m: a slide joint's displacement from its ``qpos0`` (0 for other joints). MuJoCo's
    ``xanchor`` of a slide is its point at ``qpos0``, fixed in the parent; the scene's anchor
    moves with the child (a native model's slide may start away from ``qpos0``)."""
    if m.jnt_type[jid] != mujoco.mjtJoint.mjJNT_SLIDE:
        return 0.0
    adr = m.jnt_qposadr[jid]
    return float(d.qpos[adr] - m.qpos0[adr])


def _skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) [v]×, the matrix of ``v × ·``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _conjugate(quat: np.ndarray) -> np.ndarray:
    """The inverse of a unit quaternion w x y z."""
    return quat * np.array([1.0, -1.0, -1.0, -1.0])


class MujocoAdapter:
    """MuJoCo as an ``EngineAdapter``; ``observe`` returns the scene's bodies in order."""

    def __init__(self, spec: EngineSpec):
        self.spec = spec
        self.settings = {**DEFAULT_SETTINGS, **spec.as_dict()}

    def load(self, scene: CompiledScene) -> None:
        """Compile the scene's MJCF and set the initial state (world ω -> body-frame qvel)."""
        self.scene = scene
        self.scenario = scenario = scene.scenario
        self.messages: list[str] = []  # MuJoCo's warning messages so far, as it words them
        self.tree = scene.joint_tree
        self.loader = model_loader(self.spec.name, self.settings)
        self.natives, self.attach_notes = [], []
        if self.loader == "native" and scene.models:
            rest, rest_tree = without_models(scene)
            self.xml, self.plan, self.solver = build_mjcf(rest, self.settings, rest_tree)
            with collected_warnings(self.messages):
                self.model, self.attach_notes = compile_with_models(self.xml, scene.models)
                self.natives = list(scene.models)
                self.data = mujoco.MjData(self.model)
            set_joint_state(self.model, self.data, self.natives)
        else:
            self.xml, self.plan, self.solver = build_mjcf(scenario, self.settings, self.tree)
            with collected_warnings(self.messages):
                self.model = mujoco.MjModel.from_xml_string(self.xml)
                self.data = mujoco.MjData(self.model)
        self._index_bodies(scenario)
        self._set_initial_state(scenario)
        if self.tree is not None:
            self._set_joint_velocities(scenario)
        self.qpos_start = self.data.qpos.copy()

    def _index_bodies(self, scenario: Scenario) -> None:
        """MuJoCo's body of each scene body (the same name; a native model's link body), each
        scene body's frame in it (``native.body_offsets``: identity but for native models'
        bodies) and the free roots whose state is their joint's."""
        m = self.model
        self.moving = dynamic_bodies(self.scene)
        self.body_ids = np.array(
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b.name) for b in scenario.bodies],
            dtype=np.int64,
        )
        missing = [b.name for b, i in zip(scenario.bodies, self.body_ids, strict=True) if i < 0]
        if missing:
            raise RuntimeError(f"MuJoCo built no body {missing[0]!r} from the model file")
        self.offset_rot, self.offset_pos, self.in_model = body_offsets(
            self.scene if self.natives else None, len(scenario.bodies)
        )
        self.offset_quat = offset_quaternions(self.offset_rot)
        own = self.moving[~self.in_model[self.moving]]  # bodies written by ``mjcf``
        self.free = own[m.body_jntnum[self.body_ids[own]] > 0]
        self.free = self.free[
            m.jnt_type[m.body_jntadr[self.body_ids[self.free]]] == mujoco.mjtJoint.mjJNT_FREE
        ]  # the free roots: their state is their joint's (the others' comes from kinematics)
        joints = m.body_jntadr[self.body_ids[self.free]]
        self.qpos_adr = m.jnt_qposadr[joints]
        self.dof_adr = m.jnt_dofadr[joints]
        offset = np.abs(m.body_ipos[self.body_ids[own]]).max(initial=0.0)
        if offset > INERTIAL_ORIGIN_TOLERANCE:
            raise RuntimeError(f"MuJoCo moved a centre of mass off its body origin by {offset} m")
        self.fixed_pose = (
            np.array([b.position for b in scenario.bodies], dtype=float),
            np.array([b.orientation for b in scenario.bodies], dtype=float),
        )

    def _set_initial_state(self, scenario: Scenario) -> None:
        """Initial qpos/qvel, and the constant applied loads in ``xfrc_applied`` (world-frame
        force at the body's centre of mass ``xipos``, then torque; MuJoCo keeps the field
        between steps and applies it at every stage of every integrator)."""
        d = self.data
        loads = np.concatenate([self.scene.force, self.scene.torque], axis=1)
        d.xfrc_applied[self.body_ids] = loads
        for row, adr, dof in zip(self.free, self.qpos_adr, self.dof_adr, strict=True):
            body = scenario.bodies[row]
            rot = quat_to_matrix(np.array([body.orientation]))[0]
            d.qpos[adr : adr + 3] = body.position
            d.qpos[adr + 3 : adr + 7] = body.orientation
            d.qvel[dof : dof + 3] = body.velocity
            d.qvel[dof + 3 : dof + 6] = rot.T @ np.asarray(body.angular_velocity)

    def _set_joint_velocities(self, scenario: Scenario) -> None:
        """qvel of a scene with joints from the bodies' stated velocities, through MuJoCo's
        own Jacobians at the initial configuration (``mj_jacBody`` of each moving body's
        centre, world frame): the least-squares qvel of ``J qvel = (v, ω)``, exact for the
        velocities the scene's checks let through (the joints allow them). A native model's
        dofs (those of its bodies) are set already, from its joint rates: left out of the
        solve."""
        m, d = self.model, self.data
        mujoco.mj_forward(m, d)
        own = self.moving[~self.in_model[self.moving]]
        columns = np.flatnonzero(~np.isin(m.dof_bodyid, self.body_ids[self.in_model]))
        if not own.size or not columns.size:
            return
        rows, targets = [], []
        for row in own:
            jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            mujoco.mj_jacBody(m, d, jacp, jacr, int(self.body_ids[row]))
            body = scenario.bodies[row]
            rows += [jacp, jacr]
            targets += [np.asarray(body.velocity), np.asarray(body.angular_velocity)]
        jacobian, stated = np.concatenate(rows)[:, columns], np.concatenate(targets)
        d.qvel[columns] = np.linalg.lstsq(jacobian, stated, rcond=None)[0]

    def joint_report(self) -> JointReport:
        """The joints MuJoCo compiled, at the initial state (``mj_forward`` on a scratch copy):
        each stated joint's type (``jnt_type``; a fixed joint is a body welded into its
        parent: no joint), anchor ``xanchor`` (a slide's moved with its child, ``_slid``) and
        axis ``xaxis``, world frame; its range (``jnt_range`` where ``jnt_limited``) less its
        coordinate at t = 0, ``dof_damping``, ``dof_armature`` and ``dof_frictionloss``
        (``native.joint_friction``); and M(q0), ``mj_fullM``,
        carried into the joint tree's coordinates: ``M_tree = Tᵀ M T`` (``_tree_velocities``)."""
        m = self.model
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:] = self.data.qpos, self.data.qvel
        mujoco.mj_forward(m, d)
        types, anchors, axes = [], [], []
        joints = len(self.scenario.joints)
        limits, damping, armature = np.full((joints, 2), np.nan), np.zeros(joints), np.zeros(joints)
        for k, joint in enumerate(self.scenario.joints):
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint.name)
            welded = jid < 0
            types.append("fixed" if welded else JOINT_WORDS[int(m.jnt_type[jid])])
            has_axis = not welded and joint.type in ("hinge", "slider")
            axes.append(d.xaxis[jid].copy() if has_axis else np.zeros(3))
            if welded:
                anchors.append(joint.anchor)
                continue
            anchors.append(d.xanchor[jid] + _slid(m, d, jid) * d.xaxis[jid])
            dof = m.jnt_dofadr[jid]
            damping[k], armature[k] = m.dof_damping[dof], m.dof_armature[dof]
            if has_axis and m.jnt_limited[jid]:
                limits[k] = m.jnt_range[jid] - self.qpos_start[m.jnt_qposadr[jid]]
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        change = self._tree_velocities(d)
        return JointReport(
            tuple(types),
            np.array(anchors),
            np.array(axes),
            change.T @ full @ change,
            limits=limits,
            damping=damping,
            armature=armature,
            friction=joint_friction(m, self.scenario),
        )

    def _scene_axes(self, d, row: int) -> np.ndarray:
        """(3, 3) the scene body ``row``'s axes at the state of ``d``: its MuJoCo body's frame
        turned by the body's offset (``native.body_offsets``)."""
        return d.xmat[int(self.body_ids[row])].reshape(3, 3) @ self.offset_rot[row]

    def _free_offset(self, d, row: int) -> np.ndarray:
        """(3,) m, world: the MuJoCo body's origin relative to the scene body's centre (zero but
        for a native model's free root)."""
        return -d.xmat[int(self.body_ids[row])].reshape(3, 3) @ self.offset_pos[row]

    def _joint_dof(self, joint) -> int:
        """MuJoCo's first dof of a tree joint (a free root's: its body's joint)."""
        m = self.model
        if joint.type == "free":
            jid = int(m.body_jntadr[int(self.body_ids[joint.child])])
        else:
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint.name)
        return int(m.jnt_dofadr[jid])

    def _tree_velocities(self, d) -> np.ndarray:
        """(nv MuJoCo, nv tree) T: MuJoCo's qvel of the joint tree's ν at the state of ``d``:
        a hinge's or slide's rate as it is; a ball's spin relative to its parent (parent's
        scene axes) into the child's MuJoCo frame, R_Cᵀ R_P; a free root's world ω into its
        body frame, R_Cᵀ, and its centre's velocity to its body origin's, v + ω × r (r the
        origin from the centre, ``_free_offset``)."""
        m, tree = self.model, self.tree
        change = np.zeros((m.nv, tree.nv))
        for joint in tree.joints:
            if joint.type == "fixed":
                continue
            dof = self._joint_dof(joint)
            rows = slice(dof, dof + joint.v_slice.stop - joint.v_slice.start)
            child = d.xmat[int(self.body_ids[joint.child])].reshape(3, 3)
            if joint.type in ("hinge", "slider"):
                change[rows, joint.v_slice] = np.eye(1)
            elif joint.type == "ball":
                parent = np.eye(3) if joint.parent < 0 else self._scene_axes(d, joint.parent)
                change[rows, joint.v_slice] = child.T @ parent
            else:  # free: (v world at the centre, ω world) -> (v world at the origin, ω body)
                offset = _skew(self._free_offset(d, joint.child))
                change[rows, joint.v_slice] = np.block(
                    [[np.eye(3), -offset], [np.zeros((3, 3)), child.T]]
                )
        return change

    def _tree_velocity_rates(self, d, nu: np.ndarray) -> np.ndarray:
        """(nv MuJoCo,) Ṫ ν at ν̇ = 0: zero for hinges, slides, balls (the child's spin
        relative to its parent is the joint's own) and a free root's spin; a free root whose
        origin is off its centre adds the centripetal ω × (ω × r) to its origin's velocity."""
        rates = np.zeros(self.model.nv)
        for joint in self.tree.joints:
            if joint.type == "free":
                spin = nu[joint.v_slice][3:]
                dof = self._joint_dof(joint)
                rates[dof : dof + 3] = np.cross(
                    spin, np.cross(spin, self._free_offset(d, joint.child))
                )
        return rates

    def _set_tree_state(self, d, q: np.ndarray) -> None:
        """MuJoCo's qpos of the tree's q (relative to t = 0; ``_tree_velocities`` for the
        frames): a hinge's or slide's coordinate added to its qpos at t = 0; a ball's relative
        rotation Q as MuJoCo's joint quaternion bqᵀ O_P Q R0 O_Cᵀ (bq the child's body_quat,
        O the scene bodies' offsets, R0 the child's rotation in its parent at t = 0); a free
        root's centre and axes as its body origin and frame."""
        m = self.model
        d.qpos[:] = self.qpos_start
        for joint in self.tree.joints:
            if joint.type == "fixed":
                continue
            adr = int(m.jnt_qposadr[m.dof_jntid[self._joint_dof(joint)]])
            coordinate = q[joint.q_slice]
            if joint.type in ("hinge", "slider"):
                d.qpos[adr] += coordinate[0]
            elif joint.type == "ball":
                body = int(self.body_ids[joint.child])
                frame = quat_to_matrix(m.body_quat[body][None])[0]
                parent = np.eye(3) if joint.parent < 0 else self.offset_rot[joint.parent]
                relative = quat_to_matrix(coordinate[None])[0]
                turn = frame.T @ parent @ relative @ joint.rotation @ self.offset_rot[joint.child].T
                d.qpos[adr : adr + 4] = matrix_to_quat(turn)
            else:
                row = joint.child
                quat = quat_multiply(coordinate[3:], _conjugate(self.offset_quat[row]))
                rot = quat_to_matrix(quat[None])[0]
                d.qpos[adr : adr + 3] = coordinate[:3] - rot @ self.offset_pos[row]
                d.qpos[adr + 3 : adr + 7] = quat

    def model_probe(self, q: np.ndarray, nu: np.ndarray) -> ModelProbe:
        """The scene at the joint state (q, ν) of the joint tree (relative to t = 0), on a
        scratch ``MjData`` (the run's state is untouched): every scene body's centre and axes
        (as ``observe``), M = Tᵀ ``mj_fullM`` T and the bias b = Tᵀ (b_MuJoCo + M Ṫ ν), where
        b_MuJoCo = ``qfrc_bias`` less the scene's springs and applied loads (``qfrc_actuator -
        qfrc_smooth - dof_damping·qvel``: the reference's ``bias_forces``, joint damping
        left out) after ``mj_forward``."""
        m = self.model
        d = mujoco.MjData(m)
        d.xfrc_applied[:] = self.data.xfrc_applied
        self._set_tree_state(d, np.asarray(q, dtype=float))
        with collected_warnings(self.messages):
            mujoco.mj_kinematics(m, d)
            change = self._tree_velocities(d)
            d.qvel[:] = change @ np.asarray(nu, dtype=float)
            mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        bias = d.qfrc_actuator - d.qfrc_smooth - m.dof_damping * d.qvel
        bias = bias + full @ self._tree_velocity_rates(d, np.asarray(nu, dtype=float))
        pos, quat = self._scene_poses(d)
        return ModelProbe(pos, quat, change.T @ full @ change, change.T @ bias)

    def _scene_poses(self, d) -> tuple[np.ndarray, np.ndarray]:
        """Every scene body's centre (n, 3) and quaternion (n, 4) at the kinematics of ``d``:
        MuJoCo's body frame composed with the body's offset (``native.body_offsets``; the
        bodies ``mjcf`` wrote are their own frames, read as they are)."""
        ids = self.body_ids
        pos, quat = d.xipos[ids].copy(), d.xquat[ids].copy()
        rows = self.in_model
        if rows.any():
            frames = d.xmat[ids[rows]].reshape(-1, 3, 3)
            pos[rows] = d.xpos[ids[rows]] + np.einsum("nij,nj->ni", frames, self.offset_pos[rows])
            quat[rows] = quat_multiply(d.xquat[ids[rows]], self.offset_quat[rows])
        return pos, quat

    def model_report(self) -> ModelReport:
        """Read back from MuJoCo after ``mj_forward`` on a scratch copy of the current state
        (so reading never perturbs the run): ``body_mass``, ``xipos``, ``ximat · diag(
        body_inertia) · ximatᵀ``, ``mj_energyPos + mj_energyVel`` (plus the applied forces'
        potential -F·x, which MuJoCo does not define) and the world subtree's momenta
        (``mj_subtreeVel``; fixed bodies are massless, so these are the moving ones')."""
        m = self.model
        d = mujoco.MjData(m)
        d.qpos[:] = self.data.qpos
        d.qvel[:] = self.data.qvel
        with collected_warnings(self.messages):
            mujoco.mj_forward(m, d)
            mujoco.mj_energyPos(m, d)
            mujoco.mj_energyVel(m, d)
            mujoco.mj_subtreeVel(m, d)
        ids = self.body_ids[self.moving]
        frames = d.ximat[ids].reshape(-1, 3, 3)
        inertia = frames @ (m.body_inertia[ids][:, :, None] * frames.transpose(0, 2, 1))
        force_potential = self.scene.applied_force_energy(d.xipos[self.body_ids][None])[0]
        return ModelReport(
            mass=m.body_mass[ids].copy(),
            com=d.xipos[ids].copy(),
            inertia_world=inertia,
            energy=float(d.energy[0] + d.energy[1] + force_potential),
            linear_momentum=m.body_subtreemass[0] * d.subtree_linvel[0].copy(),
            angular_momentum=d.subtree_angmom[0].copy(),
        )

    def advance(self, steps: int) -> None:
        """``steps`` MuJoCo steps of the scene's dt."""
        with collected_warnings(self.messages):
            mujoco.mj_step(self.model, self.data, nstep=steps)

    def advance_observed(self, steps: int) -> Trajectory:
        """``steps`` single steps, the raw ``time, qpos, qvel`` copied after each (a few µs),
        converted to the scene's conventions in one vectorized pass at the end."""
        m, d = self.model, self.data
        times = np.empty(steps)
        qpos = np.empty((steps, m.nq))
        qvel = np.empty((steps, m.nv))
        with collected_warnings(self.messages):
            for k in range(steps):
                mujoco.mj_step(m, d)
                times[k] = d.time
                qpos[k] = d.qpos
                qvel[k] = d.qvel
        return self._states(times, qpos, qvel)

    def observe(self) -> Snapshot:
        """The current state (see ``_states``)."""
        d = self.data
        states = self._states(np.array([d.time]), d.qpos[None], d.qvel[None])
        return Snapshot(
            float(d.time), *(a[0] for a in (states.pos, states.quat, states.vel, states.ang_vel))
        )

    def _states(self, times: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> Trajectory:
        """COM position, quaternion w x y z, COM velocity and world ω of every scenario body
        for ``s`` raw states ``qpos (s, nq)``, ``qvel (s, nv)`` (kinematic arrays such as
        ``xpos`` lag one step after ``mj_step``). Fixed bodies: their constant pose, at rest."""
        samples, n = times.size, len(self.body_ids)
        if self.tree is not None:
            return self._states_by_kinematics(times, qpos, qvel)
        pos = np.repeat(self.fixed_pose[0][None], samples, axis=0)
        quat = np.repeat(self.fixed_pose[1][None], samples, axis=0)
        vel = np.zeros((samples, n, 3))
        ang_vel = np.zeros((samples, n, 3))
        if self.moving.size:
            body_q = qpos[:, self.qpos_adr[:, None] + np.arange(7)]
            moving_quat = body_q[..., 3:] / np.linalg.norm(body_q[..., 3:], axis=2, keepdims=True)
            body_v = qvel[:, self.dof_adr[:, None] + np.arange(6)]
            rot = quat_to_matrix(moving_quat.reshape(-1, 4)).reshape(samples, -1, 3, 3)
            pos[:, self.moving] = body_q[..., :3]
            quat[:, self.moving] = moving_quat
            vel[:, self.moving] = body_v[..., :3]
            ang_vel[:, self.moving] = np.einsum("snij,snj->sni", rot, body_v[..., 3:])
        return Trajectory(times.astype(float), pos, quat, vel, ang_vel)

    def _states_by_kinematics(
        self, times: np.ndarray, qpos: np.ndarray, qvel: np.ndarray
    ) -> Trajectory:
        """Every body's state through MuJoCo's own kinematics (a scene with joints, whose
        bodies' states are no joint's coordinates): on a scratch ``MjData``, ``mj_kinematics``,
        ``mj_comPos`` and ``mj_comVel`` for each raw state, then ``xipos``, ``xquat`` and
        ``mj_objectVelocity`` (world frame, at the body's origin, its centre of mass)."""
        m = self.model
        d = mujoco.MjData(m)
        samples, n = times.size, len(self.body_ids)
        pos, quat = np.zeros((samples, n, 3)), np.zeros((samples, n, 4))
        vel, ang_vel = np.zeros((samples, n, 3)), np.zeros((samples, n, 3))
        velocity = np.zeros(6)
        for s in range(samples):
            d.qpos[:], d.qvel[:] = qpos[s], qvel[s]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_comVel(m, d)
            pos[s], quat[s] = self._scene_poses(d)
            for k, body in enumerate(self.body_ids):
                mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, int(body), velocity, 0)
                ang_vel[s, k], vel[s, k] = velocity[:3], velocity[3:]
            if self.in_model.any():  # from the inertial frame's origin to the scene's centre
                ids = self.body_ids[self.in_model]
                vel[s, self.in_model] += cross(
                    ang_vel[s, self.in_model], pos[s, self.in_model] - d.xipos[ids]
                )
        return Trajectory(times.astype(float), pos, quat, vel, ang_vel)

    def provenance(self) -> Provenance:
        """MuJoCo's version, every ``m.opt`` field, the profile and the contact calibration."""
        settings: dict[str, object] = {
            **{f"spec.{k}": v for k, v in self.settings.items()},
            **option_settings(self.model),
            "contact_pairs": self.plan.touching_pairs,
            "bodies_that_can_touch": self.plan.touching_bodies,
        }
        notes = [f"solver {self.solver} (setting {self.settings['solver']})"]
        notes += self._model_notes()
        if self.settings["profile"] == "matched" and self.plan.touching_pairs:
            notes.append(contact_note(self.plan, self.model))
            notes.append(RESTITUTION_NOTES[str(self.settings["restitution"])])
            notes += self._damper_caveats()
        if self.settings["profile"] == "defaults":
            notes.append(
                "profile=defaults: MuJoCo's default geoms and contacts (condim 3, μ = 1, "
                "solref (0.02, 1)); the scene's restitution and friction are not used"
            )
        notes += [f"MuJoCo warning: {message}" for message in self.messages]
        return Provenance(
            engine="mujoco", version=mujoco.__version__, settings=settings, notes=notes
        )

    def _model_notes(self) -> list[str]:
        """How the scene's models were loaded, and what MuJoCo dropped from their files."""
        if not self.scene.models:
            return []
        if not self.natives:
            return ["models: built from physval's reading of the files (model_loader=physval)"]
        files = ", ".join(f"{layout.name}: {layout.path.name}" for layout in self.natives)
        notes = [
            f"models loaded by MuJoCo's own compiler (model_loader=native): {files}; "
            "fusestatic off (every link a body), the scene's <option> governs"
        ]
        return notes + [f"model file's option not used: {note}" for note in self.attach_notes]

    def _damper_caveats(self) -> list[str]:
        """What the damper calibration does not cover in this run's settings."""
        if self.settings["restitution"] != "damper":
            return []
        caveats = []
        if self.settings["integrator"] == "RK4":
            caveats.append(
                "integrator=RK4 with restitution=damper: the one-step damper assumes a "
                "first-order step; measured e ≈ 0 for requested 0.5 and 1.0 (sphere, dt = 1e-3)"
            )
        frictional = self.plan.frictional
        if frictional:
            caveats.append(FRICTION_IN_IMPACTS)
        if frictional and self.model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL:
            caveats.append(
                "cone=pyramidal with friction under restitution=damper: sliding bodies are "
                "pushed off the ground at ≈ μ|v_t| (measured 0.8 m/s at 2 m/s, μ = 0.5)"
            )
        return caveats

    def instability_warnings(self) -> list[str]:
        """MuJoCo's own instability warnings raised so far (bad qacc/qpos/qvel: it reset the
        state; full constraint or contact buffers: it dropped contacts), as text: one entry
        per warning kind with its count, then, if there is any, the messages MuJoCo wrote."""
        found = []
        for name in INSTABILITY_WARNINGS:
            count = self.data.warning[int(getattr(mujoco.mjtWarning, name))].number
            if count:
                found.append(f"MuJoCo {name} x{count}")
        if found:
            found += [f"MuJoCo: {message}" for message in dict.fromkeys(self.messages)]
        return found

    def close(self) -> None:
        """Drop the model and data (MuJoCo frees them with the Python objects)."""
        self.model = None
        self.data = None
