"""``physval conformance ENGINE_SPEC``: does an adapter keep the contract of
``validation.engines.base``? It checks the boundary, not the physics quality.

Each check (``CHECKS``) builds small scenes from the engine's declared capabilities, runs the
adapter through the public protocol and returns what broke (nothing: it passes):

- ``declaration``: the declaration is well formed and the adapter class has the protocol;
- ``parity``: the parity gate passes on each declared shape, rotated, with a full inertia;
- ``frames``: a spinning, translating body read back as the closed form says (positions at
  the centre of mass in the world frame, quaternions w x y z, world angular velocity);
- ``advance``: ``advance(n)`` equals n × ``advance(1)``;
- ``observe``: observing after every step (or ``advance_observed``) does not change the run;
- ``determinism``: a second adapter gives the same states;
- ``close``: ``close()`` is idempotent and repeated load/close cycles do not grow memory;
- ``provenance``: every option written in a spec reaches ``Provenance.settings``;
- ``capabilities``: a scene needing a declared capability runs; one needing a missing one
  is ``unsupported``, naming it, without an exception.

Exit codes: 0 every check passes, 1 one fails, 2 bad input (an unknown or broken engine, a
bad spec). ``pytest --physval-conformance SPEC`` runs the same checks as tests, and the
``physval_conformance`` fixture returns ``run_conformance``.
"""

from __future__ import annotations

import gc
import json
import re
import resource
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from validation.contract import CONFORMANCE_CHECKS, EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from validation.engine_api import (
    FEATURES,
    SHAPES,
    Capabilities,
    EngineDeclaration,
    EngineOption,
    declaration_of,
    declaration_problems,
)
from validation.engines.base import Snapshot
from validation.engines.parity import PRECISION_TOLERANCE, compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.jobs.executor import run_jobs
from validation.measure.runner import raised_message, run_engine
from validation.reference.rotation import quat_multiply, quat_to_matrix
from validation.scenario import Scenario
from validation.scenario.compiled import CompiledScene, compile_scene
from validation.scenario.engine_spec import (
    EngineSpec,
    EngineSpecError,
    parse_engine_spec,
    parse_installed_spec,
)
from validation.scenario.needs import missing

# --- the scenes ----------------------------------------------------------------------------

DT = 1e-3
"""s, every conformance scene's step."""

FRAME_DURATION = 0.5
"""s, the spinning body's run: 500 steps, two radians of turn at ``SPIN_RATE``."""

SPIN_RATE = 4.0
"""rad/s about the body's major principal axis (a stable, torque-free spin: ω constant)."""

GRAVITY = (0.0, 0.0, -9.81)
"""m/s², world frame."""

START_VELOCITY = (1.0, -0.5, 2.0)
"""m/s, world frame, the spinning body's centre-of-mass velocity at t = 0."""

TILT = (0.9, 0.2, -0.3, 0.25)
"""A generic rotation (w x y z, normalised when used): no axis of the body is a world axis."""

PRINCIPAL_MOMENTS = (0.05, 0.04, 0.03)
"""kg·m², the full-inertia body's principal moments (distinct, triangle inequality kept)."""

SHAPE_FIELDS: dict[str, dict] = {
    "sphere": {"type": "sphere", "radius": 0.1},
    "box": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
    "capsule": {"type": "capsule", "radius": 0.05, "half_length": 0.15},
    "cylinder": {"type": "cylinder", "radius": 0.08, "half_length": 0.12},
}
"""One shape of each type (m)."""

assert set(SHAPE_FIELDS) == set(SHAPES), "a shape without its conformance body"

RUN_STEPS = 200
"""Steps of the advance, observe and determinism comparisons (0.2 s: the contact scene's
bodies land in it)."""


def _unit(q) -> list[float]:
    q = np.asarray(q, dtype=float)
    return (q / np.linalg.norm(q)).tolist()


