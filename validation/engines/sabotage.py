"""Sabotaged mini engines: test doubles that measure the library's power.

Each ``Sabotage`` is one realistic single-point bug in mini_engine (a sign, a factor, a
transposed matrix, a dropped term), put in by replacing one function, method or table entry
of mini_engine while mini steps, never by editing its files. ``PHYSVAL_SABOTAGE=<name>`` in
the environment (inherited by every worker process) makes ``registry.create_adapter`` wrap
every mini spec's adapter in ``SabotagedAdapter``: the bug is active only inside that
adapter's own calls (loading, the model report, stepping, observing), so the reference side,
the other engines and the measurements (mini_engine's collision detection reads the observed
poses of every engine) run the real code in the same process. The model is built again
inside the sabotage, so a bug in a shape's inertia reaches mini's model as it would.

Every result of a sabotaged run says so: the engine version ends in ``+sabotage.<name>``
(results.csv, provenance.json, baselines, history), so a sabotaged run can never pass for a
real one. ``benchmarks/mutation_score.py`` runs the library once per sabotage and prints
which scenes caught it (``tests/test_sabotage.py`` checks a few in CI).
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import os
import pkgutil
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

SABOTAGE_VARIABLE = "PHYSVAL_SABOTAGE"
"""Environment variable naming the sabotage of every mini spec (unset or empty: none)."""

VERSION_MARK = "+sabotage."
"""Appended to a sabotaged adapter's engine version, then the sabotage's name (a PEP 440
local version label: ``0.1.0+sabotage.gravity_low``)."""

PATCHED_PACKAGES = ("mini_engine", "validation.engines.mini")
"""Modules in which a replaced function is replaced under every name bound to it: mini_engine
and its adapter (``from mini_engine.rotation import world_inertia`` binds the same function in
``mini_engine.step`` and the adapter; a bug in its one definition reaches both)."""

GRAVITY_FACTOR = 0.99
"""``gravity_low``: gravity 1 % low (a wrong constant, a float32 round trip of a unit)."""

FRICTION_FACTOR = 2.0
"""``friction_doubled``: the Coulomb disc of radius 2μλ_n (μ applied twice)."""

WARM_START_FACTOR = 2.0
"""``warm_start_doubled``: the last step's impulses carried over twice."""

ROTATED_BODY = 2
"""``inertial_frame_rotated``: the index, among a scene's first model's bodies, of the body
whose link's inertial frame is turned (the third: the Kuka's ``lbr_iiwa_link_3``; the last
of a model with fewer)."""

INERTIAL_TURN = 0.5
"""rad: ``inertial_frame_rotated`` adds this to the roll of the link's ``<inertial><origin
rpy>``: its inertia about turned axes, the slip a converter makes that drops or doubles an
inertial rotation."""

WRONG_RESTITUTION_THRESHOLD = 0.1
"""m/s. ``restitution_threshold``: contacts approaching slower than this stop dead, where the
documented law (``Settings.restitution_threshold`` = 0) bounces every approach."""


@dataclass(frozen=True)
class Patch:
    """One replacement: ``owner.name`` (or the entry ``owner.name[key]``) becomes
    ``make(original)`` while the sabotage is active.

    Attributes:
        owner: ``module`` or ``module:Class`` holding the attribute.
        name: the attribute.
        make: the original value -> the sabotaged one.
        key: a key of the dict ``owner.name`` (a registry entry), or None.
        key_of: a function returning that key, called when the patch is first applied (a key
            made of mini_engine's values: this module imports nothing of mini_engine, nor
            NumPy, until a sabotage is active, so ``physval check`` stays light), or None.
    """

    owner: str
    name: str
    make: Callable[[object], object]
    key: object = None
    key_of: Callable[[], object] | None = None

    def entry(self) -> object:
        """The dict key this patch replaces (``key`` or ``key_of()``), or None for an attribute."""
        return self.key if self.key_of is None else self.key_of()

    def sites(self) -> list[tuple[object, str | None, object]]:
        """(holder, attribute or None for a dict entry, original) of every place to replace."""
        _import_patched_packages()
        module_name, _, class_name = self.owner.partition(":")
        holder = importlib.import_module(module_name)
        if class_name:
            holder = getattr(holder, class_name)
        original = getattr(holder, self.name)
        key = self.entry()
        if key is not None:
            return [(original, None, original[key])]
        if class_name:  # a method: one class attribute
            return [(holder, self.name, original)]
        return [
            (module, self.name, original)
            for module_name, module in sorted(sys.modules.items())
            if any(module_name == p or module_name.startswith(p + ".") for p in PATCHED_PACKAGES)
            and getattr(module, self.name, None) is original
        ]


