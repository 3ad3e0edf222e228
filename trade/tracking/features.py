"""Multi-channel appearance features of an image patch for the correlation filter tracker.

Owns the HOG-like gradient-orientation histograms and the cell-averaged Lab colour channels.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

FloatArray32 = npt.NDArray[np.float32]
IntpArray = npt.NDArray[np.intp]

# Lab channels of a uint8 image span [0, 255]; we map them to [-0.5, 0.5].
_UINT8_MAX = 255.0
_COLOUR_CENTRE = 0.5
# HOG block: a cell's histogram is normalised by the energy of its 3x3 neighbourhood of cells.
_BLOCK_CELLS = 3
# cv2.boxFilter accepts images of at most this many channels (found by test on OpenCV 5).
_CV_MAX_CHANNELS = 128


@dataclass(frozen=True)
class FeatureConfig:
    """Feature layout: `n_orientation_bins` gradient channels then 3 Lab channels per cell."""

    cell_size_px: int = 4
    n_orientation_bins: int = 9
    hog_clip: float = 0.2  # truncation of normalised histogram values (Dalal-Triggs 0.2)
    norm_eps: float = 1e-4  # added to the block energy before the square root
    colour_weight: float = 0.5  # multiplies the Lab channels relative to the gradient ones

    def __post_init__(self) -> None:
        if int(self.cell_size_px) != self.cell_size_px or self.cell_size_px < 1:
            raise ValueError(f"FeatureConfig.cell_size_px must be a positive integer, got {self.cell_size_px!r}")
        if int(self.n_orientation_bins) != self.n_orientation_bins or self.n_orientation_bins < 2:
            raise ValueError(
                f"FeatureConfig.n_orientation_bins must be an integer >= 2, got {self.n_orientation_bins!r}"
            )
        for name in ("hog_clip", "norm_eps"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"FeatureConfig.{name} must be finite and > 0, got {value!r}")
        if not np.isfinite(self.colour_weight) or self.colour_weight < 0:
            raise ValueError(f"FeatureConfig.colour_weight must be finite and >= 0, got {self.colour_weight!r}")

    @property
    def n_channels(self) -> int:
        """Channels per cell: orientation bins + L, a, b."""
        return self.n_orientation_bins + 3


@lru_cache(maxsize=32)
def _pixel_cell_index(height_px: int, width_px: int, cell_size_px: int, n_bins: int) -> IntpArray:
    """(H*W,) first histogram slot (cell index * n_bins) of each pixel's cell, row-major cells."""
    rows = np.arange(height_px, dtype=np.intp) // cell_size_px
    cols = np.arange(width_px, dtype=np.intp) // cell_size_px
    index = (rows[:, None] * (width_px // cell_size_px) + cols[None, :]) * n_bins
    index = index.reshape(-1)
    index.setflags(write=False)
    return index


def _central_differences(gray: FloatArray32) -> tuple[FloatArray32, FloatArray32]:
    """(N, H, W) gx = I(x+1) - I(x-1), gy = I(y+1) - I(y-1) of each patch, its own edges replicated."""
    height, width = gray.shape[1:]
    gx, gy = np.empty_like(gray), np.empty_like(gray)
    np.subtract(gray[:, :, 2:], gray[:, :, :-2], out=gx[:, :, 1:-1])
    gx[:, :, 0] = gray[:, :, min(1, width - 1)] - gray[:, :, 0]
    gx[:, :, -1] = gray[:, :, -1] - gray[:, :, max(width - 2, 0)]
    np.subtract(gray[:, 2:], gray[:, :-2], out=gy[:, 1:-1])
    gy[:, 0] = gray[:, min(1, height - 1)] - gray[:, 0]
    gy[:, -1] = gray[:, -1] - gray[:, max(height - 2, 0)]
    return gx, gy


def orientation_histograms(gray: FloatArray32, config: FeatureConfig) -> FloatArray32:
    """Unnormalised per-cell histograms of unsigned gradient orientation for a batch of patches.

    gray: (N, H, W) float32 intensity with H, W multiples of the cell size.
    Returns (N, H/c, W/c, n_bins): sum over a cell's pixels of |grad| split linearly between the
    two bins nearest to the orientation theta in [0, pi).
    """
    n_patches, height, width = gray.shape
    n_bins, cell = config.n_orientation_bins, config.cell_size_px
    h_cells, w_cells = height // cell, width // cell
    n_slots = n_patches * h_cells * w_cells * n_bins
    gx, gy = _central_differences(gray)
    magnitude, position = cv2.cartToPolar(gx.reshape(-1, width), gy.reshape(-1, width))
    del gx, gy  # the temporaries here are sized to the patch: keep few alive at once (no heap regrowth)
    magnitude, position = magnitude.reshape(-1), position.reshape(-1)
    # bin coordinate b = theta * n_bins / pi, theta in [0, 2 pi); bins wrap mod n_bins; centres at integers
    np.multiply(position, np.float32(n_bins / np.pi), out=position)
    slot = position.astype(np.intp)  # floor(b), since b >= 0
    upper_weight = np.subtract(position, slot, out=position)  # b - floor(b), exact in float32
    np.remainder(slot, n_bins, out=slot)
    slot += _pixel_cell_index(n_patches * height, width, cell, n_bins)
    # h[cell, bin] = sum |g| (1 - w) over pixels with floor(b) = bin + sum |g| w over floor(b) + 1 = bin;
    # the second sum is over the first's slots with weights |g| w, each moved one bin up (mod n_bins)
    weight = np.multiply(magnitude, upper_weight, dtype=np.float64)  # |g| w, exact in float64
    upper = np.bincount(slot, weights=weight, minlength=n_slots).reshape(-1, n_bins)
    np.subtract(magnitude, weight, out=weight)  # |g| (1 - w), to float64 rounding
    hist = np.bincount(slot, weights=weight, minlength=n_slots).reshape(-1, n_bins)
    hist[:, 1:] += upper[:, :-1]
    hist[:, 0] += upper[:, -1]
    return hist.reshape(n_patches, h_cells, w_cells, n_bins).astype(np.float32)


def normalise_histograms(hist: FloatArray32, config: FeatureConfig) -> FloatArray32:
    """(N, h, w, bins) block-normalised, truncated histograms: min(h / sqrt(mean_3x3 |h|^2 + eps), clip).

    The 3x3 neighbourhood of cells replicates each patch's edge cells.
    """
    n_patches, h_cells, w_cells = hist.shape[:3]
    # energy laid out (h, w, N): one cv2 call filters a chunk of patches, each with its own border
    energy = np.einsum("nijk,nijk->ijn", hist, hist)
    block_energy = np.empty((h_cells, w_cells, n_patches), dtype=np.float32)
    for i in range(0, n_patches, _CV_MAX_CHANNELS):
        chunk = np.ascontiguousarray(energy[..., i : i + _CV_MAX_CHANNELS])
        filtered = cv2.boxFilter(chunk, -1, (_BLOCK_CELLS, _BLOCK_CELLS), normalize=True,
                                 borderType=cv2.BORDER_REPLICATE)
        block_energy[..., i : i + _CV_MAX_CHANNELS] = filtered.reshape(chunk.shape)
    norm = np.sqrt(block_energy.transpose(2, 0, 1) + config.norm_eps)[..., None]
    normalised = hist / norm
    return np.minimum(normalised, np.float32(config.hog_clip), out=normalised)


def extract_features(patches_rgb: npt.NDArray[np.uint8], config: FeatureConfig) -> FloatArray32:
    """Features of one RGB patch (H, W, 3) or of a batch (N, H, W, 3), uint8.

    Trailing rows/columns beyond a whole cell are dropped. Returns (h, w, C) or (N, h, w, C) float32
    with h = H // c, w = W // c, C = n_bins + 3: normalised orientation histograms, then the Lab colour of
    each cell's mean RGB, centred to [-0.5, 0.5] and scaled by `colour_weight`.
    """
    single = patches_rgb.ndim == 3
    batch = patches_rgb[None] if single else patches_rgb
    if batch.ndim != 4 or batch.shape[3] != 3 or batch.dtype != np.uint8:
        raise ValueError(f"patches_rgb must be (H, W, 3) or (N, H, W, 3) uint8, got {patches_rgb.shape} "
                         f"{patches_rgb.dtype}")
    cell = config.cell_size_px
    n_patches, h_cells, w_cells = batch.shape[0], batch.shape[1] // cell, batch.shape[2] // cell
    if h_cells < 1 or w_cells < 1 or n_patches < 1:
        raise ValueError(f"patches_rgb of shape {patches_rgb.shape} holds no whole {cell} px cell")
    height, width = h_cells * cell, w_cells * cell
    stacked = np.ascontiguousarray(batch[:, :height, :width]).reshape(n_patches * height, width, 3)
    gray = np.multiply(cv2.cvtColor(stacked, cv2.COLOR_RGB2GRAY), np.float32(1.0 / _UINT8_MAX), dtype=np.float32)
    hog = normalise_histograms(orientation_histograms(gray.reshape(n_patches, height, width), config), config)
    # Lab of each cell's mean colour (INTER_AREA with an integer factor is an exact box average): a 16th of
    # the conversions of averaging per-pixel Lab, which it equals on cells of one colour
    rgb_cells = cv2.resize(stacked, (w_cells, n_patches * h_cells), interpolation=cv2.INTER_AREA)
    lab_cells = cv2.cvtColor(rgb_cells, cv2.COLOR_RGB2LAB)
    # (Lab / 255 - 1/2) * colour_weight
    colour = np.multiply(lab_cells, np.float32(1.0 / _UINT8_MAX), dtype=np.float32)
    np.subtract(colour, np.float32(_COLOUR_CENTRE), out=colour)
    np.multiply(colour, np.float32(config.colour_weight), out=colour)
    features = np.concatenate([hog, colour.reshape(n_patches, h_cells, w_cells, 3)], axis=3)
    return features[0] if single else features
