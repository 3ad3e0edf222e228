"""The run video: onboard view beside a top view over an IoU / depth-error strip, at least 512 px a panel."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from trade_gym.bench.dashboard import DRONE_RGB, TARGET_RGB, Dashboard, view_box
from trade_gym.bench.suites import RunSpec
from trade_gym.bench.video import VIDEO_PANEL_PX, record_video
from trade_gym.env import TradeFollowEnv
from trade_gym.rollout import fly_episode
from trade_gym.bench.policies import make_policy

STEPS = 4
PANEL_PX = 128  # the dashboard's own tests draw small panels


@pytest.fixture(scope="module")
def flown():
    env = TradeFollowEnv(scene="city", perception="oracle", episode_duration_s=1.0)
    try:
        infos = fly_episode(env, make_policy("scripted", 0, env.config.camera_pitch_deg), 0, STEPS)
        yield env, infos
    finally:
        env.close()


def test_view_box_holds_the_target_route_and_the_drone(flown):
    env, infos = flown
    box = view_box(env.world, PANEL_PX)
    for info in infos:
        for key in ("target_position_m", "drone_position_m"):
            u, v = box.to_px(info[key])[0]
            assert 0 <= u < PANEL_PX and 0 <= v < PANEL_PX


def test_frame_is_two_panels_over_a_strip_with_target_and_drone_drawn_where_they_are(flown):
    env, infos = flown
    board = Dashboard(env.world, PANEL_PX, duration_s=1.0)
    onboard = np.zeros((32, 32, 3), np.uint8)
    for info in infos:
        frame = board.frame(onboard, info, np.asarray(info["target_position_m"]))
    header_px = len(board_header_rows(frame))
    strip_px = frame.shape[0] - header_px - PANEL_PX
    assert frame.shape[1] == 2 * PANEL_PX and 0 < strip_px < PANEL_PX and frame.dtype == np.uint8
    top = frame[header_px:header_px + PANEL_PX, PANEL_PX:]
    for key, colour in (("target_position_m", TARGET_RGB), ("drone_position_m", DRONE_RGB)):
        u, v = board.box.to_px(infos[-1][key])[0]
        near = top[max(v - 8, 0):v + 9, max(u - 8, 0):u + 9].reshape(-1, 3)
        assert (near == colour).all(axis=1).any(), key
    strip = frame[header_px + PANEL_PX:]
    assert (strip.reshape(-1, 3) == TARGET_RGB).all(axis=1).any()  # the IoU line


def board_header_rows(frame: np.ndarray) -> np.ndarray:
    """The legend rows above the panels: the leading rows of the strip's background colour or its text."""
    onboard_rows = np.flatnonzero((frame[:, :PANEL_PX] == 0).all(axis=(1, 2)))  # the black test image
    return frame[:onboard_rows[0]]


def test_record_video_writes_an_mp4_of_every_frame_with_panels_of_at_least_512_px(tmp_path):
    spec = RunSpec("follow", "follow", "desert", "scripted", "trade", "gt", 0, STEPS, 64)
    path = record_video(dataclasses.replace(spec), tmp_path / "video")
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    if path.suffix == ".gif":
        pytest.fail("OpenCV wrote no mp4 (the project's opencv-python-headless has an mp4 encoder)")
    assert len(frames) == STEPS + 1  # the reset frame and every step
    assert frames[0].shape[1] == 2 * VIDEO_PANEL_PX and frames[0].shape[0] > VIDEO_PANEL_PX


def test_overlay_tints_the_ground_mask_and_leaves_the_rest():
    from types import SimpleNamespace

    from trade.geometry import CameraIntrinsics, Pose
    from trade_gym.perception.trade_stack import TradeOverlay

    image = np.full((16, 16, 3), 100, np.uint8)
    mask = np.zeros((16, 16), bool)
    mask[8:] = True
    est = SimpleNamespace(roi=None, trajectory_preview_world_m=np.zeros((0, 3)))
    K = CameraIntrinsics(10.0, 10.0, 7.5, 7.5, 16, 16)
    TradeOverlay(est, K, Pose(np.eye(3), np.zeros(3)), mask).draw(image)
    assert (image[:8] == 100).all()
    assert (image[8:, :, 0] < 100).all() and (image[8:, :, 1:] > 100).all()  # towards cyan
