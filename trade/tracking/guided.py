"""The image side of TRADE: the correlation filter guided by the trajectory prediction, per frame.

Owns the DCF and the colour model, the boxes carried into each frame by the camera's rotation (from the pose),
the choice of a peak near the trajectory prediction (with the constant-image-velocity window as a second
opinion), re-detection while lost (inside the prediction's validation gate, with the boxes sized by its depth),
the output box (colour-blob refinement, or coasting on the prediction) and the optional snapping of the initial
box. Its settings are `GuidedTrackerConfig`; the DCF and the colour refiner are injected (built from the config
when not given).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from trade.geometry import RotationWarp
from trade.tracking.colour_box import BoxRefinement, ColourBoxRefiner
from trade.tracking.dcf import DcfTracker
from trade.tracking.guided_config import GuidedTrackerConfig, blob_size_tolerance
from trade.tracking.peaks import PeakChoice, highest_peak, peaks_above, select_peak
from trade.types import BBox, PixelPrediction

FloatArray = npt.NDArray[np.float64]
ImageRGB = npt.NDArray[np.uint8]
T = TypeVar("T")


BOX_SIDE_QUANTUM_PX = 1.0
"""A colour blob's box is measured to a pixel a side: the box-area bound allows its reference that much more (a 5 px
wide car's blob box flickered between 4 and 7 px from frame to frame in the quick suite's 128 px city camera)."""


def _after_init(value: T | None) -> T:
    """`value`, one of the tracker's states that `GuidedTracker.init` sets; RuntimeError before init."""
    if value is None:
        raise RuntimeError("GuidedTracker.init must be called before using the tracker")
    return value


@dataclass(frozen=True, eq=False)
class TrackedFrame:
    """One frame's image tracking: the output box [px] (the coasting box when not tracked), the peak
    chosen and whether it passed (a fresh box this frame)."""

    box: BBox
    choice: PeakChoice
    tracked: bool


def _inside(pixel: FloatArray, image_rgb: ImageRGB) -> bool:
    """Whether (x, y) [px] is finite and inside the image."""
    h, w = image_rgb.shape[:2]
    return bool(np.all(np.isfinite(pixel)) and 0 <= pixel[0] < w and 0 <= pixel[1] < h)