def _full_inertia() -> list[list[float]]:
    """kg·m², body frame: ``PRINCIPAL_MOMENTS`` about axes turned by ``TILT`` (off-diagonal
    terms, so an adapter must find the principal axes itself)."""
    axes = quat_to_matrix(np.asarray(_unit(TILT)))
    return (axes @ np.diag(PRINCIPAL_MOMENTS) @ axes.T).tolist()


def _scene(name: str, bodies: list[dict], duration: float, **extra) -> Scenario:
    return Scenario.model_validate(
        {
            "name": name,
            "dt": DT,
            "duration": duration,
            "gravity": list(GRAVITY),
            "bodies": bodies,
            **extra,
        }
    )


def _body(name: str, shape: str, **fields) -> dict:
    return {"name": name, "shape": SHAPE_FIELDS[shape], "mass": 2.0, **fields}


def parity_scene(shape: str) -> Scenario:
    """One rotated body of ``shape`` with a full inertia, moving and spinning."""
    body = _body(
        "body",
        shape,
        inertia=_full_inertia(),
        orientation=_unit(TILT),
        velocity=list(START_VELOCITY),
        angular_velocity=[0.3, -1.2, 2.0],
    )
    return _scene(f"conformance_parity_{shape}", [body], 10 * DT)


def spin_axis_world() -> np.ndarray:
    """(3,) unit, world frame: the full-inertia body's major principal axis at t = 0."""
    moments, axes = np.linalg.eigh(np.asarray(_full_inertia()))
    return quat_to_matrix(np.asarray(_unit(TILT))) @ axes[:, int(np.argmax(moments))]


def frames_scene(shape: str) -> Scenario:
    """A rotated body spinning at ``SPIN_RATE`` about its major axis while it flies."""
    body = _body(
        "spinner",
        shape,
        inertia=_full_inertia(),
        orientation=_unit(TILT),
        position=[0.0, 0.0, 1.0],
        velocity=list(START_VELOCITY),
        angular_velocity=(SPIN_RATE * spin_axis_world()).tolist(),
    )
    return _scene("conformance_frames", [body], FRAME_DURATION)


def contact_scene() -> Scenario:
    """A tilted box and a sphere dropped on a frictional, restitutive ground."""
    bodies = [
        _body(
            "box",
            "box",
            position=[0.0, 0.0, 0.36],
            orientation=_unit((1.0, 0.05, 0.03, 0.0)),
            velocity=[0.3, 0.0, 0.0],
            restitution=0.4,
            friction=0.5,
        ),
        _body(
            "ball",
            "sphere",
            position=[0.8, 0.0, 0.2],
            velocity=[-0.2, 0.1, 0.0],
            angular_velocity=[0.0, 0.0, 3.0],
            restitution=0.6,
            friction=0.3,
        ),
    ]
    return _scene("conformance_contact", bodies, RUN_STEPS * DT, ground={"friction": 0.5})


