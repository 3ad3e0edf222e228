"""Benchmark suites as data: groups of runs (one group per table), expanded into run specs.

A `GroupSpec` is a grid (scenes x policies x perceptions x pose sources x ablation switches x seeds);
a `Selection` (from the command line) filters the categorical axes and overrides seeds, steps, camera size.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, fields
from types import MappingProxyType
from typing import Any

from trade_gym.bench.policies import policy_env_kwargs
from trade_gym.bench.splits import DEVELOPMENT, EVALUATION, TRAINING
from trade_gym.config import APPEARANCE_MODES, CAMERA_RATE_HZ, SCENE_NAMES, TARGET_MOTIONS, EnvConfig
from trade_gym.sim.thermal_crossover import TIMES_OF_DAY, time_of_day_h

Kwargs = tuple[tuple[str, Any], ...]  # sorted (name, value) pairs: hashable env keyword arguments
# Which table a group renders in results.md (and how its runs are compared).
GROUP_KINDS = ("follow", "tracking", "table1", "table2", "unseen", "latency", "breadth", "real_flight", "thermal", "custom")
BOOL_SWITCHES = tuple(f.name for f in fields(EnvConfig) if f.type == "bool")
# The paper's protocol: one sequence per scene (a fixed world), each run of it with its first tracked
# frame shifted within 10 frames and its initial box perturbed within 5 px (and its own sensor noise);
# the stack snaps the perturbed box to the target's colour blob, as it would a box drawn by hand.
PAPER_SEQUENCE_WORLD_SEED = 0
PAPER_PROTOCOL: Kwargs = (("init_box_perturb_px", 5.0), ("init_frame_shift_max", 10), ("snap_init_box", True),
                          ("world_seed", PAPER_SEQUENCE_WORLD_SEED))
DEPTH_RUNS, TRACKING_RUNS = (0, 4), (0, 9)  # seeds (inclusive): 5 runs for depth, 10 for tracking
# The same protocol on worlds nobody tuned on: one run per evaluation world, whose reset seed draws it.
UNSEEN_PROTOCOL: Kwargs = tuple(kv for kv in PAPER_PROTOCOL if kv[0] != "world_seed")
UNSEEN_WORLDS = (EVALUATION.first, EVALUATION.last)
UNSEEN_ABLATION_WORLDS = (EVALUATION.first, EVALUATION.first + 4)  # Table 1's ablation rows on the first 5
# The unseen suite's grid on 20 development worlds, to tune on (the evaluation worlds only report). They
# start at 100, past the low seeds the tests and the paper's sequence (world 0) use.
TUNING_WORLDS = (DEVELOPMENT.first + 100, DEVELOPMENT.first + 119)
# The latency sweep: fixed perception latencies [ms] (0 = none; 33 ~ one frame at 30 Hz; TRADE ran at 5-10 fps
# onboard, 100-200 ms) on development worlds.
LATENCIES_MS = (0.0, 33.0, 100.0, 200.0, 400.0)
LATENCY_PROTOCOL: Kwargs = (("perception_latency", "fixed"),)
LATENCY_WORLDS = (0, 0)  # development world seeds (reset seed = world seed), first and last
# Scenario breadth: one table per decoy tier, each the grid target motion x appearance x follower x perception,
# vio pose, one run per configuration on the first 5 evaluation worlds of each scene, so every configuration of a
# scene meets the same worlds (paired comparisons). A cell of the success table (follower, perception, motion,
# appearance; runs pooled over scenes, worlds and tiers) holds 3 scenes x 5 worlds x 3 tiers = 45 runs, enough for
# a 95 % interval of about +-0.12 at a rate of 0.8. `breadth-tuning` is the same grid on training worlds: the
# one to find failures on and tune against.
BREADTH_TIERS = ("none", "parked", "ambiguous")  # easiest first
BREADTH_WORLDS = (EVALUATION.first, EVALUATION.first + 4)
BREADTH_TUNING_WORLDS = (TRAINING.first + 200, TRAINING.first + 204)  # past the depth finder's and the sweeps'
# The depth failure finder: ground depth under full TRADE (both followers, gt and vio pose, clean start) on every
# evaluation world and on training worlds, whose group is the one to tune on (`--tables depth_training`).
DEPTH_FINDER_TRAINING_WORLDS = (TRAINING.first, TRAINING.first + 39)
DEPTH_FINDER_STEPS = 300
# Real flight (issue 45): the paper's onboard setup (trade_paper.tex, real-time implementation): a FLIR Boson thermal
# camera at 45 deg pitch, the light TRADE stack of the Voxl 2, waypoints sent to PX4 from the filtered target position
# (the waypoint follower), TRADE against DCF, at night, at the scene's morning crossover and by day, on every evaluation
# world. VIO pose: the flight had no other (xVIO ran beside TRADE on the board), and ground-truth pose would hide
# the pose drift that the light stack's plane fit, its only depth (no ground mask, no single-image depth), suffers.
REAL_FLIGHT_PITCH_DEG = 45.0  # the Boson's mount on the quadcopter (trade_paper.tex: "mounted with a 45 deg pitch")
REAL_FLIGHT_ENV: Kwargs = (("camera_modality", "thermal"), ("camera_pitch_deg", REAL_FLIGHT_PITCH_DEG),
                           ("stack", "light"))
TIME_OF_DAY_AXIS = "time_of_day"
# `real-flight-tuning`: the same grid on 10 training worlds per scene, past the breadth group's: where its failures
# are found and fixed, since the evaluation worlds only report.
REAL_FLIGHT_TUNING_WORLDS = (TRAINING.first + 210, TRAINING.first + 219)
# Thermal tracking (issue 45): the unseen suite's full TRADE runs (scripted follower, downward camera, gt pose, the
# paper's start protocol) on the thermal camera at night, at the scene's morning crossover and by day; then the light
# stack's ground depth in the cells issue 45's thermal gates name (night and day, desert and mountain), which the
# light group flies. `thermal-tuning` is the same grid on the tuning suite's development worlds
# (benchmarks/thermal_tracking.py flies those one at a time, with traces).
THERMAL_ENV: Kwargs = (("camera_modality", "thermal"),)
THERMAL_GATE_SCENES = ("desert", "mountain")
THERMAL_GATE_TIMES = ("night", "day")


@dataclass(frozen=True)
class NamedAxis:
    """A grid axis whose values are names, each given to the env as `keyword` by `resolve(scene, name)` (a value
    that differs per scene); a run's id keeps the name."""

    keyword: str
    names: tuple[str, ...]
    resolve: Callable[[str, str], Any]


