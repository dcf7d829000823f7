"""MuJoCo at scale: the matched profile's contacts in O(N).

- a 2,000-sphere scene's MJCF holds no explicit pair (each pair's values come from MuJoCo's
  mixing of the two geoms'), passes the parity gate, and is built and compiled quickly;
- the mixing is a faithful stand-in: a scene of every kind of contact class (restitutions,
  frictions, a fixed body, the ground, pair overrides, values mixing cannot give) steps
  bit for bit as with one explicit pair per pair (the profile before contacts were filtered in O(N)), under both
  restitution models;
- two fixed bodies never touch (MuJoCo never collides geoms welded to the world).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from validation.engines.mujoco import mjcf
from validation.engines.parity import compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

GRID_SPHERES = 2_000

MATCHED = mjcf.PROFILES["matched"]

MINIMUM_FRICTION = mujoco.mjMINMU
"""MuJoCo's mjMINMU: the least friction coefficient a contact gets (pairs and geoms alike)."""


def sphere_grid(count: int, friction: float = 0.0) -> Scenario:
    """``count`` spheres in 4 layers 1 cm apart above the ground (benchmarks/scale.py's scene)."""
    side = math.ceil(math.sqrt(count / 4))
    bodies = []
    for k in range(count):
        layer, rest = divmod(k, side * side)
        i, j = divmod(rest, side)
        bodies.append(
            {
                "name": f"s{k}",
                "shape": {"type": "sphere", "radius": 0.05},
                "mass": 1.0,
                "position": [i * 0.11, j * 0.11, 0.1 + layer * 0.11],
                "restitution": 0.5,
                "friction": friction,
            }
        )
    return Scenario.model_validate(
        {
            "name": f"grid{count}",
            "dt": 2e-3,
            "duration": 0.3,
            "ground": {"restitution": 0.5, "friction": friction},
            "engines": ["mujoco"],
            "bodies": bodies,
        }
    )


def load(scenario: Scenario, spec: str = "mujoco"):
    adapter = create_adapter(parse_engine_spec(spec))
    adapter.load(compile_scene(scenario))
    return adapter


def test_a_2000_sphere_scene_has_no_explicit_pairs_and_passes_the_parity_gate():
    scenario = sphere_grid(GRID_SPHERES)
    xml, plan, solver = mjcf.build_mjcf(scenario, dict(mjcf.DEFAULT_SETTINGS))
    root = ET.fromstring(xml)
    n = GRID_SPHERES
    assert plan.touching_pairs == n * (n - 1) // 2 + n  # every pair can touch ...
    assert len(root.findall("contact/pair")) == 0  # ... and none is written out
    assert len(plan.pairs) == 0 and plan.excludes == []
    geoms = root.findall("worldbody/body/geom") + root.findall("worldbody/geom")
    assert len(geoms) == n + 1
    assert {(g.get("contype"), g.get("conaffinity")) for g in geoms} == {
        (str(mjcf.SHARED_BIT), str(mjcf.ALL_BITS))
    }
    assert len(xml) < 1_000 * n, len(xml)  # linear: about 400 bytes a body
    memory = int(root.find("size").get("memory"))
    assert memory == mjcf.arena_bytes(scenario, plan, solver) < 2**30, memory
    adapter = load(scenario)
    assert adapter.model.npair == 0 and adapter.model.narena == memory
    mismatches = compare(adapter.model_report(), reference_report(adapter.scene))
    assert mismatches == [], [str(m) for m in mismatches[:3]]
    adapter.advance(60)  # the lowest layer lands (t = 0.10 s): 500 ground contacts at least
    assert adapter.data.ncon >= 500, adapter.data.ncon
    assert adapter.instability_warnings() == []
    adapter.close()


