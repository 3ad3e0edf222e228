"""Tests of the simulated world: scenes, terrain, vehicles, determinism and rendered texture detail."""

from __future__ import annotations

import cv2
import numpy as np
import pybullet as p
import pytest

from trade.geometry import CameraIntrinsics, Pose, quat_xyzw_to_matrix
from trade_gym.sim.bullet_lists import bullet_list
from trade_gym.sim.desert import OVERTAKE_LATERAL_M
from trade_gym.sim.meshes import rock_mesh
from trade_gym.sim.scenes import DECOY_NEAR_PATH_M, SCENES, SceneSpec, get_scene
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.terrain import distance_to_path
from trade_gym.sim.vehicles import terrain_pose
from trade_gym.sim.world import World, build_world, make_layout

FOV_DEG = 110.0
IMAGE_PX = 256
HARRIS_MIN_CORNERS = 100
TARGET_BOX_MARGIN_PX = 3
HUG_TOLERANCE_M = 0.3
LANE_TOLERANCE_M = 0.3  # the lane is a spline through offset points, not the exact offset curve


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    try:
        yield cid
    finally:
        p.disconnect(cid)


def _build(cid: int, scene: str, seed: int = 0, **kwargs) -> World:
    p.resetSimulation(physicsClientId=cid)
    return build_world(cid, scene, np.random.default_rng(seed), **kwargs)


def _render_down(cid: int, world: World) -> tuple[np.ndarray, np.ndarray]:
    """RGB (H, W, 3) and segmentation (H, W) from drone_start, camera straight down, image up = drone forward."""
    pos, yaw = world.drone_start()
    view = p.computeViewMatrix(pos.tolist(), (pos - [0.0, 0.0, 1.0]).tolist(), [np.cos(yaw), np.sin(yaw), 0.0])
    proj = p.computeProjectionMatrixFOV(FOV_DEG, 1.0, 0.1, 1000.0)
    _, _, rgb, _, seg = p.getCameraImage(IMAGE_PX, IMAGE_PX, view, proj, renderer=p.ER_TINY_RENDERER,
                                         physicsClientId=cid)
    return np.reshape(rgb, (IMAGE_PX, IMAGE_PX, 4))[..., :3].astype(np.uint8), np.reshape(seg, (IMAGE_PX, IMAGE_PX))


def _down_camera_rotation(world: World) -> np.ndarray:
    """R_world_cam of a camera at drone_start looking straight down, image up = drone forward."""
    _, yaw = world.drone_start()
    fwd, left = np.array([np.cos(yaw), np.sin(yaw), 0.0]), np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    return np.column_stack([-left, -fwd, [0.0, 0.0, -1.0]])  # x right, y down (toward the back), z down


def _down_camera_points_to_pixels(world: World, points_m: np.ndarray) -> np.ndarray:
    """Pinhole projection (N, 3) world [m] -> (N, 2) pixels for the straight-down start camera."""
    pos, _ = world.drone_start()
    cam = (points_m - pos) @ _down_camera_rotation(world)
    return CameraIntrinsics.from_fov(IMAGE_PX, IMAGE_PX, FOV_DEG).project(cam)


def test_get_scene_unknown_name_raises_value_error_listing_valid_names():
    with pytest.raises(ValueError, match="desert.*city|city.*desert"):
        get_scene("moon")


def test_scene_spec_negative_altitude_raises_value_error_naming_field():
    with pytest.raises(ValueError, match="follow_altitude_agl_m"):
        SceneSpec("x", -1.0, "car", 1.0, 10.0, 50.0, 1.0, "desert_ground", "car", 0, 0, 0)


def test_build_world_nonpositive_speed_raises_value_error(client):
    with pytest.raises(ValueError, match="target_speed_mps"):
        build_world(client, "desert", np.random.default_rng(0), target_speed_mps=0.0)