CAPABILITY_SCENES: dict[str, Callable[[], Scenario]] = {
    **{
        shape: (lambda s=shape: _scene(f"conformance_{s}", [_body("b", s)], 20 * DT))
        for shape in SHAPES
    },
    "ground": lambda: _scene(
        "conformance_ground", [_body("b", "sphere", position=[0, 0, 0.1])], 50 * DT, ground={}
    ),
    "tilted_ground": lambda: _scene(
        "conformance_tilted_ground",
        [_body("b", "sphere", position=[0, 0, 0.12])],
        50 * DT,
        ground={"normal": [0.0, 0.2, 1.0]},
    ),
    "contacts": lambda: _scene(
        "conformance_contacts",
        [_body("a", "sphere", velocity=[1, 0, 0]), _body("b", "sphere", position=[0.3, 0, 0])],
        100 * DT,
        gravity=[0, 0, 0],
    ),
    "fixed_bodies": lambda: _scene(
        "conformance_fixed_bodies",
        [_body("base", "box", fixed=True), _body("b", "sphere", position=[0, 0, 0.45])],
        100 * DT,
    ),
    "springs": lambda: _scene(
        "conformance_springs",
        [_body("b", "sphere")],
        100 * DT,
        gravity=[0, 0, 0],
        springs=[
            {"a": "b", "b": "world", "anchor_b": [0.1, 0, 0], "stiffness": 50.0, "rest_length": 0.0}
        ],
    ),
    "loads": lambda: _scene(
        "conformance_loads", [_body("b", "box", force=[1, 0, 0], torque=[0, 0, 0.1])], 50 * DT
    ),
    "restitution": lambda: _scene(
        "conformance_restitution",
        [_body("b", "sphere", position=[0, 0, 0.15], restitution=0.5)],
        200 * DT,
        ground={},
    ),
    "friction": lambda: _scene(
        "conformance_friction",
        [_body("b", "box", position=[0, 0, 0.3], velocity=[1, 0, 0], friction=0.3)],
        100 * DT,
        ground={"friction": 0.3},
    ),
    "joints": lambda: _scene(
        "conformance_joints",
        [_body("bob", "sphere", position=[0.3, 0, 0.0])],
        100 * DT,
        joints=[_hinge()],
    ),
    "joint_limits": lambda: _scene(
        "conformance_joint_limits",
        [_body("bob", "sphere", position=[0.3, 0, 0.0])],
        100 * DT,
        joints=[{**_hinge(), "limits": [-0.2, 0.2]}],
    ),
    "placed_shapes": lambda: _scene(
        "conformance_placed_shapes",
        [
            {
                **_body("b", "box", inertia=[0.02, 0.03, 0.04], angular_velocity=[0, 0, 1.0]),
                "shape": {**SHAPE_FIELDS["box"], "offset": [0.05, 0.0, 0.0]},
            }
        ],
        20 * DT,
    ),
    "non_colliding": lambda: _scene(
        "conformance_non_colliding",
        [
            _body("b", "sphere", position=[0, 0, 0.1]),
            _body("ghost", "sphere", position=[0, 0, 0.15], collides=False),
        ],
        50 * DT,
        ground={},
    ),
}
"""Capability -> a small scene that needs it (and perhaps others: ``restitution`` needs a
ground and contacts)."""


def _hinge() -> dict:
    """A pendulum's hinge about y at the origin (the bob 0.3 m out along x swings down)."""
    return {
        "name": "pivot",
        "type": "hinge",
        "parent": "world",
        "child": "bob",
        "anchor": [0.0, 0.0, 0.0],
        "axis": [0.0, 1.0, 0.0],
    }


assert set(CAPABILITY_SCENES) == set(SHAPES) | set(FEATURES), "a capability without its scene"

# --- tolerances ----------------------------------------------------------------------------

FRAME_POSITION_TOLERANCE = 5e-3
"""m. Twice a first-order integrator's ballistic error ½|g|·T·dt = 2.45e-3 m (T = 0.5 s,
dt = 1e-3); a frame mistake (a swapped axis, gravity along y) is of order ½|g|T² = 1.2 m."""

FRAME_ANGLE_TOLERANCE = 1e-2
"""rad. A torque-free spin about a principal axis has constant ω, so the exact quaternion is
exp(½ω t) ⊗ q0; a linearized update drifts by ~|ω|³dt²T/12 ≪ 1e-2; a quaternion read x y z w,
a body-frame rotation or an inverted one is off by an angle of order 1."""

FRAME_VELOCITY_TOLERANCE = {"float64": 1e-6, "float32": 1e-3}
"""m/s and rad/s, per declared precision. v = v0 + g t and ω are exact for every integrator
under constant gravity and a torque-free principal spin; what is left is round-off over 500
steps (float64: ~1e-13; float32: 500 × 6e-8 × 10 m/s ≈ 3e-4); a body-frame angular velocity is
off by |ω| |R0 - 1| ≈ 4 rad/s."""

FRAME_ANGULAR_VELOCITY_TOLERANCE = {"float64": 1e-6, "float32": 1e-2}
"""rad/s, per declared precision. float64 as ``FRAME_VELOCITY_TOLERANCE``. A float32 engine's
principal axes and gyroscopic update carry float32 error, which makes the principal spin
precess a little (Rapier 0.36: 2.6e-3 rad/s off over the 0.5 s at 4 rad/s, measured; its
isotropic sphere 5e-4 rad/s): physics quality, not the boundary. A body-frame readback or a
swapped axis is off by about 4 rad/s, 400 times the float32 allowance."""

