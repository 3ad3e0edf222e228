"""Warm start of a PPO policy from the scripted follower (training only; imports torch): the actor is
cloned from its actions, the critic regressed on the demonstrations' discounted returns.

Demonstrations are flown with perturbed actions (DART: the executed action is the scripted one plus
Gaussian noise, the recorded label the clean scripted action), so the clone sees recovering states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch

from trade_gym.agents.obs_flatten import flatten_observation
from trade_gym.agents.scripted import ScriptedFollower
from trade.validation import is_int_at_least, require

FloatArray = npt.NDArray[np.float32]
CLONED_DIMS = 3  # forward, left, up; yaw stays zero
RETURN_TAIL = 0.01  # returns cut closer than gamma^k = 1 % before their end are not used for the critic


@dataclass(frozen=True)
class Demonstrations:
    """features (N, F), scripted labels (N, 3), discounted returns (N,) and which returns are usable (N,):
    those not cut short by the end of the collection or a time-limit truncation."""

    features: FloatArray
    labels: FloatArray
    returns: FloatArray
    return_valid: npt.NDArray[np.bool_]


@dataclass(frozen=True)
class WarmStartConfig:
    """Demonstration budget, DART noise [action units], and the regression's schedule."""

    demo_steps: int = 40_000
    action_noise_std: float = 0.2
    epochs: int = 30
    batch_size: int = 256
    learning_rate: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("demo_steps", "epochs", "batch_size"):
            value = getattr(self, name)
            require(is_int_at_least(value, 1, numpy_ints=False), f"WarmStartConfig.{name}", value, "an integer >= 1")
        require(np.isfinite(self.action_noise_std) and self.action_noise_std >= 0, "WarmStartConfig.action_noise_std",
                self.action_noise_std, ">= 0")
        require(np.isfinite(self.learning_rate) and self.learning_rate > 0, "WarmStartConfig.learning_rate",
                self.learning_rate, "> 0")