def test_spline_arc_length_parametrisation_moves_one_metre_per_metre():
    spline = CatmullRomSpline([[0.0, 0.0], [10.0, 0.0], [20.0, 8.0], [25.0, 30.0]])
    s = np.linspace(0.0, spline.length_m, 400)
    step = np.linalg.norm(np.diff(spline.position_m(s), axis=0), axis=1)
    np.testing.assert_allclose(step, s[1] - s[0], rtol=1e-3)
    d, _ = spline.closest(np.array([[10.0, 0.0], [20.0, 8.0]]))
    assert np.all(d < 1e-2)  # passes through its control points
    np.testing.assert_allclose(CatmullRomSpline([[0.0, 0.0], [0.0, 5.0]]).heading_rad(2.0), np.pi / 2)


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_ground_height_equals_pybullet_raycast_on_terrain(client, scene):
    world = _build(client, scene, seed=4)
    xy = np.random.default_rng(0).uniform(-0.45, 0.45, (400, 2)) * world.spec.terrain_size_m
    hits = p.rayTestBatch(np.column_stack([xy, np.full(len(xy), 500.0)]).tolist(),
                          np.column_stack([xy, np.full(len(xy), -500.0)]).tolist(), physicsClientId=client)
    on_terrain = np.array([h[0] == world.body_ids_by_role["terrain"][0] for h in hits])
    z = np.array([h[3][2] for h in hits])
    assert on_terrain.sum() > 300
    np.testing.assert_allclose(z[on_terrain], world.ground_height_m(xy[on_terrain, 0], xy[on_terrain, 1]), atol=1e-3)


def test_desert_decoys_at_least_six_identical_to_target_car(client):
    world = _build(client, "desert")
    assert len(world.decoys) >= 6
    def look(body):  # geometry type, mesh dimensions, colour, texture per visual shape
        data = p.getVisualShapeData(body, flags=p.VISUAL_SHAPE_DATA_TEXTURE_UNIQUE_IDS, physicsClientId=client)
        return [(d[2], tuple(d[3]), tuple(d[7]), d[8]) for d in data]
    for d in world.decoys:
        assert d.kind == world.target.kind == "car"
        np.testing.assert_array_equal(d.half_extents_m, world.target.half_extents_m)
        assert look(d.body_id) == look(world.target.body_id)


def test_desert_decoys_include_mover_and_parked_car_within_15_m_of_path(client):
    world = _build(client, "desert")
    route = world.target.motion.path
    parked = [d for d in world.decoys if not d.motion.is_moving]
    moving = [d for d in world.decoys if d.motion.is_moving]
    assert moving and parked
    parked_xy = np.array([world.vehicle_pose(d, 0.0)[0][:2] for d in parked])
    assert np.min(route.closest(parked_xy)[0]) <= DECOY_NEAR_PATH_M
    t = np.linspace(0.0, world.duration_s, 60)
    for d in moving:  # it drives while the target does, and comes near the target's path
        xy = np.array([world.vehicle_pose(d, ti)[0][:2] for ti in t])
        assert np.linalg.norm(xy[-1] - xy[0]) > 10.0
        assert np.min(route.closest(xy)[0]) <= DECOY_NEAR_PATH_M


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_desert_overtaking_decoy_passes_beside_target_in_its_lane_within_15_s(client, seed):
    """One identical car drives the target's way in a lane beside it: behind at the start, level with it within
    the paper's 15 s sequence (1-2 m between the cars, same heading), ahead at the end."""
    world = _build(client, "desert", seed)
    t = np.linspace(0.0, 15.0, 151)
    target = np.array([world.vehicle_pose(world.target, ti)[0][:2] for ti in t])
    heading = np.array([world.target.motion.path.heading_rad(world.target.motion.distance_m(ti)) for ti in t])
    forward = np.column_stack([np.cos(heading), np.sin(heading)])

    def along_and_beside(d):
        rel = np.array([world.vehicle_pose(d, ti)[0][:2] for ti in t]) - target
        return np.einsum("ij,ij->i", rel, forward), np.abs(forward[:, 0] * rel[:, 1] - forward[:, 1] * rel[:, 0])

    passes = []
    for d in world.decoys:
        along, beside = along_and_beside(d)
        if d.motion.is_moving and along[0] < -5.0 and along[-1] > 5.0:
            passes.append((along, beside, d))
    assert len(passes) == 1
    along, beside, decoy = passes[0]
    level = np.abs(along) < 2.0
    lo_m, hi_m = OVERTAKE_LATERAL_M
    assert level.any() and np.all((beside[level] > lo_m - LANE_TOLERANCE_M) & (beside[level] < hi_m + LANE_TOLERANCE_M))
    level_time = t[np.argmin(np.abs(along))]
    decoy_heading = decoy.motion.path.heading_rad(decoy.motion.distance_m(level_time))
    target_heading = world.target.motion.path.heading_rad(world.target.motion.distance_m(level_time))
    assert abs(np.angle(np.exp(1j * (decoy_heading - target_heading)))) < np.radians(10.0)


