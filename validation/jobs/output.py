"""The output folder of ``physval run``: checked, locked, staged and published without loss.

- **Checked before any work** (``check_destination``): publishing replaces ``--out`` whole,
  so it must be a new path, an empty folder, or a physval run folder (``run_folder_problem``:
  a ``provenance.json`` of physval's and nothing but a run's files, ``RUN_FOLDER_FILES``).
  Anything else is refused with one line (exit 2) naming what it holds, and left as it was:
  a folder of the user's, a file, a symlink (publishing replaces the folder by rename, which
  would replace the link), a path below a file, a mount point (it cannot be renamed), the
  working folder or one of its parents (``.``, ``..``, ``/``). ``--new-folder`` publishes
  into a new subfolder of ``--out`` instead (``fresh_subfolder``). The parent must take a new
  folder and a file (probed by writing one; missing folders are created) and have
  ``MIN_FREE_BYTES`` free. Publishing checks ``--out`` once more, and refuses (the run kept for
  ``--resume``) if something else appeared there meanwhile.
- **Locked** (``claim``): ``flock`` on ``.<name>.lock`` next to ``--out`` for the whole run,
  opened without following a symlink (``O_NOFOLLOW``: a planted link is refused, its target
  never truncated) and only as a regular file of one link. A second run on the same ``--out``
  does not wait: it exits 2 at once naming the lock's holder.
- **Staged**: the run's files are assembled in ``.<name>-staging-<id>/run/`` beside the journal
  (``.<name>-staging-<id>/journal/``, ``validation.jobs.journal``).
- **Published** (``Output.publish``) by one atomic exchange of the staged folder with
  ``--out`` (Linux ``renameat2(RENAME_EXCHANGE)``): at every instant ``--out`` holds the old
  report or the new one. Where the exchange is not available, two renames; a kill between
  them leaves the old report as ``.<name>.old-<id>``, which the next run puts back.
- **Recovered**: a run that takes the lock first restores or removes what killed runs left:
  an ``.old-*`` folder goes back to ``--out`` if ``--out`` is missing and is removed otherwise;
  staging folders are removed (``physval run --resume`` finishes one instead).

Folders are created with mode 0o777 and files with 0o666, both less the umask.
"""

from __future__ import annotations

import ctypes
import datetime as dt_module
import errno
import fcntl
import os
import secrets
import shutil
import stat
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from validation.contract import (
    BASELINE_FILE,
    IMPACTS_FILE,
    PROVENANCE_FILE,
    REPORT_FILE,
    RESULTS_FILE,
    SCENE_FILE,
    SERIES_FILE,
    SWEEP_FILE,
    TRACE_FILE,
)
from validation.files import Written, file_target_problem, folder_target_problem, sync_folder
from validation.jobs.plan import BadInputError
from validation.report.read import ReportInputError, read_provenance

MIN_FREE_BYTES = 256 * 1024 * 1024
"""Free space the output's file system must have before a run starts: the library's run
writes about 40 MB of record and report and up to about 150 MB of journal (the 216-ball pile
keeps 5,000 positions of 216 bodies per engine), so 256 MiB leaves room to spare."""

RUN_FOLDER = "run"
JOURNAL_FOLDER = "journal"
"""Sub-folders of a staging folder: the run folder to publish, and the journal beside it."""

STAGING_MARK = "-staging-"
OLD_MARK = ".old-"
HISTORY_FOLDER = "runs"
"""Default runs also keep a copy in ``<parent of --out>/runs/<stamp>-<id>``."""

ID_BYTES = 3
"""Random bytes in a folder id (6 hex digits): unique among runs started in the same
microsecond, short enough to read."""

RUN_FOLDER_FILES = frozenset(
    {
        RESULTS_FILE,
        SERIES_FILE,
        IMPACTS_FILE,
        PROVENANCE_FILE,
        REPORT_FILE,
        BASELINE_FILE,
        SWEEP_FILE,
        TRACE_FILE,
        SCENE_FILE,
    }
)
"""Every file a run folder holds (``run.write_run``, ``render_report``, the baseline and
sweep rows, the scene of ``physval sim2sim``): a folder holding anything else is not replaced
by a run."""

RUN_MARK_FIELDS = ("command", "git_commit", "created")
"""The provenance.json fields every physval run writes (``run._provenance``): with the file
valid as physval's (``report.read.Provenance``), they mark a physval run folder."""

SHOWN_ENTRIES = 3
"""Entries named in the line that refuses a folder (then ``and N more``)."""

NEW_FOLDER_PREFIX = "run-"
"""``--new-folder``: the run is published to ``<--out>/run-<stamp>-<id>`` (``history_name``)."""

