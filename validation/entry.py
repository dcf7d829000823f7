"""The ``physval`` command's entry point (``[project.scripts]``).

It imports the harness inside the Ctrl-C handling, so a Ctrl-C while Python is still
importing it (NumPy, MuJoCo, PyBullet, pandas: about a second) ends like one at any later
moment: ``contract.INTERRUPTED_MESSAGE`` and exit 130, no traceback.
"""

from __future__ import annotations

import sys

from validation.contract import EXIT_INTERRUPTED, INTERRUPTED_MESSAGE


def main() -> int:
    try:
        from validation.cli import main as physval
    except KeyboardInterrupt:
        print(INTERRUPTED_MESSAGE, file=sys.stderr)
        return EXIT_INTERRUPTED
    return physval()


if __name__ == "__main__":
    sys.exit(main())
