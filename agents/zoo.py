"""rl-zoo3's hyperparameter file for TradeFollow-v0, rendered from a `TrainConfig` (agents/hyperparams/ppo.yml), so
the two cannot drift: `python -m trade_gym.agents.zoo` writes agents/hyperparams/rl_zoo3/ppo.yml, `--check` fails on
a stale one.

rl-zoo3 makes the env with `gym.make("TradeFollow-v0", **env_kwargs)` and applies `env_wrapper` in order; the file's
wrappers compose around it what `trade_gym.agents.train.make_training_env` composes (`EpisodeDraws`, `ResidualAction`
for a residual policy, `ShapedAction`, `ZeroYawAction`, `FlatObservation`). rl-zoo3 has no warm start, critic warm-up
or fine-tune stage: the file trains as `python -m trade_gym.agents.train --from-scratch --finetune-steps 0` does.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import yaml

from trade_gym import ENV_ID
from trade_gym.agents.train import HYPERPARAMS_DIR, TrainConfig, hyperparams_path, load_train_config

ZOO_DIR = HYPERPARAMS_DIR / "rl_zoo3"  # rl-zoo3's layout: one <algo>.yml keyed by env id
ZOO_ALGOS = ("ppo",)  # the shipped policy's algorithm; SAC's TrainConfig is untuned (sac.yml)
EPISODE_DRAWS = "trade_gym.agents.training_env.EpisodeDraws"
SHAPED_ACTION = "trade_gym.agents.action_shaping.ShapedAction"
RESIDUAL_ACTION = "trade_gym.agents.training_env.ResidualAction"
ZERO_YAW = "trade_gym.agents.training_env.ZeroYawAction"
FLAT_OBSERVATION = "trade_gym.agents.obs_flatten.FlatObservation"

# (rl-zoo3 key, TrainConfig field) for the settings rl-zoo3 passes on to PPO unchanged
PPO_FIELDS = (("n_envs", "n_envs"), ("n_timesteps", "total_steps"), ("learning_rate", "learning_rate"),
              ("n_steps", "n_steps_per_env"), ("batch_size", "batch_size"), ("n_epochs", "n_epochs"),
              ("gamma", "gamma"), ("gae_lambda", "gae_lambda"), ("clip_range", "clip_range"),
              ("ent_coef", "ent_coef"), ("use_sde", "use_sde"), ("sde_sample_freq", "sde_sample_freq"))
# the TrainConfig fields in the file besides PPO_FIELDS (policy_kwargs, env_wrapper, env_kwargs)
OTHER_FILE_FIELDS = ("hidden_units", "log_std_init", "scenes", "target_motions", "decoy_tiers", "appearances",
                     "action_shaping", "residual_scale", "residual_axes", "env_kwargs", "episode_duration_s")
# TrainConfig fields with no place in rl-zoo3's file: the stages rl-zoo3 does not have, and the settings that are
# rl-zoo3's command-line flags (`zoo_command`) or belong to the SAC trainer; n_workers: rl-zoo3's subproc VecEnv runs
# one env per process
NOT_IN_FILE = ("algo", "seed", "n_workers", "warm_start", "critic_warmup_steps", "finetune_steps", "finetune_env_kwargs",
               "torch_threads", "progress_bar", "tensorboard_dir", "checkpoint_every_steps", "verbose",
               "sac_buffer_size", "sac_learning_starts", "sac_gradient_steps")


def zoo_hyperparams(config: TrainConfig) -> dict[str, Any]:
    """rl-zoo3's settings for `config` (one env id's entry of its hyperparameter file)."""
    if config.algo not in ZOO_ALGOS:
        raise ValueError(f"TrainConfig.algo must be one of {ZOO_ALGOS} for rl-zoo3's file, got {config.algo!r}")
    values: dict[str, Any] = {"policy": "MlpPolicy"}
    values |= {key: getattr(config, name) for key, name in PPO_FIELDS}
    values["policy_kwargs"] = {"net_arch": list(config.hidden_units), "log_std_init": config.log_std_init}
    values["env_wrapper"] = env_wrappers(config)
    values["env_kwargs"] = dict(config.env_kwargs) | {"episode_duration_s": config.episode_duration_s}
    return values


def env_wrappers(config: TrainConfig) -> list[Any]:
    """rl-zoo3's `env_wrapper` list: `make_training_env`'s wrappers (without its Monitor: rl-zoo3 adds its own
    around the made env), innermost first."""
    draws = {"scenes": list(config.scenes), "target_motions": list(config.target_motions),
             "decoy_tiers": list(config.decoy_tiers), "appearances": list(config.appearances)}
    residual = [] if config.residual_scale is None else [
        {RESIDUAL_ACTION: {"scale": config.residual_scale, "axes": list(config.residual_axes)}}]
    shaping = [SHAPED_ACTION] if config.action_shaping else []
    return [{EPISODE_DRAWS: draws}, *residual, *shaping, ZERO_YAW, FLAT_OBSERVATION]


def zoo_command(config: TrainConfig, conf_file: str) -> list[str]:
    """The rl-zoo3 command that trains as `python -m trade_gym.agents.train --from-scratch --finetune-steps 0`, with
    `config`'s settings that are rl-zoo3 flags (seed, threads, device, checkpoints; no evaluation runs), as groups of
    words (a flag and its value)."""
    words = ["python -m rl_zoo3.train", f"--algo {config.algo}", f"--env {ENV_ID}", "--gym-packages trade_gym",
             f"--conf-file {conf_file}", f"--seed {config.seed}", "--device cpu",
             f"--num-threads {config.torch_threads}", f"--save-freq {config.checkpoint_every_steps or -1}",
             "--eval-freq -1"]
    if config.n_envs > 1:
        words.append("--vec-env subproc")
    if config.progress_bar:
        words.append("--progress")
    if config.tensorboard_dir is not None:
        words.append(f"--tensorboard-log {config.tensorboard_dir}")
    return words


def _command_lines(words: list[str], width: int = 100) -> list[str]:
    """`words` joined into shell lines of about `width` characters, continued with a backslash."""
    lines = [words[0]]
    for word in words[1:]:
        if len(lines[-1]) + 1 + len(word) > width:
            lines[-1] += " \\"
            lines.append("    " + word)
        else:
            lines[-1] += " " + word
    return lines


def _yaml(value: Any) -> str:
    """`value` as one line of YAML (flow style)."""
    return yaml.safe_dump(value, default_flow_style=True, sort_keys=False, width=1 << 20).removesuffix("...\n").strip()


def render(config: TrainConfig, source: str, conf_file: str) -> str:
    """The text of rl-zoo3's hyperparameter file for `config`, read from `source` (a path, for the header)."""
    values = zoo_hyperparams(config)
    fields = dict(PPO_FIELDS) | {"policy_kwargs": "hidden_units, log_std_init"}
    lines = [
        f"# Generated from {source} by `python -m trade_gym.agents.zoo`: do not edit (a test checks it is current).",
        "# rl-zoo3's hyperparameter file for the learned follower: the settings of `python -m trade_gym.agents.train",
        "# --from-scratch --finetune-steps 0`. rl-zoo3 cannot express the trainer's warm start (cloning the scripted",
        "# follower), its critic warm-up or its fine-tune stage (finetune_steps on finetune_env_kwargs).",
        "# Train (the flags carry the trainer's seed, threads, device and checkpoints; docs/training.md):",
        *(f"#   {line}" for line in _command_lines(zoo_command(config, conf_file))),
        f"{ENV_ID}:",
    ]
    for key in ("policy", *dict(PPO_FIELDS), "policy_kwargs"):
        comment = f"  # TrainConfig.{fields[key]}" if key in fields else ""
        lines.append(f"  {key}: {_yaml(values[key])}{comment}")
    lines.append("  # make_training_env's wrappers around gym.make's env, innermost first (rl-zoo3's Monitor is below)")
    lines.append("  env_wrapper:")
    for wrapper in values["env_wrapper"]:
        if isinstance(wrapper, dict):  # {name: kwargs}, the kwargs a line each
            (name, kwargs), = wrapper.items()
            lines += [f"    - {name}:", *(f"        {key}: {_yaml(value)}" for key, value in kwargs.items())]
        else:
            lines.append(f"    - {wrapper}")
    lines.append("  # gym.make kwargs: TrainConfig.env_kwargs and episode_duration_s")
    lines.append(f"  env_kwargs: {_yaml(values['env_kwargs'])}")
    return "\n".join(lines) + "\n"


