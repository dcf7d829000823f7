"""Writing files so that a reader never sees a half-written one."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

import pandas as pd


def write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to a new file next to ``path``, then rename it over ``path``.

    Readers see the old file or the new one, never a half-written one; on any error the
    temporary file is removed and ``path`` is untouched.
    """
    temporary = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
    try:
        # O_EXCL: never reuse a stranger's file; 0o666 & ~umask like any new file.
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(descriptor, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def write_table(rows: list[dict], path: Path) -> None:
    """A CSV of ``rows`` written atomically (``files.write_atomically``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, pd.DataFrame(rows).to_csv(index=False))
