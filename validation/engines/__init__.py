"""Engine adapters, one module per engine, picked by name from ``ADAPTERS``."""

from __future__ import annotations

import importlib

from validation.engine_spec import EngineSpec
from validation.engines.base import EngineAdapter

ADAPTERS: dict[str, str] = {
    "mini": "validation.engines.mini:MiniAdapter",
    "mujoco": "validation.engines.mujoco_engine:MujocoAdapter",
    "pybullet": "validation.engines.pybullet_engine:PybulletAdapter",
}
"""Engine name -> ``module:Class``; imported on first use, so a run pays only for the
engines it names."""


def create_adapter(spec: EngineSpec) -> EngineAdapter:
    """A new, unloaded adapter for ``spec`` (its name was checked when the spec was parsed)."""
    module_name, class_name = ADAPTERS[spec.name].split(":")
    return getattr(importlib.import_module(module_name), class_name)(spec)