READBACK_TOLERANCE = {"float64": 1e-12, "float32": 1e-6}
"""Relative, per declared precision: one state read back two ways (``advance_observed``'s
batch and ``observe``) may differ by the round-off of a different order of the same
operations (measured: 7.4e-17 for MuJoCo's batched angular velocity), never by a step."""

CLOSE_CYCLES = 12
"""Load/advance/close cycles whose memory growth is measured (after ``CLOSE_WARMUP``)."""

CLOSE_WARMUP = 3
"""Cycles first run unmeasured (imports, caches, allocator pools)."""

CLOSE_GROWTH_BYTES = 512 * 1024
"""Resident memory growth allowed per cycle. An adapter that keeps its engine alive keeps at
least its world (measured: PyBullet with a ``close`` that does not disconnect, 28 MB a
cycle); one that frees it reuses the same pages (measured: mini and PyBullet 0 KiB, MuJoCo
25 KiB a cycle)."""


@dataclass(frozen=True)
class CheckResult:
    """One check's outcome: ``problems`` empty when it passes; ``detail`` what it covered."""

    name: str
    problems: tuple[str, ...]
    detail: str = ""

    @property
    def passed(self) -> bool:
        return not self.problems


@dataclass(frozen=True)
class Subject:
    """The engine under test: its spec, declaration and the capabilities under the spec."""

    spec: EngineSpec
    declaration: EngineDeclaration

    @property
    def capabilities(self) -> Capabilities:
        return self.declaration.capabilities_of(self.spec.as_dict())

    @property
    def supported(self) -> frozenset[str]:
        return self.capabilities.supported

    def runnable(self, scenario: Scenario) -> bool:
        return not missing(self.capabilities, scenario)


# --- running an adapter --------------------------------------------------------------------


def _loaded(spec: EngineSpec, scene: CompiledScene):
    adapter = create_adapter(spec)
    adapter.load(scene)
    return adapter


def _final_state(spec: EngineSpec, scene: CompiledScene, step: Callable) -> Snapshot:
    """The observed state after ``step(adapter)`` on a fresh adapter (closed after)."""
    adapter = _loaded(spec, scene)
    try:
        step(adapter)
        return adapter.observe()
    finally:
        adapter.close()


def _difference(a: Snapshot, b: Snapshot) -> tuple[float, str]:
    """The largest relative difference of two states (per quantity, scaled by its largest
    magnitude) and the quantity it is in."""
    worst, where = 0.0, ""
    for quantity in ("pos", "quat", "vel", "ang_vel"):
        x, y = np.asarray(getattr(a, quantity)), np.asarray(getattr(b, quantity))
        if x.shape != y.shape:
            return np.inf, f"{quantity} shapes {x.shape} and {y.shape}"
        scale = max(float(np.max(np.abs(y), initial=0.0)), 1.0)
        error = float(np.max(np.abs(x - y), initial=0.0)) / scale
        if not np.isfinite(error) or error > worst:
            worst, where = (np.inf if not np.isfinite(error) else error), quantity
    if abs(a.time - b.time) > worst:
        worst, where = abs(a.time - b.time), "time"
    return worst, where


def _same(name: str, a: Snapshot, b: Snapshot, tolerance: float) -> list[str]:
    error, where = _difference(a, b)
    if error > tolerance:
        return [f"{name}: states differ by {error:.3g} (relative, in {where}) > {tolerance:g}"]
    return []


def _run_scene(subject: Subject) -> Scenario:
    """The richest scene the engine can run: contacts if it has them, else free flight."""
    scene = contact_scene()
    return scene if subject.runnable(scene) else frames_scene(_frame_shape(subject))


def _frame_shape(subject: Subject) -> str:
    shapes = subject.capabilities.shapes
    return "box" if "box" in shapes else shapes[0]


