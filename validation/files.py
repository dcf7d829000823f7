"""Writing files so that a reader never sees a half-written one, and a kill never loses one
that was reported written."""

from __future__ import annotations

import os
import secrets
import stat
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


def _blocked_folder(folder: Path) -> str | None:
    """Why ``folder`` cannot be created or written into: a file where it (or the nearest of
    its parents that exists) must be a folder; None when it can."""
    for parent in (folder, *folder.parents):
        if parent.exists():
            return None if parent.is_dir() else f"{parent} is a file; expected a folder"
    return None


def file_target_problem(path: Path) -> str | None:
    """Why a command cannot write the file ``path`` (a folder is there, or a file where one of
    its folders must be); None when it can. Checked before any work, so nothing of the
    user's is overwritten and no run is lost at its end."""
    if path.is_dir():
        return f"{path} is a folder; expected a file"
    return _blocked_folder(path.parent)


def folder_target_problem(path: Path, files: tuple[str, ...] = ()) -> str | None:
    """Why a command cannot write ``files`` into the folder ``path`` (a file is there or
    where one of its parents must be, or a folder where one of ``files`` must be); None when
    it can."""
    if path.exists() and not path.is_dir():
        return f"{path} is a file; expected a folder"
    for name in files:
        if (path / name).is_dir():
            return f"{path / name} is a folder; expected a file"
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
