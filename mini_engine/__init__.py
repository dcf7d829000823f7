"""mini_engine: the rigid-body engine of the documented formulas, in NumPy.

Public API::

    from mini_engine import Body, Box, Settings, Sphere, build_model, step

    model, state = build_model([Body(Sphere(0.1), mass=1.0, position=(0, 0, 1))])
    state, report = step(model, state, Settings(dt=1e-3))

The static ``Model`` and the dynamic ``State`` are structures of arrays; see
``docs/formulas.md`` for the formulas and ``Settings`` for every option
the articles leave open. Nothing here imports from ``validation``.
"""

import importlib

_HOMES = {
    "Contacts": "mini_engine.contacts",
    "SHARED_WORLD": "mini_engine.model",
    "Body": "mini_engine.model",
    "Joint": "mini_engine.joints",
    "Model": "mini_engine.model",
    "PairProperties": "mini_engine.model",
    "Spring": "mini_engine.model",
    "State": "mini_engine.model",
    "build_model": "mini_engine.model",
    "replicate": "mini_engine.model",
    "Settings": "mini_engine.settings",
    "Box": "mini_engine.shapes",
    "Capsule": "mini_engine.shapes",
    "Plane": "mini_engine.shapes",
    "ShapeType": "mini_engine.shapes",
    "Sphere": "mini_engine.shapes",
    "ContactReport": "mini_engine.solver",
    "StepResult": "mini_engine.step",
    "step": "mini_engine.step",
}
"""Where each public name lives. The package imports a module when one of its names is first
used (PEP 562), so that reading ``mini_engine.settings`` alone (an engine declaration, a
light command) does not load the whole engine and NumPy's linear algebra."""


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'mini_engine' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_HOMES])


__all__ = [
    "SHARED_WORLD",
    "Body",
    "Box",
    "Capsule",
    "ContactReport",
    "Contacts",
    "Joint",
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
