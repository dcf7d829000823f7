"""A throwaway PostgreSQL server for the tests that need a real one (a history database behind a
password): ``initdb`` in a temporary folder, password (SCRAM) authentication, a Unix socket only
(no TCP port is opened), stopped and removed at the end of the session.

The server is Debian's ``postgresql`` package (``initdb`` and ``pg_ctl`` on PATH or under
``/usr/lib/postgresql/*/bin``), the driver ``psycopg`` (``pip install -e ".[test]"``). Without
them the tests that need the server are skipped on a developer's machine and fail under CI
(``CI`` set), where ``.ci/run`` installs both. As root (CI) the server runs as the ``postgres``
user, since PostgreSQL refuses to run as root.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

PASSWORD = "Pg-s3cret-7f3a9"
"""The server's password: the tests look for this text in every output."""

USER = "physval"
PORT = 54329
"""Only names the socket file (``.s.PGSQL.54329``): the server listens on no TCP port."""

START_SECONDS = 60
"""``pg_ctl start -w`` gives up after this (a start takes ~1 s here; a loaded machine more)."""


@dataclass(frozen=True)
class Server:
    url: str
    """``postgresql+psycopg://physval:PASSWORD@/postgres?host=SOCKET_FOLDER&port=PORT``."""
    password: str

    def url_with_password(self, password: str) -> str:
        return self.url.replace(f":{self.password}@", f":{password}@")


def _binary(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    candidates = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    return candidates[-1] if candidates else None


def _missing() -> str | None:
    """Why no server can be started here (None when one can)."""
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return 'the psycopg driver is not installed (pip install -e ".[test]")'
    if _binary("initdb") is None or _binary("pg_ctl") is None:
        return "PostgreSQL's initdb and pg_ctl are not installed (apt-get install postgresql)"
    if os.geteuid() == 0:
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            return "running as root and there is no postgres user to run the server as"
    return None


def _as_server_user(command: list[str]) -> list[str]:
    return ["runuser", "-u", "postgres", "--", *command] if os.geteuid() == 0 else command


def _run(command: list[str]) -> None:
    done = subprocess.run(
        _as_server_user(command), capture_output=True, text=True, timeout=START_SECONDS, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {done.stdout}{done.stderr}")


@pytest.fixture(scope="session")
def postgres() -> Iterator[Server]:
    missing = _missing()
    if missing is not None:
        if "CI" in os.environ:
            pytest.fail(f"CI is set but no PostgreSQL server can be started: {missing}")
        pytest.skip(missing)
    folder = Path(tempfile.mkdtemp(prefix="physval-postgres-"))
    if os.geteuid() == 0:
        server_user = pwd.getpwnam("postgres")
        os.chown(folder, server_user.pw_uid, server_user.pw_gid)
    data, socket, log, password_file = (folder / n for n in ("data", "socket", "log", "pw"))
    try:
        _run(["mkdir", str(socket)])
        _run(["sh", "-c", f"umask 077 && printf %s '{PASSWORD}' > {password_file}"])
        _run(
            [
                _binary("initdb"),
                "-D",
                str(data),
                "-U",
                USER,
                "--auth=scram-sha-256",
                f"--pwfile={password_file}",
                "-E",
                "UTF8",
            ]
        )
        options = f"-c listen_addresses='' -k {socket} -p {PORT} -c fsync=off"
        _run([_binary("pg_ctl"), "-D", str(data), "-l", str(log), "-w", "-o", options, "start"])
        try:
            yield Server(
                f"postgresql+psycopg://{USER}:{PASSWORD}@/postgres?host={socket}&port={PORT}",
                PASSWORD,
            )
        finally:
            _run([_binary("pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop"])
    finally:
        shutil.rmtree(folder, ignore_errors=True)
