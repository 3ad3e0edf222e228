"""One-dimensional DSST scale filter: estimates how much the target's size changed since the last frame.

Owns the scale sample pyramid, its Fourier-domain filter over scales and the running-average update.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.fft

from trade.tracking.features import FeatureConfig, extract_features
from trade.tracking.peaks import parabola_vertex_offset
from trade.tracking.window import blur_batch, sample_windows

FloatArray = npt.NDArray[np.float64]
ImageRGB = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class ScaleConfig:
    """DSST scale search (Danelljan et al. 2014): n_scales samples of the box at scale_step ** k."""

    n_scales: int = 17  # odd; k = -(n - 1) / 2 .. (n - 1) / 2
    scale_step: float = 1.03
    sigma_factor: float = 0.25  # label sigma = sigma_factor * sqrt(n_scales) [scale steps]
    model_max_area_px: int = 576  # each sample is resized to at most this area, in whole cells
    min_model_cells: int = 2  # lower bound on either side of a sample's cell grid
    sample_blur_sigma_px: float = 1.5  # Gaussian blur of each resized sample [sample px], >= 0
    regularisation: float = 1e-2  # lambda in A / (B + lambda)
    learning_rate: float = 0.025  # eta of the running-average model update
    # The update learns from the samples of the same frame's estimate (no new pyramid) when it is at the same
    # centre and the box changed size by at most this many scale steps since (0: only an unchanged box)
    update_reuse_max_steps: float = 0.5

    def __post_init__(self) -> None:
        checks = {
            "n_scales": int(self.n_scales) == self.n_scales and self.n_scales >= 3 and self.n_scales % 2 == 1,
            "scale_step": self.scale_step > 1.0,
            "sigma_factor": self.sigma_factor > 0,
            "model_max_area_px": int(self.model_max_area_px) == self.model_max_area_px and self.model_max_area_px > 0,
            "min_model_cells": int(self.min_model_cells) == self.min_model_cells and self.min_model_cells >= 1,
            "sample_blur_sigma_px": self.sample_blur_sigma_px >= 0,
            "regularisation": self.regularisation > 0,
            "learning_rate": 0 < self.learning_rate <= 1,
            "update_reuse_max_steps": self.update_reuse_max_steps >= 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and ok):
                raise ValueError(f"ScaleConfig.{name} has invalid value {value!r}")

    @property
    def exponents(self) -> FloatArray:
        """(n_scales,) k such that the sample sizes are box size * scale_step ** k."""
        return np.arange(self.n_scales, dtype=np.float64) - (self.n_scales - 1) / 2


def spectral_power(spectrum: npt.NDArray[np.complex64], subscripts: str) -> npt.NDArray[np.float32]:
    """sum |X|^2 of a complex64 spectrum over the axis that the einsum `subscripts` ("ab,ab->a") contracts, float32."""
    return np.einsum(subscripts, spectrum.real, spectrum.real) + np.einsum(subscripts, spectrum.imag, spectrum.imag)


_SCALE_POWER = "kd,kd->k"  # (n_scales, d) -> (n_scales,): sum over the feature dimensions


class ScaleFilter:
    """1-D correlation filter over a pyramid of box-sized samples; features are flattened per scale."""

    def __init__(self, config: ScaleConfig, features: FeatureConfig) -> None:
        self.config = config
        self.features = features
        k = config.exponents
        self._factors = config.scale_step**k
        # the model lives in single precision, like the features it is learnt from
        self._window = np.hanning(config.n_scales)[:, None].astype(np.float32)
        sigma = config.sigma_factor * np.sqrt(config.n_scales)
        # label g_k = exp(-k^2 / (2 sigma^2)), peak at the middle sample (scale 1)
        self._label_f = np.fft.fft(np.exp(-(k**2) / (2.0 * sigma**2)))[:, None].astype(np.complex64)
        self._model_wh: tuple[int, int] | None = None
        # the last estimate's image, centre (x, y) [px], box (w, h) [px] and spectrum, for the update to reuse
        self._estimated: tuple[ImageRGB, FloatArray, FloatArray, npt.NDArray] | None = None

    def _spectrum(self, image_rgb: ImageRGB, center_px: FloatArray, box_wh_px: FloatArray) -> npt.NDArray:
        """(n_scales, d) complex64 FFT over scales of the Hann-weighted flattened features of each scaled sample."""
        if self._model_wh is None:
            raise RuntimeError("ScaleFilter.init must be called first")
        windows = self._factors[:, None] * np.asarray(box_wh_px, dtype=np.float64)[None, :]
        # the blur evens out the detail that resampling by different factors keeps at each scale
        samples = sample_windows(image_rgb, center_px, windows, self._model_wh)
        samples = blur_batch(samples, self.config.sample_blur_sigma_px)
        feats = extract_features(samples, self.features)
        return scipy.fft.fft(feats.reshape(self.config.n_scales, -1) * self._window, axis=0)

    def init(self, image_rgb: ImageRGB, center_px: FloatArray, box_wh_px: FloatArray) -> None:
        """Fix the sample size (box aspect, area <= model_max_area_px) and train on this frame."""
        cfg, cell = self.config, self.features.cell_size_px
        box = np.asarray(box_wh_px, dtype=np.float64)
        shrink = min(1.0, float(np.sqrt(cfg.model_max_area_px / box.prod())))
        cells = np.maximum(np.floor(box * shrink / cell), cfg.min_model_cells).astype(int)
        self._model_wh = (int(cells[0]) * cell, int(cells[1]) * cell)
        self._estimated = None
        spectrum = self._spectrum(image_rgb, center_px, box)
        # A = G conj(X) per feature dimension, B = sum_d |X_d|^2
        self._num = self._label_f * np.conj(spectrum)
        self._den = spectral_power(spectrum, _SCALE_POWER)

    def estimate(self, image_rgb: ImageRGB, center_px: FloatArray, box_wh_px: FloatArray) -> float:
        """Size factor of the target at `center_px` relative to `box_wh_px`, refined between scale steps."""
        spectrum = self._spectrum(image_rgb, center_px, box_wh_px)
        self._estimated = (image_rgb, np.array(center_px, dtype=np.float64), np.array(box_wh_px, dtype=np.float64),
                           spectrum)
        # r_k = IFFT( sum_d A_d Z_d / (B + lambda) )
        resp_f = np.einsum("kd,kd->k", self._num, spectrum) / (self._den + np.float32(self.config.regularisation))
        resp = scipy.fft.ifft(resp_f).real
        best = int(np.argmax(resp))
        exponent = self.config.exponents[best] + parabola_vertex_offset(resp, best)
        return float(self.config.scale_step**exponent)

    def update(self, image_rgb: ImageRGB, center_px: FloatArray, box_wh_px: FloatArray) -> None:
        """A <- (1 - eta) A + eta G conj(X); B <- (1 - eta) B + eta sum_d |X_d|^2.

        X is the spectrum of the same frame's last estimate when that was at this centre and the box has
        changed size since by at most `update_reuse_max_steps` scale steps (the image must not have been
        modified in place in between); else the pyramid is sampled anew.
        """
        eta = np.float32(self.config.learning_rate)
        spectrum = self._reusable_spectrum(image_rgb, center_px, box_wh_px)
        if spectrum is None:
            spectrum = self._spectrum(image_rgb, center_px, box_wh_px)
        self._num = (1 - eta) * self._num + eta * (self._label_f * np.conj(spectrum))
        self._den = (1 - eta) * self._den + eta * spectral_power(spectrum, _SCALE_POWER)

    def _reusable_spectrum(self, image_rgb: ImageRGB, center_px: FloatArray,
                           box_wh_px: FloatArray) -> npt.NDArray | None:
        """The last estimate's spectrum if it was of this image at this centre with a box within
        `update_reuse_max_steps` scale steps of this one (per side), else None; used at most once."""
        estimated, self._estimated = self._estimated, None
        if estimated is None:
            return None
        image, center, box_wh, spectrum = estimated
        steps = np.abs(np.log(np.asarray(box_wh_px, dtype=np.float64) / box_wh)) / np.log(self.config.scale_step)
        same_place = image is image_rgb and np.array_equal(center, center_px)
        return spectrum if same_place and bool(np.all(steps <= self.config.update_reuse_max_steps)) else None
