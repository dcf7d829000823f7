"""One line per metric: the definition the report's legend prints (scene files and CI depend on the names).

The code that computes each metric is in ``validation.measure.metrics``; this table is its
contract, kept apart so that a report can be rendered without importing any engine.
"""

from __future__ import annotations

METRIC_DEFINITIONS: dict[str, str] = {
    "energy_drift": "max over t of |E(t) - E(0)| / |E(0)|, E = kinetic (translational + rotational) "
    "+ gravitational potential + spring energy + the applied forces' potential -F·x; absolute (J) "
    "when E(0) = 0; not defined under an applied torque (its work has no potential)",
    "angular_momentum_drift": "max over t of |L(t) - L(0) - Στ t| / max(|L(0)|, |Στ| t_end), L of "
    "all bodies about the system's centre of mass, world frame, τ the applied torques; absolute "
    "when both are 0; defined only while no fixed body, ground or spring to the world acts and "
    "g + F/m is the same for every body (then the forces exert no torque about the centre of mass)",
    "linear_momentum_drift": "max over t of |p(t) - p(0) - (M g + ΣF) t| / max(|p(0)|, |M g + ΣF| "
    "t_end), F the applied forces; defined only while no fixed body, ground or spring to the world "
    "acts",
    "position_error": "max over t and bodies of the distance (m) from the analytic ballistic "
    "trajectory (acceleration g + F/m); only for scenes where nothing can touch and no spring acts",
    "velocity_error": "max over t and bodies of the distance (m/s) from the analytic ballistic "
    "velocity; only for scenes where nothing can touch and no spring acts",
    "restitution_error": "|e_measured - e_requested| of the impact farthest beyond its band, "
    "e_measured = -(v_rel'·n)/(v_rel·n) from the impact events (velocities carried to the "
    "impulse centroid); passes when |Δe| <= tolerance + band, band = (1 + e)·|a·n|·dt/|v_before| "
    "(engines take e before or after the step's forces: the two differ by exactly this)",
    "penetration_max": "the deepest overlap (m) of any two shapes over every observed step",
    "divergence": "max over t of the centre-of-mass distance (m) between this engine and the "
    "reference engine of the scene (the first engine listed) on the same scene",
}
"""Metric name -> the one-line definition shown in the report legend."""

EXPECTATION_DEFINITIONS: dict[str, str] = {
    "velocity_after_impact": "|v(after the body's first impact) - expected| (m/s), read once the "
    "contact has ended and carried back to the impulse with the free acceleration g + F/m",
    "position_at": "|x(time) - expected| (m), x observed at the time (interpolated between the "
    "two observed steps around it)",
    "velocity_at": "|v(time) - expected| (m/s), as position_at",
    "angular_velocity_at": "|ω(time) - expected| (rad/s, world frame), as position_at",
    "angular_velocity_after_impact": "|ω after the body's first impact - expected| (rad/s), read "
    "once the contact has ended (carried back with an applied torque's I⁻¹τ)",
    "orientation_at": "rotation angle (rad) between the body's orientation at the time (the "
    "nearer observed step) and the expected one",
    "flip_times": "max over flips of |time of a sign change of the body-axis angular velocity - "
    "expected| (s), crossings interpolated between steps",
    "impact_times": "max over the body's impacts of |impulse time - expected| (s)",
    "energy_at": "|the body's kinetic + gravitational energy at the time - expected| (J)",
    "bounce_heights": "max over bounces of |apex height of the COM - expected| (m)",
    "precession_rate": "|fitted body-frame precession rate - expected| (rad/s)",
    "flips": "|number of sign changes of the body-axis angular velocity - expected|",
}
"""Expectation kind -> the definition of its metric (named ``<kind>.<body>``)."""

EXPECTED_KINDS = ("analytic", "conserved", "engine")
"""What a row was compared against: a closed form, a conserved quantity (value its drift,
expected 0), or another engine (written ``engine:<spec>``)."""
