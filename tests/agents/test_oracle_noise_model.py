"""The oracle's noise model that learned followers train on: correlated noise, first-fix delay, coasting.

(Here beside the training code it serves; `trade_gym/perception/oracle.py` implements it.)
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.geometry import Pose
from trade.types import ImuBatch
from trade_gym.config import CAMERA_RATE_HZ, EnvConfig
from trade_gym.ground_truth import GroundTruth
from trade_gym.perception.base import SensorFrame
from trade_gym.perception.oracle import OracleConfig, OraclePerception

DT_S = 1.0 / CAMERA_RATE_HZ
HEIGHT_M = 20.0
TRUE_BOX = np.array([100.0, 110.0, 20.0, 30.0])
N_FRAMES = 6000
# Camera looking straight down from HEIGHT_M: camera z = -world z, x = world x, y = -world y.
T_WORLD_CAM = Pose(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, HEIGHT_M]))
EMPTY_IMU = ImuBatch(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))


def truth(box: np.ndarray = TRUE_BOX) -> GroundTruth:
    return GroundTruth(
        target_bbox=box.copy(), decoy_bboxes=np.zeros((0, 4)), target_visible_fraction=1.0,
        target_position_m=np.zeros(3), target_velocity_mps=np.array([2.0, 0.0, 0.0]),
        target_depth_m=HEIGHT_M, target_center_px=np.array([110.0, 125.0]), ground_depth_m=HEIGHT_M,
    )


def run(config: OracleConfig, n_frames: int, seed: int = 0, hidden_after: int | None = None) -> list:
    now = {"truth": truth()}  # the current frame's truth, as the env's provider returns it
    oracle = OraclePerception(config, lambda: now["truth"], lambda: T_WORLD_CAM)
    frame = lambda k: SensorFrame(k * DT_S, None, T_WORLD_CAM, EMPTY_IMU)  # noqa: E731
    outputs = [oracle.reset(frame(0), TRUE_BOX, np.random.default_rng(seed))]
    for k in range(1, n_frames):
        box = np.full(4, np.nan) if hidden_after is not None and k > hidden_after else TRUE_BOX
        now["truth"] = truth(box)
        outputs.append(oracle.step(frame(k)))
    return outputs


def box_errors(outputs: list) -> np.ndarray:
    return np.array([o.bbox for o in outputs]) - TRUE_BOX


def lag1(x: np.ndarray) -> float:
    return float(np.sum(x[:-1] * x[1:]) / np.sum(x * x))


def test_oracle_correlated_noise_has_the_configured_sigma_and_lag1_correlation():
    tau = 0.5
    errors = box_errors(run(OracleConfig(box_sigma_px=2.0, noise_correlation_s=tau), N_FRAMES))
    rho = math.exp(-DT_S / tau)
    assert np.std(errors) == pytest.approx(2.0, rel=0.15)
    assert np.mean([lag1(errors[:, i]) for i in range(4)]) == pytest.approx(rho, abs=0.02)


def test_oracle_zero_correlation_time_gives_white_noise():
    errors = box_errors(run(OracleConfig(box_sigma_px=2.0, noise_correlation_s=0.0), N_FRAMES))
    assert abs(np.mean([lag1(errors[:, i]) for i in range(4)])) < 0.05
    assert np.std(errors) == pytest.approx(2.0, rel=0.05)


def test_oracle_position_noise_scales_with_depth_and_is_correlated():
    outputs = run(OracleConfig(depth_sigma_frac=0.05, noise_correlation_s=1.0), N_FRAMES)
    errors = np.array([o.position_world_m for o in outputs])  # truth at the origin
    assert np.std(errors) == pytest.approx(0.05 * HEIGHT_M, rel=0.25)
    assert lag1(errors[:, 0]) > 0.9


def test_oracle_first_fix_delay_gives_box_without_position_until_the_delay_passes():
    delay = 0.5
    outputs = run(OracleConfig(first_fix_delay_s=delay), 30)
    first_fix = next(k for k, o in enumerate(outputs) if np.all(np.isfinite(o.position_world_m)))
    assert first_fix == math.ceil(delay * CAMERA_RATE_HZ - 1e-9)
    for o in outputs[:first_fix]:
        assert o.valid and np.all(np.isfinite(o.bbox))
        assert np.all(np.isnan(o.velocity_world_mps)) and math.isnan(o.target_depth_m)
    assert all(np.all(np.isfinite(o.velocity_world_mps)) for o in outputs[first_fix:])


def test_oracle_coasting_moves_the_last_position_on_at_the_last_velocity():
    outputs = run(OracleConfig(box_sigma_px=0.0, depth_sigma_frac=0.0, velocity_sigma_mps=0.0), 20,
                  hidden_after=10)
    last, coast = outputs[10], outputs[11:]
    assert all(not o.valid and np.all(np.isnan(o.bbox)) for o in coast)
    for k, o in enumerate(coast, start=1):
        np.testing.assert_allclose(o.position_world_m, last.position_world_m + k * DT_S * last.velocity_world_mps,
                                   atol=1e-9)


def test_oracle_same_seed_gives_identical_noise_stream():
    config = OracleConfig(noise_correlation_s=0.3, dropout_prob=0.1)
    a, b = run(config, 200, seed=5), run(config, 200, seed=5)
    np.testing.assert_array_equal(np.array([o.bbox for o in a]), np.array([o.bbox for o in b]))


@pytest.mark.parametrize("field", ["noise_correlation_s", "first_fix_delay_s"])
def test_oracle_config_negative_value_raises_value_error_naming_field(field):
    with pytest.raises(ValueError, match=field):
        OracleConfig(**{field: -0.1})
    with pytest.raises(ValueError, match=f"oracle_{field}"):
        EnvConfig(**{f"oracle_{field}": -0.1})
