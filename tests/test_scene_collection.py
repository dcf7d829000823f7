"""``pytest --physval`` collects exactly the files ``physval run`` reads (``scenario_files``,
one collection for both) and reports the same refusals: a dangling link or a FIFO named
``*.yaml`` is a collection error with ``run``'s line, never silently passed over."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from validation.bundled import BUNDLED_SCENARIOS
from validation.cli import main

PYTEST_TIMEOUT = 300
"""s: collecting three files takes about 2 s; far beyond that something hangs (a FIFO read)."""


@pytest.fixture
def library(tmp_path) -> Path:
    """A folder of one valid scene, a link to nowhere and a FIFO, all named ``*.yaml``."""
    folder = tmp_path / "scenes"
    folder.mkdir()
    shutil.copy(BUNDLED_SCENARIOS / "formulas" / "projectile.yaml", folder / "projectile.yaml")
    (folder / "dangling.yaml").symlink_to(tmp_path / "gone.yaml")
    os.mkfifo(folder / "pipe.yaml")
    return folder


def run_refusals(folder: Path, capsys) -> list[str]:
    assert main(["run", str(folder), "--engines", "mini", "--out", str(folder.parent / "o")]) == 2
    return capsys.readouterr().err.strip().splitlines()


PYTEST = (sys.executable, "-m", "pytest", "-p", "no:cacheprovider")


def collect(folder: Path) -> subprocess.CompletedProcess:
    environment = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    return subprocess.run(
        [*PYTEST, "--physval", str(folder), "--collect-only", "-q", "-n", "0"],
        cwd=folder.parent,
        env=environment,
        capture_output=True,
        text=True,
        timeout=PYTEST_TIMEOUT,
        check=False,
    )


def test_pytest_reports_every_refusal_of_run(library, capsys):
    refusals = run_refusals(library, capsys)
    assert len(refusals) == 2, refusals
    assert any("dangling.yaml: cannot read the file" in line for line in refusals), refusals
    assert any("pipe.yaml: expected a regular file; this is a FIFO" in line for line in refusals)
    result = collect(library)
    shown = result.stdout + result.stderr
    assert result.returncode != 0, shown
    for line in refusals:
        assert line in shown, shown
    assert "ERROR scenes/dangling.yaml" in shown and "ERROR scenes/pipe.yaml" in shown, shown


def test_pytest_collects_the_valid_scene_alongside(library):
    """The control: the valid scene is collected with its items, as ``run`` would run it."""
    (library / "dangling.yaml").unlink()
    (library / "pipe.yaml").unlink()
    result = collect(library)
    items = {line for line in result.stdout.splitlines() if "::" in line}
    assert "scenes/projectile.yaml::mini" in items, result.stdout + result.stderr
    assert result.returncode == 0, result.stdout + result.stderr


def test_a_dangling_link_named_alone_is_refused_as_in_a_folder(library, capsys):
    """``run`` and ``check`` of the link itself say what ``run`` of its folder says."""
    link = library / "dangling.yaml"
    line = f"{link}: cannot read the file: No such file or directory"
    assert main(["run", str(link), "--out", str(library.parent / "o")]) == 2
    assert capsys.readouterr().err.strip() == line
    assert main(["check", str(link)]) == 2
    assert capsys.readouterr().err.strip().splitlines()[0] == line


def test_a_fifo_named_alone_is_the_same_collection_error(library, capsys):
    pipe = library / "pipe.yaml"
    assert main(["run", str(pipe), "--out", str(library.parent / "o")]) == 2
    line = capsys.readouterr().err.strip()
    result = collect(pipe)
    assert line in result.stdout + result.stderr, result.stdout + result.stderr
    assert re.search(r"^ERROR \S*pipe.yaml$", result.stdout, re.MULTILINE), result.stdout
