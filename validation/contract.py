"""Names that CI jobs, scenario authors and report readers depend on, defined once.

The run folder's files and their columns, and the command's exit codes. The producer
(``validation.jobs.run``, ``validation.measure.comparator``) and the consumer (``validation.report``)
both import them from here.
"""

from __future__ import annotations

RESULTS_FILE = "results.csv"
SERIES_FILE = "series.csv"
IMPACTS_FILE = "impacts.csv"
PROVENANCE_FILE = "provenance.json"
REPORT_FILE = "report.html"
BASELINE_FILE = "baseline.csv"
BASELINE_ACTION_NAMES = ("save",)
"""``physval baseline ACTION``: the actions (``validation.nightly.baseline.BASELINE_ACTIONS``)."""
"""In a run folder run against a baseline: every row's class, the baseline's rows the run
lacks (``missing``) included, with the baseline's value and error next to the run's."""
SWEEP_FILE = "sweep.csv"
"""In a run folder whose scenes declare ``sweep:``: the sweep rows (as ``physval sweep``)."""
SCENE_FILE = "scene.yaml"
"""In a run folder of ``physval sim2sim``: the scene it wrote for the model and ran (``physval
run`` runs it again)."""
TRACE_FILE = "trace.csv"
"""In a run folder whose scenes have expectations with a chart: the thin trace of each body's
quantity under test (``validation.report.closed_form``)."""

NIGHTLY_COLUMNS = ("outcome", "known", "baseline")

SIGNED_ERROR_COLUMN = "signed_error"
VECTOR_ERROR_COLUMNS = ("error_x", "error_y", "error_z")
SIGNED_COLUMNS = (SIGNED_ERROR_COLUMN, *VECTOR_ERROR_COLUMNS)
"""The error with its sign, ``measured - expected``: ``signed_error`` for a scalar quantity,
``error_x, error_y, error_z`` (world frame) for a vector; empty where the quantity has none.
``error`` is its magnitude. Opposite errors of one size (explicit and semi-implicit Euler on a
projectile) differ here, and a baseline compares them."""
"""The columns the nightly bookkeeping adds to a measured row (``validation.nightly``)."""

RESULTS_COLUMNS = (
    "scenario",
    "engine",
    "metric",
    "value",
    "expected",
    "expected_kind",
    "error",
    "tolerance",
    "passed",
    "status",
    "dt",
    "steps",
    "wall_time_s",
    "engine_version",
    "settings",
    "message",
    "band",
    *SIGNED_COLUMNS,
    *NIGHTLY_COLUMNS,
)
"""results.csv, in order: ``validation.measure.comparator`` writes these columns, and CI jobs
and ``validation.report`` read them by name. ``outcome`` is the row's verdict with the scene's
known findings applied (passed, failed, known, fixed, no_tolerance, or a bad status), ``known``
the matching finding's reason, ``baseline`` its class against the run's baseline (empty
without one); ``SIGNED_COLUMNS`` the signed error."""

SERIES_COLUMNS = ("scenario", "engine", "t", "energy", "px", "py", "pz", "Lx", "Ly", "Lz")
"""series.csv: energy (J), linear momentum (kg·m/s), angular momentum about the system COM."""

IMPACTS_COLUMNS = (
    "scenario",
    "engine",
    "body_a",
    "body_b",
    "time",
    "e_requested",
    "e_measured",
    "normal_velocity_before",
    "normal_velocity_after",
    "delta_e",
    "band",
)
"""impacts.csv: one row per kept impact event (every one of a run up to
``impact_log.MAX_SAMPLED_IMPACTS``; beyond, an evenly spaced sample and the worst);
``delta_e`` = e_measured - e_requested and its discretization ``band``
(``validation.measure.restitution``)."""

TRACE_COLUMNS = ("scenario", "engine", "body", "quantity", "t", "x", "y", "z")
"""trace.csv: a body's ``quantity`` (pos m, vel m/s, ang_vel rad/s world frame, body_ang_vel
rad/s body frame) at time ``t`` (s), components x, y, z."""