def test_city_takeoff_building_tall_and_roof_fills_part_of_start_view(client):
    world = _build(client, "city", seed=2)
    k = world.layout.takeoff_building
    lo, hi = world.buildings_lo_m[k], world.buildings_hi_m[k]
    pos, _ = world.drone_start()
    street = float(world.ground_height_m(*pos[:2]))
    assert hi[2] - street >= 28.0
    assert 30.0 <= pos[2] - street <= 34.0 and pos[2] > hi[2]
    # pinhole: pixel rays from drone_start meet the roof plane inside the roof rectangle for part of the image
    R_world_cam = _down_camera_rotation(world)
    u, v = np.meshgrid(np.arange(IMAGE_PX), np.arange(IMAGE_PX))
    rays = CameraIntrinsics.from_fov(IMAGE_PX, IMAGE_PX, FOV_DEG).rays(np.column_stack([u.ravel(), v.ravel()]))
    d = rays @ R_world_cam.T
    hit = pos + d * ((hi[2] - pos[2]) / d[:, 2])[:, None]
    on_roof = (hit[:, 0] >= lo[0]) & (hit[:, 0] <= hi[0]) & (hit[:, 1] >= lo[1]) & (hit[:, 1] <= hi[1])
    assert 0.2 < on_roof.mean() < 0.8
    # the roof edge the drone takes off from projects near the image centre
    edge = np.clip(pos[:2], lo[:2], hi[:2])
    border = edge.copy()
    k_axis = np.argmin(np.minimum(np.abs(edge - lo[:2]), np.abs(hi[:2] - edge)))
    border[k_axis] = lo[k_axis] if abs(edge[k_axis] - lo[k_axis]) < abs(hi[k_axis] - edge[k_axis]) else hi[k_axis]
    uv = _down_camera_points_to_pixels(world, np.array([[*border, hi[2]]]))[0]
    assert np.linalg.norm(uv - (IMAGE_PX - 1) / 2.0) < 0.2 * IMAGE_PX


def test_mountain_relief_and_slopes_near_route_over_seeds():
    spec = get_scene("mountain")
    for seed in range(4):
        layout = make_layout(spec, np.random.default_rng(seed), spec.target_speed_mps)
        m, hf = layout.target, layout.terrain
        route = m.path.position_m(np.arange(m.start_s_m, m.end_s_m, 1.0))
        gx, gy = np.meshgrid(hf.x_m, hf.y_m)
        dist, foot = distance_to_path(hf, m.path, 40.0)
        near = ((dist <= 40.0) & (foot >= m.start_s_m) & (foot <= m.end_s_m)).ravel()
        nodes = np.column_stack([gx.ravel(), gy.ravel()])
        heights = hf.height_m(nodes[near, 0], nodes[near, 1])
        assert heights.max() - heights.min() >= 40.0, seed
        assert hf.slope_deg(nodes[near, 0] + 0.1, nodes[near, 1] + 0.2).max() >= 20.0, seed
        road_h = hf.height_m(route[:, 0], route[:, 1])
        assert np.max(np.abs(np.diff(road_h))) < 0.2  # the carved road itself stays drivable (< 20 % grade)


