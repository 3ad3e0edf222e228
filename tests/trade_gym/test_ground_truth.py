"""Ground truth's shortcuts give what the long way gives: one ray batch equals separate ray tests, one
flattened projection equals projecting each vehicle on its own."""

from __future__ import annotations

import numpy as np

from trade_gym.env import TradeFollowEnv
from trade_gym.ground_truth import ground_depth, projected_boxes, visible_fraction


def test_ground_truth_ray_batch_equals_separate_visibility_and_ground_ray_tests():
    env = TradeFollowEnv(scene="city", perception="oracle", camera_size=64)
    try:
        env.reset(seed=1)
        for _ in range(30):
            _, _, _, _, info = env.step(np.array([0.4, 0.2, 0.0, 0.0], np.float32))
            truth = env._last_truth
            T = env._true_camera_pose()
            box = env._vehicles.box(env.world.target, env._t_s)
            assert truth.target_visible_fraction == visible_fraction(env._client, env.camera.intrinsics, T, box)
            centre = truth.target_bbox[:2] + truth.target_bbox[2:] / 2.0
            expected = ground_depth(env._client, env.camera.intrinsics, T, centre,
                                    env._state.position_m[2] + 1000.0)
            assert np.array_equal(truth.ground_depth_m, expected, equal_nan=True)
    finally:
        env.close()


def test_projected_boxes_of_all_vehicles_equal_each_vehicle_projected_alone():
    env = TradeFollowEnv(scene="desert", perception="oracle", camera_size=64)
    try:
        env.reset(seed=0)
        for _ in range(20):
            env.step(np.array([0.3, -0.2, 0.0, 0.0], np.float32))
            T_cam_world = env._true_camera_pose().inverse()
            corners = env._vehicles.corners(env._vehicles.box(env.world.target, env._t_s), env._t_s)
            together = projected_boxes(env.camera.intrinsics, T_cam_world, corners)
            alone = np.concatenate([projected_boxes(env.camera.intrinsics, T_cam_world, c[None]) for c in corners])
            assert np.array_equal(together, alone, equal_nan=True)
    finally:
        env.close()
