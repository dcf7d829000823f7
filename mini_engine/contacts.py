"""Contact records shared by the narrow phase, the solver and the step report.

Sign convention (one for the whole engine, as in formulas.md section 3):
the normal is a unit vector **from body A to body B**, depth is positive when
the shapes overlap, and the relative normal speed ``(v_PB - v_PA) · n`` is
negative while the bodies approach.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class PairContacts(NamedTuple):
    """Contacts produced by one narrow-phase function for a batch of ``k`` candidate pairs.

    Attributes:
        pair: (c,) int, index of the candidate pair (0..k-1) each contact belongs to;
            a pair may produce several contacts (a box face on a plane gives four).
        point: (c, 3) m, world frame, the contact point, midway between the two
            surfaces along the normal.
        normal: (c, 3) unit, world frame, from A to B.
        depth: (c,) m, penetration depth; positive means overlap. Contacts are
            reported while ``depth >= -margin``.
    """

    pair: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray

    @staticmethod
    def empty() -> PairContacts:
        return PairContacts(
            pair=np.zeros(0, dtype=np.int64),
            point=np.zeros((0, 3)),
            normal=np.zeros((0, 3)),
            depth=np.zeros(0),
        )


class Contacts(NamedTuple):
    """All contacts of one step, between bodies of the model.

    Attributes:
        body_a: (c,) int, body index of A.
        body_b: (c,) int, body index of B.
        point: (c, 3) m, world frame.
        normal: (c, 3) unit, world frame, from A to B.
        depth: (c,) m, positive when overlapping.
    """

    body_a: np.ndarray
    body_b: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray

    @property
    def count(self) -> int:
        return int(self.body_a.shape[0])

    @staticmethod
    def empty() -> Contacts:
        """No contacts: one shared instance of read-only empty arrays (a step without
        contacts builds none)."""
        return NO_CONTACTS


def read_only(array: np.ndarray) -> np.ndarray:
    """``array``, marked read-only (for arrays shared between steps)."""
    array.flags.writeable = False
    return array


NO_CONTACTS = Contacts(
    body_a=read_only(np.zeros(0, dtype=np.int64)),
    body_b=read_only(np.zeros(0, dtype=np.int64)),
    point=read_only(np.zeros((0, 3))),
    normal=read_only(np.zeros((0, 3))),
    depth=read_only(np.zeros(0)),
)
"""``Contacts.empty()``."""
