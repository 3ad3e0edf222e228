"""rl-zoo3's hyperparameter file (agents/hyperparams/rl_zoo3/ppo.yml): rendered from the trainer's
agents/hyperparams/ppo.yml and current, holding its every shared value, its wrappers around `gym.make`'s env giving
the training env's episodes; and (slow, with rl-zoo3 installed) `rl_zoo3.train` with it training the trainer's model
bit for bit, which SB3 and rl-zoo3's `enjoy` load."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import yaml
from stable_baselines3.common.monitor import Monitor

import trade_gym
from trade_gym.agents import zoo
from trade_gym.agents.train import TrainConfig, hyperparams_path, load_train_config, make_training_env, train

SHIPPED = zoo.zoo_path("ppo")


def _entry(path: Path = SHIPPED) -> dict[str, Any]:
    (env_id, entry), = yaml.safe_load(path.read_text()).items()
    assert env_id == trade_gym.ENV_ID
    return entry


def _zoo_env(entry: dict[str, Any]) -> gym.Env:
    """The env rl-zoo3 trains on with `entry`: gym.make's env, a Monitor, then each `env_wrapper` in order (as
    rl_zoo3.utils.get_wrapper_class applies them: "module.Class" or {"module.Class": kwargs})."""
    env: gym.Env = Monitor(gym.make(trade_gym.ENV_ID, **entry["env_kwargs"]))
    for wrapper in entry["env_wrapper"]:
        name, kwargs = next(iter(wrapper.items())) if isinstance(wrapper, dict) else (wrapper, {})
        module, _, cls = name.rpartition(".")
        env = getattr(importlib.import_module(module), cls)(env, **kwargs)
    return env


def test_shipped_zoo_file_is_current_and_check_fails_on_a_stale_one(tmp_path, capsys):
    assert zoo.main(["--check"]) == 0
    stale = tmp_path / "ppo.yml"
    stale.write_text(SHIPPED.read_text().replace("gamma: 0.98", "gamma: 0.99"))
    assert zoo.main(["--check", "--out", str(stale)]) == 1
    assert f"{stale} is stale" in capsys.readouterr().out
    assert zoo.main(["--out", str(stale)]) == 0 and zoo.main(["--check", "--out", str(stale)]) == 0
    assert _entry(stale) == _entry()  # the header's command names the file written


def test_zoo_file_holds_every_value_it_shares_with_the_trainers_file():
    config, entry = load_train_config(hyperparams_path("ppo")), _entry()
    assert entry == {
        "policy": "MlpPolicy", "n_envs": config.n_envs, "n_timesteps": config.total_steps,
        "learning_rate": config.learning_rate, "n_steps": config.n_steps_per_env, "batch_size": config.batch_size,
        "n_epochs": config.n_epochs, "gamma": config.gamma, "gae_lambda": config.gae_lambda,
        "clip_range": config.clip_range, "ent_coef": config.ent_coef, "use_sde": config.use_sde,
        "sde_sample_freq": config.sde_sample_freq,
        "policy_kwargs": {"net_arch": list(config.hidden_units), "log_std_init": config.log_std_init},
        "env_wrapper": [
            {"trade_gym.agents.training_env.EpisodeDraws": {
                "scenes": list(config.scenes), "target_motions": list(config.target_motions),
                "decoy_tiers": list(config.decoy_tiers), "appearances": list(config.appearances)}},
            *(["trade_gym.agents.action_shaping.ShapedAction"] if config.action_shaping else []),
            "trade_gym.agents.training_env.ZeroYawAction", "trade_gym.agents.obs_flatten.FlatObservation"],
        "env_kwargs": dict(config.env_kwargs) | {"episode_duration_s": config.episode_duration_s},
    }


def test_every_train_config_field_is_in_the_zoo_file_or_named_as_not():
    in_file = [name for _, name in zoo.PPO_FIELDS] + list(zoo.OTHER_FILE_FIELDS)
    assert sorted(in_file + list(zoo.NOT_IN_FILE)) == sorted(f.name for f in fields(TrainConfig))


def test_zoo_file_for_a_sac_config_raises_naming_the_algo():
    with pytest.raises(ValueError, match="'sac'"):
        zoo.zoo_hyperparams(load_train_config(hyperparams_path("sac")))


def test_zoo_wrappers_around_gym_make_fly_the_training_envs_episodes():
    """The zoo file's env (of a config with 0.5 s episodes, so 60 steps span several) and make_training_env's, on
    one seed: the same scenes, observations, rewards and episode ends."""
    config = replace(load_train_config(hyperparams_path("ppo")), episode_duration_s=0.5)
    ours, theirs = make_training_env(config, rank=0)(), _zoo_env(zoo.zoo_hyperparams(config))
    actions = np.random.default_rng(1).uniform(-1.0, 1.0, (60, 3)).astype(np.float32)
    scenes = set()
    try:
        assert ours.observation_space == theirs.observation_space and ours.action_space == theirs.action_space
        a, info_a = ours.reset(seed=0)
        b, info_b = theirs.reset(seed=0)
        np.testing.assert_array_equal(a, b)
        for action in actions:
            a, reward_a, *ends_a, info_a = ours.step(action)
            b, reward_b, *ends_b, info_b = theirs.step(action)
            np.testing.assert_array_equal(a, b)
            assert (reward_a, ends_a, info_a["scene"]) == (reward_b, ends_b, info_b["scene"])
            scenes.add(info_a["scene"])
            if any(ends_a):
                np.testing.assert_array_equal(ours.reset()[0], theirs.reset()[0])
        assert len(scenes) > 1
    finally:
        ours.close()
        theirs.close()


def _run(module: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    """`python -m module args` on this process's trade_gym (its folder first on PYTHONPATH)."""
    code_root = str(Path(trade_gym.__file__).parents[1])  # not resolved: a folder of links stays one
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([code_root, *filter(None, [os.environ.get("PYTHONPATH")])]))
    done = subprocess.run([sys.executable, "-m", module, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


@pytest.mark.slow
def test_rl_zoo3_trains_with_the_zoo_file_the_model_the_trainer_trains(tmp_path):
    """4096 steps, one env, seed 0 (~40 s): rl_zoo3.train with the shipped file saves a model whose parameters equal
    those of `trade_gym.agents.train --from-scratch --finetune-steps 0` on the same settings; SB3 loads it and it
    acts on the zoo env's observation; rl-zoo3's enjoy flies it."""
    pytest.importorskip("rl_zoo3", reason="rl-zoo3 is not installed: pip install -e '.[zoo]' (make test-slow does)")
    from stable_baselines3 import PPO

    steps, logs = 4096, tmp_path / "logs"
    zoo_args = ["--algo", "ppo", "--env", trade_gym.ENV_ID, "--gym-packages", "trade_gym", "--seed", "0",
                "--device", "cpu", "-f", str(logs)]
    _run("rl_zoo3.train", *zoo_args, "--conf-file", str(SHIPPED), "-n", str(steps), "--hyperparams", "n_envs:1",
         "--num-threads", "1", "--eval-freq", "-1", cwd=tmp_path)
    saved = logs / "ppo" / f"{trade_gym.ENV_ID}_1" / f"{trade_gym.ENV_ID}.zip"
    model = PPO.load(saved, device="cpu")

    config = replace(load_train_config(hyperparams_path("ppo")), total_steps=steps, n_envs=1, warm_start=None,
                     critic_warmup_steps=0, finetune_steps=0, checkpoint_every_steps=0, progress_bar=False)
    train(config, tmp_path / "trainer")
    reference = PPO.load(tmp_path / "trainer" / "model.zip", device="cpu")
    ours, theirs = reference.policy.state_dict(), model.policy.state_dict()
    assert ours.keys() == theirs.keys()
    for name in ours:
        assert np.array_equal(ours[name].numpy(), theirs[name].numpy()), name

    env = _zoo_env(_entry())
    try:
        action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    finally:
        env.close()
    assert action.shape == env.action_space.shape and np.all(np.abs(action) <= 1.0)
    enjoyed = _run("rl_zoo3.enjoy", *zoo_args, "--exp-id", "1", "-n", "50", "--no-render", cwd=tmp_path)
    assert f"Loading {saved}" in enjoyed.stdout
