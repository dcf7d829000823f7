"""The quantity under test against its closed form: what a scene card plots for its expectations.

For each expectation kind in ``CLOSED_FORMS``, the run records a thin trace of the body's
quantity (``trace.csv``: ``trace_rows``, in the worker that ran the job) and the expectations
themselves (``provenance.json``'s ``scenes.<name>.expect``: ``expectation_records``); the
report draws the quantity of every engine over time with the closed form on top
(``closed_form_charts``): z(t) with the expected apex heights for ``bounce_heights``, v(t)
through the ``velocity_at`` points, ω(t) through the ``angular_velocity_at`` points and the
level expected after an impact, the body-frame ω component with the expected flip times.
A reader sees where and how a row missed, not only by how much.

``provenance.json`` is read back as untrusted data: every expectation field is checked
(``read_expectations``) and one that does not fit is left out with a warning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from validation.reference.newton_euler import reference_motion
from validation.reference.rotation import quat_to_matrix
from validation.report.palette import engine_style
from validation.report.svgchart import Chart, Trace

TRACE_POINTS = 150
"""Samples per (scene, engine, body, quantity) kept in trace.csv: evenly spaced over the run,
one per 2 px of a chart's 312-px plot area (a curve drawn through them is smooth at that
width); 27 ms apart on a 4-s scene, so an apex drawn from them is within g·(13 ms)²/2 = 0.9 mm
of the sampled one (the row's message gives the measured apexes exactly). The library's
trace.csv: 382 traces, 57,000 rows, about 3.8 MB (its series.csv: 19.6 MB), measured before
the tilt and the closed-form residuals were traced: with them the rotation folder's trace.csv
went from 9,300 to 24,600 rows (1.95 MB), a contact scene's gains only the tilt."""

MAX_CHARTS = 6
"""Closed-form charts per scene card (two rows of three); the rest are counted in a note."""

MAX_COMPONENTS = 2
"""Vector components charted per (body, quantity): those the closed form sets (non-zero)."""

EXPECTED_COLOUR = "#1d1d1d"
"""The closed form: black markers and dotted levels, apart from every engine's colour."""

QUANTITY_WORDS = {
    "pos": ("{c}(t)", "m"),
    "vel": ("v_{c}(t)", "m/s"),
    "ang_vel": ("ω_{c}(t)", "rad/s"),
    "body_ang_vel": ("body-frame ω_{c}(t)", "rad/s"),
    "tilt": ("tilt of the {c} axis", "rad"),
}
"""Trace quantity -> the chart's title pattern and unit (``{c}`` the component)."""


@dataclass(frozen=True)
class ClosedForm:
    """How an expectation kind is drawn: the body's quantity traced, and how its expected
    values appear: ``points`` at (time, value), ``levels`` (horizontal lines at each value of
    one component), ``after_impact`` (a level: the vector expected once the impact is over),
    ``times`` (markers on the zero line: sign changes), ``zero`` (the zero line alone)."""

    quantity: str
    expected: str
    component: str = ""
    """Fixed component (``z`` for apex heights, the expectation's ``axis`` for flips), or ""."""


CLOSED_FORMS: dict[str, ClosedForm] = {
    "position_at": ClosedForm("pos", "points"),
    "velocity_at": ClosedForm("vel", "points"),
    "angular_velocity_at": ClosedForm("ang_vel", "points"),
    "bounce_heights": ClosedForm("pos", "levels", "z"),
    "velocity_after_impact": ClosedForm("vel", "after_impact"),
    "angular_velocity_after_impact": ClosedForm("ang_vel", "after_impact"),
    "flip_times": ClosedForm("body_ang_vel", "times", "axis"),
    "flips": ClosedForm("body_ang_vel", "zero", "axis"),
    "orientation_at": ClosedForm("tilt", "orientation"),
}
"""Expectation kind -> how it is charted. Kinds not listed (precession rates,
energies, impact times, and a joint's ``joint_position_at`` and ``period``: their subject is a
joint, not a body) have no time trace that shows more than their row."""

EXPECTATION_FIELDS = ("kind", "body", "name", "time", "value", "axis")
"""The fields of an expectation kept in provenance.json for the charts."""


# --- the run's side: what to record ---------------------------------------------------------


def expectation_records(expectations: list[Any]) -> list[dict[str, Any]]:
    """A scene's expectations that have a chart, as plain JSON records for provenance.json."""
    found = []
    for expectation in expectations:
        if expectation.kind not in CLOSED_FORMS:
            continue
        record = {"kind": expectation.kind, "body": expectation.body, "metric": expectation.metric}
        for name in ("time", "value", "axis"):
            value = getattr(expectation, name, None)
            if value is not None:
                record[name] = list(value) if isinstance(value, tuple | list) else value
        found.append(record)
    return found


def traced(expectations: list[Any]) -> list[tuple[str, str]]:
    """(body, quantity) pairs the trace keeps for a scene's expectations: those of the charts
    a card draws (the first ``MAX_CHARTS``), in order, once each."""
    charted = list(_groups(expectation_records(expectations)))[:MAX_CHARTS]
    pairs = [(body, quantity) for body, quantity, _ in charted]
    pairs += [(body, "tilt") for body, quantity in pairs if quantity in ROTATION_QUANTITIES]
    return list(dict.fromkeys(pairs))


ROTATION_QUANTITIES = ("ang_vel", "body_ang_vel", "tilt")
"""Traced quantities of a body's rotation: where one is charted, so is the body's tilt (the
angle of each body axis from its initial direction: a box toppling reads 0 to 90°, where its
ω is a burst of noise at the impact)."""


def _axes(trajectory, body: int) -> np.ndarray:
    """(samples, 3, 3): the body's axes in the world frame (columns of its rotation)."""
    return quat_to_matrix(trajectory.quat[:, body])


def _axis_angles(axes: np.ndarray, others: np.ndarray) -> np.ndarray:
    """(samples, 3) rad: the angle between each body axis of ``axes`` and of ``others``."""
    return np.arccos(np.clip(np.einsum("sji,sji->si", axes, others), -1.0, 1.0))


def _quantity(trajectory, body: int, quantity: str) -> np.ndarray:
    if quantity == "tilt":
        axes = _axes(trajectory, body)
        return _axis_angles(axes, np.broadcast_to(axes[:1], axes.shape))
    if quantity == "body_ang_vel":
        rot = quat_to_matrix(trajectory.quat[:, body])
        return np.einsum("sji,sj->si", rot, trajectory.ang_vel[:, body])
    return getattr(trajectory, quantity)[:, body]


TIMED = ("points", "orientation")
"""``ClosedForm.expected`` of the kinds with a ``time``."""

RESIDUAL_KINDS = frozenset(k for k, form in CLOSED_FORMS.items() if form.expected in TIMED)
"""Expectation kinds drawn as a residual panel (``residual_chart``): a vector at a time, whose
row has a signed error per component (``error_x``, ``error_y``, ``error_z``), or an
orientation, whose row's error is the angle to the closed form."""


def residual_pairs(expectations: list[Any]) -> set[tuple[str, str]]:
    """(body, quantity) pairs a residual panel draws minus their closed form."""
    records = expectation_records(expectations)
    return {
        (r["body"], CLOSED_FORMS[r["kind"]].quantity)
        for r in records
        if r["kind"] in RESIDUAL_KINDS
    }


CLOSED_FORM_SUFFIX = "-closed_form"
"""trace.csv's quantity ``<quantity>-closed_form``: the traced quantity minus the scene's
closed form (the DOP853 reference motion, ``newton_euler.reference_motion``) at the same
times, kept where the scene has one (nothing can touch)."""


def closed_form_motion(scene: Any, times: np.ndarray):
    """The scene's reference motion at ``times`` (``reference_motion``), or None where it has
    none: bodies that can touch (contacts have no closed form here), or no scene given."""
    if scene is None or getattr(scene, "can_touch", True) or times.size == 0:
        return None
    return reference_motion(scene, times)


def trace_rows(
    scenario: str,
    engine: str,
    trajectory,
    bodies: list[str],
    wanted: list[tuple[str, str]],
    scene: Any = None,
) -> pd.DataFrame:
    """The thin trace of a run (``TRACE_POINTS`` evenly spaced samples) of each wanted (body,
    quantity): trace.csv's rows (``contract.TRACE_COLUMNS``); with the compiled ``scene``,
    also each quantity minus its closed form (``CLOSED_FORM_SUFFIX``) where the scene has one."""
    size = len(trajectory)
    if size == 0 or not wanted:
        return pd.DataFrame()
    keep = np.unique(np.linspace(0, size - 1, min(size, TRACE_POINTS)).astype(int))
    kept = trajectory.take(keep)
    reference = closed_form_motion(scene, np.asarray(kept.t, dtype=float))
    drawn = residual_pairs(scene.scenario.expect) if reference is not None else set()
    frames = []
    for body, quantity in wanted:
        if body not in bodies:
            continue
        index = bodies.index(body)
        values = _quantity(kept, index, quantity)
        frames.append(_trace_frame(scenario, engine, body, quantity, kept.t, values))
        if (body, quantity) in drawn:
            residual = _minus_closed_form(kept, reference, index, quantity, values)
            frames.append(
                _trace_frame(
                    scenario, engine, body, quantity + CLOSED_FORM_SUFFIX, kept.t, residual
                )
            )
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _minus_closed_form(kept, reference, body: int, quantity: str, values) -> np.ndarray:
    """The traced quantity minus its closed form: a difference, or for the tilt the angle of
    each body axis from where the closed form puts it (rad, never negative)."""
    if quantity == "tilt":
        return _axis_angles(_axes(kept, body), _axes(reference, body))
    return values - _quantity(reference, body, quantity)


def _trace_frame(scenario, engine, body, quantity, t, values) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "scenario": scenario,
            "engine": engine,
            "body": body,
            "quantity": quantity,
            "t": t,
            "x": values[:, 0],
            "y": values[:, 1],
            "z": values[:, 2],
        }
    )


