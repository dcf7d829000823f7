"""A run's memory, estimated before any work from what each job keeps, and refused when it
cannot fit in what the machine has free.

A job's memory is bounded by its scene, never by its samples (``validation.measure.recording``):
the engine's model (``ENGINE_BYTES_PER_BODY``), one batch of observed states being measured
(``recording.batch_size`` states of every body, ``BYTES_PER_BODY_STATE`` each with the copies
measuring makes), the series at the kept samples (``SERIES_NUMBERS`` per sample) and the kept
positions (``recording.MAX_KEPT_POSITIONS`` at most). The command's own process holds every
job's series and positions until the run is written. The estimate is that, summed over the
``--jobs`` largest jobs running at once, plus the command's process; the constants are peak
RSS measured with ``benchmarks/scale.py`` (the sphere grids, every engine), rounded up.

A scene's expectation lists (``bounce_heights``, ``impact_times``, ``flip_times``: a list
of any length) cost the command's process ``EXPECTED_VALUE_BYTES`` per listed value, once per
scene: reading, validating and writing them (900,000 bounce heights: 1.9 GB).

A tracker whose memory grows with the run (``expectations.GROWING_BYTES_PER_STATE``: a
``period`` keeps its joint's coordinate at every step) adds its bytes per step to the worker.

A run keeps at most ``impact_log.KEPT_IMPACTS_BOUND`` impact records (``IMPACT_BYTES``
each), however many impacts it has: they are in the worker's estimate of every scene that
can touch. The command's process holds each run's kept impacts too; its estimate leaves them
out, since most scenes have few (every run of the library together: 8,352, about 17 MB).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from validation.jobs.plan import BadInputError, Plan
from validation.measure.expectations import GROWING_BYTES_PER_STATE
from validation.measure.impact_log import KEPT_IMPACTS_BOUND
from validation.measure.recording import (
    MAX_KEPT_POSITIONS,
    batch_size,
    kept_samples,
    position_stride,
)
from validation.scenario.compiled import CompiledScene
from validation.scenario.engine_spec import EngineSpec

MB = 1 << 20
"""Bytes in a MiB (what the messages print)."""

PROCESS_BYTES = 250 * MB
"""A worker process with every engine imported and a small scene loaded (measured with
``benchmarks/scale.py``: 173, 197 and 208 MB of peak RSS for 100 spheres over 10 steps in mini,
MuJoCo and PyBullet), rounded up."""

ENGINE_BYTES_PER_BODY = {"mini": 40_000, "mujoco": 60_000, "pybullet": 50_000}
"""Bytes per body of the scene as loaded, the engine's model and its collision structures
(measured: the peak RSS of the 1,000-sphere grid over 10 steps less the 100-sphere one, per
body: 31, 43 and 46 KB, a batch of 11 states included), rounded up; an engine not listed
counts as the largest."""

BYTES_PER_BODY_STATE = 13 * 8 * 12
"""Bytes per body and observed state of a batch being measured: 13 float64 numbers, and about
a dozen arrays of that size alive at once (the adapter's copy, the detector's context and
ground-padded copy, the kept states, the rotation matrices of the invariants, the contacts)."""

IMPACT_BYTES = 2_000
"""Bytes per kept impact record: an ``ImpactEvent`` (about 950 bytes) in the worker and in
the command's process, and its impacts.csv row (a dict of 11 cells, about 1 KB) there,
rounded up."""

SERIES_NUMBERS = 21
"""float64 numbers per kept sample of a series (t, energy, motion, the two momentum scales,
the joint violation; momentum, angular momentum, centre of mass, the two ballistic offsets: 3
each)."""


EXPECTED_VALUE_BYTES = 2_200
"""Bytes per value of a scene's expectations in the command's process: its YAML node and
source position, the validated scenario, and the rows and report written from it (measured:
the peak RSS of ``physval run --jobs 1`` of one ball with 200,000 bounce heights less that of
one with 1, 420 MB, 2,150 bytes a value), rounded up."""


def expected_values(scene: CompiledScene) -> int:
    """The numbers the scene's expectations list (a vector's 3, a list's every entry)."""
    return sum(int(np.size(e.value)) for e in scene.scenario.expect)


