"""trade-bench flies the waypoint follower by name, on an env in action_mode="waypoint" (`policy_env_kwargs`), and
refuses to mix a follower with the other action mode; the velocity followers' runs are as before."""

from __future__ import annotations

import json

import jsonschema
import pytest

from trade_gym.agents import WaypointFollower
from trade_gym.bench import cli
from trade_gym.bench.policies import POLICY_NAMES, make_policy, policy_env_kwargs
from trade_gym.bench.results import load_results, load_schema
from trade_gym.bench.suites import SUITES, RunSpec, Selection, expand_suite
from trade_gym.config import EnvConfig

VELOCITY_POLICIES = ("scripted", "learned", "hover", "random")


def test_only_the_waypoint_follower_sets_an_env_keyword():
    assert "waypoint" in POLICY_NAMES
    assert policy_env_kwargs("waypoint") == {"action_mode": "waypoint"}
    assert all(policy_env_kwargs(name) == {} for name in VELOCITY_POLICIES)


def test_a_waypoint_run_flies_a_waypoint_env_and_the_other_runs_keep_their_kwargs():
    waypoint = RunSpec("custom", "custom", "desert", "waypoint", "oracle", "gt", 0, 30, 32)
    scripted = RunSpec("custom", "custom", "desert", "scripted", "oracle", "gt", 0, 30, 32)
    assert EnvConfig(**waypoint.env_kwargs()).action_mode == "waypoint"
    assert set(scripted.env_kwargs()) == {*RunSpec.OWN_ENV_KEYS}  # no action_mode: results.json as before
    quick = expand_suite("quick", Selection(), VELOCITY_POLICIES)
    assert all("action_mode" not in run.env_kwargs() for run in quick)


def test_the_full_suite_flies_the_waypoint_follower_with_the_others():
    (group,) = [g for g in SUITES["full"] if g.name == "policies"]
    assert "waypoint" in group.policies


def test_make_policy_builds_the_waypoint_follower_from_the_env_config():
    config = EnvConfig(action_mode="waypoint", camera_pitch_deg=45.0)
    policy = make_policy("waypoint", 0, config.camera_pitch_deg, env_config=config)
    assert isinstance(policy, WaypointFollower) and policy.config.camera_pitch_deg == 45.0
    assert make_policy("waypoint", 0, 60.0).config.camera_pitch_deg == 60.0  # without a config: the given pitch


@pytest.mark.parametrize("name, mode", [("waypoint", "velocity"), ("scripted", "waypoint")])
def test_make_policy_refuses_an_env_of_the_other_action_mode(name, mode):
    with pytest.raises(ValueError, match=f"policy '{name}' flies action_mode=.*the env has action_mode='{mode}'"):
        make_policy(name, 0, 90.0, env_config=EnvConfig(action_mode=mode))


def test_cli_policies_waypoint_runs_a_waypoint_episode_and_reloads_its_spec(tmp_path):
    args = ["--scenes", "desert", "--policies", "waypoint", "--seeds", "0", "0", "--steps", "30", "--camera-size", "32"]
    assert cli.main(args + ["--out", str(tmp_path / "a")]) == 0
    doc = json.loads((tmp_path / "a" / "results.json").read_text())
    jsonschema.validate(doc, load_schema())
    (run,) = doc["runs"]
    assert run["policy"] == "waypoint" and run["env_kwargs"]["action_mode"] == "waypoint"
    assert run["error"] is None and run["metrics"]["steps"] == 30 and run["metrics"]["visible_fraction"] == 1.0
    (result,), _ = load_results(tmp_path / "a" / "results.json")
    assert result.spec == expand_suite(None, Selection(scenes=("desert",), policies=("waypoint",), seeds=(0, 0),
                                                       steps=30, camera_size=32), ("waypoint",))[0]
