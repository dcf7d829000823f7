"""A journal is data, never code, and ``--resume`` writes nowhere its command line does not
name: attacks on a killed run's staging folder (a CI cache or an artifact restored from
elsewhere), each on a copy of the session's real killed run (``conftest.real_run``)."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import pickle
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from validation.cli import main
from validation.engines.parity import Mismatch
from validation.jobs import records
from validation.jobs.journal import HEADER_FILE
from validation.jobs.run import JOURNAL_SCHEMA
from validation.jobs.terminal import message_lines
from validation.measure.runner import EngineRun

RECORDED_FILES = ("results.csv", "series.csv", "impacts.csv", "sweep.csv")
"""The files of a run folder computed from the jobs' results alone (provenance.json holds the
time it was written)."""

MARKER = "code-ran"
"""The file a planted pickle creates when it is unpickled."""


class _Planted:
    """A pickle that creates ``MARKER`` in the working folder when it is loaded."""

    def __reduce__(self):
        return (open, (MARKER, "w"))


PLANTED = pickle.dumps(_Planted())


def killed_copy(real_run, folder: Path) -> Path:
    """The real run's killed staging folder copied into ``folder`` (the journal's ``cwd``
    moved with it, as a legitimate move would); returns its journal folder."""
    stage = folder / real_run.journal.name
    shutil.copytree(real_run.journal, stage, symlinks=True)
    journal = stage / "journal"
    edit_header(journal, lambda header: header["request"].update(cwd=str(folder)))
    return journal


def edit_header(journal: Path, change: Callable[[dict], object]) -> None:
    header = json.loads((journal / HEADER_FILE).read_text())
    change(header)
    (journal / HEADER_FILE).write_text(json.dumps(header))


def members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def write_members(path: Path, found: dict[str, bytes], compression=zipfile.ZIP_STORED) -> None:
    with zipfile.ZipFile(path, "w", compression=compression) as archive:
        for name, data in found.items():
            archive.writestr(name, data)


def edit_record(path: Path, change: Callable[[list], object]) -> None:
    """Rewrite the record's JSON document after ``change(tree)``."""
    found = members(path)
    tree = json.loads(found["record.json"])
    change(tree)
    found["record.json"] = json.dumps(tree).encode()
    write_members(path, found)


def resume(folder: Path, monkeypatch, capsys, *extra: str) -> tuple[int, str, str]:
    monkeypatch.chdir(folder)
    code = main(["run", "--resume", "killed", "--jobs", "1", *extra])
    out, err = capsys.readouterr()
    return code, out, err


def assert_refused(code: int, err: str, *expected: str) -> None:
    assert code == 2, err
    assert len(message_lines(err)) == 1 and "Traceback" not in err, err
    for text in expected:
        assert text in err, err


def test_a_resumed_run_writes_the_bytes_of_the_uninterrupted_run(real_run):
    """Every job of the real run came from its journal: results.csv (wall times included),
    series, impacts and sweep are byte for byte those the run had in memory."""
    for name in RECORDED_FILES:
        resumed = (real_run.folder / name).read_bytes()
        whole = (real_run.uninterrupted / name).read_bytes()
        assert resumed == whole, f"{name}: {len(resumed)} bytes resumed, {len(whole)} whole"
    provenance = json.loads((real_run.folder / "provenance.json").read_text())
    assert provenance["resumed"]["jobs_run"] == 0, provenance["resumed"]


def test_records_the_plan_never_made_are_never_opened(real_run, tmp_path, monkeypatch, capsys):
    """A planted pickle beside the records, under the old record name and under an index
    past the plan's: never read, so it never runs."""
    journal = killed_copy(real_run, tmp_path)
    for name in ("job-000000.pickle", "job-000999.pickle", "job-000999.zip"):
        (journal / name).write_bytes(PLANTED)
    code, out, err = resume(tmp_path, monkeypatch, capsys)
    assert code == 0, err
    assert not (tmp_path / MARKER).exists(), "a planted pickle was loaded"
    assert "jobs from the journal" in out, out


def _swap(name: str) -> Callable[[Path], None]:
    def damage(journal: Path) -> None:
        shutil.copyfile(journal / name, journal / "job-000000.zip")

    return damage


