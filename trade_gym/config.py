"""Typed configuration of TradeFollow-v0: every keyword argument of `gym.make`.

One frozen dataclass, validated on construction, so a bad value fails at `gym.make` with
an error naming the parameter and the value.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

from trade.validation import (check_choice, check_non_negative, check_positive, check_range, is_int_at_least,
                             nested_config, require)
from trade_gym.action import ACTION_MODES, WaypointScale
from trade_gym.perception.oracle import OracleConfig
from trade_gym.reward import RewardConfig
from trade_gym.sim.appearance import APPEARANCE_MODES
from trade_gym.sim.camera import MODALITIES, RENDERERS, CameraConfig
from trade_gym.sim.pose_source import VioConfig
from trade_gym.sim.quadrotor import QuadrotorConfig
from trade_gym.sim.scenes import DECOY_TIERS
from trade_gym.sim.target_motion import TARGET_MOTIONS
from trade_gym.sim.thermal_sensor import ThermalConfig

PERCEPTION_MODES = ("trade", "dcf", "oracle")
POSE_SOURCES = ("gt", "vio")
RENDER_MODES = (None, "rgb_array")
SCENE_NAMES = ("desert", "city", "mountain")
# When an estimate reaches the observation (`trade_gym.latency`): at once, a fixed delay after its frame, or
# after the stack's own measured compute time for that frame.
LATENCY_MODES = ("none", "fixed", "measured")
MS_PER_S = 1000.0
# EnvConfig's fields that hold a component's whole config (given as the config or a mapping of its fields)
NESTED_CONFIGS = {"reward": RewardConfig, "quadrotor": QuadrotorConfig, "vio": VioConfig,
                  "waypoint_scale": WaypointScale, "thermal": ThermalConfig}
ORACLE_PREFIX = "oracle_"  # EnvConfig's oracle_<name> is OracleConfig's <name>
# The settings `reset(options=...)` may set for one episode (`EnvConfig.for_episode`): the scene and the scenario.
# Each reset builds its world from them; nothing the env builds at construction depends on them.
EPISODE_OPTIONS = ("scene", "decoys", "target_motion", "appearance")

# `stack`: the perception stack's preset. "full": the offline TRADE of the paper (every module, estimates at once).
# "light": the onboard TRADE the paper flew on a Voxl 2 (trade_paper.tex, the lighter version's paragraph): the
# tracker (STARK there) at about 5-10 fps through onnxruntime, ROI feature tracking with robust plane fitting and
# temporal fusion in a separate thread, no single-image depth and no ground mask. Its tracker's compute is charged
# through the fixed latency mode: one period of LIGHT_TRACKER_RATE_HZ, the middle of the paper's 5-10 fps band. The
# stack still sees every frame (its throughput is not limited; only when an estimate arrives is).
STACKS = ("full", "light")
LIGHT_TRACKER_RATE_HZ = 7.5
# The keywords a preset sets, and their values; a keyword left at STACK_DEFAULT takes its stack's value, one given
# explicitly must agree with a preset that fixes it.
STACK_PRESETS: dict[str, dict[str, Any]] = {
    "full": {"temporal_fusion": True, "ground_mask": True, "single_image_depth": False,
             "perception_latency": "none", "perception_latency_ms": None, "latency_compensation": False},
    "light": {"temporal_fusion": True, "ground_mask": False, "single_image_depth": False,
              "perception_latency": "fixed", "perception_latency_ms": MS_PER_S / LIGHT_TRACKER_RATE_HZ,
              "latency_compensation": True},
}
# Keywords a light preset fixes (the full stack is the default of each: there they stay free for ablations)
LIGHT_FIXED = ("ground_mask", "single_image_depth")


class _StackDefault:
    """The default of a keyword the `stack` preset sets (`STACK_PRESETS`), replaced by the preset's value."""

    def __repr__(self) -> str:
        return "STACK_DEFAULT"


STACK_DEFAULT: Any = _StackDefault()

PHYSICS_RATE_HZ = 240
CAMERA_RATE_HZ = 30
MIN_CAMERA_SIZE_PX = 16
CAMERA_FOV_RANGE_DEG = (10.0, 170.0)
CAMERA_PITCH_RANGE_DEG = (30.0, 90.0)  # 90 = straight down
TIME_OF_DAY_RANGE_H = (0.0, 24.0)


