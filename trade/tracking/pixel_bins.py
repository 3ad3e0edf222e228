"""How the colour model (`trade.tracking.colour_box`) bins pixels: RGB cubes on a colour image, grey levels on a grey one.

A grey image (every pixel's three channels equal, as a thermal camera's) carries no colour: there the histograms are
over grey levels, finer than the colour cubes' 16 levels per channel (see `ColourBoxConfig.grey_bins`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

ImageRGB = npt.NDArray[np.uint8]
Mask = npt.NDArray[np.uint8]
# OpenCV's stubs type every result as "an integer or float array": calcHist and sepFilter2D keep float32 here
Histogram = npt.NDArray[np.float32]
IndexArray = npt.NDArray[np.intp]

# Histogram channels (R, G, B) and their value ranges for cv2.calcHist.
_CHANNELS = [0, 1, 2]
_RANGES = [0, 256, 0, 256, 0, 256]
_GREY_RANGE = [0, 256]
_BITS_PER_CHANNEL = 8  # bin = value * n // 256 = (value * n) >> 8
# The 3-tap binomial kernel [1 2 1] / 4 that smooths the histograms along each axis.
_BLUR_KERNEL = np.array([0.25, 0.5, 0.25])
_IDENTITY_KERNEL = np.ones(1)


def is_grey(image_rgb: ImageRGB) -> bool:
    """Whether every pixel of the (H, W, 3) image has three equal channels (a grey image in RGB form)."""
    return bool(np.array_equal(image_rgb[..., 0], image_rgb[..., 1])
                and np.array_equal(image_rgb[..., 1], image_rgb[..., 2]))


def _normalised(hist: Histogram) -> Histogram:
    """The histogram over its sum (unchanged when empty)."""
    total = float(hist.sum())
    return hist / total if total > 0 else hist


@dataclass(frozen=True)
class ColourBins:
    """n^3 cubes of RGB space, n = bins_per_channel; flat bin (r n + g) n + b of r, g, b = value * n // 256."""

    bins_per_channel: int
    blur_passes: int  # binomial [1 2 1] / 4 smoothing passes along each colour axis
    grey = False

    @property
    def shape(self) -> tuple[int, ...]:
        n = self.bins_per_channel
        return (n, n, n)

    def density(self, pixels: ImageRGB, mask: Mask) -> Histogram:
        """Normalised, smoothed (n, n, n) colour histogram of the (h, w, 3) pixels under the (h, w) mask."""
        n = self.bins_per_channel
        hist = cast(Histogram, cv2.calcHist([pixels], _CHANNELS, mask, [n, n, n], _RANGES))  # float32 counts
        for _ in range(self.blur_passes):
            # axes 0 and 1 as image rows and columns with axis 2 as channels, then axis 2 as columns; ddepth -1 keeps
            # float32, zero outside
            hist = cast(Histogram, cv2.sepFilter2D(hist, -1, _BLUR_KERNEL, _BLUR_KERNEL,
                                                   borderType=cv2.BORDER_CONSTANT))
            hist = cast(Histogram, cv2.sepFilter2D(
                hist.reshape(n * n, n), -1, _BLUR_KERNEL, _IDENTITY_KERNEL, borderType=cv2.BORDER_CONSTANT
            ).reshape(n, n, n))
        return _normalised(hist)

    def flat_index(self, image_rgb: ImageRGB) -> IndexArray:
        """(h, w) flat bin of each pixel of an (h, w, 3) uint8 image."""
        n = self.bins_per_channel
        q = (image_rgb.astype(np.uint16) * n) >> _BITS_PER_CHANNEL
        return cast(IndexArray, (q[..., 0] * n + q[..., 1]) * n + q[..., 2])


@dataclass(frozen=True)
class GreyBins:
    """n bins of grey level (value * n // 256); a pixel's grey level is OpenCV's RGB-to-grey luma, which is its value
    on a grey image (the weights sum to one exactly in OpenCV's fixed point)."""

    bins: int
    blur_passes: int  # binomial [1 2 1] / 4 smoothing passes along the grey axis
    grey = True

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.bins,)

    def density(self, pixels: ImageRGB, mask: Mask) -> Histogram:
        """Normalised, smoothed (n,) grey-level histogram of the (h, w, 3) pixels under the (h, w) mask."""
        grey = cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_RGB2GRAY)
        hist = cast(Histogram, cv2.calcHist([grey], [0], mask, [self.bins], _GREY_RANGE))  # (n, 1) float32 counts
        for _ in range(self.blur_passes):
            hist = cast(Histogram, cv2.sepFilter2D(hist, -1, _IDENTITY_KERNEL, _BLUR_KERNEL,
                                                   borderType=cv2.BORDER_CONSTANT))
        return _normalised(hist.reshape(self.bins))

    def flat_index(self, image_rgb: ImageRGB) -> IndexArray:
        """(h, w) grey-level bin of each pixel of an (h, w, 3) uint8 image."""
        grey = cv2.cvtColor(np.ascontiguousarray(image_rgb), cv2.COLOR_RGB2GRAY)
        return cast(IndexArray, (grey.astype(np.uint16) * self.bins) >> _BITS_PER_CHANNEL)


PixelBins = ColourBins | GreyBins