# --- the checks ----------------------------------------------------------------------------


PROTOCOL_METHODS = ("load", "model_report", "advance", "observe", "provenance", "close")
"""What ``EngineAdapter`` requires of an adapter class."""


def check_declaration(subject: Subject) -> CheckResult:
    problems = list(declaration_problems(subject.declaration))
    try:
        adapter_class = subject.declaration.load_adapter()
    except Exception as error:
        problems.append(f"adapter {subject.declaration.adapter}: {type(error).__name__}: {error}")
    else:
        problems += [
            f"adapter {subject.declaration.adapter} has no {m}()"
            for m in PROTOCOL_METHODS
            if not callable(getattr(adapter_class, m, None))
        ]
    return CheckResult(
        "declaration", tuple(problems), f"API version {subject.declaration.api_version}"
    )


def check_parity(subject: Subject) -> CheckResult:
    tolerance = PRECISION_TOLERANCE[subject.capabilities.precision]
    problems, shapes = [], subject.capabilities.shapes
    for shape in shapes:
        scene = compile_scene(parity_scene(shape))
        adapter = _loaded(subject.spec, scene)
        try:
            found = compare(adapter.model_report(), reference_report(scene), tolerance)
        finally:
            adapter.close()
        problems += [f"{shape}: {mismatch}" for mismatch in found]
    return CheckResult(
        "parity", tuple(problems), f"rotated {', '.join(shapes)} with a full inertia"
    )


def frames_expected(scenario: Scenario, times: np.ndarray) -> dict[str, np.ndarray]:
    """The closed form of ``frames_scene``: (s, 3) positions m, (s, 4) quaternions w x y z,
    (s, 3) velocities m/s and angular velocities rad/s, world frame, at ``times`` (s,)."""
    body = scenario.bodies[0]
    p0, v0, g = (np.asarray(x, dtype=float) for x in (body.position, body.velocity, GRAVITY))
    omega = np.asarray(body.angular_velocity, dtype=float)
    rate = float(np.linalg.norm(omega))
    half = 0.5 * rate * times[:, None]
    turn = np.hstack([np.cos(half), np.sin(half) * omega / rate])
    quat = quat_multiply(turn, np.asarray(body.orientation, dtype=float)[None])
    return {
        "pos": p0 + v0 * times[:, None] + 0.5 * g * times[:, None] ** 2,
        "quat": quat,
        "vel": v0 + g * times[:, None],
        "ang_vel": np.repeat(omega[None], times.size, axis=0),
    }