def test_mountain_route_turns_65_deg_after_about_50_m(client):
    world = _build(client, "mountain", seed=1)
    m = world.target.motion
    heading = m.path.heading_rad(np.arange(m.start_s_m, m.end_s_m, 1.0))
    turn = np.degrees(np.unwrap(heading) - heading[0])
    assert abs(abs(turn[-1]) - 65.0) < 3.0
    first_half_turn = np.argmax(np.abs(turn) > 32.5)
    assert 40 <= first_half_turn <= 60


def test_mountain_lake_is_flat_and_untextured(client):
    world = _build(client, "mountain", seed=3)
    lake = world.layout.lake
    box = lake.centre_m + np.random.default_rng(0).uniform(-1.0, 1.0, (2000, 2)) * lake.semi_axes_m.max()
    inner = box[lake.normalised_radius(box[:, 0], box[:, 1]) < 0.98]
    assert len(inner) > 200
    h = world.ground_height_m(inner[:, 0], inner[:, 1])
    assert np.ptp(h) < 1e-5 and abs(h[0] - lake.level_m) < 1e-5
    (lake_body,) = world.body_ids_by_role["lake"]
    data = p.getVisualShapeData(lake_body, flags=p.VISUAL_SHAPE_DATA_TEXTURE_UNIQUE_IDS, physicsClientId=client)
    assert all(d[8] == -1 for d in data)  # uniform colour, no texture


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_start_view_has_target_and_100_harris_corners_outside_target_box(client, scene):
    world = _build(client, scene, seed=5)
    rgb, seg = _render_down(client, world)
    target = seg == world.target.body_id
    assert target.sum() >= 30  # the target is in view at the start
    ys, xs = np.nonzero(target)
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    corners = cv2.goodFeaturesToTrack(gray, 500, 0.01, 3, useHarrisDetector=True).reshape(-1, 2)
    cx, cy = corners[:, 0], corners[:, 1]
    in_box = (cx >= xs.min() - TARGET_BOX_MARGIN_PX) & (cx <= xs.max() + TARGET_BOX_MARGIN_PX)
    in_box &= (cy >= ys.min() - TARGET_BOX_MARGIN_PX) & (cy <= ys.max() + TARGET_BOX_MARGIN_PX)
    lake = np.isin(seg, world.body_ids_by_role["lake"])[np.round(cy).astype(int), np.round(cx).astype(int)]
    assert np.sum(~in_box & ~lake) >= HARRIS_MIN_CORNERS


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_same_seed_same_world_and_different_seed_different_world(client, scene):
    def snapshot(seed):
        world = _build(client, scene, seed)
        poses = [world.vehicle_pose(v, 7.5) for v in (world.target, *world.decoys)]
        return world.terrain.heights_m.copy(), np.concatenate([np.concatenate([q, R.ravel()]) for q, R in poses])
    (h1, v1), (h2, v2), (h3, v3) = snapshot(11), snapshot(11), snapshot(12)
    np.testing.assert_array_equal(h1, h2)
    np.testing.assert_array_equal(v1, v2)
    assert not np.array_equal(h1, h3)
    assert v1.shape != v3.shape or not np.allclose(v1, v3)


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_target_hugs_terrain_and_body_follows_update_once_placed(client, scene):
    world = _build(client, scene, seed=6)
    hz = world.target.half_extents_m[2]
    for t in np.linspace(0.0, world.duration_s + 2.0, 12):
        world.update(t)
        world.place_vehicle_bodies()
        pos, R = world.vehicle_pose(world.target, t)
        bottom = pos - hz * R[:, 2]
        assert abs(bottom[2] - world.ground_height_m(*bottom[:2])) <= HUG_TOLERANCE_M
        body_pos, body_quat = p.getBasePositionAndOrientation(world.target.body_id, physicsClientId=client)
        np.testing.assert_allclose(body_pos, pos, atol=1e-6)
        np.testing.assert_allclose(quat_xyzw_to_matrix(body_quat), R, atol=1e-6)