# The time of day by name (night, crossover, day): the crossover hour is the scene's own (`thermal_crossover`)
NAMED_AXES = MappingProxyType({TIME_OF_DAY_AXIS: NamedAxis("time_of_day_h", TIMES_OF_DAY, time_of_day_h)})


def named_axis_kwargs(scene: str, switches: Kwargs) -> dict[str, Any]:
    """The env keyword arguments of `switches`' named axes (`NAMED_AXES`) in `scene`."""
    return {NAMED_AXES[name].keyword: NAMED_AXES[name].resolve(scene, value) for name, value in switches
            if name in NAMED_AXES}


@dataclass(frozen=True)
class RunSpec:
    """One episode: which group it belongs to and every env keyword argument it needs."""

    group: str
    kind: str
    scene: str
    policy: str
    perception: str
    pose_source: str
    seed: int
    steps: int  # episode length [frames]; the env truncates there
    camera_size: int  # [px]
    switches: Kwargs = ()  # the group's ablation axes, e.g. (("ground_mask", True),)
    extra: Kwargs = ()  # kwargs fixed across the group (protocol, depth mode)
    depth_kind: str = "ground"  # which depth the group's tables and plots score

    @property
    def config_id(self) -> str:
        """Identifies the configuration (everything but the seed)."""
        parts = [self.group, self.scene, self.policy, self.perception, self.pose_source]
        if self.switches:
            parts.append(",".join(f"{k}={switch_text(v)}" for k, v in self.switches))
        return "/".join(parts)

    @property
    def run_id(self) -> str:
        return f"{self.config_id}/seed{self.seed}"

    @property
    def world_seed(self) -> int:
        """The seed of the run's world: the protocol's fixed world, or else the reset seed."""
        fixed = dict(self.extra).get("world_seed", dict(self.switches).get("world_seed"))
        return self.seed if fixed is None else int(fixed)

    # env keyword arguments every spec sets itself (and its policy's, `policy_env_kwargs`); the rest of `env_kwargs`
    # is its extras and switches
    OWN_ENV_KEYS = ("scene", "perception", "pose_source", "camera_size", "episode_duration_s")

    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of `TradeFollowEnv` for this run; truncation at exactly `steps` frames. A named axis
        (`NAMED_AXES`) gives its keyword unless an extra fixes it (a spec read back from results.json keeps the
        value it was flown with)."""
        return {
            "scene": self.scene,
            "perception": self.perception,
            "pose_source": self.pose_source,
            "camera_size": self.camera_size,
            "episode_duration_s": self.steps / CAMERA_RATE_HZ,
            **policy_env_kwargs(self.policy),
            **named_axis_kwargs(self.scene, self.switches),
            **dict(self.extra),
            **{name: value for name, value in self.switches if name not in NAMED_AXES},
        }

    def switch_value(self, name: str) -> Any:
        """The value this run gives an env keyword (its switches, then extras, then the env default); a named axis's
        name (None where the run has no such axis)."""
        if name in NAMED_AXES:
            return dict(self.switches).get(name)
        return dict(self.switches).get(name, dict(self.extra).get(name, getattr(EnvConfig(), name)))


def switch_text(value: Any) -> str:
    """A switch value in an id: 0/1 for a bool (as ids always had), the shortest form of a number."""
    if isinstance(value, str):  # a categorical option, e.g. target_motion=evasive
        return value
    return str(int(value)) if isinstance(value, bool) else f"{value:g}"


@dataclass(frozen=True)
class Selection:
    """Command-line choices. Categorical axes filter a suite (None = keep all); seeds (first, last
    inclusive), steps and camera size override it."""

    scenes: tuple[str, ...] | None = None
    policies: tuple[str, ...] | None = None
    perceptions: tuple[str, ...] | None = None
    pose_sources: tuple[str, ...] | None = None
    switches: tuple[tuple[str, tuple[Any, ...]], ...] = ()  # name -> allowed values (bools, or a named axis' names)
    groups: tuple[str, ...] | None = None
    seeds: tuple[int, int] | None = None
    steps: int | None = None
    camera_size: int | None = None


@dataclass(frozen=True)
class GroupSpec:
    """A grid of runs rendered as one table."""

    name: str
    kind: str
    title: str
    scenes: tuple[str, ...]
    policies: tuple[str, ...]
    perceptions: tuple[str, ...]
    pose_sources: tuple[str, ...]
    seeds: tuple[int, int]  # first, last (inclusive)
    steps: int
    camera_size: int
    switch_grid: tuple[tuple[str, tuple[Any, ...]], ...] = ()  # env keyword -> values (bools, or numbers)
    extra: Kwargs = ()
    depth_kind: str = "ground"

    def __post_init__(self) -> None:
        if self.kind not in GROUP_KINDS:
            raise ValueError(f"GroupSpec.kind must be one of {GROUP_KINDS}, got {self.kind!r}")
        if self.seeds[0] > self.seeds[1]:
            raise ValueError(f"GroupSpec.seeds must be (first, last) with first <= last, got {self.seeds!r}")

    def expand(self, selection: Selection, available_policies: tuple[str, ...]) -> list[RunSpec]:
        """Runs of this group kept by `selection`; policies not available here are dropped."""
        def keep(values: tuple[str, ...], chosen: tuple[str, ...] | None) -> tuple[str, ...]:
            return tuple(v for v in values if chosen is None or v in chosen)

        first, last = selection.seeds or self.seeds
        names = [n for n, _ in self.switch_grid]
        runs = []
        for scene, policy, perception, pose, values, seed in itertools.product(
                keep(self.scenes, selection.scenes), keep(self.policies, selection.policies),
                keep(self.perceptions, selection.perceptions), keep(self.pose_sources, selection.pose_sources),
                itertools.product(*(v for _, v in self.switch_grid)), range(first, last + 1)):
            if policy not in available_policies:
                continue
            run = RunSpec(self.name, self.kind, scene, policy, perception, pose, seed,
                          selection.steps or self.steps, selection.camera_size or self.camera_size,
                          tuple(zip(names, values)), self.extra, self.depth_kind)
            if all(run.switch_value(n) in allowed for n, allowed in selection.switches):
                runs.append(run)
        return runs


ALL_SCENES = SCENE_NAMES
ON_OFF = (False, True)

QUICK = (
    GroupSpec("follow", "follow", "Followers on oracle perception (hover and random are floors)",
              ALL_SCENES, ("scripted", "learned", "hover", "random"), ("oracle",), ("gt",), (0, 0), 300, 128),
    GroupSpec("tracking", "tracking", "TRADE against its DCF baseline (scripted follower)",
              ALL_SCENES, ("scripted",), ("trade", "dcf"), ("gt",), (0, 0), 150, 128),
)


def _paper_groups(steps: int, camera_size: int) -> tuple[GroupSpec, ...]:
    return (
        GroupSpec("table1", "table1", "Table 1: ground-depth RMSE [m], temporal fusion x ground mask, gt (vio) pose",
                  ALL_SCENES, ("scripted",), ("trade",), ("gt", "vio"), DEPTH_RUNS, steps, camera_size,
                  (("temporal_fusion", ON_OFF), ("ground_mask", ON_OFF)), PAPER_PROTOCOL, "ground"),
        # Table 2 needs the depth-only single-image mode (`single_image_depth=True`, RANSAC on/off), which
        # replaces the plane fit the ground mask selects points for, so the mask is off.
        GroupSpec("table2", "table2", "Table 2: target-depth RMSE [m] from single-image depth, RANSAC off/on",
                  ALL_SCENES, ("scripted",), ("trade",), ("gt",), DEPTH_RUNS, steps, camera_size,
                  (("depth_only_ransac", ON_OFF),),
                  PAPER_PROTOCOL + (("single_image_depth", True), ("ground_mask", False)), "target"),
        GroupSpec("tracking", "tracking", "Tracking: TRADE against DCF (no trajectory guidance), vio pose",
                  ALL_SCENES, ("scripted",), ("trade", "dcf"), ("vio",), TRACKING_RUNS, steps, camera_size,
                  (), PAPER_PROTOCOL, "ground"),
    )


def _unseen_groups(steps: int, camera_size: int, name: str = "unseen", worlds: tuple[int, int] = UNSEEN_WORLDS,
                   which: str = "evaluation") -> tuple[GroupSpec, ...]:
    """The unseen suite's groups; with another name and world range, the same grid on those worlds."""
    title = (f"Unseen worlds: full TRADE (gt and vio pose) and the DCF baseline (vio), scripted follower, "
             f"one run per {which} world")
    ablation_worlds = (worlds[0], worlds[0] + UNSEEN_ABLATION_WORLDS[1] - UNSEEN_ABLATION_WORLDS[0])
    return (
        GroupSpec(name, "unseen", title, ALL_SCENES, ("scripted",), ("trade",), ("gt", "vio"), worlds,
                  steps, camera_size, (), UNSEEN_PROTOCOL),
        GroupSpec(name, "unseen", title, ALL_SCENES, ("scripted",), ("dcf",), ("vio",), worlds,
                  steps, camera_size, (), UNSEEN_PROTOCOL),
        # the followers compared on the same worlds (the learned follower's model card); its scripted runs are
        # the first group's full TRADE runs, flown once (`cli.run_once_each`)
        GroupSpec(f"{name}_follow", "follow", f"Followers on {which} worlds: scripted and learned, full TRADE, gt "
                  "and vio pose", ALL_SCENES, ("scripted", "learned"), ("trade",), ("gt", "vio"), worlds, steps,
                  camera_size, (), UNSEEN_PROTOCOL),
        GroupSpec(f"{name}_table1", "table1", f"Table 1 on the first 5 {which} worlds: ground-depth RMSE [m], "
                  "temporal fusion x ground mask, gt (vio) pose", ALL_SCENES, ("scripted",), ("trade",),
                  ("gt", "vio"), ablation_worlds, steps, camera_size,
                  (("temporal_fusion", ON_OFF), ("ground_mask", ON_OFF)), UNSEEN_PROTOCOL, "ground"),
    )


