"""Where a model file's mesh references point: ``package://NAME/path`` (ROS's convention) and
paths relative to the model file, resolved the same way for physval's load-time check and for
the native adapters that hand the files to an engine's own loader.

``package://NAME/path`` is looked for, in order, in the model file's own folder tree (each
folder from the file's up to the filesystem root: the folder itself when it is named NAME, else
its subfolder NAME) and then in the run's package paths (``--package-path NAME=DIR``, the
``PACKAGE_PATHS`` of ``validation/scenario/urdf.py``, carried in ``ModelLayout.package_paths``).
Any other reference is a path relative to the model file's folder (or absolute); a
``file://`` prefix is dropped.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

PACKAGE_URI = "package://"
FILE_URI = "file://"


def candidates(reference: str, model_file: Path, package_paths: Mapping[str, str]) -> list[Path]:
    """Every place ``reference`` (as written in ``model_file``) may be, in the order looked."""
    if not reference.startswith(PACKAGE_URI):
        inside = reference.removeprefix(FILE_URI)
        return [model_file.parent / inside]
    name, _, inside = reference[len(PACKAGE_URI) :].partition("/")
    folder = model_file.resolve().parent
    places = [(f if f.name == name else f / name) / inside for f in (folder, *folder.parents)]
    if name in package_paths:
        places.append(Path(package_paths[name]) / inside)
    return places


def resolve(
    reference: str, model_file: Path, package_paths: Mapping[str, str] | Iterable = ()
) -> Path | None:
    """The file ``reference`` (a mesh's ``filename``/``file`` in ``model_file``) names, or
    None when it is nowhere; ``package_paths`` NAME -> DIR (a dict or ``(NAME, DIR)`` pairs,
    like ``ModelLayout.package_paths``)."""
    found = [p for p in candidates(reference, model_file, dict(package_paths)) if p.is_file()]
    return found[0] if found else None


def missing_file(
    references: Iterable[str], model_file: Path, package_paths: Mapping[str, str]
) -> str | None:
    """One line naming the first reference that resolves nowhere and where it was looked
    for; None when every one exists."""
    for reference in references:
        if resolve(reference, model_file, package_paths) is None:
            return f"mesh {reference!r} not found: {_looked(reference, model_file, package_paths)}"
    return None


def _looked(reference: str, model_file: Path, package_paths: Mapping[str, str]) -> str:
    """Where ``reference`` was looked for, in words."""
    if not reference.startswith(PACKAGE_URI):
        return f"looked at {candidates(reference, model_file, package_paths)[0]}"
    name, _, inside = reference[len(PACKAGE_URI) :].partition("/")
    tree = f"looked for {name}/{inside} in {model_file.resolve().parent} and each folder above it"
    if name in package_paths:
        return f"{tree}, and at {Path(package_paths[name]) / inside} (--package-path {name})"
    return f"{tree}; give --package-path {name}=DIR"
