"""The camera's mount pitch: the mount's rotation, and the settings of the stack that follow from the pitch, each by
a written geometric rule.

The paper's offline settings are a nadir camera's (pitch 90 deg); its real flight pitched the camera 45 deg. A
nadir camera keeps every setting exactly as configured (sin 90 deg = 1 in floating point too).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from trade.roi_features import RoiConfig

NADIR_PITCH_DEG = 90.0  # optical axis straight down (the paper's offline setting)


def mount_rotation(pitch_deg: float) -> npt.NDArray[np.float64]:
    """R_body_cam (3, 3): optical axis pitched `pitch_deg` below body x, x_cam = -y_body, image top forward.

    z_cam = cos(th) x_b - sin(th) z_b; x_cam = -y_b; y_cam = z_cam x x_cam = -sin(th) x_b - cos(th) z_b.
    """
    th = math.radians(pitch_deg)
    s, c = math.sin(th), math.cos(th)
    return np.array([[0.0, -s, c], [-1.0, 0.0, 0.0], [0.0, -c, -s]])


def standoff_m(height_m: float, pitch_deg: float) -> float:
    """The horizontal distance [m] at which a camera `height_m` above flat ground, pitched `pitch_deg` below the
    horizon, has the ground on its optical axis: height / tan(pitch); exactly 0 for a downward camera. The following
    band (`trade_gym.scoring.FollowBand`) is centred there, and a pitched camera's drone starts there
    (`trade_gym.sim.world.World.drone_start`)."""
    return height_m / math.tan(math.radians(pitch_deg)) if pitch_deg < NADIR_PITCH_DEG else 0.0


def check_pitch(name: str, pitch_deg: float) -> None:
    """ValueError naming `name` unless 0 < pitch_deg <= 90 [deg] (90: nadir; 0 would look at the horizon)."""
    if not (math.isfinite(pitch_deg) and 0.0 < pitch_deg <= NADIR_PITCH_DEG):
        raise ValueError(f"{name} must be in (0, {NADIR_PITCH_DEG}] deg (90: straight down), got {pitch_deg!r}")


def axis_height_fraction(pitch_deg: float) -> float:
    """Height change per metre along the optical axis of a level camera pitched `pitch_deg` below the horizon:
    sin(pitch) (1 for a nadir camera). A point's error along the centre ray reaches its height by this factor."""
    return math.sin(math.radians(pitch_deg))


def roi_config_for_pitch(roi: RoiConfig, pitch_deg: float) -> RoiConfig:
    """`roi` for a camera pitched `pitch_deg`: its promotion threshold read as a height error, its tracks kept over
    the margins a nadir camera would have from the same height. Both are unchanged for a nadir camera.

    Promotion: the plane fit judges a point by its distance from the plane (MSAC inlier threshold 0.5 m), and a
    track's depth error sigma_z moves its point along its ray, changing its height by sigma_z sin(pitch) near the
    image centre (where the follower keeps the target). So the absolute threshold on sigma_z is promote_sigma_m /
    sin(pitch). The relative one stays: sigma_z <= r z is a height error <= r x the camera's height above the point.

    Keeping: a track gains parallax while it stays in the ROI, which slides over the ground with the target. Per
    metre along the view, the drone's motion and the target's both move a ground point's image against the box by
    sin^2(pitch) / h rad (h: height above the ground), so the parallax a track gains before it leaves is the margin's
    angle times the drone's over the target's speed, at any pitch. The height error above asks for the parallax a
    nadir camera's tracks need from the same height, but the paper's margins scale with the box, whose side at the
    standoff range h / sin(pitch) is sin(pitch) of the nadir camera's: so tracks are kept within margins 1/sin(pitch)
    wider (new ones are still seeded in the paper's ROI).
    """
    check_pitch("pitch_deg", pitch_deg)
    fraction = axis_height_fraction(pitch_deg)
    return replace(roi, promote_sigma_m=roi.promote_sigma_m / fraction,
                   keep_margin_scale=roi.keep_margin_scale / fraction)


def ground_mask_usable(pitch_deg: float, min_model_pitch_deg: float) -> bool:
    """Whether the single-image depth model sees views like those it was trained on: a camera pitched at least
    `min_model_pitch_deg` (the data set's lowest mount pitch). Below it the view takes in the horizon and sky the
    model never saw, and its map is not a depth map of the scene (`trade.ground_filter.SHIPPED_MODEL_MIN_PITCH_DEG`)."""
    check_pitch("pitch_deg", pitch_deg)
    return pitch_deg >= min_model_pitch_deg
