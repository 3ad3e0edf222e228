"""World splits: disjoint seed ranges, evaluation worlds flown only by the evaluation suites, and no test,
script default or training draw on them."""

from __future__ import annotations

import ast
import importlib.util
import re
import sys
from pathlib import Path

import pytest

from trade_gym.bench import cli
from trade_gym.bench.splits import (DEVELOPMENT, EVALUATION, SPLITS, TRAINING, EvaluationWorldError,
                                    ranges_overlap, refuse_evaluation_worlds, require_training_worlds, split_of)
from trade_gym.bench.suites import UNSEEN_ABLATION_WORLDS, Selection, expand_suite
from trade_gym.config import SCENE_NAMES

ROOT = Path(__file__).resolve().parents[2]
SCANNED = ("tests", "scripts", "benchmarks", "agents", "trade_gym", "trade")
SPLITS_MODULE = ROOT / "trade_gym" / "bench" / "splits.py"


def _load_script(relative: str):
    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module
    spec.loader.exec_module(module)
    return module


def test_splits_are_the_documented_disjoint_ranges():
    assert (DEVELOPMENT.first, DEVELOPMENT.last) == (0, 999)
    assert (EVALUATION.first, EVALUATION.last, len(EVALUATION)) == (5000, 5019, 20)
    assert TRAINING.first == 10_000
    for a in SPLITS:
        for b in SPLITS:
            assert a is b or not ranges_overlap(a.first, a.last, b)
    assert split_of(0) is DEVELOPMENT and split_of(5019) is EVALUATION and split_of(123_456) is TRAINING
    assert split_of(3000) is None and True not in EVALUATION


def test_refusing_evaluation_worlds_names_the_seed():
    refuse_evaluation_worlds([0, 999, 10_000], "x")
    with pytest.raises(EvaluationWorldError, match=f"world seed {EVALUATION.first + 3}"):
        refuse_evaluation_worlds([1, EVALUATION.first + 3], "x")
    with pytest.raises(ValueError, match="world seed 7 is not a training world"):
        require_training_worlds([TRAINING.first, 7], "x")


SEED_CONTEXT = re.compile(r"seed|world|reset|rng", re.IGNORECASE)  # names a world seed is passed through


def _names(node: ast.AST) -> list[str]:
    """Names a literal is bound to or passed through at `node`: keyword, assignment target, called function."""
    if isinstance(node, ast.keyword):
        return [node.arg or ""]
    if isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        return [ast.unparse(t) for t in targets]
    if isinstance(node, ast.Call):
        return [ast.unparse(node.func)]
    if isinstance(node, ast.arg):
        return [node.arg]
    return []


def _seed_literals(path: Path) -> list[tuple[int, int]]:
    """(line, value) of the evaluation-world literals of `path` that reach a seed: an int bound to or passed
    through a seed/world/reset/rng name, or a string after "--seeds" in a list of arguments."""
    tree = ast.parse(path.read_text(), str(path))
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and type(node.value) is int and node.value in EVALUATION:
            up, names = node, []
            while up in parents and not isinstance(up, ast.stmt):
                up = parents[up]
                names += _names(up)
            names += _names(up)
            if any(SEED_CONTEXT.search(n) for n in names):
                hits.append((node.lineno, node.value))
        elif isinstance(node, (ast.List, ast.Tuple)):
            words = [e.value if isinstance(e, ast.Constant) else None for e in node.elts]
            after = words[words.index("--seeds") + 1:] if "--seeds" in words else []
            hits += [(node.lineno, int(w)) for w in after if isinstance(w, str) and w.isdigit() and int(w) in EVALUATION]
    return hits


def test_seed_literal_scan_finds_seeds_and_ignores_other_numbers(tmp_path):
    probe = tmp_path / "probe.py"
    first = EVALUATION.first
    probe.write_text(f"env.reset(seed={first})\nworld_seed = {first}\nsteps = {first}\n"
                     f"argv = ['--seeds', '{first}', '{first}']\nbuffer_size: int = {first}\n")
    assert sorted(line for line, _ in _seed_literals(probe)) == [1, 2, 4, 4]


def test_no_source_file_passes_an_evaluation_world_as_a_seed():
    """Tests, scripts, benchmarks, agents and the packages reach evaluation worlds only through
    `trade_gym.bench.splits.EVALUATION` (the unseen suite): no literal seed of that range anywhere else."""
    hits = []
    for folder in SCANNED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path != SPLITS_MODULE:
                hits += [f"{path.relative_to(ROOT)}:{line}: {value}" for line, value in _seed_literals(path)]
    assert not hits, hits


