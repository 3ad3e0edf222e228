"""Variants of the shipped textures for appearance randomisation, written once per process to a cache directory.

pybullet keeps a loaded texture by its file name (a second `loadTexture` of one name reads no file and adds no memory;
a new name per reset grew the process by ~130 kB a reset, measured), so the variants are a finite set of files.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from trade_gym.sim.meshes import texture_path
from trade_gym.sim.vehicles import PALETTE_CELL_PX

Image = npt.NDArray[np.uint8]
OPENCV_HUE_PER_DEG = 0.5  # OpenCV's 8-bit hue runs 0-179 for 0-360 deg
_cache: tempfile.TemporaryDirectory | None = None  # removed when the interpreter exits


def variant_path(name: str, key: str, make: Callable[[Image], Image]) -> Path:
    """The file of variant `key` of texture `name`: `make` applied to its (H, W, 3) RGB pixels, written on first use
    (one key must always mean the same pixels: pybullet serves a name it has loaded from memory)."""
    global _cache
    if _cache is None:
        _cache = tempfile.TemporaryDirectory(prefix="trade_gym_textures_")
    path = Path(_cache.name) / f"{name}-{key}.png"
    if not path.is_file():
        bgr = cv2.imread(str(texture_path(name)), cv2.IMREAD_COLOR)
        if bgr is None:
            raise OSError(f"could not read texture {texture_path(name)}")
        rgb = cast(Image, bgr[:, :, ::-1])  # IMREAD_COLOR gives 8-bit BGR
        partial = path.with_name(f"partial-{os.getpid()}-{path.name}")
        if not cv2.imwrite(str(partial), np.ascontiguousarray(make(rgb)[:, :, ::-1])):
            raise OSError(f"could not write texture variant {partial}")
        os.replace(partial, path)  # never a half-written file under the final name
    return path


def ground_variant(rgb: Image, quarter_turns: int, detail: int, contrast: float) -> Image:
    """A tiling ground texture turned by `quarter_turns` x 90 deg, its pattern `detail` times finer (tiled detail x
    detail and shrunk back to its size, so it still tiles) and its contrast about the mean scaled by `contrast`."""
    h, w = rgb.shape[:2]
    out = np.rot90(rgb, quarter_turns)
    if detail > 1:
        out = cast(Image, cv2.resize(np.tile(out, (detail, detail, 1)), (w, h), interpolation=cv2.INTER_AREA))
    out = out.astype(np.float64)
    mean = out.mean(axis=(0, 1))
    return np.clip(np.rint(mean + contrast * (out - mean)), 0, 255).astype(np.uint8)


def palette_variant(rgb: Image, cells: tuple[int, ...], hue_shift_deg: float) -> Image:
    """The vehicle palette with the hue of its cells `cells` (indices into `vehicles.PALETTE_RGB`) turned by
    `hue_shift_deg`; the other cells (glass, tyres, lamps) as they are."""
    hsv = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV)
    shifted = hsv.copy()
    shifted[:, :, 0] = ((hsv[:, :, 0].astype(np.int64) + round(hue_shift_deg * OPENCV_HUE_PER_DEG)) % 180)
    turned = cv2.cvtColor(shifted, cv2.COLOR_HSV2RGB)
    out = rgb.copy()
    for cell in cells:
        columns = slice(cell * PALETTE_CELL_PX, (cell + 1) * PALETTE_CELL_PX)
        out[:, columns] = turned[:, columns]
    return out
