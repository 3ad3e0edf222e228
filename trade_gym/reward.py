"""Reward of TradeFollow-v0: the following task in its own units, as named terms computed from ground truth.

The terms sum to the reward (each is in `info["reward_<term>"]`):

- `visible`: `+visible_bonus` on a frame whose target is in view (ground-truth visibility, so a policy is
  paid for what happens, not for what perception believes). It keeps the reward of a good frame positive,
  so ending the episode early never pays.
- `distance`: `-distance_weight * (s min(d / r, 1) + (1 - s) min(d / h, 1))`, d the horizontal distance from
  the drone to the target less the band's standoff (0 with the downward camera), r the following band's distance
  (`trade_gym.scoring.FollowBand`: a quarter of the camera footprint's half-width at the follow height, 4-11 m
  across the scenes), h the scene's follow height
  and s `band_distance_share`. The band part makes letting the target leave the band cost most of the bonus;
  the follow-height part keeps a pull towards the target from farther off, where the band part is flat. A
  drone hovering at its start distance earns at most half of the scripted follower's return (tested), though
  a slow city target drives only half a follow height away in 10 s.
- `height`: `-height_weight * min(|z - g - h| / h, 1)`, z the drone's height and g the terrain height
  under the target: the drone is paid for holding the scene's follow height above the target's ground
  (terrain only, so a roof or the target's own height does not move the set point).
- `effort`: `-effort_weight * mean(action^2)`: a small price on commanded speed, against dithering.
- `crash`: `-crash_penalty` on the frame the drone hits terrain or a building.

Both errors saturate (at one band distance and one follow height), so a lost drone's reward stays bounded;
the crash penalty is at least the worst loss of flying on until the lost-target timeout ends the episode
(tested), so a crash never pays.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from trade.validation import is_finite_number, require

RELATIVE_ERROR_CAP = 1.0  # distance and height errors saturate at one band distance and one follow height


@dataclass(frozen=True)
class RewardConfig:
    """Weights of the reward terms, per frame (dimensionless; errors are in follow heights)."""

    visible_bonus: float = 1.0
    distance_weight: float = 1.0
    # of the distance term in band distances; the rest in follow heights (0.5 left hovering 0.47 of following's
    # return in the city, 0.75 leaves 0.33: dev worlds 0-3, oracle, 300 frames)
    band_distance_share: float = 0.75
    height_weight: float = 0.5
    effort_weight: float = 0.05
    # >= (distance_weight + height_weight + effort_weight) x lost-timeout frames (1.55 x 3 s x 30 Hz = 139.5)
    crash_penalty: float = 150.0

    def __post_init__(self) -> None:
        for name in ("visible_bonus", "distance_weight", "height_weight", "effort_weight", "crash_penalty"):
            value = getattr(self, name)
            require(is_finite_number(value) and value >= 0, f"RewardConfig.{name}", value, "a finite number >= 0")
        share = self.band_distance_share
        require(is_finite_number(share) and 0.0 <= share <= 1.0, "RewardConfig.band_distance_share", share, "in [0, 1]")

    def worst_frame_loss(self) -> float:
        """The most a frame without a crash can lose: no target in view, both errors saturated, full action."""
        return self.distance_weight * RELATIVE_ERROR_CAP + self.height_weight * RELATIVE_ERROR_CAP + self.effort_weight


@dataclass(frozen=True)
class RewardInputs:
    """What one frame's reward depends on (ground truth and the action applied)."""

    target_visible: bool
    horizontal_distance_m: float
    height_above_target_ground_m: float  # drone height minus the terrain height under the target
    follow_height_m: float  # the scene's nominal height above the ground
    follow_distance_m: float  # the following band's horizontal distance (`trade_gym.scoring.FollowBand`)
    action: Sequence[float]  # the ACTION_DIM values applied (`trade_gym.action.clip_action`); () at the reset
    crashed: bool
    # the horizontal distance [m] at which the camera centres the target (`trade_gym.scoring.FollowBand`): 0 for a
    # downward camera, the follow height over tan(pitch) for a pitched one
    standoff_m: float = 0.0

    @property
    def follow_error_m(self) -> float:
        """How far [m] the drone's horizontal distance to the target is from the standoff (its distance with a
        downward camera)."""
        return abs(self.horizontal_distance_m - self.standoff_m)


def compute_reward(config: RewardConfig, x: RewardInputs) -> tuple[float, dict[str, float]]:
    """(total, terms) of one frame; the terms sum to the total."""
    h = x.follow_height_m
    share, d = config.band_distance_share, x.follow_error_m
    distance_error = (share * min(d / x.follow_distance_m, RELATIVE_ERROR_CAP)
                      + (1.0 - share) * min(d / h, RELATIVE_ERROR_CAP))
    height_error = min(abs(x.height_above_target_ground_m - h) / h, RELATIVE_ERROR_CAP)
    terms = {
        "visible": config.visible_bonus * float(x.target_visible),
        "distance": -config.distance_weight * distance_error,
        "height": -config.height_weight * height_error,
        "effort": -config.effort_weight * sum(float(a) * float(a) for a in x.action) / len(x.action),
        "crash": -config.crash_penalty * float(x.crashed),
    }
    return float(sum(terms.values())), terms
