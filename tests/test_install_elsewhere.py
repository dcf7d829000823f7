"""physval installed into another project: a wheel built from this checkout, installed with
``--no-deps`` into a fresh venv outside it, runs a scene folder of that project and the
bundled scene library (which ships inside the wheel), with the checkout nowhere on the path.

The venv takes numpy, MuJoCo, PyBullet... from this interpreter's environment (a ``.pth``
line naming its site-packages; ``.pth`` files there, such as an editable install of physval,
are not run), so nothing is downloaded."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest
from tiny_project import physval_wheel, run_ok, tiny_project, venv_with

from validation.bundled import BUNDLED_SCENARIOS
from validation.contract import RESULTS_FILE

ROOT = Path(__file__).resolve().parent.parent

LIBRARY_SCENE = "bounce_impact_times"
"""A bundled scene that runs in a fraction of a second in mini."""


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, Path, dict]:
    """(the wheel, the other project's folder, the environment of a shell there: the venv first
    on PATH, no PYTHONPATH)."""
    work = tmp_path_factory.mktemp("elsewhere")
    wheel = physval_wheel(work)
    env = venv_with(work / "venv", wheel)
    project = tiny_project(work / "project", "scenes")
    return wheel, project, env


def test_the_wheel_ships_the_scene_library_and_every_data_file_of_the_package(installed):
    wheel, _, _ = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    library = sorted(p for p in BUNDLED_SCENARIOS.rglob("*") if p.suffix in (".yaml", ".md"))
    assert library, BUNDLED_SCENARIOS
    shipped = [f"validation/library/{p.relative_to(BUNDLED_SCENARIOS)}" for p in library]
    data = [  # templates, style sheets: what a run reads besides code
        str(p.relative_to(ROOT))
        for package in ("validation", "mini_engine")
        for p in (ROOT / package).rglob("*")
        if p.is_file() and p.suffix not in (".py", ".pyc") and "library" not in p.parts
    ]
    assert data, "the package's templates"
    assert not [name for name in [*shipped, *data] if name not in names]


def test_the_installed_package_imports_from_the_venv_not_the_checkout(installed):
    _, project, env = installed
    imports = "import validation, mini_engine; print(validation.__file__, mini_engine.__file__)"
    done = run_ok(project, env, "python", "-c", imports)
    files = [Path(f) for f in done.stdout.split()]
    assert all("site-packages" in f.parts and ROOT not in f.parents for f in files), files


def test_physval_runs_the_projects_scenes_and_the_bundled_library(installed):
    _, project, env = installed
    quiet = ("--jobs", "1", "--history", "none")
    run_ok(project, env, "physval", "run", "scenes", "--out", "reports/latest", *quiet,
         "--junit", "reports/junit.xml")  # fmt: skip
    assert (project / "reports" / "latest" / RESULTS_FILE).is_file()
    assert (project / "reports" / "junit.xml").is_file()
    library = run_ok(project, env, "physval", "run", "--only", LIBRARY_SCENE, "--engines", "mini",
                   "--out", "library", *quiet)  # fmt: skip
    results = (project / "library" / RESULTS_FILE).read_text()
    assert LIBRARY_SCENE in results, library.stdout
