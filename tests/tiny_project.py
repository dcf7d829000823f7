"""A tiny project of physval's user, for the tests that run physval's commands as a shell in
another project would: one scene that runs in mini in a few milliseconds."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

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
