"""The MuJoCo adapter: a ``Scenario`` as MJCF, stepped by ``mujoco.mj_step``.

Model (all SI units, world frame z up, quaternions w x y z as in the scene):

- one MuJoCo body per scenario body, its frame at the centre of mass (``<inertial
  pos="0 0 0">``) and oriented as the scene's body frame; a free joint unless the body
  is fixed. Mass and the full body-frame inertia are written explicitly, so MuJoCo never
  recomputes them from the geoms (engines.md 1.3);
- one geom per body (sphere ``[r]``, box half extents, capsule and cylinder ``[r,
  half_length]`` along the shape's z), at the shape's ``offset`` and ``orientation`` in the
  body (a placed shape: geom ``pos``/``quat``), and a plane for ``scenario.ground``, placed
  with the one ground pose of ``physics.ground_pose`` (the plane's normal is its geom z axis);
- constant applied forces and torques are not part of the MJCF: the adapter writes them to
  ``xfrc_applied`` (world frame, the force at the body's centre of mass);
- springs as spatial tendons between two sites (stiffness, damping, springlength = the
  rest length), whose energy MuJoCo's ``mj_energyPos`` includes;
- profile ``matched``: the scene's restitution and friction on every pair that can touch,
  written in O(N) for N bodies: each geom carries its body's values and MuJoCo's own
  collision mixes two geoms' values (``mixed_values``); a ``<pair>`` is written only where
  that mix differs from the scene's pair (``_matched_contacts``), and bitmasks or
  ``<exclude>`` switch the mixed contact off there; the arena is sized from the scene
  (``arena_bytes``); profile ``defaults``: MuJoCo's own contacts.

State at the boundary (engines.md 1.4): MuJoCo's free-joint ``qpos`` is the body-frame
origin (here the centre of mass) and the world quaternion; ``qvel`` is the world velocity
of that origin and the angular velocity in the *body* frame, converted with R = R(quat):
ω_world = R ω_body.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

from validation.engines.frames import matrix_to_quat
from validation.engines.mujoco.declaration import DECLARATION
from validation.scenario import BodySpec, Scenario
from validation.scenario.physics import body_inertia, ground_pose, pair_rule, rest_length

# --- constants, each with where its number comes from ------------------------------------

GROUND = "ground"
"""Name of the ground plane geom and the ``b`` of a pair override that means the ground."""

WORLD = "world"
"""The ``b`` of a spring anchored at a world point."""

WORLD_BODY = "world"
"""MuJoCo's name of its world body (the ground plane's body, for ``<exclude>``)."""

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

ARENA_FLOOR = 16 * 1024 * 1024
"""Bytes: the least arena written. MuJoCo's own guess for a one-body scene is 13.6 MB, and
the library's scenes use at most 0.6 MB (maxuse_arena over up to 3,000 steps, the 6x6x6
pile included); an arena is virtual memory until used, so a floor costs nothing."""

BROADPHASE_BYTES_PER_BODY_PAIR = 8
"""Bytes of arena per pair of bodies (the world included): ``mj_collision`` takes an int per
possible body pair for its broadphase list, and the broadphase as much again (measured:
maxuse_arena 401.07 MB for 10,000 spheres, 8 B x 10,001 x 10,000 / 2 = 400.04 MB; 16.2 MB
for 2,000, 16.0 MB)."""

CONTACTS_PER_BODY = 16
"""Contacts room is made for per moving body: a sphere in a dense pile has at most 12
neighbours and the ground, a box on a box up to 8 contacts (MuJoCo's box-box)."""

CONTACT_BYTES = 4096
"""Bytes per contact: the ``mjContact`` and its (at most 4, pyramidal condim 3) constraint
rows with sparse Jacobians and the solver's per-row work, with room to spare (measured:
maxuse_arena - broadphase = 1.0 MB for 10,000 resting sphere contacts, 100 B each)."""

NEWTON_BYTES_PER_DOF_SQUARED = 24
"""Bytes per nv² under the Newton solver: its Hessian, Cholesky factor and one more nv x nv
work matrix (3 x 8 B), the dense worst case."""

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
    **{option.name: option.default for option in DECLARATION.options},
    "cone": "auto",  # not a spec word: resolved by ``choose_cone``
}
"""Every option of MuJoCo's declaration and the value used when a spec omits it (the
declaration's defaults: integrator Euler, the documented engine's semi-implicit Euler and
MuJoCo's default too; iterations 100, MuJoCo's default, engines.md 1.2)."""

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
    "cylinder": lambda s: (s.radius, s.half_length),
}
"""Scenario shape -> MuJoCo geom ``size`` (engines.md 1.3: capsule and cylinder = [r,
half-length], along the geom's z)."""


