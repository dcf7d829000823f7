"""Running one scene in one engine, never letting an engine take the run down with it.

``run_engine`` loads the scene, passes it through the parity gate, records it, and
returns an ``EngineRun`` whose ``status`` says what happened:

- ``ok``: the engine ran the whole scene;
- ``model_mismatch``: its model differs from the scenario (the message names the
  quantity and both values); it is not run, since its numbers would mean nothing. Under
  native model loading (``model_loader`` native: the engine read a scene's model files
  itself) a difference of a model's own bodies and joints is no refusal: it is what tier 1,
  ``model_fields``, measures (``model_owned``), and the run goes on;
- ``unstable``: the run failed one of the stability checks (``stability.KINDS``: non-finite
  state, energy blow-up, quaternion drift, tunnelling, impossible speed, the engine's own
  instability warning); the run stops there and is kept for the report;
- ``error``: the engine raised (its constructor, its declaration's ``capabilities_for``,
  any adapter call, ``close`` included) or broke the adapter contract (a provenance that is
  not text); the message carries the exception;
- ``unsupported``: the scene needs a capability the engine's declaration lacks
  (``validation.scenario.needs``); the message names each and why; the engine is not even
  imported;
- ``not_installed``: the scene names an engine whose package is not installed here; the
  message is the line that installs it.

A scene with ``models`` also gets the model tiers (``validation.measure.tiers``): tier 1 from
the reports the engine gave at load, tiers 2 and 3 probed once the recording is done (the
engine's state no longer matters then), each failure a NaN row, never a failed job; they
travel in ``EngineRun.tiers`` to ``comparator.measure_run``. Metrics and the comparison with
tolerances (``failed``) come on top of this (``validation.measure.comparator``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from validation.engine_api import declaration_of, model_loader
from validation.engines.base import JointReport, ModelReport, Provenance
from validation.engines.joint_parity import compare_joint_report, compare_joints
from validation.engines.parity import PER_BODY, PRECISION_TOLERANCE, Mismatch, compare
from validation.engines.reference import dynamic_bodies, reference_report
from validation.engines.registry import create_adapter
from validation.measure.measurement import Measurement
from validation.measure.recording import Recording, record
from validation.measure.tiers import guarded, model_fields, probe_tiers
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec, not_installed
from validation.scenario.needs import missing, unsupported_message


@dataclass
class EngineRun:
    """One scene in one engine: the status, why, and what was recorded."""

    scenario: str
    engine: str
    status: str
    message: str = ""
    recording: Recording | None = None
    mismatches: list[Mismatch] = field(default_factory=list)
    provenance: Provenance | None = None
    wall_time_s: float = 0.0
    trace: dict[str, Any] | None = None
    """The thin trace of the bodies under test, trace.csv's columns (``contract.TRACE_COLUMNS``:
    lists of text, float arrays), set by the run's job; None when the scene charts none."""
    tiers: list[Measurement] = field(default_factory=list)
    """The model tiers' rows of a scene with models (``validation.measure.tiers``), computed
    here while the adapter is alive; ``comparator.measure_run`` adds them to the metrics."""


def run_engine(
    scene: CompiledScene, spec: EngineSpec, sample_every: int = 1, keep: str = "states"
) -> EngineRun:
    """Load, gate, record (``keep``: what the recording's trajectory holds, ``recording.KEEP``);
    every engine failure becomes a status, never an exception."""
    start = time.perf_counter()
    run = EngineRun(scene.name, spec.label, "error")
    absent = not_installed(spec.name)
    if absent:
        run.status, run.message = "not_installed", absent
        return run
    try:
        capabilities = declaration_of(spec.name).capabilities_of(spec.as_dict())
    except Exception as error:  # a plugin's declaration: its failure is its row
        run.status, run.message = "error", f"capabilities_for: {raised_message(error)}"
        return run
    lacking = missing(capabilities, scene.scenario)
    if lacking:
        run.status, run.message = "unsupported", unsupported_message(spec.name, lacking)
        return run
    try:
        adapter = create_adapter(spec)
    except Exception as error:
        run.status, run.message = "error", f"the adapter's constructor: {raised_message(error)}"
        run.wall_time_s = time.perf_counter() - start
        return run
    try:
        adapter.load(scene)
        run.provenance = checked_provenance(adapter.provenance())
        tolerance = PRECISION_TOLERANCE[capabilities.precision]
        model, joints = adapter.model_report(), _joint_report(adapter, scene)
        run.mismatches = refusing(scene, adapter, spec, (model, joints), tolerance)
        if run.mismatches:
            run.status = "model_mismatch"
            run.message = "; ".join(str(m) for m in run.mismatches)
            return run
        if scene.models:
            run.tiers.append(guarded("model_fields", lambda: model_fields(scene, model, joints)))
        with np.errstate(over="ignore", invalid="ignore"):  # an explosion is a status, not noise
            run.recording = record(adapter, scene, sample_every, keep)
        run.status = "unstable" if run.recording.unstable else "ok"
        run.message = run.recording.unstable or ""
        if scene.models:
            mass_matrix = None if joints is None else joints.mass_matrix
            run.tiers += probe_tiers(
                scene, adapter, lambda: create_adapter(spec), mass_matrix, capabilities.precision
            )
    except Exception as error:  # an engine's crash is a result for the report, not the harness's
        run.status, run.message = "error", raised_message(error)
    finally:
        _close(adapter, run)
        run.wall_time_s = time.perf_counter() - start
    return run


