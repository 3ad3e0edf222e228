"""Import names of our own (issue 44): the wheel's top-level packages are `trade` and `trade_gym` only, a package
that owns `agents` (and `assets`) beside them breaks nothing, and code, tests and docs use one import path per module.

The wheel is built from a copy of the four package folders (setuptools writes build/ and egg-info beside the sources)
with this Python's setuptools and no build isolation or index: no registry is asked.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade_gym.agents import LearnedFollower, ScriptedFollower

ROOT = Path(__file__).resolve().parents[1]
# repo folder -> where it installs (pyproject.toml's package-dir)
INSTALLED_AS = {"trade": "trade", "trade_gym": "trade_gym", "agents": "trade_gym/agents", "assets": "trade_gym/assets"}
FOREIGN_OWNER = "foreign-agents"  # the marker of the other distribution's `agents` and `assets`
FOREIGN_PYPROJECT = """[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "foreign-agents"
version = "1.0"

[tool.setuptools]
packages = ["agents", "assets"]
"""
SKIPPED = ("__pycache__", "*.pyc", "*.egg-info")

# A fresh interpreter imports the foreign `agents` and `assets` first, then flies both followers one step on the
# oracle env and loads the depth model, and prints where each package came from and the followers' actions.
PROBE = """
import json, sys
import agents, assets
import gymnasium as gym
import trade_gym, trade_gym.assets
from trade.model_file import shipped_assets_dir
from trade.single_image_depth import SingleImageDepth
from trade_gym.agents import LearnedFollower, ScriptedFollower
env = gym.make("TradeFollow-v0", perception="oracle")
obs, _ = env.reset(seed=0)
followers = (ScriptedFollower(), LearnedFollower(soft_start_s=0.0))
actions = [f.predict(obs, episode_start=[True])[0].tolist() for f in followers]
env.step(actions[1]); env.close()
SingleImageDepth()  # the shipped depth model, its SHA-256 checked
print(json.dumps({"agents": sys.modules["agents"].OWNER, "assets": sys.modules["assets"].OWNER,
                  "trade": sys.modules["trade"].__file__, "followers": sys.modules["trade_gym.agents"].__file__,
                  "assets_dir": str(trade_gym.assets.ASSETS_DIR), "stack_assets_dir": str(shipped_assets_dir()),
                  "actions": actions}))
"""


def _pip(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input", *map(str, args)],
                          check=True, capture_output=True, text=True, timeout=300)


def _package_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"]


def _write_foreign_sources(folder: Path) -> Path:
    """A folder holding packages `agents` and `assets` that are not ours (and a pyproject.toml that owns them)."""
    for package in ("agents", "assets"):
        (folder / package).mkdir(parents=True)
        (folder / package / "__init__.py").write_text(f"OWNER = {FOREIGN_OWNER!r}\n")
    (folder / "pyproject.toml").write_text(FOREIGN_PYPROJECT)
    return folder


def _run_probe(pythonpath: Path, cwd: Path) -> dict:
    """PROBE with `pythonpath` first on sys.path after the (empty) working folder `cwd`."""
    env = dict(os.environ, PYTHONPATH=str(pythonpath))
    done = subprocess.run([sys.executable, "-c", PROBE], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    for folder in INSTALLED_AS:
        shutil.copytree(ROOT / folder, src / folder, ignore=shutil.ignore_patterns(*SKIPPED))
    dist = tmp_path_factory.mktemp("dist")
    _pip("wheel", "--no-deps", "--no-index", "--no-build-isolation", "--wheel-dir", dist, src)
    (path,) = dist.glob("*.whl")
    return path


@pytest.fixture(scope="module")
def reference_actions() -> list[list[float]]:
    """The followers' first actions in this process (the repo's code), as PROBE computes them."""
    env = gym.make("TradeFollow-v0", perception="oracle")
    obs, _ = env.reset(seed=0)
    actions = [f.predict(obs, episode_start=[True])[0].tolist()
               for f in (ScriptedFollower(), LearnedFollower(soft_start_s=0.0))]
    env.close()
    return actions


def test_wheel_holds_only_trade_and_trade_gym_at_top_level_and_every_module_and_shipped_file(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top = {name.split("/")[0] for name in names}
    (dist_info,) = [t for t in top if t.endswith(".dist-info")]
    assert top == {"trade", "trade_gym", dist_info}, sorted(top)
    expected = {f"{INSTALLED_AS[folder]}/{path.relative_to(ROOT / folder).as_posix()}"
                for folder in INSTALLED_AS for path in _package_files(ROOT / folder)}
    assert {name for name in names if not name.startswith(dist_info)} == expected
    assert {"trade_gym/assets/models/depth_small.onnx", "trade_gym/assets/policies/follower_ppo.onnx",
            "trade_gym/assets/policies/follower_ppo.md", "trade_gym/agents/hyperparams/ppo.yml"} <= expected


def test_wheel_installed_beside_a_package_that_owns_agents_leaves_both_importable(wheel, reference_actions,
                                                                                     tmp_path):
    site = tmp_path / "site"
    foreign = _write_foreign_sources(tmp_path / "foreign")
    _pip("install", "--no-deps", "--no-index", "--no-build-isolation", "--target", site, foreign)
    ours = _pip("install", "--no-deps", "--no-index", "--target", site, wheel)
    assert "already exists" not in ours.stderr, ours.stderr  # pip --target skips a top-level name it would clash on
    (tmp_path / "cwd").mkdir()
    found = _run_probe(site, tmp_path / "cwd")
    assert found["agents"] == found["assets"] == FOREIGN_OWNER
    assert Path(found["trade"]).is_relative_to(site)
    assert Path(found["followers"]) == site / "trade_gym" / "agents" / "__init__.py"
    assert Path(found["assets_dir"]) == Path(found["stack_assets_dir"]) == site / "trade_gym" / "assets"
    np.testing.assert_array_equal(found["actions"], reference_actions)


def test_foreign_agents_first_on_sys_path_does_not_break_the_followers_in_the_repo(reference_actions, tmp_path):
    """The editable install: trade_gym.agents and trade_gym.assets still come from the repo's folders."""
    foreign = _write_foreign_sources(tmp_path / "foreign")
    (tmp_path / "cwd").mkdir()
    found = _run_probe(foreign, tmp_path / "cwd")
    assert found["agents"] == found["assets"] == FOREIGN_OWNER
    assert Path(found["followers"]) == ROOT / "agents" / "__init__.py"
    assert Path(found["assets_dir"]) == Path(found["stack_assets_dir"]) == ROOT / "assets"
    np.testing.assert_array_equal(found["actions"], reference_actions)


