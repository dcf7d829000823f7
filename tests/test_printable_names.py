"""Folder and file names with control characters (a newline, an escape sequence) are printed
escaped in every line a command prints about them: a refusal stays one line per problem and
cannot drive the terminal or forge a line of the log."""

from __future__ import annotations

import shutil

from validation.bundled import BUNDLED_SCENARIOS
from validation.cli import main
from validation.jobs.terminal import message_lines
from validation.scenario.problems import printable

ESCAPE = "\x1b[31mred"
"""An ANSI sequence that turns a terminal's text red."""

NEWLINE = "two\nlines"
PROJECTILE = BUNDLED_SCENARIOS / "formulas" / "projectile.yaml"


def test_printable_escapes_controls_only():
    assert (
        printable(f"a/{ESCAPE}/{NEWLINE}/\udcff/ω×é\t")
        == "a/\\x1b[31mred/two\\nlines/\\udcff/ω×é\\t"
    )


def _no_raw_controls(text: str) -> None:
    assert "\x1b" not in text, repr(text)


def test_check_prints_a_folder_name_escaped(tmp_path, capsys):
    folder = tmp_path / ESCAPE / NEWLINE
    folder.mkdir(parents=True)
    (folder / "bad.yaml").write_text("dt: 010\n")
    assert main(["check", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    _no_raw_controls(captured.out + captured.err)
    problems = captured.err.strip().splitlines()
    assert problems and all(line.startswith(str(tmp_path)) for line in problems), problems
    assert "\\x1b[31mred/two\\nlines/bad.yaml:1:1: dt: 010 is 8" in problems[0], problems


def test_run_prints_missing_paths_and_out_escaped_one_line_each(tmp_path, capsys):
    missing = tmp_path / f"gone{NEWLINE}"
    assert main(["run", str(PROJECTILE), str(missing), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    _no_raw_controls(err)
    assert message_lines(err) == [f"{tmp_path}/gonetwo\\nlines: no such file or folder"], err
    a_file = tmp_path / f"file{ESCAPE}"
    a_file.write_text("")
    assert main(["run", str(PROJECTILE), "--engines", "mini", "--out", str(a_file)]) == 2
    err = capsys.readouterr().err
    _no_raw_controls(err)
    assert message_lines(err)[0].startswith(f"--out {tmp_path}/file\\x1b[31mred: "), err


def test_a_run_prints_its_out_folder_escaped(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scenes = tmp_path / f"scenes{ESCAPE}"
    scenes.mkdir()
    shutil.copy(PROJECTILE, scenes / "projectile.yaml")
    out = tmp_path / f"out{ESCAPE}{NEWLINE}"
    assert main(["run", str(scenes), "--engines", "mini", "--out", str(out)]) in (0, 1)
    captured = capsys.readouterr()
    _no_raw_controls(captured.out + captured.err)
    assert "rows -> " in captured.out and "out\\x1b[31mredtwo\\nlines/results.csv" in captured.out
