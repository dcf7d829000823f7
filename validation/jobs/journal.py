"""The journal of a run: every finished job committed to disk as it finishes.

A run writes its journal into its staging folder: ``header.json`` (what was asked, written
first) and one record file per finished job (``job-000012.zip``, the job's index in the
plan), each written atomically and fsync'd with its folder before the next result is taken
(``validation.files.write_atomically``). A kill (SIGKILL, an out-of-memory kill, a CI
timeout) therefore loses at most the jobs that were still running; ``physval run --resume``
reads the header, plans the same jobs again, and runs only those without a record.

A journal is data, never code (a killed run's staging folder may come from a CI cache or an
artifact): a record is numbers, strings and arrays (``validation.jobs.records``: JSON and
``.npy`` in an uncompressed ZIP), holding the job it belongs to (``JobId``) and its result.
``finished(jobs)`` opens only the records of the jobs the plan names (any other file in the
folder is never opened), and reads each back as the type its job kind declares, checking
every field, the job's identity against the plan's, and the arrays' shapes against the
scene: anything else is a ``JournalError`` naming the file and the field.

The interface is four calls, so that another store can take its place:
``Journal.create(folder, header, schema)``, ``Journal.open(folder, schema)``,
``journal.append(job, result)`` and ``journal.finished(jobs)``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from validation.files import open_regular, read_regular, write_atomically
from validation.jobs import records

HEADER_FILE = "header.json"
RECORD_PATTERN = "job-{index:06d}.zip"
"""One file per finished job, named by its index in the plan (six digits: sorted by name)."""

JOURNAL_VERSION = 3
"""Bumped when the record layout changes; a journal of another version is not resumed
(version 1 stored pickles; version 2 had no ``Recording.impact_count``)."""

MAX_HEADER_BYTES = 16 * 1024 * 1024
"""A header larger than this is refused unread: it holds the request and one short
fingerprint per job (about 120 bytes each), so 16 MiB is over 100,000 jobs."""


class JournalError(ValueError):
    """A journal that cannot be resumed (missing, damaged, another version, not the plan's)."""


@dataclass(frozen=True)
class JobId:
    """Which job a record is of: its index and kind, its scene and engine, the fingerprint of
    the validated scene and spec (``run.job_fingerprints``), and the scene's body count (the
    length the record's arrays must have)."""

    index: int
    kind: str
    scene: str
    engine: str
    fingerprint: str
    bodies: int


@dataclass(frozen=True)
class Schema:
    """What the records of a journal hold: job kind -> the declared type of its result, and
    the array shapes of its dataclasses (``records.Shapes``; ``bodies`` is the job's)."""

    results: dict[str, Any]
    shapes: records.Shapes = field(default_factory=dict)


class Journal:
    """The finished jobs of one run, in ``folder``."""

    def __init__(self, folder: Path, header: dict[str, Any], schema: Schema):
        self.folder = folder
        self.header = header
        self.schema = schema

    @classmethod
    def create(cls, folder: Path, header: dict[str, Any], schema: Schema) -> Journal:
        """A new, empty journal in ``folder`` (created) with ``header`` committed first."""
        folder.mkdir(parents=True, exist_ok=True)
        header = {**header, "journal_version": JOURNAL_VERSION}
        write_atomically(folder / HEADER_FILE, json.dumps(header, indent=2, default=str))
        return cls(folder, header, schema)

    @classmethod
    def open(cls, folder: Path, schema: Schema) -> Journal:
        """The journal in ``folder``; raises ``JournalError`` when there is none to resume.
        The header is only parsed here (a JSON object of this version): its fields are the
        resuming command's to check."""
        path = folder / HEADER_FILE
        try:
            text = read_regular(path, MAX_HEADER_BYTES).decode("utf-8")
            header = json.loads(text)
        except (OSError, ValueError, RecursionError) as error:
            raise JournalError(
                f"{path}: cannot be read ({type(error).__name__}: {error})"
            ) from None
        if not isinstance(header, dict) or header.get("journal_version") != JOURNAL_VERSION:
            raise JournalError(
                f"{path}: journal_version: expected {JOURNAL_VERSION} (a journal of this "
                "version); run it again without --resume"
            )
        return cls(folder, header, schema)

    def append(self, job: JobId, result: Any) -> None:
        """Commit the ``result`` of ``job``; durable when this returns."""
        kind = tuple[JobId, self.schema.results[job.kind]]
        write_atomically(self.record_path(job), records.dumps((job, result), kind))

    def finished(self, jobs: Iterable[JobId]) -> dict[int, Any]:
        """Index -> result of every job of ``jobs`` (the plan's) with a record; only their
        files are opened. ``JournalError`` naming the file and the field when a record is
        not a regular file, not a record, not of its job, or not of its declared type."""
        found: dict[int, Any] = {}
        for job in jobs:
            path = self.record_path(job)
            try:
                found[job.index] = self._read(path, job)
            except FileNotFoundError:
                continue
            except records.RecordError as error:
                raise JournalError(f"{path}: {error}") from None
            except OSError as error:
                raise JournalError(f"{path}: cannot be read ({error.strerror or error})") from None
        return found

    def record_path(self, job: JobId) -> Path:
        """The file of ``job``'s record."""
        return self.folder / RECORD_PATTERN.format(index=job.index)

    def _read(self, path: Path, job: JobId) -> Any:
        kind = tuple[JobId, self.schema.results[job.kind]]
        with open_regular(path) as handle:
            recorded, result = records.loads(
                handle, kind, self.schema.shapes, {"bodies": job.bodies}
            )
        if recorded != job:
            wrong = next(
                n for n in JobId.__dataclass_fields__ if getattr(recorded, n) != getattr(job, n)
            )
            raise records.RecordError(
                f"[0].{wrong}",
                f"a record of another job ({getattr(recorded, wrong)!r}; the plan's job "
                f"{job.index} has {getattr(job, wrong)!r})",
            )
        return result
