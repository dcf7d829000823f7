"""States of a scene's bodies over time, as the reference side writes them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Motion:
    """``s`` states of the ``n`` scene bodies (scenario order), the layout of an engine's
    ``Trajectory`` (``validation.engines.base``).

    Attributes:
        t: (s,) s. pos: (s, n, 3) m, world frame, centres of mass. quat: (s, n, 4) unit
        quaternions w x y z, body to world. vel: (s, n, 3) m/s, world frame. ang_vel: (s, n,
        3) rad/s, world frame.
    """

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    ang_vel: np.ndarray