def _latency_groups(steps: int, camera_size: int) -> tuple[GroupSpec, ...]:
    return (
        GroupSpec("latency", "latency", "Following under perception latency: full TRADE, gt pose, scripted and "
                  "learned followers, fixed latency per run", ALL_SCENES, ("scripted", "learned"), ("trade",),
                  ("gt",), LATENCY_WORLDS, steps, camera_size, (("perception_latency_ms", LATENCIES_MS),),
                  LATENCY_PROTOCOL),
    )


def _breadth_groups(steps: int, camera_size: int, worlds: tuple[int, int] = BREADTH_WORLDS,
                    split: str = "evaluation") -> tuple[GroupSpec, ...]:
    return tuple(
        GroupSpec(f"breadth_{tier}", "breadth", f"Scenario breadth, decoys={tier}: success rate by target motion "
                  f"and appearance, scripted and learned followers, full TRADE and DCF, vio pose, {split} worlds",
                  ALL_SCENES, ("scripted", "learned"), ("trade", "dcf"), ("vio",), worlds, steps, camera_size,
                  (("target_motion", TARGET_MOTIONS), ("appearance", APPEARANCE_MODES)),
                  UNSEEN_PROTOCOL + (("decoys", tier),))
        for tier in BREADTH_TIERS)


def _depth_finder_groups(steps: int, camera_size: int) -> tuple[GroupSpec, ...]:
    return tuple(
        GroupSpec(f"depth_{which}", "unseen", f"Depth failure finder, {which} worlds: ground depth under full TRADE, "
                  "scripted and learned followers, gt and vio pose, clean start, one run per world", ALL_SCENES,
                  ("scripted", "learned"), ("trade",), ("gt", "vio"), worlds, steps, camera_size)
        for which, worlds in (("training", DEPTH_FINDER_TRAINING_WORLDS), ("evaluation", UNSEEN_WORLDS)))


