"""The HTML report: content, self-containment, atomic writing, the CLI entry and a real browser.

The run folder is the synthetic one of ``report_fixtures`` (2 scenes × 3 engines with a
failed row, an unstable run, a model mismatch, rows without tolerance, series, impacts).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from markupsafe import escape
from report_fixtures import (
    ENGINES,
    FAILED,
    MISMATCH_MESSAGE,
    MODEL_MISMATCH,
    PROVENANCE,
    SCENES,
    UNSTABLE,
    write_synthetic_run,
)

from validation import files
from validation.measure.definitions import (
    EXPECTATION_DEFINITIONS,
    INTERPOLATION_BOUND,
    METRIC_DEFINITIONS,
    SIGNED_ERROR_DEFINITION,
)
from validation.report import build, render
from validation.report.outcomes import GREEN, RED
from validation.report.svgchart import _runs, thin_line
from validation.report.templating import compact

RUN_FILES = {"results.csv", "series.csv", "impacts.csv", "trace.csv", "provenance.json"}
URL_ATTRIBUTES = {"src", "href", "xlink:href", "srcset", "action", "formaction", "data", "poster"}
"""Attributes whose value a browser fetches or navigates to."""


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> tuple[Path, str]:
    """The synthetic run rendered once: (run folder, report.html text)."""
    run_dir = write_synthetic_run(tmp_path_factory.mktemp("run"))
    path = render.render_report(run_dir)
    assert path == run_dir / "report.html"
    return run_dir, path.read_text(encoding="utf-8")


class TagCollector(HTMLParser):
    """Every start tag with its attributes, in document order."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str]]] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, {k: v or "" for k, v in attrs}))

    handle_startendtag = handle_starttag


def tags_of(html: str) -> list[tuple[str, dict[str, str]]]:
    collector = TagCollector()
    collector.feed(html)
    return collector.tags


def matrix_cells(html: str) -> dict[tuple[str, str], dict[str, str]]:
    """(scene, engine) -> the matrix cell's attributes (outcome, link, title)."""
    table = re.search(r'<table class="matrix" id="matrix-table">(.*?)</table>', html, re.S)
    assert table, "no matrix table"
    header, body = table.group(1).split("<tbody>")
    engines = [escape(e) for e in ENGINES]
    assert all(str(e) in header for e in engines), header
    cells = {}
    for row in re.findall(r"<tr>(.*?)</tr>", body, re.S):
        scene = re.search(r'<th class="scene"[^>]*><a href="#[^"]+">(.*?)</a>', row).group(1)
        tds = re.findall(
            r'<td class="o-(\w+)" data-outcome="\w+" title="[^"]*"><a href="#([^"]+)">', row
        )
        assert len(tds) == len(ENGINES), row
        for engine, (outcome, anchor) in zip(ENGINES, tds, strict=True):
            cells[scene, engine] = {"outcome": outcome, "anchor": anchor}
    return cells


# ------------------------------------------------------------------------------ content


def test_the_matrix_has_every_scene_and_engine_and_marks_the_bad_cells(rendered):
    _, html = rendered
    cells = matrix_cells(html)
    assert set(cells) == {(s, e) for s in SCENES for e in ENGINES}
    assert cells[FAILED[:2]]["outcome"] == "failed"
    assert cells[UNSTABLE]["outcome"] == "unstable"
    assert cells[MODEL_MISMATCH]["outcome"] == "model_mismatch"
    assert cells[SCENES[0], ENGINES[0]]["outcome"] == "passed"
    # the worst scene comes first: the model mismatch outranks the unstable run
    assert list(dict.fromkeys(s for s, _ in cells)) == [SCENES[0], SCENES[1]]
    ids = {attrs.get("id") for _, attrs in tags_of(html)}
    for (scene, _), cell in cells.items():
        assert cell["anchor"] in ids, f"{scene}: the cell links to a missing section"


