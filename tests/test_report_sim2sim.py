"""The report's sim2sim card (issue 36): per engine of a scene with model tiers, the first
tier where its rows disagree, the row's message and numbers, or that it agrees on every tier,
and what that points at; rendered from results.csv alone."""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from validation.contract import RESULTS_COLUMNS, RESULTS_FILE
from validation.report import render, sim2sim

SCENE = "kuka_iiwa_swing"
SECOND = "cartpole_swing"
"""A second scene with tier rows, its engines in another order than the first's."""
PLAIN = "projectile"
"""A scene with energy and joint rows but no tier rows: it gets no card."""

ENGINES = ("mini", "mujoco", "pybullet", "drake", "rapier")
"""The scene's engines, the reference first: the card keeps this order."""

INERTIA_MESSAGE = "link arm/lbr_iiwa_link_3: inertia differs by 2.30e-01 (relative)"
BIAS_MESSAGE = "at configuration 3 of 5, b[2] (arm/lbr_iiwa_joint_3): off by 0.04 of max |b| 12.1"
ENERGY_MESSAGE = "max|ΔE| 0.31 J over E_scale 12.4 J"
CRASH_MESSAGE = "the engine raised <RuntimeError> at t = 0.2 s"
KNOWN_REASON = "Drake's discrete solver damps the swing (measured 0.25 s lost)"


def row(engine, metric, value, tolerance, message="", scene=SCENE, **columns):
    """One results.csv row with every contract column, judged as the runner judges it."""
    passed = None if tolerance is None else abs(value) <= tolerance
    base = dict.fromkeys(RESULTS_COLUMNS, "")
    base.update(
        scenario=scene,
        engine=engine,
        metric=metric,
        value=value,
        expected=0.0,
        expected_kind="analytic",
        error=abs(value) if value is not None else None,
        tolerance=tolerance,
        passed=passed,
        status="failed" if passed is False else "ok",
        dt=0.001,
        steps=1000,
        wall_time_s=0.1,
        engine_version="1.0",
        settings="{}",
        message=message,
    )
    base.update(columns)
    return base


def tier_rows() -> list[dict]:
    """mini agrees everywhere; mujoco's model fields differ (and its trajectory, later in the
    order); pybullet's bias forces (and its trajectory); drake only its trajectory, energy the
    worse of two failing rows, agreement_time a known finding; rapier crashed."""
    mini, mujoco, pybullet, drake, rapier = ENGINES
    return [
        row(mini, "model_fields", 1e-15, 1e-6),
        row(mini, "fk_error", 1e-16, 1e-9),
        row(mini, "energy_drift", 1e-4, 1e-3),
        row(mini, "joint_violation", 1e-5, 2e-5),
        row(mujoco, "joint_divergence", 0.5, 8e-3),  # listed first: the card orders by tier
        row(mujoco, "fk_error", 3e-3, 1e-9, "at configuration 2 of 5, link arm/link4 ..."),
        row(mujoco, "model_fields", 0.23, 1e-6, INERTIA_MESSAGE),
        row(mujoco, "mass_matrix_error", 1e-2, 1e-8, "M[2,3] ..."),
        row(pybullet, "model_fields", 1e-12, 1e-6),
        row(pybullet, "fk_error", 1e-12, 1e-9),
        row(pybullet, "mass_matrix_error", 1e-10, 1e-8),
        row(pybullet, "bias_force_error", 4e-3, 1e-8, BIAS_MESSAGE),
        row(pybullet, "joint_divergence", 0.2, 8e-3),
        row(drake, "model_fields", 1e-12, 1e-6),
        row(drake, "fk_error", 1e-12, 1e-9),
        row(drake, "mass_matrix_error", 1e-10, 1e-8),
        row(drake, "bias_force_error", 1e-10, 1e-8),
        row(drake, "joint_divergence", 4e-3, 8e-3),
        row(drake, "agreement_time", 0.25, 0.1, outcome="known", known=KNOWN_REASON),
        row(drake, "energy_drift", 2.5e-2, 1e-3, ENERGY_MESSAGE),
        row(rapier, "status", None, None, CRASH_MESSAGE, status="crashed", error=None),
        row("mujoco", "model_fields", 1e-15, 1e-6, scene=SECOND),
        row("mini", "model_fields", 1e-15, 1e-6, scene=SECOND),
        row("mini", "energy_drift", 1e-4, 1e-3, scene=PLAIN),
        row("mujoco", "energy_drift", 1e-4, 1e-3, scene=PLAIN),
    ]


