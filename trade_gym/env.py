"""TradeFollow-v0: follow a ground vehicle from a quadrotor with a downward camera.

The env owns one pybullet client and wires sim -> sensors -> perception -> observation; the policy's action flows back
as a velocity (or a position) setpoint. Perception sees the sensors only; the env scores it (`trade_gym.scoring`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import fields
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet as p

from trade.geometry import Pose
from trade_gym.action import ACTION_DIM, ActionScale, action_space, clip_action, waypoint_setpoint
from trade_gym.annotate import annotate_frame, display_image
from trade_gym.config import CAMERA_RATE_HZ, PHYSICS_RATE_HZ, EnvConfig
from trade_gym.faults import SensorFilter
from trade_gym.ground_truth import GroundTruth, VehicleBoxes, compute_ground_truth
from trade_gym.latency import HeldEstimates
from trade_gym.observation import build_observation, observation_space
from trade_gym.perception.base import PerceptionOutput, SensorFrame
from trade_gym.perception.factory import make_perception
from trade_gym.reward import RewardInputs, compute_reward
from trade_gym.scoring import EnvFrame, ScoredEstimate, env_info, follow_band, reward_inputs, score_estimate
from trade_gym.sim.appearance import EpisodeLook, appearance_stream
from trade_gym.sim.camera import Camera, CameraFrame
from trade_gym.sim.imu import Imu, ImuConfig
from trade_gym.sim.pose_source import make_pose_source
from trade_gym.sim.quadrotor import Quadrotor
from trade_gym.sim.thermal_camera import thermal_camera, thermal_stream
from trade_gym.sim.world import DecoyTier, TargetMotion, World, build_world

GRAVITY_MPS2 = 9.81
GROUND_RAY_RANGE_M = 1000.0  # rays for the ground-depth truth reach this far beyond the drone's height [m]


class TradeFollowEnv(gym.Env):
    """Follow a ground target from a quadrotor, perceiving it with the TRADE stack.

    ## Description
    A pybullet world (desert, city or mountain; seeded, procedural) holds a target vehicle that
    drives along a spline, identical decoys, terrain and buildings. A quadrotor carries a
    body-fixed camera (110 deg FOV, 30 Hz) and an IMU (200 Hz). Each step is one camera frame:
    the action sets a velocity (or position) setpoint for 1/30 s of 240 Hz physics, the camera renders, and the
    perception mode (`trade`, `dcf` or `oracle`) estimates the target. With `perception_latency` the estimate
    of a frame reaches the observation later (see Perception Latency).

    ## Action Space
    `Box(-1, 1, (4,), float32)`: forward, left and up velocity in the drone's heading frame and
    yaw rate, scaled by the quadrotor's setpoint limits (`trade_gym.action`, `env.action_scale`; by default
    8 m/s horizontal, 3 m/s vertical, 1.5 rad/s; `quadrotor=` sets them).
    With `action_mode="waypoint"` the same Box is a position setpoint as PX4 offboard takes one: forward, left and up
    offsets from the drone in its heading frame when the action arrives, scaled by `waypoint_scale` (`WaypointScale`;
    by default 20 m, 5 m), and a heading offset (by default pi/2 rad). The env adds them to the drone's position and
    heading at that moment and the quadrotor's position controller holds that absolute point and heading (PX4's
    yaw is an absolute heading; it is relative here because the observation has none) until the next action:
    velocity setpoint k_p (p_sp - p), yaw rate k_yaw (psi_sp - psi), clipped to the limits above (`QuadrotorConfig`).
    A zero action holds the drone where it is. In both modes values beyond the bounds act as the bound; a wrong
    shape or a non-finite value raises `ValueError`.

    ## Observation Space
    | key | shape | bounds | meaning |
    |---|---|---|---|
    | target_pos_rel_m | 3 | +-1000 m | estimated target minus drone position, heading frame |
    | target_vel_mps | 3 | +-100 m/s | estimated target velocity, heading frame |
    | drone_vel_mps | 3 | +-100 m/s | drone velocity from the pose source (drifts with `vio`), heading frame |
    | bbox_norm | 4 | [0, 1] | estimated box centre and size over the image side (0 if none) |
    | target_depth_m | 1 | [0, 1000] m | estimated camera-frame depth of the target (0 if none) |
    | track_valid | 1 | {0, 1} | 1 when the estimate held brought a fresh box at its frame |
    | time_lost_s | 1 | [0, 3600] s | time since the last estimate held with a fresh box |
    | imu | 6 | +-16 g, +-2000 deg/s | mean specific force and angular rate over the frame |
    | estimate_age_s | 1 | [0, 3600] s | age of the estimate held: now minus its frame's time (0 without latency) |

    The drone's own entries (`drone_vel_mps`, `imu`, the pose the relative position is taken from) are always
    this frame's; the target's entries are the estimate held (see Perception Latency).

    ## Perception Latency
    `perception_latency="none"` (default): each frame's observation holds that frame's estimate. `"fixed"`: the
    estimate of frame k reaches the observation at the first frame j with t_j >= t_k + `perception_latency_ms`
    (within 1e-9 s); until then the observation holds the newest estimate that has arrived (before the first
    one, a missing estimate: zeros, `track_valid` 0, its age counted from the reset frame). `"fixed"` with 0 ms
    equals `"none"` exactly. `"measured"`: the latency of frame k is the wall-clock time perception took on it
    (`perception.reset`/`step`, measured with `time.perf_counter`), so episodes are not deterministic and
    depend on the machine and its load. The stack still processes every frame (a pipelined stack); an
    estimate that arrives after a newer one is dropped. Scoring follows what the policy sees, as VOT's
    real-time experiment does: `info`'s `est_bbox`, `iou`, `on_decoy`, `target_depth_est`, `ground_depth_est`
    and `est_valid` are the held estimate's, compared with the ground truth of the current frame (but
    `ground_depth_est` along frame k's true box ray, scored at frame k); `info["estimate_age_s"]` is its age. With
    `latency_compensation` (the light stack's default) a held box moves with the camera's rotation since its frame.

    ## Info
    Ground truth and the estimate, per step: `t_s`; `gt_bbox` and `est_bbox` (x, y, w, h) [px] (`gt_bbox`
    NaN while the target is out of view); `iou`; `target_visible`, `target_visible_fraction`; `on_decoy`;
    `target_depth_gt`, `target_depth_est`, `ground_depth_gt`, `ground_depth_est` [m], each `None` where that
    depth does not exist (no estimate yet, target or ground not in view: None compares equal to itself, so
    `check_env` and saved episodes compare); `est_valid`; `estimate_age_s`; `crashed`; `drone_position_m`,
    `target_position_m`; `horizontal_distance_m`; `decoy_bboxes`; `reward_<term>`. The env computes them all
    (`trade_gym.scoring`; perception sees sensors only, the oracle truth through providers given at construction);
    `ground_depth_est`, the paper's Table 1 quantity, is the estimated ground's depth on the true box centre's ray.
    The reset's `info` also holds `target_motion` (the mode and what was drawn for it, `TargetMotion`), `appearance`
    ({"mode": "fixed"} or the `appearance="randomized"` draw) and with a thermal camera `thermal` (`ThermalLook`).

    ## Rewards
    The task in its own units, from ground truth; the terms sum to the reward and each is in
    `info["reward_<term>"]` (weights: `gym.make(..., reward=RewardConfig(...))`, see `trade_gym.reward`):
    `visible` +1 while the target is in view; `distance` -min(d / h, 1), d the horizontal distance to the
    target, h the scene's follow height; `height` -0.5 min(|height above the target's ground - h| / h, 1);
    `effort` -0.05 mean(action^2); `crash` -150 on a crash (more than flying on until the lost-target timeout
    can lose, so a crash never pays).

    ## Reset Options
    `reset(options={"scene": ..., "decoys": ..., "target_motion": ..., "appearance": ...})` (any subset) sets those
    arguments for that episode only (`episode_config` holds the episode's arguments); other keys raise `ValueError`.

    ## Starting State
    The drone hovers at the scene's follow height with the target in view; tracking starts from
    the ground-truth box, optionally shifted by up to `init_frame_shift_max` frames and perturbed by
    `init_box_perturb_px`; with `snap_init_box` the TRADE stack snaps the box it is given to the
    target's colour blob.

    ## Episode End
    Terminated on a crash into terrain or buildings, or when the target has been out of view for
    `lost_timeout_s`; truncated after `episode_duration_s` (30 s, 900 steps).

    ## Arguments
    All fields of `trade_gym.config.EnvConfig`, e.g. `scene`, `perception`, `pose_source`,
    `camera_size`, `camera_fov_deg`, `camera_pitch_deg`, `render_mode`, `stack` ("full", the default; "light": the
    paper's onboard stack, `trade_gym.config.STACK_PRESETS`), ablation switches (their defaults are the stack's),
    `perception_latency` ("none", "fixed", "measured") and `perception_latency_ms` (with "fixed" only, >= 0),
    `action_mode` ("velocity", "waypoint"), the components' configs `reward=`, `quadrotor=`, `vio=`, `waypoint_scale=`
    and `thermal=` (each the config or a mapping of its fields), `decoys`, `target_motion`, `appearance`, `renderer`,
    `camera_modality` ("rgb", "thermal": the camera outputs one grey image, in all three channels) and `time_of_day_h`.

    ## Version History
    - v0: initial release.
    - v0, issue 22: `perception_latency` and `perception_latency_ms`; the observation gains `estimate_age_s` and
      `info` the same; `track_valid` and `time_lost_s` describe the estimate held. With the default
      `perception_latency="none"` every other entry is as before.
    - v0, issue 17: the reward is the task: terms `visible`, `distance`, `height`, `effort`, `crash` replace
      `visible`, `centering`, `altitude`, `effort`, `crash` (centering paid for standing off the target while
      accelerating; altitude for climbing half the target's height); `reward=` sets the weights.
    - v0, issue 18: `quadrotor=` (QuadrotorConfig: airframe, setpoint limits = action scale, gains) and `vio=`
      (VioConfig: the VIO pose drift), defaults as before; perception sees sensors only, the env scores it.
    - v0, issue 17: `drone_vel_mps` comes from the pose source (with `vio`: rotated by the yaw drift, plus a
      bounded velocity error, `VioConfig`), no longer from the simulator's true state.
    - v0, issue 19: `decoys=` ("ambiguous", the default and as before; "parked"; "none"), see `DecoyTier`.
    - v0, issue 19: `target_motion=` ("cruise", the default and as before; "stop_and_go"; "evasive"), see
      `TargetMotion`; the reset's `info["target_motion"]` holds the mode and what was drawn for it.
    - v0, issue 19: `appearance=` ("fixed", the default: every image as before; "randomized": light, ground, vehicle
      paint, haze and camera effects per reset, `trade_gym.sim.appearance`); the reset's info gains `appearance`.
    - v0, issue 22: `renderer=` ("tiny", the default and as before: TinyRenderer; "egl": pybullet's EGL plugin).
    - v0, issue 41: the reward's `distance` is measured mostly in following-band distances (`RewardConfig`).
    - v0, issue 41: `reset(options={...})` sets `decoys`, `target_motion` and `appearance` for that episode only.
    - v0, issue 44: `reset(options={...})` sets the `scene` too (a wrapper above the env can draw it per episode).
    - v0, issue 45 (each default as before): `action_mode` ("velocity"; "waypoint") and `waypoint_scale`; `stack`
      ("full"; "light": no ground mask or single-image depth, a fixed latency of one 7.5 fps tracker period);
      `camera_modality` ("rgb"; "thermal"), `time_of_day_h` and `thermal=`; `latency_compensation` (off; light: on).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": CAMERA_RATE_HZ}
    world: World  # the episode's, built by reset() (no attribute before the first reset)

    def __init__(self, **kwargs: Any) -> None:
        self.config = EnvConfig(**kwargs)
        self.episode_config = self.config  # the config of the current episode: `config` with its reset options
        self.render_mode = self.config.render_mode
        self.quad_config = self.config.quadrotor
        self.camera_config = self.config.camera_config()
        self.imu_config = ImuConfig(noise=self.config.imu_noise)
        self.action_space = action_space()
        self.observation_space = observation_space()
        # what followers divide their setpoints by: velocities (action_mode "velocity"), or offsets ("waypoint")
        self.action_scale = ActionScale.of(self.quad_config)
        self.waypoint_scale = self.config.waypoint_scale
        self._waypoint_mode = self.config.action_mode == "waypoint"
        self._action_scale = (self.waypoint_scale if self._waypoint_mode else self.action_scale).per_component()
        self._client: int | None = p.connect(p.DIRECT)
        self.camera = Camera(self._client, self.camera_config)
        self._T_cam_body = self.camera.T_body_cam.inverse()
        self.quadrotor = Quadrotor(self._client, self.quad_config)
        self.perception = make_perception(self.config, self.camera.intrinsics, self._frame_truth,
                                          self._true_camera_pose)
        self._last_frame: CameraFrame | None = None
        self._last_truth: GroundTruth | None = None
        self._last_sensors: SensorFrame | None = None
        self._init_box: np.ndarray | None = None
        self._T_world_cam_true: Pose | None = None
        self._last_estimate = PerceptionOutput.missing()
        self._held_estimates: HeldEstimates | None = None
        self._estimate_age_s = 0.0
        self._needs_reset = True
        self._sensor_filter: SensorFilter | None = None

    # ----------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        cid = self._require_client()
        p.resetSimulation(physicsClientId=cid)
        p.setGravity(0.0, 0.0, -GRAVITY_MPS2, physicsClientId=cid)
        p.setTimeStep(1.0 / PHYSICS_RATE_HZ, physicsClientId=cid)
        cfg = self.episode_config = self.config.for_episode(options)  # this episode's scene and scenario
        rng, look_rng = self.np_random, appearance_stream(self.np_random, cfg.appearance)
        heat_rng = thermal_stream(self.np_random, cfg.camera_modality)  # None for "rgb"; neither moves `rng`
        world_rng = rng if cfg.world_seed is None else np.random.default_rng(cfg.world_seed)
        self.world = build_world(cid, cfg.scene, world_rng, cfg.target_speed_mps, DecoyTier(cfg.decoys, cfg.camera_fov_deg),
                                 TargetMotion(cfg.target_motion, cfg.camera_fov_deg), rendered=cfg.needs_rendering)
        thermal = thermal_camera(heat_rng, self.world, self.camera.intrinsics, cfg.thermal, cfg.time_of_day_h,
                                 cfg.appearance == "randomized")
        self._look = EpisodeLook(look_rng, self.world, self.camera, thermal)
        self._follow_band = follow_band(self.world.spec.follow_altitude_agl_m, cfg.camera_fov_deg, cfg.camera_pitch_deg)
        start_position, start_yaw = self.world.drone_start(cfg.camera_pitch_deg)
        self.quadrotor.spawn(start_position, start_yaw)
        self._state = self.quadrotor.read_state()
        self.imu = Imu(self.imu_config, rng)
        self.imu.prime_at_rest(self._state.R_world_body, GRAVITY_MPS2, CAMERA_RATE_HZ, rng)
        self.pose_source = make_pose_source(self.config.pose_source, rng=rng, vio_config=self.config.vio)
        self._t_s = 0.0
        self._vehicles = VehicleBoxes(self.world, self._t_s)
        self._steps = 0
        self._distance_flown_m = 0.0
        self._time_lost_s = 0.0
        self._time_target_hidden_s = 0.0
        self._needs_reset = False
        # The paper's protocol: the first tracked frame shifts randomly within N frames.
        shift = int(rng.integers(0, self.config.init_frame_shift_max + 1))
        for _ in range(shift):
            self._advance([0.0] * ACTION_DIM)
        sensors, truth = self._sense()
        init_box = self._init_box = self._perturbed_init_box(truth.target_bbox, rng)
        self._held_estimates = (None if self.config.perception_latency == "none"
                                else HeldEstimates(self.config, self.camera.intrinsics, self._t_s))
        held = self._perceive(sensors, truth, lambda: self.perception.reset(sensors, init_box, rng))
        visible = truth.target_visible_fraction >= self.config.visible_fraction_threshold
        inputs = reward_inputs(truth, self.world, self._follow_band, self._state.position_m, visible, (), False)
        info = self._info(truth, held, inputs, terms=None) | {"target_motion": self.world.target_motion_info}
        return self._observe(held.estimate, sensors), info | self._look.info

    def step(self, action):
        if self._client is None:
            raise RuntimeError("step() called after close(); create a new env")
        if self._needs_reset:
            raise RuntimeError("step() called before reset()")
        action = clip_action(action)
        crashed = self._advance(action)
        sensors, truth = self._sense()
        held = self._perceive(sensors, truth, lambda: self.perception.step(sensors))
        self._time_lost_s = 0.0 if held.estimate.valid else self._time_lost_s + self.config.frame_dt_s
        visible = truth.target_visible_fraction >= self.config.visible_fraction_threshold
        self._time_target_hidden_s = 0.0 if visible else self._time_target_hidden_s + self.config.frame_dt_s
        self._steps += 1
        inputs = reward_inputs(truth, self.world, self._follow_band, self._state.position_m, visible, action, crashed)
        reward, terms = compute_reward(self.config.reward, inputs)
        terminated = crashed or self._time_target_hidden_s >= self.config.lost_timeout_s
        truncated = self._steps >= self.config.max_episode_steps and not terminated
        obs = self._observe(held.estimate, sensors)
        return obs, reward, terminated, truncated, self._info(truth, held, inputs, terms=terms)

    def render(self):
        if self.render_mode is None:
            return None
        if self._last_frame is None:
            raise RuntimeError("render() needs a reset() first")
        return annotate_frame(display_image(self._last_frame.rgb, self.config.camera_modality), self._last_truth,
                              self._last_estimate, getattr(self.perception, "overlay", None))

    def close(self) -> None:
        if self._client is not None:
            try:
                self.camera.close()
                p.disconnect(physicsClientId=self._client)
            except p.error:
                pass
            self._client = None
        super().close()

    def set_sensor_filter(self, sensor_filter: SensorFilter | None) -> None:
        """Install (None: remove) a transform of the sensors between the simulator and perception; it
        applies from the next reset or step (see `SensorFilter`; `trade_gym.faults` uses it)."""
        self._sensor_filter = sensor_filter

    # ------------------------------------------------ this frame, for recorders
    @property
    def delivered_sensors(self) -> SensorFrame | None:
        """What perception received at the current frame (after any sensor filter); None before reset."""
        return self._last_sensors

    @property
    def ground_truth(self) -> GroundTruth | None:
        """The current frame's ground truth (as scored; a fault wrapper may lower the visible fraction in info);
        already this frame's while perception runs."""
        return self._last_truth

    @property
    def estimate(self) -> PerceptionOutput:
        """The estimate the current observation holds (after any perception latency)."""
        return self._last_estimate

    @property
    def camera_frame(self) -> CameraFrame | None:
        """The current frame (image as the camera delivered it, true depth and segmentation); None if not rendered."""
        return self._last_frame

    @property
    def true_camera_pose(self) -> Pose | None:
        """T_world_cam the current frame was rendered and scored from (not the pose source's estimate)."""
        return self._T_world_cam_true

    @property
    def initial_box(self) -> np.ndarray | None:
        """(4,) x, y, w, h [px]: the box perception was initialised with at the last reset (perturbed)."""
        return self._init_box

    def __getstate__(self) -> dict[str, Any]:
        """Pickling keeps the configuration and the random generator (so `reset()` without a seed
        continues the same stream); not the simulation, the episode or a sensor filter. The copy
        connects its own pybullet client and needs `reset()` before `step()`."""
        return {"config": self.config, "np_random": self._np_random, "np_random_seed": self._np_random_seed}

    def __setstate__(self, state: dict[str, Any]) -> None:
        config = state["config"]
        TradeFollowEnv.__init__(self, **{f.name: getattr(config, f.name) for f in fields(config)})
        self._np_random, self._np_random_seed = state["np_random"], state["np_random_seed"]

    # --------------------------------------------------------------- internals
    def _perceive(self, sensors: SensorFrame, truth: GroundTruth,
                  run: Callable[[], PerceptionOutput]) -> ScoredEstimate:
        """Run perception on the frame perception receives (`sensors`) and time it, score its estimate against
        this frame's truth; the estimate the observation holds (see `_held_estimate`)."""
        start_s = time.perf_counter()
        estimate = run()
        compute_s = time.perf_counter() - start_s
        self._last_sensors = sensors
        return self._held_estimate(score_estimate(estimate, truth, sensors.T_world_cam, self.camera.intrinsics),
                                   compute_s, sensors.T_world_cam)

    def _held_estimate(self, scored: ScoredEstimate, compute_s: float, T_world_cam_est: Pose) -> ScoredEstimate:
        """The estimate this frame's observation holds (`trade_gym.latency.HeldEstimates`), given this frame's scored
        estimate, the wall-clock time [s] perception took on it and the camera pose perception received; sets its
        age and keeps its estimate for `render`."""
        if self._held_estimates is None:
            self._estimate_age_s, held = 0.0, scored
        else:
            held, self._estimate_age_s = self._held_estimates.hold(scored, self._t_s, compute_s, T_world_cam_est)
        self._last_estimate = held.estimate
        return held

    def _require_client(self) -> int:
        if self._client is None:
            raise RuntimeError("reset() called after close(); create a new env")
        return self._client

    def _advance(self, action: list[float]) -> bool:
        """Run one camera frame of physics under the action; True if the drone crashed."""
        if self._waypoint_mode:  # offsets from the drone now, in its heading frame now
            offset = [a * s for a, s in zip(action, self._action_scale)]
            state = self._state
            self.quadrotor.set_position_setpoint(*waypoint_setpoint(offset, state.position_m.tolist(), state.yaw_rad))
        else:
            fwd, left, up, yaw_rate = (a * s for a, s in zip(action, self._action_scale))
            self.quadrotor.set_setpoint((fwd, left, up), yaw_rate)
        dt = 1.0 / PHYSICS_RATE_HZ
        previous = self._state.position_m.tolist()
        quadrotor = self.quadrotor
        self._t_s = quadrotor.fly(self.config.physics_steps_per_frame, dt, self.imu.add_truth_rows)  # since spawn
        self._state = quadrotor.read_state()
        self._distance_flown_m += math.dist(self._state.position_m.tolist(), previous)
        self.world.update(self._t_s, self._state.position_m)  # an evasive target reacts to the drone
        return quadrotor.collided(self.world.static_body_ids) or self._below_surface()

    def _below_surface(self) -> bool:
        x, y, z = self._state.position_m
        return bool(z < float(self.world.surface_height_m(x, y)))

    def _true_camera_pose(self) -> Pose:
        """The camera's exact pose at the current frame (computed once per frame in `_sense`)."""
        if self._T_world_cam_true is None:
            raise RuntimeError("no camera pose before reset()")
        return self._T_world_cam_true

    def _frame_truth(self) -> GroundTruth:
        """The current frame's ground truth (computed once per frame in `_sense`): the oracle's provider."""
        if self._last_truth is None:
            raise RuntimeError("no ground truth before reset()")
        return self._last_truth

    def _sense(self) -> tuple[SensorFrame, GroundTruth]:
        """This frame's ground truth and the sensors perception receives (after any sensor filter)."""
        T_world_cam = self.camera.pose(self._state.R_world_body, self._state.position_m)
        if self._sensor_filter is not None:  # e.g. a camera knocked out of its mount: renders and truth see it
            T_world_cam = self._sensor_filter.filter_camera_pose(T_world_cam)
        self._T_world_cam_true = T_world_cam
        if self.config.needs_rendering:
            self.world.place_vehicle_bodies()
            frame = self._look.render(T_world_cam, self._state)
        else:
            frame = None
        self._last_frame = frame
        target_box = self._vehicles.box(self.world.target, self._t_s)
        truth = compute_ground_truth(
            self._require_client(),
            self.camera.intrinsics,
            T_world_cam,
            target_box,
            self.world.target_velocity_mps(self._t_s),
            self._vehicles.corners(target_box, self._t_s) if frame is None else np.zeros((0, 8, 3)),
            None if frame is None else frame.seg,
            self.world.target.body_id,
            self._vehicles.decoy_ids,
            max_range_m=self._state.position_m[2] + GROUND_RAY_RANGE_M,
        )
        self._last_truth = truth
        T_est = self.pose_source.estimate(T_world_cam, self._distance_flown_m)
        velocity = self.pose_source.velocity(self._state.velocity_mps, self._t_s)
        sensors = SensorFrame(self._t_s, None if frame is None else frame.rgb, T_est, self.imu.read(), velocity)
        if self._sensor_filter is not None:
            sensors = self._sensor_filter.filter_sensors(sensors, truth)
        return sensors, truth

    def _perturbed_init_box(self, box: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        jitter = self.config.init_box_perturb_px
        if jitter <= 0.0 or not np.all(np.isfinite(box)):
            return box
        return box + np.concatenate([rng.uniform(-jitter, jitter, 2), np.zeros(2)])

    def _observe(self, estimate: PerceptionOutput, sensors: SensorFrame) -> dict[str, np.ndarray]:
        T_world_body_est = sensors.T_world_cam.compose(self._T_cam_body)
        forward = T_world_body_est.R[:, 0].tolist()
        yaw_est = math.atan2(forward[1], forward[0])
        return build_observation(
            estimate,
            drone_position_est_m=T_world_body_est.t,
            drone_yaw_est_rad=yaw_est,
            drone_velocity_world_mps=sensors.velocity_world_mps,
            imu=sensors.imu,
            time_lost_s=self._time_lost_s,
            estimate_age_s=self._estimate_age_s,
            image_size_px=self.config.camera_size,
        )

    def _info(self, truth: GroundTruth, held: ScoredEstimate, x: RewardInputs, terms: dict | None) -> dict[str, Any]:
        frame = EnvFrame(self._t_s, self._state.position_m, self._estimate_age_s, x.crashed, self._follow_band.holds(x))
        return env_info(truth, held, frame, self.config.visible_fraction_threshold, terms)
