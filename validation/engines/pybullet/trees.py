"""A scene's joint tree as PyBullet multibodies: one btMultiBody (Featherstone, reduced
coordinates) per tree of the compiled scene's ``JointTree``, planned here without PyBullet.

A tree is rooted at the world (a massless, shapeless fixed base at the world origin), at a
fixed body (its base, massless: a fixed base) or at a floating body (its base, free: the
multibody's six base coordinates). Every other body of the tree is a link, in depth-first
order (PyBullet's own order of a multibody's links).

Frames (engines.md 2.5). A link's frame (PyBullet's URDF link frame, where its joint is) has
its origin at the joint's anchor and the body's axes; its inertial frame is the body's centre
of mass with the principal axes, as for a base (adapter module docstring). So, for a joint of
the tree (``anchor`` a and ``axis`` u in the parent's body frame, ``offset`` r0 and
``rotation`` R0 of the child at q = 0):

    child's centre in its link frame       R0ᵀ r0          (linkInertialFramePositions)
    joint frame in the parent's link frame a + c_parent    (linkPositions; c_parent is the
                                           R0                parent's centre in its link frame,
                                                             0 for a base) (linkOrientations)
    joint axis in the child's link frame   R0ᵀ u           (linkJointAxis)

which places every body at its stated pose at q = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.reference.articulated import WORLD, Joint, JointTree

BASE = -1
"""PyBullet's link index of a multibody's base."""


@dataclass(frozen=True)
class Link:
    """One jointed body as a link of its tree's multibody (module docstring's frames)."""

    body: int
    """The scene body's index."""
    joint: str
    """The scene joint's name."""
    type: str
    """``hinge``, ``slider``, ``ball`` or ``fixed``."""
    parent: int
    """The parent's link index in the multibody (``BASE`` for the base)."""
    position: np.ndarray
    """(3,) m, the joint frame's origin in the parent's link frame."""
    rotation: np.ndarray
    """(3, 3) the joint frame (the child's axes) relative to the parent's link frame."""
    centre: np.ndarray
    """(3,) m, the child's centre of mass in its link frame."""
    axis: np.ndarray
    """(3,) unit, the joint's axis in the child's link frame (zeros for ball and fixed)."""
    damping: float
    """N·m·s/rad or N·s/m: the scene joint's damping."""


@dataclass(frozen=True)
class Tree:
    """One multibody: its base (a scene body's index, or ``WORLD``) and its links."""

    root: int
    links: tuple[Link, ...]

    @property
    def bodies(self) -> list[int]:
        """The scene bodies this multibody holds: the root (unless the world), then the links."""
        return ([] if self.root == WORLD else [self.root]) + [link.body for link in self.links]


def plan_trees(tree: JointTree) -> list[Tree]:
    """The multibodies of ``tree``: one per root with jointed children (the world first if
    any joint hangs from it, then the bodies in their scene order), each with its links in
    depth-first order (``_depth_first``)."""
    children: dict[int, list[Joint]] = {}
    for joint in tree.joints:
        if joint.type != "free":
            children.setdefault(joint.parent, []).append(joint)
    jointed = {joint.child for hanging in children.values() for joint in hanging}
    roots = sorted(parent for parent in children if parent not in jointed)
    return [Tree(root, _depth_first(root, children)) for root in roots]


def _depth_first(root: int, children: dict[int, list[Joint]]) -> tuple[Link, ...]:
    """The links below ``root`` in pre-order, each parent's children in the tree's order:
    the order PyBullet gives a multibody's links whatever order they are passed in
    (engines.md 2.5: passed parents-first, base->0, base->1, 0->2 came back as 0, 2, 1), so
    a link's index here is its index in PyBullet."""
    links: list[Link] = []
    index: dict[int, int] = {}  # body -> its link index
    centre: dict[int, np.ndarray] = {}  # body -> its centre in its link frame
    pending = list(reversed(children.get(root, [])))
    while pending:
        joint = pending.pop()
        index[joint.child] = len(links)
        centre[joint.child] = joint.rotation.T @ joint.offset
        links.append(
            Link(
                body=joint.child,
                joint=joint.name,
                type=joint.type,
                parent=index.get(joint.parent, BASE),
                position=joint.anchor + centre.get(joint.parent, np.zeros(3)),
                rotation=joint.rotation,
                centre=centre[joint.child],
                axis=joint.rotation.T @ joint.axis,
                damping=joint.damping,
            )
        )
        pending += reversed(children.get(joint.child, []))
    return tuple(links)
