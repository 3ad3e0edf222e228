"""Discriminative correlation filter tracker: multichannel DSST translation filter plus a 1-D scale filter.

Owns the Fourier-domain appearance model, the committed box and the score map; picking a peak is peaks.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
import scipy.fft

from trade.tracking.features import FeatureConfig, extract_features
from trade.tracking.peaks import ResponseMap, refine_peak
from trade.tracking.scale import ScaleConfig, ScaleFilter, spectral_power
from trade.tracking.window import sample_windows
from trade.types import BBox

FloatArray = npt.NDArray[np.float64]
ImageRGB = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class DcfConfig:
    """Tracker settings. The search window (padding x box) is resampled to a fixed-area template."""

    padding: float = 2.0  # search window side = padding * box side
    template_side_px: int = 96  # sqrt of the template area; the aspect ratio follows the first box
    min_template_cells: int = 8  # lower bound on either side of the cell grid
    output_sigma_factor: float = 0.1  # label sigma = factor * sqrt(target area in cells)
    regularisation: float = 1e-2  # lambda in r = IFFT(sum_l A_l Z_l / (B + lambda))
    learning_rate: float = 0.02  # eta of the running-average model update
    estimate_scale: bool = True  # run the DSST scale filter (else the box keeps its size)
    min_box_px: float = 4.0  # lower bound on committed box width and height
    features: FeatureConfig = field(default_factory=FeatureConfig)
    scale: ScaleConfig = field(default_factory=ScaleConfig)

    def __post_init__(self) -> None:
        checks = {
            "padding": self.padding > 1.0,
            "template_side_px": int(self.template_side_px) == self.template_side_px and self.template_side_px > 0,
            "min_template_cells": int(self.min_template_cells) == self.min_template_cells
            and self.min_template_cells >= 2,
            "output_sigma_factor": self.output_sigma_factor > 0,
            "regularisation": self.regularisation > 0,
            "learning_rate": 0 < self.learning_rate <= 1,
            "min_box_px": self.min_box_px > 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and ok):
                raise ValueError(f"DcfConfig.{name} has invalid value {value!r}")


def _check_image(image_rgb: ImageRGB) -> None:
    if image_rgb.ndim != 3 or image_rgb.shape[2] != 3 or image_rgb.dtype != np.uint8 or min(image_rgb.shape[:2]) < 1:
        raise ValueError(f"image_rgb must be (H, W, 3) uint8, got {image_rgb.shape} {image_rgb.dtype}")


def gaussian_label(shape_hw: tuple[int, int], sigma_cells: float) -> FloatArray:
    """(h, w) label g = exp(-|d|^2 / (2 sigma^2)) with its peak at cell (0, 0), wrapped circularly."""
    rows = np.fft.ifftshift(np.arange(shape_hw[0]) - shape_hw[0] // 2)
    cols = np.fft.ifftshift(np.arange(shape_hw[1]) - shape_hw[1] // 2)
    return np.exp(-(rows[:, None] ** 2 + cols[None, :] ** 2) / (2.0 * sigma_cells**2))


_CHANNEL_POWER = "l...,l...->..."  # (C, h, w') -> (h, w'): sum over the feature channels


class DcfTracker:
    """Correlation filter tracker. Per frame the caller does:

    resp = tracker.response(image, search_center_px)   # score map around the last box or a prediction
    choice = select_peak(resp, peak_config)             # or highest_peak(resp) for the "dcf" baseline
    tracker.commit(choice.location_px, resp.scale)      # move and resize the box
    tracker.update(image)                               # learn at the new box; skip when ambiguous

    resp.scale is estimated at the highest peak; a caller that picks another peak may re-estimate
    it there with `tracker.estimate_scale(image, location_px)`.
    """

    def __init__(self, config: DcfConfig | None = None) -> None:
        self.config = config if config is not None else DcfConfig()
        self._scale_filter = ScaleFilter(self.config.scale, self.config.features)
        self._box: BBox | None = None

    @property
    def box(self) -> BBox:
        """Current committed box [px]."""
        if self._box is None:
            raise RuntimeError("DcfTracker.init must be called before using the tracker")
        return self._box

    def init(self, image_rgb: ImageRGB, box: BBox) -> None:
        """Fix the template geometry from `box` (image (H, W, 3) uint8 RGB) and train on this frame."""
        _check_image(image_rgb)
        cfg = self.config
        cell = cfg.features.cell_size_px
        self._image_wh = np.array([image_rgb.shape[1], image_rgb.shape[0]], dtype=np.float64)
        self._box = box
        window = cfg.padding * np.array([box.w_px, box.h_px])
        # template: the window's aspect ratio with an area of template_side_px^2, in whole cells
        cells = np.round(window * cfg.template_side_px / np.sqrt(window.prod()) / cell)
        cells = np.maximum(cells, cfg.min_template_cells).astype(int)
        self._cells_wh = (int(cells[0]), int(cells[1]))
        self._template_wh = (self._cells_wh[0] * cell, self._cells_wh[1] * cell)
        shape_hw = (self._cells_wh[1], self._cells_wh[0])
        self._cos_window = np.outer(np.hanning(shape_hw[0]), np.hanning(shape_hw[1])).astype(np.float32)
        sigma_cells = cfg.output_sigma_factor * np.sqrt(cells.prod()) / cfg.padding
        # the model lives in single precision, like the features it is learnt from
        self._label_f = np.fft.rfft2(gaussian_label(shape_hw, sigma_cells)).astype(np.complex64)
        spectrum = self._spectrum(image_rgb, box.center, window)
        # A_l = G conj(F_l), B = sum_l |F_l|^2
        self._num = self._label_f * np.conj(spectrum)
        self._den = spectral_power(spectrum, _CHANNEL_POWER)
        if cfg.estimate_scale:
            self._scale_filter.init(image_rgb, box.center, np.array([box.w_px, box.h_px]))

    def _spectrum(self, image_rgb: ImageRGB, center_px: FloatArray, window_wh_px: FloatArray) -> npt.NDArray:
        """(C, h, w // 2 + 1) complex64 rfft2 of the cosine-windowed features of one window (w, h) [px]."""
        _check_image(image_rgb)
        patch = sample_windows(image_rgb, center_px, window_wh_px, self._template_wh)[0]
        features = extract_features(patch, self.config.features).transpose(2, 0, 1)  # (C, h, w)
        return scipy.fft.rfft2(features * self._cos_window)

    def response(self, image_rgb: ImageRGB, search_center_px: npt.ArrayLike, with_scale: bool = True) -> ResponseMap:
        """Score map of the window (padding x current box) centred on `search_center_px` (x, y) [px].

        The map's cells are displacements of the target from the search centre; `scale` is the
        DSST size factor at the highest peak (1 when scale estimation is off or `with_scale` is False).
        """
        cfg = self.config
        box = self.box
        center = np.asarray(search_center_px, dtype=np.float64).reshape(2)
        window = cfg.padding * np.array([box.w_px, box.h_px])
        spectrum = self._spectrum(image_rgb, center, window)
        # r = IFFT( sum_l A_l Z_l / (B + lambda) ), peak at the target's displacement (circular)
        resp_f = np.einsum("lij,lij->ij", self._num, spectrum) / (self._den + np.float32(cfg.regularisation))
        scores = scipy.fft.irfft2(resp_f, s=(self._cells_wh[1], self._cells_wh[0]))  # float32
        resp = ResponseMap(
            scores=np.fft.fftshift(scores),
            scale=1.0,
            origin_px=center,
            px_per_cell=window / np.array(self._cells_wh),
        )
        if not (cfg.estimate_scale and with_scale):
            return resp
        peak_rc = refine_peak(resp.scores, np.unravel_index(int(np.argmax(resp.scores)), resp.scores.shape))
        return replace(resp, scale=self.estimate_scale(image_rgb, resp.cell_to_image_px(peak_rc)))

    def estimate_scale(self, image_rgb: ImageRGB, center_px: npt.ArrayLike) -> float:
        """DSST size factor of the target centred at `center_px` (x, y) [px] relative to the current box."""
        if not self.config.estimate_scale:
            return 1.0
        box = self.box
        center = np.asarray(center_px, dtype=np.float64).reshape(2)
        return self._scale_filter.estimate(image_rgb, center, np.array([box.w_px, box.h_px]))

    def commit(self, center_px: npt.ArrayLike, scale: float = 1.0) -> BBox:
        """Move the box centre to `center_px` (x, y) [px], clamped to the image, and scale its size.

        Size is clamped to [min_box_px, image size]; returns the new box.
        """
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"DcfTracker.commit scale must be finite and > 0, got {scale!r}")
        box = self.box
        center = np.clip(np.asarray(center_px, dtype=np.float64).reshape(2), 0.0, self._image_wh - 1.0)
        size = np.clip(np.array([box.w_px, box.h_px]) * scale, self.config.min_box_px, self._image_wh)
        self._box = BBox.from_center(float(center[0]), float(center[1]), float(size[0]), float(size[1]))
        return self._box

    def update(self, image_rgb: ImageRGB, box: BBox | None = None) -> None:
        """Running-average update of both filters on the window around `box` (default: the committed box)."""
        box = self.box if box is None else box
        eta = np.float32(self.config.learning_rate)
        size = np.array([box.w_px, box.h_px])
        spectrum = self._spectrum(image_rgb, box.center, self.config.padding * size)
        # A <- (1 - eta) A + eta G conj(F); B <- (1 - eta) B + eta sum_l |F_l|^2
        self._num = (1 - eta) * self._num + eta * (self._label_f * np.conj(spectrum))
        self._den = (1 - eta) * self._den + eta * spectral_power(spectrum, _CHANNEL_POWER)
        if self.config.estimate_scale:
            self._scale_filter.update(image_rgb, box.center, size)