def test_each_scene_has_a_section_with_a_plot_impacts_and_its_rows(rendered):
    _, html = rendered
    sections = re.findall(r'<section class="scene" id="([^"]+)">(.*?)\n</section>', html, re.S)
    assert [re.search(r"<h3>(\S+)", body).group(1) for _, body in sections] == list(SCENES)
    for _, body in sections:
        for engine in ENGINES:
            assert str(escape(engine)) in body
    titles = {
        name: re.findall(r'<svg class="chart"[^>]*><title>(.*?)</title>', body)
        for name, body in zip(SCENES, (b for _, b in sections), strict=True)
    }
    # the quantities under test against their closed forms, then a conserved quantity whose
    # drift row did not pass everywhere (the spin's energy: no tolerance in mini; every other
    # drift passed, a flat line that says no more than its rows), then e against impact speed
    assert titles[SCENES[0]] == [
        "z(t) of ball",
        "v_z(t) of ball",
        "e measured against impact speed",
    ], titles
    assert titles[SCENES[1]] == ["body-frame ω_y(t) of box", "energy E (J)"], titles
    bounce = sections[0][1]
    assert "e requested" in bounce and "0.42" in bounce  # mujoco's measured restitution
    assert "band" in bounce
    assert "restitution_error" in bounce and "8×" in bounce  # error 0.08, tolerance 0.01
    assert "no tolerance" in bounce and "unsupported" in sections[1][1]


def test_the_legend_defines_every_metric(rendered):
    _, html = rendered
    legend = html[html.index('<section id="legend">') :]
    for name, definition in METRIC_DEFINITIONS.items():
        assert f'id="metric-{name}"' in legend
        assert str(escape(definition)) in legend, name
    for kind, definition in EXPECTATION_DEFINITIONS.items():
        assert f'id="expectation-{kind}"' in legend and str(escape(definition)) in legend
    assert 'href="#expectation-bounce_heights"' in html  # the row's metric links to it
    # how a number is read: the signed error's columns and the interpolant between steps
    assert str(escape(SIGNED_ERROR_DEFINITION)) in legend and "error_z" in legend
    assert str(escape(INTERPOLATION_BOUND)) in legend and "Hermite" in legend


def test_provenance_and_summary_are_shown(rendered):
    _, html = rendered
    block = html[html.index('<section id="provenance">') :]
    for value in (PROVENANCE["command"], PROVENANCE["git_commit"], PROVENANCE["created"]):
        assert str(escape(value)) in block
    for value in PROVENANCE["machine"].values():
        assert str(escape(str(value))) in block
    for label, info in PROVENANCE["engines"].items():
        assert str(escape(label)) in block and info["version"] in block
        for key in info["settings"]:
            assert key in block
        for note in info["notes"]:
            assert str(escape(note)) in block
    summary = html[: html.index('<section id="matrix">')]
    assert "3 of 6 runs need a look" in summary
    for word in ("failed", "unstable", "model_mismatch", "passed", "no tolerance"):
        assert f">{word} <b>" in summary


def test_text_from_the_run_is_escaped(rendered):
    _, html = rendered
    assert "<clamped>" not in html
    assert str(escape(MISMATCH_MESSAGE)) in html


def test_the_page_fetches_nothing(rendered):
    _, html = rendered
    for tag, attrs in tags_of(html):
        assert tag not in ("script", "link", "img", "iframe", "object", "embed", "base"), tag
        for name, value in attrs.items():
            if name in URL_ATTRIBUTES:
                assert value.startswith("#"), f"<{tag} {name}={value!r}> leaves the page"
            if "url(" in value:
                assert re.fullmatch(r"url\(#[\w-]+\)", value.strip()), (tag, name, value)
    for match in re.finditer(r"url\(\s*([^)]*)\)", html):
        assert match.group(1).startswith("#"), match.group(0)
    assert "@import" not in html and "@font-face" not in html
    # the only network addresses left are SVG namespace names, which nothing fetches
    for match in re.finditer(r"(https?:)?//[\w.-]+\.\w+", html):
        before = html[max(0, match.start() - 20) : match.start()]
        assert re.search(r'xmlns(:\w+)?="$', before), f"network address {match.group(0)!r}"


def test_missing_optional_files_still_render(tmp_path):
    run_dir = write_synthetic_run(tmp_path)
    for name in ("series.csv", "impacts.csv", "provenance.json"):
        (run_dir / name).unlink()
    html = render.render_report(run_dir).read_text(encoding="utf-8")
    assert "no series.csv in this run" in html and "No impacts.csv in this run" in html
    assert "provenance.json: missing" in html
    assert str(escape(ENGINES[0])) in html[html.index('<section id="provenance">') :]