def mixed_scene() -> dict:
    """Every kind of contact class, all touching or about to: two restitutions, frictionless
    and two frictions (0.4 mixes like the ground's 0.4; 0.3 with 0.4 does not: geometric mean
    against MuJoCo's max), two fixed boxes, overrides that the mix gives and that it does not;
    under the damper a frictional pair is always explicit (geom contacts have no
    solreffriction), so g-h and i-j make frictionless contacts of two restitutions."""

    def ball(name, x, y, z, e, mu, **extra):
        return {
            "name": name,
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "position": [x, y, z],
            "velocity": [0.3, -0.2, -1.0],
            "restitution": e,
            "friction": mu,
            **extra,
        }

    return {
        "name": "mixed",
        "dt": 1e-3,
        "duration": 0.5,
        "ground": {"restitution": 0.2, "friction": 0.4},
        "engines": ["mujoco"],
        "bodies": [
            ball("a", 0.0, 0.0, 0.11, 0.2, 0.4),
            ball("b", 0.19, 0.0, 0.11, 0.7, 0.4),
            ball("c", 0.0, 0.19, 0.11, 0.2, 0.3),
            ball("d", 0.19, 0.19, 0.11, 0.7, 0.0),
            ball("e", 0.0, 0.0, 0.31, 0.2, 0.4),
            ball("f", 0.1, 0.1, 0.31, 0.7, 0.0),
            ball("g", -0.4, 0.0, 0.11, 0.2, 0.0),  # lands, bounces into h: e 0.2 meets 0.7
            ball("h", -0.4, 0.0, 0.32, 0.7, 0.0),
            ball("i", -0.8, 0.0, 0.11, 0.2, 0.0),  # the same, without an override
            ball("j", -0.8, 0.0, 0.32, 0.7, 0.0),
            {
                "name": "wall",
                "shape": {"type": "box", "half_extents": [0.05, 0.5, 0.5]},
                "mass": 1.0,
                "position": [0.34, 0.0, 0.5],
                "fixed": True,
                "restitution": 0.2,
                "friction": 0.4,
            },
            {
                "name": "post",
                "shape": {"type": "box", "half_extents": [0.05, 0.05, 0.5]},
                "mass": 1.0,
                "position": [0.34, 0.0, 0.5],
                "fixed": True,
                "friction": 0.3,
            },
        ],
        "pairs": [
            {"a": "a", "b": "ground", "restitution": 0.9},  # the mix gives 0.2: explicit
            {"a": "e", "b": "a", "restitution": 0.2},  # the mix gives it: nothing written
            {"a": "b", "b": "d", "friction": 0.2},  # a class pair explicit anyway
            {"a": "g", "b": "h", "restitution": 0.9},  # the mix gives 0.7: pair and exclude
        ],
    }


def every_pair_explicit(scenario: Scenario, restitution: str) -> mjcf.ContactPlan:
    """The matched profile as it was before the O(N) contact filter: one ``<pair>`` per pair that can touch, geoms
    that collide with nothing."""
    pairs = mjcf.contact_pairs(scenario)
    geom = {"contype": "0", "conaffinity": "0", "condim": str(mjcf.FRICTIONLESS_CONDIM)}
    names = [mjcf.GROUND] + [f"{b.name}/geom" for b in scenario.bodies]
    plan = MATCHED(scenario, restitution)
    return mjcf.ContactPlan(
        pairs,
        dict.fromkeys(names, geom),
        [],
        disable_contact=not pairs,
        touching_bodies=plan.touching_bodies,
        touching_pairs=len(pairs),
        frictional=any(p.friction > 0 for p in pairs),
    )


def trajectory(scenario: Scenario, spec: str, steps: int) -> tuple[np.ndarray, int, int]:
    adapter = load(scenario, spec)
    assert compare(adapter.model_report(), reference_report(adapter.scene)) == []
    states, most = [], 0
    for _ in range(steps):
        adapter.advance(1)
        most = max(most, adapter.data.ncon)
        states.append(np.concatenate([adapter.data.qpos, adapter.data.qvel]))
    npair = adapter.model.npair
    adapter.close()
    return np.array(states), most, npair


