"""The ``physval`` command's entry point (``[project.scripts]``).

It imports the harness inside the stop handling, so a Ctrl-C (or SIGTERM, SIGHUP:
``validation.signals``) while Python is still importing it (NumPy, MuJoCo, PyBullet, pandas:
about a second) ends like one at any later moment: one line and exit 128 + the signal's
number, no traceback.

Its output streams never end a command either (``guard_streams``): a character the terminal's
encoding lacks (``PYTHONIOENCODING=ascii``) is printed as its escape (``\\u03c9``); a reader
that goes away (``physval list | head -1``) or a stream closed from the start (``>&-``) sends
the rest of that stream's output to ``os.devnull``, and the command finishes its work (a run
is still written) with its own exit code.
"""

from __future__ import annotations

import os
import sys

from validation import signals


class GuardedStream:
    """A text stream whose reader may go away: the first broken pipe sends this and every
    later write to ``os.devnull`` (the stream's file descriptor is pointed there), so that no
    print can fail the command. Everything else is the wrapped stream's."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._to_devnull()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._to_devnull()

    def _to_devnull(self) -> None:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, self._stream.fileno())
        finally:
            os.close(devnull)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _guarded(stream, mode: str):
    """``stream`` escaping what its encoding cannot write and surviving a broken pipe;
    ``os.devnull`` when it was closed before Python started (None)."""
    if stream is None:
        return open(os.devnull, mode, encoding="utf-8")
    reconfigure = getattr(stream, "reconfigure", None)
    if reconfigure is not None:
        reconfigure(errors="backslashreplace")
    return GuardedStream(stream)


def guard_streams() -> None:
    """Make stdout and stderr safe to print to, whatever is at their other end."""
    sys.stdout = _guarded(sys.stdout, "w")
    sys.stderr = _guarded(sys.stderr, "w")


def main() -> int:
    guard_streams()
    signals.install()
    try:
        try:
            from validation.cli import main as physval
        except KeyboardInterrupt as stop:  # Ctrl-C, or signals.Stopped
            signum = signals.signal_number(stop)
            print(signals.stop_message(signum), file=sys.stderr)
            return signals.exit_code(signum)
        return physval()
    finally:
        sys.stdout.flush()  # a reader gone before Python's own last flush: not a traceback
        sys.stderr.flush()


if __name__ == "__main__":
    sys.exit(main())