@dataclass(frozen=True)
class EnvConfig:
    """Keyword arguments of `gym.make("TradeFollow-v0", **kwargs)`; see `TradeFollowEnv`."""

    scene: str = "desert"
    perception: str = "trade"
    pose_source: str = "gt"
    render_mode: str | None = None
    camera_size: int = 256  # square image side [px]
    camera_fov_deg: float = 110.0  # vertical = horizontal field of view [deg]
    camera_pitch_deg: float = 90.0  # optical axis below the body x axis [deg]; 90 = straight down
    # pybullet renderer: "tiny" (TinyRenderer, pip-only) or "egl" (the EGL plugin, where an EGL driver exists; Mesa's
    # software llvmpipe counts). Images agree within the tolerances of tests/trade_gym/test_egl.py, not bytewise. EGL
    # holds on to ~4 MB per world never built before in the process (`trade_gym.sim.camera.Camera`).
    renderer: str = "tiny"
    target_speed_mps: float | None = None  # None: the scene's default
    episode_duration_s: float = 30.0  # truncation horizon [s]
    lost_timeout_s: float = 3.0  # terminate when the target is out of view this long [s]
    visible_fraction_threshold: float = 0.25  # target counts as visible above this fraction
    # The perception stack's preset (STACKS): "full" TRADE (the default) or the paper's onboard "light" one; it sets
    # the switches and the latency below that are left at their default (STACK_PRESETS)
    stack: str = "full"
    # Perception ablation switches (perception="trade" or "dcf"); the defaults are the stack's (full TRADE: on, on,
    # off; light: on, off, off, and the light stack cannot turn the ground mask or single-image depth on).
    temporal_fusion: bool = STACK_DEFAULT
    ground_mask: bool = STACK_DEFAULT  # single-image depth runs every third frame for it
    single_image_depth: bool = STACK_DEFAULT  # depth-only mode (paper Table 2); needs ground_mask=False
    depth_only_ransac: bool = True  # depth-only alignment by RANSAC; False: plain least squares
    trajectory_guidance: bool = True
    init_box_perturb_px: float = 0.0  # uniform perturbation of the initial box [px]
    init_frame_shift_max: int = 0  # start tracking after 0..N frames, drawn per episode
    snap_init_box: bool = False  # the stack snaps the initial box to the target's colour blob (for a rough box)
    # None: each reset's seed draws the world too. An int fixes the world (the "sequence") while the
    # reset seed still drives sensor noise, the start shift and the box perturbation (repeated runs).
    world_seed: int | None = None
    # Decoy difficulty tier: "ambiguous" (the paper's scenes: identical decoys crossing, overtaking, parked beside
    # the path), "parked" (only parked ones never in view with the target), "none" (`trade_gym.sim.world.DecoyTier`)
    decoys: str = "ambiguous"
    # How the target drives its route: "cruise" (constant speed), "stop_and_go" (stops and speed changes drawn per
    # reset), "evasive" (faster and swerving while the drone is overhead) (`trade_gym.sim.target_motion.TargetMotion`)
    target_motion: str = "cruise"
    # "fixed" (the paper's scenes as they are) or "randomized": light, ground, vehicle paint, haze and camera effects
    # drawn per reset from the reset seed, on a stream of their own (`trade_gym.sim.appearance`)
    appearance: str = "fixed"
    # What the camera images (`trade_gym.sim.thermal_camera`): "rgb" (visible light) or "thermal" (a scene of surface
    # temperatures through a Boson-like microbolometer, `thermal=`: the grey image it outputs, in all three channels).
    # time_of_day_h [h, 0-24, solar time] sets the thermal scene's sun and air; None: 13 h, or drawn per reset with
    # appearance="randomized". Thermal only (the visible scenes' light is pybullet's own or the appearance's draw).
    camera_modality: str = "rgb"
    time_of_day_h: float | None = None
    # Oracle noise model (perception="oracle"): oracle_<name> is OracleConfig's <name> (`self.oracle`), with its
    # defaults (fitted to full TRADE's closed-loop errors on training worlds; see OracleConfig).
    oracle_box_sigma_px: float = OracleConfig.box_sigma_px  # box jitter per x, y, w, h [px]
    oracle_depth_sigma_frac: float = OracleConfig.depth_sigma_frac  # position noise per camera axis / depth
    oracle_velocity_sigma_mps: float = OracleConfig.velocity_sigma_mps  # target velocity noise per axis [m/s]
    oracle_dropout_prob: float = OracleConfig.dropout_prob  # chance per frame that the estimate is missing
    oracle_noise_correlation_s: float = OracleConfig.noise_correlation_s  # of the noise above [s]; 0 = white
    # No 3D position/velocity this long after reset [s] (fitted: FITTED_FIRST_FIX_DELAY_S, not the default)
    oracle_first_fix_delay_s: float = OracleConfig.first_fix_delay_s
    imu_noise: bool = True
    # render the camera even in oracle mode (for the GT box). An oracle env without frames (and without render_mode)
    # builds its world undrawn, without visual shapes (`trade_gym.sim.world.BodyLooks`): ask for frames to render it
    render_oracle_frames: bool = False
    # Perception latency (`trade_gym.latency`): "none" (the estimate of a frame is in that frame's observation),
    # "fixed" (it arrives perception_latency_ms after its frame) or "measured" (after perception's wall-clock
    # compute time for that frame: not deterministic). perception_latency_ms only with "fixed" [ms].
    # The stack's latency by default: "none" for the full stack, "fixed" at one tracker period for the light one.
    perception_latency: str = STACK_DEFAULT
    perception_latency_ms: float | None = STACK_DEFAULT
    # Whether a late estimate's box moves with the camera: while the observation holds the estimate of an earlier
    # frame, its box is carried to the current image by the camera's rotation since that frame (the infinite
    # homography of the poses perception received then and now, `trade.geometry.RotationWarp`), as an onboard stack
    # does with its attitude between a tracker result and the frame it is used on. On by default in the light stack
    # (a fixed camera at 45 deg swings the target through the image as the drone tilts: one tracker period late, its
    # box missed the target on most frames), off in the full one (the latency sweep measures raw latency).
    latency_compensation: bool = STACK_DEFAULT
    # What the action sets (`trade_gym.action`): "velocity" (velocity and yaw-rate setpoints, heading frame) or
    # "waypoint" (a position and heading offset from the drone, held by the quadrotor's position controller as a PX4
    # offboard position setpoint; scaled by `waypoint_scale`, unused in velocity mode).
    action_mode: str = "velocity"
    # Components' configs, each a config or a mapping of its fields (NESTED_CONFIGS): the reward's weights
    # (`trade_gym.reward`); the airframe, setpoint limits (the velocity action's scale, `trade_gym.action`) and
    # controller gains (velocity, attitude, position); the VIO pose drift (pose_source="vio"); the waypoint action's
    # scale (action_mode="waypoint"); the thermal camera's sensor (camera_modality="thermal", `ThermalConfig`).
    reward: RewardConfig = field(default_factory=RewardConfig)
    quadrotor: QuadrotorConfig = field(default_factory=QuadrotorConfig)
    vio: VioConfig = field(default_factory=VioConfig)
    waypoint_scale: WaypointScale = field(default_factory=WaypointScale)
    thermal: ThermalConfig = field(default_factory=ThermalConfig)

    def __post_init__(self) -> None:
        _apply_stack(self)
        for name, config_type in NESTED_CONFIGS.items():
            object.__setattr__(self, name, nested_config(name, getattr(self, name), config_type))
        check_choice("scene", self.scene, SCENE_NAMES)
        check_choice("perception", self.perception, PERCEPTION_MODES)
        check_choice("pose_source", self.pose_source, POSE_SOURCES)
        check_choice("decoys", self.decoys, DECOY_TIERS)
        check_choice("target_motion", self.target_motion, TARGET_MOTIONS)
        check_choice("appearance", self.appearance, APPEARANCE_MODES)
        check_choice("render_mode", self.render_mode, RENDER_MODES)
        check_choice("renderer", self.renderer, RENDERERS)
        check_choice("action_mode", self.action_mode, ACTION_MODES)
        check_choice("camera_modality", self.camera_modality, MODALITIES)
        _check_time_of_day(self.time_of_day_h, self.camera_modality)
        _check_latency(self.perception_latency, self.perception_latency_ms)
        require(is_int_at_least(self.camera_size, MIN_CAMERA_SIZE_PX, numpy_ints=False), "camera_size",
                self.camera_size, f"an integer >= {MIN_CAMERA_SIZE_PX} [px]")
        check_range("camera_fov_deg", self.camera_fov_deg, *CAMERA_FOV_RANGE_DEG)
        check_range("camera_pitch_deg", self.camera_pitch_deg, *CAMERA_PITCH_RANGE_DEG)
        if self.target_speed_mps is not None:
            check_positive("target_speed_mps", self.target_speed_mps)
        for name in ("episode_duration_s", "lost_timeout_s"):
            check_positive(name, getattr(self, name))
        check_range("visible_fraction_threshold", self.visible_fraction_threshold, 0.0, 1.0)
        for name in ("init_box_perturb_px", "oracle_box_sigma_px", "oracle_depth_sigma_frac",
                     "oracle_velocity_sigma_mps", "oracle_noise_correlation_s", "oracle_first_fix_delay_s"):
            check_non_negative(name, getattr(self, name))
        check_range("oracle_dropout_prob", self.oracle_dropout_prob, 0.0, 1.0)
        require(self.world_seed is None or is_int_at_least(self.world_seed, 0, numpy_ints=False), "world_seed",
                self.world_seed, "None or an integer >= 0")
        require(is_int_at_least(self.init_frame_shift_max, 0, numpy_ints=False), "init_frame_shift_max",
                self.init_frame_shift_max, "an integer >= 0")
        for f in fields(self):
            if f.type == "bool":
                require(isinstance(getattr(self, f.name), bool), f.name, getattr(self, f.name), "a bool")

    @property
    def oracle(self) -> OracleConfig:
        """The oracle's noise model: OracleConfig's fields from the `oracle_<field>` arguments."""
        return OracleConfig(**{f.name: getattr(self, ORACLE_PREFIX + f.name) for f in fields(OracleConfig)})

    def for_episode(self, options: dict[str, Any] | None) -> EnvConfig:
        """This config with the `reset(options=...)` scenario settings (EPISODE_OPTIONS) for one episode; ValueError
        names an unknown option or a bad value."""
        if not options:
            return self
        unknown = sorted(set(options) - set(EPISODE_OPTIONS))
        if unknown:
            raise ValueError(f"reset options {unknown} are not episode options; allowed: {list(EPISODE_OPTIONS)}")
        return replace(self, **options)

    def camera_config(self) -> CameraConfig:
        """The camera these arguments describe (square image, field of view, pitch, renderer, modality)."""
        return CameraConfig(width_px=self.camera_size, height_px=self.camera_size, fov_deg=self.camera_fov_deg,
                            pitch_deg=self.camera_pitch_deg, renderer=self.renderer, modality=self.camera_modality)

    @property
    def physics_steps_per_frame(self) -> int:
        return PHYSICS_RATE_HZ // CAMERA_RATE_HZ

    @property
    def frame_dt_s(self) -> float:
        return 1.0 / CAMERA_RATE_HZ

    @property
    def max_episode_steps(self) -> int:
        return int(round(self.episode_duration_s * CAMERA_RATE_HZ))

    @property
    def perception_latency_s(self) -> float:
        """The fixed latency [s] ("fixed" mode; 0 otherwise: "measured" measures its own per frame)."""
        ms = self.perception_latency_ms  # given with "fixed" only (`_check_latency`)
        return ms / MS_PER_S if self.perception_latency == "fixed" and ms is not None else 0.0

    @property
    def needs_rendering(self) -> bool:
        """Whether a step renders the camera."""
        return self.perception != "oracle" or self.render_mode is not None or self.render_oracle_frames


