"""The simulated world of one episode: builds a scene's pybullet bodies and poses its vehicles.

Owns `World` and `build_world`; every pybullet call names the client explicitly.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade_gym.sim import city, desert, mountain
from trade_gym.sim.layout import SceneLayout
from trade_gym.sim.meshes import (
    TEXTURE_PERIOD_M, Mesh, building_meshes, create_terrain_visual, polygon_mesh, rock_mesh, strip_mesh,
    texture_path,
)
from trade_gym.sim.scenes import SceneSpec, get_scene
from trade_gym.sim.terrain import Heightfield
from trade_gym.sim.vehicles import (
    Vehicle, VehicleMotion, create_vehicle_body, create_vehicle_shape, matrix_to_quat_xyzw, terrain_pose,
    vehicle_model,
)

FloatArray = npt.NDArray[np.float64]

ROAD_LIFT_M = 0.04  # road ribbon drawn this far above the carved terrain
ROAD_SAMPLE_M = 1.0
LAKE_LIFT_M = 0.02  # lake surface drawn this far above the (flat) terrain under it
LAKE_RGBA = (0.80, 0.86, 0.90, 1.0)  # icy, uniform colour, no texture
WHITE_RGBA = (1.0, 1.0, 1.0, 1.0)
LAYOUT_BUILDERS = MappingProxyType(
    {"desert": desert.make_desert, "city": city.make_city, "mountain": mountain.make_mountain}
)


def make_layout(spec: SceneSpec, rng: np.random.Generator, target_speed_mps: float) -> SceneLayout:
    """Generate the scene named by `spec` without pybullet (same rng state -> identical layout)."""
    if spec.name not in LAYOUT_BUILDERS:
        raise ValueError(f"no layout generator for scene {spec.name!r}; valid: {sorted(LAYOUT_BUILDERS)}")
    return LAYOUT_BUILDERS[spec.name](spec, rng, target_speed_mps)


def _textured_body(cid: int, mesh: Mesh, texture_id: int, collision: int = -1) -> int:
    """Static body at the world origin: `mesh` in world coordinates, optional collision shape."""
    body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=collision,
                             baseVisualShapeIndex=mesh.create_visual_shape(cid), physicsClientId=cid)
    if texture_id >= 0:
        p.changeVisualShape(body, -1, textureUniqueId=texture_id, rgbaColor=list(WHITE_RGBA), physicsClientId=cid)
    return body


def _terrain_body(cid: int, layout: SceneLayout, texture_id: int) -> int:
    """Heightfield collision + identical textured grid mesh (triangulated the same way)."""
    hf = layout.terrain
    ny, nx = hf.shape
    collision = p.createCollisionShape(p.GEOM_HEIGHTFIELD, meshScale=[hf.spacing_m, hf.spacing_m, 1.0],
                                       heightfieldData=hf.heights_m.ravel().tolist(), numHeightfieldRows=nx,
                                       numHeightfieldColumns=ny, physicsClientId=cid)
    origin = np.array([*hf.centre_m, hf.bullet_base_z_m])
    drop = None
    if layout.lake is not None:
        gx, gy = np.meshgrid(hf.x_m, hf.y_m)
        drop = layout.lake.normalised_radius(gx, gy) <= 1.0
    visual = create_terrain_visual(cid, hf.x_m, hf.y_m, hf.heights_m, hf.vertex_normals(),
                                   TEXTURE_PERIOD_M[layout.spec.ground_texture], origin, drop)
    body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=collision, baseVisualShapeIndex=visual,
                             basePosition=origin.tolist(), physicsClientId=cid)
    p.changeVisualShape(body, -1, textureUniqueId=texture_id, rgbaColor=list(WHITE_RGBA), physicsClientId=cid)
    return body


def _boulder_bodies(cid: int, layout: SceneLayout, texture_id: int) -> list[int]:
    """Boulders sharing one collision hull and visual shape per (prototype, size class).

    (pybullet's batchPositions would be faster but leaves getNumBodies() wrong, so bodies are made one by one.)
    """
    shapes: dict[tuple[int, int], tuple[int, int]] = {}
    ids = []
    for b in layout.boulders:
        key = (b.prototype, b.size_class)
        if key not in shapes:
            mesh = rock_mesh(*key)
            shapes[key] = (p.createCollisionShape(p.GEOM_MESH, vertices=mesh.vertices_list, physicsClientId=cid),
                           mesh.create_visual_shape(cid))
        quat = [0.0, 0.0, float(np.sin(b.yaw_rad / 2.0)), float(np.cos(b.yaw_rad / 2.0))]
        body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shapes[key][0],
                                 baseVisualShapeIndex=shapes[key][1], basePosition=b.centre_m.tolist(),
                                 baseOrientation=quat, physicsClientId=cid)
        p.changeVisualShape(body, -1, textureUniqueId=texture_id, rgbaColor=list(WHITE_RGBA), physicsClientId=cid)
        ids.append(body)
    return ids


def _building_bodies(cid: int, layout: SceneLayout, textures: dict[str, int]) -> list[int]:
    lo, hi = layout.buildings_lo_m, layout.buildings_hi_m
    if len(lo) == 0:
        return []
    walls, roofs = building_meshes(lo, hi, TEXTURE_PERIOD_M["facade"], TEXTURE_PERIOD_M["roof"])
    n = len(lo)
    collision = p.createCollisionShapeArray(shapeTypes=[p.GEOM_BOX] * n, halfExtents=((hi - lo) / 2.0).tolist(),
                                            collisionFramePositions=((hi + lo) / 2.0).tolist(), physicsClientId=cid)
    return [_textured_body(cid, walls, textures["facade"], collision=collision),
            _textured_body(cid, roofs, textures["roof"])]


def _road_body(cid: int, layout: SceneLayout, texture_id: int) -> int:
    road, hf = layout.road, layout.terrain
    s, xy = road.path.sample(ROAD_SAMPLE_M)
    normal = road.path.tangent(s) @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # rotate +90 deg: left normal
    sides = np.stack([xy + road.half_width_m * normal, xy - road.half_width_m * normal], 1)  # (K, 2 left/right, 2)
    z = hf.height_m(sides[..., 0], sides[..., 1]) + ROAD_LIFT_M
    return _textured_body(cid, strip_mesh(xy, normal, s, road.half_width_m, z, TEXTURE_PERIOD_M["dirt_road"]),
                          texture_id)


def _lake_body(cid: int, layout: SceneLayout) -> int:
    mesh = polygon_mesh(layout.lake.outline_m(), layout.lake.level_m + LAKE_LIFT_M)
    shape = p.createVisualShape(p.GEOM_MESH, vertices=mesh.vertices_list, indices=mesh.indices_list,
                                normals=mesh.normals_list, rgbaColor=list(LAKE_RGBA), physicsClientId=cid)
    return p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=shape, physicsClientId=cid)


class World:
    """One episode's scene; vehicle poses are functions of time only (kinematic, visual-only bodies).

    Attributes: `spec`, `layout` (everything generated), `terrain` (Heightfield), `target` and `decoys`
    (Vehicle), `body_ids_by_role` (terrain, boulders, buildings, road, lake) and `static_body_ids` (all of
    those; road and lake have no collision shape, the terrain's is a GEOM_HEIGHTFIELD matching `terrain`).
    """

    def __init__(self, client_id: int, layout: SceneLayout, target: Vehicle, decoys: tuple[Vehicle, ...],
                 body_ids_by_role: dict[str, tuple[int, ...]]) -> None:
        self.client_id = client_id
        self.layout = layout
        self.spec: SceneSpec = layout.spec
        self.terrain: Heightfield = layout.terrain
        self.target = target
        self.decoys = decoys
        # roles: terrain, boulders, buildings (walls with box collision, roofs), road and lake (visual only)
        self.body_ids_by_role = MappingProxyType(dict(body_ids_by_role))
        self.static_body_ids: tuple[int, ...] = tuple(i for ids in self.body_ids_by_role.values() for i in ids)
        self._moving = tuple(v for v in (target, *decoys) if v.motion.is_moving)
        self._pose_cache: dict[int, tuple[float | None, FloatArray, FloatArray]] = {}
        self._place(tuple(v for v in (target, *decoys) if not v.motion.is_moving), None)
        self.update(0.0)

    @property
    def duration_s(self) -> float:
        """Time the target drives before it stops at its path's end [s]."""
        return self.target.motion.stop_time_s

    @property
    def buildings_lo_m(self) -> FloatArray:
        return self.layout.buildings_lo_m

    @property
    def buildings_hi_m(self) -> FloatArray:
        return self.layout.buildings_hi_m

    def _poses(self, vehicles: tuple[Vehicle, ...], t_s: float) -> tuple[FloatArray, FloatArray]:
        """(N, 3) box centres [m] and (N, 3, 3) R_world_vehicle, one vectorised terrain query."""
        s = [v.motion.distance_m(t_s) for v in vehicles]
        xy = np.array([v.motion.path.position_m(si) for v, si in zip(vehicles, s)])
        yaw = np.array([v.motion.path.heading_rad(si) for v, si in zip(vehicles, s)])
        return terrain_pose(self.terrain, xy, yaw, np.array([v.half_extents_m for v in vehicles]))

    def vehicle_pose(self, v: Vehicle, t_s: float) -> tuple[FloatArray, FloatArray]:
        """(3,) box centre [m] and (3, 3) R_world_vehicle at time t_s (cached for the last `update`)."""
        cached = self._pose_cache.get(v.body_id)
        if cached is not None and (cached[0] is None or cached[0] == t_s):
            return cached[1].copy(), cached[2].copy()
        pos, R = self._poses((v,), t_s)
        return pos[0], R[0]

    def _place(self, vehicles: tuple[Vehicle, ...], t_s: float | None) -> None:
        """Pose bodies at t_s (None: parked, valid at any time) and remember the poses."""
        if not vehicles:
            return
        pos, R = self._poses(vehicles, 0.0 if t_s is None else t_s)
        for v, pk, Rk in zip(vehicles, pos, R):
            self._pose_cache[v.body_id] = (t_s, pk, Rk)
            p.resetBasePositionAndOrientation(v.body_id, pk.tolist(), matrix_to_quat_xyzw(Rk).tolist(),
                                              physicsClientId=self.client_id)

    def update(self, t_s: float) -> None:
        """Pose the target and the moving decoys at time t_s (parked ones never move)."""
        self._place(self._moving, float(t_s))

    def target_velocity_mps(self, t_s: float) -> FloatArray:
        """(3,) world velocity [m/s]: v_xy along the path, v_z = grad h . v_xy."""
        m = self.target.motion
        v_xy = m.planar_velocity_mps(t_s)
        xy = m.path.position_m(m.distance_m(t_s))
        return np.array([*v_xy, float(self.terrain.gradient(*xy) @ v_xy)])

    def ground_height_m(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """Terrain height [m] (buildings, rocks and vehicles excluded); vectorised."""
        return self.terrain.height_m(x_m, y_m)

    def surface_height_m(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """max(terrain, roof of the building containing (x, y)) [m]; rocks excluded."""
        x, y = np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64)
        ground = self.terrain.height_m(x, y)
        lo, hi = self.buildings_lo_m, self.buildings_hi_m
        if len(lo) == 0:
            return ground
        xe, ye = x[..., None], y[..., None]
        inside = (xe >= lo[:, 0]) & (xe <= hi[:, 0]) & (ye >= lo[:, 1]) & (ye <= hi[:, 1])
        return np.maximum(ground, np.max(np.where(inside, hi[:, 2], -np.inf), axis=-1))

    def drone_start(self) -> tuple[FloatArray, float]:
        """(3,) start position [m] and yaw [rad]: the target is in view of a downward camera."""
        return self.layout.drone_start_m.copy(), self.layout.drone_yaw_rad


def build_world(client_id: int, scene: str, rng: np.random.Generator, target_speed_mps: float | None = None) -> World:
    """Generate and build `scene` in a freshly reset pybullet client (same rng state -> same world)."""
    spec = get_scene(scene)
    speed = spec.target_speed_mps if target_speed_mps is None else float(target_speed_mps)
    if not np.isfinite(speed) or speed <= 0.0:
        raise ValueError(f"target_speed_mps must be finite and > 0, got {target_speed_mps!r}")
    layout = make_layout(spec, rng, speed)
    names = {spec.ground_texture, "vehicle_palette"} | ({"rock"} if layout.boulders else set())
    names |= {"facade", "roof"} if len(layout.buildings_lo_m) else set()
    names |= {"dirt_road"} if layout.road is not None else set()
    tex = {name: p.loadTexture(str(texture_path(name)), physicsClientId=client_id) for name in sorted(names)}
    roles = {
        "terrain": (_terrain_body(client_id, layout, tex[spec.ground_texture]),),
        "boulders": tuple(_boulder_bodies(client_id, layout, tex.get("rock", -1))),
        "buildings": tuple(_building_bodies(client_id, layout, tex)),
        "road": (_road_body(client_id, layout, tex["dirt_road"]),) if layout.road is not None else (),
        "lake": (_lake_body(client_id, layout),) if layout.lake is not None else (),
    }
    shapes = {kind: create_vehicle_shape(client_id, kind) for kind in sorted({spec.target_kind, spec.decoy_kind})}

    def spawn(kind: str, motion: VehicleMotion) -> Vehicle:
        body = create_vehicle_body(client_id, shapes[kind], tex["vehicle_palette"])
        return Vehicle(kind, body, vehicle_model(kind).half_extents_m, motion)

    target = spawn(spec.target_kind, layout.target)
    decoys = tuple(spawn(spec.decoy_kind, m) for m in layout.decoys)
    return World(client_id, layout, target, decoys, roles)
