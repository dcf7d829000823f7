"""The MuJoCo adapter: a ``Scenario`` as MJCF, stepped by ``mujoco.mj_step``.

Model (all SI units, world frame z up, quaternions w x y z as in the scene):

- one MuJoCo body per scenario body, its frame at the centre of mass (``<inertial
  pos="0 0 0">``) and oriented as the scene's body frame; a free joint unless the body
  is fixed. Mass and the full body-frame inertia are written explicitly, so MuJoCo never
  recomputes them from the geoms (engines.md 1.3);
- one geom per body (sphere ``[r]``, box half extents, capsule ``[r, half_length]`` along
  body z) and a plane for ``scenario.ground``, placed with the one ground pose of
  ``physics.ground_pose`` (the plane's normal is its geom z axis);
- constant applied forces and torques are not part of the MJCF: the adapter writes them to
  ``xfrc_applied`` (world frame, the force at the body's centre of mass);
- springs as spatial tendons between two sites (stiffness, damping, springlength = the
  rest length), whose energy MuJoCo's ``mj_energyPos`` includes;
- profile ``matched``: one explicit ``<pair>`` per pair of bodies that can touch, with the
  scene's restitution and friction; profile ``defaults``: MuJoCo's own contacts.

State at the boundary (engines.md 1.4): MuJoCo's free-joint ``qpos`` is the body-frame
origin (here the centre of mass) and the world quaternion; ``qvel`` is the world velocity
of that origin and the angular velocity in the *body* frame, converted with R = R(quat):
ω_world = R ω_body.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from validation.scenario import BodySpec, Scenario
from validation.scenario.physics import body_inertia, ground_pose, pair_rule, rest_length

# --- constants, each with where its number comes from ------------------------------------

GROUND = "ground"
"""Name of the ground plane geom and the ``b`` of a pair override that means the ground."""

WORLD = "world"
"""The ``b`` of a spring anchored at a world point."""

PLANE_SIZE = (0.0, 0.0, 1.0)
"""m. A plane's size only affects rendering; it is infinite for collision (engines.md 1.3)."""

DAMPER_SOLIMP = (0.995, 0.995, 0.001, 0.5, 2.0)
"""solimp of the restitution damper: engines.md 1.7, measured e within 1 % of the request
(dt = 1e-3: 0.496–0.500 for e = 0.5 over 13 drop heights, 1.000 for e = 1)."""

SOFT_SOLREF = (0.02, 1.0)
"""MuJoCo's default contact solref (timeconst s, dampratio): engines.md 1.2; critically
damped, so e ≈ 0 (engines.md 1.7 table, first row)."""

SOFT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
"""MuJoCo's default contact solimp (engines.md 1.2)."""

DAMPER_FRICTION_SOLREF = SOFT_SOLREF
"""solreffriction of a frictional pair under the damper. With the damper on the friction
rows too (or on pyramidal cones, whose edge rows mix normal and friction and share the
normal's solref), MuJoCo's convex contact model pushes a sliding body off the ground at
≈ μ|v_t|: measured vz = 0.80 m/s after one step for a box sliding at 2 m/s, μ = 0.5, e = 0,
dt = 1e-3 (deceleration 3.29 m/s² instead of μg = 4.905). With this soft friction on
elliptic cones: vz ≤ 0.076 m/s and 4.91 m/s² (e = 0), 4.58 m/s² (e = 0.5)."""

FRICTION_RATIOS = (0.0, 0.0, 0.0)
"""Torsional and two rolling friction coefficients of a condim-3 pair: unused by condim 3
(sliding only), written as 0 so the pair carries no friction the scene did not ask for."""

CG_BODY_THRESHOLD = 100
"""Above this many bodies that can touch, ``solver=auto`` picks CG: engines.md 1.9 measured
Newton at ~0.8 s/step on a 1000-sphere pile against 8–10 ms for CG, and both within 15 %
of each other at 100 bodies."""

FRICTIONLESS_CONDIM = 1
"""Normal force only (engines.md 1.5: condim mixes by max, so both geoms and the pair get 1)."""

FRICTIONAL_CONDIM = 3
"""Normal force plus a two-dimensional sliding-friction cone."""