# --- the report's side: read back and draw -------------------------------------------------


def _finite_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


VALUE_SHAPES = {
    "points": "vector",
    "after_impact": "vector",
    "levels": "list",
    "times": "list",
    "zero": "number",
    "orientation": "quaternion",
}
"""What an expectation's ``value`` is, by how it is drawn (``ClosedForm.expected``): a vector
of three numbers, a non-empty list of numbers, one number, or a quaternion (four)."""


SIZES = {"vector": 3, "quaternion": 4}
"""Numbers in a value of a fixed size (``VALUE_SHAPES``)."""


def _valid(record: Any) -> bool:
    """An expectation record as ``expectation_records`` writes it: a known kind, a body name,
    a finite time where the kind has one, a value of the kind's shape (``VALUE_SHAPES``) of
    finite numbers, an axis x, y or z."""
    if not isinstance(record, dict) or record.get("kind") not in CLOSED_FORMS:
        return False
    form = CLOSED_FORMS[record["kind"]]
    if not isinstance(record.get("body"), str):
        return False
    if form.expected in TIMED and not _finite_number(record.get("time")):
        return False
    value, shape = record.get("value"), VALUE_SHAPES[form.expected]
    if shape == "number":
        values = [value]
    elif isinstance(value, list) and value and (shape == "list" or len(value) == SIZES[shape]):
        values = value
    else:
        return False
    return all(_finite_number(v) for v in values) and record.get("axis", "x") in ("x", "y", "z")


