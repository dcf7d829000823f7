"""Memory bounded by the work: what a run keeps does not grow with bodies x samples, the
metrics read it as if they had the whole trajectory, and a run that cannot fit is refused
before any work."""

from __future__ import annotations

import dataclasses
from dataclasses import fields

import numpy as np
import pytest

from validation.jobs import memory
from validation.jobs.run import run_job, run_main
from validation.measure import impact_log, metrics
from validation.measure import recording as recording_module
from validation.measure.metrics import Context
from validation.measure.states import Series, Trajectory, ballistic, invariants
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec
from validation.scenario.physics import GROUND

BODIES = 6
DT = 0.01
SHORT_STEPS = 50
"""A run of N steps and one of 4N (``LONG_STEPS``): both keep every step as a sample."""
LONG_STEPS = 4 * SHORT_STEPS
KEPT_POSITIONS = BODIES * 3 * 20
"""A budget of 20 samples of positions (``recording.MAX_KEPT_POSITIONS``, made small so that
both runs exceed it)."""


def free_spheres(bodies: int, steps: int, engines=("mini",)) -> Scenario:
    """``bodies`` spheres 1 m apart in a row under gravity, no ground, each with its own
    velocity, flying apart (one sphere alone has the ballistic metrics: two can touch)."""
    return Scenario.model_validate(
        {
            "name": f"free_{bodies}_{steps}",
            "dt": DT,
            "duration": steps * DT,
            "engines": list(engines),
            "bodies": [
                {
                    "name": f"s{k}",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0 + k,
                    "position": [float(k), 0.0, 0.0],
                    "velocity": [0.3 * k, 0.1, 2.0 - k],
                    "angular_velocity": [0.0, 0.5 * k, 0.0],
                }
                for k in range(bodies)
            ],
        }
    )


def test_kept_positions_stay_within_their_budget_however_long_the_run(monkeypatch):
    """A run of N and of 4N steps keep at most ``MAX_KEPT_POSITIONS`` numbers of positions
    (plus the final state's), orientations and velocities none, and a series with no body
    dimension: at most 21 numbers a sample (``memory.SERIES_NUMBERS``) whatever the bodies."""
    monkeypatch.setattr(recording_module, "MAX_KEPT_POSITIONS", KEPT_POSITIONS)
    kept = {}
    for steps in (SHORT_STEPS, LONG_STEPS):
        run, _ = run_job((compile_scene(free_spheres(BODIES, steps)), parse_engine_spec("mini")))
        trajectory, series = run.recording.trajectory, run.recording.series
        numbers = trajectory.pos.size + trajectory.quat.size + trajectory.vel.size
        numbers += trajectory.ang_vel.size
        assert numbers <= KEPT_POSITIONS + BODIES * 3, (steps, numbers, trajectory.pos.shape)
        per_sample = sum(getattr(series, f.name).size for f in fields(Series)) / series.t.size
        assert series.t.size == steps + 1, series.t.size  # every step still a sample
        assert per_sample <= memory.SERIES_NUMBERS, per_sample
        kept[steps] = numbers
    assert kept[LONG_STEPS] < 2 * kept[SHORT_STEPS], kept  # four times the samples