def _placement(shape) -> dict[str, str]:
    """A placed shape's geom ``pos`` and ``quat`` in its body (whose frame is the centre of
    mass, the explicit ``<inertial>`` unchanged by them: ``inertiafromgeom="false"``); none
    for a shape at the centre of mass along the body axes."""
    if not shape.placed:
        return {}
    return {"pos": _fmt(shape.offset), "quat": _fmt(shape.orientation)}


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


# --- contacts -----------------------------------------------------------------------------


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


@dataclass(frozen=True)
class _End:
    """One side of a contact: a body or the ground, with its own values."""

    index: int
    """Its place among the ends: colliding scene bodies in order, then the ground."""
    name: str
    geom: str
    restitution: float
    friction: float
    fixed: bool

    @property
    def surface(self) -> tuple[float, float]:
        """The values a geom carries: ends with equal surfaces share a contact class."""
        return (self.restitution, self.friction)


def _ends(scenario: Scenario) -> list[_End]:
    """The bodies that take part in contacts (``collides``), then the ground."""
    colliding = [b for b in scenario.bodies if b.collides]
    ends = [
        _End(i, b.name, _geom_name(b.name), b.restitution, b.friction, b.fixed)
        for i, b in enumerate(colliding)
    ]
    if scenario.ground is not None:
        ground = scenario.ground
        ends.append(
            _End(len(ends), GROUND, GROUND, ground.restitution, ground.friction, fixed=True)
        )
    return ends


def _overrides(scenario: Scenario) -> dict[frozenset, object]:
    """``scenario.pairs`` by their two names, those with a body that collides with nothing
    left out."""
    apart = {b.name for b in scenario.bodies if not b.collides}
    return {frozenset((p.a, p.b)): p for p in scenario.pairs if not {p.a, p.b} & apart}


def _pair(a: _End, b: _End, override) -> ContactPair:
    """The scene's pair of ends ``a`` (the earlier) and ``b``: restitution = max of the two,
    friction = geometric mean, unless ``scenario.pairs`` overrides a value (the mini_engine
    defaults ``restitution_mix=max``, ``friction_mix=geometric_mean``)."""
    e = pair_rule("restitution", a.restitution, b.restitution, override and override.restitution)
    mu = pair_rule("friction", a.friction, b.friction, override and override.friction)
    return ContactPair(a.geom, b.geom, e, mu)


def contact_pairs(scenario: Scenario) -> list[ContactPair]:
    """Every pair that can touch: each body with every later body and with the ground,
    skipping pairs of two fixed bodies (N² of them: for inspection and small scenes; the
    MJCF writes only ``ContactPlan.pairs``)."""
    overrides = _overrides(scenario)
    return [
        _pair(a, b, overrides.get(frozenset((a.name, b.name))))
        for a, b in combinations(_ends(scenario), 2)
        if not (a.fixed and b.fixed)
    ]


def _damper_contact(e: float, dt: float) -> dict[str, tuple[float, ...]]:
    """engines.md 1.7: damping b = (1+e)/dt reverses the normal velocity in one step
    (v+ = (1 - b dt) v- = -e v-); friction rows stay soft (``DAMPER_FRICTION_SOLREF``)."""
    return {
        "solref": (0.0, -(1.0 + e) / dt),
        "solreffriction": DAMPER_FRICTION_SOLREF,
        "solimp": DAMPER_SOLIMP,
    }


def _soft_contact(e: float, dt: float) -> dict[str, tuple[float, ...]]:
    """MuJoCo's default soft contact, whatever e (engines.md 1.2)."""
    return {"solref": SOFT_SOLREF, "solimp": SOFT_SOLIMP}


RESTITUTION_MODELS: dict[str, Callable[[float, float], dict[str, tuple[float, ...]]]] = {
    "damper": _damper_contact,
    "soft": _soft_contact,
}
"""Spec ``restitution`` -> the pair's solver attributes, from (e, dt s)."""


