"""The thermal camera's sensor: an uncooled microbolometer like FLIR's Boson, from scene radiance temperatures to the
8-bit image it outputs (optics blur, temporal noise, column fixed-pattern noise, 14-bit counts, automatic gain control
by plateau histogram equalisation, frame freezes during flat-field correction).

Owns `ThermalConfig` and `ThermalSensor` (its per-frame noise from the generator it is given) and `plateau_equalize`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from trade.validation import check_non_negative, check_positive, check_range, require

F32 = npt.NDArray[np.float32]
UInt8Image = npt.NDArray[np.uint8]
MK_PER_K = 1000.0
# Raw output: 14-bit counts (FLIR's cores: the Lepton datasheet's AGC maps 14 bits to 8), linear in radiance temperature
# around the scene (a linearisation: a microbolometer is linear in in-band radiance, not in temperature); one count is
# RAW_K_PER_COUNT (assumed: fine beside the NETD, so quantisation adds (20 mK)^2 / 12, ~6 mK rms), count 0 at
# RAW_ZERO_K, so 200-528 K fit
RAW_BITS = 14
RAW_MAX_COUNT = 2**RAW_BITS - 1
RAW_K_PER_COUNT = 0.02
RAW_ZERO_K = 200.0
OUT_MAX_DN = 255  # the 8-bit AGC output's full scale
BLUR_KERNEL_SIGMAS = 3.0  # Gaussian kernel half-width in standard deviations


@dataclass(frozen=True)
class ThermalConfig:
    """The microbolometer and its processing, Boson-like (FLIR Boson 640: 640x512 uncooled VOx, 12 um pixels, f/1.0
    optics, 60 Hz; datasheet 102-2013-40). The env renders at its own `camera_size` and `camera_fov_deg` and takes
    that grid as the sensor's pixels (a Boson 640's vertical resolution is `camera_size=512`).

    - netd_mk: temporal noise, std per pixel per frame [mK]. The datasheet gives "as low as <40 mK at f/1.0" for
      its best configurations; 50 mK leaves a typical unit's margin.
    - column_fpn_mk: std of a per-column offset left after flat-field correction [mK] (assumed: microbolometer
      readouts per column leave faint stripes; the datasheet gives no figure), redrawn at each correction.
    - blur_sigma_px: Gaussian optics blur [px]: f/1.0 diffraction at 10 um (Airy core ~ Gaussian sigma 0.42 lambda N
      = 4.2 um) with the 12 um pixel's own aperture (sigma 12 / sqrt(12) = 3.5 um): sqrt(4.2^2 + 3.5^2) / 12 um
      = 0.45 px, independent of the focal length.
    - agc_plateau_fraction: the plateau: histogram bins are clipped at this share of all pixels before equalising
      (the "clip limit high" of the histogram equalisation in FLIR's Lepton datasheet 500-0659-00-09), so a large
      uniform area (the ground) cannot take most of the grey levels. Chosen by eye on development world 3 (the Lepton's
      power-on default is the whole pixel count: no clipping, classic equalisation).
    - agc_tail_fraction: share of the pixels at each end of the histogram mapped to 0 / 255 outright (assumed).
    - agc_linear_fraction: share of a linear stretch between the tails mixed into the equalised map (the
      "linear percent" control of the Lepton SDK's histogram equalisation; value assumed).
    - ffc_freeze: whether flat-field correction freezes the output: every `ffc_interval_s` [s] the shutter closes
      and the last image is held for `ffc_duration_s` [s]. FLIR's cores correct themselves after a set period or a
      camera temperature change (the Lepton's FFC mode has both); 180 s is assumed ("every few minutes"). The
      Lepton's shutter event lasts ~1 s (its datasheet) and cameras with FLIR cores freeze the video for under a second
      (e.g. Bosch MIC thermal manual): 0.5 s assumed. When the first one comes is drawn per episode, uniformly over
      one interval.
    """

    netd_mk: float = 50.0
    column_fpn_mk: float = 20.0
    blur_sigma_px: float = 0.45
    agc_plateau_fraction: float = 0.002
    agc_tail_fraction: float = 0.002
    agc_linear_fraction: float = 0.2
    ffc_freeze: bool = False
    ffc_interval_s: float = 180.0
    ffc_duration_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("netd_mk", "column_fpn_mk", "blur_sigma_px"):
            check_non_negative(f"ThermalConfig.{name}", getattr(self, name))
        check_range("ThermalConfig.agc_plateau_fraction", self.agc_plateau_fraction, 0.0, 1.0)
        require(self.agc_plateau_fraction > 0.0, "ThermalConfig.agc_plateau_fraction", self.agc_plateau_fraction,
                "> 0")
        check_range("ThermalConfig.agc_tail_fraction", self.agc_tail_fraction, 0.0, 0.25)
        check_range("ThermalConfig.agc_linear_fraction", self.agc_linear_fraction, 0.0, 1.0)
        require(isinstance(self.ffc_freeze, bool), "ThermalConfig.ffc_freeze", self.ffc_freeze, "a bool")
        check_positive("ThermalConfig.ffc_interval_s", self.ffc_interval_s)
        check_non_negative("ThermalConfig.ffc_duration_s", self.ffc_duration_s)
        require(self.ffc_duration_s < self.ffc_interval_s, "ThermalConfig.ffc_duration_s", self.ffc_duration_s,
                f"< ffc_interval_s ({self.ffc_interval_s!r})")


class ThermalSensor:
    """One episode's camera: `capture` turns a radiance-temperature image into the 8-bit image the camera outputs.

    Draws from `rng` (its own stream), in order: the first flat-field correction's time (uniform in one interval),
    the column offsets, then per frame the temporal noise (one standard normal per pixel), and new column offsets
    after each correction. `last_raw` holds the last frame's 14-bit counts (H, W) uint16 (None before the first)."""

    def __init__(self, config: ThermalConfig, width_px: int, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._first_ffc_s = float(rng.uniform(0.0, config.ffc_interval_s))
        self._columns_k = self._draw_columns(width_px)
        self._ffc_index = -1  # corrections done so far - 1
        self._held: UInt8Image | None = None
        self.last_raw: npt.NDArray[np.uint16] | None = None

    def capture(self, radiance_k: F32, t_s: float) -> UInt8Image:
        """(H, W) uint8 camera output for the scene's (H, W) radiance temperatures [K] at time `t_s` [s]; during a
        flat-field correction (`ffc_freeze`) the image held from before it, unchanged."""
        index = self._ffc_index_at(t_s)
        if index is not None and index > self._ffc_index:  # a correction started: offsets re-zeroed, then new ones
            self._ffc_index = index
            self._columns_k = self._draw_columns(radiance_k.shape[1])
        if index is not None and self._frozen(t_s, index) and self._held is not None:
            return self._held
        cfg = self.config
        signal = _gaussian_blur(radiance_k.astype(np.float32), cfg.blur_sigma_px)
        noise = self._rng.standard_normal(signal.shape, dtype=np.float32)
        signal = signal + noise * np.float32(cfg.netd_mk / MK_PER_K) + self._columns_k[None, :]
        raw = np.clip(np.rint((signal - RAW_ZERO_K) / RAW_K_PER_COUNT), 0, RAW_MAX_COUNT).astype(np.uint16)
        self.last_raw = raw
        image = plateau_equalize(raw, cfg.agc_plateau_fraction, cfg.agc_tail_fraction, cfg.agc_linear_fraction)
        self._held = image
        return image

    @property
    def first_ffc_s(self) -> float:
        """When the first flat-field correction starts [s] (it only freezes frames with `ffc_freeze`)."""
        return self._first_ffc_s

    def _ffc_index_at(self, t_s: float) -> int | None:
        """Index of the last correction started at or before `t_s` (None: none yet, or `ffc_freeze` off)."""
        if not self.config.ffc_freeze or t_s < self._first_ffc_s:
            return None
        return math.floor((t_s - self._first_ffc_s) / self.config.ffc_interval_s)

    def _frozen(self, t_s: float, index: int) -> bool:
        start = self._first_ffc_s + index * self.config.ffc_interval_s
        return t_s - start < self.config.ffc_duration_s

    def _draw_columns(self, width_px: int) -> F32:
        return (self._rng.standard_normal(width_px, dtype=np.float32)
                * np.float32(self.config.column_fpn_mk / MK_PER_K))


def _gaussian_blur(image: F32, sigma_px: float) -> F32:
    if sigma_px <= 0.0:
        return image
    size = 2 * math.ceil(BLUR_KERNEL_SIGMAS * sigma_px) + 1
    return cast(F32, cv2.GaussianBlur(image, (size, size), sigma_px, borderType=cv2.BORDER_REFLECT))


def plateau_equalize(raw: npt.NDArray[np.uint16], plateau_fraction: float, tail_fraction: float,
                     linear_fraction: float) -> UInt8Image:
    """(H, W) uint8 from (H, W) counts by plateau histogram equalisation, as thermal cameras' automatic gain control
    does: the histogram of counts between the tails (the darkest and brightest `tail_fraction` of the pixels) is
    clipped at `plateau_fraction` of the pixels per bin, its cumulative sum maps counts to [0, 255], mixed with
    `linear_fraction` of a linear stretch between the tails; counts beyond the tails map to 0 and 255."""
    flat = raw.ravel()
    low, high = (int(v) for v in np.quantile(flat, (tail_fraction, 1.0 - tail_fraction), method="nearest"))
    if high <= low:  # a flat image: mid grey
        return np.full(raw.shape, (OUT_MAX_DN + 1) // 2, dtype=np.uint8)
    counts = np.bincount(np.clip(flat, low, high) - low, minlength=high - low + 1).astype(np.float64)
    clipped = np.minimum(counts, plateau_fraction * flat.size)
    cumulative = np.cumsum(clipped)
    # bin b maps to the share of clipped pixels below it plus half its own: the first bin to ~0, the last to ~1
    first, last = 0.5 * clipped[0], 0.5 * clipped[-1]
    equalised = (cumulative - 0.5 * clipped - first) / (cumulative[-1] - first - last)
    linear = np.linspace(0.0, 1.0, high - low + 1)
    lut = np.rint(OUT_MAX_DN * ((1.0 - linear_fraction) * equalised + linear_fraction * linear))
    lut = np.clip(lut, 0, OUT_MAX_DN).astype(np.uint8)
    return lut[np.clip(raw, low, high).astype(np.intp) - low]