def rotation_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(s,) rad, the angle of the rotation between unit quaternions ``a`` and ``b`` (s, 4)
    (sign-free: q and -q are one rotation)."""
    dot = np.clip(np.abs(np.sum(a * b, axis=-1)), 0.0, 1.0)
    return 2.0 * np.arccos(dot)


def check_frames(subject: Subject) -> CheckResult:
    shape = _frame_shape(subject)
    scenario = frames_scene(shape)
    scene = compile_scene(scenario)
    adapter = _loaded(subject.spec, scene)
    try:
        states = [adapter.observe()]
        for _ in range(scenario.steps):
            adapter.advance(1)
            states.append(adapter.observe())
    finally:
        adapter.close()
    times = np.array([s.time for s in states])
    want = frames_expected(scenario, np.arange(len(states)) * DT)
    velocity_tolerance = FRAME_VELOCITY_TOLERANCE[subject.capabilities.precision]
    spin_tolerance = FRAME_ANGULAR_VELOCITY_TOLERANCE[subject.capabilities.precision]
    measured = {
        "time": (np.abs(times - np.arange(len(states)) * DT).max(), 1e-9, "s"),
        "pos": (
            np.abs(np.stack([s.pos[0] for s in states]) - want["pos"]).max(),
            FRAME_POSITION_TOLERANCE,
            "m",
        ),
        "quat": (
            rotation_angle(np.stack([s.quat[0] for s in states]), want["quat"]).max(),
            FRAME_ANGLE_TOLERANCE,
            "rad",
        ),
        "vel": (
            np.abs(np.stack([s.vel[0] for s in states]) - want["vel"]).max(),
            velocity_tolerance,
            "m/s",
        ),
        "ang_vel": (
            np.abs(np.stack([s.ang_vel[0] for s in states]) - want["ang_vel"]).max(),
            spin_tolerance,
            "rad/s",
        ),
    }
    problems = [
        f"{quantity}: largest error {error:.3g} {unit} > {tolerance:g} {unit} against the "
        "closed form (world frame, centre of mass, quaternion w x y z)"
        for quantity, (error, tolerance, unit) in measured.items()
        if not error <= tolerance
    ]
    detail = ", ".join(f"{q} {e:.2g} {u}" for q, (e, _, u) in measured.items())
    return CheckResult("frames", tuple(problems), f"{shape} spinning and flying: {detail}")


def _tolerance(subject: Subject) -> float:
    return subject.capabilities.advance_tolerance


def check_advance(subject: Subject) -> CheckResult:
    scenario = _run_scene(subject)
    scene = compile_scene(scenario)

    def one_at_a_time(adapter) -> None:
        for _ in range(RUN_STEPS):
            adapter.advance(1)

    stepped = _final_state(subject.spec, scene, one_at_a_time)
    whole = _final_state(subject.spec, scene, lambda a: a.advance(RUN_STEPS))
    problems = _same(
        f"advance({RUN_STEPS}) vs {RUN_STEPS} x advance(1)", whole, stepped, _tolerance(subject)
    )
    return CheckResult("advance", tuple(problems), scenario.name or "")


def check_observe(subject: Subject) -> CheckResult:
    scenario = _run_scene(subject)
    scene = compile_scene(scenario)

    def observing(adapter) -> None:
        for _ in range(RUN_STEPS):
            adapter.advance(1)
            adapter.observe()

    quiet = _final_state(subject.spec, scene, lambda a: a.advance(RUN_STEPS))
    watched = _final_state(subject.spec, scene, observing)
    problems = _same("observing after every step", watched, quiet, _tolerance(subject))
    detail = "observe() after each step"
    if callable(getattr(subject.declaration.load_adapter(), "advance_observed", None)):
        adapter = _loaded(subject.spec, scene)
        try:
            trajectory = adapter.advance_observed(RUN_STEPS)
            after = adapter.observe()
        finally:
            adapter.close()
        last = Snapshot(
            float(trajectory.t[-1]),
            trajectory.pos[-1],
            trajectory.quat[-1],
            trajectory.vel[-1],
            trajectory.ang_vel[-1],
        )
        readback = READBACK_TOLERANCE[subject.capabilities.precision]
        problems += _same("advance_observed's last state vs observe()", last, after, readback)
        problems += _same("advance_observed vs advance", after, quiet, _tolerance(subject))
        if len(trajectory) != RUN_STEPS:
            problems.append(f"advance_observed({RUN_STEPS}) returned {len(trajectory)} states")
        detail += " and advance_observed"
    return CheckResult("observe", tuple(problems), f"{scenario.name}: {detail}")


def check_determinism(subject: Subject) -> CheckResult:
    scenario = _run_scene(subject)
    scene = compile_scene(scenario)
    first = _final_state(subject.spec, scene, lambda a: a.advance(RUN_STEPS))
    second = _final_state(subject.spec, scene, lambda a: a.advance(RUN_STEPS))
    return CheckResult(
        "determinism", tuple(_same("a second run", second, first, 0.0)), scenario.name or ""
    )


def resident_bytes() -> int:
    """This process's resident memory now (Linux ``/proc/self/statm``), else its peak."""
    statm = Path("/proc/self/statm")
    if statm.exists():
        return int(statm.read_text().split()[1]) * resource.getpagesize()
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def check_close(subject: Subject) -> CheckResult:
    scene = compile_scene(_run_scene(subject))
    problems: list[str] = []

    def cycle() -> None:
        adapter = _loaded(subject.spec, scene)
        adapter.advance(10)
        adapter.close()
        try:
            adapter.close()
        except Exception as error:
            problems.append(f"a second close() raised {type(error).__name__}: {error}")

    for _ in range(CLOSE_WARMUP):
        cycle()
    gc.collect()
    before = resident_bytes()
    for _ in range(CLOSE_CYCLES):
        cycle()
    gc.collect()
    growth = (resident_bytes() - before) / CLOSE_CYCLES
    if growth > CLOSE_GROWTH_BYTES:
        problems.append(
            f"memory grew by {growth / 1024:.0f} KiB per load/close cycle "
            f"(> {CLOSE_GROWTH_BYTES // 1024} KiB): close() does not free the engine"
        )
    return CheckResult(
        "close",
        tuple(dict.fromkeys(problems)),
        f"{CLOSE_CYCLES} cycles, {growth / 1024:.0f} KiB per cycle",
    )


