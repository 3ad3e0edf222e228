"""The learned follower's action shaping: a soft start and gentle acceleration before the 3D fix.

One implementation, used where the policy runs (`LearnedFollower`) and where it trains (`ShapedAction`, inside the
training env), so the policy learns under the same shaping it flies with.

Soft start: for the first `soft_start_s` of an episode the policy's action is scaled by the fraction of that time
elapsed (0 on the episode's first frame, 1 from `soft_start_s` on). The camera is fixed to the drone's body, so a
sudden command tilts the drone and moves the image by tens of pixels within a few frames, and a correlation-filter
tracker initialised on the first frame, before its first 3D fix (no trajectory guidance yet), loses a target moved
that far.

Gentle acceleration before the 3D fix: until the observation holds the target's 3D position, the horizontal
setpoint (forward, left) may change by at most `max_accel_unfixed_mps2` per second from the last frame's (zero on
an episode's first frame). Until that fix TRADE's tracker has no trajectory prediction and searches where constant
image velocity puts the target; the camera turns with the drone's tilt, so a hard brake or swerve turns the image
faster than that guess follows and the target leaves the search window. After the fix the trajectory prediction
guides the window and the setpoint is not limited: limiting it all the time made the follower lag behind the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from trade.validation import is_finite_number, is_positive_number, require
from trade_gym.action import ACTION_DIM, DEFAULT_ACTION_SCALE
from trade_gym.config import CAMERA_RATE_HZ

# Length of the soft start [s]; set on development worlds 100-119 of the city, where the policy without it lost the
# target in its first frames on 6 of 20 worlds under full TRADE (the model card).
SOFT_START_S = 1.0
# Limit on the horizontal setpoint's change before the 3D fix [m/s^2]; set on development worlds 100-119 of the
# city and the mountain (the model card): with it the city's early losses went away and the mountain was unchanged;
# the same limit held for the whole episode made the follower lag (mountain tracked 0.998 -> 0.905).
MAX_ACCEL_UNFIXED_MPS2 = 6.0
# The setpoint per unit action the policy is trained with [m/s] (the env's default quadrotor)
POLICY_SPEED_SCALE_MPS = DEFAULT_ACTION_SCALE.horizontal_mps
HORIZONTAL = slice(0, 2)  # forward, left in the action


@dataclass(frozen=True)
class ActionShapingConfig:
    """`soft_start_s=0` turns the soft start off, `max_accel_unfixed_mps2=math.inf` the acceleration limit."""

    soft_start_s: float = SOFT_START_S  # [s]
    max_accel_unfixed_mps2: float = MAX_ACCEL_UNFIXED_MPS2  # [m/s^2]

    def __post_init__(self) -> None:
        require(is_finite_number(self.soft_start_s) and self.soft_start_s >= 0.0, "soft_start_s", self.soft_start_s,
                ">= 0")
        require(self.max_accel_unfixed_mps2 == math.inf or is_positive_number(self.max_accel_unfixed_mps2),
                "max_accel_unfixed_mps2", self.max_accel_unfixed_mps2, "> 0 (math.inf: no limit)")

    @property
    def max_step(self) -> float:
        """The acceleration limit as a step of the horizontal action per frame [action units]."""
        return self.max_accel_unfixed_mps2 / CAMERA_RATE_HZ / POLICY_SPEED_SCALE_MPS


class ActionShaping:
    """Shapes the actions of N envs: per env the frames since its episode's start and its last shaped action.

    `shape(action, position_known, episode_start)`: (N, ACTION_DIM) actions in, shaped actions out; envs whose
    `episode_start` is True (and all of them on the first call, after `reset()` or when N changes) start anew."""

    def __init__(self, config: ActionShapingConfig = ActionShapingConfig()) -> None:
        self.config = config
        self._frames: np.ndarray | None = None  # (N,) frames since each episode's start
        self._last_action: np.ndarray | None = None  # (N, ACTION_DIM) the action returned on the last frame

    def reset(self) -> None:
        """Forget the episodes' frame counts and last actions: the next call starts new episodes."""
        self._frames = None
        self._last_action = None

    def shape(self, action: np.ndarray, position_known: np.ndarray,
              episode_start: np.ndarray | None = None) -> np.ndarray:
        frames, last_action = self._start_episodes(len(action), episode_start)
        scaled = np.asarray(action, dtype=np.float32) * self._soft_start_scale(frames)[:, None]
        return self._limit_unfixed_accel(scaled, last_action, np.asarray(position_known, dtype=bool).reshape(-1))

    def _start_episodes(self, n: int, episode_start: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        frames, last_action = self._frames, self._last_action
        if frames is None or last_action is None or len(frames) != n:
            frames = self._frames = np.zeros(n, dtype=np.int64)
            last_action = self._last_action = np.zeros((n, ACTION_DIM), dtype=np.float32)
        if episode_start is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1)
            frames[starts] = 0
            last_action[starts] = 0.0
        return frames, last_action

    def _limit_unfixed_accel(self, action: np.ndarray, last_action: np.ndarray,
                             position_known: np.ndarray) -> np.ndarray:
        """(n, ACTION_DIM) actions whose horizontal setpoint, where the 3D position is not known yet, moved from the
        `last_action`'s by at most `config.max_step`; remembered as the last actions."""
        max_step = self.config.max_step
        step = action[:, HORIZONTAL] - last_action[:, HORIZONTAL]
        norm = np.linalg.norm(step, axis=1)
        over = ~position_known & (norm > max_step)  # the envs whose step is cut to max_step (same direction)
        limited = action.copy()
        limited[over, HORIZONTAL] = last_action[over, HORIZONTAL] + step[over] * (max_step / norm[over])[:, None]
        self._last_action = limited
        return limited.copy()

    def _soft_start_scale(self, frames: np.ndarray) -> np.ndarray:
        """(n,) float32 action scale of this frame per env from its `frames` count, then one frame more counted
        (in place)."""
        ramp_frames = self.config.soft_start_s * CAMERA_RATE_HZ
        scale = np.ones(len(frames)) if ramp_frames == 0 else np.minimum(1.0, frames / ramp_frames)
        frames += 1
        return scale.astype(np.float32)


def position_known(observation: dict[str, np.ndarray]) -> bool:
    """Whether a single Dict observation holds the target's 3D position (the flat features' derived flag)."""
    return bool(np.any(np.asarray(observation["target_pos_rel_m"]) != 0.0))


class ShapedAction(gym.Wrapper):
    """A TradeFollow env whose actions pass through `ActionShaping` (the training env's, so the policy learns what
    `LearnedFollower` flies); the last observation tells whether the 3D position is known."""

    def __init__(self, env: gym.Env, config: ActionShapingConfig = ActionShapingConfig()) -> None:
        super().__init__(env)
        self.shaping = ActionShaping(config)
        self._known = False
        self._start = True

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._known, self._start = position_known(obs), True
        return obs, info

    def step(self, action):
        shaped = self.shaping.shape(np.asarray(action, np.float32)[None], np.array([self._known]),
                                    np.array([self._start]))[0]
        self._start = False
        obs, reward, terminated, truncated, info = self.env.step(shaped)
        self._known = position_known(obs)
        return obs, reward, terminated, truncated, info