def _import_patched_packages() -> None:
    """Every module of ``PATCHED_PACKAGES`` imported, so that every name bound to a replaced
    function is found whatever the run imported so far."""
    for package_name in PATCHED_PACKAGES:
        package = importlib.import_module(package_name)
        for module in pkgutil.walk_packages(package.__path__, package_name + "."):
            importlib.import_module(module.name)


@dataclass(frozen=True)
class Sabotage:
    """A realistic bug in one place of mini_engine: a name, what it breaks, where, and how.

    ``loader``: None for a bug of the solver; ``"native"`` for a model-reading bug (the
    adapter builds a scene's models from its own, wrong, reading of the file, as an engine
    with a native loader does): the sabotaged adapter then states ``model_loader`` native,
    so the runner measures the difference as tier 1 (``model_fields``) instead of refusing.
    """

    name: str
    what: str
    where: str
    patches: tuple[Patch, ...]
    loader: str | None = None

    @functools.cached_property
    def _sites(self) -> list[tuple[object, str | None, object, object, object]]:
        """(holder, attribute or None, original, replacement, key), found once per process."""
        found = []
        for patch in self.patches:
            for holder, attribute, original in patch.sites():
                found.append((holder, attribute, original, patch.make(original), patch.entry()))
        return found

    @contextlib.contextmanager
    def active(self) -> Iterator[None]:
        """Every replacement in place for the block, every original back after it."""
        done = []
        try:
            for holder, attribute, original, replacement, key in self._sites:
                _put(holder, attribute, key, replacement)
                done.append((holder, attribute, key, original))
            yield
        finally:
            for holder, attribute, key, original in reversed(done):
                _put(holder, attribute, key, original)


def _put(holder, attribute: str | None, key, value) -> None:
    if attribute is None:
        holder[key] = value
    else:
        setattr(holder, attribute, value)


# --- the bugs, each a replacement of the original -------------------------------------------


def _frozen_pose(original):
    """Positions and orientations never integrated: ``integrate_pose`` returns the old pose."""

    def integrate_pose(pos, quat, vel, ang_vel, moving, orientation_update, dt):
        return pos.copy(), quat.copy()

    return integrate_pose


def _no_contacts(original):
    from mini_engine.contacts import Contacts

    def detect_contacts(model, pos, rot, margin, padding=0.0):
        return Contacts.empty()

    return detect_contacts


def _scaled_gravity(original):
    def gravity_acceleration(model):
        return GRAVITY_FACTOR * original(model)

    return gravity_acceleration


def _pair_values(restitution_factor: float, friction_factor: float):
    def make(original):
        def pair_values(model, contacts, settings):
            restitution, friction = original(model, contacts, settings)
            return restitution * restitution_factor, friction * friction_factor

        return pair_values

    return make


def _no_gyroscopic(original):
    from mini_engine.integrate import GYROSCOPIC_RULES

    return GYROSCOPIC_RULES["none"]


def _gyroscopic_sign(original):
    """The gyroscopic rule with ``+ω × Iω``: both rules are odd in dt's sign of that term."""

    def rule(ang_vel, rot, inertia, bodies, dt):
        original(ang_vel, rot, inertia, bodies, -dt)

    return rule