def read_expectations(provenance: dict | None, scene: str, warnings: list[str]) -> list[dict]:
    """The scene's charted expectations from provenance.json (``scenes.<scene>.expect``); a
    record that does not fit is left out with one warning per scene."""
    scenes = (provenance or {}).get("scenes")
    entry = scenes.get(scene) if isinstance(scenes, dict) else None
    records = entry.get("expect", []) if isinstance(entry, dict) else []
    if not isinstance(records, list):
        records = [records]
    good = [r for r in records if _valid(r)]
    if len(good) < len(records):
        warnings.append(
            f"provenance.json: scenes.{scene}.expect: {len(records) - len(good)} expectations "
            "not of the form the run writes; not charted"
        )
    return good


def _component(record: dict, form: ClosedForm) -> list[str]:
    if form.component == "axis":
        return [str(record.get("axis", "y"))]
    if form.component:
        return [form.component]
    value = record.get("value")
    if isinstance(value, list) and len(value) == 3:
        return [c for c, v in zip("xyz", value, strict=True) if v != 0.0]
    return []


def _groups(expectations: list[dict]) -> dict[tuple[str, str, str], list[dict]]:
    """(body, quantity, component) -> its expectations, in the scene's order."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for record in expectations:
        form = CLOSED_FORMS[record["kind"]]
        chosen = _component(record, form) or ["z"]
        for component in chosen[:MAX_COMPONENTS]:
            groups.setdefault((record["body"], form.quantity, component), []).append(record)
    return groups


def _expected_traces(records: list[dict], component: str, t_end: float) -> list[Trace]:
    """The closed form of one chart: markers at the expected points, dotted levels, the zero
    line with the expected sign changes."""
    index = "xyz".index(component)
    found: list[Trace] = []
    points = [
        (r["time"], r["value"][index])
        for r in records
        if CLOSED_FORMS[r["kind"]].expected == "points"
    ]
    if points:
        t, v = np.array(points, dtype=float).T
        found.append(
            Trace("closed form", t, v, EXPECTED_COLOUR, line=False, marker="o", hollow=True)
        )
    for record in records:
        form = CLOSED_FORMS[record["kind"]]
        if form.expected == "levels":
            for level in record["value"]:
                found.append(_level(level, t_end, "closed form: expected apexes"))
        elif form.expected == "after_impact":
            found.append(_level(record["value"][index], t_end, "closed form: after the impact"))
        elif form.expected in ("times", "zero"):
            found.append(_level(0.0, t_end, "zero: a sign change is a flip"))
            if form.expected == "times":
                times = np.asarray(record["value"], dtype=float)
                found.append(
                    Trace(
                        "closed form: flip times",
                        times,
                        np.zeros(times.size),
                        EXPECTED_COLOUR,
                        line=False,
                        marker="^",
                    )
                )
    return found


def _level(value: float, t_end: float, label: str) -> Trace:
    return Trace(
        label,
        np.array([0.0, t_end]),
        np.array([value, value]),
        EXPECTED_COLOUR,
        dash="1 3",
        width=1.2,
    )


ERROR_COLUMNS = ("error_x", "error_y", "error_z")
"""results.csv's signed world-frame error of a vector row: measured minus closed form."""

