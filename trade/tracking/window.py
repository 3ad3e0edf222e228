"""Resampling of image windows onto the fixed-size templates the correlation filters work on.

Owns the window geometry (pixel centres at integer coordinates, OpenCV), border handling and sample blur.
"""

from __future__ import annotations

from functools import lru_cache
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
ImageRGB = npt.NDArray[np.uint8]

# Windows are pre-shrunk with INTER_AREA when they span at least this many image px per template px.
ANTIALIAS_MIN_FACTOR = 2
# Extra image px kept around the clipped window before the pre-shrink, for the bilinear taps.
_ROI_MARGIN_PX = 2
# Template pixels interpolate the (possibly pre-shrunk) image bilinearly.
_INTERPOLATION = cv2.INTER_LINEAR
# Gaussian kernels are cut at this many standard deviations.
_BLUR_TRUNCATE_SIGMAS = 3.0
# The separable filter's kernel along the axis it leaves alone.
_IDENTITY_KERNEL = np.ones((1, 1))


def _shrunk_roi(
    image: ImageRGB, center_px: FloatArray, half_extent_px: FloatArray, shrink: int
) -> tuple[ImageRGB, FloatArray, FloatArray]:
    """INTER_AREA shrink by ~`shrink` of the image part under center +- half_extent (clipped, non-empty).

    Returns (src, offset, step) with image coordinate = offset + step * src coordinate, per axis (x, y).
    """
    size = np.array([image.shape[1], image.shape[0]])
    lo = np.clip(np.floor(center_px - half_extent_px) - _ROI_MARGIN_PX, 0, size - 1).astype(int)
    hi = np.clip(np.ceil(center_px + half_extent_px) + _ROI_MARGIN_PX, 0, size).astype(int)
    hi = np.maximum(hi, lo + 1)
    roi = image[lo[1] : hi[1], lo[0] : hi[0]]
    small = np.maximum(np.round((hi - lo) / shrink), 1).astype(int)
    # cv2.resize keeps the dtype (its stubs say only "an integer or float array")
    src = cast(ImageRGB, cv2.resize(roi, (int(small[0]), int(small[1])), interpolation=cv2.INTER_AREA))
    # resize maps dst pixel i to roi coordinate (i + 1/2) s - 1/2 with s = roi size / dst size
    step = (hi - lo) / small
    return src, lo + 0.5 * step - 0.5, step


def sample_windows(
    image_rgb: ImageRGB, center_px: npt.ArrayLike, windows_wh_px: npt.ArrayLike, out_wh_px: tuple[int, int]
) -> npt.NDArray[np.uint8]:
    """Resample S windows sharing one centre onto (out_h, out_w) templates.

    image_rgb: (H, W, 3) uint8; center_px: (2,) (x, y) [px], pixel centres at integers;
    windows_wh_px: (S, 2) window (width, height) [px]; out_wh_px: template (width, height) [px].
    Returns (S, out_h, out_w, 3) uint8. Template pixel u maps to image x = c + (u - (out - 1) / 2) * w / out.
    Outside the image the border is replicated. Windows spanning >= 2 image px per template px are
    sampled from one INTER_AREA-shrunk copy of the image region (anti-aliasing, bounded cost).
    """
    windows = np.atleast_2d(np.asarray(windows_wh_px, dtype=np.float64))
    center = np.asarray(center_px, dtype=np.float64).reshape(2)
    out = np.asarray(out_wh_px, dtype=np.float64)
    if windows.shape[1] != 2 or not np.all(windows > 0) or not np.all(np.isfinite(center)):
        raise ValueError(f"sample_windows needs positive (S, 2) windows and a finite centre, got {windows} {center}")
    steps = windows / out  # image px per template px, (S, 2)
    src, offset, src_step = image_rgb, np.zeros(2), np.ones(2)
    shrink = int(np.floor(steps.min()))
    if shrink >= ANTIALIAS_MIN_FACTOR:
        src, offset, src_step = _shrunk_roi(image_rgb, center, windows.max(axis=0) / 2, shrink)
    # src coordinate of template pixel u: (c + (u - (out - 1) / 2) step - offset) / src_step, per axis:
    # per window the axis-aligned affine map u -> (step / src_step) u + (c - (out - 1) / 2 step - offset) / src_step
    inverse_maps = np.zeros((len(windows), 2, 3))
    inverse_maps[:, 0, 0], inverse_maps[:, 1, 1] = (steps / src_step).T
    inverse_maps[:, :, 2] = (center - (out - 1) / 2 * steps - offset) / src_step
    out_w, out_h = int(out[0]), int(out[1])
    sampled = np.empty((len(windows), out_h, out_w, 3), dtype=np.uint8)
    for inverse_map, dst in zip(inverse_maps, sampled):
        cv2.warpAffine(src, inverse_map, (out_w, out_h), dst=dst, flags=_INTERPOLATION | cv2.WARP_INVERSE_MAP,
                       borderMode=cv2.BORDER_REPLICATE)
    return sampled


@lru_cache(maxsize=8)
def _gaussian_kernel(sigma_px: float) -> npt.NDArray[np.float64]:
    """(k, 1) Gaussian kernel of `sigma_px`, cut at _BLUR_TRUNCATE_SIGMAS (read-only)."""
    # float64: getGaussianKernel's default ktype is CV_64F
    kernel = cast(FloatArray, cv2.getGaussianKernel(2 * int(np.ceil(_BLUR_TRUNCATE_SIGMAS * sigma_px)) + 1, sigma_px))
    kernel.setflags(write=False)
    return kernel


def blur_batch(samples: npt.NDArray[np.uint8], sigma_px: float) -> npt.NDArray[np.uint8]:
    """Gaussian blur of each of (S, h, w, 3) samples with its own replicated border (no bleeding).

    Separable: the x pass runs on the samples stacked vertically, the y pass on them side by side.
    """
    if sigma_px <= 0:
        return samples
    n_samples, height, width, _ = samples.shape
    kernel, identity = _gaussian_kernel(float(sigma_px)), _IDENTITY_KERNEL
    along_x = cv2.sepFilter2D(
        samples.reshape(n_samples * height, width, 3), -1, kernel, identity, borderType=cv2.BORDER_REPLICATE
    )
    side_by_side = along_x.reshape(n_samples, height, width, 3).transpose(1, 0, 2, 3).reshape(height, -1, 3)
    along_y = cv2.sepFilter2D(side_by_side, -1, identity, kernel, borderType=cv2.BORDER_REPLICATE)
    return np.ascontiguousarray(along_y.reshape(height, n_samples, width, 3).transpose(1, 0, 2, 3))
