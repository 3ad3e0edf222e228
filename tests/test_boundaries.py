"""The package boundaries of DESIGN.md, checked statically on the source (AST, nothing imported):

- `trade/` (the perception stack, run on recorded data too) imports none of pybullet, gymnasium, `trade_gym`
  (with its followers, `trade_gym.agents`) or torch;
- the TRADE adapter (every file under trade_gym/perception whose name contains "trade") and the perception
  contract (`base.py`) do not import the ground-truth module: perception sees sensors only, the env scores it.
"""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STACK_FORBIDDEN = ("pybullet", "gymnasium", "gym", "trade_gym", "torch")
GROUND_TRUTH_MODULE = "trade_gym.ground_truth"
IMPORT_CALLS = ("import_module", "__import__")  # importlib.import_module("x"), __import__("x")


def _package(path: Path) -> str:
    """The dotted package a module file belongs to (for relative imports)."""
    return ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])


def imported_modules(source: str, package: str) -> set[str]:
    """Every module a source imports, dotted and absolute: `import a.b`, `from a import b` (as a and a.b),
    relative imports resolved against `package`, and importlib / __import__ calls with a literal name."""
    modules: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            modules.add(base)
            modules.update(f"{base}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
            if name in IMPORT_CALLS and isinstance(node.args[0].value, str):
                modules.add(node.args[0].value)
    return modules


def _imports(path: Path) -> set[str]:
    return imported_modules(path.read_text(), _package(path))


def _is_within(module: str, root: str) -> bool:
    return module == root or module.startswith(root + ".")


STACK_FILES = sorted((ROOT / "trade").rglob("*.py"))
ADAPTER_FILES = sorted(p for p in (ROOT / "trade_gym" / "perception").rglob("*.py") if "trade" in p.name)
CONTRACT_FILES = [ROOT / "trade_gym" / "perception" / "base.py"]


def test_the_checked_file_sets_are_not_empty():
    assert len(STACK_FILES) > 10 and ROOT / "trade" / "pipeline.py" in STACK_FILES
    assert ROOT / "trade_gym" / "perception" / "trade_stack.py" in ADAPTER_FILES


@pytest.mark.parametrize("path", STACK_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_stack_module_imports_no_simulator_env_agents_or_torch(path):
    bad = sorted(m for m in _imports(path) if any(_is_within(m, f) for f in STACK_FORBIDDEN))
    assert not bad, f"{path.relative_to(ROOT)} imports {bad}"


@pytest.mark.parametrize("path", ADAPTER_FILES + CONTRACT_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_trade_adapter_and_perception_contract_do_not_import_ground_truth(path):
    bad = sorted(m for m in _imports(path) if _is_within(m, GROUND_TRUTH_MODULE))
    assert not bad, f"{path.relative_to(ROOT)} imports {bad}"


@pytest.mark.parametrize("source, found", [
    ("import torch.nn", "torch.nn"),
    ("from gymnasium import spaces", "gymnasium"),
    ("from trade_gym import ground_truth", "trade_gym.ground_truth"),
    ("from ..ground_truth import GroundTruth", "trade_gym.ground_truth"),
    ("import importlib\nimportlib.import_module('pybullet')", "pybullet"),
    ("def f():\n    import trade_gym.agents", "trade_gym.agents"),
])
def test_import_checker_finds_direct_relative_lazy_and_dynamic_imports(source, found):
    assert found in imported_modules(source, "trade_gym.perception")


def test_perception_modes_take_no_ground_truth_in_reset_or_step():
    from trade_gym.perception.base import Perception
    from trade_gym.perception.oracle import OraclePerception
    from trade_gym.perception.trade_stack import TradePerception

    for cls in (Perception, OraclePerception, TradePerception):
        for method in ("reset", "step"):
            params = inspect.signature(getattr(cls, method)).parameters
            assert not any("truth" in name for name in params), f"{cls.__name__}.{method}{tuple(params)}"
