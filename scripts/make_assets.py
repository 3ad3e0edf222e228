"""Generate the seamless ground/building/rock textures and the vehicle palette into assets/textures/.

Deterministic (fixed seeds): re-running reproduces identical PNGs. Usage: python scripts/make_assets.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from trade_gym.sim.meshes import TEXTURE_DIR, TEXTURE_PERIOD_M  # noqa: E402
from trade_gym.sim.vehicles import PALETTE_CELL_PX, PALETTE_RGB  # noqa: E402

SEED = 7
SIZE_PX = {"desert_ground": 256, "city_ground": 256, "mountain_ground": 256, "roof": 256, "facade": 128,
           "dirt_road": 128, "rock": 64}
MAX_TOTAL_BYTES = 2_000_000


def noise(size: int, feature_px: float, rng: np.random.Generator) -> np.ndarray:
    """Tileable band-limited noise, unit std: white noise low-passed in Fourier space (periodic)."""
    f = np.fft.fftfreq(size)
    r2 = f[:, None] ** 2 + f[None, :] ** 2
    spectrum = np.fft.fft2(rng.standard_normal((size, size))) * np.exp(-r2 * (np.pi * feature_px) ** 2 / 2.0)
    out = np.real(np.fft.ifft2(spectrum))
    return out / out.std()


def wrapped(size: int, draw) -> None:
    """Call draw(dx, dy) for the 9 periodic copies so shapes crossing an edge wrap around."""
    for dx in (-size, 0, size):
        for dy in (-size, 0, size):
            draw(dx, dy)


def blobs(img: np.ndarray, count: int, radius_px: tuple, shades: tuple, rng, shadow_px: int = 1) -> None:
    """Random rotated ellipses (pebbles, patches) scaling the colour by a random shade, with a shadow."""
    size = img.shape[0]
    for _ in range(count):
        c = rng.uniform(0, size, 2)
        axes = rng.uniform(*radius_px, 2)
        angle, shade = rng.uniform(0, 180), rng.uniform(*shades)
        tint = np.clip(img[int(c[1]) % size, int(c[0]) % size] * shade * rng.uniform(0.92, 1.08, 3), 0, 255)

        def draw(dx, dy, colour, off):
            centre = (int(c[0] + dx + off), int(c[1] + dy + off))
            cv2.ellipse(img, centre, (int(axes[0]), int(axes[1])), angle, 0, 360, colour, -1, cv2.LINE_AA)

        if shadow_px:
            wrapped(size, lambda dx, dy: draw(dx, dy, tuple(float(v) for v in tint * 0.55), shadow_px))
        wrapped(size, lambda dx, dy: draw(dx, dy, tuple(float(v) for v in tint), 0))


def polygons(img: np.ndarray, count: int, radius_px: tuple, shades: tuple, rng) -> None:
    """Random convex polygons (rock plates, repair patches) with hard edges."""
    size = img.shape[0]
    for _ in range(count):
        c, r = rng.uniform(0, size, 2), rng.uniform(*radius_px)
        angles = np.sort(rng.uniform(0, 2 * np.pi, rng.integers(4, 8)))
        pts = np.stack([np.cos(angles), np.sin(angles)], 1) * r * rng.uniform(0.6, 1.0, (len(angles), 1)) + c
        shade = rng.uniform(*shades)
        colour = tuple(float(v) for v in np.clip(img[int(c[1]) % size, int(c[0]) % size] * shade, 0, 255))
        wrapped(size, lambda dx, dy: cv2.fillPoly(img, [np.round(pts + [dx, dy]).astype(np.int32)], colour,
                                                  cv2.LINE_AA))


def base(size: int, rgb: tuple, variation: tuple, features_px: tuple, rng) -> np.ndarray:
    """Colour field rgb * (1 + sum_k variation_k noise_k)."""
    shade = 1.0 + sum(v * noise(size, f, rng) for v, f in zip(variation, features_px))
    return np.clip(np.asarray(rgb, np.float64)[None, None, :] * shade[..., None], 0, 255)


def px_per_m(name: str) -> float:
    return SIZE_PX[name] / TEXTURE_PERIOD_M[name]


def desert_ground(rng) -> np.ndarray:
    n, k = SIZE_PX["desert_ground"], px_per_m("desert_ground")
    img = base(n, (196, 164, 122), (0.05, 0.06), (6.0 * k, 1.0 * k), rng)
    polygons(img, 40, (1.0 * k, 2.5 * k), (0.72, 0.88), rng)
    blobs(img, 420, (0.25 * k, 0.7 * k), (0.45, 0.8), rng)
    blobs(img, 160, (0.25 * k, 0.55 * k), (1.1, 1.3), rng, shadow_px=0)
    return img


def mountain_ground(rng) -> np.ndarray:
    n, k = SIZE_PX["mountain_ground"], px_per_m("mountain_ground")
    img = base(n, (104, 110, 78), (0.14, 0.08), (8.0 * k, 1.5 * k), rng)
    polygons(img, 55, (1.2 * k, 3.0 * k), (1.15, 1.45), rng)  # grey rock slabs
    blobs(img, 260, (0.35 * k, 0.9 * k), (0.45, 0.75), rng)  # stones and hollows
    blobs(img, 90, (0.3 * k, 0.8 * k), (1.6, 2.0), rng, shadow_px=0)  # snow patches
    return img


def city_ground(rng) -> np.ndarray:
    n, k = SIZE_PX["city_ground"], px_per_m("city_ground")
    img = base(n, (92, 92, 96), (0.08, 0.05), (5.0 * k, 0.8 * k), rng)
    polygons(img, 45, (1.5 * k, 3.5 * k), (0.7, 1.35), rng)  # repair patches
    blobs(img, 120, (0.35 * k, 0.9 * k), (0.5, 0.75), rng, shadow_px=0)  # stains, manholes
    for _ in range(70):  # painted marks
        c, a, length = rng.uniform(0, n, 2), rng.choice([0.0, np.pi / 2]), rng.uniform(1.0, 2.5) * k
        d = np.array([np.cos(a), np.sin(a)]) * length / 2
        wrapped(n, lambda dx, dy: cv2.line(img, tuple(np.round(c - d + [dx, dy]).astype(int)),
                                           tuple(np.round(c + d + [dx, dy]).astype(int)), (225, 225, 215),
                                           max(int(0.3 * k), 1), cv2.LINE_AA))
    return img


def roof(rng) -> np.ndarray:
    n, k = SIZE_PX["roof"], px_per_m("roof")
    img = base(n, (168, 166, 160), (0.07, 0.08), (3.0 * k, 0.15 * k), rng)
    for _ in range(14):  # ventilation units with shadows
        c, half = rng.uniform(0, n, 2), rng.uniform(0.4, 1.2, 2) * k
        shade = rng.uniform(0.5, 1.3)
        top = tuple(float(v) for v in np.array([200, 200, 205]) * shade)
        for off, colour in ((0.25 * k, (60, 60, 60)), (0.0, top)):
            wrapped(n, lambda dx, dy: cv2.rectangle(img, tuple(np.round(c - half + off + [dx, dy]).astype(int)),
                                                    tuple(np.round(c + half + off + [dx, dy]).astype(int)), colour, -1))
    blobs(img, 60, (0.1 * k, 0.3 * k), (0.35, 0.6), rng, shadow_px=0)
    return img


def facade(rng) -> np.ndarray:
    n, k = SIZE_PX["facade"], px_per_m("facade")
    img = base(n, (176, 160, 140), (0.05,), (0.5 * k,), rng)
    for fx in (0.25, 0.75):
        for fz in (0.25, 0.75):  # 2 x 2 windows per repeat (3 m floors)
            c = np.array([fx, fz]) * n
            half = np.array([0.7, 0.75]) * k
            frame = (225, 220, 210)
            cv2.rectangle(img, tuple((c - half - 2).astype(int)), tuple((c + half + 2).astype(int)), frame, -1)
            cv2.rectangle(img, tuple((c - half).astype(int)), tuple((c + half).astype(int)), (52, 62, 78), -1)
    return img


def dirt_road(rng) -> np.ndarray:
    n = SIZE_PX["dirt_road"]
    img = base(n, (142, 112, 80), (0.10, 0.06), (8.0, 2.0), rng)
    u = np.arange(n) / n
    ruts = 1.0 - 0.22 * (np.exp(-((u - 0.3) / 0.06) ** 2) + np.exp(-((u - 0.7) / 0.06) ** 2))
    img *= ruts[None, :, None]
    blobs(img, 60, (1.5, 4.0), (0.5, 0.8), rng)
    return img


def rock(rng) -> np.ndarray:
    n = SIZE_PX["rock"]
    img = base(n, (132, 118, 102), (0.15, 0.1), (10.0, 2.0), rng)
    blobs(img, 25, (1.0, 3.0), (0.6, 0.85), rng, shadow_px=0)
    return img


def palette() -> np.ndarray:
    row = np.repeat(np.asarray(PALETTE_RGB, np.float64), PALETTE_CELL_PX, axis=0)
    return np.repeat(row[None], PALETTE_CELL_PX, axis=0)


def main() -> None:
    TEXTURE_DIR.mkdir(parents=True, exist_ok=True)
    makers = {"desert_ground": desert_ground, "mountain_ground": mountain_ground, "city_ground": city_ground,
              "roof": roof, "facade": facade, "dirt_road": dirt_road, "rock": rock}
    images = {name: make(np.random.default_rng([SEED, i])) for i, (name, make) in enumerate(makers.items())}
    images["vehicle_palette"] = palette()
    total = 0
    for name, img in images.items():
        path = TEXTURE_DIR / f"{name}.png"
        cv2.imwrite(str(path), np.clip(np.round(img), 0, 255).astype(np.uint8)[..., ::-1],
                    [cv2.IMWRITE_PNG_COMPRESSION, 9])
        total += path.stat().st_size
        print(f"{path.relative_to(TEXTURE_DIR.parents[1])}: {img.shape[1]}x{img.shape[0]}, {path.stat().st_size} B")
    print(f"total {total} B")
    if total > MAX_TOTAL_BYTES:
        raise SystemExit(f"textures total {total} B exceed {MAX_TOTAL_BYTES} B")


if __name__ == "__main__":
    main()
