"""trade-bench: score follower policies and perception variants on TradeFollow-v0.

`trade-bench --suite quick --out DIR` (see `trade_gym.bench.cli`) writes results.json, results.md and plots.
"""

from trade_gym.bench.executors import Executor, LocalExecutor, RayExecutor
from trade_gym.bench.runner import RunResult, run_all, run_spec
from trade_gym.bench.suites import SUITES, GroupSpec, RunSpec, Selection, expand_suite

__all__ = ["SUITES", "Executor", "GroupSpec", "LocalExecutor", "RayExecutor", "RunResult", "RunSpec", "Selection",
           "expand_suite", "run_all", "run_spec"]
