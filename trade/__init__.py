"""TRADE perception stack: tracking and 3D localisation of a ground target from a UAV.

Runs on any sequence of images, camera poses and IMU samples; it never imports the
simulator, the Gymnasium env or the agents.
"""

from trade.geometry import CameraIntrinsics, Pose
from trade.types import BBox, ImuBatch

__all__ = ["BBox", "CameraIntrinsics", "ImuBatch", "Pose"]