def test_oracle_noise_fit_defaults_to_training_worlds_and_refuses_evaluation_ones(capsys):
    fit = _load_script("benchmarks/fit_oracle_noise.py")
    assert all(seed in TRAINING for seed in fit.build_parser().parse_args([]).seeds)
    with pytest.raises(SystemExit) as exit_info:
        fit.main(["--seeds", str(EVALUATION.first)])
    assert exit_info.value.code == 2 and f"world seed {EVALUATION.first}" in capsys.readouterr().err


def test_depth_dataset_draws_training_worlds_and_refuses_evaluation_ones(tmp_path):
    dataset = _load_script("scripts/make_depth_dataset.py")
    assert dataset.TRAIN_SEED_BASE in TRAINING and dataset.HELDOUT_SEED_BASE in TRAINING
    with pytest.raises(EvaluationWorldError):
        dataset.render_split(tmp_path / "train", EVALUATION.first, 2, 1, dataset.ViewConfig())
    assert list(tmp_path.iterdir()) == []  # refused before anything was written


def test_unseen_suite_flies_each_evaluation_world_once_per_configuration():
    runs = expand_suite("unseen", Selection(), ("scripted",))
    main = [r for r in runs if r.group == "unseen"]
    configs = {(r.scene, r.perception, r.pose_source) for r in main}
    assert configs == {(s, p, pose) for s in SCENE_NAMES for p, pose in (("trade", "gt"), ("trade", "vio"),
                                                                          ("dcf", "vio"))}
    for config in configs:
        worlds = [r.world_seed for r in main if (r.scene, r.perception, r.pose_source) == config]
        assert worlds == list(EVALUATION.seeds())
    ablation = [r for r in runs if r.group == "unseen_table1"]
    assert {r.world_seed for r in ablation} == set(range(UNSEEN_ABLATION_WORLDS[0], UNSEEN_ABLATION_WORLDS[1] + 1))
    assert len(ablation) == 3 * 2 * 4 * 5  # scenes x pose x (fusion x mask) x worlds
    for r in runs:
        kw = r.env_kwargs()
        assert "world_seed" not in kw and kw["init_box_perturb_px"] == 5.0 and kw["snap_init_box"]
    cli.check_worlds("unseen", runs)


def test_depth_finder_flies_every_evaluation_world_and_forty_training_worlds_per_scene_and_configuration():
    runs = expand_suite("unseen-depth", Selection(), ("scripted", "learned"))
    configs = {(r.scene, r.policy, r.perception, r.pose_source) for r in runs}
    assert configs == {(s, p, "trade", pose) for s in SCENE_NAMES for p in ("scripted", "learned")
                       for pose in ("gt", "vio")}
    for config in configs:
        mine = [r for r in runs if (r.scene, r.policy, r.perception, r.pose_source) == config]
        assert [r.world_seed for r in mine if r.group == "depth_evaluation"] == list(EVALUATION.seeds())
        training = [r.world_seed for r in mine if r.group == "depth_training"]
        assert len(training) >= 40 and all(seed in TRAINING for seed in training)
    assert all(r.kind == "unseen" and "init_box_perturb_px" not in r.env_kwargs() for r in runs)  # clean start
    cli.check_worlds("unseen-depth", runs)
    with pytest.raises(cli.UsageError, match="development|only"):  # never a development world
        cli.check_worlds("unseen-depth", expand_suite("unseen-depth", Selection(seeds=(0, 0)), ("scripted",)))


@pytest.mark.parametrize("argv", [
    ["--suite", "quick", "--seeds", str(EVALUATION.first), str(EVALUATION.first + 1)],
    ["--seeds", str(EVALUATION.last), str(EVALUATION.last + 5)],  # a custom grid overlapping the split
    ["--suite", "unseen", "--seeds", "0", "1"],
])
def test_cli_keeps_evaluation_worlds_to_the_unseen_suite(argv, monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(cli, "run_all", lambda *a, **k: pytest.fail("an episode ran"))
    assert cli.main(argv + ["--out", str(tmp_path / "out")]) == 2
    assert "evaluation world" in capsys.readouterr().err