def test_thin_line_keeps_spikes_and_bounds_points():
    t = np.linspace(0, 1, 100_001)
    y = np.zeros_like(t)
    y[54_321] = 7.0
    y[-1] = np.inf
    tt, yy = thin_line(t, y, max_points=1000)
    assert tt.size <= 1000 and np.nanmax(yy) == 7.0 and np.all(np.diff(tt) > 0)
    assert np.isnan(yy[-1]) or tt[-1] < 1.0


def test_a_line_path_passes_through_every_drawn_point():
    """A line's path data (a move, then relative line-tos) read back as absolute pixels is the
    rounded points, less repeats, split at the gap."""
    rng = np.random.default_rng(7)
    x = np.cumsum(rng.uniform(0.0, 4.0, 60))
    y = rng.uniform(-50.0, 150.0, 60)
    y[30] = np.nan
    drawn = []
    for path in _runs(x, y):
        numbers = [float(v) for v in re.findall(r"-?[0-9.]+", path)]
        points = np.cumsum(np.reshape(numbers, (-1, 2)), axis=0)  # relative after the move
        drawn.append(points)
    for points, part in zip(drawn, (slice(0, 30), slice(31, 60)), strict=True):
        expected = np.column_stack([np.round(x[part]), np.round(y[part])])
        expected = expected[np.r_[True, np.any(np.diff(expected, axis=0) != 0, axis=1)]]
        assert np.array_equal(points, expected), f"path points {points} != {expected}"


def test_compact_pages_keep_preformatted_text():
    html = "<div>\n    <p>a</p>\n  <pre class=s>x\n    y</pre>\n\t<b>c</b></div>"
    assert compact(html) == "<div>\n<p>a</p>\n<pre class=s>x\n    y</pre>\n<b>c</b></div>"


# ------------------------------------------------------------------------------ writing


def test_no_temporary_file_is_left_behind(rendered):
    run_dir, _ = rendered
    assert {p.name for p in run_dir.iterdir()} == RUN_FILES | {"report.html"}


def test_a_failing_plot_leaves_the_previous_report_intact(tmp_path, monkeypatch):
    run_dir = write_synthetic_run(tmp_path)
    (run_dir / "report.html").write_text("previous report")

    def broken_plot(*args, **kwargs):
        raise RuntimeError("plotting failed")

    monkeypatch.setattr(build, "plot_scene_series", broken_plot)
    with pytest.raises(RuntimeError, match="plotting failed"):
        render.render_report(run_dir)
    assert (run_dir / "report.html").read_text() == "previous report"
    assert {p.name for p in run_dir.iterdir()} == RUN_FILES | {"report.html"}


def test_a_failing_rename_removes_the_temporary_file(tmp_path, monkeypatch):
    run_dir = write_synthetic_run(tmp_path)
    (run_dir / "report.html").write_text("previous report")

    def broken_replace(source, destination):
        raise OSError("disk gone")

    monkeypatch.setattr(files.os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk gone"):
        render.render_report(run_dir)
    assert (run_dir / "report.html").read_text() == "previous report"
    assert {p.name for p in run_dir.iterdir()} == RUN_FILES | {"report.html"}


# ------------------------------------------------------------------------------ command


def test_report_command_on_a_folder_without_results_returns_2(tmp_path, capsys):
    assert render.report_command(tmp_path) == 2
    captured = capsys.readouterr()
    assert captured.err == f"{tmp_path}: no results.csv (not a physval run folder)\n"
    assert captured.out == ""
    assert not (tmp_path / "report.html").exists()


def test_report_command_on_a_broken_results_file_returns_2(tmp_path, capsys):
    (tmp_path / "results.csv").write_text("scenario,engine\nbounce,mini\n")
    assert render.report_command(tmp_path) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "results.csv: missing columns metric" in err


def test_report_command_renders_a_run_folder(tmp_path, capsys):
    run_dir = write_synthetic_run(tmp_path)
    assert render.report_command(str(run_dir)) == 0
    assert capsys.readouterr().out == f"{run_dir / 'report.html'}\n"


# ------------------------------------------------------------------------------ browser

CHROMIUM = shutil.which("chromium") or (
    "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None
)
requires_chromium = pytest.mark.skipif(
    CHROMIUM is None and "CI" not in os.environ,
    reason="chromium is not installed (apt-get install -y chromium); required when CI is set",
)
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-logging=stderr",
    "--v=0",
    # never reach the network, whatever the browser tries (its own requests are filtered below)
    "--host-resolver-rules=MAP * ~NOTFOUND",
)
SCREEN = (1280, 2000)  # px, the screenshot's window
MIN_SCREENSHOT_BYTES = 30_000  # a blank 1280×2000 page is a few kB


