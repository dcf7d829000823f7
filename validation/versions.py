"""Installed versions, read from the packages' metadata (nothing imported): what
``physval --version`` prints and ``physval list`` shows per engine."""

from __future__ import annotations

import importlib.metadata
import platform

VERSION_PACKAGES = ("mujoco", "pybullet", "numpy")
"""What ``physval --version`` names besides physval itself (the numbers' provenance)."""


def version_of(distribution: str) -> str:
    """The installed version of a distribution, or ``not installed``."""
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def version_text() -> str:
    """``physval 0.1.0 (mujoco 3.x, pybullet 3.x, numpy 2.x, Python 3.11.7)``."""
    parts = [f"{name} {version_of(name)}" for name in VERSION_PACKAGES]
    return (
        f"physval {version_of('physval')} ({', '.join(parts)}, Python {platform.python_version()})"
    )