_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100  # fcntl.h: paths relative to the working directory


def short_id() -> str:
    return secrets.token_hex(ID_BYTES)


def history_name(now: dt_module.datetime | None = None) -> str:
    """``20250101-120000.123456-1a2b3c``: a microsecond UTC stamp plus a short id, so that
    runs started in the same second (or microsecond) never share a history folder."""
    now = now or dt_module.datetime.now(dt_module.UTC)
    return f"{now.strftime('%Y%m%d-%H%M%S.%f')}-{short_id()}"


def _refuse(destination: Path, why: str) -> BadInputError:
    return BadInputError(f"--out {destination}: {why}")


def _named(entries: list[str]) -> str:
    shown = ", ".join(sorted(entries)[:SHOWN_ENTRIES])
    more = len(entries) - SHOWN_ENTRIES
    return shown + (f" and {more} more" if more > 0 else "")


REPLACED_WHOLE = (
    "a run replaces its --out whole, so it is left as it was: give a new or empty folder, "
    "or add --new-folder to publish into a new subfolder of it"
)


def run_folder_problem(folder: Path) -> str | None:
    """What makes the existing folder ``folder`` something a run must not replace: None when
    it is empty or a physval run folder (its provenance.json physval's, ``RUN_MARK_FIELDS``
    present, and no file but ``RUN_FOLDER_FILES``)."""
    try:
        entries = os.listdir(folder)
    except OSError as error:
        return f"cannot be listed ({error.strerror})"
    if not entries:
        return None
    try:
        provenance = read_provenance(folder / PROVENANCE_FILE, [])
    except ReportInputError:
        provenance = None
    if provenance is None or not all(name in provenance for name in RUN_MARK_FIELDS):
        return (
            f"holds {len(entries)} {'entry' if len(entries) == 1 else 'entries'} "
            f"({_named(entries)}) and is not a physval run folder "
            f"(no {PROVENANCE_FILE} of physval's); {REPLACED_WHOLE}"
        )
    foreign = [name for name in entries if name not in RUN_FOLDER_FILES]
    if foreign:
        return f"is a physval run folder that also holds {_named(foreign)}; {REPLACED_WHOLE}"
    return None


def _place_problem(destination: Path) -> str | None:
    """What makes ``destination`` a place no run folder can be published to by rename: the
    working folder or one of its parents (``.``, ``..``, ``/``), a path ending in ``..``, a
    mount point."""
    if destination.resolve() in (Path.cwd(), *Path.cwd().parents):
        return (
            "is the working folder or one of its parents, which a run cannot replace; give a "
            "folder below it, or add --new-folder to publish into a new subfolder of it"
        )
    if destination.name == "..":
        return "ends in ..; give the folder by its own name"
    if os.path.ismount(destination):
        return (
            "is a mount point, which cannot be replaced by rename; give a folder inside it, or "
            "add --new-folder"
        )
    return None


def fresh_subfolder(out: Path) -> Path:
    """``--new-folder``: a new subfolder of ``out`` to publish the run to (``NEW_FOLDER_PREFIX``
    and a stamp, ``history_name``)."""
    return out / f"{NEW_FOLDER_PREFIX}{history_name()}"


def check_destination(destination: Path) -> None:
    """Refuse an ``--out`` a run must not replace (module docstring; ``BadInputError``)."""
    problem = _place_problem(destination)
    if problem:
        raise _refuse(destination, problem)
    try:
        found = os.lstat(destination)
    except FileNotFoundError:
        found = None
    except NotADirectoryError:
        found = None  # below a file: found by the walk up below
    except OSError as error:
        raise _refuse(destination, f"cannot be examined ({error.strerror})") from None
    if found is not None:
        if stat.S_ISLNK(found.st_mode):
            raise _refuse(
                destination,
                f"is a symlink to {os.readlink(destination)}; publishing replaces the folder "
                "by rename, which would replace the link: give the folder it points to",
            )
        if not stat.S_ISDIR(found.st_mode):
            raise _refuse(destination, "is an existing file, not a folder; it is left as it was")
        problem = run_folder_problem(destination)
        if problem:
            raise _refuse(destination, problem)
        return
    _check_ancestors(destination)


def check_inside(destination: Path, flag: str, path: Path | None) -> None:
    """Refuse a file the run writes besides its run folder (``--junit``, an SQLite
    ``--history``) inside ``--out``: publishing replaces ``--out`` whole, and the file with it."""
    if path is None:
        return
    inside = path.resolve()
    if destination.resolve() in (inside, *inside.parents):
        raise BadInputError(
            f"{flag} {path}: is inside --out {destination}, which the run replaces whole "
            "(and the file with it); give a path outside it"
        )