# Ways of naming the followers or the shipped files by their old top-level names, `agents` and `assets`.
OLD = r"(?:agents|assets)"
STALE = {
    "python -m": re.compile(rf"-m\s+{OLD}\."),
    "from-import": re.compile(rf"(?<![\w.])from\s+{OLD}(?:\.\w+)*\s+import\b"),
    "import": re.compile(rf"(?<![\w.])import\s+(?:[\w.]+\s*,\s*)*{OLD}(?!\w)"),
    "module name": re.compile(rf"[\"'`]{OLD}\.\w"),  # "agents.learned", `agents.train`
}
FROM_PACKAGE_BEFORE = re.compile(r"\bfrom\s+[\w.]+\s+$")  # `from trade_gym import agents` is the new path
SCANNED_DIRS = ("trade", "trade_gym", "agents", "assets", "tests", "benchmarks", "scripts", "docs")
SCANNED_FILES = ("README.md", "Makefile", "pyproject.toml", ".ci/run")
SCANNED_SUFFIXES = {".py", ".md", ".yml", ".yaml", ".toml", ".txt", ".cfg"}


def stale_uses(line: str) -> list[str]:
    """The kinds of old-name use in one line of code or text (a `\\n` in a string of code counts as a new line)."""
    line = line.replace("\\n", " ")
    found = []
    for kind, pattern in STALE.items():
        for match in pattern.finditer(line):
            if not (kind == "import" and FROM_PACKAGE_BEFORE.search(line[:match.start()])):
                found.append(kind)
    return found


@pytest.mark.parametrize("line, kinds", [
    ("python -m agents.train --out runs/ppo", ["python -m"]),
    ("from agents import ScriptedFollower", ["from-import"]),
    ("    from agents.learned import LearnedFollower", ["from-import"]),
    ("from assets import ASSETS_DIR", ["from-import"]),
    ('code = "import sys, agents; agents.x"', ["import"]),
    ("import assets.models", ["import"]),
    ('code = ("import gymnasium as gym\\nfrom agents import ScriptedFollower\\n")', ["from-import"]),
    ('_LAZY = {"LearnedFollower": "agents.learned"}', ["module name"]),
    ("runs `agents.LearnedFollower` too", ["module name"]),
    ("from trade_gym.agents import ScriptedFollower", []),
    ("from trade_gym import agents", []),
    ('code = ("import gymnasium as gym, trade_gym\\nfrom trade_gym import agents\\n")', []),
    ("import trade_gym.agents as agents", []),
    ("python -m trade_gym.agents.train --hyperparams agents/hyperparams/ppo.yml", []),
    ("`assets/policies/follower_ppo.onnx`, the repo's `agents/` folder; the agents package", []),
])
def test_stale_name_checker_finds_old_imports_and_module_names_only(line, kinds):
    assert stale_uses(line) == kinds


def test_code_tests_and_docs_use_one_import_path_for_the_followers_and_the_shipped_files():
    paths = [ROOT / name for name in SCANNED_FILES if (ROOT / name).is_file()]
    paths += [p for d in SCANNED_DIRS for p in sorted((ROOT / d).rglob("*"))
              if p.suffix in SCANNED_SUFFIXES and "__pycache__" not in p.parts]
    paths = [p for p in paths if p != Path(__file__).resolve()]  # this file holds the examples
    assert len(paths) > 100
    stale = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in paths
             for n, line in enumerate(p.read_text(errors="replace").splitlines(), 1) if stale_uses(line)]
    assert not stale, "old top-level names (use trade_gym.agents / trade_gym.assets):\n" + "\n".join(stale)
