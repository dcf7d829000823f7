"""A robot model's links and joints as physval reads them, whatever the file's format: the
structure the URDF reader (``validation/scenario/urdf.py``) and the MJCF reader
(``validation/scenario/mjcf.py``) both produce, so one expansion into scene bodies and joints
serves both.

A link has an inertial frame (its centre of mass and the axes its inertia is written about,
in the link's frame), a mass and an inertia; a massless link (mass 0) can only be carried on a
fixed joint. A joint joins a parent link to a child link: the joint frame is ``origin`` in the
parent's frame, the child's frame is ``child_in_joint`` in the joint frame at coordinate 0,
and the joint moves along or about ``axis`` (joint frame). A URDF's child frame is its joint
frame (``child_in_joint`` the identity); an MJCF joint sits at a pivot ``pos`` inside the
child body, so its joint frame is the pivot and ``child_in_joint`` moves back to the body's
origin: a hinge then turns the child about the pivot, not about the child's origin.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Frame:
    """A rigid transform: rotation (3, 3) and translation (3,)."""

    rotation: np.ndarray
    translation: np.ndarray

    def __mul__(self, other: Frame) -> Frame:
        return Frame(
            self.rotation @ other.rotation, self.rotation @ other.translation + self.translation
        )


IDENTITY = Frame(np.eye(3), np.zeros(3))


def translation(offset) -> Frame:
    """The frame moved by ``offset`` (3,) m, axes unturned."""
    return Frame(np.eye(3), np.asarray(offset, dtype=float))


@dataclass(frozen=True)
class Geometry:
    """One collision element of a link: ``kind`` the file's word for its geometry (``sphere``,
    ``box``, ``cylinder``, ``capsule``, ``mesh``, ...), ``sizes`` its numbers in physval's
    terms (a sphere's radius; a box's half extents; a cylinder's or capsule's radius and half
    length, along its frame's z), ``frame`` where it sits in the link's frame."""

    kind: str
    sizes: tuple[float, ...]
    frame: Frame


@dataclass(frozen=True)
class Link:
    """A link's inertial frame (in the link frame), mass (kg, 0: massless) and inertia (kg·m²,
    about the inertial frame's axes); ``geometry`` its collision elements."""

    name: str
    inertial: Frame
    mass: float
    inertia: np.ndarray
    geometry: tuple[Geometry, ...] = ()


MASSLESS = (IDENTITY, 0.0, np.zeros((3, 3)))
"""A link's inertial frame, mass and inertia when the file gives it none."""


@dataclass(frozen=True)
class Joint:
    """A joint: ``kind`` a physval joint type (hinge, slider, fixed); ``origin`` the joint
    frame in the parent link's frame; ``axis`` a unit vector in the joint frame; ``limits``
    the file's (absolute coordinates) or None; ``child_in_joint`` the child link's frame in
    the joint frame at coordinate 0; ``in_file`` False for a weld the file does not write as
    a joint (an MJCF body without joints); ``friction`` the file's dry friction (N·m or N:
    URDF ``<dynamics friction>``, MJCF ``frictionloss``), which physval's scene joints do not
    have: carried in ``ModelLayout.frictions`` for the ``model_fields`` tier only."""

    name: str
    kind: str
    parent: str
    child: str
    origin: Frame
    axis: np.ndarray
    limits: tuple[float, float] | None
    damping: float
    child_in_joint: Frame = IDENTITY
    in_file: bool = True
    friction: float = 0.0


@dataclass
class Robot:
    """A model's links and joints, its root link and each link's child joints; ``format`` the
    file's (``"urdf"`` or ``"mjcf"``), ``meshes`` the mesh files its geometry names (as
    written; ``validation/scenario/packages.py`` resolves them)."""

    links: dict[str, Link]
    joints: list[Joint]
    format: str = "urdf"
    root: str = ""
    children: dict[str, list[Joint]] = field(default_factory=dict)
    meshes: list[str] = field(default_factory=list)

    def assemble(self) -> Robot:
        """The root and children filled in; ValueError unless the joints make one tree."""
        for joint in self.joints:
            unknown = {joint.parent, joint.child} - set(self.links)
            if unknown:
                raise ValueError(f"joint {joint.name!r} names no link {unknown.pop()!r}")
        children = [j.child for j in self.joints]
        if len(children) != len(set(children)):
            raise ValueError("a link is the child of two joints (not a tree)")
        roots = [name for name in self.links if name not in children]
        if len(roots) != 1:
            raise ValueError(f"expected one root link; found {roots}")
        self.root = roots[0]
        for joint in self.joints:
            self.children.setdefault(joint.parent, []).append(joint)
        return self


def rotation_class():
    """SciPy's ``Rotation``, imported when a model is read (``physval check`` of a scene
    without models loads no SciPy: ``tests/test_architecture.py``)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def xml_root(path: Path) -> ElementTree.Element:
    """The root element of the XML file at ``path``; ValueError when it cannot be read."""
    try:
        return ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as error:
        raise ValueError(f"cannot read {path}: {error}") from None