INERTIAL_ORIGIN_TOLERANCE = 0.0
"""m. MuJoCo's ``body_ipos`` must be exactly zero (the state conversion assumes the body
origin is the centre of mass); with explicit ``<inertial pos="0 0 0">`` it is, bit for bit."""

INTEGRATORS = {
    "Euler": "Euler",
    "RK4": "RK4",
    "implicit": "implicit",
    "implicitfast": "implicitfast",
}
"""Spec word -> MJCF option value (case-sensitive in MJCF, engines.md 1.1)."""

DEFAULT_SETTINGS: dict[str, object] = {
    "profile": "matched",
    "integrator": "Euler",  # the documented engine is semi-implicit Euler; MuJoCo's default too
    "solver": "auto",
    "cone": "auto",  # not a spec word: resolved by ``choose_cone``
    "restitution": "damper",
    "iterations": 100,  # MuJoCo's default (engines.md 1.2)
}
"""Every ``ENGINE_OPTIONS["mujoco"]`` setting and the value used when a spec omits it."""

RESTITUTION_NOTES = {
    "damper": (
        "restitution=damper: each pair gets solref = (0, -(1+e)/dt), a pure damper that "
        "reverses the normal velocity in one step, and solimp = "
        f"{DAMPER_SOLIMP}; this is a calibration, not a MuJoCo restitution model "
        "(engines.md 1.7: measured e within 1 % of the request at dt <= 2e-3); sliding "
        f"friction rows stay soft, solreffriction {DAMPER_FRICTION_SOLREF} on elliptic cones "
        "(a damper there launches sliding bodies at ≈ μ|v_t|)"
    ),
    "soft": (
        f"restitution=soft: MuJoCo's default soft contact, solref {SOFT_SOLREF}, solimp "
        f"{SOFT_SOLIMP}; critically damped, so bounces are ≈ inelastic whatever e the scene asks"
    ),
}


def _fmt(values) -> str:
    """Numbers as MJCF text, each written with ``repr`` so it reads back bit for bit."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


# --- mass properties and geometry ---------------------------------------------------------


GEOM_SIZES: dict[str, Callable[[object], tuple[float, ...]]] = {
    "sphere": lambda s: (s.radius,),
    "box": lambda s: tuple(s.half_extents),
    "capsule": lambda s: (s.radius, s.half_length),
}
"""Scenario shape -> MuJoCo geom ``size`` (engines.md 1.3: capsule = [r, half-length], along z)."""


def _inertial_attributes(body: BodySpec) -> dict[str, str]:
    """``<inertial>`` at the body origin. A fixed body gets zero mass: it never moves, and
    any mass would enter MuJoCo's system centre of mass, momenta and gravitational energy,
    which the scene (like ``mini_engine.quantities``) takes over moving bodies only."""
    if body.fixed:
        return {"pos": "0 0 0", "mass": "0", "diaginertia": "0 0 0"}
    inertia = body_inertia(body)
    full = (
        inertia[0, 0],
        inertia[1, 1],
        inertia[2, 2],
        inertia[0, 1],
        inertia[0, 2],
        inertia[1, 2],
    )
    return {"pos": "0 0 0", "mass": repr(float(body.mass)), "fullinertia": _fmt(full)}


# --- contact pairs ------------------------------------------------------------------------


@dataclass(frozen=True)
class ContactPair:
    """Two geoms that may touch and the scene's values for them.

    Attributes:
        geom_a, geom_b: MJCF geom names (``geom_b`` may be the ground).
        restitution: e in [0, 1].
        friction: Coulomb μ >= 0; 0 is frictionless (condim 1).
    """

    geom_a: str
    geom_b: str
    restitution: float
    friction: float


def _geom_name(body_name: str) -> str:
    return f"{body_name}/geom"


def contact_pairs(scenario: Scenario) -> list[ContactPair]:
    """Every pair that can touch: each body with every later body and with the ground,
    skipping pairs of two fixed bodies. Restitution = max of the two (ground:
    ``scenario.ground.restitution``), friction = geometric mean, unless ``scenario.pairs``
    overrides a value (the mini_engine defaults ``restitution_mix=max``,
    ``friction_mix=geometric_mean``)."""
    ends = [(b.name, b.restitution, b.friction, b.fixed) for b in scenario.bodies]
    if scenario.ground is not None:
        ends.append((GROUND, scenario.ground.restitution, scenario.ground.friction, True))
    overrides = {frozenset((p.a, p.b)): p for p in scenario.pairs}
    pairs = []
    for (name_a, e_a, mu_a, fixed_a), (name_b, e_b, mu_b, fixed_b) in combinations(ends, 2):
        if fixed_a and fixed_b:
            continue
        override = overrides.get(frozenset((name_a, name_b)))
        e = pair_rule("restitution", e_a, e_b, override and override.restitution)
        mu = pair_rule("friction", mu_a, mu_b, override and override.friction)
        geom_b = GROUND if name_b == GROUND else _geom_name(name_b)
        pairs.append(ContactPair(_geom_name(name_a), geom_b, e, mu))
    return pairs


def _damper_contact(e: float, dt: float) -> dict[str, str]:
    """engines.md 1.7: damping b = (1+e)/dt reverses the normal velocity in one step
    (v+ = (1 - b dt) v- = -e v-); friction rows stay soft (``DAMPER_FRICTION_SOLREF``)."""
    return {
        "solref": _fmt((0.0, -(1.0 + e) / dt)),
        "solreffriction": _fmt(DAMPER_FRICTION_SOLREF),
        "solimp": _fmt(DAMPER_SOLIMP),
    }


def _soft_contact(e: float, dt: float) -> dict[str, str]:
    """MuJoCo's default soft contact, whatever e (engines.md 1.2)."""
    return {"solref": _fmt(SOFT_SOLREF), "solimp": _fmt(SOFT_SOLIMP)}