def option_values(option: EngineOption) -> list[object]:
    """Values other than the default that a spec can write for ``option``."""
    if option.type is str:
        return [c for c in option.choices if c != option.default]
    if option.type is bool:
        return [not option.default] if option.default is not None else [True, False]
    if option.example is not None:
        return [option.example]
    return [option.type(option.default * 2 if option.default else 1)]


def _written(value: object) -> str:
    return str(value).lower() if isinstance(value, bool) else str(value)


def check_provenance(subject: Subject) -> CheckResult:
    scene = compile_scene(parity_scene(_frame_shape(subject)))
    problems, tried, skipped = [], 0, []
    for option in subject.declaration.options:
        for value in option_values(option):
            text = f"{subject.declaration.name}({option.name}={_written(value)})"
            try:
                spec = parse_engine_spec(text)
            except EngineSpecError as error:
                skipped.append(f"{text} ({error})")
                continue
            adapter = _loaded(spec, scene)
            try:
                settings = adapter.provenance().settings
            finally:
                adapter.close()
            tried += 1
            keys = [k for k in (f"spec.{option.name}", option.name) if k in settings]
            if not keys:
                problems.append(f"{text}: provenance settings have no {option.name!r}")
            elif _written(settings[keys[0]]) != _written(spec.as_dict()[option.name]):
                problems.append(f"{text}: provenance says {keys[0]} = {settings[keys[0]]!r}")
    problems += _provenance_repeats(subject, scene)
    detail = f"{tried} option values" + (
        f"; not valid alone: {'; '.join(skipped)}" if skipped else ""
    )
    return CheckResult("provenance", tuple(problems), detail)


MEMORY_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
"""An object's default repr: a memory address, different in every process."""


def _provenance_repeats(subject: Subject, scene: CompiledScene) -> list[str]:
    """The spec's provenance, read from two loads of one scene, is the same text and holds no
    memory address: a rerun or a resumed run must record the same provenance."""
    texts = []
    for _ in range(2):
        adapter = _loaded(subject.spec, scene)
        try:
            provenance = adapter.provenance()
        finally:
            adapter.close()
        texts.append(json.dumps(asdict(provenance), sort_keys=True, default=str))
    problems = []
    found = MEMORY_ADDRESS.search(texts[0])
    if found:
        start = max(0, found.start() - 60)
        problems.append(f"provenance holds a memory address: ...{texts[0][start : found.end()]}")
    elif texts[0] != texts[1]:
        problems.append("provenance differs between two loads of one scene")
    return problems


def check_capabilities(subject: Subject) -> CheckResult:
    problems, ran, refused = [], [], []
    for word, build in CAPABILITY_SCENES.items():
        scenario = build()
        run = run_engine(compile_scene(scenario), subject.spec)
        if word in subject.supported:
            if not subject.runnable(scenario):
                continue  # it needs another capability the engine lacks
            ran.append(word)
            if run.status not in ("ok", "unstable"):
                problems.append(f"{word} (declared): {run.status}: {run.message}")
        else:
            refused.append(word)
            if run.status != "unsupported" or word not in run.message:
                problems.append(
                    f"{word} (not declared): expected an unsupported run naming it; got "
                    f"{run.status}: {run.message}"
                )
    detail = f"ran {', '.join(ran) or 'none'}; refused {', '.join(refused) or 'none'}"
    return CheckResult("capabilities", tuple(problems), detail)


