"""Frozen per-scene parameters (the paper's three scenes) and the `SCENES` registry.

Owns `SceneSpec`, `SCENES` and `get_scene`; the procedural layout that uses them lives in `layout.py`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from types import MappingProxyType

VEHICLE_KINDS = ("car", "truck", "tank")


@dataclass(frozen=True)
class SceneSpec:
    """What a scene contains and how the drone follows in it (paper, Experiments)."""

    name: str
    follow_altitude_agl_m: float  # nominal drone height above the ground under it [m]
    target_kind: str  # one of VEHICLE_KINDS
    target_speed_mps: float  # default target speed along its path [m/s]
    route_length_m: float  # nominal straight-line extent of the target's route [m]
    terrain_size_m: float  # side of the square heightfield [m]
    terrain_spacing_m: float  # heightfield grid step [m]
    ground_texture: str  # texture name in assets/textures (without .png)
    decoy_kind: str  # one of VEHICLE_KINDS
    parked_decoys_near_path: int  # parked within DECOY_NEAR_PATH_M of the target's path
    parked_decoys_far: int  # parked farther away
    moving_decoys: int  # decoys that drive across or beside the target's path
    boulder_count: int = 0  # rocks with collision (desert)
    turn_deg: float = 0.0  # yaw turn of the route (mountain)
    turn_after_m: float = 0.0  # distance before the turn [m] (mountain)
    takeoff_building_height_m: float = 0.0  # roof height of the take-off building (city) [m]

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("float", "int") and not value >= 0:
                raise ValueError(f"SceneSpec.{f.name} must be >= 0, got {value!r}")
        for name in ("follow_altitude_agl_m", "target_speed_mps", "route_length_m", "terrain_size_m",
                     "terrain_spacing_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SceneSpec.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("target_kind", "decoy_kind"):
            if getattr(self, name) not in VEHICLE_KINDS:
                raise ValueError(f"SceneSpec.{name} must be one of {VEHICLE_KINDS}, got {getattr(self, name)!r}")
        if self.terrain_size_m < 2 * self.terrain_spacing_m:
            raise ValueError(f"SceneSpec.terrain_size_m must span >= 2 cells, got {self.terrain_size_m!r}")

    @property
    def decoy_count(self) -> int:
        return self.parked_decoys_near_path + self.parked_decoys_far + self.moving_decoys


DECOY_NEAR_PATH_M = 15.0  # "near the path" for parked decoys [m]

SCENES: MappingProxyType[str, SceneSpec] = MappingProxyType(
    {
        "desert": SceneSpec(
            name="desert", follow_altitude_agl_m=16.0, target_kind="car", target_speed_mps=3.0,
            route_length_m=100.0, terrain_size_m=250.0, terrain_spacing_m=1.25, ground_texture="desert_ground",
            decoy_kind="car", parked_decoys_near_path=4, parked_decoys_far=1, moving_decoys=3, boulder_count=110,
        ),
        "city": SceneSpec(
            name="city", follow_altitude_agl_m=32.0, target_kind="truck", target_speed_mps=1.5,
            route_length_m=45.0, terrain_size_m=200.0, terrain_spacing_m=2.5, ground_texture="city_ground",
            decoy_kind="car", parked_decoys_near_path=5, parked_decoys_far=0, moving_decoys=1,
            takeoff_building_height_m=30.0,
        ),
        "mountain": SceneSpec(
            name="mountain", follow_altitude_agl_m=30.0, target_kind="tank", target_speed_mps=2.7,
            route_length_m=86.0, terrain_size_m=240.0, terrain_spacing_m=1.5, ground_texture="mountain_ground",
            decoy_kind="tank", parked_decoys_near_path=2, parked_decoys_far=0, moving_decoys=0,
            turn_deg=65.0, turn_after_m=50.0,
        ),
    }
)


# Difficulty tiers of the decoys (`trade_gym.sim.world.DecoyTier`): none, parked far from the target's route only,
# or all of them (the paper's scenes).
DECOY_TIERS = ("none", "parked", "ambiguous")


def get_scene(name: str) -> SceneSpec:
    """SceneSpec by name; ValueError listing the valid names otherwise."""
    try:
        return SCENES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown scene {name!r}; valid scenes: {sorted(SCENES)}") from None