def test_the_thinned_positions_are_every_kth_sample_in_every_engine(monkeypatch):
    """Thinned positions are the same samples in every engine of a scene (every k-th kept
    sample and the last), so divergence still compares two engines at common times."""
    monkeypatch.setattr(recording_module, "MAX_KEPT_POSITIONS", KEPT_POSITIONS)
    scene = compile_scene(free_spheres(BODIES, LONG_STEPS, ("mini", "mujoco")))
    stride = recording_module.position_stride(scene, 1)
    times = {}
    for engine in ("mini", "mujoco"):
        run, _ = run_job((scene, parse_engine_spec(engine)))
        times[engine] = run.recording.trajectory.t
    expected = np.unique(np.r_[np.arange(0, LONG_STEPS + 1, stride), LONG_STEPS]) * DT
    assert stride > 1, stride
    np.testing.assert_allclose(times["mini"], expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(times["mujoco"], expected, rtol=0, atol=1e-9)


def _largest(difference: np.ndarray) -> tuple[float, tuple[float, ...]]:
    """The whole-trajectory definition: the largest norm over samples and bodies of
    ``difference (s, n, 3)`` and that difference."""
    distance = np.linalg.norm(difference, axis=2)
    sample, body = np.unravel_index(int(np.argmax(distance)), distance.shape)
    return float(distance[sample, body]), tuple(float(x) for x in difference[sample, body])


def _wobbling(scene, samples: int) -> Trajectory:
    """``samples`` states of the scene's bodies near their ballistic motion, each off it by a
    different deterministic amount, tumbling (so each body's share differs)."""
    rng = np.random.default_rng(7)
    t = np.arange(samples) * DT
    pos, vel = ballistic(scene, t)
    shape = pos.shape
    quat = rng.normal(size=(*shape[:2], 4))
    quat /= np.linalg.norm(quat, axis=2, keepdims=True)
    return Trajectory(
        t,
        pos + 1e-3 * rng.normal(size=shape),
        quat,
        vel + 1e-2 * rng.normal(size=shape),
        rng.normal(size=shape),
    )


def test_metrics_from_the_series_equal_the_whole_trajectory_definitions():
    """position_error, velocity_error, energy_drift's scale and the series, computed a batch at
    a time as a run does, are bit for bit the maxima over the whole trajectory of every body
    (6 bodies, 601 samples in batches of 256)."""
    scene = compile_scene(free_spheres(BODIES, 600))
    states = _wobbling(scene, 601)
    size = recording_module.BATCH_OBSERVATIONS
    parts = [
        invariants(scene, states.take(slice(first, first + size)), free=True)
        for first in range(0, len(states), size)
    ]
    series = Series.concat(*parts)
    ctx = Context(scene, recording_module.Recording(states, [], 0.0, series))
    analytic = ballistic(scene, states.t)
    for compute, difference in (
        (metrics.position_error, states.pos - analytic[0]),
        (metrics.velocity_error, states.vel - analytic[1]),
    ):
        found = compute(ctx)
        value, signed = _largest(difference)
        assert (found.value, found.signed) == (value, signed), (found, value, signed)
    # the internal energy of the whole trajectory (free spheres): kinetic energy about the
    # centre of mass plus the centre of mass's change of kinetic energy since the start
    centre = np.einsum("n,sni->si", scene.mass, states.vel) / scene.mass.sum()
    about = scene.kinetic_energy(states.quat, states.vel - centre[:, None], states.ang_vel)
    change = 0.5 * scene.mass.sum() * np.sum((centre - centre[0]) ** 2, axis=1)
    largest = float(np.max(about + change, initial=0.0))
    assert metrics.energy_scale(ctx)[1] == largest, (metrics.energy_scale(ctx), largest)
    whole = scene.energy(states.pos, states.quat, states.vel, states.ang_vel)
    assert np.array_equal(series.energy, whole), np.abs(series.energy - whole).max()
    per_sample = sum(getattr(series, f.name)[0].size for f in fields(Series))
    assert per_sample == memory.SERIES_NUMBERS, per_sample  # what the estimate counts


def test_a_batch_of_a_large_scene_holds_a_bounded_number_of_body_states():
    """Scenes up to 1,024 bodies measure 256 states at a time (the library's numbers do not
    move); 10,000 bodies at most ``BATCH_BODY_STATES`` body states."""
    small = compile_scene(free_spheres(2, 10))
    assert recording_module.batch_size(small) == recording_module.BATCH_OBSERVATIONS
    large = compile_scene(free_spheres(10_000, 10))
    states = recording_module.batch_size(large) * large.count
    assert 0 < states <= recording_module.BATCH_BODY_STATES, states


def test_the_estimate_grows_with_the_bodies_not_with_the_duration():
    """Six times the duration (30 s against 5 s of 1,000 bodies) adds only the series' and
    no more positions than the budget; ten times the bodies adds the engine's share."""
    spec = parse_engine_spec("mini")

    def estimate(bodies: int, steps: int) -> int:
        return memory.job_estimate(compile_scene(free_spheres(bodies, steps)), spec, 1).worker

    short, long = estimate(1_000, 5_000), estimate(1_000, 30_000)
    series_growth = 2 * 25_000 * memory.SERIES_NUMBERS * 8
    positions_budget = 2 * recording_module.MAX_KEPT_POSITIONS * 8
    assert long - short <= series_growth + positions_budget, (short, long)
    assert estimate(10_000, 5_000) > short + 9_000 * memory.ENGINE_BYTES_PER_BODY["mini"]


def test_a_run_that_cannot_fit_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    """With 100 MB available, the run is exit 2, one line naming the scene file and its
    estimate, and nothing is written."""
    path = tmp_path / "free.yaml"
    path.write_text(free_spheres(BODIES, SHORT_STEPS).model_dump_json())
    monkeypatch.setattr(memory, "available_memory", lambda: 100 * memory.MB)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    code = run_main([path], "mini", out, None, None, ["run", str(path)])
    err = capsys.readouterr().err.strip()
    assert code == 2, (code, err)
    assert len(err.splitlines()) == 1, err
    assert str(path) in err and "estimated" in err and "100 MB available" in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == [path], list(tmp_path.iterdir())


def test_a_run_that_fits_is_not_refused(tmp_path, monkeypatch):
    """The same run with the machine's memory runs (the check refuses only what cannot fit)."""
    path = tmp_path / "free.yaml"
    path.write_text(free_spheres(2, 5).model_dump_json())
    monkeypatch.chdir(tmp_path)
    code = run_main([path], "mini", tmp_path / "out", None, None, ["run", str(path)])
    assert code in (0, 1), code
    assert (tmp_path / "out" / "results.csv").exists()


@pytest.mark.parametrize("text", ["MemTotal: 10 kB\n", "MemAvailable: lots\n"])
def test_available_memory_falls_back_when_meminfo_says_nothing(tmp_path, monkeypatch, text):
    """``/proc/meminfo`` without a readable MemAvailable: the free physical pages instead."""
    meminfo = tmp_path / "meminfo"
    meminfo.write_text(text)
    monkeypatch.setattr(memory, "MEMINFO", meminfo)
    found = memory.available_memory()
    assert found is None or found > 0, found


SAMPLED_IMPACTS = 8
WORST_IMPACTS = 2
"""The impact log's bounds made small (``impact_log.MAX_SAMPLED_IMPACTS``,
``MAX_WORST_IMPACTS``), so that runs of a few dozen impacts exceed them."""
IMPACTS_BOUND = SAMPLED_IMPACTS + WORST_IMPACTS * len(impact_log.RANKINGS)
"""The most impact records a run may keep under those bounds."""


@pytest.fixture
def small_impact_bounds(monkeypatch):
    monkeypatch.setattr(impact_log, "MAX_SAMPLED_IMPACTS", SAMPLED_IMPACTS)
    monkeypatch.setattr(impact_log, "MAX_WORST_IMPACTS", WORST_IMPACTS)


def bouncing_balls(balls: int, duration: float) -> Scenario:
    """``balls`` spheres 0.5 m apart dropped from 0.1 m and up onto the ground, each with its
    own e (0.8 and up, ground 0.9): a few impacts each per second, never one another."""
    return Scenario.model_validate(
        {
            "name": f"bouncing_{balls}_{duration:g}",
            "dt": 2e-3,
            "duration": duration,
            "engines": ["mini"],
            "ground": {"restitution": 0.9},
            "bodies": [
                {
                    "name": f"b{k}",
                    "shape": {"type": "sphere", "radius": 0.05},
                    "mass": 1.0,
                    "position": [0.5 * k, 0.0, 0.1 + 0.02 * k],
                    "restitution": 0.8 + 0.01 * k,
                }
                for k in range(balls)
            ],
        }
    )


BALLS = 12
SHORT_BOUNCING_S = 0.5
LONG_BOUNCING_S = 1.5
"""s: 19 impacts, and 72 (measured in mini), both over ``IMPACTS_BOUND``."""


def _restitution_row(measured: list) -> tuple:
    (row,) = [m for m in measured if m.metric == "restitution_error"]
    return (row.value, row.expected, row.error, row.band, row.signed, row.message)


def test_impact_records_stay_within_their_bound_however_many_impacts(small_impact_bounds):
    """Three times the duration, about four times the impacts: the records a run keeps stay
    within the bound, the count is every impact."""
    counts, kept = {}, {}
    for duration in (SHORT_BOUNCING_S, LONG_BOUNCING_S):
        run, _ = run_job(
            (compile_scene(bouncing_balls(BALLS, duration)), parse_engine_spec("mini"))
        )
        counts[duration] = run.recording.impact_count
        kept[duration] = len(run.recording.impacts)
    assert counts[LONG_BOUNCING_S] > 3 * counts[SHORT_BOUNCING_S] > 3 * IMPACTS_BOUND, counts
    assert max(kept.values()) <= IMPACTS_BOUND, (kept, IMPACTS_BOUND)


def test_restitution_error_from_the_kept_impacts_equals_the_one_from_every_impact(monkeypatch):
    """The same run keeping every impact and keeping a bounded set: restitution_error's row
    (the worst impact, its count) and the largest |Δe| are the same; the kept impacts are some
    of every impact, in the same order, and reach the end of the run."""
    scene = compile_scene(bouncing_balls(BALLS, LONG_BOUNCING_S))
    every_run, every_measured = run_job((scene, parse_engine_spec("mini")))
    monkeypatch.setattr(impact_log, "MAX_SAMPLED_IMPACTS", SAMPLED_IMPACTS)
    monkeypatch.setattr(impact_log, "MAX_WORST_IMPACTS", WORST_IMPACTS)
    kept_run, kept_measured = run_job((scene, parse_engine_spec("mini")))
    every, kept = every_run.recording.impacts, kept_run.recording.impacts
    assert len(every) == every_run.recording.impact_count == kept_run.recording.impact_count
    assert len(kept) <= IMPACTS_BOUND < len(every), (len(kept), len(every))
    assert _restitution_row(kept_measured) == _restitution_row(every_measured)
    positions = [every.index(event) for event in kept]
    assert positions == sorted(positions), positions
    assert positions[-1] >= len(every) - len(every) // SAMPLED_IMPACTS * 2, positions

    def largest_delta(events) -> float:
        return max(
            abs(e.restitution - scene.pair_value(e.body_a, e.body_b, "restitution")) for e in events
        )

    assert largest_delta(kept) == largest_delta(every)


SYNTHETIC_IMPACTS = 5_000
PLANTED = {"beyond_band": 3_333, "delta_e": 4_999, "nan": 2_717}
"""Ordinals of the planted worst impacts (odd: off every stride of the sample)."""


def _synthetic_impacts(scene) -> list:
    """``SYNTHETIC_IMPACTS`` ground impacts of body ``b`` (e 0.5) with |Δe| up to 0.05 and a
    band, at t = ordinal ms; planted: the one furthest beyond its band (a small band), the
    largest |Δe| (a large band), then a NaN e (what ``np.argmax`` picks over them all)."""
    rng = np.random.default_rng(3)
    events = []
    for k in range(SYNTHETIC_IMPACTS):
        before = -float(rng.uniform(0.5, 3.0))
        measured = 0.5 + float(rng.uniform(-0.05, 0.05))
        if k == PLANTED["beyond_band"]:
            before, measured = -50.0, 0.6  # |Δe| 0.1, band 3e-4
        if k == PLANTED["delta_e"]:
            before, measured = -0.01, 0.7  # |Δe| 0.2, band 1.5
        if k == PLANTED["nan"]:
            measured = np.nan
        events.append(
            recording_module.ImpactEvent(
                GROUND,
                "b",
                k * 1e-3,
                k * 1e-3,
                k * 1e-3,
                (0.0, 0.0, 1.0),
                before,
                -measured * before,
                approach_acceleration=-9.81,
                step=1e-3,
            )
        )
    return events


def _one_ball() -> Scenario:
    """Ball ``b`` (e 0.5) over the ground (e 0.5): the pair of the synthetic impacts."""
    return Scenario.model_validate(
        {
            "name": "one_ball",
            "dt": 1e-3,
            "duration": 0.01,
            "engines": ["mini"],
            "ground": {"restitution": 0.5},
            "bodies": [
                {
                    "name": "b",
                    "shape": {"type": "sphere", "radius": 0.05},
                    "mass": 1.0,
                    "position": [0.0, 0.0, 1.0],
                    "restitution": 0.5,
                }
            ],
        }
    )


def _restitution_error_of(scene, impacts: list, count: int) -> str:
    """restitution_error over ``impacts`` of ``count`` (the metric reads only the impacts and
    their count), as text: a NaN row equals itself."""
    recording = recording_module.Recording(None, impacts, 0.0, None, impact_count=count)
    return repr(metrics.restitution_error(Context(scene, recording)))


@pytest.mark.parametrize("with_nan", [False, True], ids=["numbers", "a_nan"])
def test_the_impact_log_keeps_an_even_sample_and_every_worst(small_impact_bounds, with_nan):
    """5,000 impacts fed to the log in two parts: at most the bound kept; an evenly spaced
    sample over the whole run (every s-th impact, at least half the sample's bound); the worst
    of each ranking, and restitution_error's pick over every impact (the NaN when there is
    one), kept although none of them is on the sample's stride."""
    scene = compile_scene(_one_ball())
    events = _synthetic_impacts(scene)
    if not with_nan:
        nan = PLANTED["nan"]
        exact = -0.5 * events[nan].normal_velocity_before  # e 0.5 as requested
        events[nan] = dataclasses.replace(events[nan], normal_velocity_after=exact)
    log = impact_log.ImpactLog(scene)
    log.add(events[:1_234])
    log.add(events[1_234:])
    kept = log.events()
    assert log.count == SYNTHETIC_IMPACTS, log.count
    assert len(kept) <= IMPACTS_BOUND, len(kept)
    ordinals = [round(e.time_start * 1e3) for e in kept]
    assert ordinals == sorted(ordinals), ordinals
    sample = list(range(0, SYNTHETIC_IMPACTS, log.stride))
    assert SAMPLED_IMPACTS // 2 <= len(sample) <= SAMPLED_IMPACTS, (log.stride, len(sample))
    assert set(sample) <= set(ordinals), (sample, ordinals)
    planted = [PLANTED["beyond_band"], PLANTED["delta_e"]] + [PLANTED["nan"]] * with_nan
    assert set(planted) <= set(ordinals), (planted, ordinals)
    found = _restitution_error_of(scene, kept, log.count)
    every = _restitution_error_of(scene, events, len(events))
    assert found == every, (found, every)
    worst = PLANTED["nan"] if with_nan else PLANTED["beyond_band"]
    assert f"at t = {worst * 1e-3:.4g} s" in found, found
