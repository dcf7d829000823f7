"""The library's model scenes (scenarios/models/, issue 36): robots from the model files of
installed packages, each expanded into the links and joints its file has, swinging clear of
its joint limits, and passing its checks in every engine it names (known findings aside)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from validation.cli import BUNDLED_SCENARIOS, main
from validation.contract import RESULTS_FILE
from validation.jobs.plan import plan_run
from validation.reference.articulated import (
    Loads,
    acceleration,
    initial_velocities,
    position_rate,
)
from validation.scenario.compiled import compile_scene
from validation.scenario.load import load_scenario

MODELS = BUNDLED_SCENARIOS / "models"

EXPANSION = {
    # scene: (bodies, hinges, sliders, fixed joints)
    "kuka_iiwa_swing": (7, 7, 0, 0),  # link_0 massless: folded, joint 1 hangs from the world
    "pendulum5_swing": (5, 5, 0, 0),  # the massless "world" link folded
    "cartpole_swing": (2, 1, 1, 0),  # the massless rail folded
    "a1_hanging": (22, 12, 0, 10),  # every link has mass: 9 welds and the fixed base's
    "inverted_double_pendulum_swing": (3, 2, 1, 0),  # MJCF: cart and two poles
}
"""What each scene's model expands into (``validation/scenario/urdf.py``), counted from its
file: a massless link on a fixed joint (or a fixed base's massless root) is folded into its
parent, a massive one stays a body on a fixed joint."""

LIMIT_MARGIN = 0.05
"""rad or m: the reference swing keeps every joint this far inside its limits at least (first-
order engines follow it within 1e-2 rad over these swings: the scenes' divergence tolerances
over their levers), so no engine meets a limit."""

SWING_RTOL = 1e-6
"""The limit checks' integration tolerance: the joints' equations of the reference side
(``articulated.position_rate``, ``acceleration``) by DOP853, but at 1e-6, not the reference's
3e-14 (a limit's distance is judged at ``LIMIT_MARGIN``; the tight one takes 20 s on Kuka)."""

A1_FIRST_LIMIT = 0.172
"""s: when the joint-space reference puts the A1's knees on their limits (a hanging leg has no
equilibrium inside them); the scene ends before."""


def reference_swing(scene_name: str, end: float | None = None):
    """The scene's joints from its stated state under gravity, no limits (``SWING_RTOL``),
    sampled every ms to ``end`` (default its duration): its tree, scenario, times and q."""
    scene = compile_scene(load_scenario(MODELS / f"{scene_name}.yaml"))
    tree = scene.joint_tree
    loads = Loads(scene.gravity, scene.springs, scene.force, scene.torque)
    nu0, _ = initial_velocities(tree, scene.start.vel[0], scene.start.ang_vel[0])
    end = scene.scenario.duration if end is None else end
    times = np.linspace(0.0, end, round(end / 1e-3) + 1)

    def rates(_t: float, state: np.ndarray) -> np.ndarray:
        q, nu = state[: tree.nq], state[tree.nq :]
        return np.concatenate([position_rate(tree, q, nu), acceleration(tree, q, nu, loads)])

    start = np.concatenate([tree.zero(), nu0])
    solution = solve_ivp(rates, (0.0, end), start, "DOP853", times, rtol=SWING_RTOL, atol=1e-9)
    return tree, scene.scenario, times, solution.y[: tree.nq].T


def limit_slack(scene_name: str, end: float | None = None) -> tuple[float, float | None]:
    """The smallest distance (rad or m) of any limited joint from its limits over the
    reference swing, and the first time one is beyond them (None: never)."""
    tree, scenario, times, q = reference_swing(scene_name, end)
    limits = {j.name: j.limits for j in scenario.joints if getattr(j, "limits", None)}
    slack, first = np.inf, None
    for joint in tree.joints:
        if joint.name not in limits:
            continue
        (low, high), path = limits[joint.name], q[:, joint.q_slice.start]
        distance = np.minimum(path - low, high - path)
        slack = min(slack, float(distance.min()))
        beyond = np.nonzero(distance < 0)[0]
        if beyond.size and (first is None or times[beyond[0]] < first):
            first = float(times[beyond[0]])
    return slack, first


@pytest.mark.parametrize("scene_name", sorted(EXPANSION))
def test_each_model_expands_into_the_links_and_joints_of_its_file(scene_name):
    scenario = load_scenario(MODELS / f"{scene_name}.yaml")
    types = [joint.type for joint in scenario.joints]
    counted = (len(scenario.bodies), types.count("hinge"), types.count("slider"))
    assert (*counted, types.count("fixed")) == EXPANSION[scene_name]
    prefix = scenario.models[0].name + "/"
    assert all(body.name.startswith(prefix) for body in scenario.bodies)


@pytest.mark.parametrize("scene_name", sorted(EXPANSION))
def test_the_swing_stays_clear_of_every_joint_limit(scene_name):
    slack, first = limit_slack(scene_name)
    assert first is None and slack > LIMIT_MARGIN, (slack, first)


def test_the_a1_swing_ends_before_its_knees_reach_their_limits():
    # the duration is what keeps the A1 off its limits: 25 ms longer and the knees are on them
    _, first = limit_slack("a1_hanging", end=A1_FIRST_LIMIT + 0.025)
    assert first == pytest.approx(A1_FIRST_LIMIT, abs=2e-3)


WITHOUT_MODELS = "*scenarios/[!m]*"
"""The ``--only`` pattern the docs give for the library without ``models/`` (nightly.md)."""


def test_only_can_leave_the_model_scenes_out_of_a_library_run():
    everything = {
        job[0].scenario.name for job in plan_run([BUNDLED_SCENARIOS], None, None, None).jobs
    }
    kept = {
        job[0].scenario.name
        for job in plan_run([BUNDLED_SCENARIOS], None, None, WITHOUT_MODELS).jobs
    }
    assert everything - kept == set(EXPANSION)


@pytest.fixture(scope="module")
def library_run(tmp_path_factory) -> tuple[int, pd.DataFrame]:
    """The model scenes run in the engines they name (one worker: the machine is shared): the
    exit code and results.csv."""
    out = tmp_path_factory.mktemp("models") / "run"
    arguments = ["run", str(MODELS), "--out", str(out), "--jobs", "1"]
    code = main([*arguments, "--history", "none", "--baseline", "none"])
    return code, pd.read_csv(out / RESULTS_FILE, keep_default_na=False)


def test_every_model_scene_passes_its_checks_in_every_engine(library_run):
    code, rows = library_run
    judged = rows[rows["tolerance"] != ""]
    assert set(judged["scenario"]) == set(EXPANSION)
    bad = judged[~judged["outcome"].isin(["passed", "known"])]
    assert bad.empty, bad[["scenario", "engine", "metric", "value", "tolerance"]].to_string()
    assert code == 0


KNOWN_ROWS = sorted(
    [
        *(
            (scene, "mini", metric)
            for scene in ("a1_hanging", "kuka_iiwa_swing")
            for metric in ("agreement_time", "divergence", "joint_divergence")
        ),
        *(
            ("pendulum5_swing", "mujoco", metric)
            for metric in ("agreement_time", "divergence", "joint_divergence")
        ),
        *(
            ("pendulum5_swing", engine, "model_fields")
            for engine in ("drake", "mini", "pybullet", "rapier")
        ),
        *(
            ("inverted_double_pendulum_swing", "pybullet", metric)
            for metric in (
                "agreement_time",
                "bias_force_error",
                "divergence",
                "joint_divergence",
                "mass_matrix_error",
                "model_fields",
            )
        ),
    ]
)
"""The rows the scenes declare known, each with its measured reason: mini's rotation law
without the gyroscopic term (three-dimensional swings), MuJoCo's reading of the URDF's joint
friction and the other engines' dropping it (tier 1), PyBullet's MJCF loader (damping and inertias)."""


def test_the_known_findings_are_the_declared_ones(library_run):
    _, rows = library_run
    known = rows[rows["outcome"] == "known"]
    assert (
        sorted(zip(known["scenario"], known["engine"], known["metric"], strict=True)) == KNOWN_ROWS
    )
