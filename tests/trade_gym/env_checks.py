"""Shared test checks: Gymnasium's `check_env` with every warning raised as an error; two episodes that differ only
in how the camera images the scene have the same ground truth and observations."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
from gymnasium.utils.env_checker import check_env


def check_env_strict(env: gym.Env, **kwargs) -> None:
    """`check_env(env.unwrapped, **kwargs)` with warnings as errors (a warning is a failed check)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, **kwargs)


# The ground truth a change of the camera's look (appearance, modality) must leave as it was
TRUTH_KEYS = ("gt_bbox", "target_visible_fraction", "target_depth_gt", "ground_depth_gt", "decoy_bboxes",
              "drone_position_m", "target_position_m")


def assert_same_truth_and_observations(infos_a: list[dict], infos_b: list[dict], obs_a: list[dict],
                                       obs_b: list[dict]) -> None:
    """Two episodes' ground truth (TRUTH_KEYS of each info) and observations are equal, frame by frame (oracle runs:
    the oracle's noise, the IMU and VIO come from the env's own stream, which the camera's look must not move)."""
    for a, b in zip(infos_a, infos_b, strict=True):
        for key in TRUTH_KEYS:
            np.testing.assert_array_equal(np.asarray(a[key], dtype=float), np.asarray(b[key], dtype=float))
    for a, b in zip(obs_a, obs_b, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
