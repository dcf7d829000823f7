"""The comparator: engine runs and their measurements become the long-format result rows.

One row per (scenario, engine spec, metric), with the columns of ``COLUMNS``. A metric
with a tolerance in the scene's ``checks`` gets ``passed``; one without gets ``passed``
empty (never a guessed tolerance). An engine that did not produce metrics (model
mismatch, error) gets one row with metric ``status`` and its message.

A ``divergence`` row measures a pair of engines, one against the scene's reference (the
first engine that ran), so its failure is the pair's until the engines' own rows say whose
it is (``judge_divergence``): an engine with a failing row of its own (a closed form it
misses, a bad status) is *off its closed forms*. A divergence beyond its tolerance fails
its engine when that engine is off its closed forms, or when neither is (the pair
disagrees; the message names both); when only the reference is off, the row is not judged
(``passed`` empty): the reference is suspect, and its own rows carry the failure.
"""

from __future__ import annotations

import functools
import json
import math

from validation.contract import (
    BAD_STATUSES,
    NOT_JUDGED_STATUSES,
    RESULTS_COLUMNS,
    SIGNED_COLUMNS,
    SIGNED_ERROR_COLUMN,
    VECTOR_ERROR_COLUMNS,
)
from validation.engine_api import Capabilities, declaration_of
from validation.measure.metrics import (
    Context,
    Measurement,
    agreement_time,
    divergence,
    joint_divergence,
    measure,
)
from validation.measure.noise import DIVERGENCE
from validation.measure.resolution import precision_band, resolution_note
from validation.measure.runner import EngineRun
from validation.scenario.compiled import CompiledScene
from validation.scenario.definability import why_undefined
from validation.scenario.engine_spec import parse_engine_spec

COLUMNS = RESULTS_COLUMNS
"""The columns of results.csv, in order (``validation.contract``)."""


def _common(scene: CompiledScene, run: EngineRun) -> dict:
    provenance = run.provenance
    return {
        "scenario": scene.name,
        "engine": run.engine,
        "dt": scene.scenario.dt,
        "steps": scene.scenario.steps,
        "wall_time_s": round(run.wall_time_s, 6),
        "engine_version": provenance.version if provenance else "",
        "settings": json.dumps(
            provenance.settings if provenance else {}, sort_keys=True, default=str
        ),
    }


def signed_columns(result: Measurement) -> dict:
    """The row's ``SIGNED_COLUMNS``: ``signed_error`` for a scalar error with a sign, the
    three world-frame components for a vector one, None elsewhere."""
    columns: dict = dict.fromkeys(SIGNED_COLUMNS)
    if len(result.signed) == 1:
        columns[SIGNED_ERROR_COLUMN] = float(result.signed[0])
    elif len(result.signed) == len(VECTOR_ERROR_COLUMNS):
        columns.update(zip(VECTOR_ERROR_COLUMNS, map(float, result.signed), strict=True))
    return columns


@functools.cache
def _capabilities(label: str) -> Capabilities:
    """The declared capabilities of the engine spec ``label`` (an installed engine's)."""
    spec = parse_engine_spec(label)
    return declaration_of(spec.name).capabilities_of(spec.as_dict())


def _precision_band(scene: CompiledScene, run: EngineRun, result: Measurement) -> float:
    """The row's precision band (``resolution.precision_band``): what the engine's declared
    precision cannot resolve; 0 for a float64 engine or a row without a value and expectation."""
    if result.value is None or result.expected is None:
        return 0.0
    capabilities = _capabilities(run.engine)
    return precision_band(
        capabilities.precision,
        result.metric,
        float(result.value),
        float(result.expected),
        scene.scenario.steps,
        capabilities.substeps,
    )


def _with_resolution_note(scene: CompiledScene, run: EngineRun, result: Measurement) -> str:
    """The message of a row beyond its tolerance, led by the float32 resolution note when the
    engine is float32 and the error is within what it resolves (``validation.measure.resolution``)."""
    capabilities = _capabilities(run.engine)
    if capabilities.precision != "float32" or result.value is None or result.expected is None:
        return result.message
    note = resolution_note(
        result.metric,
        float(result.value),
        float(result.expected),
        float(result.error),
        scene.scenario.steps,
        capabilities.substeps,
    )
    return "; ".join(part for part in (note, result.message) if part)


def _row(scene: CompiledScene, run: EngineRun, result: Measurement, status: str) -> dict:
    tolerance = scene.scenario.tolerance(result.metric, run.engine)
    band = result.band + _precision_band(scene, run, result)
    passed = (
        None
        if tolerance is None
        else bool(math.isfinite(result.error) and result.error <= tolerance + band)
    )
    message = result.message
    beyond = tolerance is not None and not (result.error <= tolerance + result.band)
    if status == "ok" and beyond:  # failed, or passed by its precision band alone
        message = _with_resolution_note(scene, run, result)
    if status == "ok" and passed is False:
        status = "failed"
    return {
        **_common(scene, run),
        "metric": result.metric,
        "value": result.value,
        "expected": result.expected,
        "expected_kind": result.expected_kind,
        "error": result.error,
        "tolerance": tolerance,
        "band": band,
        "passed": passed,
        "status": status,
        "message": message,
        **signed_columns(result),
    }


