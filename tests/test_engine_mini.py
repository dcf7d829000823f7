"""The mini adapter and the parity gate (the same gate the MuJoCo and PyBullet adapters pass)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from validation.cli import BUNDLED_SCENARIOS
from validation.engine_api import declaration_of
from validation.engines.parity import PARITY_TOLERANCE, compare
from validation.engines.reference import reference_report
from validation.engines.registry import create_adapter
from validation.scenario import Scenario, load_scenario, scenario_files
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.needs import missing
from validation.scenario.urdf import expand_models

ROTATED_OFFSET_SPINNING = {
    "dt": 0.001,
    "duration": 0.01,
    "gravity": [0, 0, 0],
    "ground": {"restitution": 0.5},
    "bodies": [
        {
            "name": "box",
            "shape": {"type": "box", "half_extents": [0.1, 0.2, 0.3]},
            "mass": 2.0,
            "inertia": [[0.3, 0.02, 0.0], [0.02, 0.25, 0.0], [0.0, 0.0, 0.1]],
            "position": [1.0, -2.0, 3.0],
            "orientation": [0.8775826, 0.4794255, 0.0, 0.0],
            "velocity": [0.5, -0.25, 1.0],
            "angular_velocity": [1.0, 2.0, -3.0],
        },
        {
            "name": "post",
            "shape": {"type": "sphere", "radius": 0.1},
            "mass": 1.0,
            "fixed": True,
            "position": [5, 5, 5],
        },
    ],
}


def scenario_from(data: dict) -> Scenario:
    return Scenario.model_validate({"name": "test", **data})


def test_snapshot_is_the_scenario_state_in_scenario_order_without_the_ground():
    scenario = scenario_from(ROTATED_OFFSET_SPINNING)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    snap = adapter.observe()
    box = scenario.bodies[0]
    assert snap.pos.shape == (2, 3), "the ground must not be a body of the snapshot"
    assert np.allclose(snap.pos[0], box.position) and np.allclose(snap.quat[0], box.orientation)
    assert np.allclose(snap.vel[0], box.velocity) and np.allclose(
        snap.ang_vel[0], box.angular_velocity
    )
    adapter.advance(1)
    moved = adapter.observe().pos[0] - np.asarray(box.position)
    assert np.allclose(moved, np.asarray(box.velocity) * scenario.dt, atol=1e-15), moved


# --- an independent reference: textbook closed forms from the scenario YAML alone ---------

REFERENCE_TOLERANCE = 1e-9
"""Relative, the parity gate's own (``PARITY_TOLERANCE``). The closed forms below and the
engine both evaluate a few dozen double-precision operations per value (round-off ~1e-15
relative); anything beyond 1e-9 is a different formula, not round-off."""

ABSOLUTE_FLOOR = 1e-12
"""In the quantity's SI unit: the scale below which a difference is round-off, for
quantities that are zero in a scene (the momentum of a scene at rest)."""

DEFAULT_GRAVITY = (0.0, 0.0, -9.81)
"""m/s², the scenario format's documented default ``gravity`` (scenarios/README.md)."""

YAML_ROUNDING = 5e-13
"""kg·m²: ``capsule_drop.yaml`` writes its explicit inertia to 12 decimal places
(0.011943181818, 0.001204545455), so within half a unit of the 12th of the exact value."""


class YamlLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader reading ``1.0e6`` as a float (YAML 1.2; YAML 1.1 wants ``1.0e+6``),
    as the scenario format does."""


YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def read_yaml(path) -> dict:
    return yaml.load(path.read_text(), Loader=YamlLoader)


def textbook_inertia(shape: dict, mass: float) -> np.ndarray:
    """(3, 3) kg·m², body frame, about the centre of a uniform solid, from the closed forms."""
    kind = shape["type"]
    if kind == "sphere":
        r = float(shape["radius"])
        return np.eye(3) * 2.0 / 5.0 * mass * r**2  # solid sphere: 2/5 m r²
    if kind == "box":
        a, b, c = (2.0 * float(h) for h in shape["half_extents"])  # full edge lengths
        return np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2]) * mass / 12.0  # m/12 (b² + c²)
    if kind == "capsule":
        return textbook_capsule(float(shape["radius"]), float(shape["half_length"]), mass)
    raise AssertionError(f"no closed form for shape {kind!r}")


def textbook_capsule(r: float, half_length: float, mass: float) -> np.ndarray:
    """Cylinder (length h = 2·half_length) plus two solid hemispheres, mass split by volume.

    Hemisphere of mass m_h: about any diameter of its flat face 2/5 m_h r² (half a sphere);
    its centroid lies 3r/8 from the face, so about its own centroid 2/5 m_h r² - m_h (3r/8)²,
    and the parallel-axis theorem moves that to the capsule centre, h/2 + 3r/8 away.
    """
    h = 2.0 * half_length
    v_cylinder, v_hemisphere = np.pi * r**2 * h, 2.0 / 3.0 * np.pi * r**3
    density = mass / (v_cylinder + 2.0 * v_hemisphere)
    m_c, m_h = density * v_cylinder, density * v_hemisphere
    axial = m_c * r**2 / 2.0 + 2.0 * (2.0 / 5.0 * m_h * r**2)
    hemisphere_centroid = 2.0 / 5.0 * m_h * r**2 - m_h * (3.0 * r / 8.0) ** 2
    shift = h / 2.0 + 3.0 * r / 8.0
    transverse = m_c * (3.0 * r**2 + h**2) / 12.0 + 2.0 * (hemisphere_centroid + m_h * shift**2)
    return np.diag([transverse, transverse, axial])


def rotation(quaternion) -> np.ndarray:
    """Body-to-world matrix of a quaternion w x y z (normalised, as the format says)."""
    w, x, y, z = np.asarray(quaternion, dtype=float) / np.linalg.norm(quaternion)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def vector(body: dict, key: str, default=(0.0, 0.0, 0.0)) -> np.ndarray:
    return np.asarray([float(v) for v in body.get(key, default)])


def textbook_report(data: dict) -> dict[str, np.ndarray]:
    """Mass, COM, world inertia (moving bodies) and the scene's energy and momenta at t = 0,
    from the raw scenario document (defaults as documented: at rest, identity orientation)."""
    gravity = np.asarray([float(g) for g in data.get("gravity", DEFAULT_GRAVITY)])
    bodies = {b["name"]: b for b in data["bodies"]}
    moving = [b for b in data["bodies"] if not b.get("fixed", False)]
    mass = np.array([float(b["mass"]) for b in moving])
    com = np.array([vector(b, "position") for b in moving])
    vel = np.array([vector(b, "velocity") for b in moving])
    omega = np.array([vector(b, "angular_velocity") for b in moving])
    inertia_world = []
    for b in moving:
        body_frame = (
            textbook_inertia(b["shape"], float(b["mass"]))
            if b.get("inertia") is None
            else np.asarray(b["inertia"], dtype=float)
        )
        body_frame = np.diag(body_frame) if body_frame.shape == (3,) else body_frame
        R = rotation(b.get("orientation", (1.0, 0.0, 0.0, 0.0)))
        inertia_world.append(R @ body_frame @ R.T)
    inertia_world = np.array(inertia_world)
    spin = np.einsum("nij,nj->ni", inertia_world, omega)
    kinetic = 0.5 * np.sum(mass * np.sum(vel**2, axis=1)) + 0.5 * np.sum(omega * spin)
    potential = -np.sum(mass * (com @ gravity))

    def anchor(name: str, point) -> np.ndarray:
        point = np.asarray([float(v) for v in point])
        if name == "world":
            return point
        body = bodies[name]
        return vector(body, "position") + rotation(body.get("orientation", (1, 0, 0, 0))) @ point

    elastic = 0.0
    for spring in data.get("springs", []):
        a = anchor(spring["a"], spring.get("anchor_a", (0.0, 0.0, 0.0)))
        b = anchor(spring["b"], spring.get("anchor_b", (0.0, 0.0, 0.0)))
        length = np.linalg.norm(b - a)
        rest = length if spring.get("rest_length") is None else float(spring["rest_length"])
        elastic += 0.5 * float(spring["stiffness"]) * (length - rest) ** 2  # ½ k (L - L0)²
    centre = mass @ com / mass.sum()
    return {
        "mass": mass,
        "com": com,
        "inertia_world": inertia_world,
        "energy": np.array(kinetic + potential + elastic),
        "linear_momentum": mass @ vel,
        "angular_momentum": np.sum(np.cross(com - centre, mass[:, None] * vel) + spin, axis=0),
    }


def differences(engine, expected: dict[str, np.ndarray]) -> list[str]:
    """Every quantity (per body where it has one) beyond ``REFERENCE_TOLERANCE`` relative."""
    found = []
    for quantity, want in expected.items():
        got = np.asarray(getattr(engine, quantity), dtype=float)
        rows = zip(got, want, strict=True) if quantity in PER_BODY else [(got, want)]
        for body, (g, w) in enumerate(rows):
            scale = max(float(np.max(np.abs(w))), ABSOLUTE_FLOOR / REFERENCE_TOLERANCE)
            error = float(np.max(np.abs(g - w))) / scale
            if not error <= REFERENCE_TOLERANCE:
                where = f" body {body}" if quantity in PER_BODY else ""
                found.append(
                    f"{quantity}{where}: mini {np.asarray(g).tolist()}, textbook "
                    f"{np.asarray(w).tolist()} (relative error {error:.3g})"
                )
    return found


PER_BODY = ("mass", "com", "inertia_world")

BUNDLED = [
    path
    for path in scenario_files([BUNDLED_SCENARIOS])
    if not missing(declaration_of("mini").capabilities_of({}), load_scenario(path))
]
"""The library's scenes mini can represent (not ``cylinder_rolls_down_incline``: mini has no
cylinder, its row there is ``unsupported``)."""


def without_explicit_inertia(data: dict) -> dict:
    """The scene with every ``inertia:`` dropped, so each body gets its solid shape's."""
    return {
        **data,
        "bodies": [{k: v for k, v in b.items() if k != "inertia"} for b in data["bodies"]],
    }


