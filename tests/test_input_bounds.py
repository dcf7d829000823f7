"""Values that read as a different number, or whose products leave the floats: each refused
by ``check`` and ``run`` in one line naming the file, the line, the field and what was
expected (exit 2, no traceback, before any work); and ``check`` linear in the file."""

from __future__ import annotations

import time

import pytest

from validation.cli import main
from validation.scenario import Scenario
from validation.scenario.checks import document_problems
from validation.scenario.yaml_source import SourceMap

BALL = """dt: 1.0e-3
duration: 0.1
engines: [mini]
gravity: [0.0, 0.0, {gravity}]
bodies:
  - name: ball
    shape: {{type: sphere, radius: 0.1}}
    mass: {mass}
    force: [0.0, 0.0, {force}]
    position: [0.0, 0.0, 1.0]
    velocity: [3.0, 0.0, 8.0]
"""
"""One ball in flight; gravity, mass and force filled in (line 4, 8 and 9)."""

LINE = {"gravity": 4, "mass": 8, "force": 9}


def ball(tmp_path, gravity="-9.81", mass="1.0", force="0.0"):
    path = tmp_path / "ball.yaml"
    path.write_text(BALL.format(gravity=gravity, mass=mass, force=force))
    return path


def refusal(argv: list[str], capsys) -> str:
    """``physval ARGV``: exit 2 and its first stderr line, no traceback."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return err.strip().splitlines()[0]


def test_the_scene_as_written_is_valid(tmp_path, capsys):
    """The control: the file of every case below is valid with ordinary values."""
    assert main(["check", str(ball(tmp_path))]) == 0


@pytest.mark.parametrize(
    ("text", "value"), [("010", "8"), ("1:30", "90"), ("0b101", "5"), ("1:30.5", "90.5")]
)
def test_yaml_1_1_number_forms_are_refused_at_their_field(tmp_path, capsys, text, value):
    """PyYAML reads ``010`` as 8, ``1:30`` as 90 and ``0b101`` as 5 (YAML 1.1); YAML 1.2 reads
    them as 10 or text: the file means one number, so the form is refused, never guessed."""
    path = ball(tmp_path, mass=text)
    line = refusal(["check", str(path)], capsys)
    assert line.startswith(
        f"{path}:{LINE['mass']}:5: bodies[0].mass: {text} is {value} in YAML 1.1"
    )
    assert "expected a decimal number" in line
    assert refusal(["run", str(path), "--out", str(tmp_path / "out")], capsys) == line
    assert not (tmp_path / "out").exists()


def test_a_quoted_form_is_text_and_a_hexadecimal_number_reads_alike_in_both(tmp_path, capsys):
    """Only the forms the two YAML versions read differently are refused."""
    assert main(["check", str(ball(tmp_path, mass="0x10"))]) == 0
    line = refusal(["check", str(ball(tmp_path, mass='"010"'))], capsys)
    assert "bodies[0].mass: expected a valid number" in line


@pytest.mark.parametrize("text", ["5e-324", "-1e-310", "1e-400"])
def test_subnormal_numbers_are_refused_not_a_crash(tmp_path, capsys, text):
    """A mass of 5e-324 crashed ``check`` (a singular inertia); 1e-400 rounds to 0 silently."""
    path = ball(tmp_path, force=text)
    line = refusal(["check", str(path)], capsys)
    assert line.startswith(f"{path}:{LINE['force']}:23: bodies[0].force[2]: {text} is below")
    line = refusal(["check", str(ball(tmp_path, mass="5e-324"))], capsys)
    assert "bodies[0].mass: 5e-324 is below 2.2250738585072014e-308" in line


def test_a_mass_whose_inertia_is_subnormal_is_refused(tmp_path, capsys):
    """1e-307 kg is a normal double, its sphere's inertia (4e-310 kg·m²) is not."""
    line = refusal(["check", str(ball(tmp_path, mass="1.0e-307"))], capsys)
    assert "bodies[0]: the inertia of 'ball'" in line and "underflows" in line


@pytest.mark.parametrize(
    ("field", "values", "where"),
    [
        ("mass", {"mass": "1.0e308"}, "bodies[0].mass"),
        ("force", {"force": "1.0e308"}, "bodies[0].force"),
        ("gravity", {"gravity": "-1.0e308"}, "gravity"),
        ("mass", {"mass": "1.0e200"}, "bodies[0].mass"),
    ],
)
def test_values_whose_products_overflow_are_refused_before_any_work(
    tmp_path, capsys, field, values, where
):
    """A mass, force or gravity of 1e308 gave NaN rows marked ok; now the field is named."""
    path = ball(tmp_path, **values)
    started = time.monotonic()
    line = refusal(["run", str(path), "--out", str(tmp_path / "out")], capsys)
    assert time.monotonic() - started < 5
    assert line.startswith(f"{path}:{LINE[field]}:")
    assert f": {where}: " in line and "LARGEST_SCALE" in line
    assert not (tmp_path / "out").exists()


def _checks_scene(entries: int) -> Scenario:
    return Scenario.model_validate(
        {
            "dt": 1e-3,
            "duration": 0.1,
            "engines": ["mini"],
            "bodies": [{"name": "b", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1.0}],
            "expect": [
                {
                    "name": f"p{i}",
                    "kind": "position_at",
                    "body": "b",
                    "time": 0.05,
                    "value": [0, 0, 1],
                }
                for i in range(entries)
            ],
            "checks": {f"p{i}": 1e-3 for i in range(entries)},
        }
    )


def _rules_seconds(scenario: Scenario) -> float:
    """The fastest of three passes of the whole-document rules (CPU seconds)."""
    best = float("inf")
    for _ in range(3):
        started = time.process_time()
        assert document_problems(scenario, "scene.yaml", SourceMap()) == []
        best = min(best, time.process_time() - started)
    return best


LINEAR_RATIO = 16
"""8 times the entries: a linear rule takes about 8 times as long, a quadratic one 64 times
(16,000 entries took 50 s before the expectation map was built once); 16 leaves twice the
linear ratio for a shared machine's noise."""


def test_check_is_linear_in_the_checks_entries():
    small, large = (_rules_seconds(_checks_scene(n)) for n in (1000, 8000))
    assert large < LINEAR_RATIO * small, (small, large)
