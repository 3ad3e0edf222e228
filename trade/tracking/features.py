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
IntArray = npt.NDArray[np.int32]

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
def _pixel_cell_index(height_px: int, width_px: int, cell_size_px: int, n_bins: int) -> IntArray:
    """(H*W,) first histogram slot (cell index * n_bins) of each pixel's cell, row-major cells."""
    rows = np.arange(height_px, dtype=np.int32) // cell_size_px
    cols = np.arange(width_px, dtype=np.int32) // cell_size_px
    index = (rows[:, None] * (width_px // cell_size_px) + cols[None, :]) * n_bins
    index = index.reshape(-1)
    index.setflags(write=False)
    return index


@lru_cache(maxsize=8)
def _bin_wrap(n_bins: int) -> IntArray:
    """(n_bins + 2,) table mapping a bin coordinate floor in [0, n_bins + 1] to its bin mod n_bins."""
    table = np.arange(n_bins + 2, dtype=np.int32) % n_bins
    table.setflags(write=False)
    return table


def orientation_histograms(gray: FloatArray32, config: FeatureConfig) -> FloatArray32:
    """Unnormalised per-cell histograms of unsigned gradient orientation for a batch of patches.

    gray: (N, H, W) float32 intensity with H, W multiples of the cell size.
    Returns (N, H/c, W/c, n_bins): sum over a cell's pixels of |grad| split linearly between the
    two bins nearest to the orientation theta in [0, pi).
    """
    n_patches, height, width = gray.shape
    n_bins = config.n_orientation_bins
    stacked = gray.reshape(n_patches * height, width)
    # central differences gx = I(x+1) - I(x-1), gy = I(y+1) - I(y-1) (Sobel, ksize=1), edges replicated
    gx = cv2.Sobel(stacked, cv2.CV_32F, 1, 0, ksize=1, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(stacked, cv2.CV_32F, 0, 1, ksize=1, borderType=cv2.BORDER_REPLICATE)
    # rows at the seams between stacked patches: replicate each patch's own edge instead
    gy_patches = gy.reshape(n_patches, height, width)
    gy_patches[:, 0] = gray[:, min(1, height - 1)] - gray[:, 0]
    gy_patches[:, -1] = gray[:, -1] - gray[:, max(height - 2, 0)]
    magnitude, angle = cv2.cartToPolar(gx, gy)
    # bin coordinate b = (theta mod pi) * n_bins / pi, theta in [0, 2 pi); bin centres at integers
    position = angle.reshape(-1) * np.float32(n_bins / np.pi)
    np.subtract(position, np.float32(n_bins), out=position, where=position >= n_bins)
    lower = position.astype(np.int32)  # floor, since position >= 0
    upper_weight = position - lower
    wrap = _bin_wrap(n_bins)
    mag = magnitude.reshape(-1)
    cell = _pixel_cell_index(n_patches * height, width, config.cell_size_px, n_bins)
    h_cells, w_cells = height // config.cell_size_px, width // config.cell_size_px
    n_values = n_patches * h_cells * w_cells * n_bins
    # h[cell, bin] = sum |g| (1 - w) over pixels with floor(b) = bin + sum |g| w over floor(b) + 1 = bin
    # np.take: the same look-up as wrap[lower], without fancy indexing's per-call overhead
    hist = np.bincount(cell + np.take(wrap, lower), weights=mag * (1.0 - upper_weight), minlength=n_values)
    hist += np.bincount(cell + np.take(wrap, lower + 1), weights=mag * upper_weight, minlength=n_values)
    return hist.reshape(n_patches, h_cells, w_cells, n_bins).astype(np.float32)


def normalise_histograms(hist: FloatArray32, config: FeatureConfig) -> FloatArray32:
    """(N, h, w, bins) block-normalised, truncated histograms: min(h / sqrt(mean_3x3 |h|^2 + eps), clip).

    The 3x3 neighbourhood of cells replicates each patch's edge cells.
    """
    # energy laid out (h, w, N): one cv2 call filters a chunk of patches, each with its own border
    energy = np.einsum("nijk,nijk->ijn", hist, hist)
    chunks = [
        cv2.boxFilter(
            np.ascontiguousarray(energy[..., i : i + _CV_MAX_CHANNELS]),
            -1,
            (_BLOCK_CELLS, _BLOCK_CELLS),
            normalize=True,
            borderType=cv2.BORDER_REPLICATE,
        ).reshape(energy.shape[0], energy.shape[1], -1)
        for i in range(0, energy.shape[2], _CV_MAX_CHANNELS)
    ]
    block_energy = np.concatenate(chunks, axis=2).transpose(2, 0, 1)
    normalised = hist / np.sqrt(block_energy + config.norm_eps)[..., None]
    return np.minimum(normalised, config.hog_clip).astype(np.float32)


def extract_features(patches_rgb: npt.NDArray[np.uint8], config: FeatureConfig) -> FloatArray32:
    """Features of one RGB patch (H, W, 3) or of a batch (N, H, W, 3), uint8.

    Trailing rows/columns beyond a whole cell are dropped. Returns (h, w, C) or (N, h, w, C) float32
    with h = H // c, w = W // c, C = n_bins + 3: normalised orientation histograms, then Lab colour
    averaged over each cell, centred to [-0.5, 0.5] and scaled by `colour_weight`.
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
    gray = cv2.cvtColor(stacked, cv2.COLOR_RGB2GRAY).astype(np.float32) * np.float32(1.0 / _UINT8_MAX)
    hog = normalise_histograms(orientation_histograms(gray.reshape(n_patches, height, width), config), config)
    lab = cv2.cvtColor(stacked, cv2.COLOR_RGB2LAB)
    # cell mean of each Lab channel (INTER_AREA with an integer factor is an exact box average)
    lab_cells = cv2.resize(lab, (w_cells, n_patches * h_cells), interpolation=cv2.INTER_AREA)
    colour = (lab_cells.astype(np.float32) * np.float32(1.0 / _UINT8_MAX) - np.float32(_COLOUR_CENTRE)) * np.float32(
        config.colour_weight
    )
    features = np.concatenate([hog, colour.reshape(n_patches, h_cells, w_cells, 3)], axis=3)
    return features[0] if single else features
