"""The flat, scaled feature vector a learned follower sees: one order shared by training and run time.

Owns `FEATURE_LAYOUT`, `flatten_observation` (numpy, single or batched Dict observations) and the
gymnasium wrapper that applies it during training, so the ONNX policy and SB3 see identical inputs.
"""

from __future__ import annotations

from collections.abc import Mapping

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium import spaces

# (key, size, offset, scale): feature = (obs[key] - offset) / scale, then clipped to +-FEATURE_CLIP.
# Scales are the magnitudes the env produces while following (heights 16-32 m, speeds of a few m/s).
FEATURE_LAYOUT: tuple[tuple[str, int, float, float], ...] = (
    ("target_pos_rel_m", 3, 0.0, 20.0),  # [m]
    ("target_vel_mps", 3, 0.0, 4.0),  # [m/s]
    ("drone_vel_mps", 3, 0.0, 4.0),  # [m/s]
    ("bbox_norm", 4, 0.5, 0.5),  # centre and size over the image side: centre -> [-1, 1]
    ("target_depth_m", 1, 0.0, 20.0),  # [m]
    ("track_valid", 1, 0.0, 1.0),  # {0, 1}
    ("time_lost_s", 1, 0.0, 3.0),  # [s]
    ("imu", 6, 0.0, 10.0),  # [m/s^2] and [rad/s]; gravity reads about +1
)
# Not a feature: `estimate_age_s` (perception latency, issue 22) came after the shipped policy was trained, so it
# is left out and the policy's input is unchanged.
FEATURE_CLIP = 10.0
# One derived feature: 1 once the perception has a 3D position (the relative position is non-zero).
N_DERIVED = 1
N_FEATURES = sum(size for _, size, _, _ in FEATURE_LAYOUT) + N_DERIVED
POSITION_KNOWN_INDEX = N_FEATURES - 1  # the derived feature's column

_OFFSETS = np.concatenate([np.full(n, off) for _, n, off, _ in FEATURE_LAYOUT]).astype(np.float32)
_SCALES = np.concatenate([np.full(n, s) for _, n, _, s in FEATURE_LAYOUT]).astype(np.float32)


def flatten_observation(observation: Mapping[str, npt.ArrayLike]) -> tuple[npt.NDArray[np.float32], bool]:
    """Dict observation -> ((N, N_FEATURES) float32 features, batched).

    Accepts one observation (each value of shape (k,)) or a batch (each (N, k)), like SB3's predict;
    `batched` tells which, so callers can return actions of the matching shape."""
    first_key, first_size = FEATURE_LAYOUT[0][0], FEATURE_LAYOUT[0][1]
    if first_key not in observation:
        raise KeyError(f"observation lacks {first_key!r}; keys: {sorted(observation)}")
    batched = np.ndim(observation[first_key]) == 2
    parts = []
    for key, size, _, _ in FEATURE_LAYOUT:
        if key not in observation:
            raise KeyError(f"observation lacks {key!r}; keys: {sorted(observation)}")
        value = np.asarray(observation[key], dtype=np.float32)
        parts.append(value.reshape(-1, size))
    raw = np.concatenate(parts, axis=1)
    # x = clip((obs - offset) / scale, -c, c); derived: position known = any(target_pos_rel != 0)
    scaled = np.clip((raw - _OFFSETS) / _SCALES, -FEATURE_CLIP, FEATURE_CLIP)
    known = np.any(raw[:, :first_size] != 0.0, axis=1, keepdims=True).astype(np.float32)
    return np.ascontiguousarray(np.concatenate([scaled, known], axis=1), dtype=np.float32), batched


def feature_space() -> spaces.Box:
    return spaces.Box(-FEATURE_CLIP, FEATURE_CLIP, (N_FEATURES,), np.float32)


class FlatObservation(gym.ObservationWrapper):
    """Wraps a TradeFollow env so it emits `flatten_observation`'s vector (training only)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.observation_space = feature_space()

    def observation(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return flatten_observation(observation)[0][0]
