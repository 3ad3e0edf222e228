"""Spec of the damped constant-acceleration trajectory model (trade/trajectory.py)."""

from __future__ import annotations

import numpy as np
import pytest

from trade.trajectory import (
    TrajectoryConfig,
    TrajectoryModel,
    measurement_matrix,
    process_noise,
    transition_matrix,
)

FRAME_DT_S = 1.0 / 30.0
P0_M = np.array([10.0, -5.0, 0.0])
V0_MPS = np.array([5.0, 2.0, 0.0])
A_MPS2 = np.array([0.5, -0.3, 0.0])


def _truth(t_s: float) -> np.ndarray:
    """Constant-acceleration target: p(t) = p0 + v0 t + a t^2 / 2."""
    return P0_M + V0_MPS * t_s + 0.5 * A_MPS2 * t_s**2


def _tracked_model(rng: np.random.Generator, noise_m: float, n_frames: int) -> TrajectoryModel:
    model = TrajectoryModel(TrajectoryConfig())
    model.reset(_truth(0.0) + rng.normal(0.0, noise_m, 3), 0.0)
    for k in range(1, n_frames + 1):
        t = k * FRAME_DT_S
        model.predict(t)
        assert model.update(_truth(t) + rng.normal(0.0, noise_m, 3), noise_m)
    return model


@pytest.mark.parametrize("seed", range(10))
def test_predict_constant_acceleration_after_30_noisy_frames_within_20cm(seed: int) -> None:
    noise_m = 0.1
    model = _tracked_model(np.random.default_rng(seed), noise_m, n_frames=30)
    t_next = 31 * FRAME_DT_S
    predicted = model.predict(t_next).position_m
    assert np.linalg.norm(predicted - _truth(t_next)) < 0.2


def test_predict_without_updates_2s_stays_finite_within_damped_bound() -> None:
    config = TrajectoryConfig()
    model = _tracked_model(np.random.default_rng(0), 0.1, n_frames=60)
    start = model.state
    # Discrete bound on sum_k (v_k h + a_k h^2 / 2) with v_{k+1} = d_v (v_k + a_k h), a_{k+1} = d_a a_k:
    # |dp| <= h |v0| / (1 - d_v) + h^2 |a0| (d_v / (1 - d_v) + 1/2) / (1 - d_a), for any horizon.
    h = FRAME_DT_S
    d_v, d_a = config.velocity_damping_per_s**h, config.accel_damping_per_s**h
    v0, a0 = np.linalg.norm(start.velocity_mps), np.linalg.norm(start.acceleration_mps2)
    bound_m = h * v0 / (1 - d_v) + h**2 * a0 * (d_v / (1 - d_v) + 0.5) / (1 - d_a)
    for k in range(1, 61):
        state = model.predict(start.t_s + k * h)
        assert np.all(np.isfinite(state.position_m)) and np.all(np.isfinite(state.covariance))
        assert np.linalg.norm(state.position_m - start.position_m) < bound_m
    assert np.linalg.norm(state.velocity_mps) < v0 + a0 * 2.0  # damped: no runaway speed
    far = model.predict(start.t_s + 60.0)
    assert np.linalg.norm(far.position_m - start.position_m) < bound_m
    assert np.linalg.norm(far.velocity_mps) < 0.1 * v0


def test_update_nan_measurement_rejected_state_unchanged() -> None:
    model = _tracked_model(np.random.default_rng(1), 0.1, n_frames=10)
    before = model.state
    assert not model.update(np.array([np.nan, 0.0, 0.0]), 0.1)
    assert not model.update(np.array([1.0, 2.0, 3.0]), np.inf)
    after = model.state
    for name in ("position_m", "velocity_mps", "acceleration_mps2", "covariance"):
        np.testing.assert_array_equal(getattr(after, name), getattr(before, name))
        assert np.all(np.isfinite(getattr(after, name)))


def test_class_matches_hand_written_kalman_equations() -> None:
    config = TrajectoryConfig()
    model = TrajectoryModel(config)
    model.reset(np.array([1.0, 2.0, 3.0]), 0.0)
    x = np.concatenate([model.state.position_m, np.zeros(6)])
    P = model.state.covariance
    H = measurement_matrix()
    rng = np.random.default_rng(3)
    t = 0.0
    for dt in (0.02, 0.04, 0.033, 0.01):
        t += dt
        F, Q = transition_matrix(dt, config), process_noise(dt, config)
        x, P = F @ x, F @ P @ F.T + Q  # x = F x; P = F P F^T + Q
        z, sigma = rng.normal(1.0, 1.0, 3), np.array([0.3, 0.4, 0.5])
        R = np.diag(sigma**2)
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)  # K = P H^T (H P H^T + R)^-1
        x, P = x + K @ (z - H @ x), (np.eye(9) - K @ H) @ P  # x += K y; P = (I - K H) P
        model.predict(t)
        model.update(z, sigma)
        s = model.state
        np.testing.assert_allclose(np.concatenate([s.position_m, s.velocity_mps, s.acceleration_mps2]), x, atol=1e-9)
        np.testing.assert_allclose(s.covariance, P, atol=1e-9)


def test_transition_matrix_damping_compounds_per_second() -> None:
    config = TrajectoryConfig(velocity_damping_per_s=0.5, accel_damping_per_s=0.25)
    F_full = transition_matrix(1.0, config)
    F_half = transition_matrix(0.5, config)
    assert F_full[3, 3] == pytest.approx(0.5) and F_full[6, 6] == pytest.approx(0.25)
    np.testing.assert_allclose((F_half @ F_half)[3:9, 3:9].diagonal(), F_full[3:9, 3:9].diagonal())


def test_predict_ahead_matches_predict_and_leaves_state_unchanged() -> None:
    model = _tracked_model(np.random.default_rng(2), 0.1, n_frames=20)
    before = model.state
    ahead = model.predict_ahead(1.0, 10)
    assert ahead.shape == (10, 3)
    np.testing.assert_array_equal(model.state.position_m, before.position_m)
    assert model.state.t_s == before.t_s
    stepped = np.array([model.predict(before.t_s + 0.1 * k).position_m for k in range(1, 11)])
    np.testing.assert_allclose(ahead, stepped, atol=1e-9)


def test_predict_backwards_in_time_raises() -> None:
    model = TrajectoryModel()
    model.reset(np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="t_s"):
        model.predict(0.5)


def test_config_invalid_damping_names_field() -> None:
    with pytest.raises(ValueError, match="velocity_damping_per_s"):
        TrajectoryConfig(velocity_damping_per_s=1.5)