def _real_flight_groups(steps: int, camera_size: int, worlds: tuple[int, int] = UNSEEN_WORLDS,
                        split: str = "evaluation") -> tuple[GroupSpec, ...]:
    return (
        GroupSpec("real_flight", "real_flight", "Real flight: thermal camera at 45 deg, light stack, waypoint "
                  "follower, VIO pose; TRADE against DCF at night, at the morning crossover and by day, one run per "
                  f"{split} world", ALL_SCENES, ("waypoint",), ("trade", "dcf"), ("vio",), worlds, steps,
                  camera_size, ((TIME_OF_DAY_AXIS, TIMES_OF_DAY),), UNSEEN_PROTOCOL + REAL_FLIGHT_ENV),
    )


def _thermal_groups(steps: int, camera_size: int, worlds: tuple[int, int] = UNSEEN_WORLDS,
                    split: str = "evaluation") -> tuple[GroupSpec, ...]:
    return (
        GroupSpec("thermal", "thermal", "Thermal camera: full TRADE, scripted follower, gt pose, at night, at the "
                  f"morning crossover and by day, one run per {split} world", ALL_SCENES, ("scripted",), ("trade",),
                  ("gt",), worlds, steps, camera_size, ((TIME_OF_DAY_AXIS, TIMES_OF_DAY),),
                  UNSEEN_PROTOCOL + THERMAL_ENV),
        GroupSpec("thermal_light", "thermal", "Thermal camera: the light stack's ground depth, scripted follower, gt "
                  f"pose, at night and by day, one run per {split} world", THERMAL_GATE_SCENES, ("scripted",),
                  ("trade",), ("gt",), worlds, steps, camera_size, ((TIME_OF_DAY_AXIS, THERMAL_GATE_TIMES),),
                  UNSEEN_PROTOCOL + THERMAL_ENV + (("stack", "light"),)),
    )


