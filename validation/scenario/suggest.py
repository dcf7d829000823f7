"""Suggestions: the ``; did you mean 'X'?`` of a mistyped name, chosen only among the names
that exist (bodies, joints, metrics, fields, expectation kinds, engine names and options),
never the input's own spelling."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

SIMILARITY = 0.5
"""difflib's ratio (twice the matching characters over both lengths) a name must reach to be
suggested: half its characters in common, which catches a dropped, doubled or swapped letter
of a short name (``bal`` -> ``ball`` is 0.86, ``sphre`` -> ``sphere`` 0.91) and leaves unrelated
names unsuggested."""


def closest(word: str, choices: Iterable[str]) -> str | None:
    """The existing name in ``choices`` closest to ``word``, case aside (``rk4`` -> ``RK4``),
    or None; never ``word`` itself (the input's own spelling suggests nothing)."""
    by_lower = {str(choice).lower(): str(choice) for choice in choices if choice != word}
    close = difflib.get_close_matches(str(word).lower(), list(by_lower), n=1, cutoff=SIMILARITY)
    return by_lower[close[0]] if close else None


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``; did you mean 'X'?`` for the closest existing name, or nothing."""
    close = closest(word, choices)
    return f"; did you mean {close!r}?" if close else ""
