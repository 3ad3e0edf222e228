"""The simulated world of one episode: builds a scene's pybullet bodies and poses its vehicles.

Owns `World` and `build_world`; every pybullet call names the client explicitly.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass
from types import MappingProxyType
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade.camera_pitch import NADIR_PITCH_DEG, standoff_m
from trade.geometry import CameraIntrinsics, Pose
from trade_gym.sim import city, desert, mountain
from trade_gym.sim.bullet_lists import bullet_list
from trade_gym.sim.culling import ViewCuller
from trade_gym.sim.evasive import EvasiveMotion
from trade_gym.sim.layout import Lake, Road, SceneLayout, direction, parked
from trade_gym.sim.mesh_files import remove_mesh_files
from trade_gym.sim.meshes import (
    TEXTURE_PERIOD_M, Mesh, building_meshes, create_terrain_visual, grid_uvs, placed_meshes, polygon_mesh, rock_mesh,
    strip_mesh, texture_path,
)
from trade_gym.sim.roofs import RoofIndex
from trade_gym.sim.scenes import DECOY_TIERS, SceneSpec, get_scene
from trade_gym.sim.target_motion import TargetMotion, motion_summary
from trade_gym.sim.terrain import Heightfield
from trade_gym.sim.vehicle_poses import VehiclePoses
from trade_gym.sim.vehicles import (
    Motion, Vehicle, VehicleMotion, vehicle_model,
)

FloatArray = npt.NDArray[np.float64]

ROAD_LIFT_M = 0.04  # road ribbon drawn this far above the carved terrain
ROAD_SAMPLE_M = 1.0
LAKE_LIFT_M = 0.02  # lake surface drawn this far above the (flat) terrain under it
LAKE_RGBA = (0.80, 0.86, 0.90, 1.0)  # icy, uniform colour, no texture
WHITE_RGBA = (1.0, 1.0, 1.0, 1.0)
# The terrain mesh is built as this many tiles per side, so the tiles outside the camera's view can be left out of
# a render (`trade_gym.sim.culling`). At the scenes' follow heights the 110 deg camera sees a 2.9 h wide footprint
# (46-92 m of 200-250 m terrains), a few tiles; more tiles trim closer but cost a body each.
TERRAIN_TILES_PER_SIDE = 8
LAYOUT_BUILDERS = MappingProxyType(
    {"desert": desert.make_desert, "city": city.make_city, "mountain": mountain.make_mountain}
)


def make_layout(spec: SceneSpec, rng: np.random.Generator, target_speed_mps: float) -> SceneLayout:
    """Generate the scene named by `spec` without pybullet (same rng state -> identical layout)."""
    if spec.name not in LAYOUT_BUILDERS:
        raise ValueError(f"no layout generator for scene {spec.name!r}; valid: {sorted(LAYOUT_BUILDERS)}")
    return LAYOUT_BUILDERS[spec.name](spec, rng, target_speed_mps)


@dataclass(frozen=True)
class BodyLooks:
    """How a world's bodies are drawn: its textures by name (`texture`) and visual shapes (`visual`). A world that is
    never rendered is built without any (`drawn` False: every id is -1, no texture is loaded). Its bodies, their order
    and their collision shapes are the same, so are the physics and every ray test. The terrain's visual mesh is most
    of a drawn world's build time."""

    client_id: int
    drawn: bool
    textures: MappingProxyType[str, int]

    @classmethod
    def load(cls, client_id: int, drawn: bool, names: set[str]) -> BodyLooks:
        """Load the textures `names` (none unless `drawn`)."""
        tex = {n: p.loadTexture(str(texture_path(n)), physicsClientId=client_id) for n in sorted(names)} if drawn else {}
        return cls(client_id, drawn, MappingProxyType(tex))

    def texture(self, name: str) -> int:
        return self.textures[name] if self.drawn else -1

    def visual(self, mesh: Mesh, rgba: tuple[float, float, float, float] | None = None) -> int:
        return mesh.create_visual_shape(self.client_id, rgba) if self.drawn else -1


