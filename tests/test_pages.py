"""What every page shows and how: one colour per engine spec on every page, tick labels that
are values (never an offset), one stylesheet, the compare page grouped by scene with its
missing and unchanged rows folded, known reasons on the report, the quantity under test
against its closed form in a real run, and the library-sized report within its 2 MB."""

from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from markupsafe import escape
from report_fixtures import ENGINES, KNOWN_REASON, SCENES, write_synthetic_run
from test_history import night, row, write_run

from validation.cli import main
from validation.contract import EXIT_OK
from validation.nightly import compare, history, history_page
from validation.nightly.pages import render_page
from validation.report import render
from validation.report.palette import SPEC_STYLES, engine_colour
from validation.report.svgchart import Chart, Trace, render_chart, tick_labels
from validation.report.sweep_page import render_sweep
from validation.report.templating import ENVIRONMENT, compact

HEX = r"#[0-9A-Fa-f]{6}"


@pytest.fixture(scope="module")
def report_html(tmp_path_factory) -> str:
    run_dir = write_synthetic_run(tmp_path_factory.mktemp("run"))
    return render.render_report(run_dir).read_text(encoding="utf-8")


def sweep_rows() -> list[dict]:
    """sweep.csv rows of one scene in two engine specs: a converging curve, a floor-bound
    point and a failed one; orientation identically zero in every engine."""
    rows = []
    for engine, slope in (("mini", 1.0), ("mujoco(integrator=RK4)", 4.0)):
        for k, dt in enumerate((8e-3, 4e-3, 2e-3, 1e-3)):
            error = 0.5 * (dt / 8e-3) ** slope
            role = "floor" if engine != "mini" and k == 3 else "fitted"
            status = "unstable" if engine == "mini" and k == 0 else "ok"
            common = {
                "scenario": "spin",
                "engine": engine,
                "dt": dt,
                "steps": 1 / dt,
                "expected_kind": "reference:dop853",
                "status": status,
                "wall_time_s": 0.01 / dt * 1e-3,
                "real_time_factor": 1.0,
            }
            rows.append(
                {
                    **common,
                    "metric": "position_error",
                    "value": error,
                    "error": np.nan if status != "ok" else error,
                    "fit_role": role,
                    "message": "",
                }
            )
            rows.append(
                {
                    **common,
                    "metric": "orientation_error",
                    "value": 0.0,
                    "error": 0.0,
                    "fit_role": "unmeasured",
                    "message": "identically zero at every dt: the reference cannot see this motion",
                }
            )
    return rows


# --- one colour per engine spec --------------------------------------------------------------


def line_colours(html: str, label: str = r"[^<]+") -> dict[str, set[str]]:
    """Each line's title (its engine) -> the stroke colours it is drawn in (a line's path is a
    move and relative line-tos only: markers draw with h, m or z too)."""
    found: dict[str, set[str]] = {}
    pattern = (
        rf'<path d="M[-0-9. ]+(?:l[-0-9. ]*)?" fill="none" stroke="({HEX})"[^>]*>'
        rf"<title>({label})</title>"
    )
    for colour, title in re.findall(pattern, html):
        found.setdefault(title, set()).add(colour)
    return found


def test_the_library_specs_have_distinct_colours():
    colours = [style.colour for style in SPEC_STYLES.values()]
    assert len(set(colours)) == len(colours), SPEC_STYLES


def test_one_colour_per_engine_spec_on_the_report_sweep_and_history_pages(report_html, tmp_path):
    """The same spec is drawn in the same colour on every page, whatever its position in the
    run (the report lists mini(gyroscopic=implicit) first, the sweep mini first)."""
    drawn: dict[str, set[str]] = {}
    for engine, colours in line_colours(report_html).items():
        if engine in ENGINES:
            drawn.setdefault(engine, set()).update(colours)
    sweep = render_sweep(sweep_rows(), tmp_path / "sweep.html").read_text()
    for title, colours in line_colours(sweep).items():
        drawn.setdefault(title.rsplit(" (", 1)[0], set()).update(colours)
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    for day in (1, 2):
        rows = [
            row("projectile", engine, "energy_drift", 1e-3 * day) for engine in ("mini", "mujoco")
        ]
        history.record_run(write_run(tmp_path / f"r{day}", rows, night(day)), url)
    assert main(["history", "--db", url, "--out", str(tmp_path / "h.html")]) == EXIT_OK
    page = (tmp_path / "h.html").read_text()
    for engine, colour in re.findall(
        rf'<tr id="[^"]+"><td>([^<]+)</td>.*?<polyline fill="none" stroke="({HEX})"', page, re.S
    ):
        drawn.setdefault(engine, set()).add(colour)
    assert {"mini", "mujoco", "mujoco(integrator=RK4)", *ENGINES} <= set(drawn), drawn
    for engine, colours in drawn.items():
        assert colours == {engine_colour(engine)}, f"{engine}: drawn in {colours}"