class CardCells(HTMLParser):
    """Each ``table.sim2sim`` row's engine and cell texts, in page order."""

    def __init__(self):
        super().__init__()
        self.rows: list[tuple[str, list[str]]] = []
        self.in_card = False
        self.cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        attributes = dict(attrs)
        if tag == "table" and "sim2sim" in (attributes.get("class") or "").split():
            self.in_card = True
        elif self.in_card and tag == "tr" and "data-engine" in attributes:
            self.rows.append((attributes["data-engine"], []))
        elif self.in_card and tag == "td":
            self.cell = []

    def handle_endtag(self, tag):
        if tag == "table":
            self.in_card = False
        elif tag == "td" and self.cell is not None:
            self.rows[-1][1].append(" ".join("".join(self.cell).split()))
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell.append(data)


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> str:
    run_dir = tmp_path_factory.mktemp("run")
    pd.DataFrame(tier_rows(), columns=RESULTS_COLUMNS).to_csv(run_dir / RESULTS_FILE, index=False)
    return Path(render.render_report(run_dir)).read_text()


def cards(html: str) -> dict[str, dict[str, list[str]]]:
    """Scene anchor -> its card: engine -> the texts of its line after the engine's own cell,
    engines in page order."""
    found = {}
    for section in html.split('<section class="scene" id="')[1:]:
        parser = CardCells()
        parser.feed(section)
        if parser.rows:
            found[section.split('"', 1)[0]] = {e: cells[1:] for e, cells in parser.rows}
    return found


def test_each_card_lists_its_scenes_engines_in_the_scenes_order(page):
    order = {scene: list(card) for scene, card in cards(page).items()}
    assert order == {f"scene-{SCENE}": list(ENGINES), f"scene-{SECOND}": ["mujoco", "mini"]}


def test_each_engine_shows_its_first_disagreeing_tier_with_the_rows_message_and_numbers(page):
    lines = cards(page)[f"scene-{SCENE}"]
    assert lines["mini"] == [sim2sim.AGREES]
    # engine, then: tier, metric, outcome, value, tolerance, ratio, message, fix
    assert lines["mujoco"][:5] == [
        "tier 1: model fields",
        "model_fields",
        "failed",
        "0.23",
        "1e-06",
    ]
    assert lines["mujoco"][6:] == [INERTIA_MESSAGE, sim2sim.FIX_MODEL]
    assert lines["pybullet"][:2] == ["tier 3: mass matrix and bias forces", "bias_force_error"]
    assert lines["pybullet"][3:5] == ["0.004", "1e-08"]
    assert lines["pybullet"][6:] == [BIAS_MESSAGE, sim2sim.FIX_MODEL]
    # the trajectory tier's worst row (energy 25x its tolerance; the known agreement time 2.5x)
    assert lines["drake"][:5] == ["tier 4: trajectory", "energy_drift", "failed", "0.025", "0.001"]
    assert lines["drake"][6:] == [ENERGY_MESSAGE, sim2sim.FIX_SOLVER]
    assert lines["rapier"][:3] == [sim2sim.NOT_MEASURED, "status", "crashed"]
    assert CRASH_MESSAGE in lines["rapier"][6]


def test_a_known_finding_is_a_disagreement_and_shows_its_reason():
    rows = [
        {"metric": "agreement_time", "outcome": "known", "engine": "drake"},
        {"metric": "joint_divergence", "outcome": "passed", "engine": "drake"},
    ]
    assert sim2sim.first_disagreement(rows) == (3, rows[0])
    known = {**dict.fromkeys(sim2sim.SHOWN, ""), **rows[0], "known": KNOWN_REASON}
    line = sim2sim.engine_line("drake", [known])
    assert (line.tier, line.fix, line.known) == (
        "tier 4: trajectory",
        sim2sim.FIX_SOLVER,
        KNOWN_REASON,
    )


def test_only_a_scene_with_tier_rows_gets_a_card(page):
    assert f"scene-{PLAIN}" not in cards(page)
    card_of = sim2sim.build_sim2sim_card
    assert card_of([{"metric": "energy_drift", "engine": "mini"}], ["mini"]) is None
