"""mini_engine: the rigid-body engine of the documented formulas, in NumPy.

Public API::

    from mini_engine import Body, Box, Settings, Sphere, build_model, step

    model, state = build_model([Body(Sphere(0.1), mass=1.0, position=(0, 0, 1))])
    state, report = step(model, state, Settings(dt=1e-3))

The static ``Model`` and the dynamic ``State`` are structures of arrays; see
``docs/formulas.md`` for the formulas and ``Settings`` for every option
the articles leave open. Nothing here imports from ``validation``.
"""

from mini_engine.contacts import Contacts
from mini_engine.model import (
    SHARED_WORLD,
    Body,
    Model,
    PairProperties,
    Spring,
    State,
    build_model,
    replicate,
)
from mini_engine.settings import Settings
from mini_engine.shapes import Box, Capsule, Plane, ShapeType, Sphere
from mini_engine.solver import ContactReport
from mini_engine.step import StepResult, step

__all__ = [
    "SHARED_WORLD",
    "Body",
    "Box",
    "Capsule",
    "ContactReport",
    "Contacts",
    "Model",
    "PairProperties",
    "Plane",
    "Settings",
    "ShapeType",
    "Sphere",
    "Spring",
    "State",
    "StepResult",
    "build_model",
    "replicate",
    "step",
]
