"""Hostile values, files and records: every bad value is exit 2 with
one line and no traceback, before any work and within 5 s; files are refused by type and size
before they are read; ``stability`` and ``sweep`` report an engine that cannot load a scene as
``error``; ``physval report`` survives ``$`` in names, absurd series values and unreadable
files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from report_fixtures import write_synthetic_run

from validation.cli import BUNDLED_SCENARIOS, main
from validation.jobs.stability_search import stability_limit
from validation.scenario import load_scenario, yaml_source
from validation.scenario.engine_spec import parse_engine_spec

PROJECTILE = str(BUNDLED_SCENARIOS / "formulas" / "projectile.yaml")

BAD_INPUT_SECONDS = 5
"""The issue's bound: bad input is refused before any work, so within 5 s."""

FALL = "dt: 0.01\nduration: 0.1\nengines: [mini]\nbodies: [{name: b, shape: {type: sphere, radius: %s}, mass: %s}]\n"
"""A tiny scene; radius and mass filled in."""

MUJOCO_CANNOT_LOAD = (
    "dt: 0.01\nduration: 0.1\nengines: [mujoco]\n"
    "bodies: [{name: b, shape: {type: sphere, radius: 0.1}, mass: 1.0e-300}]\n"
)
"""MuJoCo's compiler refuses it ("inertia must have positive eigenvalues")."""


def exit_code(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as stop:
        return int(stop.code)


def refused(argv: list[str], capsys) -> str:
    """Run ``physval ARGV`` in this process: exit 2, one line on stderr, no traceback, within
    ``BAD_INPUT_SECONDS`` (an alarm ends a hang: a FIFO opened for reading blocks). Returns the
    line."""

    def too_slow(*_):
        raise TimeoutError(f"physval {' '.join(argv)} took more than {BAD_INPUT_SECONDS} s")

    previous = signal.signal(signal.SIGALRM, too_slow)
    signal.alarm(BAD_INPUT_SECONDS)
    try:
        code = exit_code(argv)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, (code, err)
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def scene(tmp_path: Path, text: str, name: str = "scene.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("arguments", "expected"),
    [
        (["run", PROJECTILE, "--dt", "1e-308"], "MAX_STEPS"),
        (["run", PROJECTILE, "--dt", "5e-324"], "MAX_STEPS"),
        (["sweep", PROJECTILE, "--engines", "mini", "--dt", "1e-2:1e-4:1000000000"], "MAX_GRID"),
        (["sweep", PROJECTILE, "--engines", "mini", "--dt", "1e-6"], "MAX_STEPS"),
        (["run", PROJECTILE, "--engines", "mujoco(iterations=-5)"], ">= 1"),
        (["run", PROJECTILE, "--engines", "pybullet(solver_iterations=-1)"], ">= 1"),
        (["run", PROJECTILE, "--engines", "mini(solver_iterations=0)"], ">= 1"),
    ],
)
def test_a_bad_value_is_exit_2_with_one_line(tmp_path, capsys, arguments, expected):
    line = refused([*arguments, "--out", str(tmp_path / "out")], capsys)
    assert expected in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["check", "run"])
def test_mass_properties_that_overflow_are_refused_by_check_and_run(tmp_path, capsys, command):
    path = scene(tmp_path, FALL % ("1.0e200", "1.0"))
    extra = ["--out", str(tmp_path / "out")] if command == "run" else []
    line = refused([command, str(path), *extra], capsys)
    assert "bodies[0]" in line and "overflows" in line, line


@pytest.mark.parametrize("command", ["check", "run"])
def test_two_files_with_one_scene_name_are_refused(tmp_path, capsys, command):
    for name in ("a.yaml", "b.yaml"):
        scene(tmp_path, "name: same\n" + FALL % ("0.1", "1.0"), name)
    extra = ["--out", str(tmp_path / "out")] if command == "run" else []
    line = refused([command, str(tmp_path), *extra], capsys)
    assert "b.yaml: name: 'same' is also the name of" in line and "a.yaml" in line, line


def test_a_fifo_is_refused_by_its_type_without_blocking(tmp_path, capsys):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    assert "FIFO" in refused(["check", str(fifo)], capsys)


def test_a_device_is_refused_by_its_type(tmp_path, capsys):
    link = tmp_path / "zero.yaml"
    link.symlink_to("/dev/zero")
    assert "character device" in refused(["check", str(link)], capsys)


MEMORY_HEADROOM = 256 * 2**20
"""Bytes of address space the check may take beyond what importing physval took: a file is
refused from its size, never read whole (a 1 GiB file read whole needs four times this)."""

WITHIN_MEMORY = f"""
import resource
import validation.cli
size = int(open("/proc/self/statm").read().split()[0]) * resource.getpagesize()
resource.setrlimit(resource.RLIMIT_AS, (size + {MEMORY_HEADROOM}, resource.RLIM_INFINITY))
"""