def refusing(
    scene: CompiledScene,
    adapter: Any,
    spec: EngineSpec,
    reports: tuple[ModelReport, JointReport | None],
    tolerance: float,
) -> list[Mismatch]:
    """The parity gate's mismatches that refuse the run: every difference of the engine's
    ``reports`` at load (``model_report()``, ``joint_report()``) from the scene beyond
    ``tolerance``, but for an engine that loaded the models natively, the models' own
    (``model_owned``: tier 1 measures them)."""
    model, joints = reports
    found = compare(model, reference_report(scene), tolerance)
    if scene.joint_tree is not None:
        found += (
            compare_joints(adapter, scene, tolerance)
            if joints is None
            else compare_joint_report(joints, scene, tolerance)
        )
    if scene.models and loader_of(adapter, spec) == "native":
        found = model_owned(scene, found)[1]
    return found


def _joint_report(adapter: Any, scene: CompiledScene) -> JointReport | None:
    """The engine's ``joint_report()`` at load, for a scene with joints and an adapter that
    has one (the gate and tier 1 read the same report); None otherwise."""
    report = getattr(adapter, "joint_report", None)
    return None if scene.joint_tree is None or report is None else report()


def loader_of(adapter: Any, spec: EngineSpec) -> str:
    """How the engine got the scene's models: the adapter's own ``model_loader`` when it
    states one (a test double that reads a model file itself,
    ``validation.engines.sabotage``), else the spec's (``engine_api.model_loader``)."""
    return getattr(adapter, "model_loader", None) or model_loader(spec.name, spec.as_dict())


WHOLE_SCENE = ("energy", "linear_momentum", "angular_momentum")
"""The gate's totals over every body: a model's difference changes them too."""


def model_owned(
    scene: CompiledScene, mismatches: list[Mismatch]
) -> tuple[list[Mismatch], list[Mismatch]]:
    """``mismatches`` split into (the models', the rest) for an engine that loaded the models
    natively: a model body's mass, centre or inertia and a model joint's field are the
    model's (tier 1 measures them), M(q0) is (tier 3 measures M), and so are the totals
    (energy, momenta) when a model item differs (they sum over its bodies); anything else,
    a non-model body or joint, a total with no model difference to explain it, an unusable
    report, still refuses the run."""
    bodies = [scene.scenario.bodies[k].name for k in dynamic_bodies(scene)]

    def owns(mismatch: Mismatch) -> bool:
        if mismatch.problem:
            return False
        if mismatch.quantity in PER_BODY and mismatch.body is not None:
            return scene.model_of(bodies[mismatch.body]) is not None
        if mismatch.item is not None:
            return scene.model_of(mismatch.item) is not None
        return mismatch.quantity.startswith("mass_matrix")

    owned = [m for m in mismatches if owns(m)]
    if owned:
        owned += [m for m in mismatches if m.quantity in WHOLE_SCENE and not m.problem]
    kept = {id(m) for m in owned}
    return owned, [m for m in mismatches if id(m) not in kept]


def raised_message(error: BaseException) -> str:
    """An exception as an ``error`` row's message, even one whose ``__str__`` raises."""
    try:
        return f"{type(error).__name__}: {error}"
    except Exception:
        return f"{type(error).__name__} (its message cannot be shown)"


def _close(adapter: Any, run: EngineRun) -> None:
    """``adapter.close()``; when it raises, the run is an ``error`` (its recording dropped:
    an engine that cannot release what it holds has broken the contract), unless it already
    failed otherwise."""
    try:
        adapter.close()
    except Exception as error:
        if run.status not in ("error", "model_mismatch"):
            run.status, run.recording = "error", None
            run.message = f"close: {raised_message(error)}"


def checked_provenance(provenance: Any) -> Provenance:
    """The adapter's provenance, its fields of the types the contract names (``version``
    text, not None: the journal and the report write it); ``TypeError`` naming the field
    otherwise (the run's ``error`` row)."""
    if not isinstance(provenance, Provenance):
        raise TypeError(f"provenance(): expected a Provenance; got {type(provenance).__name__}")
    for name, kind in PROVENANCE_TYPES.items():
        value = getattr(provenance, name)
        if not isinstance(value, kind):
            raise TypeError(
                f"provenance().{name}: expected {kind.__name__}; got {type(value).__name__}"
            )
    return provenance


PROVENANCE_TYPES = {"engine": str, "version": str, "settings": dict, "notes": list}
"""What each field of an adapter's ``Provenance`` must be (``checked_provenance``)."""
