"""Markdown table pieces shared by the benchmark's reports: numbers, 'mean ± std', pooled rates with their 95 % Wilson
interval, and the table itself.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from trade_gym.bench.summary import wilson_interval

Record = dict[str, Any]
MISSING = "–"


def fmt(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return MISSING
    return f"{value:.{digits}g}" if abs(value) >= 10 ** digits else f"{value:.{digits}f}".rstrip("0").rstrip(".")


def mean_pm(stats: dict[str, float], digits: int = 3) -> str:
    """'mean ± std' (std omitted for a single run)."""
    if not stats["n"]:
        return MISSING
    std = stats["std"]
    return fmt(stats["mean"], digits) + (f" ± {fmt(std, digits)}" if math.isfinite(std) else "")


def with_frames(rmse: float | None, frames: int) -> str:
    """A pooled depth RMSE with the number of frames it pools, 'rmse [frames]'."""
    return f"{fmt(rmse)} [{frames}]"


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in rows]


def pooled_mean(records: Sequence[Record], metric: str) -> tuple[float, int]:
    """The mean of `metric` over every run of `records` (each record's mean weighted by its run count), and n."""
    stats = [r["metrics"][metric] for r in records if r["metrics"][metric]["n"]]
    n = sum(s["n"] for s in stats)
    return (sum(s["mean"] * s["n"] for s in stats) / n if n else math.nan), n


def rate_cell(rate: float, n: int) -> str:
    """A success rate with its 95 % Wilson interval and its runs: 'rate [low, high] (n)'."""
    low, high = wilson_interval(rate, n)
    return f"{fmt(rate, 2)} [{fmt(low, 2)}, {fmt(high, 2)}] ({n})" if n else f"{MISSING} (0)"