def test_target_moves_at_its_speed_and_stops_at_path_end(client):
    world = _build(client, "desert", seed=7, target_speed_mps=2.0)
    m = world.target.motion
    assert world.duration_s == pytest.approx(m.path.length_m / 2.0)
    v = world.target_velocity_mps(5.0)
    assert np.linalg.norm(v[:2]) == pytest.approx(2.0)
    p0, _ = world.vehicle_pose(world.target, 4.99)
    p1, _ = world.vehicle_pose(world.target, 5.01)
    np.testing.assert_allclose((p1 - p0) / 0.02, v, atol=0.15)
    end, _ = world.vehicle_pose(world.target, world.duration_s)
    later, _ = world.vehicle_pose(world.target, world.duration_s + 10.0)
    np.testing.assert_allclose(end, later)
    np.testing.assert_array_equal(world.target_velocity_mps(world.duration_s + 1.0), 0.0)


def test_rays_pass_through_vehicles_but_hit_terrain(client):
    world = _build(client, "desert", seed=8)
    pos, _ = world.vehicle_pose(world.target, 0.0)
    hit = p.rayTest((pos + [0, 0, 20]).tolist(), (pos - [0, 0, 20]).tolist(), physicsClientId=client)[0]
    assert hit[0] in world.static_body_ids
    assert hit[0] not in {v.body_id for v in (world.target, *world.decoys)}


def test_surface_height_includes_roofs_and_ground_height_excludes_them(client):
    world = _build(client, "city", seed=0)
    lo, hi = world.buildings_lo_m, world.buildings_hi_m
    centre = (lo + hi) / 2.0
    np.testing.assert_allclose(world.surface_height_m(centre[:, 0], centre[:, 1]), hi[:, 2])
    assert np.all(world.ground_height_m(centre[:, 0], centre[:, 1]) < hi[:, 2] - 5.0)
    hit = p.rayTest([*centre[0, :2], 100.0], [*centre[0, :2], -100.0], physicsClientId=client)[0]
    assert hit[0] in world.body_ids_by_role["buildings"] and hit[3][2] == pytest.approx(hi[0, 2], abs=1e-3)


def test_vehicle_pose_same_whether_or_not_update_ran_for_that_time(client):
    world = _build(client, "desert", seed=9)
    vehicles = (world.target, *world.decoys)
    times = np.linspace(0.1, world.duration_s + 1.0, 9)
    cached = []
    for t in times:
        on_demand = [world.vehicle_pose(v, t) for v in vehicles]  # before update(t): computed, not cached
        world.update(t)
        cached.append([world.vehicle_pose(v, t) for v in vehicles])
        for (p0, R0), (p1, R1) in zip(on_demand, cached[-1]):
            np.testing.assert_array_equal(p0, p1)
            np.testing.assert_array_equal(R0, R1)
    for t, poses in zip(times, cached):  # earlier times after later updates, and the vectorised reference
        for v, (pos, R) in zip(vehicles, poses):
            again = world.vehicle_pose(v, t)
            np.testing.assert_array_equal(again[0], pos)
            np.testing.assert_array_equal(again[1], R)
            s = v.motion.distance_m(t)
            ref_pos, ref_R = terrain_pose(world.terrain, v.motion.path.position_m(s)[None],
                                          v.motion.path.heading_rad(s), v.half_extents_m)
            np.testing.assert_allclose(pos, ref_pos[0], atol=1e-12)
            np.testing.assert_allclose(R, ref_R[0], atol=1e-12)
    with pytest.raises(ValueError):  # read-only: a caller cannot corrupt the cache
        cached[-1][0][0][0] = 0.0


