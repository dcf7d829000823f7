"""Secrets never reach an output: passwords in URLs and command lines are shown as ``***``.

A history database may be a server's (``--history postgresql://ci:PASSWORD@db/physval``); its
URL, and the command line that named it, are printed, written to provenance.json, shown in
report.html and history.html and recorded in the history's ``command`` column. Each of them
goes through here first:

- ``shown_url``: a URL (SQLAlchemy's rendering with the password hidden), or a message that
  holds URLs (every ``scheme://user:password@`` and ``?password=`` part replaced);
- ``shown_argv`` / ``shown_command``: a command line with every token that holds such a URL
  masked, ``--history URL`` and ``--history=URL`` alike.
"""

from __future__ import annotations

import re

import sqlalchemy as sa

HIDDEN = "***"
"""What a password is shown as (SQLAlchemy's own mark)."""

PASSWORD_IN_URL = re.compile(r"(://[^/@:\s]*:)[^/\s]*@")
"""``scheme://user:password@host``: the password part of a URL (that may not even parse)."""

PASSWORD_IN_QUERY = re.compile(r"([?&](?:password|passwd|pwd)=)[^&\s]*", re.IGNORECASE)
"""``...?password=...``: a password given as a URL's query parameter."""


def _scrubbed(text: str) -> str:
    """Every password part of every URL in ``text`` replaced (``PASSWORD_IN_URL``,
    ``PASSWORD_IN_QUERY``)."""
    return PASSWORD_IN_QUERY.sub(rf"\1{HIDDEN}", PASSWORD_IN_URL.sub(rf"\1{HIDDEN}@", text))


def shown_url(text: object) -> str:
    """``text`` as it may be printed: a URL with a password rendered by SQLAlchemy with the
    password hidden; any other text (a message, a URL that does not parse) with every password
    part of a URL in it replaced by ``***``."""
    text = str(text)
    try:
        url = sa.engine.make_url(text)
    except (sa.exc.ArgumentError, ValueError, TypeError):
        return _scrubbed(text)
    if url.password is None:
        return _scrubbed(text)
    return _scrubbed(url.render_as_string(hide_password=True))


def shown_argument(token: str) -> str:
    """One command-line token masked: ``URL`` and ``--flag=URL`` alike (``shown_url``)."""
    flag, equals, value = token.partition("=")
    if token.startswith("-") and equals:
        return f"{flag}={shown_url(value)}"
    return shown_url(token)


def shown_argv(argv: list[str]) -> list[str]:
    """A command line's arguments, every password in them masked."""
    return [shown_argument(str(token)) for token in argv]


def shown_command(argv: list[str]) -> str:
    """``physval ARGS`` as provenance.json and the history record it, passwords masked."""
    return " ".join(["physval", *shown_argv(argv)])
