"""GroupedSubprocVecEnv: several envs per worker process, each stepping exactly as under SB3's SubprocVecEnv."""

from __future__ import annotations

import functools

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import SubprocVecEnv

from trade_gym.agents.vec_env import GroupedSubprocVecEnv, worker_groups

N_ENVS = 5
STEPS = 60  # CartPole's random-action episodes last 10-40 steps: every env auto-resets on the way


def _cartpole() -> gym.Env:
    return Monitor(gym.make("CartPole-v1"))


def _rollout(vec_env, seed: int) -> list:
    """Observations, rewards, dones and the infos' terminal observations of `STEPS` seeded random steps."""
    vec_env.seed(seed)
    vec_env.action_space.seed(seed)
    trace = [vec_env.reset()]
    for _ in range(STEPS):
        obs, rewards, dones, infos = vec_env.step(np.array([vec_env.action_space.sample() for _ in range(N_ENVS)]))
        trace += [obs, rewards, dones, [info.get("terminal_observation") for info in infos],
                  [info.get("TimeLimit.truncated") for info in infos]]
    return trace


@pytest.fixture(scope="module")
def grouped():
    vec_env = GroupedSubprocVecEnv([_cartpole] * N_ENVS, n_workers=2)
    yield vec_env
    vec_env.close()


def test_worker_groups_are_contiguous_and_balanced():
    assert worker_groups(5, 2) == [range(0, 2), range(2, 5)]
    assert worker_groups(8, 2) == [range(0, 4), range(4, 8)]
    assert worker_groups(3, 3) == [range(0, 1), range(1, 2), range(2, 3)]


def test_grouped_envs_step_as_subprocvecenv_does(grouped):
    reference = SubprocVecEnv([_cartpole] * N_ENVS, start_method="spawn")
    try:
        expected = _rollout(reference, seed=7)
    finally:
        reference.close()
    got = _rollout(grouped, seed=7)
    assert any(d.any() for d in got[3::5])  # some env finished and auto-reset
    for e, g in zip(expected, got, strict=True):
        if isinstance(e, np.ndarray):
            np.testing.assert_array_equal(g, e)
        else:
            assert [None if x is None else np.asarray(x).tolist() for x in g] == \
                   [None if x is None else np.asarray(x).tolist() for x in e]


def test_attributes_and_methods_reach_the_right_envs(grouped):
    grouped.set_attr("tag", "b", indices=[1, 3])
    grouped.set_attr("tag", "a", indices=[0, 2, 4])
    assert grouped.get_attr("tag") == ["a", "b", "a", "b", "a"]
    assert grouped.get_attr("tag", indices=[4, 1]) == ["a", "b"]
    assert grouped.has_attr("tag") and not grouped.has_attr("no_such_attribute")
    assert grouped.env_is_wrapped(Monitor) == [True] * N_ENVS
    assert grouped.env_method("get_episode_rewards", indices=2) == [grouped.get_attr("episode_returns", [2])[0]]


@pytest.mark.parametrize("n_workers", [0, N_ENVS + 1])
def test_bad_worker_count_is_named(n_workers):
    with pytest.raises(ValueError, match="n_workers"):
        GroupedSubprocVecEnv([functools.partial(gym.make, "CartPole-v1")] * N_ENVS, n_workers=n_workers)