BAND_COLOUR = "#2e9d4a"
"""The tolerance band's legend sample (the strip itself is ``svgchart.BAND_FILL``)."""


def _row_errors(rows: pd.DataFrame, metric: str, engines: list[str]) -> dict[str, np.ndarray]:
    """Engine -> the signed error vector of its ``metric`` row, for engines whose row has one."""
    mine = rows[rows["metric"] == metric]
    found = {}
    for engine in engines:
        row = mine[mine["engine"] == engine]
        if row.empty or not all(c in row for c in ERROR_COLUMNS):
            continue
        error = pd.to_numeric(row.iloc[0][list(ERROR_COLUMNS)], errors="coerce").to_numpy(float)
        if np.isfinite(error).any():
            found[engine] = error
    return found


def _worst_component(record: dict, errors: dict[str, np.ndarray]) -> str:
    """The component where the engines' errors are largest; where every error is zero, the
    first the closed form sets (``_component``)."""
    with np.errstate(invalid="ignore"):
        worst = np.nanmax(np.abs(np.vstack(list(errors.values()))), axis=0)
    worst = np.where(np.isfinite(worst), worst, 0.0)
    if worst.max() > 0.0:
        return "xyz"[int(np.argmax(worst))]
    return (_component(record, CLOSED_FORMS[record["kind"]]) or ["z"])[0]


