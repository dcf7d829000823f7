"""report.html's charts and matrix as a reader sees them (issue 37, item 5).

A residual panel per expectation at a time: measured minus closed form over time, with the
band ±(tolerance + band), so a failure at 200x its tolerance is visibly outside its band; a
matrix of 14 engines that scrolls inside its own box; tick labels inside their charts. Checked
in headless Chromium at 1400 and 800 px: the page is copied with a measuring script appended
(the report itself has none), and the script's findings are read back from the dumped DOM.
The screenshots are written to ``tmp_path``.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest
from report_fixtures import ENGINES, SCENES, write_synthetic_run
from test_report import chromium, requires_chromium

from validation.engines.base import Trajectory
from validation.reference.newton_euler import reference_motion
from validation.report import render
from validation.report.closed_form import CLOSED_FORM_SUFFIX, trace_rows, traced
from validation.report.svgchart import Chart, Trace, figure_html
from validation.scenario.compiled import compile_scene
from validation.scenario.load import load_scenario

BOUNCE = SCENES[0]
MINI, MUJOCO = ENGINES[:2]
METRIC = "velocity_at.ball"
TOLERANCE = 1e-3
"""The fixture's velocity_at.ball tolerance (tests/report_fixtures.py)."""

FAILING_ERROR = 200 * TOLERANCE
"""mujoco's signed error v_z - closed form: 200x its tolerance, the issue's example."""

PASSING_ERROR = 1e-6
"""mini's signed error: well inside the band."""

EXTRA_ENGINES = tuple(f"plugin_engine_{i:02d}(solver=variant_{i})" for i in range(11))
"""With the fixture's three, a 14-engine matrix (the issue's case)."""

WIDTHS = (1400, 800)
"""px: the window widths the layout is checked at (the issue's)."""

WINDOW_HEIGHT = 3000
"""px: tall enough for the header, the matrix and the first scene's charts."""

SLACK_PX = 0.5
"""A box may reach this far past another (sub-pixel rounding of layout)."""

MEASURE = """
<script>
(() => {
  const vw = document.documentElement.clientWidth;
  const box = document.getElementById("matrix-scroll");
  const scrolls = [...document.body.querySelectorAll("*")].filter(
    (el) => ["auto", "scroll"].includes(getComputedStyle(el).overflowX));
  const name = (el) => el.tagName + (el.id ? "#" + el.id : "") +
    (typeof el.className === "string" && el.className ? "." + el.className : "");
  const wide = [];
  for (const el of document.body.querySelectorAll("*")) {
    if (el.tagName === "SCRIPT" || scrolls.some((s) => s !== el && s.contains(el))) continue;
    const r = el.getBoundingClientRect();
    if (r.width && (r.right > vw + SLACK || r.left < -SLACK)) wide.push([name(el), r.left, r.right]);
  }
  const charts = [];
  for (const svg of document.querySelectorAll("svg.chart")) {
    const s = svg.getBoundingClientRect();
    const title = svg.querySelector("title").textContent;
    const outside = [];
    for (const text of svg.querySelectorAll("text")) {
      const r = text.getBoundingClientRect();
      if (r.left < s.left - SLACK || r.right > s.right + SLACK ||
          r.top < s.top - SLACK || r.bottom > s.bottom + SLACK) outside.push(text.textContent);
    }
    const band = svg.querySelector("rect.band");
    const b = band ? band.getBoundingClientRect() : null;
    const markers = {};
    for (const path of svg.querySelectorAll("path")) {
      const t = path.querySelector("title");
      if (t && t.textContent.endsWith(": measured − closed form")) {
        const r = path.getBoundingClientRect();
        markers[t.textContent.split(": ")[0]] = (r.top + r.bottom) / 2;
      }
    }
    charts.push({title, outside, band: b && [b.top, b.bottom], markers});
  }
  const r = box ? box.getBoundingClientRect() : null;
  const result = {vw, page: document.documentElement.scrollWidth, wide, charts,
    box: box && {left: r.left, right: r.right, scroll: box.scrollWidth, client: box.clientWidth}};
  const pre = document.createElement("pre");
  pre.id = "layout-result";
  pre.textContent = JSON.stringify(result);
  document.body.appendChild(pre);
})();
</script>
""".replace("SLACK", str(SLACK_PX))


