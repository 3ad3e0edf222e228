"""View culling of the terrain tiles: the frustum test on hand-built boxes, renders unchanged by it, colours kept."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from trade.geometry import CameraIntrinsics, Pose
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.culling import ViewCuller, boxes_in_view
from trade_gym.sim.world import TERRAIN_TILES_PER_SIDE

K = CameraIntrinsics.from_fov(64, 64, 90.0)  # half-angle 45 deg: at 10 m the view spans x, y in [-10, 10] m
DOWN = np.diag([1.0, -1.0, -1.0])  # camera z (forward) = world -z, x = world x, y = world -y
T_DOWN_10M = Pose(DOWN, np.array([0.0, 0.0, 10.0]))


def _box(centre, half=0.5):
    c = np.asarray(centre, dtype=np.float64)
    return c - half, c + half


@pytest.mark.parametrize("centre, seen", [
    ((0.0, 0.0, 0.0), True),      # straight below
    ((9.0, -9.0, 0.0), True),     # near a corner of the footprint
    ((10.4, 0.0, 0.0), True),     # straddles the footprint's edge
    ((12.0, 0.0, 0.0), False),    # beside it
    ((0.0, -14.0, 0.0), False),
    ((0.0, 0.0, 12.0), False),    # above the camera (behind it)
    ((0.0, 0.0, 9.95, 0.02), False),  # closer than the near plane
    ((0.0, 0.0, -2000.0), False), # beyond the far plane
])
def test_boxes_in_view_keeps_what_the_frustum_can_see_and_drops_the_rest(centre, seen):
    lo, hi = _box(centre[:3], *centre[3:])
    got = boxes_in_view(lo[None], hi[None], T_DOWN_10M, K, near_m=0.1, far_m=1000.0)
    assert got.tolist() == [seen]


def test_a_box_spanning_the_whole_view_is_kept_though_no_corner_is_in_it():
    got = boxes_in_view(np.array([[-100.0, -100.0, -1.0]]), np.array([[100.0, 100.0, 0.0]]), T_DOWN_10M, K, 0.1, 1e3)
    assert got.tolist() == [True]


def test_culler_rejects_mismatched_boxes_and_colours():
    with pytest.raises(ValueError, match="one box and colour per body"):
        ViewCuller(0, [1, 2], np.zeros((2, 3)), np.ones((2, 3)), [(1.0, 1.0, 1.0, 1.0)])


@pytest.mark.parametrize("appearance", ["fixed", "randomized"])
def test_culled_frames_equal_the_frames_with_every_tile_drawn(appearance):
    env = TradeFollowEnv(scene="desert", perception="oracle", render_oracle_frames=True, camera_size=64,
                         appearance=appearance)
    try:
        env.reset(seed=2)
        world, client = env.world, env.unwrapped._client
        culler = world.culler
        assert len(culler.body_ids) == TERRAIN_TILES_PER_SIDE ** 2 == len(world.body_ids_by_role["terrain"])
        for _ in range(3):
            env.step(np.array([0.8, 0.3, 0.0, 0.2], dtype=np.float32))
            frame = env.camera_frame
            lighting = env._look.appearance.lighting if env._look.appearance is not None else None
            culled = env.camera.render(frame.T_world_cam, lighting)  # as drawn, before any camera effect
            np.testing.assert_array_equal(culled.depth_m, frame.depth_m)
            assert 0 < culler.shown.sum() < len(culler.body_ids) / 2  # the desert's footprint: a few tiles
            hidden = [b for b, s in zip(culler.body_ids, culler.shown) if not s]
            shown = [b for b, s in zip(culler.body_ids, culler.shown) if s]
            colour = p.getVisualShapeData(shown[0], physicsClientId=client)[0][7]
            assert p.getVisualShapeData(hidden[0], physicsClientId=client)[0][7] == (*colour[:3], 0.0)
            for body in hidden:  # draw every tile in its colour, render the same pose again
                p.changeVisualShape(body, -1, rgbaColor=list(colour), physicsClientId=client)
            full = env.camera.render(frame.T_world_cam, lighting)
            np.testing.assert_array_equal(full.rgb, culled.rgb)
            np.testing.assert_array_equal(full.depth_m, culled.depth_m)
            np.testing.assert_array_equal(full.seg, culled.seg)
            culler.shown[:] = True  # the culler now knows every tile is drawn
    finally:
        env.close()


def test_a_colour_set_while_hidden_is_the_colour_shown_later():
    client = p.connect(p.DIRECT)
    try:
        shape = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.5, 0.5, 0.5], physicsClientId=client)
        bodies = [p.createMultiBody(0.0, -1, shape, [x, 0.0, 0.0], physicsClientId=client) for x in (0.0, 50.0)]
        lo, hi = zip(*(_box((x, 0.0, 0.0)) for x in (0.0, 50.0)))
        culler = ViewCuller(client, bodies, lo, hi, [(1.0, 1.0, 1.0, 1.0)] * 2)
        colour = lambda b: p.getVisualShapeData(b, physicsClientId=client)[0][7]  # noqa: E731
        assert culler.update(T_DOWN_10M, K, 0.1, 1e3) == 1 and colour(bodies[1])[3] == 0.0
        culler.set_colour((0.2, 0.4, 0.6, 1.0))
        assert colour(bodies[0]) == pytest.approx((0.2, 0.4, 0.6, 1.0)) and colour(bodies[1])[3] == 0.0
        moved = Pose(DOWN, np.array([50.0, 0.0, 10.0]))
        assert culler.update(moved, K, 0.1, 1e3) == 1
        assert colour(bodies[1]) == pytest.approx((0.2, 0.4, 0.6, 1.0)) and colour(bodies[0]) == pytest.approx(
            (0.2, 0.4, 0.6, 0.0))
    finally:
        p.disconnect(client)