def check_file_destination(
    destination: Path, written: Written, inputs: tuple[Path, ...] = ()
) -> None:
    """Refuse an ``--out FILE`` (a CSV written atomically: by rename) that is a folder, a
    symlink (the rename would replace the link, not its target), below a file, one of the
    command's ``inputs``, or a file that physval did not write as ``written``
    (``files.file_target_problem``)."""
    if destination.is_symlink():
        raise _refuse(
            destination,
            f"is a symlink to {os.readlink(destination)}; the file is replaced by rename, "
            "which would replace the link: give the file it points to",
        )
    problem = file_target_problem(destination, written, inputs)
    if problem:
        raise _refuse(destination, problem)


def check_folder_destination(destination: Path, files: dict[str, Written]) -> None:
    """Refuse an ``--out DIR`` that ``files`` are written into (each atomically, the folder
    kept) when it is an existing file or below a file, or when one of ``files`` is there and
    physval did not write it (``files.folder_target_problem``); a symlink to a folder is
    written through."""
    problem = folder_target_problem(destination, files)
    if problem:
        raise _refuse(destination, problem)


def _check_ancestors(destination: Path) -> None:
    """The nearest existing ancestor of ``destination`` is a folder."""
    for ancestor in destination.absolute().parents:
        if ancestor.exists():
            if not ancestor.is_dir():
                raise _refuse(destination, f"{ancestor} is a file, so nothing can be below it")
            return