def _condim(friction: float) -> int:
    return FRICTIONAL_CONDIM if friction > 0.0 else FRICTIONLESS_CONDIM


def _pair_attributes(pair: ContactPair, restitution: str, dt: float) -> dict[str, str]:
    attributes = {"geom1": pair.geom_a, "geom2": pair.geom_b, "condim": str(_condim(pair.friction))}
    if pair.friction > 0.0:
        attributes["friction"] = _fmt((pair.friction, pair.friction, *FRICTION_RATIOS))
    model = RESTITUTION_MODELS[restitution](pair.restitution, dt)
    attributes.update({name: _fmt(values) for name, values in model.items()})
    return attributes


# --- what a contact gets: an explicit pair's values, or MuJoCo's mix of two geoms' --------

NO_SOLREF = (0.0, 0.0)
"""A contact's ``solreffriction`` when none is set: its friction rows then use ``solref``
(engine_collision_driver.c: contacts between geoms always get (0, 0))."""

SOLMIX = 1.0
"""Every geom's ``solmix`` (MuJoCo's default): two geoms of one priority weigh ½ each."""

GEOM_FRICTION_RATIOS = (0.0, 0.0)
"""Torsional and rolling friction of a geom: unused by condim 1 and 3, written as 0."""


@dataclass(frozen=True)
class ContactValues:
    """What MuJoCo's solver uses for one contact (``mjContact``): the values that decide
    whether a pair needs its own ``<pair>`` or two geoms' values mix into the same.

    ``friction`` and ``solreffriction`` are None under condim 1 (no friction rows: MuJoCo
    reads neither); ``solreffriction`` is the effective one (``solref`` where unset)."""

    condim: int
    solref: tuple[float, ...]
    solimp: tuple[float, ...]
    friction: tuple[float, ...] | None
    solreffriction: tuple[float, ...] | None


def _values(condim, solref, solimp, friction, solreffriction) -> ContactValues:
    solref = tuple(float(v) for v in solref)
    if condim == FRICTIONLESS_CONDIM:
        return ContactValues(condim, solref, tuple(solimp), None, None)
    own = tuple(float(v) for v in solreffriction)
    return ContactValues(
        condim, solref, tuple(solimp), tuple(friction), solref if own == NO_SOLREF else own
    )


def pair_values(pair: ContactPair, restitution: str, dt: float) -> ContactValues:
    """The contact an explicit ``<pair>`` (``_pair_attributes``) gives."""
    model = RESTITUTION_MODELS[restitution](pair.restitution, dt)
    mu = pair.friction
    return _values(
        _condim(mu),
        model["solref"],
        model["solimp"],
        (mu, mu, *FRICTION_RATIOS),
        model.get("solreffriction", NO_SOLREF),
    )


@dataclass(frozen=True)
class GeomSurface:
    """A geom's contact attributes (``condim``, ``friction``, ``solref``, ``solimp``;
    priority 0 and ``solmix`` 1 on every geom)."""

    condim: int
    friction: tuple[float, float, float]
    solref: tuple[float, ...]
    solimp: tuple[float, ...]

    def attributes(self) -> dict[str, str]:
        return {
            "condim": str(self.condim),
            "friction": _fmt(self.friction),
            "solref": _fmt(self.solref),
            "solimp": _fmt(self.solimp),
        }


def geom_surface(end: _End, restitution: str, dt: float) -> GeomSurface:
    """The geom values of an end: its own e and μ as if it met itself."""
    model = RESTITUTION_MODELS[restitution](end.restitution, dt)
    return GeomSurface(
        _condim(end.friction),
        (end.friction, *GEOM_FRICTION_RATIOS),
        tuple(model["solref"]),
        tuple(model["solimp"]),
    )