CHECKS: dict[str, Callable[[Subject], CheckResult]] = {
    "declaration": check_declaration,
    "parity": check_parity,
    "frames": check_frames,
    "advance": check_advance,
    "observe": check_observe,
    "determinism": check_determinism,
    "close": check_close,
    "provenance": check_provenance,
    "capabilities": check_capabilities,
}
"""Every conformance check, in the order they run (the declaration first: the others need it);
the names are ``contract.CONFORMANCE_CHECKS``."""

assert tuple(CHECKS) == CONFORMANCE_CHECKS, "contract.CONFORMANCE_CHECKS is out of step"


def subject_of(text: str) -> Subject:
    """The engine under test of a spec, or ``EngineSpecError`` (unknown, broken, bad spec,
    not installed)."""
    spec = parse_installed_spec(text)
    return Subject(spec, declaration_of(spec.name))


def run_check(subject: Subject, name: str) -> CheckResult:
    """One check; an exception the adapter raises is that check's failure, not a crash."""
    try:
        return CHECKS[name](subject)
    except Exception as error:
        return CheckResult(name, (f"raised {raised_message(error)}",))


def _isolated_check(job: tuple[str, str]) -> CheckResult:
    """One check of the engine spec ``text`` (``job``: text, check name), in a worker."""
    text, name = job
    return run_check(subject_of(text), name)


def _lost_check(job: tuple[str, str], status: str, message: str) -> CheckResult:
    """A check whose process crashed or ran past its time limit (``executor.run_jobs``): a
    failure naming which."""
    return CheckResult(job[1], (f"{status}: {message}",))


def run_conformance(text: str, only: list[str] | None = None) -> list[CheckResult]:
    """Every check (or those named in ``only``) of the engine spec ``text``."""
    subject = subject_of(text)
    return [run_check(subject, name) for name in (only or CHECKS)]


def isolated_conformance(
    text: str,
    only: list[str] | None = None,
    job_timeout: float | None = None,
    on_result: Callable[[int, CheckResult], None] | None = None,
) -> list[CheckResult]:
    """``run_conformance``, each check in a worker process of its own (``executor.run_jobs``):
    one that crashes or runs past ``job_timeout`` (``--job-timeout``) fails with that status;
    ``on_result(index, result)`` as each finishes."""
    checks = [(text, name) for name in only or CHECKS]
    return run_jobs(
        _isolated_check, checks, 1, on_result, lost=_lost_check, job_timeout=job_timeout
    )


def conformance_main(
    text: str, only: list[str] | None = None, job_timeout: float | None = None
) -> int:
    """Print one line per check; 0 all pass, 1 one fails, 2 bad input. Each check runs in a
    worker process of its own (``executor.run_jobs``): an adapter that crashes, exits or
    hangs fails that check (``crashed``, ``timed_out``: ``job_timeout`` is
    ``--job-timeout``) and the others still run."""
    unknown = [name for name in only or [] if name not in CHECKS]
    if unknown:
        print(
            f"--only {', '.join(unknown)}: expected checks of {', '.join(CHECKS)}", file=sys.stderr
        )
        return EXIT_BAD_INPUT
    try:
        subject = subject_of(text)
    except EngineSpecError as error:
        print(f"conformance {text}: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT

    def shown(_: int, result: CheckResult) -> None:
        print(f"{'pass' if result.passed else 'FAIL'} {result.name}: {result.detail}", flush=True)
        for problem in result.problems:
            print(f"     {problem}", flush=True)

    results = isolated_conformance(text, only, job_timeout, shown)
    failed = [r.name for r in results if not r.passed]
    summary = f"conformance of {subject.spec.label}: {len(results) - len(failed)} of {len(results)} checks pass"
    print(summary + (f" (failing: {', '.join(failed)})" if failed else ""))
    return EXIT_FAILED if failed else EXIT_OK
