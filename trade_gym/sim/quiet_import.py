"""pybullet's C module prints a build-time banner on stderr when it is imported; import it silently."""

from __future__ import annotations

import os
import sys


def import_pybullet_quietly() -> None:
    """Import pybullet with file descriptor 2 pointed at /dev/null (a no-op once it is imported), so making
    and stepping the env prints nothing and the CLIs' one-line errors stay one line."""
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