RESTITUTION_MODELS: dict[str, Callable[[float, float], dict[str, str]]] = {
    "damper": _damper_contact,
    "soft": _soft_contact,
}
"""Spec ``restitution`` -> the pair's solver attributes, from (e, dt s)."""


def _pair_attributes(pair: ContactPair, restitution: str, dt: float) -> dict[str, str]:
    attributes = {"geom1": pair.geom_a, "geom2": pair.geom_b}
    if pair.friction > 0.0:
        attributes["condim"] = str(FRICTIONAL_CONDIM)
        attributes["friction"] = _fmt((pair.friction, pair.friction, *FRICTION_RATIOS))
    else:
        attributes["condim"] = str(FRICTIONLESS_CONDIM)
    attributes.update(RESTITUTION_MODELS[restitution](pair.restitution, dt))
    return attributes


# --- MJCF ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ContactPlan:
    """What a profile does about contacts.

    Attributes:
        pairs: explicit pairs (empty under ``defaults``).
        geom: attributes every geom gets (``contype``/``conaffinity``/``condim``).
        disable_contact: set MuJoCo's contact disable flag (nothing can touch).
        touching_bodies: how many moving bodies can touch something (for ``solver=auto``).
    """

    pairs: list[ContactPair]
    geom: dict[str, str]
    disable_contact: bool
    touching_bodies: int


def _matched_contacts(scenario: Scenario) -> ContactPlan:
    """Only the explicit pairs collide: contype = conaffinity = 0 on every geom."""
    pairs = contact_pairs(scenario)
    names = {p.geom_a for p in pairs} | {p.geom_b for p in pairs}
    moving = sum(_geom_name(b.name) in names for b in scenario.bodies if not b.fixed)
    geom = {"contype": "0", "conaffinity": "0", "condim": str(FRICTIONLESS_CONDIM)}
    return ContactPlan(pairs, geom, disable_contact=not pairs, touching_bodies=moving)


def _default_contacts(scenario: Scenario) -> ContactPlan:
    """MuJoCo's default geoms: every geom collides with every other (condim 3, μ = 1)."""
    moving = sum(not b.fixed for b in scenario.bodies)
    return ContactPlan([], {}, disable_contact=False, touching_bodies=moving)


PROFILES: dict[str, Callable[[Scenario], ContactPlan]] = {
    "matched": _matched_contacts,
    "defaults": _default_contacts,
}
"""Spec ``profile`` -> its contact plan."""


def choose_solver(setting: str, profile: str, touching_bodies: int) -> str:
    """MJCF solver name. ``auto``: CG above ``CG_BODY_THRESHOLD`` bodies that can touch,
    Newton otherwise; under ``profile=defaults`` always Newton (what a new user gets)."""
    if setting != "auto":
        return setting
    if profile == "matched" and touching_bodies > CG_BODY_THRESHOLD:
        return "CG"
    return "Newton"


