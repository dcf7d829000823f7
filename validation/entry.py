"""The ``physval`` command's entry point (``[project.scripts]``).

It imports the harness inside the stop handling, so a Ctrl-C (or SIGTERM, SIGHUP:
``validation.signals``) while Python is still importing it (NumPy, MuJoCo, PyBullet, pandas:
about a second) ends like one at any later moment: one line and exit 128 + the signal's
number, no traceback.
"""

from __future__ import annotations

import sys

from validation import signals


def main() -> int:
    signals.install()
    try:
        from validation.cli import main as physval
    except KeyboardInterrupt as stop:  # Ctrl-C, or signals.Stopped
        signum = signals.signal_number(stop)
        print(signals.stop_message(signum), file=sys.stderr)
        return signals.exit_code(signum)
    return physval()


if __name__ == "__main__":
    sys.exit(main())
