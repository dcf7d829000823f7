"""One line per metric: the definition the report's legend prints (scene files and CI depend on the names).

The code that computes each metric is in ``validation.measure.metrics``; this table is its
contract, kept apart so that a report can be rendered without importing any engine.
"""

from __future__ import annotations

from validation.measure.impact_log import MAX_SAMPLED_IMPACTS, MAX_WORST_IMPACTS
from validation.measure.resolution import (
    CARRIED_VALUE_KINDS,
    DRIFT_SUFFIX,
    FLOAT32_DRIFT_FLOOR,
    FLOAT32_UNIT_ROUNDOFF,
    RESOLUTION_MARK,
)
from validation.measure.tier_scales import (
    FINITE_DIFFERENCE,
    LIMIT_FLOOR,
    PROBE_SPEED,
    RANDOM_STATES,
    REACH_FLOOR,
    TYPE_DIFFERENCE,
)
from validation.measure.tier_scales import TIERS as TIERS  # the report's tier order, from here

METRIC_DEFINITIONS: dict[str, str] = {
    "energy_drift": "max over every step t of |E(t) - E(0)| / E_scale, E = kinetic "
    "(translational + rotational) + gravitational potential + spring energy + the applied "
    "forces' potential -F·x; E_scale = the largest internal energy over the run + Σ m|g + F/m|·r "
    "(each body's weight, with its constant force, over its bounding radius r), the internal "
    "energy being the kinetic energy about the centre of mass + ½M|v_c(t) - v_c(0)|² (the "
    "centre of mass's change of motion) + spring energy for a free system, the kinetic + spring "
    "energy where a ground, fixed body or spring to the world holds it: no choice of origin or "
    "potential zero changes it, nor a Galilean boost of a free system; the message keeps "
    "max|ΔE| in J; signed_error is ΔE/E_scale at the worst time (negative: energy lost); "
    "absolute (J) when E_scale = 0; not defined under an applied torque (its work has no "
    "potential) or with a damped spring (it dissipates)",
    "angular_momentum_drift": "max over every step t of |L(t) - L(0) - Στ t| / L_scale, L of all "
    "bodies about the system's centre of mass c, world frame, τ the applied torques; L_scale = "
    "max(the largest Σ m|(x - c) × (v - v_c)| + |I ω| over the run (the bodies' own angular "
    "momenta, without cancellation), |Στ| t_end); absolute when it is 0; defined only while no "
    "fixed body, ground or spring to the world acts and g + F/m is the same for every body (then "
    "the forces exert no torque about the centre of mass)",
    "linear_momentum_drift": "max over every step t of |p(t) - p(0) - (M g + ΣF) t| / p_scale, F "
    "the applied forces; p_scale = max(the largest Σ m|v| over the run (the bodies' momenta, "
    "without cancellation), |M g + ΣF| t_end); absolute when it is 0; defined only while no fixed "
    "body, ground or spring to the world acts",
    "position_error": "max over every step t and bodies of the distance (m) from the analytic "
    "ballistic trajectory (acceleration g + F/m); only for scenes where nothing can touch and no "
    "spring acts",
    "velocity_error": "max over every step t and bodies of the distance (m/s) from the analytic "
    "ballistic velocity; only for scenes where nothing can touch and no spring acts",
    "restitution_error": "|e_measured - e_requested| of the impact farthest beyond its band, "
    "e_measured = -(v_rel'·n)/(v_rel·n) from the impact events (velocities carried to the "
    "impulse centroid); passes when |Δe| <= tolerance + band, band = (1 + e)·|a·n|·dt/|v_before| "
    "(engines take e before or after the step's forces: the two differ by exactly this)",
    "penetration_max": "the deepest overlap (m) of any two shapes over every observed step",
    "joint_violation": "the largest joint violation (m) over every observed step and joint, "
    "from the two bodies' poses alone: the anchor as a point of the parent against it as a "
    "point of the child (a slider's across its axis), or the angle a hinge's axis (a slider's "
    "or fixed joint's whole rotation) is off times the child's centre's distance from the anchor",
    "divergence": "max over the kept samples t of the centre-of-mass distance (m) between this "
    "engine and the reference engine of the scene (the first engine listed) on the same scene; "
    "judged on the pair: beyond its tolerance it fails this engine when this engine is off its "
    "own closed forms (a failing row of its own in the scene) or when neither engine is (the "
    "message names the pair), and is not judged (passed empty) when only the reference engine "
    "is off its closed forms (the reference is suspect: its own rows fail)",
    "model_fields": "model tier 1, scenes with models: the largest relative difference between "
    "what the engine holds after loading and physval's own reading of the model file, over "
    "every model link's mass (relative to the link's mass), centre of mass (to the model's "
    f"reach, the largest link-centre distance from its base, at least {REACH_FLOOR} m) and world "
    "inertia at q0 (to the link's largest principal moment), and every model joint's type "
    f"({TYPE_DIFFERENCE:g} when it differs), anchor (to the reach), axis (|Δ unit vector|), limits "
    f"(to max(|limit|, {LIMIT_FLOOR:g})), damping (to the stated damping, or, where none is stated, to M_kk(q0)/duration) and "
    "armature (to M_kk(q0)), where the engine reports them, and friction against the model "
    "file's (to the file's, or, where none is stated, to "
    f"M_kk(q0)·{PROBE_SPEED:g} rad/s/duration; an engine that reports none holds none: 0); "
    "the message names the worst link or joint and field. Under native model loading a "
    "difference is this row, never a model_mismatch",
    "fk_error": "model tier 2, scenes with models: max over the probed joint states (q0 and "
    f"{RANDOM_STATES} seeded random ones within the limits, rates within ±{PROBE_SPEED:g}) and "
    "model links of max(|Δ centre|, rotation angle × the model's reach) (m) between the engine's "
    "link poses (its model_probe, or the scene loaded afresh at each state) and the reference's "
    "forward kinematics",
    "mass_matrix_error": "model tier 3, scenes with models: max over the probed states of max "
    "|M_engine - M_ref| / max |M_ref| in the joint tree's coordinates, M_ref the composite-rigid-"
    "body matrix; from the engine's model_probe, else its joint_report's M(q0) (one state); no row "
    "for an engine that exposes neither (mini: maximal coordinates)",
    "bias_force_error": "model tier 3, scenes with models: max over the probed states of max "
    "|b_engine - b_ref| / max |b_ref|, b = C(q, ν)ν + g(q) (M ν̇ + b = τ) in the tree's "
    "coordinates, b_ref by recursive Newton-Euler; from the engine's model_probe, else by a "
    f"{FINITE_DIFFERENCE} (stated in the message): the scene loaded at the state, two steps "
    "with no applied torque, q̈ the second difference of the joint coordinates read from the "
    "poses, the error the residual M_ref q̈ + b_ref - τ_damping at the middle state (ν the "
    "central difference), with a band: the residual's change when ν is read backward "
    "instead, O(dt)",
    "joint_divergence": "trajectory tier, scenes with models and two or more engines: max over "
    "the kept samples and the tree's hinge and slider coordinates of |q - q_reference| (rad or "
    "m; a hinge's difference wrapped to ±π) against the scene's reference engine (the first "
    "that ran), q read from the observed poses",
    "agreement_time": "trajectory tier, scenes with models, two or more engines and a "
    "joint_divergence tolerance: the time (s) this engine's joint coordinates stay within that "
    "tolerance of the reference engine's (the whole run when they never leave it); error = "
    "duration - agreement time, the time lost",
}
"""Metric name -> the one-line definition shown in the report legend."""