def _static_body(cid: int, collision: int, visual: int, position_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 texture_id: int = -1) -> int:
    """Mass-0 body in maximal coordinates (a static btRigidBody: stepSimulation skips it at a fraction of a
    fixed-base multibody's cost), optionally textured."""
    body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=collision, baseVisualShapeIndex=visual,
                             basePosition=list(position_m), useMaximalCoordinates=True, physicsClientId=cid)
    if texture_id >= 0:
        p.changeVisualShape(body, -1, textureUniqueId=texture_id, rgbaColor=list(WHITE_RGBA), physicsClientId=cid)
    return body


def _textured_body(looks: BodyLooks, mesh: Mesh, texture: str, collision: int = -1) -> int:
    """Static body at the world origin: `mesh` in world coordinates with the texture named `texture`, optional
    collision shape."""
    return _static_body(looks.client_id, collision, looks.visual(mesh), texture_id=looks.texture(texture))


def _tile_edges(cells: int, tiles: int) -> npt.NDArray[np.int64]:
    """Cell indices where `tiles` tiles start along a side of `cells` cells, then `cells`."""
    return np.round(np.linspace(0, cells, min(tiles, cells) + 1)).astype(np.int64)


def _terrain_tiles(looks: BodyLooks, layout: SceneLayout) -> tuple[tuple[int, ...], ViewCuller]:
    """The heightfield's textured grid mesh (triangulated like the collision surface) as TERRAIN_TILES_PER_SIDE^2
    tiles, each a body at the heightfield's origin; the first also carries the GEOM_HEIGHTFIELD collision. An undrawn
    world gets one tile (tiles pay only in renders; each costs stepSimulation a static body's update per substep).
    Returns the tile bodies and the culler that owns their colour."""
    cid, hf = looks.client_id, layout.terrain
    tiles_per_side = TERRAIN_TILES_PER_SIDE if looks.drawn else 1
    texture = looks.texture(layout.spec.ground_texture)
    ny, nx = hf.shape
    collision = p.createCollisionShape(p.GEOM_HEIGHTFIELD, meshScale=[hf.spacing_m, hf.spacing_m, 1.0],
                                       heightfieldData=bullet_list("heightfield", hf.heights_m.ravel()),
                                       numHeightfieldRows=nx, numHeightfieldColumns=ny, physicsClientId=cid)
    origin = np.array([*hf.centre_m, hf.bullet_base_z_m])
    tile_visual = _terrain_tile_visuals(looks, layout, origin) if looks.drawn else lambda rows, cols: -1
    base_position = tuple(origin.tolist())
    bodies: list[int] = []
    lo, hi = [], []
    for r0, r1 in itertools.pairwise(_tile_edges(ny - 1, tiles_per_side)):
        for c0, c1 in itertools.pairwise(_tile_edges(nx - 1, tiles_per_side)):
            rows, cols = slice(r0, r1 + 1), slice(c0, c1 + 1)
            bodies.append(_static_body(cid, collision if not bodies else -1, tile_visual(rows, cols), base_position,
                                       texture))
            heights = hf.heights_m[rows, cols]
            lo.append((hf.x_m[c0], hf.y_m[r0], float(heights.min())))
            hi.append((hf.x_m[c1], hf.y_m[r1], float(heights.max())))
    return tuple(bodies), ViewCuller(cid, bodies, lo, hi, [WHITE_RGBA] * len(bodies))


def _terrain_tile_visuals(looks: BodyLooks, layout: SceneLayout, origin: FloatArray) -> Callable[[slice, slice], int]:
    """Maker of the visual shape of the terrain grid's tile (rows, cols), in the frame of a body at `origin`."""
    hf = layout.terrain
    ny, nx = hf.shape
    gx, gy = np.meshgrid(hf.x_m, hf.y_m)
    vertices = np.stack([gx - origin[0], gy - origin[1], hf.heights_m.astype(np.float64) - origin[2]], axis=-1)
    uvs = grid_uvs(ny, nx, float(hf.x_m[0]), float(hf.y_m[0]), float(hf.x_m[1] - hf.x_m[0]),
                   float(TEXTURE_PERIOD_M[layout.spec.ground_texture]))
    normals = hf.vertex_normals().reshape(ny, nx, 3)
    drop = layout.lake.normalised_radius(gx, gy) <= 1.0 if layout.lake is not None else None

    def tile_visual(rows: slice, cols: slice) -> int:
        return create_terrain_visual(looks.client_id, vertices[rows, cols], uvs[rows, cols], normals[rows, cols],
                                     None if drop is None else drop[rows, cols])

    return tile_visual