# --- tick labels are values -------------------------------------------------------------------

OFFSET_TEXT = re.compile(r"^[+−-]?\s*[0-9.]+e[−-]?\d+\s*[+−-]|^[+]|×\s*10")
"""matplotlib's offset and multiplier texts: ``1e−12+5e−1``, ``+2``, ``×10⁻³``."""


def svg_texts(svg: str) -> list[str]:
    return [t.strip() for t in re.findall(r"<text[^>]*>([^<]*)</text>", svg) if t.strip()]


def test_a_chart_of_a_quantity_constant_to_round_off_labels_its_ticks_with_values():
    t = np.linspace(0.0, 1.0, 50)
    flat = 0.5 + 1e-12 * np.sin(t)  # energy conserved to round-off
    svg = render_chart(Chart("E", "t (s)", "J", [Trace("mini", t, flat, "#000000")]))
    labels = re.findall(
        r"<text[^>]*>([^<]*)</text>", svg.split('<g class="ticks">')[1].split("</g>")[0]
    )
    values = [float(label.replace("−", "-")) for label in labels]  # each one a plain number
    assert not [text for text in labels if OFFSET_TEXT.search(text)], labels
    assert any(abs(v - 0.5) < 1e-5 for v in values), labels
    assert tick_labels([200.0, 200.5, 201.0]) == ["200", "200.5", "201"]  # not +2 / 0.5


def test_the_history_trend_plot_has_no_offset_text(tmp_path):
    runs = pd.DataFrame(
        {"id": [1, 2, 3], "created": [night(d) for d in (1, 2, 3)], "commit": ["a1", "b2", "c3"]}
    )
    view = history_page.SeriesView(
        scenario="projectile",
        engine="mujoco",
        metric="energy_drift",
        anchor="s",
        quantity="value",
        values=np.array([0.5, 0.5 + 1e-12, 0.5 + 2e-12]),
        kinds=np.zeros(3, dtype=int),
        tolerance=np.nan,
        steps=[],
        version_changes=[],
    )
    svg = history_page.trend_plot(view, runs)
    texts = svg_texts(svg)
    assert not [text for text in texts if OFFSET_TEXT.search(text)], texts
    assert "1" in texts and any("2025-01-02" in text for text in texts), texts  # run · date


# --- one stylesheet ------------------------------------------------------------------------------


def style_of(html: str) -> str:
    return re.search(r"<style>(.*?)</style>", html, re.S).group(1)


def test_every_page_uses_the_shared_stylesheet(report_html, tmp_path):
    shared = compact(ENVIRONMENT.get_template("style.css").render()).strip()
    assert "figure.chart" in shared and ".o-failed" in shared
    sweep = render_sweep(sweep_rows(), tmp_path / "sweep.html").read_text()
    compare = render_page("compare.html.j2", compare_context(tmp_path))
    for name, page in (("report", report_html), ("sweep", sweep), ("compare", compare)):
        assert style_of(page).strip().startswith(shared), f"{name}.html lacks the shared stylesheet"
        assert "<script" not in page and "http" not in style_of(page), name


def test_the_sweep_page_leads_with_charts_and_collapses_zero_metrics(tmp_path):
    page = render_sweep(sweep_rows(), tmp_path / "sweep.html").read_text()
    scene = page[page.index('<section class="scene"') :]
    assert scene.index('<svg class="chart"') < scene.index("<table"), "charts first"
    assert "Identically zero in every engine (not drawn): <code>orientation_error</code>" in scene
    assert scene.count("<h3>orientation_error</h3>") == 0  # one line, no section
    assert "1 points floor-bound or saturated" in scene  # the RK4 point at its floor, marked
    assert 'class="point-role" title="floor-bound: left out of the order fit"' in scene
    assert "#c0392b" in scene  # the failed point's red cross


# --- compare: grouped by scene, folded ---------------------------------------------------------


def compare_context(tmp_path: Path) -> dict:
    """compare.html's context for two runs: bounce regressed, spin unchanged, drop missing."""
    a = [
        row("bounce", "mini", "e", 1e-3),
        row("spin", "mini", "drift", 1e-4),
        row("drop", "mini", "z", 1e-3),
    ]
    b = [row("bounce", "mini", "e", 5e-3), row("spin", "mini", "drift", 1e-4)]
    folders = [write_run(tmp_path / f"c{i}", rows, night(i + 1)) for i, rows in enumerate((a, b))]
    out = tmp_path / "cmp"
    assert main(["compare", *map(str, folders), "--selection", "all", "--out", str(out)]) == 0

    shared = compare.shared_rows(
        *(compare.resolve_run(str(f), "sqlite://") for f in folders), "all"
    )  # as --selection all: every row of both runs
    every = compare.classified_rows(shared.a, shared.b)
    moved = every[every["change"] != "unchanged"].reset_index(drop=True)
    context = compare.build_context(
        shared.a, shared.b, moved, every[every["change"] == "unchanged"]
    )
    return {**context, "selection": compare.selection_context(shared)}


