"""One colour (and dash) per engine spec, the same on every plot of every page.

``engine_style(spec)`` is keyed by the spec's label alone, never by its position in a run, so
``mujoco(integrator=RK4)`` is the same orange in report.html, sweep.html, history.html and
compare.html, whatever else the run had. The library's specs have fixed entries; any other
spec takes a colour chosen by a hash of its label (deterministic across runs and machines).
"""

from __future__ import annotations

import hashlib
from typing import NamedTuple


class Style(NamedTuple):
    """How an engine spec's line is drawn: its colour and its SVG dash pattern."""

    colour: str
    dash: str
    """SVG ``stroke-dasharray`` ("" solid); matplotlib takes it through ``mpl_dash``."""


SPEC_STYLES: dict[str, Style] = {
    "mini": Style("#0072B2", ""),
    "mujoco": Style("#D55E00", "6 3"),
    "pybullet": Style("#009E73", "2 2"),
    "mujoco(integrator=RK4)": Style("#E69F00", "8 3 2 3"),
    "mujoco(restitution=soft)": Style("#CC79A7", "4 2"),
    "mini(gyroscopic=implicit)": Style("#56B4E9", "6 3"),
    "mini(gyroscopic=explicit)": Style("#332288", "2 2"),
    "mini(solver_iterations=50)": Style("#882255", "8 3 2 3"),
}
"""The library's engine specs (the three default engines and the variants its scenes name):
Okabe-Ito colours, readable with colour-blindness, then Tol's indigo and wine; dashes keep
coinciding lines (the usual case) apart."""

OTHER_COLOURS = ("#44AA99", "#999933", "#AA4499", "#661100", "#6699CC", "#117733", "#000000")
"""Colours of specs outside ``SPEC_STYLES``, chosen by a hash of the label: none of them is one
of the library's, so another spec never looks like a library one."""

OTHER_DASHES = ("", "6 3", "2 2", "8 3 2 3")
"""Dashes of specs outside ``SPEC_STYLES``, chosen by another part of the same hash."""


def engine_style(spec: str) -> Style:
    """The colour and dash of engine spec ``spec`` (its label) on every page."""
    if spec in SPEC_STYLES:
        return SPEC_STYLES[spec]
    digest = hashlib.sha256(str(spec).encode("utf-8")).digest()
    return Style(
        OTHER_COLOURS[digest[0] % len(OTHER_COLOURS)], OTHER_DASHES[digest[1] % len(OTHER_DASHES)]
    )


def engine_colour(spec: str) -> str:
    """The colour of engine spec ``spec`` on every page."""
    return engine_style(spec).colour


def mpl_dash(dash: str) -> tuple[int, tuple[float, ...]] | str:
    """An SVG dash pattern as a matplotlib line style (the pages drawn with matplotlib)."""
    return (0, tuple(float(part) for part in dash.split())) if dash else "-"
