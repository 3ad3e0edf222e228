"""Single-image relative inverse depth (MiDaS-like) from the shipped ONNX model, run by onnxruntime.

Owns the verified model loader (`SingleImageDepth`, `DepthModelError`), the input normalisation shared with
training, and the held-out metric: AbsRel / delta1 after per-frame scale-and-shift alignment in inverse depth.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt
import onnxruntime as ort

from trade.model_file import ModelFileError, check_sha256_format, open_verified_session, shipped_assets_dir

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

MODEL_DIR = shipped_assets_dir() / "models"  # the repo's assets/models (the stack does not import trade_gym)
DEFAULT_MODEL = MODEL_DIR / "depth_small.onnx"
# SHA-256 of the shipped model, printed by scripts/train_depth.py and recorded in depth_small.md
DEFAULT_MODEL_SHA256 = "82900bd52585efdd31317b379029b47c3d76f7f5fc9457e7eeeb6fbcec9418fb"
DEFAULT_INPUT_SIZE_PX = 128
RGB_MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)  # per channel, of rgb / 255
RGB_STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)
UINT8_MAX = 255.0
DELTA1_RATIO = 1.25  # delta1 = fraction of pixels with max(d'/d, d/d') < 1.25
SKY_DEPTH_FRACTION = 0.99  # depth >= this x far_m: nothing was hit (sky), not a valid target


class DepthModelError(ModelFileError):
    """The depth model file is missing, empty, truncated, tampered with or not a usable model."""


def to_network_input(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """rgb (N, H, W, 3) or (H, W, 3) uint8 -> (N, 3, H, W) float32: x = (rgb / 255 - mean) / std."""
    batch = np.asarray(rgb)[None] if np.ndim(rgb) == 3 else np.asarray(rgb)
    x = (batch.astype(np.float32) / np.float32(UINT8_MAX) - RGB_MEAN) / RGB_STD
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2))


def valid_depth_mask(depth_m: npt.ArrayLike, far_m: float) -> BoolArray:
    """(H, W) true where the renderer hit something: finite, > 0 and < SKY_DEPTH_FRACTION far_m [m]."""
    d = np.asarray(depth_m, dtype=np.float64)
    return np.isfinite(d) & (d > 0.0) & (d < SKY_DEPTH_FRACTION * far_m)


class SingleImageDepth:
    """Relative inverse depth of one RGB image; the model file is checked against `expected_sha256` on load.

    Single-threaded, sequential onnxruntime session (deterministic, leaves the cores to the env).
    """

    def __init__(self, model_path: str | Path = DEFAULT_MODEL, expected_sha256: str = DEFAULT_MODEL_SHA256,
                 input_size_px: int = DEFAULT_INPUT_SIZE_PX) -> None:
        check_sha256_format(expected_sha256)
        if int(input_size_px) != input_size_px or input_size_px <= 0:
            raise ValueError(f"input_size_px must be a positive integer, got {input_size_px!r}")
        self.model_path = Path(model_path)
        self.input_size_px = int(input_size_px)
        self._session = open_verified_session(self.model_path, expected_sha256, "depth model file", DepthModelError)
        self._input_name = _check_io(self._session, self.model_path, self.input_size_px)

    def predict(self, rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
        """rgb (H, W, 3) uint8 -> (H, W) float32 relative inverse depth (affine in 1 / z, larger = nearer)."""
        img = np.asarray(rgb)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or min(img.shape[:2]) == 0:
            raise ValueError(f"rgb must be a non-empty (H, W, 3) uint8 image, got {img.shape} {img.dtype}")
        h, w = img.shape[:2]
        s = self.input_size_px
        shrink = h > s or w > s
        # cv2.resize keeps the dtype (its stubs say only "an integer or float array")
        resized = cast(npt.NDArray[np.uint8], cv2.resize(img, (s, s), interpolation=cv2.INTER_AREA if shrink
                                                         else cv2.INTER_LINEAR))
        (out,) = self._session.run(None, {self._input_name: to_network_input(resized)})
        inv = np.asarray(out, dtype=np.float32).reshape(s, s)
        if (h, w) == (s, s):
            return inv
        return cast(npt.NDArray[np.float32], cv2.resize(inv, (w, h), interpolation=cv2.INTER_LINEAR))


def _check_io(session: ort.InferenceSession, path: Path, size_px: int) -> str:
    """Name of the single (N, 3, size, size) float input; DepthModelError if the model's I/O does not fit."""
    inputs, outputs = session.get_inputs(), session.get_outputs()
    if len(inputs) != 1 or len(outputs) != 1:
        raise DepthModelError(f"depth model file {path} must have one input and one output, "
                              f"got {len(inputs)} and {len(outputs)}")
    shape = list(inputs[0].shape)
    fixed = [d for d in shape[1:] if isinstance(d, int)]
    if len(shape) != 4 or inputs[0].type != "tensor(float)" or fixed != [3, size_px, size_px]:
        raise DepthModelError(f"depth model file {path} expects input {inputs[0].type} {shape}, "
                              f"not float (N, 3, {size_px}, {size_px})")
    return inputs[0].name