def test_a_huge_file_is_refused_from_its_size_before_it_is_read(tmp_path):
    huge = tmp_path / "huge.yaml"
    with huge.open("wb") as handle:
        handle.truncate(2**30)  # sparse: 1 GiB long, nothing on disk
    script = WITHIN_MEMORY + f"sys.exit(validation.cli.main(['check', {str(huge)!r}]))"
    found = subprocess.run(
        [sys.executable, "-c", "import sys\n" + script],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert found.returncode == 2, found.stderr[-2000:]
    assert "Traceback" not in found.stderr and "MAX_BYTES" in found.stderr, found.stderr


def test_a_symlinked_folder_of_scenes_is_checked(tmp_path, capsys):
    library, other = tmp_path / "library", tmp_path / "other"
    library.mkdir()
    other.mkdir()
    scene(library, "name: here\n" + FALL % ("0.1", "1.0"), "here.yaml")
    scene(other, "name: linked\n" + FALL % ("0.1", "1.0"), "linked.yaml")
    (library / "more").symlink_to(other, target_is_directory=True)
    (other / "loop").symlink_to(library, target_is_directory=True)  # followed once, no loop
    assert exit_code(["check", str(library)]) == 0
    assert "2 files: 2 valid" in capsys.readouterr().out


def test_the_value_cap_is_named_and_fits_a_large_scene(tmp_path, monkeypatch):
    """A 12,600-body scene (the issue's) fits under MAX_VALUES; scaled by 1/126, so that the
    test reads 100 bodies: the count of values is linear in the bodies."""
    lines = ["dt: 0.01", "duration: 0.02", "engines: [mini]", "bodies:"]
    lines += [
        f"  - {{name: b{i}, shape: {{type: sphere, radius: 0.1}}, mass: 1.0, position: [{i}, 0, 1]}}"
        for i in range(100)
    ]
    path = scene(tmp_path, "\n".join(lines) + "\n")
    monkeypatch.setattr(yaml_source, "MAX_VALUES", yaml_source.MAX_VALUES // 126)
    assert len(load_scenario(path).bodies) == 100
    monkeypatch.setattr(yaml_source, "MAX_VALUES", 1000)
    with pytest.raises(ValueError, match=r"more than 1000 values, the cap .*MAX_VALUES"):
        load_scenario(path)


def test_stability_reports_an_engine_that_cannot_load_the_scene_as_error(tmp_path, capsys):
    scenario = load_scenario(scene(tmp_path, MUJOCO_CANNOT_LOAD))
    limit = stability_limit(scenario, parse_engine_spec("mujoco"))
    assert limit.status == "error", limit
    assert "was not run" in limit.sentence() and "unstable" not in limit.sentence(), limit
    out = tmp_path / "stability.csv"
    path = str(tmp_path / "scene.yaml")
    assert main(["stability", path, "--out", str(out), "--jobs", "1"]) == 0
    assert list(pd.read_csv(out)["status"]) == ["error"]


def test_sweep_reports_an_engine_that_cannot_load_the_scene_as_error(tmp_path):
    path = scene(tmp_path, MUJOCO_CANNOT_LOAD)
    out = tmp_path / "sweep"
    arguments = ["sweep", str(path), "--engines", "mujoco", "--dt", "1e-2,5e-3", "--jobs", "1"]
    assert main([*arguments, "--out", str(out)]) == 0
    rows = pd.read_csv(out / "sweep.csv")
    points = rows[rows["metric"].isin(["position_error", "orientation_error"])]
    assert set(points["status"]) == {"error"}, rows
    assert (out / "sweep.html").is_file()


def test_every_sweep_point_out_of_range_still_gives_rows_and_a_page(tmp_path):
    out = tmp_path / "sweep"
    arguments = ["sweep", PROJECTILE, "--engines", "mini", "--dt", "1e-9", "--jobs", "1"]
    started = time.monotonic()
    assert main([*arguments, "--out", str(out)]) == 0
    assert time.monotonic() - started < BAD_INPUT_SECONDS, "no reference run for no point"
    rows = pd.read_csv(out / "sweep.csv")
    points = rows[rows["metric"].isin(["position_error", "orientation_error"])]
    assert len(points) == 2 and set(points["status"]) == {"unsupported"}, rows
    assert "out of range" in points["message"].iloc[0]
    assert "1e-09" in (out / "sweep.html").read_text()


MATHTEXT = r"mujoco $\frac{$"
"""An engine label that matplotlib's mathtext cannot parse (unescaped, a ValueError)."""


def test_report_escapes_mathtext_and_clips_absurd_series_values(tmp_path, capsys):
    run_dir = write_synthetic_run(tmp_path / "run")
    for name in ("results.csv", "series.csv", "impacts.csv", "provenance.json"):
        path = run_dir / name
        path.write_text(path.read_text().replace("mujoco", MATHTEXT))
    series = pd.read_csv(run_dir / "series.csv")
    series.loc[3, "t"] = 1e308
    series.loc[4, "energy"] = -1e300
    series.to_csv(run_dir / "series.csv", index=False)
    assert main(["report", str(run_dir)]) == 0, capsys.readouterr().err
    page = (run_dir / "report.html").read_text()
    assert "values non-finite or beyond" in page and "not drawn" in page


@pytest.mark.parametrize("damage", ["a folder", "not UTF-8"])
def test_an_unreadable_results_file_is_exit_2_naming_it(tmp_path, capsys, damage):
    run_dir = write_synthetic_run(tmp_path / "run")
    results = run_dir / "results.csv"
    results.unlink()
    if damage == "a folder":
        results.mkdir()
    else:
        results.write_bytes(b"scenario,engine\n\xff\xfe\x00garbage\n")
    assert "results.csv" in refused(["report", str(run_dir)], capsys)


OUT_TARGETS = {
    "a file": lambda root: root / "precious.txt",
    "below a file": lambda root: root / "precious.txt" / "below",
    "a symlink to a file": lambda root: root / "link",
}
"""``--out`` values that name something the command must not write (or cannot write into)."""

OUT_COMMANDS = {
    "sweep": ["sweep", PROJECTILE, "--engines", "mini", "--dt", "4e-3,2e-3", "--jobs", "1"],
    "stability": ["stability", PROJECTILE, "--engines", "mini", "--jobs", "1"],
}


@pytest.mark.parametrize("target", sorted(OUT_TARGETS))
@pytest.mark.parametrize("command", sorted(OUT_COMMANDS))
def test_sweep_and_stability_refuse_a_bad_out_before_any_work(tmp_path, capsys, command, target):
    """``sweep --out DIR`` and ``stability --out FILE``: a file where a folder must be, a
    path below a file, a symlink that a rename would replace: one line naming ``--out``,
    exit 2, before any engine runs, and the user's file untouched (``stability --out`` at a
    file it may replace is refused only through a symlink; sweep wrote a traceback after
    all its work before, and stability replaced the link)."""
    (tmp_path / "precious.txt").write_text("precious")
    (tmp_path / "link").symlink_to(tmp_path / "precious.txt")
    out = OUT_TARGETS[target](tmp_path)
    if command == "stability" and target == "a file":
        out = tmp_path / "folder"  # the file is its output; a folder is what it must refuse
        out.mkdir()
    start = time.monotonic()
    code = main([*OUT_COMMANDS[command], "--out", str(out)])
    seconds = time.monotonic() - start
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, (code, err)
    assert len(err) == 1 and err[0].startswith(f"--out {out}:"), err
    assert seconds < BAD_INPUT_SECONDS, f"refused after {seconds:.1f} s: after the work"
    assert (tmp_path / "precious.txt").read_text() == "precious"
    assert (tmp_path / "link").is_symlink()


SELF_REFERENCE = "a: &a [*a]\n"
"""Ten bytes: an alias inside its own anchor. It was a RecursionError traceback in check,
run and ``pytest --physval``."""


def _laughs(levels: int = 9) -> str:
    """A billion-laughs document: each level lists the previous one nine times (9¹⁰ values
    once expanded, from 0.5 kB)."""
    lines = ['l0: &l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (SELF_REFERENCE, "refers to the value that contains it"),
        (_laughs(), "more than 1000000 values"),
        ("a: " + "[" * 100 + "]" * 100 + "\n", "deeper than 32 levels"),
    ],
    ids=["self-reference", "billion laughs", "deep nesting"],
)
def test_documents_that_expand_without_end_are_refused_before_they_are_built(
    tmp_path, capsys, monkeypatch, text, expected
):
    """One line naming the place and exit 2 in ``run`` and ``check``, and not a value built:
    the refusal is decided on the composed node graph (a bomb expanded took 6 s)."""
    built = []
    real_build = yaml_source._Builder.build
    monkeypatch.setattr(
        yaml_source._Builder, "build", lambda self, *a: built.append(1) or real_build(self, *a)
    )
    path = scene(tmp_path, text)
    line = refused(["run", str(path), "--out", str(tmp_path / "out")], capsys)
    assert (expected in line and f"{path}:1:" in line) or f"{path}:" in line, line
    assert not built, f"{len(built)} values were built before the refusal"
    assert exit_code(["check", str(path)]) == 2
    output = capsys.readouterr()
    assert expected in output.out + output.err and "Traceback" not in output.out + output.err


def test_the_pytest_plugin_reports_a_self_referencing_scene_in_one_line(tmp_path):
    path = scene(tmp_path, SELF_REFERENCE)
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "--physval", str(path), "-q", "-p", "no:cacheprovider"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    output = result.stdout + result.stderr
    assert result.returncode != 0 and "refers to the value that contains it" in output, output
    assert "RecursionError" not in output and "Traceback" not in output, output[-2000:]