def mixed_values(a: GeomSurface, b: GeomSurface) -> ContactValues:
    """MuJoCo's mix of two geoms of one priority (modeling.rst "Contact parameters";
    ``mj_contactParam`` in engine_collision_driver.c): condim max; friction element-wise
    max (3 -> 5 by repeating sliding and rolling); solref solmix-weighted mean when both are
    in the (timeconst, dampratio) format, else element-wise min (the damper's direct
    (0, -b) format: the larger damping, so the larger e, which is the scene's max rule);
    solimp solmix-weighted mean; no solreffriction."""
    mix = SOLMIX / (SOLMIX + SOLMIX)
    if a.solref[0] > 0 and b.solref[0] > 0:
        solref = tuple(mix * x + (1 - mix) * y for x, y in zip(a.solref, b.solref, strict=True))
    else:
        solref = tuple(min(x, y) for x, y in zip(a.solref, b.solref, strict=True))
    solimp = tuple(mix * x + (1 - mix) * y for x, y in zip(a.solimp, b.solimp, strict=True))
    slide, torsion, roll = (max(x, y) for x, y in zip(a.friction, b.friction, strict=True))
    return _values(
        max(a.condim, b.condim), solref, solimp, (slide, slide, torsion, roll, roll), NO_SOLREF
    )


# --- the contact plan: classes of equal surfaces, bitmasks, the pairs left explicit -------

COLLISION_BITS = 31
"""Bits of ``contype``/``conaffinity`` used (MuJoCo's are C ints: the sign bit is left out)."""

ALL_BITS = (1 << COLLISION_BITS) - 1

SHARED_BIT = 1
"""The bit of every class that mixes right with every class: it collides with everything."""


@dataclass(frozen=True)
class ContactPlan:
    """What a profile does about contacts.

    Attributes:
        pairs: explicit pairs: only those whose values geom mixing cannot give (empty
            under ``defaults``).
        geoms: geom name -> its contact attributes (``contype``/``conaffinity``,
            ``condim``, ``friction``, ``solref``, ``solimp``).
        excludes: (body, body) pairs whose dynamic contact is off (an explicit pair replaces it).
        disable_contact: set MuJoCo's contact disable flag (nothing can touch).
        touching_bodies: how many moving bodies can touch something (for ``solver=auto``).
        touching_pairs: pairs that can touch (explicit or by geom mixing).
        frictional: some pair that can touch has friction.
        classes: contact classes (geoms of equal values).
    """

    pairs: list[ContactPair]
    geoms: dict[str, dict[str, str]]
    excludes: list[tuple[str, str]]
    disable_contact: bool
    touching_bodies: int
    touching_pairs: int = 0
    frictional: bool = False
    classes: int = 0


def _class_bits(compatible: dict[tuple, set], keys: list) -> dict[tuple, tuple[int, int]] | None:
    """(contype, conaffinity) per class so that two classes' geoms collide exactly when they
    are ``compatible``: one shared bit for the classes compatible with every class, an own
    bit for each other class, whose conaffinity holds the bits of the classes it may meet;
    None when more than ``COLLISION_BITS`` bits would be needed."""
    universal = [k for k in keys if compatible[k] == set(keys)]
    others = [k for k in keys if k not in universal]
    if len(others) > COLLISION_BITS - 1:
        return None
    bit = dict.fromkeys(universal, SHARED_BIT)
    bit.update({k: 1 << (i + 1) for i, k in enumerate(others)})
    masks = dict.fromkeys(universal, (SHARED_BIT, ALL_BITS))
    for k in others:
        affinity = 0
        for other in compatible[k]:
            affinity |= bit[other]
        masks[k] = (bit[k], affinity)
    return masks