def _status_row(scene: CompiledScene, run: EngineRun) -> dict:
    return {
        **_common(scene, run),
        "metric": "status",
        "value": None,
        "expected": None,
        "expected_kind": "",
        "error": None,
        "tolerance": None,
        "band": None,
        "passed": None if run.status in NOT_JUDGED_STATUSES else False,  # not run: not judged
        "status": run.status,
        "message": run.message,
        **dict.fromkeys(SIGNED_COLUMNS),
    }


SHOWN_FAILURES = 3
"""How many of an engine's own failing rows a divergence row's message names (then "…")."""


def off_closed_forms(rows: list[dict], engine: str) -> list[str]:
    """The metrics of ``engine``'s own failing rows in one scene's ``rows`` (a bad status or
    a failed check; divergence rows excluded): empty when it meets every closed form it was
    judged on."""
    return [
        str(row["metric"])
        for row in rows
        if row["engine"] == engine
        and row["metric"] != DIVERGENCE
        and (row["status"] in BAD_STATUSES or row["passed"] is False)
    ]


def _named(engine: str, metrics: list[str]) -> str:
    shown = ", ".join(metrics[:SHOWN_FAILURES]) + (", …" if len(metrics) > SHOWN_FAILURES else "")
    return f"{engine} is off its own closed forms ({shown})"


def judge_divergence(rows: list[dict], reference: str) -> list[dict]:
    """One scene's ``rows`` with each failed ``divergence`` row judged on its pair (the module
    docstring): failed and charged to its own engine when that engine is off its closed forms
    (``off_closed_forms``), failed on the pair when neither is, not judged (``passed`` empty,
    status ``ok``) when only the ``reference`` is."""
    suspect = off_closed_forms(rows, reference)
    judged = []
    for row in rows:
        if row["metric"] != DIVERGENCE or row["passed"] is not False:
            judged.append(row)
            continue
        own = off_closed_forms(rows, str(row["engine"]))
        if own:
            verdict = _named(str(row["engine"]), own)
        elif suspect:
            verdict = f"not judged: {_named(reference, suspect)}; the divergence is charged to it"
            row = {**row, "passed": None, "status": "ok"}
        else:
            verdict = (
                f"the pair {row['engine']} and {reference} diverge; neither is off its own "
                "closed forms"
            )
        message = "; ".join(part for part in (verdict, row["message"]) if part)
        judged.append({**row, "message": message})
    return judged


def measure_run(scene: CompiledScene, run: EngineRun) -> list[Measurement]:
    """Every metric of one engine run that needs only that run, the model tiers it carries
    included (``EngineRun.tiers``); empty without a recording."""
    if run.recording is None:
        return []
    return measure(Context(scene, run.recording)) + list(run.tiers)


def pair_metrics(engine: str, ctx: Context, reference: Context, label: str) -> list[Measurement]:
    """The rows of the engine spec ``engine`` against the scene's reference engine ``label``:
    ``divergence``, and where the scene defines them (a scene with models, ``definability``)
    ``joint_divergence`` and ``agreement_time`` (its band the scene's ``joint_divergence``
    tolerance for this engine)."""
    band = ctx.scenario.tolerance("joint_divergence", engine)
    found = [divergence(ctx, reference, label)]
    if why_undefined("joint_divergence", ctx.traits) is None:
        found.append(joint_divergence(ctx, reference, label))
    if why_undefined("agreement_time", ctx.traits) is None:
        found.append(agreement_time(ctx, reference, label, band))
    return [result for result in found if result is not None]


def compare_scene(
    scene: CompiledScene, runs: list[EngineRun], measured: list[list[Measurement]] | None = None
) -> list[dict]:
    """Rows for every engine run of one scene; the first engine that ran is the reference
    of ``divergence`` for the others, whose failed divergence rows are judged on the pair
    (``judge_divergence``). ``measured``: each run's ``measure_run`` when it was already
    computed (in the worker that ran it)."""
    if measured is None:
        measured = [measure_run(scene, run) for run in runs]
    rows: list[dict] = []
    contexts = {
        run.engine: Context(scene, run.recording) for run in runs if run.recording is not None
    }
    reference = next(iter(contexts), None)
    for run, results in zip(runs, measured, strict=True):
        if run.recording is None:
            rows.append(_status_row(scene, run))
            continue
        results = list(results)
        if reference is not None and run.engine != reference:
            results += pair_metrics(
                run.engine, contexts[run.engine], contexts[reference], reference
            )
        rows += [_row(scene, run, result, run.status) for result in results]
        if run.status != "ok":
            rows.append(_status_row(scene, run))
    return rows if reference is None else judge_divergence(rows, reference)
