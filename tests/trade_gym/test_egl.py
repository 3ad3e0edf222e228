"""renderer="egl": the env runs on pybullet's EGL plugin where it loads (Mesa's software llvmpipe counts) and its
images agree with TinyRenderer's where two rasterisers can; a bad renderer name fails everywhere."""

from __future__ import annotations

import functools
import importlib.util

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade_gym.env import TradeFollowEnv
from tests.trade_gym.env_checks import check_env_strict

SIDE_PX = 64
SEED = 3
# TinyRenderer and OpenGL rasterise the same triangles with other rules (edges, depth interpolation) and shade them
# differently (EGL's colours differ by 12-20 of 255 on average, so colours are not compared). Measured at 64 px,
# seeds 3 and 5 of each scene: the median |depth difference| over pixels both hit is 0.01-0.13 % of the depth, the
# target's segmentation box is the same, >= 99.9 % of pixels show the same body.
DEPTH_MEDIAN_REL_TOL = 0.005
BOX_TOL_PX = 1


@functools.cache
def egl_available() -> bool:
    """Whether pybullet's EGL renderer plugin loads into a DIRECT client here."""
    spec = importlib.util.find_spec("eglRenderer")
    if spec is None or spec.origin is None:
        return False
    client = p.connect(p.DIRECT)
    try:
        plugin = p.loadPlugin(spec.origin, "_eglRendererPlugin", physicsClientId=client)
        if plugin >= 0:
            p.unloadPlugin(plugin, physicsClientId=client)
        return plugin >= 0
    finally:
        p.disconnect(client)


needs_egl = pytest.mark.skipif(not egl_available(), reason="pybullet's EGL renderer plugin does not load here")


def _env(renderer: str, **kwargs) -> TradeFollowEnv:
    return TradeFollowEnv(perception="oracle", render_oracle_frames=True, camera_size=SIDE_PX, renderer=renderer,
                          **kwargs)


def _target_box(frame, body_id: int) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(frame.seg == body_id)
    assert rows.size > 0, "the target has no pixel"
    return int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())


def test_a_bad_renderer_is_refused_by_name():
    with pytest.raises(ValueError, match="renderer.*'vulkan'"):
        gym.make("TradeFollow-v0", renderer="vulkan")


@needs_egl
def test_egl_env_resets_and_steps_with_the_target_in_a_non_blank_image():
    env = gym.make("TradeFollow-v0", renderer="egl", camera_size=SIDE_PX)
    try:
        env.reset(seed=SEED)
        for _ in range(3):
            _, reward, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
            assert np.isfinite(reward) and not (terminated or truncated)
        frame, world = env.unwrapped.camera_frame, env.unwrapped.world
        assert frame.rgb.shape == (SIDE_PX, SIDE_PX, 3) and frame.rgb.std() > 5.0
        assert np.count_nonzero(frame.seg == world.target.body_id) >= 4 and info["target_visible"]
    finally:
        env.close()


@needs_egl
@pytest.mark.parametrize("scene", ["desert", "city", "mountain"])
def test_egl_and_tiny_frames_of_one_reset_agree(scene):
    frames = {}
    for renderer in ("tiny", "egl"):
        env = _env(renderer, scene=scene)
        try:
            env.reset(seed=SEED)
            frames[renderer], target = env.camera_frame, env.world.target.body_id
        finally:
            env.close()
    tiny, egl = frames["tiny"], frames["egl"]
    box_tiny, box_egl = _target_box(tiny, target), _target_box(egl, target)
    assert np.max(np.abs(np.subtract(box_tiny, box_egl))) <= BOX_TOL_PX, (box_tiny, box_egl)
    hit = (tiny.seg >= 0) & (egl.seg >= 0)
    assert hit.mean() > 0.9
    rel = np.abs(egl.depth_m[hit] - tiny.depth_m[hit]) / tiny.depth_m[hit]
    assert np.median(rel) < DEPTH_MEDIAN_REL_TOL
    assert np.mean(tiny.seg == egl.seg) > 0.99  # the same body at almost every pixel


@needs_egl
def test_culling_leaves_egl_frames_unchanged():
    env = _env("egl", scene="desert")
    try:
        env.reset(seed=SEED)
        client, culler = env._client, env.world.culler
        for _ in range(2):
            env.step(np.array([0.8, 0.3, 0.0, 0.2], dtype=np.float32))
            pose = env.camera_frame.T_world_cam
            culled = env.camera.render(pose)
            assert 0 < culler.shown.sum() < len(culler.body_ids)
            colour = p.getVisualShapeData(culler.body_ids[int(np.argmax(culler.shown))], physicsClientId=client)[0][7]
            for body in np.asarray(culler.body_ids)[~culler.shown]:  # draw every tile, render the same pose again
                p.changeVisualShape(int(body), -1, rgbaColor=list(colour), physicsClientId=client)
            full = env.camera.render(pose)
            np.testing.assert_array_equal(full.rgb, culled.rgb)
            np.testing.assert_array_equal(full.depth_m, culled.depth_m)
            np.testing.assert_array_equal(full.seg, culled.seg)
            culler.shown[:] = True
    finally:
        env.close()


@needs_egl
def test_egl_env_survives_resets_into_other_worlds():
    env = _env("egl", scene="mountain")
    try:
        for seed in (0, 1):
            env.reset(seed=seed)
            env.step(np.zeros(4, dtype=np.float32))
            assert np.count_nonzero(env.camera_frame.seg == env.world.target.body_id) > 0
    finally:
        env.close()


@needs_egl
def test_check_env_passes_with_egl():
    env = gym.make("TradeFollow-v0", renderer="egl", camera_size=SIDE_PX, perception="oracle",
                   render_oracle_frames=True)
    try:
        check_env_strict(env)
    finally:
        env.close()


def test_bench_meta_names_the_renderers_the_runs_used():
    from trade_gym.bench.results import collect_meta

    assert collect_meta("quick", [], 1, 1, 1.0)["renderer"] == "TinyRenderer"
    assert collect_meta("quick", [], 1, 2, 1.0, renderers=["egl", "tiny", "egl"])["renderer"] == "EGL, TinyRenderer"
