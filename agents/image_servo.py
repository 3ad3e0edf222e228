"""Where the target's box points on the ground, seen from a tilting drone: the image servo's geometry.

Before a follower has a 3D estimate it can only move the drone towards the box (`ScriptedFollower._servo_image`). A
quadrotor accelerates by tilting, and a body-mounted camera tilts with it: a drone pitched 20 deg nose-down at 32 m
sees the ground point below it 12 m forward of the image centre. Servoed on the raw image offset, that tilt is read as
the target running ahead, the servo asks for more speed and the tilt grows: the loop feeds itself until the target
is far behind. The box's ray is therefore taken to the level heading frame with the drone's attitude, integrated
from the IMU's gyro (the drone is level when an episode starts), and followed to level ground.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from trade.camera_pitch import mount_rotation, standoff_m

FloatArray = npt.NDArray[np.float64]

# The least downward component of a box ray an image servo divides by, per unit of the ray's length (here; the
# `WaypointFollower`'s rays are at least 1 long): a ray at or above the horizon meets the ground beyond any offset the
# action can ask for (1e-3 is 1000 heights away).
MIN_RAY_DESCENT = 1e-3


def attitude_after(R_heading_body: FloatArray, gyro_body_radps: FloatArray, dt_s: float) -> FloatArray:
    """The attitude (3, 3) `dt_s` [s] later, the body turning at `gyro_body_radps` (3,) [rad/s] (body x forward,
    y left, z up) over that time: R exp([w dt]x)."""
    turn, _ = cv2.Rodrigues(np.asarray(gyro_body_radps, dtype=np.float64) * dt_s)
    return R_heading_body @ turn


def box_ground_offset(bbox_norm: FloatArray, R_heading_body: FloatArray, camera_pitch_deg: float,
                      camera_fov_deg: float) -> FloatArray:
    """(forward, left) per metre of height: where the box centre's ray meets level ground below the drone, from where
    a level drone's optical axis meets it (h / tan(pitch) ahead; below it for a downward camera), in the heading
    frame. `bbox_norm`: (x centre, y centre, w, h) over the image (square pixels, `camera_fov_deg` across); the
    camera is pitched `camera_pitch_deg` below the body's x axis; `R_heading_body` is the body's attitude with the
    heading yaw taken out here. A ray at or above the horizon is read as MIN_RAY_DESCENT downward."""
    slope = math.tan(math.radians(camera_fov_deg) / 2.0)
    right, down = 2.0 * (np.asarray(bbox_norm[:2], dtype=np.float64) - 0.5)  # half-image units
    ray = R_heading_body @ mount_rotation(camera_pitch_deg) @ np.array([right * slope, down * slope, 1.0])
    yaw = math.atan2(R_heading_body[1, 0], R_heading_body[0, 0])
    c, s = math.cos(yaw), math.sin(yaw)
    forward, left = c * ray[0] + s * ray[1], -s * ray[0] + c * ray[1]
    descent = max(-ray[2], MIN_RAY_DESCENT * float(np.linalg.norm(ray)))
    return np.array([forward / descent - standoff_m(1.0, camera_pitch_deg), left / descent])
