"""What the camera does to the rendered image: haze with distance, motion blur, exposure, vignetting, noise, JPEG.

Owns `CameraLook` (one episode's drawn values) and `CameraEffects`, which applies them to the RGB image of a
`CameraFrame`; the depth and segmentation buffers (ground truth) pass through untouched.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics
from trade_gym.sim.camera import CameraFrame

FloatArray = npt.NDArray[np.float64]
WHITE_DN = 255.0  # full scale of the 8-bit image [DN]
# Longest motion smear drawn, as a fraction of the image width: at the longest exposure the yaw-rate limit smears
# ~1 % of the width, so this bound only acts while the airframe tumbles (after a crash)
MOTION_BLUR_MAX_FRACTION = 0.03
MIN_MOTION_BLUR_PX = 0.5  # shorter smears are not drawn: they move no pixel by more than half its width
DEPTH_SAMPLE_STRIDE_PX = 8  # the blur's median depth is taken on this grid (cheap; a median needs no more)
KERNEL_SAMPLES_PER_PX = 4  # points splatted per pixel of smear length into the blur kernel


@dataclass(frozen=True)
class CameraLook:
    """One episode's camera and atmosphere: haze extinction [1/m] toward `haze_rgb` (r, g, b) [DN]; exposure time
    [s] (the motion blur's); gain [EV, stops]; sensor noise std = sqrt(read^2 + shot^2 I / 255) [DN] at intensity
    I [DN]; vignetting (relative light lost at the image corner, falling off as r^2); JPEG quality (1-100)."""

    haze_extinction_per_m: float
    haze_rgb: tuple[float, float, float]
    exposure_s: float
    gain_ev: float
    read_noise_dn: float
    shot_noise_dn: float
    vignetting: float
    jpeg_quality: int


class CameraEffects:
    """Applies a `CameraLook` to each frame, in the order light meets them: haze (by each pixel's distance along
    its ray), motion blur over the exposure, vignetting and gain, sensor noise (from `rng`, one draw per frame),
    8-bit quantisation, JPEG encode/decode."""

    def __init__(self, look: CameraLook, intrinsics: CameraIntrinsics, rng: np.random.Generator) -> None:
        self.look = look
        self.intrinsics = intrinsics
        self._rng = rng
        K = intrinsics
        u = (np.arange(K.width_px) - K.cx_px) / K.fx_px
        v = (np.arange(K.height_px) - K.cy_px) / K.fy_px
        # distance along a pixel's ray = z sqrt(1 + x_n^2 + y_n^2), x_n = (u - cx) / fx, y_n likewise
        self._ray_length_per_z = np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2).astype(np.float32)
        # vignetting 1 - k r^2, r = distance from the principal point over the half diagonal; times the gain
        r2 = ((np.arange(K.width_px) - K.cx_px)[None, :] ** 2 + (np.arange(K.height_px) - K.cy_px)[:, None] ** 2)
        r2 /= (K.width_px / 2.0) ** 2 + (K.height_px / 2.0) ** 2
        self._gain = ((1.0 - look.vignetting * r2) * 2.0 ** look.gain_ev).astype(np.float32)[:, :, None]
        self._haze = np.asarray(look.haze_rgb, dtype=np.float32)

    def apply(self, frame: CameraFrame, velocity_cam_mps: FloatArray, angular_rate_cam_radps: FloatArray) -> CameraFrame:
        """`frame` with its RGB image as the camera delivers it, given the camera's velocity (3,) and angular rate
        (3,) in its own frame [m/s, rad/s] over the exposure; depth and segmentation unchanged."""
        look = self.look
        image = frame.rgb.astype(np.float32)
        # haze: I = haze + (I - haze) exp(-beta d), d the distance along the ray (far_m where nothing was hit)
        transmission = np.exp(-look.haze_extinction_per_m * frame.depth_m * self._ray_length_per_z)
        image = self._haze + (image - self._haze) * transmission[:, :, None]
        image = self._motion_blur(image, frame.depth_m, velocity_cam_mps, angular_rate_cam_radps)
        image *= self._gain
        # sensor noise: std^2 = read^2 + shot^2 I / 255 (signal-dependent shot noise plus read noise) [DN]
        std = np.sqrt(look.read_noise_dn ** 2 + (look.shot_noise_dn ** 2 / WHITE_DN) * np.maximum(image, 0.0))
        image += std * self._rng.standard_normal(image.shape, dtype=np.float32)
        rgb = np.clip(np.rint(image), 0.0, WHITE_DN).astype(np.uint8)
        return dataclasses.replace(frame, rgb=jpeg_round_trip(rgb, look.jpeg_quality))

    def blur_px(self, depth_m: npt.NDArray[np.float32], velocity_cam_mps: FloatArray,
                angular_rate_cam_radps: FloatArray) -> FloatArray:
        """(2,) smear of the image centre over the exposure (du, dv) [px], before the length bound.

        A static point on the optical axis at depth Z moves as dp/dt = -w x p - v, so u' = fx (-v_x / Z - w_y) and
        v' = fy (-v_y / Z + w_x); Z is the median depth of the image (rotation about the axis is not a linear
        smear and is left out)."""
        K, (vx, vy, _), (wx, wy, _) = self.intrinsics, velocity_cam_mps, angular_rate_cam_radps
        z = float(np.median(depth_m[::DEPTH_SAMPLE_STRIDE_PX, ::DEPTH_SAMPLE_STRIDE_PX]))
        return np.array((K.fx_px * (-vx / z - wy), K.fy_px * (-vy / z + wx))) * self.look.exposure_s

    def _motion_blur(self, image: npt.NDArray[np.float32], depth_m: npt.NDArray[np.float32],
                     velocity_cam_mps: FloatArray, angular_rate_cam_radps: FloatArray) -> npt.NDArray[np.float32]:
        smear = self.blur_px(depth_m, velocity_cam_mps, angular_rate_cam_radps)
        length = min(float(np.hypot(*smear)), MOTION_BLUR_MAX_FRACTION * self.intrinsics.width_px)
        if not length >= MIN_MOTION_BLUR_PX:
            return image
        kernel = line_kernel(length, smear / np.hypot(*smear))
        # ddepth -1 keeps float32 (OpenCV's stubs say only "an integer or float array")
        return cast(npt.NDArray[np.float32], cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REFLECT))


def line_kernel(length_px: float, direction: FloatArray) -> npt.NDArray[np.float32]:
    """(n, n) blur kernel summing to 1: a segment `length_px` long along the unit (2,) `direction` (du, dv) through
    the centre, splatted bilinearly; n = 2 ceil(length / 2) + 1."""
    half = int(math.ceil(length_px / 2.0))
    n = 2 * half + 1
    t = np.linspace(-length_px / 2.0, length_px / 2.0, max(2, math.ceil(length_px * KERNEL_SAMPLES_PER_PX)))
    x, y = half + t * direction[0], half + t * direction[1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    kernel = np.zeros((n, n), dtype=np.float64)
    for dx, dy, weight in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(kernel, (np.minimum(y0 + dy, n - 1), np.minimum(x0 + dx, n - 1)), weight)
    return (kernel / kernel.sum()).astype(np.float32)


def jpeg_round_trip(rgb: npt.NDArray[np.uint8], quality: int) -> npt.NDArray[np.uint8]:
    """(H, W, 3) RGB image after JPEG encoding at `quality` (1-100) and decoding (OpenCV, BGR order inside)."""
    ok, encoded = cv2.imencode(".jpg", np.ascontiguousarray(rgb[:, :, ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError(f"JPEG encoding failed at quality {quality!r}")
    decoded = cv2.imdecode(encoded, cv2.IMREAD_COLOR)
    if decoded is None:
        raise RuntimeError(f"JPEG decoding failed at quality {quality!r}")
    return cast(npt.NDArray[np.uint8], np.ascontiguousarray(decoded[:, :, ::-1]))  # IMREAD_COLOR: 8-bit BGR