PAPER_STEPS, FULL_STEPS = 450, 900  # 15 s sequences (about an hour on 2 cores); the env's full 30 s
PAPER_CAMERA_PX = 256

SUITES: dict[str, tuple[GroupSpec, ...]] = {
    "quick": QUICK,
    "paper": _paper_groups(PAPER_STEPS, PAPER_CAMERA_PX),
    "unseen": _unseen_groups(PAPER_STEPS, PAPER_CAMERA_PX),
    "tuning": _unseen_groups(PAPER_STEPS, PAPER_CAMERA_PX, "tuning", TUNING_WORLDS, "development"),
    "latency": _latency_groups(PAPER_STEPS, PAPER_CAMERA_PX),
    "breadth": _breadth_groups(PAPER_STEPS, PAPER_CAMERA_PX),
    "breadth-tuning": _breadth_groups(PAPER_STEPS, PAPER_CAMERA_PX, BREADTH_TUNING_WORLDS, "training"),
    "unseen-depth": _depth_finder_groups(DEPTH_FINDER_STEPS, PAPER_CAMERA_PX),
    "real-flight": _real_flight_groups(PAPER_STEPS, PAPER_CAMERA_PX),
    "real-flight-tuning": _real_flight_groups(PAPER_STEPS, PAPER_CAMERA_PX, REAL_FLIGHT_TUNING_WORLDS, "training"),
    "thermal": _thermal_groups(PAPER_STEPS, PAPER_CAMERA_PX),
    "thermal-tuning": _thermal_groups(PAPER_STEPS, PAPER_CAMERA_PX, TUNING_WORLDS, "development"),
    "full": _paper_groups(FULL_STEPS, PAPER_CAMERA_PX) + (
        GroupSpec("policies", "follow", "Followers on oracle and TRADE perception",
                  ALL_SCENES, ("scripted", "learned", "waypoint", "hover", "random"), ("oracle", "trade"), ("gt",),
                  TRACKING_RUNS, FULL_STEPS, PAPER_CAMERA_PX),
    ),
}
SUITE_JOBS = {"quick": 2, "paper": 2, "unseen": 2, "tuning": 2, "latency": 2, "breadth": 2, "breadth-tuning": 2,
              "unseen-depth": 2, "real-flight": 2, "real-flight-tuning": 2, "thermal": 2, "thermal-tuning": 2,
              "full": 2}  # default --jobs per suite
