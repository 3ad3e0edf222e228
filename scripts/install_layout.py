"""A folder of links from which a source tree imports as an install of it would.

The wheel maps the repo's agents/ and assets/ folders to trade_gym.agents and trade_gym.assets (pyproject.toml's
package-dir); an editable install does the same with an import hook, which neither a bare tree on PYTHONPATH nor
mypy sees. The A/B benchmarks run a base tree's code from such a folder, and `scripts/typecheck.py` checks it there.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
import tomllib
from pathlib import Path


def import_root(tree: Path) -> Path:
    """A folder from which `tree`'s code imports as an install of it would (removed at exit).

    It links to the tree's top-level entries, but rebuilds trade_gym/ from links with the tree's agents/ and assets/
    inside, as trade_gym.agents and trade_gym.assets. A tree from before that mapping (pyproject.toml without
    package-dir) keeps agents/ and assets/ at the top as well, where its own code imports them.
    """
    setuptools = tomllib.loads((tree / "pyproject.toml").read_text()).get("tool", {}).get("setuptools", {})
    mapped = set(setuptools.get("package-dir", {}).values())  # {"agents", "assets"} since the mapping
    root = Path(tempfile.mkdtemp(prefix="import_root_"))
    atexit.register(shutil.rmtree, root, ignore_errors=True)  # removes the links, never what they point to
    for entry in tree.iterdir():
        if entry.name != "trade_gym" and entry.name not in mapped:
            (root / entry.name).symlink_to(entry)
    (root / "trade_gym").mkdir()
    for entry in [*(tree / "trade_gym").iterdir(), tree / "agents", tree / "assets"]:
        (root / "trade_gym" / entry.name).symlink_to(entry)
    return root
