"""The reference side of the ``cylinder`` shape: its solid inertia against an integral over the
solid, its contacts with the plane and the sphere against hand-computed cases and against an
independent convex minimisation, the pairs without a closed form refused at ``physval check``,
and the capability word (an engine naming no shapes is never asked for one).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize
from test_reference_contacts import EYE, GROUND, ROUND_OFF, check, one, turn

from validation import engine_api
from validation.cli import main
from validation.reference import contacts
from validation.reference.mass_properties import cylinder_inertia
from validation.reference.rotation import quat_to_matrix
from validation.scenario.load import load_scenario
from validation.scenario.needs import missing
from validation.scenario.physics import body_inertia

INTEGRAL_AGREEMENT = 1e-10
"""Relative. ``scipy.integrate.quad`` at epsrel 1e-13 over the solid's disc slices against the
closed form (as ``tests/test_reference_side.py`` checks the capsule)."""

MINIMISER_AGREEMENT = 1e-6
"""m. SLSQP's closest point of the solid cylinder (a convex problem: one minimum) at ftol
1e-15 on squared distances of order 1 m²: its point is good to about sqrt(1e-15) ≈ 3e-8 m
(measured on the 47 outside poses below: depth within 4.7e-10 m, the normal times the gap
within 1.6e-8 m); the band leaves a factor of 60 over the worst, far below the shapes' 5 cm
and up, so a wrong closest point (a rim for a face) fails."""

SIZE = (0.1, 0.2, 0.0)
"""m, (radius, half length, 0): the ``Shapes.size`` row of a cylinder."""


# --- inertia -------------------------------------------------------------------------------

CYLINDERS = [(0.08, 0.12), (1.0, 0.01), (0.01, 3.0), (0.3, 0.15)]
"""(radius, half_length) m: the conformance cylinder, a coin, a thin rod, equal height and
diameter."""


def test_cylinder_inertia_equals_the_integral_over_the_solid():
    """Disc slices of radius r for |z| <= h: volume π r², ∫(x² + y²) dA = π r⁴/2,
    ∫ y² dA = π r⁴/4 per slice; no formula shared with the closed form."""
    body_mass = 2.5
    for radius, half_length in CYLINDERS:

        def integral(per_slice, h=half_length) -> float:
            return quad(per_slice, -h, h, epsabs=0.0, epsrel=1e-13)[0]

        volume = integral(lambda z, r=radius: np.pi * r**2)
        axial = integral(lambda z, r=radius: np.pi * r**4 / 2.0)
        transverse = integral(lambda z, r=radius: np.pi * r**4 / 4.0 + z * z * np.pi * r**2)
        integrated = np.diag([transverse, transverse, axial]) * body_mass / volume
        closed_form = cylinder_inertia(body_mass, radius, half_length)
        error = np.abs(closed_form - integrated).max() / np.abs(integrated).max()
        assert error <= INTEGRAL_AGREEMENT, (radius, half_length, np.diag(closed_form))


def test_a_scene_cylinder_gets_the_solid_inertia(tmp_path):
    scenario = load_scenario(cylinder_scene(tmp_path, []))
    np.testing.assert_allclose(
        body_inertia(scenario.body("can")), cylinder_inertia(2.0, *SIZE[:2]), rtol=0, atol=0
    )


# --- plane and cylinder ----------------------------------------------------------------------


def test_a_cylinder_standing_on_its_end_touches_at_the_end_centre():
    """The whole end is deepest together: the centre of the patch, not a rim point."""
    found = one(contacts.PLANE, contacts.CYLINDER, GROUND, ((1, 2, 0.19), EYE, SIZE))
    check(found, 0.01, (0, 0, 1), (1, 2, -0.005))


def test_a_cylinder_tilted_by_less_than_the_tie_still_touches_at_its_end_centre():
    """Turned 1e-10 rad about x: the end's rim spans 2 r sin θ = 2e-11 m in height, within
    ``contacts.TIE``: the whole end is deepest together, its centre (h sin θ along +y) the
    point, not the rim point 0.1 m off it."""
    angle = 1e-10
    nearly = turn((1, 0, 0), angle)
    found = one(contacts.PLANE, contacts.CYLINDER, GROUND, ((1, 2, 0.19), nearly, SIZE))
    check(found, 0.01, (0, 0, 1), (1, 2 + SIZE[1] * angle, -0.005))


def test_a_cylinder_lying_on_its_side_touches_at_the_middle_of_its_lowest_line():
    lying = turn((1, 0, 0), np.pi / 2)
    found = one(contacts.PLANE, contacts.CYLINDER, GROUND, ((1, 2, 0.098), lying, SIZE))
    check(found, 0.002, (0, 0, 1), (1, 2, -0.001))


def test_a_tilted_cylinder_touches_at_its_lowest_rim_point():
    """Turned 0.3 rad about x: its axis is (0, -sin, cos); the lower end's centre sits at
    -h·axis, its lowest rim point r further along -(0, cos, sin)."""
    angle, (radius, half_length, _) = 0.3, SIZE
    rim = np.array([0.0, half_length * np.sin(angle), -half_length * np.cos(angle)]) - radius * (
        np.array([0.0, np.cos(angle), np.sin(angle)])
    )
    centre = np.array([0.0, 0.0, -rim[2] - 0.003])
    found = one(contacts.PLANE, contacts.CYLINDER, GROUND, (centre, turn((1, 0, 0), angle), SIZE))
    check(found, 0.003, (0, 0, 1), (0.0, rim[1], -0.0015))


def test_a_tilted_ground_measures_a_standing_cylinder_along_its_own_normal():
    tilt = turn((0, 1, 0), 0.4)
    normal = tilt[:, 2]
    centre = np.array([0.0, 0.0, 1.0]) + 0.195 * normal
    found = one(
        contacts.PLANE, contacts.CYLINDER, ((0, 0, 1), tilt, (0, 0, 0)), (centre, tilt, SIZE)
    )
    check(found, 0.005, normal, centre - 0.1975 * normal)


def test_the_plane_contact_is_the_lowest_point_of_a_sampled_surface():
    """Random poses against the rim sampled every 2π/200000 rad (the lowest sample is within
    r (1 - cos(π/200000)) ≈ 1.2e-11 r of the true lowest point): the depths agree."""
    rng = np.random.default_rng(36)
    count, samples = 50, 200_000
    quat = rng.normal(size=(count, 4))
    rot = quat_to_matrix(quat / np.linalg.norm(quat, axis=1, keepdims=True))
    size = np.column_stack(
        [rng.uniform(0.05, 1, count), rng.uniform(0.05, 1, count), np.zeros(count)]
    )
    pos = rng.uniform(-1, 1, (count, 3))
    found = contacts.plane_cylinder(
        np.zeros((count, 3)),
        np.broadcast_to(EYE, (count, 3, 3)),
        np.zeros((count, 3)),
        pos,
        rot,
        size,
    )
    phi = np.linspace(0.0, 2 * np.pi, samples, endpoint=False)
    circle = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    for k in range(count):
        r, h = size[k, :2]
        rim = np.concatenate([np.column_stack([r * circle, np.full(samples, z)]) for z in (h, -h)])
        lowest = (pos[k] + rim @ rot[k].T)[:, 2].min()
        assert found.depth[k] == pytest.approx(-lowest, abs=1e-10 * (1 + r))


# --- sphere and cylinder ---------------------------------------------------------------------


def test_a_sphere_against_the_side_the_end_and_the_rim():
    sphere = (0.05, 0.0, 0.0)
    on_side = one(
        contacts.SPHERE, contacts.CYLINDER, ((0.14, 0, 0.1), EYE, sphere), ((0, 0, 0), EYE, SIZE)
    )
    check(on_side, 0.01, (-1, 0, 0), (0.095, 0, 0.1))
    on_end = one(
        contacts.SPHERE, contacts.CYLINDER, ((0.03, 0, 0.24), EYE, sphere), ((0, 0, 0), EYE, SIZE)
    )
    check(on_end, 0.01, (0, 0, -1), (0.03, 0, 0.195))
    corner = np.array([0.1, 0.0, 0.2])  # on the rim: the sphere 0.04 out along the diagonal
    diagonal = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    on_rim = one(
        contacts.SPHERE,
        contacts.CYLINDER,
        (corner + 0.04 * diagonal, EYE, sphere),
        ((0, 0, 0), EYE, SIZE),
    )
    check(on_rim, 0.01, -diagonal, corner - 0.005 * diagonal)


def test_a_sphere_centre_inside_leaves_through_the_nearer_surface():
    sphere = (0.05, 0.0, 0.0)
    near_side = one(
        contacts.SPHERE, contacts.CYLINDER, ((0, 0.08, 0), EYE, sphere), ((0, 0, 0), EYE, SIZE)
    )
    check(near_side, 0.07, (0, -1, 0), (0, 0.065, 0))
    near_end = one(
        contacts.SPHERE, contacts.CYLINDER, ((0, 0, -0.19), EYE, sphere), ((0, 0, 0), EYE, SIZE)
    )
    check(near_end, 0.06, (0, 0, 1), (0, 0, -0.17))  # midway: -0.19 + 0.05 and -0.2


def closest_on_cylinder(point, radius, half_length) -> np.ndarray:
    """The solid cylinder's closest point to ``point`` (its own frame) by SLSQP: minimise
    |x - point|² subject to x² + y² <= r², |z| <= h (convex: the minimum is unique)."""
    constraints = [
        {"type": "ineq", "fun": lambda x: radius**2 - x[0] ** 2 - x[1] ** 2},
        {"type": "ineq", "fun": lambda x: half_length - abs(x[2])},
    ]
    found = minimize(
        lambda x: np.sum((x - point) ** 2),
        np.zeros(3),
        method="SLSQP",
        constraints=constraints,
        options={"ftol": 1e-15, "maxiter": 500},
    )
    return found.x


def test_the_sphere_contact_agrees_with_a_convex_minimisation_on_random_poses():
    rng = np.random.default_rng(7)
    count = 60
    quat = rng.normal(size=(count, 4))
    rot = quat_to_matrix(quat / np.linalg.norm(quat, axis=1, keepdims=True))
    size_b = np.column_stack(
        [rng.uniform(0.1, 0.5, count), rng.uniform(0.1, 0.5, count), np.zeros(count)]
    )
    size_a = np.column_stack([rng.uniform(0.05, 0.3, count), np.zeros((count, 2))])
    pos_b = rng.uniform(-0.5, 0.5, (count, 3))
    local = rng.uniform(-1, 1, (count, 3)) * (size_b[:, [0, 0, 1]] + size_a[:, [0, 0, 0]])
    outside = (np.hypot(local[:, 0], local[:, 1]) > size_b[:, 0]) | (
        np.abs(local[:, 2]) > size_b[:, 1]
    )
    pos_a = pos_b + np.einsum("kij,kj->ki", rot, local)
    found = contacts.sphere_cylinder(
        pos_a, np.broadcast_to(EYE, (count, 3, 3)), size_a, pos_b, rot, size_b
    )
    assert outside.sum() > 20
    for k in np.flatnonzero(outside):
        nearest = pos_b[k] + rot[k] @ closest_on_cylinder(local[k], *size_b[k, :2])
        gap = np.linalg.norm(nearest - pos_a[k])
        assert found.depth[k] == pytest.approx(size_a[k, 0] - gap, abs=MINIMISER_AGREEMENT)
        np.testing.assert_allclose(
            found.normal[k], (nearest - pos_a[k]) / gap, atol=MINIMISER_AGREEMENT / gap
        )


def test_the_batched_finder_finds_a_cylinder_on_the_ground_and_a_sphere_on_it():
    shapes = contacts.Shapes(
        kind=np.array([contacts.CYLINDER, contacts.SPHERE, contacts.PLANE]),
        size=np.array([SIZE, (0.05, 0, 0), (0, 0, 0)]),
        fixed=np.array([False, False, True]),
    )
    pos = np.array([[[0, 0, 0.199], [0, 0, 0.448], [0, 0, 0]]])
    found = contacts.find_contacts(shapes, pos, np.broadcast_to(EYE, (1, 3, 3, 3)), 1e-6)
    assert list(zip(found.body_a, found.body_b, strict=True)) == [(1, 0), (2, 0)]
    np.testing.assert_allclose(found.depth, [0.001, 0.001], atol=ROUND_OFF)
    assert shapes.bound_radius[0] == pytest.approx(np.hypot(0.1, 0.2))


def test_the_finder_names_a_pair_it_has_no_closed_form_for():
    """Only reached past ``physval check``: an error naming the shapes, not a lost pair."""
    shapes = contacts.Shapes(
        kind=np.array([contacts.BOX, contacts.CYLINDER]),
        size=np.array([(0.1, 0.1, 0.1), SIZE]),
        fixed=np.array([False, False]),
    )
    with pytest.raises(ValueError, match="a box against a cylinder has no closed form"):
        contacts.find_contacts(shapes, np.zeros((1, 2, 3)), np.broadcast_to(EYE, (1, 2, 3, 3)), 0.0)


# --- the pairs without a closed form: refused at check --------------------------------------


def cylinder_scene(folder, others: list[str], ground: bool = False) -> object:
    path = folder / "can.yaml"
    lines = ["dt: 0.001", "duration: 0.01", "bodies:"]
    lines += [
        "  - {name: can, shape: {type: cylinder, radius: 0.1, half_length: 0.2}, mass: 2.0}",
        *others,
    ]
    if ground:
        lines.insert(2, "ground: {}")
    path.write_text("\n".join(lines) + "\n")
    return path


BOX = "  - {name: crate, shape: {type: box, half_extents: [0.1, 0.1, 0.1]}, mass: 1.0, position: [1, 0, 0]"


@pytest.mark.parametrize(
    ("other", "word"),
    [
        (BOX + "}", "box"),
        (
            "  - {name: pill, shape: {type: capsule, radius: 0.1, half_length: 0.1}, mass: 1.0, position: [1, 0, 0]}",
            "capsule",
        ),
        (
            "  - {name: tin, shape: {type: cylinder, radius: 0.1, half_length: 0.1}, mass: 1.0, position: [1, 0, 0]}",
            "cylinder",
        ),
    ],
)
def test_a_cylinder_that_can_touch_a_shape_without_a_closed_form_is_refused(
    tmp_path, capsys, other, word
):
    assert main(["check", str(cylinder_scene(tmp_path, [other]))]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert f"a cylinder that can touch a {word} is not measured yet" in err, err
    assert "bodies[0].shape" in err, err


@pytest.mark.parametrize("apart", [", collides: false}", ", fixed: true}"])
def test_a_cylinder_that_cannot_touch_the_box_is_accepted(tmp_path, capsys, apart):
    """Not both fixed or excluded: the pair never touches, so nothing goes unmeasured."""
    fixed_can = "  - {name: can, shape: {type: cylinder, radius: 0.1, half_length: 0.2}, mass: 2.0, fixed: true}"
    path = cylinder_scene(tmp_path, [BOX + apart], ground=True)
    if apart.startswith(", fixed"):
        text = path.read_text().splitlines()
        path.write_text("\n".join(fixed_can if "name: can" in x else x for x in text) + "\n")
    assert main(["check", str(path)]) == 0, capsys.readouterr().err


def test_two_cylinders_joined_by_a_joint_never_touch_and_are_accepted(tmp_path, capsys):
    """A joint's parent and child are an excluded pair: no cylinder pair is left to measure."""
    tin = "  - {name: tin, shape: {type: cylinder, radius: 0.1, half_length: 0.1}, mass: 1.0, position: [0, 0, 0.5]}"
    path = cylinder_scene(tmp_path, [tin])
    joint = "joints:\n  - {name: pin, type: hinge, parent: can, child: tin, anchor: [0, 0, 0.3], axis: [1, 0, 0]}\n"
    path.write_text(path.read_text() + joint)
    assert main(["check", str(path)]) == 0, capsys.readouterr().err


def test_a_cylinder_with_a_sphere_and_the_ground_is_accepted(tmp_path, capsys):
    sphere = "  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [1, 0, 0]}"
    assert main(["check", str(cylinder_scene(tmp_path, [sphere], ground=True))]) == 0, (
        capsys.readouterr().err
    )


# --- the capability word ---------------------------------------------------------------------


def test_cylinder_is_a_shape_word_that_old_declarations_do_not_claim(tmp_path):
    assert "cylinder" in engine_api.SHAPES
    assert "cylinder" not in engine_api.Capabilities().shapes
    scenario = load_scenario(cylinder_scene(tmp_path, []))
    assert missing(engine_api.Capabilities(), scenario) == {"cylinder": "body 'can' is a cylinder"}
    claims = replace(engine_api.Capabilities(), shapes=engine_api.SHAPES)
    assert missing(claims, scenario) == {}


def test_mini_declares_no_cylinder():
    mini = engine_api.declaration_of("mini").capabilities
    assert "cylinder" not in mini.shapes
