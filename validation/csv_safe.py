"""Spreadsheet-safe CSV: text cells that a spreadsheet would run as a formula are neutralised.

A CSV opened in a spreadsheet runs a cell that begins with ``=``, ``+``, ``-``, ``@``, a tab or
a carriage return as a formula (CSV injection): a scene named ``=HYPERLINK(...)`` in
results.csv would be one. OWASP's rule: such a text cell is written with a single quote before
it (``'=HYPERLINK(...)``), which spreadsheets show as text. The rule is decided per column
type: a number column (``-1.5``) is never touched; in a text column every text cell that
begins with one of ``FORMULA_STARTS``, or with the quote itself, gets one quote more.

Reading a CSV physval wrote (``restored``) removes exactly that one quote again, so a name
round-trips: ``=cmd`` is written ``'=cmd`` and read back as ``=cmd``, ``'quoted`` is written
``''quoted`` and read back as ``'quoted`` (which is why a leading quote is escaped too).
"""

from __future__ import annotations

from collections.abc import Iterable

import pandas as pd

QUOTE = "'"
"""What neutralises a cell: spreadsheets show a cell that begins with it as text."""

FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
"""OWASP's list of the first characters that make a spreadsheet read a cell as a formula."""

ESCAPED_STARTS = (*FORMULA_STARTS, QUOTE)
"""Every first character that gets a quote: the formula starts, and the quote itself, so
that reading back (``restored``) is exact."""


def neutralised(text: str) -> str:
    """One text cell as it is written."""
    return QUOTE + text if text.startswith(ESCAPED_STARTS) else text


def original(text: str) -> str:
    """One text cell as it was before ``neutralised``."""
    return text[len(QUOTE) :] if text.startswith(QUOTE) else text


def is_text_column(column: pd.Series) -> bool:
    """A column of text (names, statuses, messages), not of numbers or booleans."""
    return not (pd.api.types.is_numeric_dtype(column) or pd.api.types.is_bool_dtype(column))


def _each_text_cell(column: pd.Series, change) -> pd.Series:
    return column.map(lambda cell: change(cell) if isinstance(cell, str) else cell)


def safe_frame(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with every text cell of its text columns neutralised (a copy)."""
    safe = frame.copy()
    for name in safe.columns:
        if is_text_column(safe[name]):
            safe[name] = _each_text_cell(safe[name], neutralised)
    return safe


def csv_text(frame: pd.DataFrame) -> str:
    """``frame`` as spreadsheet-safe CSV text (no index)."""
    return safe_frame(frame).to_csv(index=False)


def restored(frame: pd.DataFrame, columns: Iterable[str] | None = None) -> pd.DataFrame:
    """A CSV physval wrote, read back: the text cells of ``columns`` (default: every text
    column) as they were before ``csv_text`` (in place; returns ``frame``)."""
    names = [c for c in (frame.columns if columns is None else columns) if c in frame.columns]
    for name in names:
        if is_text_column(frame[name]):
            frame[name] = _each_text_cell(frame[name], original)
    return frame