def _matched_contacts(scenario: Scenario, restitution: str) -> ContactPlan:
    """The scene's contact values with as few explicit pairs as possible.

    Ends (bodies and the ground) with equal (e, μ) form a class and their geoms carry those
    values. For each pair of classes, if MuJoCo's mix of the two geoms (``mixed_values``)
    equals the explicit pair the scene asks for (``pair_values``), MuJoCo's own collision
    (its broadphase, no pair list) makes those contacts; otherwise bitmasks keep the two
    classes apart and every pair of them is written explicitly. A ``scenario.pairs``
    override that the mix does not give is an explicit pair whose bodies' dynamic contact
    is excluded. Two fixed ends never touch: MuJoCo never collides geoms welded to the world
    (``filterBodyPair``: same weld body, or both without dofs), and no pair is written.
    """
    dt = scenario.dt
    ends = _ends(scenario)
    groups: dict[tuple, list[_End]] = {}
    for end in ends:
        groups.setdefault(end.surface, []).append(end)
    keys = list(groups)
    surfaces = {k: geom_surface(groups[k][0], restitution, dt) for k in keys}

    overrides = _overrides(scenario)
    by_name = {end.name: end for end in ends}
    overridden: dict[frozenset, int] = {}  # class pair -> its pairs that scenario.pairs sets
    for names in overrides:
        a, b = (by_name[n] for n in names)
        if not (a.fixed and b.fixed):
            classes = frozenset((a.surface, b.surface))
            overridden[classes] = overridden.get(classes, 0) + 1
    moving = {k: sum(not e.fixed for e in groups[k]) for k in keys}
    compatible: dict[tuple, set] = {k: set() for k in keys}
    touching_pairs, frictional = 0, False
    for i, ka in enumerate(keys):
        for kb in keys[i:]:
            a, b = groups[ka], groups[kb]
            wanted = pair_values(_pair(a[0], b[0], None), restitution, dt)
            if wanted == mixed_values(surfaces[ka], surfaces[kb]):
                compatible[ka].add(kb)
                compatible[kb].add(ka)
            moving_a, moving_b = moving[ka], moving[kb]
            if ka == kb:
                count = moving_a * (moving_a - 1) // 2 + moving_a * (len(a) - moving_a)
            else:
                count = len(a) * len(b) - (len(a) - moving_a) * (len(b) - moving_b)
            touching_pairs += count
            ruled = count - overridden.get(frozenset((ka, kb)), 0)  # pairs the mixing rule sets
            frictional |= ruled > 0 and wanted.friction is not None
    masks = _class_bits(compatible, keys)
    if masks is None:  # too many classes for the bits: every class pair explicit
        compatible = {k: set() for k in keys}
        masks = dict.fromkeys(keys, (0, 0))
    by_surface = {
        k: {
            **surfaces[k].attributes(),
            "contype": str(masks[k][0]),
            "conaffinity": str(masks[k][1]),
        }
        for k in keys
    }
    geoms = {end.geom: by_surface[end.surface] for end in ends}

    explicit: list[tuple[int, int]] = []  # (a, b) end indices, a < b
    for i, ka in enumerate(keys):
        for kb in keys[i:]:
            if kb in compatible[ka] or not (moving[ka] or moving[kb]):
                continue
            for a in groups[ka]:
                for b in groups[kb]:
                    if a.index < b.index and not (a.fixed and b.fixed):
                        explicit.append((a.index, b.index))
                    elif ka != kb and b.index < a.index and not (a.fixed and b.fixed):
                        explicit.append((b.index, a.index))
    excludes: list[tuple[str, str]] = []
    written = set(explicit)
    for names, override in overrides.items():
        a, b = sorted((by_name[n] for n in names), key=lambda end: end.index)
        if a.fixed and b.fixed:
            continue
        wanted = pair_values(_pair(a, b, override), restitution, dt)
        frictional |= wanted.friction is not None
        if (a.index, b.index) in written:
            continue  # its class pair is explicit already, with the override's values
        if wanted != mixed_values(surfaces[a.surface], surfaces[b.surface]):
            explicit.append((a.index, b.index))
            excludes.append(tuple(WORLD_BODY if e.name == GROUND else e.name for e in (a, b)))
    explicit.sort()
    pairs = [
        _pair(ends[a], ends[b], overrides.get(frozenset((ends[a].name, ends[b].name))))
        for a, b in explicit
    ]
    return ContactPlan(
        pairs,
        geoms,
        excludes,
        disable_contact=touching_pairs == 0,
        touching_bodies=sum(not e.fixed for e in ends) if len(ends) > 1 else 0,
        touching_pairs=touching_pairs,
        frictional=frictional,
        classes=len(keys),
    )


def _default_contacts(scenario: Scenario, restitution: str) -> ContactPlan:
    """MuJoCo's default geoms: every geom collides with every other (condim 3, μ = 1)."""
    moving = sum(not b.fixed and b.collides for b in scenario.bodies)
    return ContactPlan([], {}, [], disable_contact=False, touching_bodies=moving)


NO_CONTACT = {"contype": "0", "conaffinity": "0"}
"""A geom MuJoCo collides with nothing (neither bit set, neither side of any pair)."""