def chromium(tmp_path: Path, name: str, *arguments: str) -> tuple[str, list[str]]:
    """Run headless Chromium; returns (stdout, URLs the page itself requested)."""
    if CHROMIUM is None:
        pytest.fail("CI is set but chromium is not installed: apt-get install -y chromium")
    net_log = tmp_path / f"{name}.netlog.json"
    done = subprocess.run(
        [
            CHROMIUM,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={tmp_path / f'profile-{name}'}",
            f"--log-net-log={net_log}",
            *arguments,
        ],
        capture_output=True,
        text=True,
        timeout=90,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    console = [line for line in done.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    # Chromium logs console.error at INFO:CONSOLE, and the page has no script at all: any
    # console line (let alone "Uncaught" or "ERROR:CONSOLE") is a defect.
    assert not console, console
    return done.stdout, page_requests(net_log)


def page_requests(net_log: Path) -> list[str]:
    """URLs requested by the page (the browser's own background requests have no origin)."""
    log = json.loads(net_log.read_text())
    start_job = log["constants"]["logEventTypes"]["URL_REQUEST_START_JOB"]
    return [
        event["params"]["url"]
        for event in log["events"]
        if event["type"] == start_job
        and event.get("params", {}).get("initiator") not in (None, "not an origin")
    ]


@requires_chromium
def test_chromium_detects_a_page_that_fetches(tmp_path):
    """The network check below works: a page with a remote image is caught."""
    page = tmp_path / "fetching.html"
    page.write_text('<html><body><img src="http://example.invalid/x.png"></body></html>')
    _, requests = chromium(tmp_path, "control", "--dump-dom", page.as_uri())
    assert requests == ["http://example.invalid/x.png"]


@requires_chromium
def test_chromium_renders_the_report(rendered, tmp_path):
    run_dir, _ = rendered
    url = (run_dir / "report.html").as_uri()
    dom, requests = chromium(tmp_path, "dom", "--dump-dom", url)
    assert 'id="matrix-table"' in dom and "<svg" in dom
    assert all(str(escape(scene)) in dom for scene in SCENES)
    assert requests == []

    shot = tmp_path / "report.png"
    _, requests = chromium(
        tmp_path, "shot", f"--screenshot={shot}", f"--window-size={SCREEN[0]},{SCREEN[1]}", url
    )
    assert requests == []
    data = shot.read_bytes()
    assert data.startswith(b"\x89PNG") and len(data) > MIN_SCREENSHOT_BYTES
    import matplotlib.image

    pixels = (matplotlib.image.imread(shot)[..., :3] * 255).round().astype(int)
    assert pixels.shape[:2] == (SCREEN[1], SCREEN[0])
    for colour in (RED, GREEN):  # the matrix's failing and passing cells
        rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
        assert (np.abs(pixels - rgb).max(axis=-1) <= 2).sum() > 1000, colour


def test_a_run_against_a_baseline_with_rows_it_lacks_still_renders(tmp_path, capsys):
    """The usual case when an engine or a metric is dropped: baseline.csv lists the rows the
    run lacks (class missing), with empty and textual cells; the report was lost (a number
    format on an empty cell) and ``physval report`` crashed."""
    run_dir = write_synthetic_run(tmp_path)
    (run_dir / "baseline.csv").write_text(
        "scenario,engine,metric,value,error,tolerance,status,outcome,engine_version,"
        "scene_sha256,baseline\n"
        "bounce,pybullet,energy_drift,0.002,0.002,0.01,ok,passed,3.2.7,abc,missing\n"
        "bounce,pybullet,restitution_error,,,,error,error,3.2.7,abc,missing\n"
    )
    assert render.report_command(run_dir) == 0, capsys.readouterr().err
    page = (run_dir / "report.html").read_text()
    news = page[page.index('id="news"') : page.index('id="matrix"')]
    assert "restitution_error" in news and "0.002" in news, news[:3000]