def _hard_charts() -> str:
    """Charts whose tick labels are long: 10-character y labels (a large value varying in its
    first decimal), 8-character x labels with the last tick on the plot's right edge, a log
    axis."""
    t = 1000.0 + np.linspace(0.0, 0.00962, 50)  # padded by 4 %: the axis ends on 1000.01
    cases = [
        ("large, varying in a decimal", t, -1234567.25 + 0.5 * np.sin(400 * t)),
        ("small and negative", t, -1.2345e-4 * (1 + np.cos(400 * t))),
        ("log speeds", np.logspace(-5, 3, 50), np.linspace(-0.001, 0.5, 50)),
    ]
    charts = [
        Chart(
            title, "t (s)", "unit", [Trace("line", x, y, "#0072B2")], xlog=title.startswith("log")
        )
        for title, x, y in cases
    ]
    return '<div class="charts">' + "".join(figure_html(c) for c in charts) + "</div>"


def _fourteen_engine_run(tmp_path):
    """The report fixture with mujoco's velocity_at.ball 200x its tolerance, both engines'
    signed errors and closed-form traces, and 11 more engines in the matrix."""
    run_dir = write_synthetic_run(tmp_path / "run")
    results = pd.read_csv(run_dir / "results.csv")
    for column in ("error_x", "error_y", "error_z"):
        results[column] = np.nan
    mini_row = (results["engine"] == MINI) & (results["metric"] == METRIC)
    results.loc[mini_row, ["error_x", "error_y", "error_z"]] = [0.0, 0.0, PASSING_ERROR]
    failing = results[mini_row].iloc[0].to_dict()
    failing.update(
        engine=MUJOCO,
        value=1.962 + FAILING_ERROR,
        error=FAILING_ERROR,
        passed=False,
        status="failed",
        error_z=FAILING_ERROR,
    )
    extra = [
        {**failing, "engine": engine, "metric": "energy_drift", "error": 1e-4, "tolerance": 1e-2}
        | {"passed": True, "status": "ok", "error_z": np.nan}
        for engine in EXTRA_ENGINES
    ]
    results = pd.concat([results, pd.DataFrame([failing, *extra])], ignore_index=True)
    results.to_csv(run_dir / "results.csv", index=False)
    t = np.linspace(0.0, 2.0, 201)
    residuals = {MINI: PASSING_ERROR * np.sin(t), MUJOCO: FAILING_ERROR * t / 0.2}
    trace = pd.read_csv(run_dir / "trace.csv")
    added = [
        pd.DataFrame(
            {
                "scenario": BOUNCE,
                "engine": engine,
                "body": "ball",
                "quantity": "vel-closed_form",
                "t": t,
                "x": 0.0,
                "y": 0.0,
                "z": values,
            }
        )
        for engine, values in residuals.items()
    ]
    pd.concat([trace, *added], ignore_index=True).to_csv(run_dir / "trace.csv", index=False)
    render.render_report(run_dir)
    return run_dir


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    return _fourteen_engine_run(tmp_path_factory.mktemp("charts"))


def _residual_svg(html: str) -> str:
    charts = re.findall(r'<svg class="chart".*?</svg>', html, re.S)
    mine = [c for c in charts if f"<title>{METRIC}: v_z(t) − closed form</title>" in c]
    assert len(mine) == 1, [re.search(r"<title>(.*?)</title>", c).group(1) for c in charts]
    return mine[0]


def _marker_y(svg: str, engine: str) -> float:
    match = re.search(
        rf'<path d="M[0-9.]+ ([0-9.]+)h0"[^>]*><title>{re.escape(engine)}: measured', svg
    )
    assert match, f"no marker of {engine}"
    return float(match.group(1))


def test_a_failure_at_200x_its_tolerance_is_outside_its_band(run_dir):
    """The residual panel's band is ±(tolerance + band) about zero; the passing engine's
    marker is inside it, the failing one's far outside (an absolute value, 1.962 m/s, would
    put both outside: the panel would look the same for both)."""
    svg = _residual_svg((run_dir / "report.html").read_text())
    band = re.search(
        r'<rect class="band" x="[0-9.]+" y="([0-9.]+)" width="[0-9.]+" '
        r'height="([0-9.]+)"',
        svg,
    )
    assert band, "no tolerance band"
    top, height = float(band.group(1)), float(band.group(2))
    inside = _marker_y(svg, MINI)
    outside = _marker_y(svg, MUJOCO)
    assert top <= inside <= top + height, (top, height, inside)
    # 200 band half-widths from zero: the band is a thin strip, the marker well away from it
    assert outside < top - 10 * height, (top, height, outside)
    assert f"<title>{MUJOCO}</title>" in svg  # its residual over time, a line


