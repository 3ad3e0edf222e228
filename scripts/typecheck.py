"""Type-check the library, the env and the followers (mypy, configured in pyproject.toml) as an install lays them out.

mypy finds modules by path, so it cannot see trade_gym.agents and trade_gym.assets, which live in the repo's agents/
and assets/ folders (pyproject.toml's package-dir); it checks them in a folder of links that has them in place
(`install_layout.import_root`). Reports name the installed paths (trade_gym/agents/... for agents/...).

Usage: python scripts/typecheck.py [mypy options]   (make test runs it)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from install_layout import import_root  # scripts/ is on sys.path when this script runs

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("trade", "trade_gym")  # trade_gym includes the followers (trade_gym.agents)


def main(argv: list[str]) -> int:
    root = import_root(ROOT)
    packages = [arg for name in PACKAGES for arg in ("-p", name)]
    command = [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
               "--cache-dir", str(ROOT / ".mypy_cache"), *packages, *argv]
    return subprocess.run(command, cwd=root).returncode


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