EXPECTATION_DEFINITIONS: dict[str, str] = {
    "velocity_after_impact": "|v(after the body's first impact) - expected| (m/s), read once the "
    "contact has ended and carried back to the impulse centroid with the acceleration the body "
    "was observed to have over the step before the contact (g + F/m in free flight, nothing for "
    "a body resting on a support)",
    "position_at": "|x(time) - expected| (m), x observed at the time, or between observed steps "
    "the cubic Hermite of the observed positions and velocities (exact for a constant "
    "acceleration; error <= h⁴·max|x⁗|/384), never across an impact (the interpolation "
    "convention below); time at most the run's last observed time (a duration is a whole "
    "number of steps)",
    "velocity_at": "|v(time) - expected| (m/s), v observed at the time, or between observed steps "
    "the cubic through the four observed velocities around it (error <= 9h⁴·max|v⁗|/384), "
    "never across an impact (the interpolation convention below)",
    "angular_velocity_at": "|ω(time) - expected| (rad/s, world frame), as velocity_at",
    "angular_velocity_after_impact": "|ω after the body's first impact - expected| (rad/s), read "
    "once the contact has ended and carried back with the angular acceleration observed over "
    "the step before the contact",
    "orientation_at": "rotation angle (rad) between the body's orientation at the time and the "
    "expected one; between observed steps the cubic Hermite on the rotation group with the "
    "observed angular velocities (exact for a constant ω); signed: the world-frame rotation "
    "vector from the expected orientation to the measured one",
    "flip_times": "max over flips of |time of a sign change of the body-axis angular velocity - "
    "expected| (s), crossings interpolated between steps",
    "impact_times": "max over the body's impacts of |impulse time - expected| (s)",
    "energy_at": "|the body's kinetic + gravitational energy at the time - expected| (J), "
    "between observed steps the cubic through the four observed energies around it, never "
    "across an impact (the interpolation convention below)",
    "bounce_heights": "max over bounces of |apex height of the COM - expected| (m)",
    "precession_rate": "|fitted body-frame precession rate - expected| (rad/s)",
    "flips": "|number of sign changes of the body-axis angular velocity - expected|",
    "joint_position_at": "|q(time) - expected| (rad or m; a ball: the distance between rotation "
    "vectors, rad), q the joint's coordinate relative to t = 0 read from the observed poses of "
    "its two bodies (a hinge's angle about its axis, continuous over the run; a slider's travel "
    "along its axis; a ball's rotation vector in the parent's frame), between observed steps the "
    "cubic through the four observed coordinates around the time, never across a contact change "
    "of a body joined to it (the interpolation convention below)",
    "period": "|mean interval between successive upward crossings of a hinge's or slider's "
    "coordinate about its mean over the run - expected| (s), each crossing linearly "
    "interpolated inside its step; not measured (error inf) with fewer than two crossings",
}
"""Expectation kind -> the definition of its metric (named ``<kind>.<body>``, or
``<kind>.<joint>`` for a joint's kinds)."""

