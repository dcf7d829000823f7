"""Restitution measured fairly: the discretization band of e_measured.

Engines take restitution at different instants of a step. With the relative normal velocity
``v`` (< 0) at the state before contact, the step ``h`` and the relative acceleration along the
normal ``A = |a·n|`` (gravity, what acts besides the impulse), a one-step impulse leaves

(a) ``v⁺ = e (|v| + A h)``: e on the velocity *after* this step's forces (mini_engine, as
    documented);
(b) ``v⁺ = e |v|``: e on the velocity *before* this step's forces, the contact absorbing them
    (MuJoCo's damper, PyBullet: measured);
(c) ``v⁺ = e |v| - A h``: e before the forces, the forces then acting on the rebound.

``ImpactEvent`` carries both velocities to the impulse centroid (the end of the step), so its
``v_before = -(|v| + A h)`` for all three, and ``e_measured`` reads e for (a), lower by
``e A h / |v_before|`` for (b) and by ``(1 + e) A h / |v_before|`` for (c). None of them is the
continuous-time answer (it lies between: 2.10107 m/s for a 1 m drop at e = 0.5, where mini
rebounds at 2.10424 and PyBullet at 2.09934), so an engine honouring e under any of them must
pass: ``|e_measured - e| <= tolerance + band`` with the widest gap,

    band = (1 + e) · |a·n| · h / |v_before|,

shown per impact next to |Δe|. It is first order in h and grows as the impact slows: 0.0035
for a 4.2 m/s impact at h = 1 ms, 0.15 at 0.1 m/s. Impacts without an acceleration along the
normal (no gravity, a horizontal collision) have no band.
"""

from __future__ import annotations

import math


def restitution_band(requested: float, acceleration: float, step: float, before: float) -> float:
    """``(1 + e) |a·n| h / |v_before|`` (dimensionless): requested e, the relative normal
    acceleration (m/s²), the step between observations (s), the velocity before (m/s)."""
    if before == 0.0 or not math.isfinite(before):
        return math.inf
    return (1.0 + requested) * abs(acceleration) * step / abs(before)