def zoo_path(algo: str) -> Path:
    """The shipped rl-zoo3 file of `algo` (agents/hyperparams/rl_zoo3/<algo>.yml)."""
    return ZOO_DIR / f"{algo}.yml"


def _repo_relative(path: Path) -> str:
    """`path` as the repo names it (agents/...), or as given when it is outside the followers' folder."""
    try:
        return str(Path("agents") / path.resolve().relative_to(HYPERPARAMS_DIR.parent))
    except ValueError:
        return str(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write rl-zoo3's hyperparameter file for TradeFollow-v0 from a "
                                                 "trade_gym.agents.train hyperparameter file.")
    parser.add_argument("--hyperparams", type=Path, default=hyperparams_path("ppo"), metavar="YML",
                        help="trade_gym.agents.train's file (default: agents/hyperparams/ppo.yml)")
    parser.add_argument("--out", type=Path, default=zoo_path("ppo"), metavar="YML",
                        help="rl-zoo3's file to write (default: agents/hyperparams/rl_zoo3/ppo.yml)")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 when --out is not current")
    args = parser.parse_args(argv)
    text = render(load_train_config(args.hyperparams), _repo_relative(args.hyperparams), _repo_relative(args.out))
    if not args.check:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
        print(f"wrote {args.out}")
        return 0
    if not args.out.is_file() or args.out.read_text() != text:
        print(f"{args.out} is stale: run python -m trade_gym.agents.zoo --hyperparams {args.hyperparams} "
              f"--out {args.out}")
        return 1
    print(f"{args.out} is current")
    return 0


if __name__ == "__main__":
    sys.exit(main())