def _kept_apart(plan: ContactPlan, scenario: Scenario) -> ContactPlan:
    """``plan`` with the geom of every body with ``collides: false`` colliding with nothing."""
    apart = {_geom_name(b.name): NO_CONTACT for b in scenario.bodies if not b.collides}
    if not apart:
        return plan
    return replace(plan, geoms={**plan.geoms, **apart})


PROFILES: dict[str, Callable[[Scenario, str], ContactPlan]] = {
    "matched": _matched_contacts,
    "defaults": _default_contacts,
}
"""Spec ``profile`` -> its contact plan, from the scene and the spec's ``restitution``."""


def contact_note(plan: ContactPlan, model) -> str:
    """How the contacts were written, for the provenance."""
    return (
        f"contacts: {plan.touching_pairs} pairs can touch, {len(plan.pairs)} written as "
        f"explicit <pair> (values geom mixing cannot give), the rest by MuJoCo's mixing of "
        f"{plan.classes} geom classes; {len(plan.excludes)} <exclude>; arena "
        f"{model.narena} bytes"
    )


def arena_bytes(scenario: Scenario, plan: ContactPlan, solver: str) -> int:
    """``<size memory>`` from the scene: the broadphase's body-pair lists, room for
    ``CONTACTS_PER_BODY`` contacts per moving body, Newton's dense matrices, at least
    ``ARENA_FLOOR`` (MuJoCo's own guess grows as nv², 6.4 GB for 2,000 free bodies, and
    cannot be allocated for 10,000). A scene that outgrows it is told, not silently cut:
    MuJoCo raises mjWARN_CONTACTFULL / mjWARN_CNSTRFULL, which make the run unstable."""
    bodies = len(scenario.bodies) + 1  # and the world
    moving = sum(not b.fixed for b in scenario.bodies)
    dofs = 6 * moving
    needed = BROADPHASE_BYTES_PER_BODY_PAIR * bodies * (bodies - 1) // 2
    if not plan.disable_contact:
        needed += CONTACT_BYTES * CONTACTS_PER_BODY * moving
    if solver == "Newton":
        needed += NEWTON_BYTES_PER_DOF_SQUARED * dofs * dofs
    return max(ARENA_FLOOR, needed)


ARENA_PROFILES = {"matched": True, "defaults": False}
"""Spec ``profile`` -> whether the arena is sized from the scene (``defaults`` keeps MuJoCo's
own guess: what a new user gets)."""


def choose_solver(setting: str, profile: str, touching_bodies: int) -> str:
    """MJCF solver name. ``auto``: CG above ``CG_BODY_THRESHOLD`` bodies that can touch,
    Newton otherwise; under ``profile=defaults`` always Newton (what a new user gets)."""
    if setting != "auto":
        return setting
    if profile == "matched" and touching_bodies > CG_BODY_THRESHOLD:
        return "CG"
    return "Newton"


def choose_cone(setting: str, settings: dict[str, object], frictional: bool) -> str:
    """MJCF cone. Unset: elliptic when a damper pair has friction (its friction rows are
    then separate from the normal row and can stay soft, ``DAMPER_FRICTION_SOLREF``),
    else pyramidal, MuJoCo's default (engines.md 1.2)."""
    if setting != "auto":
        return setting
    return "elliptic" if frictional and settings["restitution"] == "damper" else "pyramidal"


MUJOCO_JOINT_TYPES = {"hinge": "hinge", "slider": "slide", "ball": "ball"}
"""The scene's joint types as MJCF's ``<joint type>``; a fixed joint is a body nested in its
parent with no joint (welded)."""

JOINT_WORDS = {3: "hinge", 2: "slider", 1: "ball", 0: "free"}
"""MuJoCo's ``mjtJoint`` codes (mjJNT_HINGE 3, mjJNT_SLIDE 2, mjJNT_BALL 1, mjJNT_FREE 0) in
the scene's words: what the parity gate reads back."""