INTERPOLATION_BOUND = (
    "between observed steps: positions by the cubic Hermite of the observed positions and "
    "velocities (error <= h⁴·max|x⁗|/384), velocities, angular velocities, energies and joint "
    "coordinates by the cubic through the four observed values around the time (<= 9h⁴·max|f⁗|/384), "
    "orientations by the same Hermite on the rotation group with the observed ω; each exact "
    "for a constant acceleration (a constant ω); never across a step an impulse can act in (one "
    "that begins or ends where the body's contacts changed): only the observed states on the "
    "time's side of it, and within that step the observed state at its end (the row's message "
    "says so)"
)
"""The interpolants and their error bounds in one line, for the legend and the README
(the interpolants: ``validation.measure.interpolation``)."""


SIGNED_ERROR_DEFINITION = (
    "signed_error (a scalar) or error_x, error_y, error_z (a vector, world frame): the error "
    "with its sign, measured - expected, of which error is the magnitude; opposite errors of "
    "one size (explicit and semi-implicit Euler on a projectile) differ here"
)
"""The legend's line for the signed-error columns."""

BAND_DEFINITION = (
    "band: the allowance a row has beyond its tolerance, derived, never guessed (a row passes "
    "when |error| <= tolerance + band): restitution_error's (1 + e)·|a·n|·dt/|v_before|, plus, "
    "for an engine that declares float32 precision, what it cannot resolve: steps × substeps × "
    f"{FLOAT32_UNIT_ROUNDOFF:.3g} (half a float32 ulp) × max(|value|, |expected|) for a value it "
    f"carries step to step ({', '.join(CARRIED_VALUE_KINDS)}), {FLOAT32_DRIFT_FLOOR:.2g} for a "
    f"relative drift (*{DRIFT_SUFFIX}); a row that passes by that alone says so "
    f"({RESOLUTION_MARK!r} in its message)"
)
"""The legend's line for the ``band`` column (``validation.measure.resolution``)."""

MAX_SAMPLES = 5000
"""Samples kept per run (the series the plots read): every step of the library's short scenes,
every k-th of long ones. Measuring (the metrics too) sees every step whatever is kept."""

MAX_SERIES_POINTS = 1000
"""Points per (scene, engine) written to series.csv for the report's plots."""

MAX_KEPT_POSITIONS = 2**23
"""Numbers of the positions a run keeps for ``divergence`` (3 per body and kept sample:
67 MB): every kept sample while samples x bodies x 3 fit (the library's largest scene, 216
bodies at 5,001 samples, keeps 3.2 million), every k-th kept sample beyond, the same k in
every engine of a scene (``recording.position_stride``)."""

SAMPLING_DEFINITION = (
    f"every step is observed and measured (impacts, stability, expectations, and every metric "
    f"that is a maximum over time but divergence: energy_drift, the momentum drifts, "
    f"position_error, velocity_error, penetration_max); the series kept for plots hold at most "
    f"{MAX_SAMPLES:,} samples per run (every step of a run of up to {MAX_SAMPLES:,} steps, every "
    f"k-th step of a longer one, k = ceil(steps / {MAX_SAMPLES:,}), and the last); plots show at most {MAX_SERIES_POINTS:,} of them per series and engine, "
    f"evenly spaced; divergence compares the positions at every kept sample, or every m-th "
    f"kept sample (and the last) where samples x bodies x 3 exceed {MAX_KEPT_POSITIONS:,} "
    f"numbers (m the least that fits, the same in every engine of the scene); impacts.csv and "
    f"the impacts tables keep every impact of a run up to {MAX_SAMPLED_IMPACTS:,}, beyond that "
    f"an evenly spaced sample of them (every s-th impact, s a power of two: "
    f"{MAX_SAMPLED_IMPACTS // 2:,} to {MAX_SAMPLED_IMPACTS:,}) and the {MAX_WORST_IMPACTS:,} "
    f"worst by |Δe| beyond the band and by |Δe| (restitution_error still judges the worst of "
    f"every impact and its message counts them all)"
)
"""How series and impacts are thinned, for the legend and the README."""

EXPECTED_KINDS = ("analytic", "conserved", "engine")
"""What a row was compared against: a closed form, a conserved quantity (value its drift,
expected 0), or another engine (written ``engine:<spec>``)."""