@pytest.mark.parametrize("solid", [False, True], ids=["as_written", "solid_shapes"])
@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_mini_model_matches_the_textbook_on_every_bundled_scene(path, solid):
    """mini's model read back (``model_report``) equals closed forms computed here from the
    YAML alone; ``solid_shapes`` drops explicit inertias so every shape formula is exercised."""
    data, _ = expand_models(read_yaml(path), path)  # a model's links as the scene's bodies
    data = {k: v for k, v in data.items() if k != "models"}
    if solid:
        data = without_explicit_inertia(data)
    scenario = Scenario.model_validate({"name": path.stem, **data})
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    found = differences(adapter.model_report(), textbook_report(data))
    assert found == [], found


def test_an_explicit_full_inertia_overrides_the_shape_and_rotates_to_the_world():
    """A full 3x3 ``inertia:`` with products of inertia, on a rotated, offset, spinning box."""
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario_from(ROTATED_OFFSET_SPINNING)))
    found = differences(adapter.model_report(), textbook_report(ROTATED_OFFSET_SPINNING))
    assert found == [], found


def test_capsule_inertia_agrees_with_the_yaml_and_with_mujoco():
    """The textbook capsule (r = 0.05 m, half_length 0.15 m, 1 kg, along z) equals the value
    capsule_drop.yaml writes, mini's solid capsule, and MuJoCo's own: the adapter's MJCF with
    the explicit ``<inertial>`` removed, so MuJoCo computes it from the capsule geom."""
    import mujoco

    from validation.engines.mujoco.mjcf import DEFAULT_SETTINGS, build_mjcf

    path = BUNDLED_SCENARIOS / "contact" / "capsule_drop.yaml"
    data = read_yaml(path)
    capsule = data["bodies"][0]
    expected = textbook_capsule(0.05, 0.15, 1.0)
    assert capsule["shape"] == {"type": "capsule", "radius": 0.05, "half_length": 0.15}
    written = np.asarray(capsule["inertia"], dtype=float)
    assert np.allclose(written, np.diag(expected), rtol=0, atol=YAML_ROUNDING), (written, expected)

    solid = Scenario.model_validate({"name": "capsule", **without_explicit_inertia(data)})
    mini = create_adapter(parse_engine_spec("mini"))
    mini.load(compile_scene(solid))
    mini_inertia = mini.model.body_inertia[0]
    assert np.allclose(mini_inertia, expected, rtol=REFERENCE_TOLERANCE, atol=0), (
        mini_inertia.tolist(),
        expected.tolist(),
    )

    xml, _, _ = build_mjcf(solid, dict(DEFAULT_SETTINGS))
    root = ET.fromstring(xml)
    root.find("compiler").set("inertiafromgeom", "true")
    body = root.find("worldbody/body")
    body.remove(body.find("inertial"))
    body.find("geom").set("mass", repr(float(capsule["mass"])))
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    body_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, capsule["name"])
    assert np.allclose(model.body_iquat[body_id], [1, 0, 0, 0]), model.body_iquat[body_id]
    assert np.allclose(
        model.body_inertia[body_id], np.diag(expected), rtol=REFERENCE_TOLERANCE, atol=0
    ), (
        model.body_inertia[body_id].tolist(),
        np.diag(expected).tolist(),
    )


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_parity_gate_passes_on_every_bundled_scene(path):
    """The gate the runner applies (mini against ``reference_report``) lets every scene run."""
    scenario = load_scenario(path)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    mismatches = compare(adapter.model_report(), reference_report(compile_scene(scenario)))
    assert mismatches == [], [str(m) for m in mismatches]


def test_parity_gate_names_a_wrong_inertia(monkeypatch):
    scenario = scenario_from(ROTATED_OFFSET_SPINNING)
    adapter = create_adapter(parse_engine_spec("mini"))
    adapter.load(compile_scene(scenario))
    wrong = adapter.model.body_inertia.copy()
    wrong[0] *= 1.0 + 1e-6  # a millionth: far below anything a plot would show
    object.__setattr__(adapter.model, "body_inertia", wrong)
    mismatches = compare(adapter.model_report(), reference_report(compile_scene(scenario)))
    quantities = {m.quantity for m in mismatches}
    assert "inertia_world" in quantities, quantities
    message = str(next(m for m in mismatches if m.quantity == "inertia_world"))
    assert "body 0" in message and str(PARITY_TOLERANCE) in message, message


def test_provenance_records_every_setting():
    adapter = create_adapter(parse_engine_spec("mini(gyroscopic=implicit, solver_iterations=20)"))
    adapter.load(compile_scene(scenario_from(ROTATED_OFFSET_SPINNING)))
    settings = adapter.provenance().settings
    assert settings["gyroscopic"] == "implicit" and settings["solver_iterations"] == 20
    assert settings["dt"] == 0.001 and "restitution_threshold" in settings