def test_scalar_height_queries_equal_vectorised_ones_including_roof_edges(client):
    world = _build(client, "city", seed=1)
    lo, hi = world.buildings_lo_m, world.buildings_hi_m
    rng = np.random.default_rng(2)
    edges = np.concatenate([lo[:, :2], hi[:, :2], np.column_stack([lo[:, 0], hi[:, 1]]),
                            np.nextafter(hi[:, :2], np.inf), np.nextafter(lo[:, :2], -np.inf)])
    xy = np.concatenate([edges, rng.uniform(-0.55, 0.55, (2000, 2)) * world.spec.terrain_size_m])
    scalar = np.array([world.surface_height_m(np.float64(x), np.float64(y)) for x, y in xy])
    np.testing.assert_array_equal(scalar, world.surface_height_m(xy[:, 0], xy[:, 1]))
    assert np.sum(scalar > world.ground_height_m(xy[:, 0], xy[:, 1]) + 1.0) > len(lo)  # roofs were found
    ground = np.array([world.ground_height_m(float(x), float(y)) for x, y in xy])
    np.testing.assert_array_equal(ground, world.ground_height_m(xy[:, 0], xy[:, 1]))
    gradient = np.array([world.terrain.gradient_at(x, y) for x, y in xy.tolist()])
    np.testing.assert_array_equal(gradient, world.terrain.gradient(xy[:, 0], xy[:, 1]))
    path = world.target.motion.path
    s = np.concatenate([[-1.0, 0.0, path.length_m, path.length_m + 1.0], rng.uniform(0.0, path.length_m, 200)])
    np.testing.assert_array_equal([path.point_at(si) for si in s.tolist()],
                                  np.column_stack([path.position_m(s), path.tangent(s)]))


def test_desert_boulders_are_one_static_body_hit_by_rays_and_contacts(client):
    world = _build(client, "desert", seed=2)
    (rocks,) = world.body_ids_by_role["boulders"]
    assert len(world.layout.boulders) == world.spec.boulder_count > 1 and rocks in world.static_body_ids
    assert p.getNumBodies(physicsClientId=client) == len(world.static_body_ids) + 1 + len(world.decoys)
    # a vertical ray through each boulder centre meets the rock body at (or above, where rocks overlap) the
    # top vertex of that boulder's mesh, which sits on its vertical axis
    tops = []
    for b in world.layout.boulders:
        v = rock_mesh(b.prototype, b.size_class).vertices
        tops.append(b.centre_m[2] + v[np.argmin(np.hypot(v[:, 0], v[:, 1]) - v[:, 2])][2])
    centres = np.array([b.centre_m for b in world.layout.boulders])
    hits = p.rayTestBatch((centres + [0.0, 0.0, 50.0]).tolist(), (centres - [0.0, 0.0, 50.0]).tolist(),
                          physicsClientId=client)
    assert all(h[0] == rocks for h in hits)
    assert np.all(np.array([h[3][2] for h in hits]) >= np.array(tops) - 1e-4)
    # a dynamic box dropped on the largest boulder touches the rock body, as crash checks need
    k = int(np.argmax([b.radii_m[2] for b in world.layout.boulders]))
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.2, 0.2, 0.05], physicsClientId=client)
    box = p.createMultiBody(1.5, shape, -1, [*centres[k, :2], tops[k] + 1.0], physicsClientId=client)
    p.setGravity(0.0, 0.0, -9.81, physicsClientId=client)
    for _ in range(240):
        p.stepSimulation(physicsClientId=client)
    assert rocks in {c[2] for c in p.getContactPoints(bodyA=box, physicsClientId=client)}


def test_bullet_list_same_shape_refills_the_same_list_objects():
    first = bullet_list("test_vertices", np.zeros((4, 3)))
    rows = list(first)
    second = bullet_list("test_vertices", np.arange(12.0).reshape(4, 3))
    assert second is first and all(a is b for a, b in zip(second, rows))  # pybullet's leaked refs stay bounded
    assert second == np.arange(12.0).reshape(4, 3).tolist()
    assert bullet_list("test_vertices", np.ones((5, 3))) is not first  # another shape, another list
    with pytest.raises(ValueError, match="test_bad"):
        bullet_list("test_bad", np.zeros((2, 2, 2)))


