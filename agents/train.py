"""Training of learned followers with stable-baselines3 (PPO or SAC) on the oracle perception mode, optionally
fine-tuned on the TRADE stack itself.

Owns `TrainConfig`, the vectorised training envs (`trade_gym.agents.training_env`: scene, world seed, target motion,
decoy tier and appearance drawn per episode; the follower's action shaping inside), the PPO warm start and critic
warm-up, the perception fine-tune, and `python -m trade_gym.agents.train --out DIR` (settings from
`agents/hyperparams/<algo>.yml`), which writes the SB3 model, the ONNX policy (`trade_gym.agents.export`) and a JSON
record of the run (seeds, steps, wall time, hash).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from trade_gym.agents.learning_curve import curve_callback
from trade_gym.agents.obs_flatten import FlatObservation
from trade_gym.agents.action_shaping import ShapedAction
from trade_gym.agents.residual import HORIZONTAL_AXES, POLICY_AXES, Residual, check_residual_axes, check_residual_scale
from trade_gym.agents.training_env import ResidualAction, ScenarioDraws, SceneRandomizedEnv, ZeroYawAction
from trade_gym.agents.warm_start import WarmStartConfig
from trade_gym.bench.splits import require_training_worlds
from trade.validation import check_choice, is_int_at_least, require
from trade_gym.config import SCENE_NAMES
from trade_gym.sim.appearance import APPEARANCE_MODES
from trade_gym.sim.scenes import DECOY_TIERS
from trade_gym.sim.target_motion import TARGET_MOTIONS
from trade_gym.perception.oracle import FITTED_FIRST_FIX_DELAY_S

ALGOS = ("ppo", "sac")
DEFAULT_ALGO = "ppo"
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"  # <algo>.yml: published settings
DEMO_SEED_OFFSET = 10_000  # demonstrations use seeds seed + 10000 + rank, apart from training's


@dataclass(frozen=True)
class TrainConfig:
    """Everything that determines a training run; `seed` fixes the env draws, torch and SB3."""

    algo: str = "ppo"
    total_steps: int = 1_200_000
    n_envs: int = 2  # training envs in total
    n_workers: int = 2  # processes the envs step in, at most n_envs (`GroupedSubprocVecEnv`; 1: in this process)
    seed: int = 0
    scenes: tuple[str, ...] = SCENE_NAMES
    episode_duration_s: float = 15.0  # shorter than the env's 30 s: more starts (the hard part) per step
    # extra gym.make kwargs; the oracle's fitted first-fix delay is not EnvConfig's default (see there)
    env_kwargs: tuple[tuple[str, Any], ...] = (("perception", "oracle"),
                                               ("oracle_first_fix_delay_s", FITTED_FIRST_FIX_DELAY_S))
    # the scenario drawn per episode (`ScenarioDraws`): every target motion, decoy tier and appearance the benchmark
    # scores (appearance changes only rendered perception, i.e. the fine-tune)
    target_motions: tuple[str, ...] = TARGET_MOTIONS
    decoy_tiers: tuple[str, ...] = DECOY_TIERS
    appearances: tuple[str, ...] = APPEARANCE_MODES
    # train under `LearnedFollower`'s soft start and acceleration limit (`ShapedAction`), as the policy will fly
    action_shaping: bool = True
    # the policy's reach as a residual of the scripted follower (`trade_gym.agents.residual`: the env flies
    # clip(scripted + residual_scale x policy, -1, 1), the shaping on the policy's part); None: the policy flies alone
    residual_scale: float | None = None
    # the action axes the residual corrects (`trade_gym.agents.residual.HORIZONTAL_AXES` says why not the height)
    residual_axes: tuple[str, ...] = HORIZONTAL_AXES
    # after `total_steps`, PPO/SAC continues `finetune_steps` more steps with `finetune_env_kwargs` on top of
    # `env_kwargs` (e.g. the TRADE stack itself at a small camera: its losses, which the oracle does not have)
    finetune_steps: int = 100_000
    finetune_env_kwargs: tuple[tuple[str, Any], ...] = (("perception", "trade"), ("camera_size", 128))
    hidden_units: tuple[int, ...] = (64, 64)
    learning_rate: float = 1e-4
    n_steps_per_env: int = 4096  # PPO rollout length per env
    batch_size: int = 256
    n_epochs: int = 10
    gamma: float = 0.98
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    # PPO exploration: generalized state-dependent exploration (gSDE), noise eps = latent(x) W with W drawn
    # every `sde_sample_freq` steps, so it is smooth in time. White per-step noise barely moves a drone
    # whose velocity loop low-passes it, and the policy gradient then drowns in noise.
    use_sde: bool = True
    sde_sample_freq: int = 8
    log_std_init: float = -3.0  # of W entries: action noise std ~0.2 (reported as exploration_std)
    sac_buffer_size: int = 300_000  # SAC replay buffer [transitions]
    sac_learning_starts: int = 5_000  # SAC: random-action steps before the first update
    sac_gradient_steps: int = 1  # SAC: updates per vector-env step (n_envs transitions)
    # PPO only: clone the scripted follower first (None: start from scratch), then train the critic alone
    # for `critic_warmup_steps` so the first policy updates use sensible advantages.
    warm_start: WarmStartConfig | None = WarmStartConfig()
    critic_warmup_steps: int = 20_000
    torch_threads: int = 1
    progress_bar: bool = True
    tensorboard_dir: str | None = None
    checkpoint_every_steps: int = 100_000  # save checkpoints/model_<steps>.zip this often (0: never)
    verbose: int = 0  # SB3 logging to stdout (1: rollout/train statistics every update)

    def __post_init__(self) -> None:
        c = "TrainConfig"
        check_choice(f"{c}.algo", self.algo, ALGOS)
        for name in ("total_steps", "n_envs", "n_workers", "n_steps_per_env", "batch_size", "n_epochs",
                     "torch_threads", "sde_sample_freq",
                     "sac_buffer_size", "sac_learning_starts", "sac_gradient_steps"):
            value = getattr(self, name)
            require(is_int_at_least(value, 1, numpy_ints=False), f"{c}.{name}", value, "an integer >= 1")
        require(bool(self.scenes) and all(s in SCENE_NAMES for s in self.scenes), f"{c}.scenes", self.scenes,
                f"a non-empty subset of {SCENE_NAMES}")
        for name in ("episode_duration_s", "learning_rate", "clip_range"):
            value = getattr(self, name)
            require(np.isfinite(value) and value > 0, f"{c}.{name}", value, "> 0")
        for name in ("gamma", "gae_lambda"):
            require(0.0 < getattr(self, name) <= 1.0, f"{c}.{name}", getattr(self, name), "in (0, 1]")
        require(np.isfinite(self.ent_coef) and self.ent_coef >= 0, f"{c}.ent_coef", self.ent_coef, ">= 0")
        if self.warm_start is not None and self.algo != "ppo":
            raise ValueError(f"TrainConfig.warm_start needs algo='ppo', got algo={self.algo!r}")
        if self.critic_warmup_steps < 0 or (self.warm_start is not None
                                            and self.critic_warmup_steps >= self.total_steps):
            raise ValueError(f"TrainConfig.critic_warmup_steps must be in [0, total_steps), got "
                             f"{self.critic_warmup_steps!r}")
        if self.checkpoint_every_steps < 0 or self.verbose not in (0, 1, 2):
            raise ValueError(f"TrainConfig.checkpoint_every_steps must be >= 0 and verbose 0, 1 or 2, got "
                             f"{self.checkpoint_every_steps!r} and {self.verbose!r}")
        require(bool(self.hidden_units) and all(int(h) >= 1 for h in self.hidden_units), f"{c}.hidden_units",
                self.hidden_units, "positive layer widths")
        _ = self.scenarios  # ScenarioDraws raises on a bad choice
        require(is_int_at_least(self.finetune_steps, 0, numpy_ints=False), f"{c}.finetune_steps", self.finetune_steps,
                "an integer >= 0")
        require(isinstance(self.action_shaping, bool), f"{c}.action_shaping", self.action_shaping, "a bool")
        check_residual_axes(self.residual_axes, f"{c}.residual_axes")  # named even while no residual is set
        if self.residual_scale is not None:
            check_residual_scale(self.residual_scale, f"{c}.residual_scale")
            if self.warm_start is not None:  # the clone is of the scripted follower, which a residual adds to
                raise ValueError("TrainConfig.residual_scale needs warm_start=None (a residual starts at the "
                                 "scripted follower's actions already)")
        world_seed = dict(self.env_kwargs).get("world_seed")
        if world_seed is not None:  # training draws its worlds from the training split; a fixed one must be too
            require_training_worlds([world_seed], "TrainConfig.env_kwargs world_seed")

    @property
    def residual(self) -> Residual | None:
        """The residual the policy is trained as (`residual_scale`, `residual_axes`), None when it flies alone."""
        return None if self.residual_scale is None else Residual(self.residual_scale, self.residual_axes)

    @property
    def scenarios(self) -> ScenarioDraws:
        """The scenario drawn per training episode (`target_motions`, `decoy_tiers`, `appearances`)."""
        return ScenarioDraws(self.target_motions, self.decoy_tiers, self.appearances)


def make_training_env(config: TrainConfig, rank: int, flat: bool = True,
                       finetune: bool = False) -> Callable[[], gym.Env]:
    """Factory of worker `rank`'s env: scene- and scenario-randomised, the residual (`residual_scale`) and the action
    shaping (`action_shaping`), then
    (flat=True, for the learner) zero yaw, flat features and an episode monitor; flat=False keeps the Dict
    observation (for the scripted demonstrator). `finetune`: with `finetune_env_kwargs` on top."""
    from stable_baselines3.common.monitor import Monitor

    kwargs = dict(config.env_kwargs) | (dict(config.finetune_env_kwargs) if finetune else {})
    scenarios = config.scenarios

    def build() -> gym.Env:
        # SB3 seeds worker `rank`'s first reset with seed + rank, which fixes its whole stream of draws
        env: gym.Env = SceneRandomizedEnv(config.scenes, scenarios, episode_duration_s=config.episode_duration_s,
                                          **kwargs)
        if config.residual_scale is not None:
            env = ResidualAction(env, config.residual_scale, config.residual_axes)
        if config.action_shaping:
            env = ShapedAction(env)
        return Monitor(FlatObservation(ZeroYawAction(env))) if flat else env

    return build


def _vec_env(config: TrainConfig, flat: bool, seed: int, finetune: bool = False):
    from stable_baselines3.common.vec_env import DummyVecEnv

    from trade_gym.agents.vec_env import GroupedSubprocVecEnv

    fns = [make_training_env(config, rank, flat, finetune) for rank in range(config.n_envs)]
    workers = min(config.n_workers, config.n_envs)
    vec_env = GroupedSubprocVecEnv(fns, workers) if workers > 1 else DummyVecEnv(fns)
    vec_env.seed(seed)
    return vec_env


def policy_metadata(config: TrainConfig) -> dict[str, str] | None:
    """The policy file's metadata entries: a residual's (`Residual.metadata`), else none."""
    residual = config.residual
    return None if residual is None else residual.metadata()


def _progress_bar_available() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True


def build_model(config: TrainConfig, vec_env):
    """The SB3 model named by `config.algo` on `vec_env`, seeded."""
    from stable_baselines3 import PPO, SAC

    policy_kwargs = {"net_arch": list(config.hidden_units)}
    common: dict[str, Any] = dict(learning_rate=config.learning_rate, gamma=config.gamma, seed=config.seed, device="cpu",
                  tensorboard_log=config.tensorboard_dir, verbose=config.verbose)
    if config.algo == "ppo":
        return PPO("MlpPolicy", vec_env, n_steps=config.n_steps_per_env, batch_size=config.batch_size,
                   n_epochs=config.n_epochs, gae_lambda=config.gae_lambda, clip_range=config.clip_range,
                   ent_coef=config.ent_coef, use_sde=config.use_sde, sde_sample_freq=config.sde_sample_freq,
                   policy_kwargs={**policy_kwargs, "log_std_init": config.log_std_init},
                   **common)
    return SAC("MlpPolicy", vec_env, batch_size=config.batch_size, buffer_size=config.sac_buffer_size,
               learning_starts=config.sac_learning_starts, gradient_steps=config.sac_gradient_steps,
               policy_kwargs=policy_kwargs, **common)


def warm_start(model, config: TrainConfig) -> dict:
    """Clone the scripted follower into `model` (demonstrations on their own seeds); returns the fit record."""
    from trade_gym.agents.warm_start import warm_start_ppo

    if config.warm_start is None:
        raise ValueError("warm_start needs TrainConfig.warm_start (the demonstration settings)")
    demo_env = _vec_env(config, flat=False, seed=config.seed + DEMO_SEED_OFFSET)
    try:
        return warm_start_ppo(model.policy, demo_env, config.warm_start, config.seed, config.gamma,
                              config.log_std_init)
    finally:
        demo_env.close()


def _learn(model, config: TrainConfig, callback) -> None:
    """PPO/SAC learning for `total_steps`; with a warm start, the actor is frozen for the critic warm-up."""
    from trade_gym.agents.warm_start import actor_parameters

    bar = config.progress_bar and _progress_bar_available()
    warmup = config.critic_warmup_steps if config.warm_start is not None else 0
    if warmup:
        for p in actor_parameters(model.policy):
            p.requires_grad_(False)  # Adam skips parameters without gradients
        model.learn(total_timesteps=warmup, callback=callback, progress_bar=bar)
        for p in actor_parameters(model.policy):
            p.requires_grad_(True)
    model.learn(total_timesteps=config.total_steps - model.num_timesteps, callback=callback, progress_bar=bar,
                reset_num_timesteps=not warmup)


def _callbacks(config: TrainConfig, out: Path):
    """The learning curve (learning_curve.csv: every training episode's return and distance) and checkpoints."""
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    callbacks = [curve_callback(out)]
    if config.checkpoint_every_steps:
        every_call = max(config.checkpoint_every_steps // config.n_envs, 1)  # one call steps every env
        callbacks.append(CheckpointCallback(every_call, str(out / "checkpoints"), name_prefix="model"))
    return CallbackList(callbacks)


def _finetune(model, config: TrainConfig, callback, out: Path) -> dict:
    """Continue `model` for `finetune_steps` on the fine-tune envs (the policy before it: policy_before_finetune.onnx);
    returns the stage's record."""
    from trade_gym.agents.export import export_onnx

    before = export_onnx(model, out / "policy_before_finetune.onnx", policy_metadata(config))
    start_steps, start = model.num_timesteps, time.perf_counter()
    # its own seed stream (seed + 1): the fine-tune's worlds and scenarios are not a replay of the first ones
    vec_env = _vec_env(config, flat=True, seed=config.seed + 1, finetune=True)
    try:
        model.set_env(vec_env)
        model.learn(total_timesteps=config.finetune_steps, callback=callback, reset_num_timesteps=False,
                    progress_bar=config.progress_bar and _progress_bar_available())
    finally:
        vec_env.close()
    return {"steps": int(model.num_timesteps - start_steps), "wall_time_s": round(time.perf_counter() - start, 1),
            "onnx_sha256_before": before}


def train(config: TrainConfig, out_dir: str | Path) -> dict:
    """(Warm-start,) train, save `model.zip`, export `policy.onnx`, write and return `train_record.json`."""
    import torch

    from trade_gym.agents.export import export_onnx, max_export_error

    if config.tensorboard_dir is not None:
        try:
            import tensorboard  # noqa: F401
        except ImportError as exc:
            raise RuntimeError("--tensorboard needs the tensorboard package (pip install tensorboard)") from exc
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(config.torch_threads)
    start = time.perf_counter()
    vec_env = _vec_env(config, flat=True, seed=config.seed)
    try:
        model = build_model(config, vec_env)
        clone = {}
        if config.warm_start is not None:
            clone = warm_start(model, config)
            # the clone alone, for comparison with the fine-tuned policy
            clone["onnx_sha256"] = export_onnx(model, out / "policy_warm_start.onnx")
        callback = _callbacks(config, out)
        _learn(model, config, callback)
    finally:
        vec_env.close()
    finetune = {}
    if config.finetune_steps:
        finetune = _finetune(model, config, callback, out)
    wall_s = time.perf_counter() - start
    model.save(out / "model.zip")
    digest = export_onnx(model, out / "policy.onnx", policy_metadata(config))
    record = {
        "config": asdict(config),
        "steps": int(model.num_timesteps),
        "warm_start": clone,
        "finetune": finetune,
        "wall_time_s": round(wall_s, 1),
        "steps_per_s": round(model.num_timesteps / wall_s, 1),
        "onnx_sha256": digest,
        "onnx_bytes": (out / "policy.onnx").stat().st_size,
        "max_abs_onnx_minus_sb3": max_export_error(model, out / "policy.onnx", np.random.default_rng(config.seed)),
        "torch_version": torch.__version__,
    }
    (out / "train_record.json").write_text(json.dumps(record, indent=2))
    return record


def _parse_env_kwarg(text: str) -> tuple[str, Any]:
    """"key=value" with a JSON value (numbers, true/false, strings in quotes) or a bare string."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"--env expects key=value, got {text!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def hyperparams_path(algo: str) -> Path:
    """The published hyperparameters of `algo` (agents/hyperparams/<algo>.yml)."""
    return HYPERPARAMS_DIR / f"{algo}.yml"


def load_train_config(path: str | Path) -> TrainConfig:
    """The TrainConfig a hyperparameter file describes; it must name every TrainConfig field, and only those."""
    import yaml

    path = Path(path)
    data = yaml.safe_load(path.read_text())
    names = [f.name for f in fields(TrainConfig)]
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of TrainConfig fields, got {type(data).__name__}")
    unknown, missing = sorted(set(data) - set(names)), [n for n in names if n not in data]
    if unknown or missing:
        raise ValueError(f"{path}: every TrainConfig field, and only those, must be given; unknown {unknown}, "
                         f"missing {missing}")
    values = dict(data)
    values["scenes"], values["hidden_units"] = tuple(data["scenes"]), tuple(data["hidden_units"])
    for name in ("target_motions", "decoy_tiers", "appearances", "residual_axes"):
        values[name] = tuple(data[name])
    for name in ("env_kwargs", "finetune_env_kwargs"):
        values[name] = tuple(dict(data[name] or {}).items())
    if data["warm_start"] is not None:
        values["warm_start"] = WarmStartConfig(**data["warm_start"])
    return TrainConfig(**values)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description="Train a learned follower (SB3) on the oracle perception and the "
                                                 "env's own reward, and export it to ONNX. Every setting comes "
                                                 "from a hyperparameter file; the flags override single values.")
    parser.add_argument("--out", type=Path, required=True, help="directory for model.zip, policy.onnx, record")
    parser.add_argument("--algo", choices=ALGOS, default=None,
                        help="picks agents/hyperparams/<algo>.yml (default ppo); must match --hyperparams' algo")
    parser.add_argument("--hyperparams", type=Path, default=None, metavar="YML",
                        help="hyperparameter file (default: agents/hyperparams/<algo>.yml)")
    parser.add_argument("--steps", type=int, default=None, help="environment steps in total")
    parser.add_argument("--n-envs", type=int, default=None, help="training envs in total")
    parser.add_argument("--n-workers", type=int, default=None, help="processes the envs step in")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--scenes", nargs="+", default=None, choices=SCENE_NAMES)
    parser.add_argument("--episode-duration-s", type=float, default=None)
    parser.add_argument("--env", type=_parse_env_kwarg, action="append", default=[], metavar="KEY=VALUE",
                        help="extra gym.make kwarg (repeatable), e.g. --env oracle_dropout_prob=0.1")
    parser.add_argument("--finetune-steps", type=int, default=None, help="steps on finetune_env_kwargs after training")
    parser.add_argument("--tensorboard", default=None, metavar="DIR", help="write TensorBoard logs to DIR")
    parser.add_argument("--residual-scale", type=float, default=None, metavar="SCALE",
                        help="train a residual of the scripted follower with this reach (needs --from-scratch)")
    parser.add_argument("--residual-axes", nargs="+", default=None, choices=POLICY_AXES, metavar="AXIS",
                        help=f"the action axes the residual corrects, of {' '.join(POLICY_AXES)}")
    parser.add_argument("--from-scratch", action="store_true",
                        help="no warm start and no critic warm-up: PPO from a random initialisation")
    parser.add_argument("--demo-steps", type=int, default=None, help="scripted demonstrations for the warm start")
    parser.add_argument("--checkpoint-every", type=int, default=None, metavar="STEPS", help="save checkpoints")
    parser.add_argument("--verbose", type=int, default=None, choices=(0, 1, 2), help="SB3 log level")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The hyperparameter file's TrainConfig with the flags given applied on top."""
    config = load_train_config(args.hyperparams or hyperparams_path(args.algo or DEFAULT_ALGO))
    if args.algo is not None and config.algo != args.algo:
        raise ValueError(f"--algo {args.algo} contradicts {args.hyperparams} (algo: {config.algo})")
    overrides = {"total_steps": args.steps, "n_envs": args.n_envs, "n_workers": args.n_workers, "seed": args.seed,
                 "scenes": tuple(args.scenes) if args.scenes else None,
                 "episode_duration_s": args.episode_duration_s, "tensorboard_dir": args.tensorboard,
                 "checkpoint_every_steps": args.checkpoint_every, "verbose": args.verbose,
                 "finetune_steps": args.finetune_steps, "residual_scale": args.residual_scale,
                 "residual_axes": tuple(args.residual_axes) if args.residual_axes else None}
    changes = {k: v for k, v in overrides.items() if v is not None}
    if args.env:
        changes["env_kwargs"] = tuple((dict(config.env_kwargs) | dict(args.env)).items())
    if args.no_progress:
        changes["progress_bar"] = False
    if args.demo_steps is not None and config.warm_start is not None:
        changes["warm_start"] = replace(config.warm_start, demo_steps=args.demo_steps)
    if args.from_scratch:
        changes |= {"warm_start": None, "critic_warmup_steps": 0}
    return replace(config, **changes)


def main(argv: list[str] | None = None) -> None:
    args = _parser().parse_args(argv)
    record = train(config_from_args(args), args.out)
    summary = ("steps", "warm_start", "wall_time_s", "steps_per_s", "onnx_sha256", "onnx_bytes",
               "max_abs_onnx_minus_sb3")
    print(json.dumps({k: record[k] for k in summary}, indent=2))


if __name__ == "__main__":
    main()