def _boulder_body(looks: BodyLooks, layout: SceneLayout) -> int:
    """All boulders as one body: their meshes merged in world coordinates, drawn as one visual shape and
    collided with as one static BVH triangle mesh (exactly the drawn surface). One body instead of one per
    rock keeps stepSimulation's per-body cost out of the step loop."""
    rocks = layout.boulders
    mesh = placed_meshes([rock_mesh(b.prototype, b.size_class) for b in rocks], [b.yaw_rad for b in rocks],
                         [b.centre_m for b in rocks])
    return _textured_body(looks, mesh, "rock", collision=mesh.create_collision_shape(looks.client_id))


def _building_bodies(looks: BodyLooks, layout: SceneLayout) -> list[int]:
    lo, hi = layout.buildings_lo_m, layout.buildings_hi_m
    if len(lo) == 0:
        return []
    walls, roofs = building_meshes(lo, hi, TEXTURE_PERIOD_M["facade"], TEXTURE_PERIOD_M["roof"])
    n = len(lo)
    collision = p.createCollisionShapeArray(shapeTypes=[p.GEOM_BOX] * n, halfExtents=((hi - lo) / 2.0).tolist(),
                                            collisionFramePositions=((hi + lo) / 2.0).tolist(),
                                            physicsClientId=looks.client_id)
    return [_textured_body(looks, walls, "facade", collision=collision), _textured_body(looks, roofs, "roof")]


def _road_body(looks: BodyLooks, road: Road, hf: Heightfield) -> int:
    s, xy = road.path.sample(ROAD_SAMPLE_M)
    normal = road.path.tangent(s) @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # rotate +90 deg: left normal
    sides = np.stack([xy + road.half_width_m * normal, xy - road.half_width_m * normal], 1)  # (K, 2 left/right, 2)
    z = hf.height_m(sides[..., 0], sides[..., 1]) + ROAD_LIFT_M
    return _textured_body(looks, strip_mesh(xy, normal, s, road.half_width_m, z, TEXTURE_PERIOD_M["dirt_road"]),
                          "dirt_road")


def _lake_body(looks: BodyLooks, lake: Lake) -> int:
    mesh = polygon_mesh(lake.outline_m(), lake.level_m + LAKE_LIFT_M)
    return _static_body(looks.client_id, -1, looks.visual(mesh, rgba=LAKE_RGBA))