def test_the_compare_page_groups_by_scene_and_folds_missing_and_unchanged(tmp_path):
    page = render_page("compare.html.j2", compare_context(tmp_path))
    groups = re.findall(r'<details class="group scene-group"( open)?>\s*<summary>(\w+)', page)
    assert groups == [(" open", "bounce"), ("", "drop"), ("", "spin")], groups
    drop = page[page.index("<summary>drop") : page.index("<summary>spin")]
    assert '<details class="folded missing-rows"><summary>missing: 1 rows' in drop
    spin = page[page.index("<summary>spin") :]
    assert '<details class="folded unchanged-rows"><summary>unchanged: 1 rows' in spin
    assert "2025-01-01T02:00:00" in page and "2025-01-02T02:00:00" in page  # the runs' dates
    assert 'class="regressed">regressed' in page and "unchanged <b>1</b>" in page


# --- the report -------------------------------------------------------------------------------


def test_each_known_row_shows_its_reason_and_each_card_its_scene(report_html):
    spin = report_html[report_html.index(f"<h3>{SCENES[1]}") :]
    assert f"<b>known:</b> {escape(KNOWN_REASON)}" in spin
    card = report_html[report_html.index(f"<h3>{SCENES[0]}") :]
    assert card.index(
        '<p class="description">A ball dropped from 1.1 m bounces &lt;twice&gt;'
    ) < card.index("<table")
    assert "scene file <code>scenarios/formulas/bounce_ladder.yaml</code>" in card
    # rows with no tolerance and a value of exactly zero are one line, not one row each
    assert (
        "2 rows with no tolerance are identically zero: <code>linear_momentum_drift</code>" in card
    )


DROP_SCENE = """\
    description: A ball dropped from 1.1 m onto a ground with e = 0.5.
    dt: 1.0e-3
    duration: 1.2
    ground: {restitution: 0.5, friction: 0.0}
    engines: [mini]
    bodies:
      - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, restitution: 0.5, position: [0.0, 0.0, 1.1]}
    expect:
      - {kind: bounce_heights, body: ball, value: [0.35]}
      - {kind: velocity_at, body: ball, time: 0.2, value: [0.0, 0.0, -1.962]}
    checks:
      bounce_heights.ball: 0.01
      velocity_at.ball: 1.0e-6
"""
"""A bounce scene with a velocity_at expectation: its apex from h = r + e²(h0 - r) = 0.35 m,
its velocity -g t at 0.2 s (in free fall until 0.45 s)."""


def test_a_real_run_charts_the_apex_and_the_velocity_against_their_closed_forms(tmp_path):
    scene = tmp_path / "drop.yaml"
    scene.write_text(textwrap.dedent(DROP_SCENE))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == EXIT_OK
    trace = pd.read_csv(out / "trace.csv")
    assert set(zip(trace["body"], trace["quantity"], strict=True)) == {
        ("ball", "pos"),
        ("ball", "vel"),
    }
    expect = json.loads((out / "provenance.json").read_text())["scenes"]["drop"]["expect"]
    assert [e["kind"] for e in expect] == ["bounce_heights", "velocity_at"]
    html = (out / "report.html").read_text()
    charts = dict(
        re.findall(r'<svg class="chart"[^>]*><title>([^<]+)</title>(.*?)</svg>', html, re.S)
    )
    assert (
        "mini" in charts["z(t) of ball"]
        and "closed form: expected apexes" in charts["z(t) of ball"]
    )
    # velocity_at: measured minus closed form at 0.2 s, in its tolerance band (a bounce scene
    # has no closed form over time: the row's marker alone)
    residual = charts["velocity_at.ball: v_z(t) − closed form"]
    assert "mini: measured − closed form" in residual and '<rect class="band"' in residual


# --- size ---------------------------------------------------------------------------------------

LIBRARY_SCENES = 42
"""Scenes of the bundled library (measured: ``physval run`` writes 42 scene cards)."""

LIBRARY_ROWS_PER_SCENE = 35
"""results.csv rows per scene: the library's 1,481 rows over 42 scenes."""

REPORT_BUDGET_BYTES = 2_000_000
"""The library's report.html may weigh at most 2 MB (the report's size target)."""


