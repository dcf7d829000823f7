"""Engine adapters, one module per engine, picked by name from ``ADAPTERS``."""

from __future__ import annotations

import importlib

from validation.engines.base import EngineAdapter
from validation.engines.sabotage import sabotaged
from validation.scenario.engine_spec import EngineSpec

ADAPTERS: dict[str, str] = {
    "mini": "validation.engines.mini.adapter:MiniAdapter",
    "mujoco": "validation.engines.mujoco.adapter:MujocoAdapter",
    "pybullet": "validation.engines.pybullet.adapter:PybulletAdapter",
    "rapier": "validation.engines.rapier.adapter:RapierAdapter",
}
"""Engine name -> ``module:Class``; imported on first use, so a run pays only for the
engines it names."""


def create_adapter(spec: EngineSpec) -> EngineAdapter:
    """A new, unloaded adapter for ``spec`` (its name was checked when the spec was parsed);
    a mini spec's wrapped in the sabotage ``PHYSVAL_SABOTAGE`` names, if any
    (``validation.engines.sabotage``: test doubles of the library's power, marked in the
    engine version)."""
    module_name, class_name = ADAPTERS[spec.name].split(":")
    return sabotaged(getattr(importlib.import_module(module_name), class_name)(spec))
