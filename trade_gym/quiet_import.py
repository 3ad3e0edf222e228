"""Importing pybullet without its build-time banner, which its C import prints on stderr and which would break
the command-line tools' one-line errors and progress lines.
"""

from __future__ import annotations

import os
import sys


def import_pybullet_quietly() -> None:
    """Import pybullet with file descriptor 2 pointed at /dev/null: its C import prints a build-time
    banner on stderr, which would break the CLI's one-line errors and its progress line."""
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