class World:
    """One episode's scene; vehicle poses are functions of time (kinematic, visual-only bodies), an evasive
    target's also of where the drone was (`update` is told each frame; `trade_gym.sim.evasive`).

    Attributes: `spec`, `layout` (everything generated), `terrain` (Heightfield), `target` and `decoys`
    (Vehicle), `body_ids_by_role` (terrain (its tiles), boulders (all rocks in one body), buildings, road, lake),
    `static_body_ids` (a frozenset of all of those; road and lake have no collision shape, the terrain's first tile
    carries a GEOM_HEIGHTFIELD matching `terrain`), `culler` (`ViewCuller` of the terrain tiles: call
    `prepare_render` before each render) and `drawn` (False: built without visual shapes or textures, never to be
    rendered; `BodyLooks`).
    """

    def __init__(self, client_id: int, layout: SceneLayout, target: Vehicle, decoys: tuple[Vehicle, ...],
                 body_ids_by_role: dict[str, tuple[int, ...]], culler: ViewCuller, drawn: bool = True) -> None:
        self.client_id = client_id
        self.drawn = drawn
        self.layout = layout
        self.spec: SceneSpec = layout.spec
        self.terrain: Heightfield = layout.terrain
        self.target = target
        self.decoys = decoys
        # roles: terrain, boulders, buildings (walls with box collision, roofs), road and lake (visual only)
        self.body_ids_by_role = MappingProxyType(dict(body_ids_by_role))
        self.static_body_ids: frozenset[int] = frozenset(i for ids in self.body_ids_by_role.values() for i in ids)
        self.culler = culler  # leaves the terrain tiles out of view out of a render; owns their colour
        self.roofs = RoofIndex(layout.buildings_lo_m, layout.buildings_hi_m)
        self._evasive = target.motion if isinstance(target.motion, EvasiveMotion) else None
        self._poses = VehiclePoses(client_id, self.terrain, (target, *decoys))  # places the parked ones
        self.update(0.0)
        self.place_vehicle_bodies()

    @property
    def duration_s(self) -> float:
        """Time the target drives before it stops at its path's end [s] (an evasive one's: at the latest)."""
        return self.target.motion.stop_time_s

    @property
    def target_motion_info(self) -> dict[str, Any]:
        """The target's motion mode and what was drawn for it (`target_motion.motion_summary`)."""
        return motion_summary(self.target.motion)

    @property
    def buildings_lo_m(self) -> FloatArray:
        return self.layout.buildings_lo_m

    @property
    def buildings_hi_m(self) -> FloatArray:
        return self.layout.buildings_hi_m

    def update(self, t_s: float, drone_position_m: npt.ArrayLike | None = None) -> None:
        """Pose the target and the moving decoys at time t_s (parked ones never move); once per t_s.
        Their pybullet bodies move at the next `place_vehicle_bodies` (only rendering sees them). An evasive target
        first drives on to t_s, then notes the drone's true position at t_s ((3,) world [m]; None: no drone), which
        it reacts to until the next update; t_s must then not decrease."""
        if self._evasive is not None:
            self._evasive.advance(t_s, drone_position_m)
        self._poses.update(t_s)

    def prepare_render(self, T_world_cam: Pose, K: CameraIntrinsics, near_m: float, far_m: float) -> None:
        """Leave the terrain tiles this camera cannot see out of its next render (`ViewCuller.update`)."""
        if not self.drawn:
            raise RuntimeError("this world was built undrawn (oracle perception without frames): make the env with "
                               "render_oracle_frames=True (or a render_mode) to render it")
        self.culler.update(T_world_cam, K, near_m, far_m)

    def place_vehicle_bodies(self) -> None:
        """Move the vehicles' pybullet bodies to their poses at the last `update` (call before rendering)."""
        self._poses.place_bodies()

    def vehicle_pose(self, v: Vehicle, t_s: float) -> tuple[FloatArray, FloatArray]:
        """(3,) box centre [m] and (3, 3) R_world_vehicle at time t_s, read-only arrays.

        Cached for the last `update` time (and for parked vehicles); the same function of t_s otherwise.
        """
        return self._poses.pose(v, t_s)

    def target_velocity_mps(self, t_s: float) -> FloatArray:
        """(3,) world velocity [m/s]: v_xy the target motion's (speed * unit tangent along the path while it does not
        swerve), v_z = grad h . v_xy; zero while it stands (before its delay, at a stop, after its stop)."""
        planar = self.target.motion.planar_velocity_at(float(t_s))
        if planar is None:
            return np.zeros(3)
        x, y, vx, vy = planar
        gx, gy = self.terrain.gradient_at(x, y)
        return np.array((vx, vy, gx * vx + gy * vy))

    def ground_height_m(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """Terrain height [m] (buildings, rocks and vehicles excluded); vectorised, fast path for two scalars."""
        if isinstance(x_m, float) and isinstance(y_m, float):  # np.float64 is a float
            return np.float64(self.terrain.height_at(float(x_m), float(y_m)))
        return self.terrain.height_m(x_m, y_m)

    def surface_height_m(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """max(terrain, roof of the building containing (x, y)) [m]; rocks excluded. Vectorised; two scalars
        (float or np.float64) take a few-microsecond path returning np.float64."""
        if isinstance(x_m, float) and isinstance(y_m, float):
            x, y = float(x_m), float(y_m)
            ground, roof = self.terrain.height_at(x, y), self.roofs.height_at(x, y)
            return np.float64(roof if roof > ground else ground)
        ground = self.terrain.height_m(x_m, y_m)
        if not len(self.buildings_lo_m):
            return ground
        return np.maximum(ground, self.roofs.heights(x_m, y_m))

    def drone_start(self, camera_pitch_deg: float = NADIR_PITCH_DEG) -> tuple[FloatArray, float]:
        """(3,) start position [m] and yaw [rad], with the target in view: the scene's start for a downward camera;
        for one pitched below the horizon, moved back against the yaw by the standoff of its height above the ground
        (`camera.standoff_m`: one height at 45 deg), at the same height above the ground there, so the camera's
        axis meets the ground where the downward camera's did (else the target starts at the image's lower edge
        and leaves it within frames)."""
        position, yaw = self.layout.drone_start_m.copy(), self.layout.drone_yaw_rad
        if camera_pitch_deg < NADIR_PITCH_DEG:
            height_m = float(position[2] - self.ground_height_m(float(position[0]), float(position[1])))
            position[:2] -= standoff_m(height_m, camera_pitch_deg) * direction(yaw)
            position[2] = float(self.ground_height_m(float(position[0]), float(position[1]))) + height_m
        return position, yaw


ROUTE_SAMPLE_M = 1.0  # spacing of the target route's points a parked decoy's distance is measured to


PARK_BAND = 0.5  # parked decoys of the "parked" tier stand 1 to 1.5 times the far distance from the route
PARK_TRIES = 50  # placements tried per parked decoy before it is dropped
PARK_SPACING_M = 6.0  # between parked decoys of the "parked" tier
PARK_EDGE_MARGIN_M = 10.0  # kept from the terrain's edge
PARK_BUILDING_MARGIN_M = 2.0  # kept from a building's footprint


@dataclass(frozen=True)
class DecoyTier:
    """Which decoys a world has: "ambiguous", the drawn ones (the paper's scenes: identical decoys crossing,
    overtaking, parked beside the path); "parked", as many parked ones, each never in view together with the
    target; "none".

    "Never in view together": farther from every point of the target's route than the half-diagonal of the
    camera's ground footprint at the scene's follow height, h tan(fov / 2) sqrt(2), so a drone above the target
    never sees both; a drone off the target (the city's start on a roof, tilting while it accelerates) may see
    one at the image's edge, far from the target. The parked places come from a child stream of the world's generator, so the rest of the
    world is the same in every tier."""

    tier: str = "ambiguous"
    camera_fov_deg: float = 110.0

    def __post_init__(self) -> None:
        if self.tier not in DECOY_TIERS:
            raise ValueError(f"decoys must be one of {DECOY_TIERS}, got {self.tier!r}")

    def far_from_route_m(self, follow_height_m: float) -> float:
        return follow_height_m * math.tan(math.radians(self.camera_fov_deg) / 2.0) * math.sqrt(2.0)

    def select(self, layout: SceneLayout, rng: np.random.Generator) -> tuple[VehicleMotion, ...]:
        if self.tier == "ambiguous":
            return layout.decoys
        if self.tier == "none":
            return ()
        return _park_away(layout, self.far_from_route_m(layout.spec.follow_altitude_agl_m), rng.spawn(1)[0])


def _route_points(layout: SceneLayout) -> FloatArray:
    path = layout.target.path
    return np.asarray(path.position_m(np.arange(0.0, path.length_m + ROUTE_SAMPLE_M, ROUTE_SAMPLE_M)))[:, :2]


def _park_away(layout: SceneLayout, far_m: float, rng: np.random.Generator) -> tuple[VehicleMotion, ...]:
    """As many parked decoys as `layout` drew, each farther than `far_m` from the target's route, on the terrain,
    clear of buildings and of each other; a decoy without such a place after PARK_TRIES is dropped."""
    path, route = layout.target.path, _route_points(layout)
    spots: list[FloatArray] = []
    edge = layout.spec.terrain_size_m / 2.0 - PARK_EDGE_MARGIN_M
    lo, hi = layout.buildings_lo_m[:, :2] - PARK_BUILDING_MARGIN_M, layout.buildings_hi_m[:, :2] + PARK_BUILDING_MARGIN_M
    for _ in layout.decoys:
        for _ in range(PARK_TRIES):
            s = rng.uniform(0.0, path.length_m)
            tx, ty = np.asarray(path.tangent(s))[:2]
            offset = rng.choice([-1.0, 1.0]) * far_m * (1.0 + rng.uniform(0.0, PARK_BAND))
            xy = np.asarray(path.position_m(s))[:2] + offset * np.array([-ty, tx])
            clear = (np.all(np.abs(xy) < edge) and float(np.min(np.hypot(*(route - xy).T))) > far_m
                     and not np.any(np.all((xy > lo) & (xy < hi), axis=1))
                     and all(np.hypot(*(xy - spot)) > PARK_SPACING_M for spot in spots))
            if clear:
                spots.append(xy)
                break
    return tuple(parked(xy, float(rng.uniform(-math.pi, math.pi))) for xy in spots)


def build_world(client_id: int, scene: str, rng: np.random.Generator, target_speed_mps: float | None = None,
                decoys: DecoyTier = DecoyTier(), target_motion: TargetMotion = TargetMotion(),
                rendered: bool = True) -> World:
    """Generate and build `scene` in a freshly reset pybullet client (same rng state -> same world); `decoys`
    picks which of the drawn decoys are built, `target_motion` how the target drives (drawn after the decoys).
    A world that is never `rendered` is built without visual shapes and textures (`BodyLooks`), its terrain as one
    body."""
    spec = get_scene(scene)
    speed = spec.target_speed_mps if target_speed_mps is None else float(target_speed_mps)
    if not np.isfinite(speed) or speed <= 0.0:
        raise ValueError(f"target_speed_mps must be finite and > 0, got {target_speed_mps!r}")
    layout = make_layout(spec, rng, speed)
    layout = dataclasses.replace(layout, decoys=decoys.select(layout, rng))
    names = {spec.ground_texture, "vehicle_palette"} | ({"rock"} if layout.boulders else set())
    names |= {"facade", "roof"} if len(layout.buildings_lo_m) else set()
    names |= {"dirt_road"} if layout.road is not None else set()
    looks = BodyLooks.load(client_id, rendered, names)
    terrain_tiles, culler = _terrain_tiles(looks, layout)
    roles = {
        "terrain": terrain_tiles,
        "boulders": (_boulder_body(looks, layout),) if layout.boulders else (),
        "buildings": tuple(_building_bodies(looks, layout)),
        "road": (_road_body(looks, layout.road, layout.terrain),) if layout.road is not None else (),
        "lake": (_lake_body(looks, layout.lake),) if layout.lake is not None else (),
    }
    shapes = {kind: looks.visual(vehicle_model(kind).mesh) for kind in sorted({spec.target_kind, spec.decoy_kind})}

    def spawn(kind: str, motion: Motion) -> Vehicle:  # no collision shape: vehicles are kinematic and visual only
        body = _static_body(client_id, -1, shapes[kind], texture_id=looks.texture("vehicle_palette"))
        return Vehicle(kind, body, vehicle_model(kind).half_extents_m, motion)

    target_half = vehicle_model(spec.target_kind).half_extents_m
    target = spawn(spec.target_kind, target_motion.build(layout, target_half, rng))
    decoy_vehicles = tuple(spawn(spec.decoy_kind, m) for m in layout.decoys)
    remove_mesh_files(client_id)  # an EGL client's OBJ files, read as the bodies were created
    return World(client_id, layout, target, decoy_vehicles, roles, culler, drawn=rendered)