class GuidedTracker:
    """`init(image, box)` once, then `step(image, prediction)` per frame (`PixelPrediction.none()` when
    there is no trajectory prediction). `dcf` and `refiner` default to ones built from `config.dcf` and
    `config.colour_box`; the search window is the DCF's (its `config.padding` x its box)."""

    def __init__(self, config: GuidedTrackerConfig, dcf: DcfTracker | None = None,
                 refiner: ColourBoxRefiner | None = None) -> None:
        self.config = config
        self.dcf = dcf if dcf is not None else DcfTracker(config.dcf)
        self.refiner = refiner if refiner is not None else ColourBoxRefiner(config.colour_box)
        self._box: BBox | None = None  # last output box
        # last frame-to-frame shift of the tracked box centre (x, y), less the camera's rotation, of a confident peak
        # (zero after a weak or ambiguous one: `GuidedTrackerConfig.motion_min_peak_score`)
        self._image_motion_px = np.zeros(2)
        self._tracked_last = True  # whether the previous frame was tracked (its shift is then current)
        # the last tracked frame's prediction, DCF box and output box (the sizes depth scaling starts from)
        self._last_tracked: tuple[PixelPrediction, BBox, BBox] | None = None
        # the last measured output box (the initial box or an accepted colour blob) and the depth [m] it was seen
        # at (NaN until a depth is known), from which a refused frame's box is sized
        self._measured: tuple[BBox, float] | None = None
        # the DCF box's width [px] and the predicted depth [m] at the reference frame (the first tracked frame with a
        # known depth, the last depth jump or the last accepted blob), from which its size is bounded (`_depth_bounded`)
        self._dcf_reference: tuple[float, float] | None = None
        self._previous_depth_m = math.nan  # the last known predicted depth [m] of a tracked frame
        # the pixel count and box of the target's blob and the predicted depth [m] it was seen at (NaN: not known): the
        # initial box's area and no box (the initial box is not a blob's), then each blob taken as the target's
        # (`_accept_as_target`)
        self._target_blob: tuple[float, BBox | None, float] | None = None
        rings = np.arange(-config.reacquire_rings, config.reacquire_rings + 1)
        grid = np.stack(np.meshgrid(rings, rings), axis=-1).reshape(-1, 2).astype(np.float64)
        # (x, y) offsets of the re-detection windows in steps, the centre first
        self._reacquire_offsets = grid[np.argsort(np.abs(grid).max(axis=1), kind="stable")]

    def init(self, image_rgb: ImageRGB, box: BBox) -> BBox:
        """Learn the target in `box` [px] (snapped to its colour blob when configured); the box used."""
        self.refiner.init(image_rgb, box)
        if self.config.snap_init_box:
            box = self._snapped(image_rgb, box)
        self.dcf.init(image_rgb, box)
        self._box = box
        self._image_motion_px = np.zeros(2)
        self._tracked_last = True
        self._last_tracked = (PixelPrediction.none(), box, box)
        self._measured = (box, math.nan)
        self._dcf_reference = None
        self._previous_depth_m = math.nan
        self._target_blob = (box.w_px * box.h_px, None, math.nan)
        return box

    def step(self, image_rgb: ImageRGB, prediction: PixelPrediction,
             rotation: RotationWarp | None = None) -> TrackedFrame:
        """Track into the next frame, guided by the trajectory model's `prediction`; `rotation` is the camera's
        rotation since the last step (`GuidedTrackerConfig.follow_camera_rotation`; None: not known, no warp)."""
        cfg = self.config
        predicted_px = prediction.centre_px
        if rotation is not None and cfg.trajectory_guidance and cfg.follow_camera_rotation:
            self._carry(rotation)
        if self._tracked_last or not cfg.trajectory_guidance:
            choice, scale = self._choose_peak(image_rgb, predicted_px)
            tracked = choice.score >= cfg.min_peak_score or not cfg.trajectory_guidance
        else:
            self._size_by_depth(prediction)
            choice, scale, tracked = self._redetect(image_rgb, prediction)
        if tracked:
            previous_px = self.dcf.box.center
            dcf_box = self.dcf.commit(choice.location_px, self._depth_bounded(scale, prediction))
            confident = not choice.ambiguous and choice.score >= cfg.motion_min_peak_score
            self._image_motion_px = dcf_box.center - previous_px if confident else np.zeros(2)
            box = self._refine_box(image_rgb, dcf_box, prediction, learn=not choice.ambiguous)
            if not choice.ambiguous:
                self.dcf.update(image_rgb)  # at the box as the blob bound left it
        else:
            box = self._coast_box(image_rgb, predicted_px)
            # the last shift is stale once a frame goes untracked: no constant-image-velocity guess
            self._image_motion_px = np.zeros(2)
        self._tracked_last = tracked
        self._box = box
        if tracked:
            self._last_tracked = (prediction, self.dcf.box, box)
        return TrackedFrame(box, choice, tracked)

    def _carry(self, rotation: RotationWarp) -> None:
        """Move the DCF and output boxes' centres to where the camera's rotation since the last frame puts them
        (sizes kept; the DCF's is clamped to the image as on every commit, and a centre whose ray turns behind the
        camera stays). The box's next shift is then measured from the carried centre, so the constant image velocity
        of `_choose_peak` is the target's own motion in the image, not the camera's last turn."""
        centre = rotation.apply(self.dcf.box.center)
        if np.all(np.isfinite(centre)):
            self.dcf.commit(centre)
        box = _after_init(self._box)
        centre = rotation.apply(box.center)
        if np.all(np.isfinite(centre)):
            self._box = BBox.from_center(centre[0], centre[1], box.w_px, box.h_px)

    def _depth_known(self, prediction: PixelPrediction) -> bool:
        """Whether the prediction's depth is positive and known to coast_scale_max_relative_sigma (False
        for NaN)."""
        return bool(prediction.depth_m > 0
                    and prediction.depth_sigma_m <= self.config.coast_scale_max_relative_sigma * prediction.depth_m)

    def _depth_bounded(self, scale: float, prediction: PixelPrediction) -> float:
        """The DSST `scale` to commit, limited so that the DCF box's width stays within `dcf_size_depth_tolerance`
        of the width the depth predicts: its width at the reference frame, scaled by the ratio of that frame's
        depth to this one's. The reference is the first tracked frame with a known depth, and again every frame
        whose depth differs from the last known one by more than `dcf_reference_max_depth_step` (a new 3D
        estimate, not motion) or whose colour blob was accepted (`_bound_by_blob`)."""
        tolerance = self.config.dcf_size_depth_tolerance
        if math.isinf(tolerance) or not self._depth_known(prediction):
            return scale
        depth_m, width_px = prediction.depth_m, self.dcf.box.w_px
        previous_m, self._previous_depth_m = self._previous_depth_m, depth_m
        if self._dcf_reference is None or abs(depth_m / previous_m - 1.0) > self.config.dcf_reference_max_depth_step:
            self._dcf_reference = (width_px, depth_m)
            return scale
        reference_px, reference_depth_m = self._dcf_reference
        expected_px = reference_px * reference_depth_m / depth_m
        bounded_px = min(max(width_px * scale, expected_px / tolerance), expected_px * tolerance)
        return bounded_px / width_px

    def _size_by_depth(self, prediction: PixelPrediction) -> None:
        """While lost, scale the DCF and output boxes from their size at the last tracked frame by the ratio
        of that frame's predicted depth to this one's (GuidedTrackerConfig.coast_scale_from_depth), when both
        are known."""
        then, dcf_then, output_then = _after_init(self._last_tracked)
        if not (self.config.coast_scale_from_depth and self._depth_known(then) and self._depth_known(prediction)):
            return
        factor = then.depth_m / prediction.depth_m
        box = self.dcf.box
        self.dcf.commit(box.center, factor * dcf_then.w_px / box.w_px)  # the DCF box scales isotropically
        centre = _after_init(self._box).center
        self._box = BBox.from_center(centre[0], centre[1], factor * output_then.w_px, factor * output_then.h_px)

    def _best_separating(self, image_rgb: ImageRGB, box: BBox) -> BBox:
        """The given box moved by the whole-px offset, up to snap_search_fraction of its shorter side along
        each axis, whose colours best separate from its surround (the given box on ties and without search)."""
        reach = math.floor(self.config.snap_search_fraction * min(box.w_px, box.h_px))
        best, best_separation = box, self.refiner.separation(image_rgb, box)
        for dy in range(-reach, reach + 1):
            for dx in range(-reach, reach + 1):
                shifted = BBox(box.x_px + dx, box.y_px + dy, box.w_px, box.h_px)
                if (dx or dy) and _inside(shifted.center, image_rgb):
                    separation = self.refiner.separation(image_rgb, shifted)
                    if separation > best_separation:
                        best, best_separation = shifted, separation
        return best

    def _snapped(self, image_rgb: ImageRGB, box: BBox) -> BBox:
        """The colour blob of the target under the given box: the box first moved to where its colours
        best separate from their surround (`_best_separating`), then the blob at its centre, with the
        colours relearnt from the blob `snap_iterations` times (a box a few px off mixes ground into the
        first model, and the blob's contrast is then too low to accept); the blob's tight box when the
        refiner accepts the last one (colours learnt from it), else the moved box (colours learnt from it)."""
        box = self._best_separating(image_rgb, box)
        self.refiner.init(image_rgb, box)
        candidate = box
        for _ in range(self.config.snap_iterations):
            refinement = self.refiner.refine(image_rgb, candidate.center, box, size_reference=box)
            if refinement is None:
                break
            candidate = refinement.box
            self.refiner.init(image_rgb, candidate)
        final = self.refiner.refine(image_rgb, candidate.center, box, size_reference=box)
        snapped = final.box if final is not None and final.accepted and self._similar_size(final.box, box) else box
        self.refiner.init(image_rgb, snapped)
        return snapped

    def _similar_size(self, box: BBox, reference: BBox) -> bool:
        """Whether width and height each lie within snap_max_side_ratio of the reference's."""
        ratio = self.config.snap_max_side_ratio
        sides = np.array([box.w_px / reference.w_px, box.h_px / reference.h_px])
        return bool(np.all((sides <= ratio) & (sides >= 1.0 / ratio)))

    def _choose_peak(self, image_rgb: ImageRGB, predicted_px: FloatArray) -> tuple[PeakChoice, float]:
        last_px = self.dcf.box.center
        if not self.config.trajectory_guidance:
            response = self.dcf.response(image_rgb, last_px)
            return highest_peak(response, self.config.peaks), response.scale
        guided = _inside(predicted_px, image_rgb)
        motion_px = last_px + self._image_motion_px  # where constant image velocity puts the target
        choice, scale = self._select(image_rgb, predicted_px if guided else motion_px)
        if not (guided and self._far_apart(predicted_px, motion_px)):
            return choice, scale
        # The prediction is only as good as the 3D estimate behind it (e.g. a roof taken for the ground
        # puts the target at a wrong depth and the prediction drifts off it). When it has moved the
        # window far from where the box's last image shift (constant image velocity) puts the target,
        # search there too and keep that peak if the prediction's would not even be a candidate beside
        # it (softmax ratio below candidate_fraction): s_motion - s_pred > T ln(1 / candidate_fraction).
        alt, alt_scale = self._select(image_rgb, motion_px)
        peaks = self.config.peaks
        if alt.score - choice.score > peaks.softmax_temperature * math.log(1.0 / peaks.candidate_fraction):
            return alt, alt_scale
        return choice, scale

    def _redetect(self, image_rgb: ImageRGB, prediction: PixelPrediction) -> tuple[PeakChoice, float, bool]:
        """While lost. The candidates are the peaks scoring at least reacquire_min_peak_score in the window at
        the prediction (at the last box when the prediction is not in the image) and in the windows on the
        grid around it, inside the prediction's validation gate. They are tried most probable first: the
        appearance likelihood exp(score / T) of the paper's softmax times the prediction's Gaussian
        exp(-d^2 / 2), so a fully visible lookalike beside a target that is only coming out from under an
        occluder loses to it. A candidate is taken (tracked) when its colour blob passes the refiner's tests,
        or, in the prediction's window, when it scores at least reacquire_confident_score (a re-emerging
        target shows only part of its blob). With none, the paper's peak in the prediction's window (not
        tracked). Returns the choice, its DSST scale, whether tracked."""
        cfg, box = self.config, self.dcf.box
        centre_px = prediction.centre_px if _inside(prediction.centre_px, image_rgb) else box.center
        distance2 = self._gate_distance2(prediction)
        step_px = cfg.reacquire_step_fraction * self.dcf.config.padding * np.array([box.w_px, box.h_px])
        centre_response = self.dcf.response(image_rgb, centre_px, with_scale=False)
        ranked: list[tuple[float, bool, PeakChoice]] = []  # (log posterior, in the prediction's window, peak)
        for offset in self._reacquire_offsets:  # [0] is the prediction's window
            centre = centre_px + offset * step_px
            central = not offset.any()
            if not (central or _inside(centre, image_rgb)):
                continue
            response = centre_response if central else self.dcf.response(image_rgb, centre, with_scale=False)
            for peak in peaks_above(response, cfg.reacquire_min_peak_score, cfg.peaks):
                d2 = distance2(peak.location_px)
                if d2 <= cfg.reacquire_gate_chi2:
                    ranked.append((peak.score / cfg.peaks.softmax_temperature - 0.5 * d2, central, peak))
        for _, central, peak in sorted(ranked, key=lambda r: -r[0]):
            if ((central and peak.score >= cfg.reacquire_confident_score)
                    or self._colour_confirms(image_rgb, peak.location_px)):
                return peak, self.dcf.estimate_scale(image_rgb, peak.location_px), True
        return select_peak(centre_response, cfg.peaks), 1.0, False

    def _gate_distance2(self, prediction: PixelPrediction) -> Callable[[FloatArray], float]:
        """Squared Mahalanobis distance d^2 = r^T (C + s^2 I)^-1 r of a pixel from the prediction (see
        GuidedTrackerConfig.reacquire_gate_chi2); 0 everywhere without a prediction."""
        if not prediction.valid:
            return lambda location_px: 0.0
        box = self.dcf.box
        sigma_px = self.config.reacquire_gate_box_sigma * max(box.w_px, box.h_px)
        information = np.linalg.inv(prediction.covariance_px2 + sigma_px**2 * np.eye(2))

        def distance2(location_px: FloatArray) -> float:
            offset = np.asarray(location_px) - prediction.centre_px
            return float(offset @ information @ offset)

        return distance2

    def _colour_confirms(self, image_rgb: ImageRGB, location_px: FloatArray) -> bool:
        """Whether the target's colour model finds a plausible blob of the target's size at `location_px`."""
        refinement = self.refiner.refine(image_rgb, location_px, _after_init(self._box), size_reference=self.dcf.box)
        return refinement is not None and refinement.accepted

    def _select(self, image_rgb: ImageRGB, centre_px: FloatArray) -> tuple[PeakChoice, float]:
        """The paper's peak choice in the window centred at `centre_px`, and the DSST scale there."""
        response = self.dcf.response(image_rgb, centre_px)
        choice = select_peak(response, self.config.peaks)
        # response.scale was estimated at the highest peak; re-estimate only when another peak won
        if choice.score < float(response.scores.max()):
            return choice, self.dcf.estimate_scale(image_rgb, choice.location_px)
        return choice, response.scale

    def _far_apart(self, predicted_px: FloatArray, motion_px: FloatArray) -> bool:
        """Whether the trajectory prediction is offset from the constant-image-velocity one by more than
        `second_window_offset_fraction` of the search window along either axis."""
        box, fraction = self.dcf.box, self.config.second_window_offset_fraction
        window = self.dcf.config.padding * np.array([box.w_px, box.h_px])
        return bool(np.any(np.abs(np.asarray(predicted_px) - motion_px) > fraction * window))

    def _refine_box(self, image_rgb: ImageRGB, dcf_box: BBox, prediction: PixelPrediction, learn: bool) -> BBox:
        """The output box: the target's colour blob around the DCF centre when the refiner accepts it and it holds the
        target alone (`_accept_as_target`), else a box centred on the DCF location with the last output box's size,
        or with `size_refused_box_by_depth` sized by depth from the last measured box (`_measured_size`)."""
        centre = dcf_box.center
        if not self.config.box_refinement:
            return dcf_box
        last = _after_init(self._box)
        refinement = self.refiner.refine(image_rgb, centre, last, size_reference=dcf_box)
        if refinement is None or not refinement.accepted or not self._accept_as_target(refinement, prediction):
            w_px, h_px = (self._measured_size(prediction) if self.config.size_refused_box_by_depth
                          else (last.w_px, last.h_px))
            return BBox.from_center(centre[0], centre[1], w_px, h_px)
        if learn:
            self.refiner.update(image_rgb, refinement)
        if self.config.size_refused_box_by_depth:
            self._measured = (refinement.box, self._known_depth_m(prediction))
        self._bound_by_blob(refinement.box, prediction)
        return refinement.box

    def _bound_by_blob(self, blob: BBox, prediction: PixelPrediction) -> None:
        """Move the DCF box's centre to the target's blob's (`dcf_centre_from_blob`), and its size (the square root of
        the area) towards `GuidedTrackerConfig.dcf_size_blob_tolerance` of the blob box's by at most one DSST scale
        step (`dcf_size_from_blob`); with the size on, make this frame the depth bound's reference when its depth is
        known (the blob has just measured the size the depth bound extrapolates)."""
        cfg, box = self.config, self.dcf.box
        size_px, blob_px = math.sqrt(box.w_px * box.h_px), math.sqrt(blob.w_px * blob.h_px)
        bounded_px = size_px
        if cfg.dcf_size_from_blob:
            step = self.dcf.config.scale.scale_step  # from the components in use: they may be injected
            tolerance = blob_size_tolerance(self.refiner.config.max_blob_fill_ratio, step)
            bounded_px = min(max(size_px, blob_px / tolerance), blob_px * tolerance)
            bounded_px = min(max(bounded_px, size_px / step), size_px * step)
        if cfg.dcf_centre_from_blob or bounded_px != size_px:
            box = self.dcf.commit(blob.center if cfg.dcf_centre_from_blob else box.center, bounded_px / size_px)
        if cfg.dcf_size_from_blob and self._depth_known(prediction):
            self._dcf_reference = (box.w_px, prediction.depth_m)

    def _accept_as_target(self, refinement: BoxRefinement, prediction: PixelPrediction) -> bool:
        """Whether a blob the refiner accepted holds the target alone, and if so make it the target's: its pixel count
        is at most `GuidedTrackerConfig.blob_max_pixel_ratio` times the target's last blob's and its box's area at
        most `blob_max_box_area_ratio` times that of the last blob's box grown by `BOX_SIDE_QUANTUM_PX` a side (both
        scaled by the ratio of that blob's depth to the predicted one when both are known), or its pixel count is at
        most the DCF box's area."""
        pixels, last, depth_m = _after_init(self._target_blob)
        scale = 1.0  # apparent size ~ 1 / depth
        if self._depth_known(prediction) and not math.isnan(depth_m):
            scale = depth_m / prediction.depth_m
        cfg, dcf_box, blob = self.config, self.dcf.box, refinement.box
        grown = refinement.area_px > cfg.blob_max_pixel_ratio * (pixels * scale ** 2)
        if last is not None:
            last_area_px = (last.w_px * scale + BOX_SIDE_QUANTUM_PX) * (last.h_px * scale + BOX_SIDE_QUANTUM_PX)
            grown = grown or blob.w_px * blob.h_px > cfg.blob_max_box_area_ratio * last_area_px
        if grown and refinement.area_px > dcf_box.w_px * dcf_box.h_px:
            return False
        self._target_blob = (float(refinement.area_px), blob, self._known_depth_m(prediction))
        return True

    def _known_depth_m(self, prediction: PixelPrediction) -> float:
        """The prediction's depth [m] when known (`_depth_known`), else NaN: the depth a measured size is tagged with."""
        return prediction.depth_m if self._depth_known(prediction) else math.nan

    def _measured_size(self, prediction: PixelPrediction) -> tuple[float, float]:
        """(w, h) [px] of a frame whose blob the refiner refused (`GuidedTrackerConfig.size_refused_box_by_depth`
        says why): the last measured box scaled by the ratio of the depth it was seen at to the predicted depth
        (apparent size ~ 1 / depth) when both are known, else the last output box's size. A box measured before
        the first 3D fix is given the first known depth as its own here (the DSST scale is no substitute for the
        depth: it drifts on a turning target)."""
        box, depth_m = _after_init(self._measured)
        if not self._depth_known(prediction):
            last = _after_init(self._box)
            return last.w_px, last.h_px
        if math.isnan(depth_m):
            self._measured = (box, prediction.depth_m)
            return box.w_px, box.h_px
        factor = depth_m / prediction.depth_m
        return factor * box.w_px, factor * box.h_px

    def _coast_box(self, image_rgb: ImageRGB, predicted_px: FloatArray) -> BBox:
        """While lost, the box follows the trajectory prediction with its last size."""
        last = _after_init(self._box)
        if not _inside(predicted_px, image_rgb):
            return last
        return BBox.from_center(predicted_px[0], predicted_px[1], last.w_px, last.h_px)
