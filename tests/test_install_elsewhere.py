"""physval installed into another project: a wheel built from this checkout, installed with
``--no-deps`` into a fresh venv outside it, runs a scene folder of that project and the
bundled scene library (which ships inside the wheel), with the checkout nowhere on the path.

The venv takes numpy, MuJoCo, PyBullet... from this interpreter's environment (a ``.pth``
line naming its site-packages; ``.pth`` files there, such as an editable install of physval,
are not run), so nothing is downloaded."""

from __future__ import annotations

import os
import shlex
import shutil
import site
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest
from tiny_project import shell, tiny_project

from validation.bundled import BUNDLED_SCENARIOS
from validation.contract import EXIT_OK, RESULTS_FILE

ROOT = Path(__file__).resolve().parent.parent

NOT_SOURCE = shutil.ignore_patterns(
    ".git", ".ci", ".venv", "reports", "build", "dist", "*.egg-info", "__pycache__", ".*_cache"
)
"""What the wheel is not built from: version control, venvs, run output and build leftovers
(building in the copy leaves the checkout as it was)."""

LIBRARY_SCENE = "bounce_impact_times"
"""A bundled scene that runs in a fraction of a second in mini."""


def _run(cwd: Path, env: dict | None, *command: str) -> subprocess.CompletedProcess:
    """``command`` run in ``cwd`` with ``env`` (None: this process's), asserted to exit 0."""
    line = shlex.join(command)
    done = shell(line, cwd, env or dict(os.environ))
    assert done.returncode == EXIT_OK, f"{line}:\n{done.stdout}\n{done.stderr}"
    return done


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, Path, dict]:
    """(the wheel, the other project's folder, the environment of a shell there: the venv first
    on PATH, no PYTHONPATH)."""
    work = tmp_path_factory.mktemp("elsewhere")
    source = work / "physval"
    shutil.copytree(ROOT, source, symlinks=True, ignore=NOT_SOURCE)
    dist = work / "dist"
    pip = (sys.executable, "-m", "pip")
    _run(
        work,
        None,
        *pip,
        "wheel",
        "--no-deps",
        "--no-build-isolation",
        "-q",
        str(source),
        "-w",
        str(dist),
    )
    (wheel,) = dist.glob("physval-*.whl")
    environment = work / "venv"
    venv.EnvBuilder(with_pip=False).create(environment)
    (purelib,) = (environment / "lib").glob("python*/site-packages")
    (purelib / "parent_environment.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    python = environment / "bin" / "python"
    _run(
        work, None, str(python), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = f"{environment / 'bin'}{os.pathsep}{env.get('PATH', '')}"
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
    done = _run(project, env, "python", "-c", imports)
    files = [Path(f) for f in done.stdout.split()]
    assert all("site-packages" in f.parts and ROOT not in f.parents for f in files), files


def test_physval_runs_the_projects_scenes_and_the_bundled_library(installed):
    _, project, env = installed
    quiet = ("--jobs", "1", "--history", "none")
    _run(project, env, "physval", "run", "scenes", "--out", "reports/latest", *quiet,
         "--junit", "reports/junit.xml")  # fmt: skip
    assert (project / "reports" / "latest" / RESULTS_FILE).is_file()
    assert (project / "reports" / "junit.xml").is_file()
    library = _run(project, env, "physval", "run", "--only", LIBRARY_SCENE, "--engines", "mini",
                   "--out", "library", *quiet)  # fmt: skip
    results = (project / "library" / RESULTS_FILE).read_text()
    assert LIBRARY_SCENE in results, library.stdout
