"""Appearance randomisation (`gym.make(..., appearance="randomized")`): light, ground, vehicle paint, haze, camera.

Owns `Appearance` (one reset's drawn values), `draw_appearance`, its own random stream (`appearance_stream`) and
`EpisodeLook`, which applies the draw to the world's bodies and renders through it; "fixed" draws and changes nothing.
A thermal camera (`trade_gym.sim.thermal_camera`) renders through it too.
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pybullet as p

from trade.geometry import Pose
from trade_gym.sim.camera import Camera, CameraFrame, Lighting
from trade_gym.sim.camera_effects import CameraEffects, CameraLook
from trade_gym.sim.quadrotor import DroneState
from trade_gym.sim.scenes import SceneSpec
from trade_gym.sim.texture_variants import ground_variant, palette_variant, variant_path
from trade_gym.sim.thermal_camera import UNLIT, ThermalCamera

if TYPE_CHECKING:
    from trade_gym.sim.world import World

APPEARANCE_MODES = ("fixed", "randomized")
# Names the appearance's stream among the streams seeded from one generator state (any fixed value does)
APPEARANCE_STREAM_KEY = 0x41505045
SEED_WORDS = 2  # 63-bit words read off the env's generator (from a copy) to seed the appearance's stream

# Light. Sun from 25 deg (lower, the unshadowed slopes facing away go dark) to 85 deg; pybullet's own is at 60 deg.
SUN_ELEVATION_RANGE_DEG = (25.0, 85.0)
# Shading coefficients about pybullet's own (0.6, 0.35, 0.05): hazy/overcast (much ambient) to clear (much diffuse),
# matt to some glare
LIGHT_AMBIENT_RANGE = (0.45, 0.75)
LIGHT_DIFFUSE_RANGE = (0.2, 0.5)
LIGHT_SPECULAR_RANGE = (0.0, 0.15)
# Light colour between a low sun's (warm, ~3500 K relative to daylight white) and shade/overcast (cool, ~8000 K)
WARM_LIGHT_RGB = (1.0, 0.86, 0.70)
COOL_LIGHT_RGB = (0.86, 0.93, 1.0)
# Ground: per-channel tint (normalised to a brightest channel of 1: colour, not exposure, which the gain draws) from
# the texture's own colour to a 20 % cast (wetter, redder or greyer soil)
GROUND_TINT_RANGE = (0.8, 1.0)
# Ground texture variants (each a cached file): contrast from soft (dust, flat light) to crisp, the pattern as
# shipped or twice as fine, turned 0 or 90 deg
GROUND_CONTRASTS = (0.7, 1.0, 1.4)
GROUND_DETAILS = (1, 2)
GROUND_QUARTER_TURNS = (0, 1)
# Vehicle paint: the hue of the paint cells (car body, the tank's olive and dark green) turned to one of 12 steps
# (30 deg apart: any paint colour; steps, since each is a cached texture), then the whole body tinted per channel
# down to 0.7 (a white truck turns pastel). Target and decoys always share the one draw, so they stay identical.
VEHICLE_PAINT_CELLS = (0, 5, 6)  # indices into vehicles.PALETTE_RGB
VEHICLE_HUE_STEPS = 12
VEHICLE_TINT_RANGE = (0.7, 1.0)
# Haze: share of the ground's light that reaches the camera straight down from the scene's follow height, from
# clear air to thick haze (0.75 = visibility ~14 follow heights; a corner ray of the 110 deg camera, 2.25 times as
# long, keeps 0.52). Relative to the follow height so the target is as hazed in every scene.
HAZE_NADIR_TRANSMISSION_RANGE = (0.75, 1.0)
HAZE_RGB_ENDS = ((188.0, 198.0, 214.0), (214.0, 206.0, 188.0))  # blue-grey to dusty [DN]; drawn between them
# Camera. Exposure from bright daylight (1/1000 s) to dim (1/60 s, half the 30 Hz frame period), log-uniform
EXPOSURE_RANGE_S = (0.001, 1.0 / 60.0)
GAIN_RANGE_EV = (-0.5, 0.5)  # auto-exposure off by up to half a stop either way
READ_NOISE_RANGE_DN = (0.5, 3.0)  # 8-bit read noise: a clean sensor to a small one at high gain
SHOT_NOISE_RANGE_DN = (1.0, 4.0)  # shot-noise std at full white (so ~0.5-2 DN in the mid-tones)
VIGNETTING_RANGE = (0.0, 0.35)  # light lost at the corner: none to a wide-angle lens without shading correction
JPEG_QUALITY_RANGE = (40, 95)  # a low-bitrate video link's blocking to near-lossless


@dataclass(frozen=True)
class Appearance:
    """One reset's drawn look: the light; the ground's texture variant (contrast, detail, quarter turns) and tint
    (r, g, b); the vehicles' paint hue shift [deg] and tint (r, g, b), shared by target and decoys; the camera's."""

    lighting: Lighting
    ground_contrast: float
    ground_detail: int
    ground_quarter_turns: int
    ground_tint_rgb: tuple[float, float, float]
    vehicle_hue_shift_deg: float
    vehicle_tint_rgb: tuple[float, float, float]
    camera: CameraLook

    def as_info(self) -> dict[str, Any]:
        """The draw as plain floats, ints and lists (`info["appearance"]`), with "mode": "randomized"."""
        values = {k: v for k, v in asdict(self).items() if k not in ("lighting", "camera")}
        values |= {f"light_{k}": v for k, v in asdict(self.lighting).items()} | asdict(self.camera)
        return {"mode": "randomized"} | {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}


def appearance_stream(rng: np.random.Generator, mode: str) -> np.random.Generator | None:
    """The appearance's own generator (None for "fixed"), seeded from `rng`'s state, a function of the reset seed:
    read off a copy, so `rng` moves not and spawns nothing (every other draw of the episode stays as it was)."""
    if mode not in APPEARANCE_MODES:
        raise ValueError(f"appearance must be one of {APPEARANCE_MODES}, got {mode!r}")
    if mode == "fixed":
        return None
    words = copy.deepcopy(rng).integers(0, 2**63, size=SEED_WORDS).tolist()
    return np.random.default_rng(np.random.SeedSequence([*words, APPEARANCE_STREAM_KEY]))


def draw_appearance(rng: np.random.Generator, spec: SceneSpec) -> Appearance:
    """Draw every appearance value from `rng`, in a fixed order; `spec` scales the haze to its follow height."""
    lighting = _draw_lighting(rng)
    ground_tint = rng.uniform(*GROUND_TINT_RANGE, 3)
    contrast = float(rng.choice(GROUND_CONTRASTS))
    detail, turns = int(rng.choice(GROUND_DETAILS)), int(rng.choice(GROUND_QUARTER_TURNS))
    hue_shift_deg = 360.0 / VEHICLE_HUE_STEPS * int(rng.integers(0, VEHICLE_HUE_STEPS))
    vehicle_tint = _float3(rng.uniform(*VEHICLE_TINT_RANGE, 3))
    return Appearance(lighting, contrast, detail, turns, _float3(ground_tint / ground_tint.max()), hue_shift_deg,
                      vehicle_tint, _draw_camera(rng, spec.follow_altitude_agl_m))


def _draw_lighting(rng: np.random.Generator) -> Lighting:
    elevation = math.radians(rng.uniform(*SUN_ELEVATION_RANGE_DEG))
    azimuth = rng.uniform(-math.pi, math.pi)
    direction = (math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation))
    warmth = rng.uniform(-1.0, 1.0)  # > 0 towards WARM_LIGHT_RGB, < 0 towards COOL_LIGHT_RGB, from white
    end = np.asarray(WARM_LIGHT_RGB if warmth > 0 else COOL_LIGHT_RGB)
    colour = 1.0 + abs(warmth) * (end - 1.0)
    return Lighting(direction, _float3(colour), float(rng.uniform(*LIGHT_AMBIENT_RANGE)),
                    float(rng.uniform(*LIGHT_DIFFUSE_RANGE)), float(rng.uniform(*LIGHT_SPECULAR_RANGE)))


def _draw_camera(rng: np.random.Generator, follow_height_m: float) -> CameraLook:
    # transmission T = exp(-beta h) at the follow height h: beta = -ln(T) / h
    extinction = -math.log(rng.uniform(*HAZE_NADIR_TRANSMISSION_RANGE)) / follow_height_m
    near, far = (np.asarray(end) for end in HAZE_RGB_ENDS)
    haze = near + rng.uniform() * (far - near)
    exposure = math.exp(rng.uniform(*np.log(EXPOSURE_RANGE_S)))
    return CameraLook(extinction, _float3(haze), exposure, float(rng.uniform(*GAIN_RANGE_EV)),
                      float(rng.uniform(*READ_NOISE_RANGE_DN)), float(rng.uniform(*SHOT_NOISE_RANGE_DN)),
                      float(rng.uniform(*VIGNETTING_RANGE)),
                      int(rng.integers(JPEG_QUALITY_RANGE[0], JPEG_QUALITY_RANGE[1] + 1)))


def _float3(values: np.ndarray) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z


def apply_to_world(world: World, appearance: Appearance) -> None:
    """Give the world's terrain its ground variant and tint and every vehicle (target and decoys alike) the paint
    (nothing to paint in a world built undrawn)."""
    if not world.drawn:
        return
    cid, a = world.client_id, appearance
    ground = world.spec.ground_texture
    key = f"c{a.ground_contrast:g}-d{a.ground_detail}-r{a.ground_quarter_turns}"
    path = variant_path(ground, key, lambda rgb: ground_variant(rgb, a.ground_quarter_turns, a.ground_detail,
                                                                   a.ground_contrast))
    texture = p.loadTexture(str(path), physicsClientId=cid)
    for body in world.body_ids_by_role["terrain"]:
        p.changeVisualShape(body, -1, textureUniqueId=texture, physicsClientId=cid)
    world.culler.set_colour([*a.ground_tint_rgb, 1.0])  # it owns the tiles' colour (hidden ones keep zero alpha)
    path = variant_path("vehicle_palette", f"h{a.vehicle_hue_shift_deg:g}",
                        lambda rgb: palette_variant(rgb, VEHICLE_PAINT_CELLS, a.vehicle_hue_shift_deg))
    palette = p.loadTexture(str(path), physicsClientId=cid)
    for vehicle in (world.target, *world.decoys):
        p.changeVisualShape(vehicle.body_id, -1, textureUniqueId=palette, rgbaColor=[*a.vehicle_tint_rgb, 1.0],
                            physicsClientId=cid)


class EpisodeLook:
    """One episode's appearance. Without a stream ("fixed") it renders exactly as `camera.render`; with one it
    draws an `Appearance` from a first child of it, applies it to `world`'s bodies at once, and renders under its
    light through `CameraEffects`, whose per-frame noise comes from a second child. With a `thermal` camera it renders
    every frame unlit and makes the thermal image of it instead (the drawn ground and paint reach it as albedo; the
    drawn light and camera effects are the visible camera's and do not apply). `info` is what the reset's info gains:
    {"appearance": {"mode": "fixed"}} or the draw (`Appearance.as_info`), and {"thermal": ...} with a thermal camera."""

    def __init__(self, stream: np.random.Generator | None, world: World, camera: Camera,
                 thermal: ThermalCamera | None = None) -> None:
        self.camera = camera
        self.world = world
        self.thermal = thermal
        self.appearance: Appearance | None = None
        self._effects: CameraEffects | None = None
        if stream is None:
            return
        draw_rng, frame_rng = stream.spawn(2)
        self.appearance = draw_appearance(draw_rng, world.spec)
        apply_to_world(world, self.appearance)
        self._effects = CameraEffects(self.appearance.camera, camera.intrinsics, frame_rng)

    @property
    def info(self) -> dict[str, Any]:
        """A fresh {"appearance": ...} (and {"thermal": ...}) for the reset's info."""
        looks = {"appearance": {"mode": "fixed"} if self.appearance is None else self.appearance.as_info()}
        return looks if self.thermal is None else looks | {"thermal": self.thermal.info}

    def render(self, T_world_cam: Pose, state: DroneState) -> CameraFrame:
        """The frame from `T_world_cam` as the camera delivers it; `state` (the drone's velocity and body rates)
        smears it over the exposure, its time (`t_s`) times the thermal camera. Depth and segmentation are the
        renderer's either way."""
        cfg = self.camera.config
        self.world.prepare_render(T_world_cam, self.camera.intrinsics, cfg.near_m, cfg.far_m)
        if self.thermal is not None:
            return self.thermal.render(self.camera.render(T_world_cam, UNLIT), state.t_s)
        if self.appearance is None or self._effects is None:  # both None, or neither
            return self.camera.render(T_world_cam)
        frame = self.camera.render(T_world_cam, self.appearance.lighting)
        velocity_cam = T_world_cam.R.T @ state.velocity_mps
        angular_rate_cam = self.camera.T_body_cam.R.T @ state.angular_velocity_body_radps
        return self._effects.apply(frame, velocity_cam, angular_rate_cam)
