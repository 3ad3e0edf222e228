"""The thermal camera of `camera_modality="thermal"`: the scene's temperatures from the one render a frame makes (unlit
colour as albedo, depth for normals and positions, segmentation for materials), through the microbolometer, as the
grey image the camera outputs.

Owns `thermal_stream`, `thermal_camera` (one episode's `ThermalCamera`), `UNLIT` (the light the thermal frame is
rendered under), the materials of the world's bodies and the heat of driving vehicles.
"""

from __future__ import annotations

import copy
import dataclasses
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics
from trade_gym.sim.camera import MODALITIES, CameraFrame, Lighting
from trade_gym.sim.thermal_scene import (
    F32, MATERIAL_NAMES, SurfaceModel, ThermalLook, albedo_from_unlit_rgb, draw_thermal_look,
)
from trade_gym.sim.thermal_sensor import ThermalConfig, ThermalSensor
from trade_gym.sim.vehicles import Vehicle

if TYPE_CHECKING:
    from trade_gym.sim.world import World

# Names the thermal camera's stream among the streams seeded from one generator state (any fixed value does; the
# appearance's is another)
THERMAL_STREAM_KEY = 0x54484D4C
SEED_WORDS = 2  # 63-bit words read off the env's generator (from a copy) to seed the stream
# Full ambient light and nothing else: pybullet draws each surface in its own texture colour times its rgba colour
# (measured: TinyRenderer returns the vehicle palette's cells exactly), the albedo the thermal scene reads
UNLIT = Lighting((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), ambient=1.0, diffuse=0.0, specular=0.0)
# With appearance "fixed" and no time_of_day_h: early afternoon, whose sun (53 deg high) is near the RGB scenes'
# light (pybullet's own, 60 deg high), so both modalities show the same day
DEFAULT_TIME_OF_DAY_H = 13.0
# Materials (`thermal_scene.MATERIALS`) of the world's bodies: terrain by its texture, the rest by role; vehicles by
# kind. Anything else in view (none known) counts as the terrain.
TERRAIN_MATERIAL = MappingProxyType({"desert_ground": "sand", "city_ground": "pavement", "mountain_ground": "soil"})
ROLE_MATERIAL = MappingProxyType({"boulders": "rock", "buildings": "concrete", "road": "soil", "lake": "ice"})
# Driving vehicles (the target and moving decoys; parked ones have neither): the whole body above its parked
# temperature (cabin, drivetrain, tyres), the engine's cover and the exhaust outlet above that [K] (assumed,
# a warm car body, a hot bonnet and a very hot pipe as LWIR imagery of traffic shows them; not measured values)
RUNNING_BODY_EXCESS_K = 5.0
ENGINE_EXCESS_K = 30.0
EXHAUST_EXCESS_K = 80.0
# Where they are, as boxes (low corner, high corner) in fractions of the vehicle's half extents (x forward, y left,
# z up; `vehicles._PARTS`): a car's bonnet and its rear outlet; a truck's cab and a stack behind it; a tank's rear
# engine deck and its rear grille
Region = tuple[tuple[float, float, float], tuple[float, float, float]]
ENGINE_REGION: MappingProxyType[str, Region] = MappingProxyType({
    "car": ((0.41, -1.0, -1.0), (1.0, 1.0, 1.0)),
    "truck": ((0.5, -1.0, -1.0), (1.0, 1.0, 1.0)),
    "tank": ((-1.0, -0.65, -1.0), (-0.45, 0.65, 1.0)),
})
EXHAUST_REGION: MappingProxyType[str, Region] = MappingProxyType({
    "car": ((-1.0, 0.2, -1.0), (-0.9, 0.6, 0.0)),
    "truck": ((0.44, 0.7, -1.0), (0.5, 1.0, 1.0)),
    "tank": ((-1.0, -0.5, -1.0), (-0.9, 0.5, 1.0)),
})


def thermal_stream(rng: np.random.Generator, modality: str) -> np.random.Generator | None:
    """The thermal camera's own generator (None for "rgb"), seeded from `rng`'s state (a function of the reset
    seed): read off a copy, so `rng` moves not and spawns nothing (every other draw of the episode stays as it was)."""
    if modality not in MODALITIES:
        raise ValueError(f"camera_modality must be one of {MODALITIES}, got {modality!r}")
    if modality == "rgb":
        return None
    words = copy.deepcopy(rng).integers(0, 2**63, size=SEED_WORDS).tolist()
    return np.random.default_rng(np.random.SeedSequence([*words, THERMAL_STREAM_KEY]))