def _add_body(
    parent: ET.Element,
    body: BodySpec,
    geom: dict[str, str],
    pose: tuple[np.ndarray, np.ndarray] | None = None,
    joint: dict[str, str] | None = None,
) -> ET.Element:
    """``body`` as a ``<body>`` of ``parent``: at its world pose with a free joint (unless
    fixed), or at ``pose`` (position, quaternion relative to the parent body) with ``joint``
    (the attributes of its ``<joint>``, None for a weld)."""
    pos, quat = (body.position, body.orientation) if pose is None else pose
    element = ET.SubElement(parent, "body", name=body.name, pos=_fmt(pos), quat=_fmt(quat))
    if pose is None and not body.fixed:
        ET.SubElement(element, "freejoint", name=f"{body.name}/free")
    if joint is not None:
        ET.SubElement(element, "joint", joint)
    ET.SubElement(element, "inertial", _inertial_attributes(body))
    ET.SubElement(
        element,
        "geom",
        name=_geom_name(body.name),
        type=body.shape.type,
        size=_fmt(GEOM_SIZES[body.shape.type](body.shape)),
        **_placement(body.shape),
        **geom,
    )
    return element


def _add_bodies(world: ET.Element, scenario: Scenario, tree, plan) -> dict[str, ET.Element]:
    """Every scene body: the roots (no joint's child) in the world body at their world poses,
    then each jointed child nested in its parent, parents first (the joint tree's order:
    ``CompiledScene.joint_tree``), at its pose relative to the parent and with its joint."""
    children = set() if tree is None else {j.child for j in tree.joints if j.type != "free"}
    elements: dict[str, ET.Element] = {}
    for k, body in enumerate(scenario.bodies):
        if k not in children:
            elements[body.name] = _add_body(world, body, plan.geoms.get(_geom_name(body.name), {}))
    for joint in () if tree is None else tree.joints:
        if joint.type == "free":
            continue
        body = scenario.bodies[joint.child]
        parent = world if joint.parent < 0 else elements[scenario.bodies[joint.parent].name]
        pose = (joint.anchor + joint.offset, matrix_to_quat(joint.rotation))
        geom = plan.geoms.get(_geom_name(body.name), {})
        elements[body.name] = _add_body(
            parent, body, geom, pose, _joint_attributes(scenario, joint)
        )
    return elements


def _joint_attributes(scenario: Scenario, joint) -> dict[str, str] | None:
    """The ``<joint>`` of a tree joint, in the child's frame (MJCF's convention): the anchor
    ``-R0ᵀ r0`` from the child's centre, the axis ``R0ᵀ u``; damping, limits as ``range``."""
    if joint.type == "fixed":
        return None
    stated = next(j for j in scenario.joints if j.name == joint.name)
    attributes = {
        "name": joint.name,
        "type": MUJOCO_JOINT_TYPES[joint.type],
        "pos": _fmt(-joint.rotation.T @ joint.offset),
        "damping": repr(float(joint.damping)),
    }
    if joint.type != "ball":
        attributes["axis"] = _fmt(joint.rotation.T @ joint.axis)
    if stated.limits is not None:
        attributes.update(limited="true", range=_fmt(stated.limits))
    return attributes


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


def build_mjcf(
    scenario: Scenario, settings: dict[str, object], tree=None
) -> tuple[str, ContactPlan, str]:
    """(MJCF text, contact plan, solver name) of ``scenario`` under the full ``settings``,
    its bodies nested by the joint ``tree`` (``CompiledScene.joint_tree``; None: no joints)."""
    profile = str(settings["profile"])
    plan = _kept_apart(PROFILES[profile](scenario, str(settings["restitution"])), scenario)
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
        cone=choose_cone(str(settings["cone"]), settings, plan.frictional),
        iterations=str(int(settings["iterations"])),
    )
    unused = {"contact": plan.disable_contact, "gravity": not any(scenario.gravity)}
    if any(unused.values()):  # pay only for what the scene uses
        ET.SubElement(option, "flag", **{name: "disable" for name, off in unused.items() if off})
    if ARENA_PROFILES[profile]:
        ET.SubElement(root, "size", memory=str(arena_bytes(scenario, plan, solver)))
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
            **plan.geoms.get(GROUND, {}),
        )
    bodies = _add_bodies(world, scenario, tree, plan)
    _add_springs(root, world, bodies, scenario)
    if plan.pairs or plan.excludes:
        contact = ET.SubElement(root, "contact")
        for pair in plan.pairs:
            ET.SubElement(
                contact, "pair", _pair_attributes(pair, str(settings["restitution"]), scenario.dt)
            )
        for body_a, body_b in plan.excludes:
            ET.SubElement(contact, "exclude", body1=body_a, body2=body_b)
    return ET.tostring(root, encoding="unicode"), plan, solver