def _probe_writable(parent: Path) -> None:
    """Create and remove a folder and a file in ``parent``; ``OSError`` when it cannot."""
    probe = parent / f".physval-probe-{short_id()}"
    os.mkdir(probe)
    try:
        descriptor = os.open(probe / "probe", os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            os.write(descriptor, b"physval")
            os.fsync(descriptor)
        finally:
            os.close(descriptor)
    finally:
        shutil.rmtree(probe, ignore_errors=True)


def check_room(destination: Path) -> None:
    """The parent of ``--out`` can be written and has ``MIN_FREE_BYTES`` free."""
    parent = destination.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        _probe_writable(parent)
        free = shutil.disk_usage(parent).free
    except OSError as error:
        raise _refuse(destination, f"{parent} cannot be written ({error.strerror})") from None
    if free < MIN_FREE_BYTES:
        raise _refuse(
            destination,
            f"{parent} has {free / 2**20:.0f} MiB free; a run needs "
            f"{MIN_FREE_BYTES / 2**20:.0f} MiB (MIN_FREE_BYTES)",
        )


LOCK_FLAGS = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK
"""How a lock file is opened: created if missing, a symlink refused (ELOOP), never waiting."""


def lock_path(destination: Path) -> Path:
    """``.<name>.lock`` beside ``destination`` (``sweep --out .``: beside the working folder);
    ``BadInputError`` for the root folder, which has no name and nothing beside it."""
    absolute = Path(os.path.abspath(destination))
    if not absolute.name:
        raise _refuse(destination, "is the root folder; give a folder below it")
    return absolute.with_name(f".{absolute.name}.lock")


@contextmanager
def locked(destination: Path) -> Iterator[None]:
    """Hold the lock of ``destination`` (``BadInputError`` at once if another run holds it)."""
    path = lock_path(destination)
    try:  # never through a planted symlink, never blocking on a FIFO
        descriptor = os.open(path, LOCK_FLAGS, 0o666)
    except OSError as error:
        why = "a symlink, never followed" if error.errno == errno.ELOOP else error.strerror
        raise _refuse(destination, f"its lock {path} cannot be opened ({why}); remove it") from None
    try:
        found = os.fstat(descriptor)
        if not stat.S_ISREG(found.st_mode) or found.st_nlink != 1:
            raise _refuse(
                destination,
                f"its lock {path} is not a regular file of its own (a link to another file, "
                "a FIFO or a device); it is left as it was: remove it",
            )
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(descriptor, 64, 0).decode(errors="replace").strip() or "unknown"
            raise _refuse(
                destination,
                f"another physval run (pid {holder}) is writing it (lock {path}); "
                "wait for it to finish or choose another --out",
            ) from None
        os.ftruncate(descriptor, 0)
        os.pwrite(descriptor, str(os.getpid()).encode(), 0)
        yield
    finally:
        os.close(descriptor)  # releases the lock


def staging_folders(destination: Path) -> list[Path]:
    """Staging folders of runs on ``destination``, newest first."""
    pattern = f".{destination.name}{STAGING_MARK}*"
    found = [p for p in destination.parent.glob(pattern) if p.is_dir() and not p.is_symlink()]
    return sorted(found, key=lambda p: p.stat().st_mtime, reverse=True)


def recover(destination: Path, keep: Path | None = None) -> list[str]:
    """Put back or remove what killed runs left next to ``destination`` (call it holding
    the lock); returns one note per action. ``keep``: a staging folder being resumed."""
    notes = []
    olds = sorted(
        destination.parent.glob(f".{destination.name}{OLD_MARK}*"),
        key=lambda p: p.stat().st_mtime,
        reverse=True,
    )
    if olds and not os.path.lexists(destination):
        os.replace(olds.pop(0), destination)
        notes.append(f"restored {destination} (a run was killed while publishing)")
    for old in olds:
        shutil.rmtree(old, ignore_errors=True)
        notes.append(f"removed {old.name} (the report a killed run replaced)")
    for stage in staging_folders(destination):
        if stage != keep:
            shutil.rmtree(stage, ignore_errors=True)
            notes.append(f"removed {stage.name} (an unfinished run; --resume finishes one)")
    return notes


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically; False when the system cannot (not Linux, old kernel or
    file system), nothing having changed."""
    renameat2 = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if renameat2 is None:
        return False
    if renameat2(_AT_FDCWD, bytes(a), _AT_FDCWD, bytes(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
        return False
    raise OSError(code, os.strerror(code), str(a), None, str(b))


@dataclass
class Output:
    """The claimed output of one run: where it is staged and where it is published."""

    destination: Path
    stage: Path
    """The staging folder: ``RUN_FOLDER`` (what is published) and ``JOURNAL_FOLDER``."""

    @property
    def run_folder(self) -> Path:
        return self.stage / RUN_FOLDER

    @property
    def journal_folder(self) -> Path:
        return self.stage / JOURNAL_FOLDER

    def publish(self) -> None:
        """Put the staged run folder at ``destination``, replacing an older run, then remove
        the staging folder. Recoverable at every instant (module docstring)."""
        staged, destination = self.run_folder, self.destination
        check_destination(destination)  # what appeared there meanwhile is kept (--resume)
        if not os.path.lexists(destination):
            os.replace(staged, destination)
        elif not _exchange(staged, destination):
            old = destination.with_name(f".{destination.name}{OLD_MARK}{short_id()}")
            os.replace(destination, old)  # a kill here: the next run puts ``old`` back
            os.replace(staged, destination)
            os.replace(old, staged)
        sync_folder(destination.parent)
        shutil.rmtree(self.stage, ignore_errors=True)  # the old report, the journal

    def keep_history(self) -> Path:
        """Copy the published run to ``runs/<stamp>-<id>`` beside it (default runs)."""
        history = self.destination.parent / HISTORY_FOLDER
        history.mkdir(exist_ok=True)
        name = history_name()
        partial = history / f".{name}.partial"
        shutil.copytree(self.destination, partial)
        os.replace(partial, history / name)
        return history / name


def new_stage(destination: Path) -> Path:
    """A new staging folder (0o777 less the umask) with its run folder."""
    stage = destination.with_name(f".{destination.name}{STAGING_MARK}{short_id()}")
    os.mkdir(stage)
    os.mkdir(stage / RUN_FOLDER)
    return stage


@contextmanager
def claim(destination: Path, resume: bool = False) -> Iterator[Output]:
    """Check ``destination``, lock it, recover leftovers and stage a run; with ``resume``,
    re-stage the staging folder of the killed run instead (``BadInputError`` if none). The
    staging folder stays when the run is killed or interrupted: ``--resume`` finishes it."""
    check_destination(destination)
    check_room(destination)
    with locked(destination):
        stage = resumable_stage(destination) if resume else None
        for note in recover(destination, keep=stage):
            print(f"note: {note}", file=sys.stderr)
        if stage is None:
            stage = new_stage(destination)
        else:  # a kill after publishing's exchange leaves the old report in the run folder
            shutil.rmtree(stage / RUN_FOLDER, ignore_errors=True)
            os.mkdir(stage / RUN_FOLDER)
        yield Output(destination, stage)


def resumable_stage(destination: Path) -> Path:
    """The staging folder of the killed run on ``destination`` (``BadInputError`` if none)."""
    found = [s for s in staging_folders(destination) if (s / JOURNAL_FOLDER).is_dir()]
    if not found:
        raise BadInputError(f"--resume {destination}: no unfinished run to resume there")
    return found[0]
