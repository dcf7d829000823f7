"""Memory bounded by the work: what a run keeps does not grow with bodies x samples, the
metrics read it as if they had the whole trajectory, and a run that cannot fit is refused
before any work."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from validation.jobs import memory
from validation.jobs.run import run_job, run_main
from validation.measure import metrics
from validation.measure import recording as recording_module
from validation.measure.metrics import Context
from validation.measure.states import Series, Trajectory, ballistic, invariants
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.engine_spec import parse_engine_spec

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
    dimension: at most 18 numbers a sample (``memory.SERIES_NUMBERS``) whatever the bodies."""
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
    motion = scene.kinetic_energy(states.quat, states.vel, states.ang_vel)
    motion = motion + scene.spring_energy(states.pos, states.quat)
    largest = float(np.max(motion, initial=0.0))
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