def _box_axes_swapped(original):
    """``Ixx`` and ``Izz`` of a box exchanged (a diagonal written in the wrong order)."""
    import numpy as np

    def unit_inertia(self):
        return np.diag(np.diagonal(original(self))[::-1])

    return unit_inertia


def _capsule_without_parallel_axis(original):
    """Each cap's transverse moment about its own base, not moved to the capsule's centre."""
    import numpy as np

    def unit_inertia(self):
        r, length = self.radius, 2.0 * self.half_length
        volume_cylinder, volume_caps = np.pi * r**2 * length, 4.0 / 3.0 * np.pi * r**3
        m_cap = 0.5 * volume_caps / (volume_cylinder + volume_caps)
        shift = 2.0 * m_cap * (length**2 / 4.0 + 3.0 * length * r / 8.0)  # both caps' term
        return original(self) - np.diag([shift, shift, 0.0])

    return unit_inertia


def _transposed_world_inertia(original):
    def world_inertia(rot, inertia_body):
        return original(rot.transpose(0, 2, 1), inertia_body)  # Rᵀ I R

    return world_inertia


def _explicit_positions(original):
    return lambda old, new: old


def _damping_sign(original):
    """The damper's term ``+c (v_B - v_A)·u`` with the sign flipped: the spring law with the
    velocities negated (velocities enter only the damper)."""

    def spring_forces(model, state, rot):
        return original(model, replace(state, vel=-state.vel, ang_vel=-state.ang_vel), rot)

    return spring_forces


def _flipped_normal(original):
    def collide(*args):
        hits = original(*args)
        return hits._replace(normal=-hits.normal)

    return collide


def _doubled_warm_start(original):
    def warm_start_impulses(model, graph, contacts, previous, settings):
        normal, friction = original(model, graph, contacts, previous, settings)
        return (
            WARM_START_FACTOR * normal,
            None if friction is None else WARM_START_FACTOR * friction,
        )

    return warm_start_impulses


