"""Writing files so that a reader never sees a half-written one, and a kill never loses one
that was reported written."""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import pandas as pd

from validation.csv_safe import csv_text


def sync_folder(folder: Path) -> None:
    """fsync a folder, so that the names created or renamed in it survive a crash."""
    descriptor = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def write_atomically(path: Path, data: str | bytes) -> None:
    """Write ``data`` (text as UTF-8) to a new file next to ``path``, fsync it, then rename it
    over ``path`` and fsync the folder.

    Readers see the old file or the new one, never a half-written one, and once this returns
    the new file survives a kill or a crash; on any error the temporary file is removed and
    ``path`` is untouched.
    """
    temporary = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
    payload = data.encode("utf-8") if isinstance(data, str) else data
    path.parent.mkdir(parents=True, exist_ok=True)  # the callers checked the path before any work
    try:
        # O_EXCL: never reuse a stranger's file; 0o666 & ~umask like any new file.
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    sync_folder(path.parent)


def write_table(rows: list[dict], path: Path) -> None:
    """A spreadsheet-safe CSV (``csv_safe``) of ``rows`` written atomically
    (``files.write_atomically``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, csv_text(pd.DataFrame(rows)))


HEAD_BYTES = 4096
"""How much of an existing file is read to tell whether physval wrote it: a CSV's header line
and a page's ``<title>`` are within its first few hundred bytes."""


@dataclass(frozen=True)
class Written:
    """How a file that physval writes begins: a command may replace a file it wrote before
    (recognised by these bytes) and refuses any other (``file_target_problem``)."""

    kind: str
    """What the file is, for the line that refuses another: ``a physval baseline``."""
    start: bytes
    """Its first bytes (a CSV's header, an XML declaration and root element, a doctype)."""
    holds: bytes = b""
    """Bytes its first ``HEAD_BYTES`` hold besides (a page's ``<title>``)."""

    def wrote(self, path: Path) -> bool:
        """Whether the regular file ``path`` (never through a symlink) is one of these."""
        try:
            with open_regular(path) as handle:
                head = handle.read(HEAD_BYTES)
        except OSError:
            return False
        return head.startswith(self.start) and self.holds in head


def csv_written(kind: str, columns: Iterable[str]) -> Written:
    """A CSV of physval's whose header begins with ``columns``."""
    return Written(kind, ",".join(columns).encode())


def page_written(kind: str, title: str) -> Written:
    """An HTML page of physval's titled ``title`` (``report/templates/base.html.j2``)."""
    return Written(kind, b"<!DOCTYPE html>", f"<title>{title}</title>".encode())


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def _what_is_there(path: Path) -> str:
    if path.is_symlink():
        return f"a symlink to {os.readlink(path)}"
    if not path.is_file():
        return "not a regular file"
    return "a file physval did not write"


def file_target_problem(
    path: Path, written: Written | None = None, inputs: Iterable[Path] = ()
) -> str | None:
    """Why a command cannot write the file ``path`` (a folder is there, or a file where one of
    its folders must be; one of the command's ``inputs``; or, given ``written``, anything that
    is not a file physval wrote as that); None when it can. Checked before any work, so nothing
    of the user's is overwritten and no run is lost at its end; missing folders are created
    when it is written (``write_atomically``)."""
    if path.is_dir():
        return f"{path} is a folder; expected a file"
    for source in inputs:
        if _same_file(path, source):
            return f"{path} is an input of this command; it is left as it was"
    if written is not None and os.path.lexists(path) and not written.wrote(path):
        return (
            f"{path} is {_what_is_there(path)} (not {written.kind}); it is left as it was: "
            "give a new file, or remove it first"
        )
    return _blocked_folder(path.parent)


def _blocked_folder(folder: Path) -> str | None:
    """Why ``folder`` cannot be created or written into: a file where it (or the nearest of
    its parents that exists) must be a folder; None when it can."""
    for parent in (folder, *folder.parents):
        if parent.exists():
            return None if parent.is_dir() else f"{parent} is a file; expected a folder"
    return None


def folder_target_problem(path: Path, files: Mapping[str, Written | None]) -> str | None:
    """Why a command cannot write ``files`` (name -> how physval writes it) into the folder
    ``path``: a file is there or where one of its parents must be, or one of ``files`` is
    there and cannot be replaced (``file_target_problem``); None when it can. The folder's
    other entries are kept."""
    if path.exists() and not path.is_dir():
        return f"{path} is a file; expected a folder"
    for name, written in files.items():
        problem = file_target_problem(path / name, written)
        if problem:
            return problem
    return _blocked_folder(path.parent)


def open_regular(path: Path) -> BinaryIO:
    """``path`` opened for reading, never through a symlink (``O_NOFOLLOW``), never blocking
    on a FIFO or a device; ``OSError`` unless it is a regular file. For files read back from
    a folder that may come from elsewhere (a run folder, a journal)."""
    descriptor = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    try:
        if not stat.S_ISREG(os.fstat(descriptor).st_mode):
            raise OSError(0, "not a regular file")
        return os.fdopen(descriptor, "rb")
    except BaseException:
        os.close(descriptor)
        raise


def read_regular(path: Path, limit: int) -> bytes:
    """The bytes of the regular file ``path`` (``open_regular``); ``ValueError`` when it holds
    more than ``limit`` bytes (read no further)."""
    with open_regular(path) as handle:
        data = handle.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"larger than {limit} bytes")
    return data
