"""docs/metrics.md is what ``validation.docs_reference`` generates from the definitions: the
documentation and the code cannot drift apart."""

from __future__ import annotations

from pathlib import Path

from validation.docs_reference import DOC_PATH, render
from validation.measure.definitions import EXPECTATION_DEFINITIONS, METRIC_DEFINITIONS

REPOSITORY = Path(__file__).resolve().parent.parent


def test_the_metric_reference_is_the_generated_one():
    on_disk = (REPOSITORY / DOC_PATH).read_text()
    assert on_disk == render(), (
        f"{DOC_PATH} is stale: python -m validation.docs_reference > {DOC_PATH}"
    )


def test_every_metric_and_expectation_has_its_row():
    text = render()
    for name in (*METRIC_DEFINITIONS, *EXPECTATION_DEFINITIONS):
        assert f"| `{name}` |" in text, name
