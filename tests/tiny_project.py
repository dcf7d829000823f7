"""A tiny project of physval's user, for the tests that run physval's commands as a shell in
another project would: one scene that runs in mini in a few milliseconds; and the wheels and
venvs (nothing downloaded) of the tests that install physval and engines outside the checkout."""

from __future__ import annotations

import os
import shlex
import shutil
import site
import subprocess
import sys
import venv
from pathlib import Path

from validation.contract import EXIT_OK

ROOT = Path(__file__).resolve().parent.parent

FALL = """\
description: a ball falling freely for 0.05 s (a tiny scene of another project, mini only)
dt: 1.0e-3
duration: 0.05
engines: [mini]
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0.0, 0.0, 1.0]}
"""

COMMAND_LIMIT_S = 300
"""s: a command that takes longer has hung (each takes a few seconds on a loaded machine)."""


def tiny_project(folder: Path, scenes: str = "scenarios") -> Path:
    """``folder`` with ``FALL`` as ``<scenes>/fall.yaml``; returns ``folder``."""
    (folder / scenes).mkdir(parents=True)
    (folder / scenes / "fall.yaml").write_text(FALL)
    return folder


def shell(line: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    """``line`` in bash in ``cwd``; by default with this checkout's physval: its package first
    on the path, this interpreter's ``physval`` command first on PATH."""
    if env is None:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return subprocess.run(
        ["bash", "-c", line],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=COMMAND_LIMIT_S,
        check=False,
    )


NOT_SOURCE = shutil.ignore_patterns(
    ".git", ".ci", ".venv", "reports", "build", "dist", "*.egg-info", "__pycache__", ".*_cache"
)
"""What a wheel is not built from: version control, venvs, run output and build leftovers
(building in a copy leaves the source as it was)."""


def run_ok(cwd: Path, env: dict | None, *command: str) -> subprocess.CompletedProcess:
    """``command`` run in ``cwd`` with ``env`` (None: this process's), asserted to exit 0."""
    line = shlex.join(command)
    done = shell(line, cwd, env or dict(os.environ))
    assert done.returncode == EXIT_OK, f"{line}:\n{done.stdout}\n{done.stderr}"
    return done


def built_wheel(source: Path, work: Path) -> Path:
    """The wheel of the Python project ``source``, built (without its dependencies) from a
    copy of it in ``work``."""
    copy = work / f"{source.name}-source"
    shutil.copytree(source, copy, symlinks=True, ignore=NOT_SOURCE)
    dist = work / f"{source.name}-dist"
    run_ok(work, None, sys.executable, "-m", "pip", "wheel", "--no-deps",
           "--no-build-isolation", "-q", str(copy), "-w", str(dist))  # fmt: skip
    (wheel,) = dist.glob("*.whl")
    return wheel


def physval_wheel(work: Path) -> Path:
    """physval's wheel, built from this checkout in ``work``."""
    return built_wheel(ROOT, work)


def venv_with(folder: Path, *wheels: Path) -> dict:
    """A fresh venv at ``folder`` with ``wheels`` installed (``--no-deps``, nothing
    downloaded: numpy, MuJoCo... come from this interpreter's site-packages, named by a
    ``.pth`` line); returns the environment of a shell that uses it: the venv first on PATH,
    no PYTHONPATH."""
    venv.EnvBuilder(with_pip=False).create(folder)
    (purelib,) = (folder / "lib").glob("python*/site-packages")
    (purelib / "parent_environment.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    python = folder / "bin" / "python"
    run_ok(folder, None, str(python), "-m", "pip", "install", "--no-deps", "--no-index", "-q",
           *map(str, wheels))  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = f"{folder / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return env
