"""trade-gym: a Gymnasium environment for vision-based UAV target following.

`import trade_gym` registers `TradeFollow-v0`.
"""

from trade_gym.quiet_import import import_pybullet_quietly

import_pybullet_quietly()  # before any module of the package imports pybullet: its banner is not ours to print

from gymnasium.envs.registration import register, registry  # noqa: E402

from trade_gym.config import CAMERA_RATE_HZ, EnvConfig  # noqa: E402

ENV_ID = "TradeFollow-v0"
DEFAULT_MAX_EPISODE_STEPS = int(EnvConfig().episode_duration_s * CAMERA_RATE_HZ)

if ENV_ID not in registry:
    register(
        id=ENV_ID,
        entry_point="trade_gym.env:TradeFollowEnv",
        max_episode_steps=DEFAULT_MAX_EPISODE_STEPS,
    )

__all__ = ["ENV_ID", "EnvConfig"]