def _tree(change: Callable[[list], object]) -> Callable[[Path], None]:
    return lambda journal: edit_record(journal / "job-000000.zip", change)


def _array(change: Callable[[np.ndarray], bytes]) -> Callable[[Path], None]:
    """Replace the record's positions array (``recording.trajectory.pos``) by ``change``'s."""

    def damage(journal: Path) -> None:
        path = journal / "job-000000.zip"
        found = members(path)
        tree = json.loads(found["record.json"])
        name = f"arrays/{tree[1][0]['recording']['trajectory']['pos']['$array']}.npy"
        found[name] = change(np.load(io.BytesIO(found[name])))
        write_members(path, found)

    return damage


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def _lying_header(array: np.ndarray) -> bytes:
    """An npy whose header claims 10^12 positions over the bytes of the real ones."""
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buffer, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 1, 3)}
    )
    return buffer.getvalue() + array.tobytes()


def _symlink(journal: Path) -> None:
    record = journal / "job-000000.zip"
    outside = journal.parent.parent / "elsewhere.zip"
    shutil.move(record, outside)
    record.symlink_to(outside)


RECORD_ATTACKS: dict[str, tuple[Callable[[Path], None], str]] = {
    "a pickle in a record's place": (
        lambda journal: (journal / "job-000000.zip").write_bytes(PLANTED),
        "not a record archive",
    ),
    "another job's record": (_swap("job-000001.zip"), "[0].index"),
    "a field of the wrong type": (
        _tree(lambda t: t[1][0].update(wall_time_s="fast")),
        "[1][0].wall_time_s: expected float",
    ),
    "an unknown field": (
        _tree(lambda t: t[1][0].update(__reduce__="os.system")),
        "[1][0].__reduce__: unknown field",
    ),
    "a missing field": (_tree(lambda t: t[1][0].pop("status")), "[1][0].status: missing"),
    "a wrong fingerprint": (
        _tree(lambda t: t[0].update(fingerprint="0" * 16)),
        "[0].fingerprint",
    ),
    "an unknown status": (_tree(lambda t: t[1][0].update(status="pwned")), "[1][0].status"),
    "a run of another scene": (
        _tree(lambda t: t[1][0].update(scenario="bounce_impact_times")),
        "a run of bounce_impact_times",
    ),
    "a pickled object array": (
        _array(lambda a: _npy(np.array([print, os.system], dtype=object))),
        "dtype object",
    ),
    "an array header that lies about its size": (_array(_lying_header), "bytes are stored"),
    "positions of another body count": (
        _array(lambda a: _npy(np.repeat(a, 2, axis=1))),
        "expected shape",
    ),
    "a compressed archive": (
        lambda journal: write_members(
            journal / "job-000000.zip",
            members(journal / "job-000000.zip"),
            zipfile.ZIP_DEFLATED,
        ),
        "compressed",
    ),
    "a truncated record": (
        lambda journal: (journal / "job-000000.zip").write_bytes(
            (journal / "job-000000.zip").read_bytes()[:1000]
        ),
        "not a record archive",
    ),
    "JSON nested without end": (
        lambda journal: write_members(
            journal / "job-000000.zip", {"record.json": b"[" * 100_000 + b"]" * 100_000}
        ),
        "record.json: not JSON",
    ),
    "a symlink to a record outside the journal": (_symlink, "cannot be read"),
}
"""Damage to a killed run's first record -> what the one line says besides the file."""


@pytest.mark.parametrize("attack", sorted(RECORD_ATTACKS))
def test_a_record_that_is_not_its_jobs_data_is_refused(
    real_run, tmp_path, monkeypatch, capsys, attack
):
    """One line naming the record and the field, exit 2, before any work: nothing run,
    nothing published, no code loaded."""
    journal = killed_copy(real_run, tmp_path)
    damage, expected = RECORD_ATTACKS[attack]
    damage(journal)
    code, _, err = resume(tmp_path, monkeypatch, capsys)
    assert_refused(code, err, "job-000000.zip", expected)
    assert not (tmp_path / "killed").exists(), "a refused resume must not publish"
    assert not (tmp_path / MARKER).exists()