@pytest.mark.parametrize("scene", ["desert", "mountain", "city"])
def test_a_pitched_camera_starts_its_standoff_behind_at_the_same_height(client, scene):
    """At 45 deg pitch the drone starts one height above the ground behind the downward camera's start, against its
    yaw, at the same height above the ground there; at 90 deg (the default) the start is the scene's."""
    world = _build(client, scene)
    nadir, yaw = world.drone_start()
    assert np.array_equal(world.drone_start(90.0)[0], nadir)
    height_m = nadir[2] - world.ground_height_m(float(nadir[0]), float(nadir[1]))
    pitched, pitched_yaw = world.drone_start(45.0)
    back_m = (nadir[:2] - pitched[:2]) @ np.array([np.cos(yaw), np.sin(yaw)])
    assert pitched_yaw == yaw and back_m == pytest.approx(height_m) and np.linalg.norm(nadir[:2] - pitched[:2]) == \
        pytest.approx(height_m)
    assert pitched[2] - world.ground_height_m(float(pitched[0]), float(pitched[1])) == pytest.approx(height_m)


def _collider_ids(world: World) -> list[int]:
    """The world's bodies with a collision shape: the terrain's first tile, the boulders, the buildings' walls."""
    roles = world.body_ids_by_role
    return [roles["terrain"][0], *roles["boulders"], *roles["buildings"][:1]]


@pytest.mark.parametrize("scene", ["desert", "city", "mountain"])
def test_an_undrawn_world_has_no_visual_shapes_and_the_same_colliders_and_rays(client, scene):
    """A world never rendered (oracle perception) is built without visual shapes; its physics must not notice."""
    def built(rendered: bool):
        world = _build(client, scene, seed=3, rendered=rendered)
        n_bodies = p.getNumBodies(physicsClientId=client)
        # pybullet reports a body without a visual shape as drawn by its collision shape, if it has one
        drawn_ids = {i for i in range(n_bodies) if p.getVisualShapeData(i, physicsClientId=client)}
        boxes = [p.getAABB(b, physicsClientId=client) for b in _collider_ids(world)]
        role = {b: name for name, ids in world.body_ids_by_role.items() for b in ids}
        (x0, x1), (y0, y1) = world.terrain.x_m[[0, -1]], world.terrain.y_m[[0, -1]]
        gx, gy = np.meshgrid(np.linspace(x0, x1, 40), np.linspace(y0, y1, 40))
        starts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 200.0)])
        hits = p.rayTestBatch(starts.tolist(), (starts - [0.0, 0.0, 400.0]).tolist(), physicsClientId=client)
        return world, n_bodies, drawn_ids, boxes, [(role.get(h[0]), h[3]) for h in hits]

    drawn, n_bodies, drawn_ids, boxes, rays = built(True)
    undrawn, n_bodies_u, drawn_ids_u, boxes_u, rays_u = built(False)
    assert drawn.drawn and not undrawn.drawn
    assert drawn.target.body_id in drawn_ids and drawn_ids_u == set(_collider_ids(undrawn))
    assert n_bodies_u == n_bodies - len(drawn.body_ids_by_role["terrain"]) + 1  # the terrain as one body
    assert boxes_u == boxes
    assert {r for r, _ in rays} >= {"terrain"} and rays_u == rays


def test_rendering_an_undrawn_world_raises_naming_the_way_to_draw_it(client):
    world = _build(client, "desert", seed=3, rendered=False)
    pose = Pose(np.eye(3), np.array([0.0, 0.0, 30.0]))
    with pytest.raises(RuntimeError, match="render_oracle_frames"):
        world.prepare_render(pose, CameraIntrinsics.from_fov(64, 64, FOV_DEG), 0.1, 100.0)
