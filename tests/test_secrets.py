"""Secrets never leak: a password in a history URL (``--history``, ``--db``, either spelling of
the flag) reaches no output. A real PostgreSQL server behind a password (``postgres_server``)
takes a whole run, and every output is searched for the password: stdout and stderr of each
command, every file the run, ``report``, ``history`` and ``compare`` write (provenance.json,
report.html, results.csv, JUnit XML, history.html, compare files), and every row of every
table of the history database (the ``runs.command`` column included). The refusals (a wrong
password, an unreachable server) print one line without it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import sqlalchemy as sa
from postgres_server import postgres  # noqa: F401  (the fixture)

from validation.contract import EXIT_BAD_INPUT, EXIT_OK
from validation.redact import shown_argv, shown_command, shown_url

FALL = (
    "dt: 0.01\nduration: 0.05\nengines: [mini]\n"
    "bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0}]\n"
)
"""A scene of five steps: the run is about its outputs, not its physics."""

COMMAND_SECONDS = 120
"""Bound on one physval command (a few seconds each; the machine may be loaded)."""


@pytest.mark.parametrize(
    ("token", "shown"),
    [
        ("postgresql://ci:hunter2@db/physval", "postgresql://ci:***@db/physval"),
        (
            "--history=postgresql://ci:hunter2@db/physval",
            "--history=postgresql://ci:***@db/physval",
        ),
        ("--db=mysql+pymysql://u:hunter2@h:3306/d", "--db=mysql+pymysql://u:***@h:3306/d"),
        ("postgresql://ci:hun%40ter2@db/physval", "postgresql://ci:***@db/physval"),
        ("postgresql://ci@db/physval?password=hunter2", "postgresql://ci@db/physval?password=***"),
        ("not a url: x://ci:hunter2@h", "not a url: x://ci:***@h"),
        ("scenarios/formulas", "scenarios/formulas"),
        ("--only=*bounce*", "--only=*bounce*"),
    ],
)
def test_every_token_holding_a_password_is_masked(token, shown):
    assert shown_argv([token]) == [shown]
    assert "hunter2" not in shown_command(["run", token]) and "hun%40ter2" not in shown_url(token)


def physval(cwd: Path, *arguments: str) -> subprocess.CompletedProcess:
    """``physval ARGUMENTS`` as a user runs it (a new process: its real stdout and stderr)."""
    return subprocess.run(
        [sys.executable, "-m", "validation.entry", *arguments],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=COMMAND_SECONDS,
        check=False,
    )


def files_holding(folder: Path, secret: str) -> list[str]:
    """Every file under ``folder`` whose bytes contain ``secret``."""
    return [
        str(path)
        for path in sorted(folder.rglob("*"))
        if path.is_file() and secret.encode() in path.read_bytes()
    ]


def database_text(url: str) -> str:
    """Every row of every table of the database, as text."""
    engine = sa.create_engine(url)
    try:
        with engine.connect() as connection:
            tables = sa.inspect(connection).get_table_names()
            return repr(
                {
                    name: connection.execute(sa.text(f'select * from "{name}"')).all()
                    for name in tables
                }
            )
    finally:
        engine.dispose()


def test_a_password_reaches_no_output_of_a_run_recorded_in_postgresql(tmp_path, postgres):  # noqa: F811
    secret = postgres.password
    (tmp_path / "fall.yaml").write_text(FALL)
    outputs = []
    for out, flag in (
        ("first", ["--history", postgres.url]),
        ("second", [f"--history={postgres.url}"]),
    ):
        outputs.append(
            physval(
                tmp_path,
                "run",
                "fall.yaml",
                "--out",
                out,
                "--jobs",
                "1",
                "--baseline",
                "none",
                "--junit",
                f"{out}.xml",
                *flag,
            )
        )
        assert outputs[-1].returncode == EXIT_OK, outputs[-1]
        assert "history run" in outputs[-1].stdout, outputs[-1].stdout  # recorded: the real path
    outputs.append(physval(tmp_path, "report", "first"))
    outputs.append(physval(tmp_path, "history", "--db", postgres.url, "--out", "history.html"))
    outputs.append(physval(tmp_path, "compare", "1", "2", "--db", postgres.url, "--out", "compare"))
    outputs.append(
        physval(tmp_path, "compare", "first", "2", f"--db={postgres.url}", "--out", "c2")
    )
    for done in outputs:
        assert done.returncode == EXIT_OK, done
        assert secret not in done.stdout + done.stderr, done

    written = {path.name for path in tmp_path.rglob("*") if path.is_file()}
    expected = {"provenance.json", "report.html", "results.csv", "first.xml", "history.html"}
    assert expected | {"compare.csv", "compare.html"} <= written, written
    assert files_holding(tmp_path, secret) == []
    assert (
        '"command": "physval run fall.yaml --out first --jobs 1 --baseline none --junit first.xml --history postgresql+psycopg://physval:***@'
        in (tmp_path / "first" / "provenance.json").read_text()
    )
    assert (
        "--history=postgresql+psycopg://physval:***@"
        in (tmp_path / "second" / "report.html").read_text()
    )

    stored = database_text(postgres.url)
    assert "physval run fall.yaml" in stored and secret not in stored, stored
    assert stored.count("physval:***@") == 2, stored  # both runs' command lines, masked


@pytest.mark.parametrize("spelling", ["--history {url}", "--history={url}"])
def test_a_wrong_password_is_one_line_before_any_work_without_the_password(
    tmp_path,
    postgres,  # noqa: F811
    spelling,
):
    wrong = "Wr0ng-pa55word"
    (tmp_path / "fall.yaml").write_text(FALL)
    flag = spelling.format(url=postgres.url_with_password(wrong)).split(" ")
    done = physval(tmp_path, "run", "fall.yaml", "--out", "out", *flag)
    assert done.returncode == EXIT_BAD_INPUT, done
    assert done.stdout == "" and len(done.stderr.strip().splitlines()) == 1, done
    assert "password authentication failed" in done.stderr, done.stderr
    assert wrong not in done.stderr and postgres.password not in done.stderr, done.stderr
    assert not (tmp_path / "out").exists()


def test_a_foreign_folder_that_recorded_a_password_is_masked_when_read(tmp_path):
    """A run folder written by an older version (or by hand) with the password in its command
    line: ``physval report`` and the history import show it masked (no server needed)."""
    from report_fixtures import write_synthetic_run

    from validation.cli import main
    from validation.nightly import history

    folder = write_synthetic_run(tmp_path / "run")
    provenance = json.loads((folder / "provenance.json").read_text())
    provenance["command"] = "physval run --history=postgresql://ci:hunter2@db/physval"
    (folder / "provenance.json").write_text(json.dumps(provenance))
    assert main(["report", str(folder)]) == EXIT_OK
    page = (folder / "report.html").read_text()
    assert "hunter2" not in page and "--history=postgresql://ci:***@db/physval" in page
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    history.record_run(folder, url)
    stored = database_text(url)
    assert "hunter2" not in stored and "ci:***@db" in stored, stored


def test_a_killed_runs_journal_keeps_no_password_and_resume_takes_it_again(tmp_path):
    """The journal's header (in the staging folder a CI may cache or upload) holds the command
    line and the history URL masked; ``--resume DIR --history URL`` matches the masked URL and
    records with the one given again."""
    from validation.jobs import run as run_module

    url = "postgresql://ci:hunter2@db/physval"
    scene = tmp_path / "fall.yaml"
    scene.write_text(FALL)
    request = run_module.RunRequest(
        [str(scene)], None, None, None, str(tmp_path / "out"), ["run", "--history", url],
        str(tmp_path), None, None, url,
    )  # fmt: skip
    header = run_module._header(request, request.plan())
    assert "hunter2" not in json.dumps(header), header
    kept = run_module.RunRequest(**header["request"])
    resumed = run_module._writes_only(kept, tmp_path / "h.json", tmp_path / "out", None, url)
    assert resumed.history == url  # the URL given again, password and all
    with pytest.raises(run_module.BadInputError, match="--history: differs"):
        run_module._writes_only(kept, tmp_path / "h.json", tmp_path / "out", None, "sqlite://")
