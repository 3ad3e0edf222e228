"""The learning curve of a training run: one row per finished training episode (env steps so far, the episode's
return on the env's reward, its mean horizontal distance to the target, scene), written to `learning_curve.csv`,
and its plot (return and following error against steps, a moving mean over episodes).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

CURVE_FILE = "learning_curve.csv"
CURVE_COLUMNS = ("steps", "episode_return", "mean_horizontal_distance_m", "episode_steps", "scene")
DISTANCE_KEY = "horizontal_distance_m"  # the env's info key (trade_gym.scoring)
SMOOTHING_EPISODES = 50  # the plot's moving mean [episodes]


def curve_callback(out_dir: str | Path):
    """An SB3 callback that appends every finished episode of every worker to `out_dir/learning_curve.csv`."""
    from stable_baselines3.common.callbacks import BaseCallback

    path = Path(out_dir) / CURVE_FILE

    class LearningCurveCallback(BaseCallback):
        def _on_training_start(self) -> None:
            n = self.training_env.num_envs
            self._return, self._distance, self._steps = np.zeros(n), np.zeros(n), np.zeros(n, int)
            self._scene = [""] * n
            if not path.exists():
                path.write_text(",".join(CURVE_COLUMNS) + "\n")

        def _on_step(self) -> bool:
            rows = []
            for i, (info, reward, done) in enumerate(zip(self.locals["infos"], self.locals["rewards"],
                                                         self.locals["dones"])):
                self._return[i] += float(reward)
                self._distance[i] += float(info.get(DISTANCE_KEY, np.nan))
                self._steps[i] += 1
                self._scene[i] = info.get("scene", self._scene[i])
                if done:
                    rows.append((self.num_timesteps, round(self._return[i], 4),
                                 round(self._distance[i] / self._steps[i], 4), int(self._steps[i]), self._scene[i]))
                    self._return[i], self._distance[i], self._steps[i] = 0.0, 0.0, 0
            if rows:
                with path.open("a", newline="") as f:
                    csv.writer(f).writerows(rows)
            return True

    return LearningCurveCallback()


def read_curve(path: str | Path) -> dict[str, np.ndarray]:
    """The curve's numeric columns as arrays (rows in the order the episodes finished)."""
    with Path(path).open() as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path}: no finished episode recorded")
    return {c: np.array([float(r[c]) for r in rows]) for c in CURVE_COLUMNS if c != "scene"}


def moving_mean(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over the last `window` values (fewer at the start)."""
    sums = np.cumsum(np.insert(np.asarray(values, float), 0, 0.0))
    idx = np.arange(1, len(values) + 1)
    start = np.maximum(idx - window, 0)
    return (sums[idx] - sums[start]) / (idx - start)


def plot_curves(runs: dict[str, str | Path], out_png: str | Path, reference: dict[str, float] | None = None) -> None:
    """Mean episode return and mean horizontal distance against env steps for each named run's curve file;
    `reference` draws horizontal lines (e.g. the scripted follower's distance) on the distance panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_r, ax_d) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for name, path in runs.items():
        c = read_curve(path)
        ax_r.plot(c["steps"], moving_mean(c["episode_return"], SMOOTHING_EPISODES), label=name)
        ax_d.plot(c["steps"], moving_mean(c["mean_horizontal_distance_m"], SMOOTHING_EPISODES), label=name)
    for name, value in (reference or {}).items():
        ax_d.axhline(value, linestyle="--", color="gray", label=name)
    ax_r.set_ylabel("episode return (env reward)")
    ax_d.set_ylabel("mean horizontal distance [m]")
    ax_d.set_xlabel("env steps")
    ax_d.set_yscale("log")
    for ax in (ax_r, ax_d):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    ax_r.set_title(f"training episodes, moving mean over {SMOOTHING_EPISODES}")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    """`python -m trade_gym.agents.learning_curve RUN_DIR... --out curve.png [--scripted-m D]`: plot runs' curves."""
    import argparse

    p = argparse.ArgumentParser(description="Plot the learning curves of trade_gym.agents.train runs.")
    p.add_argument("runs", nargs="+", type=Path,
                   help="output folders of trade_gym.agents.train (holding learning_curve.csv)")
    p.add_argument("--out", type=Path, required=True, help="PNG to write")
    p.add_argument("--scripted-m", type=float, default=None,
                   help="the scripted follower's mean horizontal distance [m], drawn as a reference line")
    args = p.parse_args(argv)
    reference = {"scripted follower": args.scripted_m} if args.scripted_m is not None else None
    plot_curves({run.name: run / CURVE_FILE for run in args.runs}, args.out, reference)


if __name__ == "__main__":
    main()