def _layout(run_dir, tmp_path, width: int) -> dict:
    page = tmp_path / f"measure-{width}.html"
    html = (run_dir / "report.html").read_text()
    page.write_text(html.replace("</body>", _hard_charts() + MEASURE + "</body>"))
    dom, requests = chromium(
        tmp_path,
        f"layout-{width}",
        "--dump-dom",
        f"--window-size={width},{WINDOW_HEIGHT}",
        page.as_uri(),
    )
    assert requests == []
    found = re.search(r'<pre id="layout-result">(.*?)</pre>', dom, re.S)
    assert found, dom[-2000:]
    return json.loads(
        found.group(1).replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">")
    )


@requires_chromium
@pytest.mark.parametrize("width", WIDTHS)
def test_the_report_fits_the_window_and_its_charts_keep_their_labels(run_dir, tmp_path, width):
    """At 1400 and 800 px: nothing wider than the window except inside a scroll box (the
    matrix's, which 14 engines overflow; a scene card's, for its rows table at 800 px), every chart's text inside its SVG, the residual panel's band drawn
    with the failing marker outside it. The screenshot is kept in tmp_path."""
    layout = _layout(run_dir, tmp_path, width)
    assert layout["wide"] == [], layout["wide"][:10]
    assert layout["page"] <= layout["vw"], layout
    box = layout["box"]
    assert box and box["right"] <= layout["vw"] + SLACK_PX
    assert box["scroll"] > box["client"], "14 engines should overflow the box (and scroll)"
    assert layout["charts"]
    for chart in layout["charts"]:
        assert chart["outside"] == [], (chart["title"], chart["outside"])
    residual = [c for c in layout["charts"] if c["title"].startswith(METRIC)]
    assert len(residual) == 1 and residual[0]["band"], layout["charts"]
    (top, bottom), markers = residual[0]["band"], residual[0]["markers"]
    assert top <= markers[MINI] <= bottom and not top <= markers[MUJOCO] <= bottom, residual
    shot = tmp_path / f"report-{width}.png"
    chromium(
        tmp_path,
        f"shot-{width}",
        f"--screenshot={shot}",
        f"--window-size={width},{WINDOW_HEIGHT}",
        "--hide-scrollbars",
        (run_dir / "report.html").as_uri(),
    )
    assert shot.read_bytes().startswith(b"\x89PNG")


def _turning_about_x(rate: float, end: float) -> Trajectory:
    """One body turning about the world x axis at ``rate`` rad/s from the identity."""
    t = np.linspace(0.0, end, 301)
    half = rate * t / 2
    quat = np.stack([np.cos(half), np.sin(half), 0 * t, 0 * t], axis=-1)[:, None, :]
    zeros = np.zeros((t.size, 1, 3))
    return Trajectory(t, zeros, quat, zeros, np.tile([rate, 0.0, 0.0], (t.size, 1, 1)))


def test_the_tilt_is_each_body_axis_angle_from_its_start():
    """A body turning about x: its y and z axes tilt by the angle turned (to π/2 at the end),
    its x axis not at all; without a closed form no residual rows are written."""
    frame = trace_rows("s", "mini", _turning_about_x(1.0, np.pi / 2), ["box"], [("box", "tilt")])
    assert set(frame["quantity"]) == {"tilt"}
    np.testing.assert_allclose(frame["x"], 0.0, atol=1e-7)
    np.testing.assert_allclose(frame["y"], frame["t"], atol=1e-7)
    np.testing.assert_allclose(frame["z"], frame["t"], atol=1e-7)
    assert frame["y"].iloc[-1] == pytest.approx(np.pi / 2)


def test_a_run_on_its_closed_form_traces_zero_residuals():
    """trace.csv's residuals of a scene with a closed form over time (nothing touches): a
    trajectory that is the closed form itself traces zeros for every residual quantity the
    scene's panels draw (position, ω and the orientation's axis angles), none for the rest."""
    scene = compile_scene(load_scenario("scenarios/rotation/spin_between_steps.yaml"))
    motion = reference_motion(scene, np.linspace(0.0, 1.0, 200))
    exact = Trajectory(motion.t, motion.pos, motion.quat, motion.vel, motion.ang_vel)
    bodies = [body.name for body in scene.scenario.bodies]
    frame = trace_rows(scene.name, "mini", exact, bodies, traced(scene.scenario.expect), scene)
    residuals = frame[frame["quantity"].str.endswith(CLOSED_FORM_SUFFIX)]
    assert set(residuals["quantity"]) == {
        "pos-closed_form",
        "ang_vel-closed_form",
        "tilt-closed_form",
    }
    np.testing.assert_allclose(residuals[["x", "y", "z"]].to_numpy(float), 0.0, atol=1e-6)
