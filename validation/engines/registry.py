"""Engine adapters by name: each installed engine's declaration (``validation.engine_api``,
found by the ``physval.engines`` entry points) names its adapter class, imported on first
use, so a run pays only for the engines it names."""

from __future__ import annotations

from validation.engine_api import declaration_of
from validation.engines.base import EngineAdapter
from validation.engines.sabotage import sabotaged
from validation.scenario.engine_spec import EngineSpec


def create_adapter(spec: EngineSpec) -> EngineAdapter:
    """A new, unloaded adapter for ``spec`` (its name was checked when the spec was parsed);
    a mini spec's wrapped in the sabotage ``PHYSVAL_SABOTAGE`` names, if any
    (``validation.engines.sabotage``: test doubles of the library's power, marked in the
    engine version)."""
    return sabotaged(declaration_of(spec.name).load_adapter()(spec))
