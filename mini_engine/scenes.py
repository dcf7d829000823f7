"""Ready-made scenes for benchmarks and examples (the YAML library lives in ``scenarios/``)."""

from __future__ import annotations

import numpy as np

from mini_engine.model import Body, Model, State, build_model, replicate
from mini_engine.shapes import Box, Plane, Sphere

PILE_LAYER_SIDE = 10
"""Spheres per row of one layer of a pile: layers of 10 x 10 = 100, as in engines.md 1.9."""

PILE_JITTER = 0.005
"""m. Random horizontal offset of each sphere of a pile, so that layers do not stack
perfectly and the pile has to settle (the seed fixes it)."""


def _plane_facing(normal: tuple[float, float, float], point: tuple[float, float, float]) -> Body:
    """A fixed plane through ``point`` whose normal (its body +z) is ``normal``."""
    n = np.asarray(normal, dtype=float)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, n)
    sine, cosine = np.linalg.norm(axis), float(z @ n)
    if sine < 1e-12:
        quat = (1.0, 0.0, 0.0, 0.0) if cosine > 0 else (0.0, 1.0, 0.0, 0.0)
    else:
        half = 0.5 * np.arctan2(sine, cosine)
        quat = (np.cos(half), *(np.sin(half) * axis / sine))
    return Body(Plane(), fixed=True, position=point, orientation=quat)


def sphere_pile(
    count: int, radius: float = 0.05, width: float = 1.2, seed: int = 0
) -> tuple[Model, State]:
    """``count`` spheres (1 kg) in layers of 100 falling into a walled box of ``width`` m.

    The ground is the plane z = 0 and the four walls are planes at ±width/2 facing in;
    layers start ``2.4 radius`` apart so the pile falls and settles (engines.md 1.9).
    """
    rng = np.random.default_rng(seed)
    half = width / 2.0
    bodies = [_plane_facing((0, 0, 1), (0, 0, 0))]
    bodies += [
        _plane_facing((1, 0, 0), (-half, 0, 0)),
        _plane_facing((-1, 0, 0), (half, 0, 0)),
        _plane_facing((0, 1, 0), (0, -half, 0)),
        _plane_facing((0, -1, 0), (0, half, 0)),
    ]
    pitch = (width - 2.0 * radius) / PILE_LAYER_SIDE
    for k in range(count):
        layer, row, column = divmod(k, PILE_LAYER_SIDE**2)[0], *divmod(k % 100, PILE_LAYER_SIDE)
        x = -half + radius + (column + 0.5) * pitch + rng.uniform(-PILE_JITTER, PILE_JITTER)
        y = -half + radius + (row + 0.5) * pitch + rng.uniform(-PILE_JITTER, PILE_JITTER)
        z = radius * 1.2 + layer * 2.4 * radius
        bodies.append(Body(Sphere(radius), mass=1.0, position=(x, y, z)))
    return build_model(bodies)


GAZEBO_BOX_HALF_EXTENTS = (0.05, 0.2, 0.45)
"""m. The Gazebo "boxes" benchmark box, 0.1 x 0.4 x 0.9 m (scpeters/benchmark, 2015)."""


def tumbling_box(copies: int = 1) -> tuple[Model, State]:
    """The Gazebo "complex" box: 10 kg, v0 = (-2, 2, 8) m/s, ω0 = (0.1, 5, 0.1) rad/s, g = 9.8.

    ``copies`` > 1 puts that many independent copies in one model (one world each).
    """
    model, state = build_model(
        [
            Body(
                Box(GAZEBO_BOX_HALF_EXTENTS),
                mass=10.0,
                velocity=(-2.0, 2.0, 8.0),
                angular_velocity=(0.1, 5.0, 0.1),
            )
        ],
        gravity=(0.0, 0.0, -9.8),
    )
    return replicate(model, state, copies) if copies > 1 else (model, state)
