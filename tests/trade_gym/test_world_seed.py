"""`world_seed` fixes the procedural world (the sequence) while the reset seed drives the run's noise."""

from __future__ import annotations

import numpy as np
import pytest

from trade_gym.env import TradeFollowEnv


def _world_and_noise(env: TradeFollowEnv, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(start position and decoy centres, the first step's IMU observation) after reset(seed)."""
    env.reset(seed=seed)
    layout = [env.world.drone_start()[0]] + [env.world.vehicle_pose(d, 0.0)[0] for d in env.world.decoys]
    obs, *_ = env.step(np.zeros(4, np.float32))
    return np.concatenate(layout), obs["imu"].copy()


def test_world_seed_same_world_for_any_reset_seed_but_different_noise():
    env = TradeFollowEnv(scene="desert", perception="oracle", world_seed=7)
    try:
        world_a, imu_a = _world_and_noise(env, seed=0)
        world_b, imu_b = _world_and_noise(env, seed=1)
    finally:
        env.close()
    np.testing.assert_array_equal(world_a, world_b)
    assert not np.array_equal(imu_a, imu_b)


def test_world_seed_none_reset_seed_draws_the_world():
    env = TradeFollowEnv(scene="desert", perception="oracle")
    try:
        world_a, _ = _world_and_noise(env, seed=0)
        world_b, _ = _world_and_noise(env, seed=1)
    finally:
        env.close()
    assert not np.array_equal(world_a, world_b)


@pytest.mark.parametrize("value", [-1, 1.5, True, "3"])
def test_world_seed_invalid_raises_naming_it(value):
    with pytest.raises(ValueError, match="world_seed"):
        TradeFollowEnv(scene="desert", perception="oracle", world_seed=value)