@dataclass(frozen=True)
class Estimate:
    """A job's estimated peak memory (bytes) in its worker, and what it leaves with the
    command's process (its series and kept positions)."""

    scene: CompiledScene
    engine: str
    worker: int
    kept: int


def job_estimate(scene: CompiledScene, spec: EngineSpec, sample_every: int) -> Estimate:
    """The estimate of one (scene, engine) job keeping every ``sample_every``-th state."""
    bodies = scene.count
    samples = kept_samples(scene.scenario.steps, sample_every)
    stride = position_stride(scene, sample_every)
    positions = min(-(-samples // stride) * bodies * 3, MAX_KEPT_POSITIONS) * 8
    kept = samples * SERIES_NUMBERS * 8 + positions
    impacts = KEPT_IMPACTS_BOUND * IMPACT_BYTES if scene.can_touch else 0
    per_body = ENGINE_BYTES_PER_BODY.get(spec.name, max(ENGINE_BYTES_PER_BODY.values()))
    batch = batch_size(scene) * bodies * BYTES_PER_BODY_STATE
    tracked = scene.scenario.steps * sum(
        GROWING_BYTES_PER_STATE.get(e.kind, 0) for e in scene.scenario.expect
    )
    worker = PROCESS_BYTES + bodies * per_body + batch + 2 * kept + impacts + tracked
    # 2 * kept: the kept samples and their concatenation
    return Estimate(scene, spec.label, worker, kept)


def run_estimate(estimates: list[Estimate], jobs: int) -> tuple[int, Estimate]:
    """(bytes, the largest job): the ``jobs`` largest workers at once, plus the command's
    process holding every job's kept numbers and every scene's expectation values (without
    workers, ``jobs`` 1: in that process)."""
    ordered = sorted(estimates, key=lambda e: e.worker, reverse=True)
    running = sum(e.worker for e in ordered[: max(jobs, 1)])
    scenes = {id(e.scene): e.scene for e in estimates}.values()  # a scene's specs share it
    expectations = sum(expected_values(scene) for scene in scenes) * EXPECTED_VALUE_BYTES
    parent = (PROCESS_BYTES if jobs > 1 else 0) + sum(e.kept for e in estimates) + expectations
    return running + parent, ordered[0]


MEMINFO = Path("/proc/meminfo")
"""Where Linux says how much memory is free for new work (``MemAvailable``)."""


def available_memory() -> int | None:
    """Bytes the machine can give new work without swapping: ``MemAvailable`` of
    ``/proc/meminfo``, else the free physical pages; None when neither can be read."""
    try:
        for line in MEMINFO.read_text().splitlines():
            name, _, value = line.partition(":")
            if name == "MemAvailable":
                return int(value.split()[0]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def check_memory(plan: Plan, jobs: int, sample_every) -> None:
    """Refuse the run (``BadInputError``, one line naming the largest scene and the estimate)
    when its estimate exceeds the available memory; ``sample_every(scene)`` is the run's
    sampling."""
    estimates = [job_estimate(scene, spec, sample_every(scene)) for scene, spec in plan.jobs]
    free = available_memory()
    if not estimates or free is None:
        return
    needed, largest = run_estimate(estimates, jobs)
    if needed <= free:
        return
    scene = max((e.scene for e in estimates), key=expected_values)
    if expected_values(scene) * EXPECTED_VALUE_BYTES < largest.worker:
        scene = largest.scene
    source = scene.scenario.source or scene.name
    raise BadInputError(
        f"{source}: the run needs an estimated {needed / MB:,.0f} MB, more than the "
        f"{free / MB:,.0f} MB available (its largest job, scene {largest.scene.name!r} in "
        f"{largest.engine}: {largest.scene.count} bodies, {largest.scene.scenario.steps} "
        f"steps, {largest.worker / MB:,.0f} MB; scene {scene.name!r} lists "
        f"{expected_values(scene):,} expected values, {EXPECTED_VALUE_BYTES:,} bytes each; "
        f"--jobs {jobs}); run fewer bodies, steps, expected values or --jobs"
    )