BODIES_PER_SCENE = 3
"""Bodies under test per scene card (each two closed-form charts in a bounce scene): the
library's 232 charts and 869 lines over 42 cards (measured), about 5.5 and 21 per card."""


def scaled_run(run_dir: Path) -> Path:
    """The synthetic run scaled to the library: ``LIBRARY_SCENES`` copies of its two scenes,
    each with ``LIBRARY_ROWS_PER_SCENE`` rows, noisy series, and ``BODIES_PER_SCENE`` bodies
    under test traced in every engine (noisy too: a real curve never thins to two points); its
    provenance lists every copy's description and expectations."""
    base = write_synthetic_run(run_dir.parent / "base")
    tables = {name: pd.read_csv(base / f"{name}.csv") for name in ("results", "series", "impacts")}
    trace = pd.read_csv(base / "trace.csv")
    provenance = json.loads((base / "provenance.json").read_text())
    rng = np.random.default_rng(0)
    scaled = {name: [] for name in (*tables, "trace")}
    scenes = {}
    for k in range(LIBRARY_SCENES):
        source = SCENES[k % 2]
        name = f"{source}_{k}"
        entry = provenance["scenes"][source]
        original = trace[(trace["scenario"] == source) & (trace["engine"] == ENGINES[0])]
        body = str(original["body"].iloc[0])
        expect = []
        for b in range(BODIES_PER_SCENE):
            expect += [{**e, "body": f"{body}_{b}"} for e in entry["expect"]]
            for engine in ENGINES:
                noisy = original.assign(scenario=name, engine=engine, body=f"{body}_{b}")
                for axis in "xyz":
                    noisy[axis] = noisy[axis] * (1 + 1e-2 * rng.standard_normal(len(noisy)))
                scaled["trace"].append(noisy)
        scenes[name] = {**entry, "expect": expect}
        for table, frame in tables.items():
            mine = frame[frame["scenario"] == source].assign(scenario=name)
            if table == "results":
                extra = mine[mine["metric"] != "status"]
                copies = [
                    extra.assign(metric=extra["metric"] + f".{i}")
                    for i in range(LIBRARY_ROWS_PER_SCENE // len(extra))
                ]
                mine = pd.concat([mine, *copies]).head(LIBRARY_ROWS_PER_SCENE)
            if table == "series":
                noise = 1e-3 * rng.standard_normal(len(mine))
                mine = mine.assign(energy=mine["energy"] * (1 + noise))
            scaled[table].append(mine)
    run_dir.mkdir()
    for table, frames in scaled.items():
        pd.concat(frames).to_csv(run_dir / f"{table}.csv", index=False)
    (run_dir / "provenance.json").write_text(json.dumps({**provenance, "scenes": scenes}))
    return run_dir


def test_a_library_sized_report_stays_within_2_mb(tmp_path):
    run_dir = scaled_run(tmp_path / "library")
    rows = pd.read_csv(run_dir / "results.csv")
    assert rows["scenario"].nunique() == LIBRARY_SCENES and len(rows) >= 1400, len(rows)
    html = render.render_report(run_dir).read_text(encoding="utf-8")
    charts = html.count('<svg class="chart"')
    assert charts >= 5 * LIBRARY_SCENES, f"only {charts} charts: not the library's load"
    size = len(html.encode("utf-8"))
    assert size <= REPORT_BUDGET_BYTES, f"report.html weighs {size:,} bytes ({charts} charts)"


def test_malformed_expectations_and_huge_traced_values_render_with_a_warning(tmp_path):
    """provenance.json and trace.csv are read back as untrusted data: an expectation of the
    wrong shape is left out with a warning, a traced value of 1e308 is a gap, not a crash."""
    run_dir = write_synthetic_run(tmp_path / "run")
    provenance = json.loads((run_dir / "provenance.json").read_text())
    provenance["scenes"][SCENES[0]]["expect"] += [
        {"kind": "velocity_at", "body": "ball", "time": 0.3, "value": [1.0]},  # not a vector
        {"kind": "velocity_at", "body": "ball", "time": "soon", "value": [0, 0, 1]},
        "not a record",
    ]
    (run_dir / "provenance.json").write_text(json.dumps(provenance))
    trace = pd.read_csv(run_dir / "trace.csv")
    trace.loc[trace.index[:3], "z"] = [1e308, -1e308, np.inf]
    trace.to_csv(run_dir / "trace.csv", index=False)
    html = render.render_report(run_dir).read_text(encoding="utf-8")
    assert f"scenes.{SCENES[0]}.expect: 3 expectations not of the form the run writes" in html
    assert "z(t) of ball" in html and "v_z(t) of ball" in html