def _apply_stack(config: EnvConfig) -> None:
    """Give every keyword left at STACK_DEFAULT its stack's value (a latency mode given explicitly brings no preset
    milliseconds: None, to be given with "fixed"); ValueError for an unknown stack, or a keyword the light stack fixes
    given another value."""
    check_choice("stack", config.stack, STACKS)
    latency_given = config.perception_latency is not STACK_DEFAULT
    for name, value in STACK_PRESETS[config.stack].items():
        given = getattr(config, name)
        if given is STACK_DEFAULT:
            object.__setattr__(config, name, None if name == "perception_latency_ms" and latency_given else value)
        elif config.stack == "light" and name in LIGHT_FIXED and given != value:
            raise ValueError(f"stack='light' runs without {name} (the paper's onboard stack), got {name}={given!r}")


def _check_latency(mode: object, latency_ms: object) -> None:
    check_choice("perception_latency", mode, LATENCY_MODES)
    if mode != "fixed":
        if latency_ms is not None:
            raise ValueError(f"perception_latency_ms is only used with perception_latency='fixed', got "
                             f"perception_latency_ms={latency_ms!r} with perception_latency={mode!r}")
        return
    if latency_ms is None:
        raise ValueError("perception_latency='fixed' needs perception_latency_ms (a number >= 0 [ms]), got None")
    check_non_negative("perception_latency_ms", latency_ms)


def _check_time_of_day(time_h: object, modality: object) -> None:
    if time_h is None:
        return
    check_range("time_of_day_h", time_h, *TIME_OF_DAY_RANGE_H)
    if modality != "thermal":
        raise ValueError(f"time_of_day_h sets the thermal scene and needs camera_modality='thermal', got "
                         f"time_of_day_h={time_h!r} with camera_modality={modality!r}")