class ThermalCamera:
    """One episode's thermal camera over `world`: the look's `SurfaceModel`, the world's material map, the driving
    vehicles' heat and a `ThermalSensor` drawing from `rng`. `last_radiance_k` holds the last frame's (H, W) scene
    radiance temperatures [K], before the sensor."""

    def __init__(self, world: World, intrinsics: CameraIntrinsics, config: ThermalConfig, look: ThermalLook,
                 rng: np.random.Generator) -> None:
        self.world = world
        self.look = look
        self.model = SurfaceModel(look)
        self.sensor = ThermalSensor(config, intrinsics.width_px, rng)
        self._materials = _material_lut(world)
        self._running = tuple(v for v in (world.target, *world.decoys) if v.motion.is_moving)
        K = intrinsics
        u = (np.arange(K.width_px, dtype=np.float32) - K.cx_px) / K.fx_px
        v = (np.arange(K.height_px, dtype=np.float32) - K.cy_px) / K.fy_px
        self._rays = np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.float32(1.0)), axis=-1)  # (H, W, 3)
        self.last_radiance_k: F32 | None = None

    @property
    def info(self) -> dict[str, Any]:
        """The look (`ThermalLook.as_info`) and when the first flat-field correction starts [s]."""
        return self.look.as_info() | {"first_ffc_s": self.sensor.first_ffc_s}

    def render(self, frame: CameraFrame, t_s: float) -> CameraFrame:
        """`frame`, rendered under `UNLIT`, as the thermal camera outputs it at time `t_s` [s]: its image the sensor's
        grey level in all three channels (H, W, 3) uint8; depth and segmentation unchanged."""
        radiance = self.last_radiance_k = self.radiance_temperature_k(frame, t_s)
        grey = self.sensor.capture(radiance, t_s)
        return dataclasses.replace(frame, rgb=np.repeat(grey[:, :, None], 3, axis=2))

    def radiance_temperature_k(self, frame: CameraFrame, t_s: float) -> F32:
        """(H, W) radiance temperature [K] of each pixel of an unlit `frame`; the clear sky's where nothing was hit."""
        seg = frame.seg
        index = seg + 1
        material = self._materials[np.where(index < len(self._materials), index, 0)]
        points = frame.depth_m[:, :, None] * self._rays  # camera frame [m]
        normals = normals_from_points(points) @ frame.T_world_cam.R.T.astype(np.float32)
        surface = self.model.surface_temperature_k(material, albedo_from_unlit_rgb(frame.rgb), normals)
        for vehicle in self._running:
            mask = seg == vehicle.body_id
            if mask.any():
                surface[mask] += self._running_heat_k(vehicle, frame, points[mask], t_s)
        radiance = self.model.radiance_temperature_k(surface, material, normals)
        radiance[seg < 0] = self.model.sun.sky_k
        return radiance

    def _running_heat_k(self, vehicle: Vehicle, frame: CameraFrame, points_cam: F32, t_s: float) -> F32:
        """(N,) heat [K] a driving vehicle adds at its (N, 3) visible points (camera frame [m])."""
        centre, R_world_vehicle = self.world.vehicle_pose(vehicle, t_s)
        T = frame.T_world_cam
        world = points_cam @ T.R.T + T.t  # p_world = R_wc p_cam + t_wc
        local = (world - centre) @ R_world_vehicle / vehicle.half_extents_m  # R^T (p - c), per half extent
        heat = np.full(len(local), RUNNING_BODY_EXCESS_K, dtype=np.float32)
        heat += ENGINE_EXCESS_K * _inside(local, ENGINE_REGION[vehicle.kind])
        heat += EXHAUST_EXCESS_K * _inside(local, EXHAUST_REGION[vehicle.kind])
        return heat


def thermal_camera(stream: np.random.Generator | None, world: World, intrinsics: CameraIntrinsics,
                   config: ThermalConfig, time_of_day_h: float | None, randomized: bool) -> ThermalCamera | None:
    """The episode's thermal camera (None without a stream, "rgb"). Its stream's first child draws the look when
    `randomized` (the time of day too unless given), the second feeds the sensor; otherwise the look is nominal at
    `time_of_day_h` (DEFAULT_TIME_OF_DAY_H if None)."""
    if stream is None:
        return None
    draw_rng, sensor_rng = stream.spawn(2)
    time_h = DEFAULT_TIME_OF_DAY_H if time_of_day_h is None else float(time_of_day_h)
    look = draw_thermal_look(draw_rng, time_of_day_h) if randomized else ThermalLook(time_h)
    return ThermalCamera(world, intrinsics, config, look, sensor_rng)


def normals_from_points(points: F32) -> F32:
    """(H, W, 3) unit surface normals facing the camera from (H, W, 3) camera-frame points: the cross product of the
    image-axis differences, each taken on the side (forward or backward) whose depth changes less, so a normal at an
    object's edge comes from its own surface."""
    normal = np.cross(_tangent(points, axis=1), _tangent(points, axis=0))
    normal *= np.where(np.sum(normal * points, axis=-1, keepdims=True) > 0.0, -1.0, 1.0).astype(np.float32)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    return (normal / np.maximum(length, np.float32(1e-12))).astype(np.float32)


def _tangent(points: F32, axis: int) -> F32:
    step = np.diff(points, axis=axis)
    first, last = np.take(step, [0], axis=axis), np.take(step, [-1], axis=axis)
    forward, backward = np.concatenate([step, last], axis=axis), np.concatenate([first, step], axis=axis)
    use_forward = np.abs(forward[..., 2:]) <= np.abs(backward[..., 2:])
    return np.where(use_forward, forward, backward)


def _inside(local: npt.NDArray[np.float64], region: Region) -> npt.NDArray[np.float32]:
    lo, hi = np.asarray(region[0]), np.asarray(region[1])
    return np.all((local >= lo) & (local <= hi), axis=1).astype(np.float32)


def _material_lut(world: World) -> npt.NDArray[np.intp]:
    """Material index (into MATERIAL_NAMES) per body id + 1 (entry 0: nothing hit, or an id beyond the table: the
    terrain's, as every body the table does not name)."""
    terrain = MATERIAL_NAMES.index(TERRAIN_MATERIAL[world.spec.ground_texture])
    vehicles = (world.target, *world.decoys)
    ids = [i for ids in world.body_ids_by_role.values() for i in ids] + [v.body_id for v in vehicles]
    lut = np.full(max(ids) + 2, terrain, dtype=np.intp)
    for role, name in ROLE_MATERIAL.items():
        for body in world.body_ids_by_role[role]:
            lut[body + 1] = MATERIAL_NAMES.index(name)
    for vehicle in vehicles:
        lut[vehicle.body_id + 1] = MATERIAL_NAMES.index(vehicle.kind)
    return lut