def align_scale_shift(pred_inv: npt.ArrayLike, target_inv: npt.ArrayLike,
                      mask: npt.ArrayLike) -> tuple[float, float]:
    """Least squares (s, t) = argmin sum_mask (s pred + t - target)^2; s = 0 if pred is constant on mask."""
    m = np.asarray(mask, dtype=bool)
    p = np.asarray(pred_inv, dtype=np.float64)[m]
    r = np.asarray(target_inv, dtype=np.float64)[m]
    if p.size == 0:
        raise ValueError("align_scale_shift needs at least one pixel in mask")
    dp, dr = p - p.mean(), r - r.mean()
    var = float(dp @ dp)
    # s = cov(p, r) / var(p); t = mean(r) - s mean(p)
    s = float(dp @ dr) / var if var > 0.0 else 0.0
    return s, float(r.mean() - s * p.mean())


@dataclass(frozen=True)
class DepthMetrics:
    """Per-frame depth accuracy after alignment: AbsRel = mean |d' - d| / d, delta1, the fit and pixel count."""

    abs_rel: float
    delta1: float
    scale: float
    shift: float
    valid_px: int


def depth_metrics_after_alignment(pred_inv: npt.ArrayLike, depth_m: npt.ArrayLike,
                                  valid: npt.ArrayLike) -> DepthMetrics:
    """pred_inv (H, W) relative inverse depth, depth_m (H, W) ground truth [m], valid (H, W) bool.

    Aligns pred to 1 / depth_m on `valid` (least squares in inverse depth), caps the aligned inverse depth
    below at 1 / max(depth_m[valid]) (so no pixel goes negative or beyond the frame's farthest point), then
    d' = 1 / aligned and scores d' against depth_m on `valid`.
    """
    v = np.asarray(valid, dtype=bool) & valid_depth_mask(depth_m, np.inf)
    d = np.asarray(depth_m, dtype=np.float64)[v]
    if d.size == 0:
        raise ValueError("depth_metrics_after_alignment needs at least one valid pixel")
    p = np.asarray(pred_inv, dtype=np.float64)[v]
    s, t = align_scale_shift(p, 1.0 / d, np.ones(d.size, dtype=bool))
    aligned = np.maximum(s * p + t, 1.0 / d.max())
    d_pred = 1.0 / aligned
    ratio = np.maximum(d_pred / d, d / d_pred)
    return DepthMetrics(float(np.mean(np.abs(d_pred - d) / d)), float(np.mean(ratio < DELTA1_RATIO)), s, t,
                        int(d.size))


def abs_rel_after_alignment(pred_inv: npt.ArrayLike, depth_m: npt.ArrayLike, valid: npt.ArrayLike) -> float:
    """AbsRel of `depth_metrics_after_alignment` (the issue's held-out target is <= 0.15)."""
    return depth_metrics_after_alignment(pred_inv, depth_m, valid).abs_rel
