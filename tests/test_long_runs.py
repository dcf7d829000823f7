"""Memory bounded by the scene, not the duration.

The measured accumulation: the energy-growth check kept one window per 8 steps for the whole
run and re-judged all of them after every batch (2,000,000 steps: 250,000 windows, and the
run's time grew as steps²). Now the judged windows are dropped, so what a long run keeps of
the check is a few windows, and a geometric growth late in the run is still found.

Peak RSS against the step count is measured, not tested (a shared 2-core machine makes RSS
thresholds flaky): ``python benchmarks/scale.py --memory-steps 200000 2000000``.
"""

from __future__ import annotations

import numpy as np

from validation.engines.base import Trajectory
from validation.measure.recording import BATCH_OBSERVATIONS
from validation.measure.stability import GROWTH_WINDOWS_IN_A_ROW, StabilityChecks
from validation.scenario import Scenario
from validation.scenario.compiled import compile_scene

DT = 1e-3
QUIET_STEPS = 200 * BATCH_OBSERVATIONS
"""51,200 steps (6,400 windows) of constant energy before the growth starts."""
GROWTH_PER_STEP = 0.05
"""Speed growth per step: the energy grows by e^0.1 a step, faster than doubling every 8."""


def checks() -> StabilityChecks:
    scenario = Scenario.model_validate(
        {
            "name": "long",
            "dt": DT,
            "duration": 100.0,
            "gravity": [0, 0, 0],
            "bodies": [
                {
                    "name": "b",
                    "shape": {"type": "sphere", "radius": 0.1},
                    "mass": 1.0,
                    "velocity": [1.0, 0, 0],
                }
            ],
        }
    )
    return StabilityChecks(compile_scene(scenario))


def batch(first: int) -> Trajectory:
    """States ``first .. first + BATCH_OBSERVATIONS - 1``: 1 m/s, then growing."""
    steps = np.arange(first, first + BATCH_OBSERVATIONS)
    speed = np.exp(GROWTH_PER_STEP * np.maximum(steps - QUIET_STEPS, 0))
    s = steps.size
    vel = np.zeros((s, 1, 3))
    vel[:, 0, 0] = speed
    quat = np.zeros((s, 1, 4))
    quat[..., 0] = 1.0
    return Trajectory(steps * DT, np.zeros((s, 1, 3)), quat, vel, np.zeros((s, 1, 3)))


def test_the_growth_check_keeps_a_few_windows_and_still_finds_late_growth():
    judge = checks()
    kept, found, first = 0, None, 0
    while found is None and first < QUIET_STEPS + 10 * BATCH_OBSERVATIONS:
        assert judge.first_failure(batch(first)) is None or first >= QUIET_STEPS
        found = judge.growth_failure(float((first + BATCH_OBSERVATIONS - 1) * DT))
        kept = max(kept, judge.window_error.size)
        first += BATCH_OBSERVATIONS
    # a batch's 32 windows plus those kept for a run of growth: not the run's 6,400
    assert kept <= BATCH_OBSERVATIONS // 8 + GROWTH_WINDOWS_IN_A_ROW + 1, kept
    assert found is not None and found.startswith("energy_growth"), found
    assert first == QUIET_STEPS + BATCH_OBSERVATIONS, first  # in the batch where it starts