# Suites that fly evaluation worlds; no other suite or grid may (`trade_gym.bench.splits`). Besides them, they may
# fly training worlds (the depth finder's group to tune on), never development worlds.
EVALUATION_SUITES = ("unseen", "breadth", "unseen-depth", "real-flight", "thermal")

# A run without --suite: one grid of the chosen axes, these defaults where nothing was chosen.
CUSTOM_DEFAULTS = GroupSpec("custom", "custom", "Custom grid", ALL_SCENES, ("scripted",), ("oracle",), ("gt",),
                            (0, 0), 300, 128)


def custom_group(selection: Selection) -> GroupSpec:
    """The grid of a run without --suite: the selection's axes (and switch values) as the group."""
    d = CUSTOM_DEFAULTS
    return GroupSpec(d.name, d.kind, d.title, selection.scenes or d.scenes, selection.policies or d.policies,
                     selection.perceptions or d.perceptions, selection.pose_sources or d.pose_sources,
                     selection.seeds or d.seeds, selection.steps or d.steps, selection.camera_size or d.camera_size,
                     selection.switches)


def expand_suite(suite: str | None, selection: Selection, available_policies: tuple[str, ...]) -> list[RunSpec]:
    """Every run of `suite` (or of the custom grid when None) kept by `selection`, in a fixed order."""
    if suite is None:
        return custom_group(selection).expand(Selection(), available_policies)
    groups = [g for g in SUITES[suite] if selection.groups is None or g.name in selection.groups]
    return [run for g in groups for run in g.expand(selection, available_policies)]

