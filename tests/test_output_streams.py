"""The command's output streams never end it with a traceback: a reader that goes away
(``physval list | head -1``), a stdout closed from the start (``>&-``), an encoding without
the report's characters (``PYTHONIOENCODING=ascii``). The installed entry point
(``validation.entry``) is run as the shell runs it, in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from validation.bundled import BUNDLED_SCENARIOS

PROJECTILE = str(BUNDLED_SCENARIOS / "formulas" / "projectile.yaml")
TIMEOUT = 300
"""s: a command here takes 1-5 s; far beyond that something hangs."""

COMMANDS = {
    "list": ["list"],
    "check": ["check", str(BUNDLED_SCENARIOS / "formulas")],
}


def physval(args: list[str], **options) -> subprocess.CompletedProcess:
    environment = {**os.environ, **options.pop("env", {})}
    return subprocess.run(
        [sys.executable, "-m", "validation.entry", *args],
        stderr=subprocess.PIPE,
        text=True,
        timeout=TIMEOUT,
        check=False,
        env=environment,
        **options,
    )


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_reader_that_went_away_is_not_a_traceback(command):
    read, write = os.pipe()
    os.close(read)  # nobody reads: the first write is a broken pipe
    try:
        done = physval(COMMANDS[command], stdout=write)
    finally:
        os.close(write)
    assert "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr, done.stderr
    assert done.returncode == 0, done.stderr


def test_a_run_with_its_reader_gone_is_still_written(tmp_path):
    read, write = os.pipe()
    os.close(read)
    out = tmp_path / "out"
    try:
        done = physval(["run", PROJECTILE, "--engines", "mini", "--out", str(out)], stdout=write)
    finally:
        os.close(write)
    assert "Traceback" not in done.stderr and "cannot write" not in done.stderr, done.stderr
    assert done.returncode in (0, 1) and (out / "results.csv").is_file(), done.stderr


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_stdout_closed_from_the_start_is_not_a_traceback(command):
    done = physval(COMMANDS[command], stdout=subprocess.DEVNULL, preexec_fn=lambda: os.close(1))
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0, done.stderr


def test_an_ascii_terminal_gets_escapes_not_a_traceback():
    """``list`` prints ω and × (the engines' and metrics' descriptions)."""
    done = physval(["list"], stdout=subprocess.PIPE, env={"PYTHONIOENCODING": "ascii"})
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0 and "\\u03c9" in done.stdout, done.stderr


def test_a_run_with_stdout_closed_from_the_start_is_written(tmp_path):
    """``physval run ... >&-`` asked a closed stdout whether it is a terminal: a traceback."""
    out = tmp_path / "out"
    done = physval(
        ["run", PROJECTILE, "--engines", "mini", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        preexec_fn=lambda: os.close(1),
    )
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode in (0, 1) and (out / "results.csv").is_file(), done.stderr