@functools.lru_cache(maxsize=64)
def _halved(settings):
    return settings.replace(solver_iterations=max(1, settings.solver_iterations // 2))


def _half_iterations(original):
    def solve_contacts(
        model, contacts, pos, inv_inertia_world, vel, ang_vel, settings, previous=None
    ):
        return original(
            model, contacts, pos, inv_inertia_world, vel, ang_vel, _halved(settings), previous
        )

    return solve_contacts


@functools.lru_cache(maxsize=64)
def _with_threshold(settings):
    return settings.replace(restitution_threshold=WRONG_RESTITUTION_THRESHOLD)


def _wrong_threshold(original):
    def normal_targets(depth, before, negative_restitution, settings):
        return original(depth, before, negative_restitution, _with_threshold(settings))

    return normal_targets


def _clock_ahead(original):
    """The clock counts the step it is about to take: ``(k + 1) dt`` after k steps."""

    from mini_engine.step import DEFAULT_SETTINGS

    def step(model, state, settings=DEFAULT_SETTINGS):
        result = original(model, state, settings)
        if state.time != 0.0:  # the first step counted twice; every later one once
            return result
        ahead = replace(result.state, time=result.state.time + settings.dt)
        return result._replace(state=ahead)

    return step


def _no_torque(original):
    import numpy as np

    def constant_loads(model):
        force, torque = original(model)
        return force, np.zeros_like(torque)

    return constant_loads


def _torque_in_body_frame(original):
    """The world-frame torque read as body-frame components: ``R τ`` instead of ``τ``."""
    import numpy as np

    def integrate_angular_velocity(ang_vel, torque, inv_inertia_world, rot, *rest, **named):
        return original(
            ang_vel, np.einsum("nij,nj->ni", rot, torque), inv_inertia_world, rot, *rest, **named
        )

    return integrate_angular_velocity


def _mixed_by(table: str, rule: str):
    """An entry of the pair-mixing table ``mini_engine.solver.<table>`` replaced by its
    ``rule`` entry (a wrong default rule)."""

    def make(original):
        from mini_engine import solver

        return getattr(solver, table)[rule]

    return make


def _damper_without_spin(original):
    """A spring's damper that takes each end's velocity as its centre of mass's (``v``, not
    ``v + ω × r``): the stretch speed of an off-centre anchor on a spinning body is lost. The
    elastic force reads no velocity, so the springs see the state with every ω zero."""
    import numpy as np

    def spring_forces(model, state, rot):
        return original(model, replace(state, ang_vel=np.zeros_like(state.ang_vel)), rot)

    return spring_forces


def _inertial_frame_rotated(original):
    """mini's model built with one model body's inertia as a copy of the first model's file
    gives it, whose ``ROTATED_BODY``'s link has its inertial frame turned by
    ``INERTIAL_TURN`` about x: that body's inertia about the scene's own body axes (so its
    observed pose is the scene's, as a native loader's observation is), every other body and
    joint as they are."""

    def build_mini_model(scenario):
        if not scenario.models:
            return original(scenario)
        import tempfile
        from pathlib import Path

        import numpy as np

        from validation.reference.rotation import quat_to_matrix
        from validation.scenario.schema import Scenario
        from validation.scenario.urdf import model_layouts, with_joint_state

        layout = model_layouts(scenario)[0]
        which = min(ROTATED_BODY, len(layout.links) - 1)
        with tempfile.TemporaryDirectory() as folder:
            copy = Path(folder) / layout.path.name
            _write_turned_inertial(layout.path, copy, layout.links[which])
            data = scenario.model_dump()
            data["models"][0]["file"] = str(copy)
            turned = Scenario.model_validate({**data, "source": scenario.source})
            read = with_joint_state(turned, {}, {}).body(layout.bodies[which])
        stated = scenario.body(layout.bodies[which])
        axes = quat_to_matrix(np.asarray(stated.orientation)).T @ quat_to_matrix(
            np.asarray(read.orientation)
        )
        data = scenario.model_dump()
        names = [body["name"] for body in data["bodies"]]
        data["bodies"][names.index(stated.name)]["inertia"] = (
            axes @ read.inertia_matrix @ axes.T
        ).tolist()
        return original(Scenario.model_validate({**data, "source": scenario.source}))

    return build_mini_model


def _write_turned_inertial(source, target, link: str) -> None:
    """``source`` (a URDF) written to ``target`` with ``link``'s ``<inertial><origin rpy>``
    turned by ``INERTIAL_TURN`` about its x axis (roll)."""
    import xml.etree.ElementTree as ElementTree

    tree = ElementTree.parse(source)
    inertial = tree.getroot().find(f"./link[@name='{link}']/inertial")
    origin = inertial.find("origin")
    if origin is None:
        origin = ElementTree.SubElement(inertial, "origin")
    roll, pitch, yaw = (float(v) for v in (origin.get("rpy") or "0 0 0").split())
    origin.set("rpy", f"{roll + INERTIAL_TURN!r} {pitch!r} {yaw!r}")
    tree.write(target)


def _sphere_box():
    from mini_engine.shapes import ShapeType

    return (ShapeType.SPHERE, ShapeType.BOX)


def _gyroscopic_patches(make) -> tuple[Patch, ...]:
    return tuple(
        Patch("mini_engine.integrate", "GYROSCOPIC_RULES", make, key=mode)
        for mode in ("explicit", "implicit")
    )


SABOTAGES: dict[str, Sabotage] = {
    s.name: s
    for s in (
        Sabotage(
            "frozen_bodies",
            "positions and orientations never move",
            "integrate.integrate_pose",
            (Patch("mini_engine.integrate", "integrate_pose", _frozen_pose),),
        ),
        Sabotage(
            "no_contacts",
            "collision detection finds nothing",
            "collision.detect_contacts",
            (Patch("mini_engine.collision", "detect_contacts", _no_contacts),),
        ),
        Sabotage(
            "gravity_low",
            "gravity 1 % low",
            "forces.gravity_acceleration",
            (Patch("mini_engine.forces", "gravity_acceleration", _scaled_gravity),),
        ),
        Sabotage(
            "restitution_ignored",
            "every contact's restitution taken as 0",
            "solver.pair_values",
            (Patch("mini_engine.solver", "pair_values", _pair_values(0.0, 1.0)),),
        ),
        Sabotage(
            "friction_doubled",
            "the friction cone 2μ",
            "solver.pair_values",
            (Patch("mini_engine.solver", "pair_values", _pair_values(1.0, FRICTION_FACTOR)),),
        ),
        Sabotage(
            "no_gyroscopic",
            "the explicit and implicit gyroscopic rules drop ω × Iω",
            "integrate.GYROSCOPIC_RULES",
            _gyroscopic_patches(_no_gyroscopic),
        ),
        Sabotage(
            "gyroscopic_sign",
            "the gyroscopic term with its sign flipped (+ω × Iω)",
            "integrate.GYROSCOPIC_RULES",
            _gyroscopic_patches(_gyroscopic_sign),
        ),
        Sabotage(
            "box_inertia_swapped",
            "a box's Ixx and Izz exchanged",
            "shapes.Box.unit_inertia",
            (Patch("mini_engine.shapes:Box", "unit_inertia", _box_axes_swapped),),
        ),
        Sabotage(
            "capsule_no_parallel_axis",
            "a capsule's caps without their parallel-axis term",
            "shapes.Capsule.unit_inertia",
            (Patch("mini_engine.shapes:Capsule", "unit_inertia", _capsule_without_parallel_axis),),
        ),
        Sabotage(
            "world_inertia_transposed",
            "world inertia Rᵀ I R instead of R I Rᵀ",
            "rotation.world_inertia",
            (Patch("mini_engine.rotation", "world_inertia", _transposed_world_inertia),),
        ),
        Sabotage(
            "explicit_euler_positions",
            "positions from the old velocities (explicit Euler) under the semi-implicit name",
            "step.POSE_VELOCITY",
            (
                Patch(
                    "mini_engine.step",
                    "POSE_VELOCITY",
                    _explicit_positions,
                    key="semi_implicit_euler",
                ),
            ),
        ),
        Sabotage(
            "damping_sign",
            "a spring's damper pushes along the stretch speed (sign flipped)",
            "forces.spring_forces",
            (Patch("mini_engine.forces", "spring_forces", _damping_sign),),
        ),
        Sabotage(
            "sphere_box_normal_flipped",
            "the sphere-box contact normal points the wrong way",
            "narrowphase.NARROW_PHASE[sphere, box]",
            (
                Patch(
                    "mini_engine.narrowphase", "NARROW_PHASE", _flipped_normal, key_of=_sphere_box
                ),
            ),
        ),
        Sabotage(
            "warm_start_doubled",
            "the last step's contact impulses carried over twice",
            "solver._warm_start_impulses",
            (Patch("mini_engine.solver", "_warm_start_impulses", _doubled_warm_start),),
        ),
        Sabotage(
            "half_solver_iterations",
            "half the sequential-impulse sweeps the settings ask for",
            "solver.solve_contacts",
            (Patch("mini_engine.solver", "solve_contacts", _half_iterations),),
        ),
        Sabotage(
            "restitution_threshold",
            f"no bounce below {WRONG_RESTITUTION_THRESHOLD} m/s (the documented law has none)",
            "solver._normal_targets",
            (Patch("mini_engine.solver", "_normal_targets", _wrong_threshold),),
        ),
        Sabotage(
            "clock_ahead",
            "the clock one step ahead: (k + 1) dt after k steps",
            "step.step",
            (Patch("mini_engine.step", "step", _clock_ahead),),
        ),
        Sabotage(
            "torque_in_body_frame",
            "a constant world torque applied as body-frame components (R τ)",
            "integrate.integrate_angular_velocity",
            (Patch("mini_engine.step", "integrate_angular_velocity", _torque_in_body_frame),),
        ),
        Sabotage(
            "restitution_mix_min",
            "a pair's restitution from the two bodies' by min, not max",
            "solver.RESTITUTION_MIX[max]",
            (
                Patch(
                    "mini_engine.solver",
                    "RESTITUTION_MIX",
                    _mixed_by("RESTITUTION_MIX", "min"),
                    key="max",
                ),
            ),
        ),
        Sabotage(
            "friction_mix_min",
            "a pair's friction from the two bodies' by min, not the geometric mean",
            "solver.FRICTION_MIX[geometric_mean]",
            (
                Patch(
                    "mini_engine.solver",
                    "FRICTION_MIX",
                    _mixed_by("FRICTION_MIX", "min"),
                    key="geometric_mean",
                ),
            ),
        ),
        Sabotage(
            "damper_without_spin",
            "a spring's damper reads its anchors' velocities without ω × r",
            "forces.spring_forces",
            (Patch("mini_engine.forces", "spring_forces", _damper_without_spin),),
        ),
        Sabotage(
            "torque_ignored",
            "a body's constant applied torque dropped",
            "forces.constant_loads",
            (Patch("mini_engine.forces", "constant_loads", _no_torque),),
        ),
        Sabotage(
            "inertial_frame_rotated",
            f"a model's third link's inertial frame turned {INERTIAL_TURN} rad about x (read "
            "natively: the model tier's planted difference)",
            "engines.mini.model.build_mini_model",
            (Patch("validation.engines.mini.model", "build_mini_model", _inertial_frame_rotated),),
            loader="native",
        ),
    )
}
"""Sabotage name -> the bug; each one realistic and in one place of mini_engine."""


class SabotageError(ValueError):
    """``PHYSVAL_SABOTAGE`` names no sabotage."""


def chosen(environment: dict[str, str] | None = None) -> Sabotage | None:
    """The sabotage ``PHYSVAL_SABOTAGE`` names (None when unset or empty); an unknown name is
    a ``SabotageError`` whose message is one line naming the accepted names."""
    name = (os.environ if environment is None else environment).get(SABOTAGE_VARIABLE, "")
    if not name:
        return None
    if name not in SABOTAGES:
        raise SabotageError(
            f"{SABOTAGE_VARIABLE}: expected one of {', '.join(SABOTAGES)}; got {name!r}"
        )
    return SABOTAGES[name]


class SabotagedAdapter:
    """A mini adapter with one sabotage active in each of its calls; its engine version says so."""

    def __init__(self, adapter, sabotage: Sabotage):
        self.adapter = adapter
        self.spec = adapter.spec
        self.sabotage = sabotage
        self.model_loader = sabotage.loader
        """``native`` for a model-reading sabotage (the runner's ``loader_of``), else None."""

    def load(self, scene) -> None:
        with self.sabotage.active():  # the adapter builds its model here, sabotaged
            self.adapter.load(scene)

    def model_report(self):
        with self.sabotage.active():
            return self.adapter.model_report()

    def joint_report(self):
        with self.sabotage.active():
            return self.adapter.joint_report()

    def advance(self, steps: int) -> None:
        with self.sabotage.active():
            self.adapter.advance(steps)

    def observe(self):
        with self.sabotage.active():
            return self.adapter.observe()

    def provenance(self):
        provenance = self.adapter.provenance()
        provenance.version += VERSION_MARK + self.sabotage.name
        provenance.notes = [
            *provenance.notes,
            f"sabotage {self.sabotage.name}: {self.sabotage.what}",
        ]
        return provenance

    def close(self) -> None:
        self.adapter.close()


def sabotaged(adapter, environment: dict[str, str] | None = None):
    """``adapter`` wrapped in the sabotage the environment names, if it is a mini adapter."""
    sabotage = chosen(environment)
    if sabotage is None or adapter.spec.name != "mini":
        return adapter
    return SabotagedAdapter(adapter, sabotage)