VICTIM = "precious.txt"
VICTIM_TEXT = "the user's own file\n"

HEADER_ATTACKS: dict[str, tuple[Callable[[dict, Path], object], str]] = {
    "junit at the user's file": (
        lambda h, root: h["request"].update(junit=str(root / VICTIM)),
        "request.junit",
    ),
    "history at the user's file": (
        lambda h, root: h["request"].update(history=f"sqlite:///{root / VICTIM}"),
        "--history",
    ),
    "out at another folder": (
        lambda h, root: h["request"].update(out=str(root / "elsewhere")),
        "request.out",
    ),
    "a relative cwd": (lambda h, root: h["request"].update(cwd="."), "request.cwd"),
    "an unknown request field": (
        lambda h, root: h["request"].update(exec="rm -rf /"),
        "request.exec",
    ),
    "a field of the wrong type": (lambda h, root: h["request"].update(dt="1e-3"), "request.dt"),
    "jobs that are not fingerprints": (lambda h, root: h.update(jobs="all"), "jobs"),
    "a journal of pickles (version 1)": (
        lambda h, root: h.update(journal_version=1),
        "journal_version",
    ),
    "a scene path that does not exist": (
        lambda h, root: h["request"].update(paths=[str(root / "nowhere.yaml")]),
        "nowhere.yaml",
    ),
}
"""Edits of a killed run's header.json -> what the one line names."""


@pytest.mark.parametrize("attack", sorted(HEADER_ATTACKS))
def test_a_header_that_names_what_this_command_does_not_is_refused(
    real_run, tmp_path, monkeypatch, capsys, attack
):
    """The header's paths get a fresh run's checks, and the resumed run writes only DIR and
    what this command line names: one line, exit 2, before any work; the user's file as it
    was."""
    journal = killed_copy(real_run, tmp_path)
    (tmp_path / VICTIM).write_text(VICTIM_TEXT)
    change, expected = HEADER_ATTACKS[attack]
    edit_header(journal, lambda header: change(header, tmp_path))
    code, _, err = resume(tmp_path, monkeypatch, capsys)
    assert_refused(code, err, expected)
    assert (tmp_path / VICTIM).read_text() == VICTIM_TEXT
    assert not (tmp_path / "killed").exists() and not (tmp_path / "elsewhere").exists()


def test_the_killed_runs_junit_file_is_written_when_this_command_names_it(
    real_run, tmp_path, monkeypatch, capsys
):
    """A run killed with ``--junit junit.xml`` resumes only when ``--junit junit.xml`` is
    given again (the journal's own value is never trusted to name a file)."""
    journal = killed_copy(real_run, tmp_path)
    edit_header(journal, lambda header: header["request"].update(junit="junit.xml"))
    code, _, err = resume(tmp_path, monkeypatch, capsys)
    assert_refused(code, err, "--junit")
    assert not (tmp_path / "junit.xml").exists()
    code, _, err = resume(tmp_path, monkeypatch, capsys, "--junit", "junit.xml")
    assert code == 0, err
    assert "<testsuite" in (tmp_path / "junit.xml").read_text()


def test_a_model_mismatch_run_reads_back_as_it_was_written():
    """A run the parity gate stopped holds free-form values (an engine's value and the
    scenario's: arrays, tuples, numbers): read back equal, their printed form included."""
    mismatch = Mismatch("inertia", 0, np.array([[1.0, 0.0], [0.0, 2.5]]), (1.0, 2.0), 0.25)
    run = EngineRun("scene", "mini", "model_mismatch", str(mismatch), None, [mismatch])
    kind = JOURNAL_SCHEMA.results["run"]
    back, measured = records.loads(records.dumps((run, []), kind), kind)
    assert measured == [] and str(back.mismatches[0]) == str(mismatch)
    assert back.mismatches[0].engine_value.tolist() == mismatch.engine_value.tolist()
    assert back.mismatches[0].expected == (1.0, 2.0)
    assert dataclasses.replace(back, mismatches=[]) == dataclasses.replace(run, mismatches=[])