def choose_cone(setting: str, settings: dict[str, object], pairs: list[ContactPair]) -> str:
    """MJCF cone. Unset: elliptic when a damper pair has friction (its friction rows are
    then separate from the normal row and can stay soft, ``DAMPER_FRICTION_SOLREF``),
    else pyramidal, MuJoCo's default (engines.md 1.2)."""
    if setting != "auto":
        return setting
    frictional = any(p.friction > 0.0 for p in pairs)
    return "elliptic" if frictional and settings["restitution"] == "damper" else "pyramidal"


def _add_body(parent: ET.Element, body: BodySpec, geom: dict[str, str]) -> ET.Element:
    element = ET.SubElement(
        parent, "body", name=body.name, pos=_fmt(body.position), quat=_fmt(body.orientation)
    )
    if not body.fixed:
        ET.SubElement(element, "freejoint", name=f"{body.name}/free")
    ET.SubElement(element, "inertial", _inertial_attributes(body))
    ET.SubElement(
        element,
        "geom",
        name=_geom_name(body.name),
        type=body.shape.type,
        size=_fmt(GEOM_SIZES[body.shape.type](body.shape)),
        **geom,
    )
    return element


def _add_springs(root: ET.Element, world: ET.Element, bodies: dict, scenario: Scenario) -> None:
    """A spatial tendon per spring between a site at each anchor (a world site for ``world``)."""
    if not scenario.springs:
        return
    tendons = ET.SubElement(root, "tendon")
    for k, spring in enumerate(scenario.springs):
        site_a, site_b = f"spring{k}/a", f"spring{k}/b"
        ET.SubElement(bodies[spring.a], "site", name=site_a, pos=_fmt(spring.anchor_a))
        parent_b = world if spring.b == WORLD else bodies[spring.b]
        ET.SubElement(parent_b, "site", name=site_b, pos=_fmt(spring.anchor_b))
        rest = rest_length(scenario, spring)
        tendon = ET.SubElement(
            tendons,
            "spatial",
            name=f"spring{k}",
            stiffness=repr(float(spring.stiffness)),
            damping=repr(float(spring.damping)),
            springlength=_fmt((rest, rest)),
        )
        ET.SubElement(tendon, "site", site=site_a)
        ET.SubElement(tendon, "site", site=site_b)


def build_mjcf(scenario: Scenario, settings: dict[str, object]) -> tuple[str, ContactPlan, str]:
    """(MJCF text, contact plan, solver name) of ``scenario`` under the full ``settings``."""
    profile = str(settings["profile"])
    plan = PROFILES[profile](scenario)
    solver = choose_solver(str(settings["solver"]), profile, plan.touching_bodies)
    root = ET.Element("mujoco", model=scenario.name or "scenario")
    ET.SubElement(root, "compiler", angle="radian", alignfree="false", inertiafromgeom="false")
    option = ET.SubElement(
        root,
        "option",
        timestep=repr(float(scenario.dt)),
        gravity=_fmt(scenario.gravity),
        integrator=INTEGRATORS[str(settings["integrator"])],
        solver=solver,
        cone=choose_cone(str(settings["cone"]), settings, plan.pairs),
        iterations=str(int(settings["iterations"])),
    )
    unused = {"contact": plan.disable_contact, "gravity": not any(scenario.gravity)}
    if any(unused.values()):  # pay only for what the scene uses
        ET.SubElement(option, "flag", **{name: "disable" for name, off in unused.items() if off})
    world = ET.SubElement(root, "worldbody")
    if scenario.ground is not None:
        point, quat = ground_pose(scenario.ground)
        ET.SubElement(
            world,
            "geom",
            name=GROUND,
            type="plane",
            size=_fmt(PLANE_SIZE),
            pos=_fmt(point),
            quat=_fmt(quat),
            **plan.geom,
        )
    bodies = {b.name: _add_body(world, b, plan.geom) for b in scenario.bodies}
    _add_springs(root, world, bodies, scenario)
    if plan.pairs:
        contact = ET.SubElement(root, "contact")
        for pair in plan.pairs:
            ET.SubElement(
                contact, "pair", _pair_attributes(pair, str(settings["restitution"]), scenario.dt)
            )
    return ET.tostring(root, encoding="unicode"), plan, solver