def collect_demonstrations(vec_env, config: WarmStartConfig, rng: np.random.Generator,
                           gamma: float) -> Demonstrations:
    """Fly the scripted follower on `vec_env` (Dict observations, 4-D actions) for `demo_steps` steps in
    total, recording features, the scripted (forward, left, up) labels and the training rewards."""
    expert = ScriptedFollower()
    n_envs = vec_env.num_envs
    obs = vec_env.reset()
    starts = np.ones(n_envs, bool)
    features, labels, rewards, dones, truncated = [], [], [], [], []
    for _ in range(-(-config.demo_steps // n_envs)):
        action, _ = expert.predict(obs, episode_start=starts)
        features.append(flatten_observation(obs)[0])
        labels.append(action[:, :CLONED_DIMS])
        # a_executed = clip(a_expert + N(0, sigma^2)), yaw rate 0
        noisy = action + rng.normal(0.0, config.action_noise_std, action.shape).astype(np.float32)
        noisy[:, CLONED_DIMS:] = 0.0
        obs, reward, done, infos = vec_env.step(np.clip(noisy, -1.0, 1.0))
        rewards.append(reward)
        dones.append(done)
        truncated.append([bool(i.get("TimeLimit.truncated", False)) for i in infos])
        starts = done
    returns, valid = discounted_returns(np.array(rewards), np.array(dones), np.array(truncated), gamma)
    # (T, E) arrays in step order -> (T * E,) samples in the same order as the features
    return Demonstrations(np.concatenate(features), np.concatenate(labels), returns.reshape(-1).astype(np.float32),
                          valid.reshape(-1))


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, truncated: np.ndarray,
                       gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """G_t = r_t + gamma G_{t+1} (0 after a done) per env column of (T, E) arrays; a return is valid when
    no truncation or collection end lies within the horizon where gamma^k still exceeds RETURN_TAIL."""
    horizon = int(np.ceil(np.log(RETURN_TAIL) / np.log(gamma))) if gamma < 1.0 else len(rewards)
    returns = np.zeros_like(rewards, dtype=np.float64)
    valid = np.zeros_like(rewards, dtype=bool)
    g = np.zeros(rewards.shape[1])
    steps_to_cut = np.full(rewards.shape[1], 0)  # steps until the episode is cut (collection end or truncation)
    for t in range(len(rewards) - 1, -1, -1):
        cut = truncated[t]
        steps_to_cut = np.where(dones[t] & ~cut, horizon, np.where(cut, 0, steps_to_cut + 1))
        g = rewards[t] + gamma * g * ~dones[t]
        returns[t], valid[t] = g, steps_to_cut >= horizon
    return returns, valid


def actor_parameters(policy) -> list[torch.nn.Parameter]:
    """The parameters of a PPO policy's action distribution (actor MLP, mean head, log std)."""
    return [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(), policy.log_std]


def _regress(module_fn, params: list, x: torch.Tensor, y: torch.Tensor, config: WarmStartConfig, seed: int) -> None:
    """Minibatch Adam on L = mean ||module_fn(x) - y||^2 for `config.epochs` epochs."""
    generator = torch.Generator().manual_seed(seed)
    optimiser = torch.optim.Adam(params, lr=config.learning_rate)
    for _ in range(config.epochs):
        order = torch.randperm(len(x), generator=generator)
        for lo in range(0, len(x), config.batch_size):
            idx = order[lo:lo + config.batch_size]
            loss = torch.mean((module_fn(x[idx]) - y[idx]) ** 2)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()


def clone_into_policy(policy, demos: Demonstrations, config: WarmStartConfig, seed: int) -> dict[str, float]:
    """Fit the PPO actor's mean to the labels and the critic to the valid discounted returns (minibatch MSE);
    returns the final action MSE and the critic's explained variance on those returns."""
    x = torch.as_tensor(demos.features)
    y = torch.as_tensor(np.clip(demos.labels, -1.0, 1.0))

    def mean_action(batch: torch.Tensor) -> torch.Tensor:
        latent = policy.mlp_extractor.forward_actor(policy.extract_features(batch, policy.pi_features_extractor))
        return policy.action_net(latent)

    def value(batch: torch.Tensor) -> torch.Tensor:
        return policy.predict_values(batch)[:, 0]

    policy.train()
    _regress(mean_action, [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()],
             x, y, config, seed)
    keep = torch.as_tensor(demos.return_valid)
    g = torch.as_tensor(demos.returns)[keep]
    with torch.no_grad():  # start the value head at the mean return: the scale Adam would take long to reach
        policy.value_net.bias.fill_(float(g.mean()))
    _regress(value, [*policy.mlp_extractor.value_net.parameters(), *policy.value_net.parameters()],
             x[keep], g, config, seed)
    policy.eval()
    with torch.no_grad():
        mse = float(torch.mean((torch.clamp(mean_action(x), -1.0, 1.0) - y) ** 2))
        # explained variance = 1 - Var(G - V) / Var(G)
        ev = float(1.0 - torch.var(g - value(x[keep])) / torch.var(g))
    return {"clone_mse": mse, "critic_explained_variance": ev}


def exploration_std(policy, features: FloatArray) -> float:
    """Mean over states and action dims of the policy's action noise std (gSDE: sqrt(latent^2 . sigma^2))."""
    with torch.no_grad():
        return float(policy.get_distribution(torch.as_tensor(features)).distribution.stddev.mean())


def warm_start_ppo(policy, demo_env, config: WarmStartConfig, seed: int, gamma: float,
                   log_std_init: float) -> dict:
    """Collect demonstrations on `demo_env`, clone them into `policy`, reset its log std; returns the record."""
    demos = collect_demonstrations(demo_env, config, np.random.default_rng(seed), gamma)
    fit = clone_into_policy(policy, demos, config, seed)
    with torch.no_grad():
        policy.log_std.fill_(log_std_init)
    fit["exploration_std"] = exploration_std(policy, demos.features)
    return {"demo_steps": int(len(demos.features)), **{k: round(v, 6) for k, v in fit.items()}}