STATUS_DESCRIPTIONS: dict[str, str] = {
    "ok": "the engine ran the whole scene and the row's check (if any) passed",
    "failed": "the metric's error exceeds the scene's tolerance",
    "unstable": "the run failed a stability check (non-finite state, energy blow-up, quaternion "
    "drift, tunnelling, impossible speed, the engine's own instability warning); it stopped there",
    "model_mismatch": "the engine's model differs from the scenario (the message names the "
    "quantity and both values): a mass, centre of mass, world inertia, energy or momentum off "
    "by more than its precision's tolerance (1e-9 float64, 1e-6 float32) of the quantity's "
    "physical magnitude (the mass; the distance from the origin plus the radius of gyration; "
    "the largest inertia entry; for a total the sizes of its terms, none cancelling: Σ m|v|, "
    "Σ m|(x - c) × (v - v_c)| + |Iω|, kinetic + |m g·x| + |F·x| + spring energy); the engine "
    "was not run",
    "error": "the engine raised; the message carries the exception",
    "crashed": "the engine's process died or exited mid-job (a segfault, an abort, an "
    "out-of-memory kill, sys.exit); the message names the signal or exit code; the other jobs "
    "ran on",
    "timed_out": "the job ran past its time limit (--job-timeout) and was stopped; the other "
    "jobs ran on",
    "unsupported": "the engine cannot represent something the scene or metric needs",
    "not_installed": "the scene names an engine whose package is not installed here (the "
    "message says how to install it); the engine was not run",
}
"""Every status a result row can carry, with its meaning. CI jobs and the report depend on
these names; ``BAD_STATUSES`` decides the exit code."""

SWEEP_ORDER = "sweep_order"
SWEEP_ERROR = "sweep_error"
SWEEP_CROSS_CHECK = "sweep_cross_check"
"""Prefixes of the result rows a scene's sweep adds: ``sweep_order.<metric>`` (the fitted
convergence order), ``sweep_error.<metric>@dt=<dt>`` (the error at one step;
``sweep_error.<metric>@accuracy=<a>`` at one accuracy of an error-controlled engine) and
``sweep_cross_check.<metric>`` (DOP853 against MuJoCo RK4); the history tracks them like
every other row."""

SWEEP_ROW_PREFIXES = (SWEEP_ORDER, SWEEP_ERROR, SWEEP_CROSS_CHECK)
"""Every prefix of a sweep's result rows (``<prefix>.<metric>``): tracked, not judged, so
they do not colour a scene's cells in the terminal matrix."""

NOT_JUDGED_STATUSES = ("unsupported", "not_installed")
"""Row statuses of a scene not run in an engine for a reason that is no fault of the engine:
never judged (``passed`` empty), never failing a run, always shown."""

RUN_FAILURE_STATUSES = ("error", "crashed", "timed_out", "model_mismatch", "unstable")
"""Row statuses of a run that produced no trustworthy numbers (the report shows the word, a
JUnit case and a pytest item are an error): the engine raised, its process died, it ran past
its time limit, it built another model, or it went unstable."""

BAD_STATUSES = ("failed", "unstable", "model_mismatch", "error", "crashed", "timed_out")
"""Row statuses that fail a row; ``physval run`` exits 1 on such a row unless it is a known
finding of its scene or, against a baseline, failed there too (``nightly.baseline``)."""

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
"""physval's exit codes: nothing regressed and no new failure; a regression or a new failure
(a failed check or an unstable, errored, crashed, timed-out or mismatched run that is not
known); bad input."""

BASELINE_CLASSES = (
    "regressed",
    "changed",
    "new",
    "missing",
    "scene_changed",
    "improved",
    "reference_moved",
    "unchanged",
)
"""Every ``baseline`` class a results.csv row can carry, the news first (``regressed`` ...
``unchanged`` are the nightly's names; ``validation.nightly.baseline`` defines them, by the
noise rule of ``validation.measure.noise``): ``changed`` a row without an error whose value
moved (fails the run like ``regressed``), ``reference_moved`` a divergence row that moved with
its scene's reference engine (not a failure)."""

EXIT_INTERRUPTED = 130
"""Ctrl-C (128 + SIGINT, the shell's convention): every worker stopped, nothing published."""

INTERRUPTED_MESSAGE = (
    "interrupted: every worker stopped; nothing was replaced (physval run --resume DIR "
    "finishes a run)"
)
"""The one line a Ctrl-C prints, whenever it comes (results are published only after every
job has finished; a run's finished jobs stay in its journal)."""


CONFORMANCE_CHECKS = (
    "declaration",
    "parity",
    "frames",
    "advance",
    "observe",
    "determinism",
    "close",
    "provenance",
    "capabilities",
)
"""The checks of ``physval conformance``, in the order they run (``validation.jobs.conformance``
defines each; ``--only`` takes these names)."""