def _tolerance(rows: pd.DataFrame, metric: str) -> float | None:
    """The widest tolerance plus band of the ``metric`` rows (the band the check allows); None
    when no row has a tolerance."""
    mine = rows[rows["metric"] == metric]
    tolerance = pd.to_numeric(mine.get("tolerance"), errors="coerce")
    band = pd.to_numeric(mine.get("band", pd.Series(0.0, index=mine.index)), errors="coerce")
    allowed = (tolerance + band.fillna(0.0)).dropna()
    return float(allowed.max()) if not allowed.empty else None


def residual_chart(
    record: dict, quantity: str, lines: dict, rows: pd.DataFrame, engines: list[str]
) -> Chart | None:
    """One expectation's panel: measured minus closed form at its time (a marker per engine,
    the row's signed error in the component where it is largest), the same component of each
    engine's trace minus the closed form over time where the scene has one, and the band
    ±(tolerance + band) where the row passes. A failure at 200x its tolerance is a marker
    200 band-widths from zero."""
    if not isinstance(record.get("metric"), str):
        return None
    if quantity == "tilt":
        return _orientation_chart(record, lines, rows, engines)
    errors = _row_errors(rows, record["metric"], engines)
    if not errors:
        return None
    component = _worst_component(record, errors)
    index = "xyz".index(component)
    traces = _closed_form_residuals(record["body"], quantity, component, lines, engines)
    traces += [_row_marker(e, float(record["time"]), error[index]) for e, error in errors.items()]
    allowed = _tolerance(rows, record["metric"])
    traces += _residual_keys(allowed is not None)
    pattern, unit = QUANTITY_WORDS[quantity]
    return Chart(
        title=f"{record['metric']}: {pattern.format(c=component)} − closed form",
        xlabel="t (s)",
        ylabel=unit,
        traces=traces,
        band=None if allowed is None else (-allowed, allowed),
    )


def _orientation_chart(
    record: dict, lines: dict, rows: pd.DataFrame, engines: list[str]
) -> Chart | None:
    """An orientation expectation's panel: the row's angle to the closed form at its time
    (a marker per engine), each engine's largest body-axis angle to the closed form over time
    (where the scene has one), and the band [0, tolerance + band]."""
    mine = rows[rows["metric"] == record["metric"]]
    angles = {
        engine: float(error)
        for engine, error in zip(
            mine["engine"], pd.to_numeric(mine["error"], errors="coerce"), strict=True
        )
        if engine in engines and math.isfinite(error)
    }
    if not angles:
        return None
    traces = engine_lines(lines, record["body"], "tilt" + CLOSED_FORM_SUFFIX, engines, _largest)
    traces += [
        _row_marker(engine, float(record["time"]), angle) for engine, angle in angles.items()
    ]
    allowed = _tolerance(rows, record["metric"])
    return Chart(
        title=f"{record['metric']}: axis angle to the closed form",
        xlabel="t (s)",
        ylabel="rad",
        traces=[*traces, *_residual_keys(allowed is not None)],
        band=None if allowed is None else (0.0, allowed),
    )


def _row_marker(engine: str, time: float, error: float) -> Trace:
    """The row's measured minus closed form at the expectation's time, in the engine's colour."""
    return Trace(
        f"{engine}: measured − closed form",
        np.array([time]),
        np.array([error]),
        engine_style(engine).colour,
        line=False,
        marker="o",
        legend=False,
    )


def tilt_chart(body: str, lines: dict, engines: list[str]) -> Chart | None:
    """The body's tilt over time, one line per engine: the angle of its body axis that turns
    most (over the engines) from its initial direction."""
    found = [(e, lines[body, "tilt", e]) for e in engines if (body, "tilt", e) in lines]
    if not found:
        return None
    turned = np.nanmax([line[["x", "y", "z"]].to_numpy(float).max(axis=0) for _, line in found], 0)
    component = "xyz"[int(np.argmax(np.where(np.isfinite(turned), turned, -1.0)))]
    traces = engine_lines(lines, body, "tilt", engines, lambda line: line[component])
    pattern, unit = QUANTITY_WORDS["tilt"]
    return Chart(f"{pattern.format(c=component)} of {body} from its start", "t (s)", unit, traces)


