"""The image servo's geometry: a box's ray to level ground, with the drone's attitude from its gyro."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.camera_pitch import mount_rotation
from trade_gym.agents.image_servo import attitude_after, box_ground_offset

FOV_DEG = 110.0
SLOPE = math.tan(math.radians(FOV_DEG) / 2.0)  # half an image's width per unit depth


def _box_of(point_heading: np.ndarray, R_heading_body: np.ndarray, pitch_deg: float) -> np.ndarray:
    """The normalised box (centre only) where a camera pitched `pitch_deg` on a body at `R_heading_body` sees a point
    given relative to the drone in the heading frame."""
    ray_cam = (R_heading_body @ mount_rotation(pitch_deg)).T @ point_heading
    right, down = ray_cam[:2] / ray_cam[2] / SLOPE
    return np.array([0.5 + right / 2.0, 0.5 + down / 2.0, 0.05, 0.05])


def _pitched_nose_down(angle_rad: float, frames: int = 10) -> np.ndarray:
    """The attitude after turning nose-down (about body y, which points left) by `angle_rad` over `frames` frames."""
    R = np.eye(3)
    for _ in range(frames):
        R = attitude_after(R, np.array([0.0, angle_rad * 30.0 / frames, 0.0]), 1.0 / 30.0)
    return R


def test_a_level_downward_camera_reads_the_box_offset_on_the_ground():
    assert box_ground_offset(np.array([0.5, 0.5, 0.1, 0.1]), np.eye(3), 90.0, FOV_DEG) == pytest.approx([0.0, 0.0])
    # 0.2 half-images right of and above the centre: right and forward by 0.2 tan(fov / 2) per metre of height
    offset = box_ground_offset(np.array([0.6, 0.4, 0.1, 0.1]), np.eye(3), 90.0, FOV_DEG)
    np.testing.assert_allclose(offset, [0.2 * SLOPE, -0.2 * SLOPE], atol=1e-12)


def test_gyro_integration_turns_the_body_by_rate_times_time():
    R = _pitched_nose_down(math.radians(20.0))
    np.testing.assert_allclose(R @ np.array([1.0, 0.0, 0.0]),
                               [math.cos(math.radians(20.0)), 0.0, -math.sin(math.radians(20.0))], atol=1e-12)


@pytest.mark.parametrize("pitch_deg", [90.0, 45.0])
def test_the_drones_tilt_is_taken_out(pitch_deg):
    """A drone pitched 20 deg nose-down (accelerating forward) sees a point below where a level one's axis would meet
    the ground far off the image centre; the servo's offset is still that point's, not the tilt's."""
    R = _pitched_nose_down(math.radians(20.0))
    axis_ahead = 0.0 if pitch_deg == 90.0 else 1.0 / math.tan(math.radians(pitch_deg))
    target = np.array([axis_ahead + 0.1, -0.05, -1.0])  # 0.1 forward of the level axis's point, 0.05 right (height 1)
    box = _box_of(target, R, pitch_deg)
    raw = box_ground_offset(box, np.eye(3), pitch_deg, FOV_DEG)  # what a servo assuming a level drone reads
    assert abs(raw[0] - 0.1) > 0.3  # the tilt alone looks like a third of a height
    np.testing.assert_allclose(box_ground_offset(box, R, pitch_deg, FOV_DEG), [0.1, -0.05], atol=1e-9)


def test_the_heading_is_taken_out():
    """Offsets are in the heading frame: a drone yawed since the episode start reads the same offset."""
    yaw = attitude_after(np.eye(3), np.array([0.0, 0.0, math.radians(30.0) * 30.0]), 1.0 / 30.0)
    box = np.array([0.65, 0.45, 0.1, 0.1])
    np.testing.assert_allclose(box_ground_offset(box, yaw, 90.0, FOV_DEG),
                               box_ground_offset(box, np.eye(3), 90.0, FOV_DEG), atol=1e-12)


def test_a_ray_above_the_horizon_is_bounded():
    """A 45 deg camera's box at the image top, on a drone pitched 60 deg nose-up: the ray points above the horizon and
    reads as a finite, far offset forward."""
    R = _pitched_nose_down(math.radians(-60.0))
    offset = box_ground_offset(np.array([0.5, 0.0, 0.1, 0.1]), R, 45.0, FOV_DEG)
    assert np.all(np.isfinite(offset)) and offset[0] > 100.0
