"""World splits: the three disjoint world-seed ranges (development, evaluation, training) and the checks
that keep the evaluation worlds for reporting only.

A world is drawn from a seed: `world_seed`, or the reset seed when `world_seed` is None. Development
worlds are for tests, tuning, examples and the figures of `docs/`; training worlds for the depth model's
data, the oracle noise fit and follower training; evaluation worlds only for the evaluation suites of
`trade-bench` (`--suite unseen`), so no parameter, threshold or test is ever chosen on them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

MAX_SEED = 2**31 - 2  # largest world seed anything draws (numpy's integers(high=2**31 - 1) is exclusive)


class EvaluationWorldError(ValueError):
    """A world seed from the evaluation split was asked for outside an evaluation suite."""


@dataclass(frozen=True)
class SeedRange:
    """World seeds `first`..`last` (inclusive) of one split."""

    name: str
    first: int
    last: int

    def __post_init__(self) -> None:
        if not 0 <= self.first <= self.last <= MAX_SEED:
            raise ValueError(f"SeedRange {self.name!r} needs 0 <= first <= last <= {MAX_SEED}, "
                             f"got {self.first}..{self.last}")

    def __contains__(self, seed: object) -> bool:
        return isinstance(seed, int) and not isinstance(seed, bool) and self.first <= seed <= self.last

    def __len__(self) -> int:
        return self.last - self.first + 1

    def seeds(self, count: int | None = None) -> tuple[int, ...]:
        """The first `count` seeds of the range (all when None; only for bounded ranges)."""
        n = len(self) if count is None else count
        if not 0 <= n <= len(self):
            raise ValueError(f"split {self.name!r} has {len(self)} seeds, asked for {count!r}")
        return tuple(range(self.first, self.first + n))

    def __str__(self) -> str:
        return f"{self.name} ({self.first}..{self.last})"


DEVELOPMENT = SeedRange("development", 0, 999)
EVALUATION = SeedRange("evaluation", 5000, 5019)  # 20 worlds per scene
TRAINING = SeedRange("training", 10_000, MAX_SEED)
SPLITS = (DEVELOPMENT, EVALUATION, TRAINING)


def split_of(seed: int) -> SeedRange | None:
    """The split holding world `seed` (None for the unassigned gaps between them)."""
    return next((s for s in SPLITS if seed in s), None)


def ranges_overlap(first: int, last: int, split: SeedRange) -> bool:
    """Whether the seeds `first`..`last` (inclusive) meet `split`."""
    return first <= split.last and split.first <= last


def refuse_evaluation_worlds(seeds: Iterable[int], what: str) -> None:
    """EvaluationWorldError naming the first evaluation world among `seeds` (`what` says where it came from)."""
    for seed in seeds:
        if seed in EVALUATION:
            raise EvaluationWorldError(
                f"{what}: world seed {seed} is in the {EVALUATION} split, which only trade-bench's evaluation "
                f"suites (--suite unseen, breadth, unseen-depth, real-flight, thermal) use; take development ({DEVELOPMENT.first}..{DEVELOPMENT.last}) or "
                f"training ({TRAINING.first}..) worlds")


def require_training_worlds(seeds: Iterable[int], what: str) -> None:
    """ValueError naming the first seed of `seeds` outside the training split (evaluation ones first)."""
    seeds = list(seeds)
    refuse_evaluation_worlds(seeds, what)
    for seed in seeds:
        if seed not in TRAINING:
            raise ValueError(f"{what}: world seed {seed} is not a training world; the {TRAINING} split is "
                             f"what fits and training draw from")