def _residual_keys(banded: bool) -> list[Trace]:
    """Legend-only traces (no points) of a residual panel: the row's marker and the band."""
    empty = np.zeros(0)
    keys = [
        Trace(
            "measured − closed form (the row)",
            empty,
            empty,
            EXPECTED_COLOUR,
            line=False,
            marker="o",
        )
    ]
    if banded:
        keys.append(Trace("tolerance + band: passes inside", empty, empty, BAND_COLOUR))
    return keys


def _closed_form_residuals(
    body: str, quantity: str, component: str, lines: dict, engines: list[str]
) -> list[Trace]:
    """Each engine's traced ``component`` minus its closed form over time (trace.csv's
    ``CLOSED_FORM_SUFFIX`` quantities, where the scene has a closed form)."""
    quantity += CLOSED_FORM_SUFFIX
    return engine_lines(lines, body, quantity, engines, lambda line: line[component])


def _largest(line: pd.DataFrame) -> pd.Series:
    """The largest of a line's three axis angles at each time."""
    return line[["x", "y", "z"]].max(axis=1)


def engine_lines(lines: dict, body: str, quantity: str, engines: list[str], pick) -> list[Trace]:
    """One line per engine with a trace of (``body``, ``quantity``): ``pick(frame)`` over time,
    in the engine's colour and dash."""
    found = []
    for engine in engines:
        line = lines.get((body, quantity, engine))
        if line is None:
            continue
        line = line.sort_values("t", kind="stable")
        style = engine_style(engine)
        values = pick(line).to_numpy(float)
        found.append(Trace(engine, line["t"].to_numpy(float), values, style.colour, style.dash))
    return found


def closed_form_charts(
    scene: str,
    trace: pd.DataFrame | None,
    expectations: list[dict],
    engines: list[str],
    rows: pd.DataFrame | None = None,
) -> tuple[list[Chart], int]:
    """The scene's closed-form charts (at most ``MAX_CHARTS``) and how many were left out: one
    residual panel per expectation at a time (``residual_chart``, from the scene's ``rows``),
    then each engine's traced quantity over time for the other kinds (apex heights, levels
    after an impact, flips), in its colour, the closed form in black."""
    if not expectations:
        return [], 0
    mine = trace[trace["scenario"] == scene] if trace is not None else pd.DataFrame()
    lines = (
        dict(tuple(mine.groupby(["body", "quantity", "engine"], sort=False))) if len(mine) else {}
    )
    charts, absolute, every = [], [], expectations
    for record in expectations:
        chart = None
        if rows is not None and record["kind"] in RESIDUAL_KINDS:
            quantity = CLOSED_FORMS[record["kind"]].quantity
            chart = residual_chart(record, quantity, lines, rows, engines)
        if chart is None:
            absolute.append(record)
        else:
            charts.append(chart)
    panels, expectations = len(charts), absolute
    rotating = dict.fromkeys(b for b, q, _ in _groups(every) if q in ROTATION_QUANTITIES)
    tilts = [chart for body in rotating if (chart := tilt_chart(body, lines, engines))]
    charts += tilts
    groups = _groups(expectations)
    for (body, quantity, component), records in groups.items():
        found = [(e, lines[body, quantity, e]) for e in engines if (body, quantity, e) in lines]
        if not found:
            continue
        traces = []
        for engine, line in found:
            t = line["t"].to_numpy(float)
            order = np.argsort(t, kind="stable")
            style = engine_style(engine)
            values = line[component].to_numpy(float)[order]
            traces.append(Trace(engine, t[order], values, style.colour, style.dash))
        t_end = max(float(line["t"].max()) for _, line in found)
        pattern, unit = QUANTITY_WORDS[quantity]
        charts.append(
            Chart(
                title=f"{pattern.format(c=component)} of {body}",
                xlabel="t (s)",
                ylabel=unit,
                traces=[*traces, *_expected_traces(records, component, t_end)],
            )
        )
    total = panels + len(tilts) + len(groups)
    return charts[:MAX_CHARTS], max(0, total - MAX_CHARTS)
