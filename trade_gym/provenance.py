"""Where a number or a file came from: the repository's commit and the machine's CPU.

Shared by trade-bench's results.json, its regression reference and recorded sequences' meta.json.
"""

from __future__ import annotations

import platform
import subprocess
from pathlib import Path

GIT_TIMEOUT_S = 5.0
PACKAGE_DIR = Path(__file__).resolve().parent  # git runs here: the repository this code was loaded from


def _git(cwd: Path | None, *args: str) -> str:
    return subprocess.run(["git", *args], capture_output=True, text=True, check=True, cwd=cwd,
                          timeout=GIT_TIMEOUT_S).stdout


def git_head(cwd: Path | None = PACKAGE_DIR) -> str:
    """Short hash of HEAD; raises OSError or subprocess.SubprocessError outside a repository (or without git)."""
    return _git(cwd, "rev-parse", "--short", "HEAD").strip()


def tracked_changes(cwd: Path | None = PACKAGE_DIR) -> list[str]:
    """`git status --porcelain` lines of tracked files changed against HEAD, staged or not (untracked files
    are not changes); raises like `git_head`."""
    return [line.strip() for line in _git(cwd, "status", "--porcelain", "--untracked-files=no").splitlines()]


def git_commit(cwd: Path | None = PACKAGE_DIR) -> str:
    """Short hash of HEAD (with '+dirty' when tracked files have changes); 'unknown' outside a repository."""
    try:
        return git_head(cwd) + ("+dirty" if tracked_changes(cwd) else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()
