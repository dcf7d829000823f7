"""Two versions of one engine compared (docs/two-engine-versions.md): the recipe's commands run
as written, offline. The engine is the example plugin (examples/engine_plugin) in two
versions, a release and a branch that changes one number of its flight; each goes into its
own venv with physval's wheel, runs one scene there into one history, and ``physval compare``
of the two run folders (and of the two run ids) names the row that moved and both versions."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest
from tiny_project import built_wheel, physval_wheel, run_ok, tiny_project, venv_with

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "engine_plugin"

RELEASE, BRANCH = "1.0.0", "1.1.0"
"""The plugin's two versions: venv A's and venv B's."""

ADAPTER = Path("physval_freeflight") / "adapter.py"
FLIGHT = "self.pos0 + self.vel0 * time + 0.5 * self.acceleration * time**2"
BRANCH_FLIGHT = "self.pos0 + self.vel0 * time + 0.6 * self.acceleration * time**2"
"""The branch's one change: the ballistic position off by a tenth of its gravity term, so
the fall's position error moves from rounding to centimetres."""

MOVED_METRIC = "position_error"
"""The fall's row that the branch's change moves beyond the noise."""


def plugin_version(folder: Path, version: str, flight: str) -> Path:
    """A copy of the example plugin at ``folder``, at ``version``, its flight written
    ``flight``; its wheel."""
    copy = folder / "physval_freeflight"
    folder.mkdir()
    shutil.copytree(EXAMPLE, copy)
    project = copy / "pyproject.toml"
    text = project.read_text()
    assert 'version = "0.1.0"' in text, "the example's version line"
    project.write_text(text.replace('version = "0.1.0"', f'version = "{version}"'))
    adapter = copy / ADAPTER
    assert FLIGHT in adapter.read_text(), "the example's flight line"
    adapter.write_text(adapter.read_text().replace(FLIGHT, flight))
    return built_wheel(copy, folder)


HISTORY = "history.sqlite"
"""The history both venvs' runs are recorded in (runs 1 and 2)."""

COMPARED = {"folders": ("runs/A", "runs/B"), "history ids": ("1", "2", "--db", HISTORY)}
"""The two ways the recipe compares the runs: their folders, or their ids in the history."""


@pytest.fixture(scope="module")
def recipe(tmp_path_factory) -> tuple[Path, dict]:
    """The recipe's runs, one per venv into one history: (the project, a shell's environment
    with venv B)."""
    work = tmp_path_factory.mktemp("versions")
    physval = physval_wheel(work)
    project = tiny_project(work / "project", "scenes")
    for name, version, flight in (("A", RELEASE, FLIGHT), ("B", BRANCH, BRANCH_FLIGHT)):
        plugin = plugin_version(work / f"plugin-{name}", version, flight)
        env = venv_with(work / f"venv-{name}", physval, plugin)
        run_ok(project, env, "physval", "run", "scenes", "--engines", "freeflight", "--jobs", "1",
               "--out", f"runs/{name}", "--history", f"sqlite:///{HISTORY}")  # fmt: skip
    return project, env


@pytest.fixture(scope="module", params=COMPARED, ids=str)
def compared(recipe, request) -> tuple[str, list[dict]]:
    """``physval compare`` of the two runs: (what it printed, compare.csv's rows)."""
    project, env = recipe
    out = f"compare-{request.param.replace(' ', '-')}"
    done = run_ok(project, env, "physval", "compare", *COMPARED[request.param], "--out", out)
    with (project / out / "compare.csv").open() as rows:
        return done.stdout, list(csv.DictReader(rows))


def test_compare_reports_the_row_the_branch_moved(compared):
    _, rows = compared
    moved = [(r["scenario"], r["engine"], r["metric"]) for r in rows]
    assert ("fall", "freeflight", MOVED_METRIC) in moved, moved


def test_compare_names_both_versions_in_its_output_and_its_rows(compared):
    printed, rows = compared
    assert f"engine versions differ: freeflight {RELEASE} → {BRANCH}" in printed, printed
    versions = {(r["engine_version_a"], r["engine_version_b"]) for r in rows}
    assert versions == {(RELEASE, BRANCH)}, versions


def test_the_history_page_names_both_versions(recipe):
    project, env = recipe
    done = run_ok(project, env, "physval", "history", "--db", HISTORY)
    page = Path(project, done.stdout.splitlines()[-1]).read_text()
    assert RELEASE in page and BRANCH in page