@pytest.mark.parametrize("restitution", ["damper", "soft"])
def test_geom_mixing_steps_bit_for_bit_as_one_explicit_pair_per_pair(monkeypatch, restitution):
    scenario = Scenario.model_validate(mixed_scene())
    spec = f"mujoco(restitution={restitution})"
    mixed, contacts, npair = trajectory(scenario, spec, 300)
    plan = mjcf.PROFILES["matched"](scenario, restitution)
    assert contacts >= 6, contacts  # the scene does collide
    every = len(mjcf.contact_pairs(scenario))
    assert 0 < npair == len(plan.pairs) < every, (npair, every)
    if restitution == "damper":  # g-h mix right, but for their override
        assert plan.excludes == [("g", "h")], plan.excludes
    monkeypatch.setitem(mjcf.PROFILES, "matched", every_pair_explicit)
    explicit, contacts_before, npair_before = trajectory(scenario, spec, 300)
    assert npair_before == every
    assert contacts_before == contacts
    assert np.array_equal(mixed, explicit), np.abs(mixed - explicit).max()


@pytest.mark.parametrize("restitution", ["damper", "soft"])
def test_mixed_values_are_what_mujoco_puts_in_its_contacts(restitution):
    """``mixed_values`` against the contacts MuJoCo makes between geoms of two classes."""
    scenario = Scenario.model_validate(mixed_scene())
    adapter = load(scenario, f"mujoco(restitution={restitution})")
    checked = 0
    for _ in range(40):
        adapter.advance(5)
        checked += mixed_contacts_checked(scenario, adapter, restitution)
    assert checked >= 20, checked
    adapter.close()


def mixed_contacts_checked(scenario: Scenario, adapter, restitution: str) -> int:
    """How many of the current contacts are mixed from two geoms (each checked)."""
    m, d = adapter.model, adapter.data
    plan = adapter.plan
    explicit = {frozenset((p.geom_a, p.geom_b)) for p in plan.pairs}
    checked = 0
    for contact in d.contact[: d.ncon]:
        names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) for g in contact.geom]
        if frozenset(names) in explicit:
            continue
        ends = {e.geom: e for e in mjcf._ends(scenario)}
        a, b = (mjcf.geom_surface(ends[name], restitution, scenario.dt) for name in names)
        want = mjcf.mixed_values(a, b)
        assert contact.dim == want.condim, names
        assert tuple(contact.solref) == want.solref, names
        assert tuple(contact.solimp) == want.solimp, names
        if want.friction is not None:  # mj_setContact raises every coefficient to mjMINMU
            floored = tuple(max(MINIMUM_FRICTION, mu) for mu in want.friction)
            assert tuple(contact.friction) == floored, names
        checked += 1
    return checked


def test_two_fixed_bodies_never_touch():
    """Overlapping fixed boxes on the ground: no pair is written for them and MuJoCo makes
    no contact between them (both are welded to the world)."""
    scenario = Scenario.model_validate(mixed_scene())
    adapter = load(scenario)
    mujoco.mj_forward(adapter.model, adapter.data)
    fixed = {adapter.body_ids[10], adapter.body_ids[11], 0}
    bodies = adapter.model.geom_bodyid
    for contact in adapter.data.contact[: adapter.data.ncon]:
        assert not {bodies[g] for g in contact.geom} <= fixed, contact.geom
    written = {frozenset((p.geom_a, p.geom_b)) for p in adapter.plan.pairs}
    assert frozenset(("wall/geom", "post/geom")) not in written
    assert frozenset(("post/geom", mjcf.GROUND)) not in written
    adapter.close()


def test_too_many_classes_for_the_bits_fall_back_to_explicit_pairs():
    """More classes that do not mix right than there are bits: every pair explicit, geoms
    that collide with nothing (correct, only not O(N))."""
    bodies = [
        {
            "name": f"b{k}",
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "position": [0.3 * k, 0.0, 0.5],
            "friction": 0.01 * (k + 1),
        }
        for k in range(mjcf.COLLISION_BITS + 2)
    ]
    scenario = Scenario.model_validate(
        {"name": "many", "dt": 1e-3, "duration": 0.01, "ground": {}, "bodies": bodies}
    )
    plan = mjcf.PROFILES["matched"](scenario, "damper")
    assert len(plan.pairs) == len(mjcf.contact_pairs(scenario)) == plan.touching_pairs
    assert {(g["contype"], g["conaffinity"]) for g in plan.geoms.values()} == {("0", "0")}
