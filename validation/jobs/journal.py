"""The journal of a run: every finished job committed to disk as it finishes.

A run writes its journal into its staging folder: ``header.json`` (what was asked, written
first) and one record file per finished job (``job-000012.pickle``, the job's index in the
plan), each written atomically and fsync'd with its folder before the next result is taken
(``validation.files.write_atomically``). A kill (SIGKILL, an out-of-memory kill, a CI
timeout) therefore loses at most the jobs that were still running; ``physval run --resume``
reads the header, plans the same jobs again, and runs only those without a record.

The interface is four calls, so that another store (the SQLite history of the nightly
issue) can take its place: ``Journal.create(folder, header)``, ``Journal.open(folder)``,
``journal.append(index, record)`` and ``journal.finished()``. Records are pickles of the
job's result: a journal is read only by the run that wrote it or its resumption, on the
same machine and code (the header names the commit), never from elsewhere.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

from validation.files import write_atomically

HEADER_FILE = "header.json"
RECORD_PATTERN = "job-{index:06d}.pickle"
"""One file per finished job, named by its index in the plan (six digits: sorted by name)."""

JOURNAL_VERSION = 1
"""Bumped when the record layout changes; a journal of another version is not resumed."""


class JournalError(ValueError):
    """A journal that cannot be resumed (missing, damaged, another version)."""


class Journal:
    """The finished jobs of one run, in ``folder``."""

    def __init__(self, folder: Path, header: dict[str, Any]):
        self.folder = folder
        self.header = header

    @classmethod
    def create(cls, folder: Path, header: dict[str, Any]) -> Journal:
        """A new, empty journal in ``folder`` (created) with ``header`` committed first."""
        folder.mkdir(parents=True, exist_ok=True)
        header = {**header, "journal_version": JOURNAL_VERSION}
        write_atomically(folder / HEADER_FILE, json.dumps(header, indent=2, default=str))
        return cls(folder, header)

    @classmethod
    def open(cls, folder: Path) -> Journal:
        """The journal in ``folder``; raises ``JournalError`` when there is none to resume."""
        try:
            header = json.loads((folder / HEADER_FILE).read_text(encoding="utf-8"))
        except (OSError, ValueError) as error:
            raise JournalError(f"{folder / HEADER_FILE}: cannot be read ({error})") from None
        if not isinstance(header, dict) or header.get("journal_version") != JOURNAL_VERSION:
            raise JournalError(
                f"{folder / HEADER_FILE}: not a journal of version {JOURNAL_VERSION}"
            )
        return cls(folder, header)

    def append(self, index: int, record: Any) -> None:
        """Commit the record of the job at ``index``; durable when this returns."""
        path = self.folder / RECORD_PATTERN.format(index=index)
        write_atomically(path, pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL))

    def finished(self) -> dict[int, Any]:
        """Index -> record of every job committed so far (a record that cannot be read, from
        a crash of the disk itself, counts as not finished: its job runs again)."""
        records: dict[int, Any] = {}
        for path in sorted(self.folder.glob(RECORD_PATTERN.replace("{index:06d}", "*"))):
            try:
                index = int(path.stem.removeprefix("job-"))
                records[index] = pickle.loads(path.read_bytes())
            except (OSError, ValueError, pickle.UnpicklingError, EOFError):
                continue
        return records
