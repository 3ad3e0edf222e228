"""Colour-model refinement of the tracker's box: a distractor-aware object/surround colour likelihood (DAT).

Owns the object and surround colour histograms, the likelihood map around the tracked centre and the
tight box of the target's blob in it, with the plausibility tests that decide whether that box is used.
On a grey image (a thermal camera's) the histograms are over grey levels (`trade.tracking.pixel_bins`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from trade.tracking.pixel_bins import ColourBins, GreyBins, PixelBins, is_grey
from trade.types import BBox

FloatArray = npt.NDArray[np.float64]
ImageRGB = npt.NDArray[np.uint8]
# OpenCV's stubs type every result as "an integer or float array"; the casts below name the dtype each call keeps
# (uint8 masks through threshold and morphology)
Mask = npt.NDArray[np.uint8]

# Likelihoods in [0, 1] are back-projected as uint8 round(255 L) (Otsu's threshold works on these).
_LEVELS = 255
# A pixel centre on the blob lies within 1/2 px of the query along each axis: d^2 <= 1/2.
_ON_PIXEL_D2 = 0.5


@dataclass(frozen=True)
class ColourBoxConfig:
    """Colour model (Possegger et al., CVPR 2015) and the tests a refined box must pass."""

    bins_per_channel: int = 16  # RGB quantisation: bins_per_channel ** 3 colour bins
    histogram_blur_passes: int = 1  # binomial [1 2 1] / 4 smoothing passes along each colour axis
    surround_factor: float = 2.0  # surround = box scaled by this about its centre, minus the box
    # L = (p_obj + lambda prior) / (p_obj + w p_surr + lambda) with p the normalised histograms;
    # w = surround_factor^2 - 1 weighs them like DAT's raw counts (the ring has that many box areas)
    surround_weight: float = 3.0
    prior_likelihood: float = 0.5  # prior: L of a colour seen in neither region
    prior_density: float = 1e-3  # lambda, a pseudo-density per bin
    window_factor: float = 2.0  # search window side = window_factor * max(box w, box h)
    min_window_px: int = 24  # lower bound on the search window side
    min_threshold: float = 0.5  # Otsu's threshold on the likelihood map is clamped to [min, max]
    max_threshold: float = 0.8
    closing_radius_px: int = 1  # morphological closing of the foreground (bridges gaps <= 2 r px)
    opening_radius_px: int = 1  # lines <= 2 r px wide are cut off the blob (see _without_lines)
    max_centre_gap_px: float = 4.0  # no blob within this distance of the centre -> no refinement
    # refined box area / previous box area must lie in [min, max]. On a grey image the ratio is to the smaller of the
    # previous box and the tracker's box (`refine`'s size_reference) when that is given: grey levels alone let the
    # blob merge with warm ground it touches, and a chain of merged blobs, each within the ratio of the last output
    # box, walked that box to 3.5 times the vehicle, whose own blob it then refused (desert by day), while the
    # tracker's box, bounded by one scale step a frame, kept the vehicle's size.
    min_area_ratio: float = 0.4
    max_area_ratio: float = 2.5
    # blob pixels / area of the tracker's (scale-tracked) box must not exceed this: one vehicle fills
    # about 0.8-1 of its box in any orientation, two identical vehicles side by side about twice that
    max_blob_fill_ratio: float = 1.4
    max_border_sides: int = 1  # blobs touching more window sides (not image borders) are rejected
    min_contrast: float = 0.6  # mean L on the blob - mean L outside its box must exceed this
    learning_rate: float = 0.05  # eta in p <- (1 - eta) p + eta p_new, on accepted refinements only
    box_rim_px: int = 1  # object colours come from the init box eroded by this (its rim mixes colours)
    blob_rim_px: int = 0  # ... and from the blob eroded by this (thresholded: its rim is mostly object)
    # On a grey image (`pixel_bins.is_grey`, a thermal camera's) the model is a histogram of grey levels. A vehicle's
    # shell at one temperature is one grey level give or take the sensor's noise, while a 16-level bin (the colour
    # cubes' side) also holds the warm rocks around it, and the blob grew over them (night desert, see
    # docs/perception.md "Thermal images").
    grey_bins: int = 128
    grey_histogram_blur_passes: int = 2  # binomial smoothing passes along the grey axis
    # On a grey image a driving vehicle's engine cover and exhaust are far hotter than its body, and their blob alone
    # (a third of the vehicle) is the likeliest one; taken, it shrank the box onto them (night mountain). So a grey
    # blob must fill at least grey_min_blob_fill_ratio of the tracker's box (blob pixels / its area), or else its
    # tight box must span at least grey_min_blob_span_ratio of the tracker's box (by area). A whole vehicle fills
    # 0.8-1 of a box learnt on it, but a turning one fills less of its axis-aligned box (2a / (1 + a)^2 = 0.40 at 45
    # deg for an a = 2.6 car), which the tracker's box follows (`GuidedTrackerConfig.dcf_size_from_blob`): its tight
    # box still spans the tracker's (0.96-1.09, desert by day). The engine alone spans 0.35-0.5 of it.
    grey_min_blob_fill_ratio: float = 0.45
    grey_min_blob_span_ratio: float = 0.7

    def __post_init__(self) -> None:
        counts = ("bins_per_channel", "histogram_blur_passes", "min_window_px", "closing_radius_px",
                  "opening_radius_px", "max_border_sides", "box_rim_px", "blob_rim_px", "grey_bins",
                  "grey_histogram_blur_passes")
        checks = {name: int(getattr(self, name)) == getattr(self, name) and getattr(self, name) >= 0 for name in counts}
        checks |= {
            "bins_per_channel": checks["bins_per_channel"] and 2 <= self.bins_per_channel <= 64,
            "grey_bins": checks["grey_bins"] and 2 <= self.grey_bins <= 256,
            "grey_min_blob_fill_ratio": 0.0 <= self.grey_min_blob_fill_ratio <= self.max_blob_fill_ratio,
            "surround_factor": self.surround_factor > 1.0,
            "prior_likelihood": 0.0 <= self.prior_likelihood <= 1.0,
            "prior_density": self.prior_density > 0,
            "surround_weight": self.surround_weight > 0,
            "window_factor": self.window_factor >= 1.0,
            "min_window_px": checks["min_window_px"] and self.min_window_px >= 3,
            "min_threshold": 0.0 < self.min_threshold < 1.0,
            "max_threshold": self.min_threshold <= self.max_threshold < 1.0,
            "max_centre_gap_px": self.max_centre_gap_px >= 0,
            "min_area_ratio": 0.0 < self.min_area_ratio <= 1.0,
            "max_area_ratio": self.max_area_ratio >= 1.0,
            "grey_min_blob_span_ratio": 0.0 <= self.grey_min_blob_span_ratio <= self.max_area_ratio,
            "max_blob_fill_ratio": self.max_blob_fill_ratio > 0.0,
            "max_border_sides": checks["max_border_sides"] and self.max_border_sides <= 4,
            "min_contrast": 0.0 <= self.min_contrast < 1.0,
            "learning_rate": 0.0 <= self.learning_rate <= 1.0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and ok):
                raise ValueError(f"ColourBoxConfig.{name} has invalid value {value!r}")


@dataclass(frozen=True, eq=False)
class BoxRefinement:
    """Tight box [px] of the colour blob at the tracked centre and the evidence for it.

    area_px: blob pixel count; mean_likelihood: mean P(target | colour) on the blob; contrast: that
    minus the mean outside the box in the window; threshold: the likelihood threshold used;
    rejection: "" when accepted, else the failed test.
    mask: (h, w) bool blob in the window whose top-left image pixel is window_origin_px (x, y).
    """

    box: BBox
    area_px: int
    mean_likelihood: float
    contrast: float
    threshold: float
    accepted: bool
    rejection: str
    mask: npt.NDArray[np.bool_]
    window_origin_px: tuple[int, int]


def _check_image(image_rgb: ImageRGB) -> None:
    if image_rgb.ndim != 3 or image_rgb.shape[2] != 3 or image_rgb.dtype != np.uint8 or min(image_rgb.shape[:2]) < 1:
        raise ValueError(f"image_rgb must be (H, W, 3) uint8, got {image_rgb.shape} {image_rgb.dtype}")


def _pixel_slices(image_hw: tuple[int, int], center_px: FloatArray, size_wh_px: FloatArray) -> tuple[slice, slice]:
    """(rows, cols) of the image pixels (centres at integers) whose centres lie in the box, clipped."""
    lo = np.clip(np.ceil(center_px - size_wh_px / 2.0 - 0.5), 0, [image_hw[1], image_hw[0]]).astype(int)
    hi = np.clip(np.floor(center_px + size_wh_px / 2.0 - 0.5) + 1, lo, [image_hw[1], image_hw[0]]).astype(int)
    return slice(lo[1], hi[1]), slice(lo[0], hi[0])


def _square_kernel(radius_px: int) -> npt.NDArray[np.uint8]:
    """The (2 r + 1)-px square structuring element of a morphological operation of radius r."""
    return np.ones((2 * radius_px + 1, 2 * radius_px + 1), np.uint8)


def _eroded(mask: npt.NDArray[np.uint8], radius_px: int) -> npt.NDArray[np.uint8]:
    """Mask eroded by a (2 r + 1)^2 square, outside counting as background; the mask itself if that empties it."""
    if radius_px <= 0:
        return mask
    core = cast(Mask, cv2.erode(mask, _square_kernel(radius_px), borderType=cv2.BORDER_CONSTANT, borderValue=0))
    return core if core.any() else mask


class ColourBoxRefiner:
    """Per frame: `ref = refiner.refine(image, dcf_centre, last_box)`; if ref and ref.accepted, use
    ref.box and call `refiner.update(image, ref)` to adapt the colour model."""

    def __init__(self, config: ColourBoxConfig | None = None) -> None:
        self.config = config if config is not None else ColourBoxConfig()
        self._colour_bins = ColourBins(self.config.bins_per_channel, self.config.histogram_blur_passes)
        self._grey_bins = GreyBins(self.config.grey_bins, self.config.grey_histogram_blur_passes)
        self._bins: PixelBins = self._colour_bins  # chosen by the image `init` learns from
        self._p_obj: npt.NDArray[np.float32] | None = None
        self._p_surr: npt.NDArray[np.float32] | None = None
        self._lut = np.full(self._bins.shape, self.config.prior_likelihood, dtype=np.float32)

    @property
    def likelihood_lut(self) -> npt.NDArray[np.float32]:
        """P(target | colour) per bin: (n, n, n) per (r, g, b) bin, n = bins_per_channel, bin = value * n // 256; after
        `init` on a grey image, (grey_bins,) per grey-level bin."""
        return self._lut

    @property
    def grey(self) -> bool:
        """Whether the model is over grey levels (`init` was given a grey image)."""
        return self._bins.grey

    def _bins_for(self, image_rgb: ImageRGB) -> PixelBins:
        return self._grey_bins if is_grey(image_rgb) else self._colour_bins

    def _object_and_surround(
        self, image_rgb: ImageRGB, box: BBox, blob: npt.NDArray[np.bool_] | None, blob_origin: tuple[int, int],
        bins: PixelBins,
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """Colour densities of the object (the box, or `blob` with its top-left pixel at `blob_origin`,
        without its rim) and of the surround ring (surround_factor x box, minus the box)."""
        size = np.array([box.w_px, box.h_px])
        rows, cols = _pixel_slices(image_rgb.shape[:2], box.center, self.config.surround_factor * size)
        in_rows, in_cols = _pixel_slices(image_rgb.shape[:2], box.center, size)
        in_h, in_w = in_rows.stop - in_rows.start, in_cols.stop - in_cols.start
        if in_h <= 0 or in_w <= 0:
            raise ValueError(f"box {box} has no pixel centre inside the image")
        ring = np.ones((rows.stop - rows.start, cols.stop - cols.start), dtype=np.uint8)
        top, left = in_rows.start - rows.start, in_cols.start - cols.start
        ring[top : top + in_h, left : left + in_w] = 0
        if blob is None:
            obj_mask = np.ones((in_h, in_w), dtype=np.uint8)
            obj_rows, obj_cols = in_rows, in_cols
        else:
            obj_mask = blob.astype(np.uint8)
            obj_rows = slice(blob_origin[1], blob_origin[1] + blob.shape[0])
            obj_cols = slice(blob_origin[0], blob_origin[0] + blob.shape[1])
        # edge pixels mix object and surround colours
        core = _eroded(obj_mask, self.config.box_rim_px if blob is None else self.config.blob_rim_px)
        return bins.density(image_rgb[obj_rows, obj_cols], core), bins.density(image_rgb[rows, cols], ring)

    def _likelihood_lut(self, p_obj: npt.NDArray[np.float32], p_surr: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """L(b) = (p_obj + lambda prior) / (p_obj + w p_surr + lambda) per bin b."""
        cfg = self.config
        lut = (p_obj + cfg.prior_density * cfg.prior_likelihood) / (
            p_obj + cfg.surround_weight * p_surr + cfg.prior_density
        )
        return lut.astype(np.float32)

    def _set_model(self, p_obj: npt.NDArray[np.float32], p_surr: npt.NDArray[np.float32]) -> None:
        self._p_obj, self._p_surr = p_obj, p_surr
        self._lut = self._likelihood_lut(p_obj, p_surr)
        # quantised look-up table indexed by the flat bin (`PixelBins.flat_index`)
        self._lut_u8 = np.round(self._lut * _LEVELS).astype(np.uint8).ravel()

    def separation(self, image_rgb: ImageRGB, box: BBox) -> float:
        """How well `box` [px] separates an object from its surround by colour: with the model learnt from
        this box (as `init` would, the current model untouched), the mean P(object | colour) inside the box
        minus the mean in the surround ring. Highest for a box on the object: a box shifted off it holds
        surround colours and leaves object colours in the ring."""
        _check_image(image_rgb)
        size = np.array([box.w_px, box.h_px])
        rows, cols = _pixel_slices(image_rgb.shape[:2], box.center, self.config.surround_factor * size)
        in_rows, in_cols = _pixel_slices(image_rgb.shape[:2], box.center, size)
        bins = self._bins_for(image_rgb)
        p_obj, p_surr = self._object_and_surround(image_rgb, box, None, (0, 0), bins)
        like = self._likelihood_lut(p_obj, p_surr).ravel()[bins.flat_index(image_rgb[rows, cols])]
        inside = np.zeros(like.shape, dtype=bool)
        inside[in_rows.start - rows.start : in_rows.stop - rows.start, in_cols.start - cols.start : in_cols.stop - cols.start] = True
        ring = ~inside
        if not ring.any():  # the surround is clipped away by the image border: nothing to separate from
            return 0.0
        return float(like[inside].mean() - like[ring].mean())

    def init(self, image_rgb: ImageRGB, box: BBox) -> None:
        """Learn the object colours inside `box` [px] (without its rim) and the surround colours in
        the ring around it; image_rgb: (H, W, 3) uint8. On a grey image the colours are grey levels (`grey`)."""
        _check_image(image_rgb)
        self._bins = self._bins_for(image_rgb)
        self._set_model(*self._object_and_surround(image_rgb, box, None, (0, 0), self._bins))

    def update(self, image_rgb: ImageRGB, refinement: BoxRefinement) -> bool:
        """Blend in the colours of an accepted refinement (object = its blob); False (no-op) if rejected."""
        if not refinement.accepted or self._p_obj is None or self._p_surr is None:
            return False  # learn only from accepted blobs
        _check_image(image_rgb)
        eta = self.config.learning_rate
        obj, surr = self._object_and_surround(image_rgb, refinement.box, refinement.mask, refinement.window_origin_px,
                                              self._bins)
        # p <- (1 - eta) p + eta p_new, per region
        self._set_model((1 - eta) * self._p_obj + eta * obj, (1 - eta) * self._p_surr + eta * surr)
        return True

    def _quantised_likelihood(self, image_rgb: ImageRGB) -> npt.NDArray[np.uint8]:
        """(h, w) round(255 P(target | colour)) of an (h, w, 3) uint8 RGB image or crop."""
        if self._p_obj is None:
            raise RuntimeError("ColourBoxRefiner.init must be called first")
        return np.take(self._lut_u8, self._bins.flat_index(image_rgb))  # = lut[flat bin], faster

    def likelihood_map(self, image_rgb: ImageRGB) -> npt.NDArray[np.float32]:
        """(h, w) P(target | colour) in [0, 1] (steps of 1/255) of an (h, w, 3) uint8 RGB image or crop."""
        _check_image(image_rgb)
        return self._quantised_likelihood(image_rgb).astype(np.float32) / np.float32(_LEVELS)

    def refine(self, image_rgb: ImageRGB, center_px: npt.ArrayLike, box: BBox,
               size_reference: BBox | None = None) -> BoxRefinement | None:
        """Tight box of the likelihood blob at `center_px` (x, y) [px], searched in a square window of
        side max(window_factor * max(w, h), min_window_px) of the previous `box`; None without a blob.
        `size_reference`: the tracker's own box (slowly scale-tracked), against which the blob's pixel
        count is tested (a blob spanning the target and a look-alike beside it is rejected)."""
        _check_image(image_rgb)
        cfg = self.config
        center = np.asarray(center_px, dtype=np.float64).reshape(2)
        side = max(cfg.window_factor * max(box.w_px, box.h_px), float(cfg.min_window_px))
        rows, cols = _pixel_slices(image_rgb.shape[:2], center, np.array([side, side]))
        if rows.stop <= rows.start or cols.stop <= cols.start:
            return None
        like = self._quantised_likelihood(image_rgb[rows, cols])
        otsu, _ = cv2.threshold(like, 0, 1, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
        threshold = float(np.clip(otsu, round(cfg.min_threshold * _LEVELS), round(cfg.max_threshold * _LEVELS)))
        fg = cast(Mask, cv2.threshold(like, threshold, 1, cv2.THRESH_BINARY)[1])  # fg = L > threshold
        if cfg.closing_radius_px > 0:
            fg = cast(Mask, cv2.morphologyEx(fg, cv2.MORPH_CLOSE, _square_kernel(cfg.closing_radius_px)))
        center_win = center - [cols.start, rows.start]
        blob = self._blob_at(fg, center_win)
        if blob is None:
            return None
        blob = self._without_lines(blob, center_win)
        return self._judge(like, blob, threshold / _LEVELS, box, (cols.start, rows.start), image_rgb.shape[:2],
                           size_reference)

    def _blob_at(self, fg: npt.NDArray[np.uint8], center_win: FloatArray) -> npt.NDArray[np.bool_] | None:
        """Mask of the 8-connected blob under the centre, else of the foreground pixel nearest to it
        within max_centre_gap_px; None when there is none."""
        n_labels, labels = cv2.connectedComponents(fg, connectivity=8)
        if n_labels <= 1:
            return None
        reach = self.config.max_centre_gap_px
        lo = np.clip(np.floor(center_win - reach), 0, [fg.shape[1] - 1, fg.shape[0] - 1]).astype(int)
        hi = np.clip(np.ceil(center_win + reach) + 1, lo + 1, [fg.shape[1], fg.shape[0]]).astype(int)
        near = labels[lo[1] : hi[1], lo[0] : hi[0]]
        ys, xs = np.nonzero(near)
        if ys.size == 0:
            return None
        d2 = (xs + lo[0] - center_win[0]) ** 2 + (ys + lo[1] - center_win[1]) ** 2
        nearest = int(np.argmin(d2))
        if d2[nearest] > reach**2 + _ON_PIXEL_D2:
            return None
        return labels == near[ys[nearest], xs[nearest]]

    def _without_lines(self, blob: npt.NDArray[np.bool_], center_win: FloatArray) -> npt.NDArray[np.bool_]:
        """The blob less the lines at most 2 opening_radius_px wide that touch it (road markings and kerbs
        beside a vehicle; the closing joins those 1-2 px off it): its opening's component under the centre,
        grown back by the radius within the blob, so the vehicle keeps its rim and corners and a line keeps
        a stub of at most the radius. The blob unchanged when nothing of it survives the opening (a target
        under 2 r + 1 px wide)."""
        radius = self.config.opening_radius_px
        if radius == 0:
            return blob
        kernel = _square_kernel(radius)
        core = self._blob_at(cast(Mask, cv2.morphologyEx(blob.astype(np.uint8), cv2.MORPH_OPEN, kernel)), center_win)
        if core is None:
            return blob
        return blob & (cv2.dilate(core.astype(np.uint8), kernel) > 0)

    def _judge(self, like: npt.NDArray[np.uint8], blob: npt.NDArray[np.bool_], threshold: float, previous: BBox,
               origin: tuple[int, int], image_hw: tuple[int, int], size_reference: BBox | None) -> BoxRefinement:
        """Tight box of the blob in the window at `origin` (x, y) and the plausibility tests on it."""
        cfg = self.config
        rows = np.flatnonzero(blob.any(axis=1))
        cols = np.flatnonzero(blob.any(axis=0))
        r0, r1, c0, c1 = int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])
        # tight box of pixel centres at integers: x = min col - 1/2, w = max col - min col + 1
        box = BBox(origin[0] + c0 - 0.5, origin[1] + r0 - 0.5, float(c1 - c0 + 1), float(r1 - r0 + 1))
        area_px = int(np.count_nonzero(blob))
        mean_in = float(like[blob].sum()) / area_px / _LEVELS
        n_out = like.size - box.w_px * box.h_px
        sum_out = float(like.sum(dtype=np.int64)) - float(like[r0 : r1 + 1, c0 : c1 + 1].sum(dtype=np.int64))
        contrast = mean_in - sum_out / n_out / _LEVELS if n_out > 0 else 0.0  # blob mean - mean outside its box
        h, w = blob.shape
        # window sides the blob touches, ignoring sides that are image borders (target leaving the view)
        touches = (
            (c0 == 0 and origin[0] > 0)
            + (r0 == 0 and origin[1] > 0)
            + (c1 == w - 1 and origin[0] + w < image_hw[1])
            + (r1 == h - 1 and origin[1] + h < image_hw[0])
        )
        area = box.w_px * box.h_px
        tracker_area = math.inf if size_reference is None else size_reference.w_px * size_reference.h_px
        grey_gates = self._bins.grey and size_reference is not None
        previous_area = previous.w_px * previous.h_px
        area_ratio = area / (min(previous_area, tracker_area) if grey_gates else previous_area)
        fill, span = area_px / tracker_area, area / tracker_area  # of the tracker's box (0 without one)
        rejection = ""
        if not cfg.min_area_ratio <= area_ratio <= cfg.max_area_ratio:
            rejection = f"area ratio {area_ratio:.2f} outside [{cfg.min_area_ratio}, {cfg.max_area_ratio}]"
        elif fill > cfg.max_blob_fill_ratio:
            rejection = f"blob fills {fill:.2f} > {cfg.max_blob_fill_ratio} of the tracker's box"
        elif grey_gates and fill < cfg.grey_min_blob_fill_ratio and span < cfg.grey_min_blob_span_ratio:
            rejection = (f"grey blob fills {fill:.2f} < {cfg.grey_min_blob_fill_ratio} of the tracker's box and spans "
                         f"{span:.2f} < {cfg.grey_min_blob_span_ratio} of it")
        elif touches > cfg.max_border_sides:
            rejection = f"blob touches {touches} window sides"
        elif contrast <= cfg.min_contrast:
            rejection = f"contrast {contrast:.2f} <= {cfg.min_contrast}"
        return BoxRefinement(box, area_px, mean_in, contrast, threshold, not rejection, rejection, blob, origin)
