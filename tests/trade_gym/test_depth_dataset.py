"""The depth model's data path: scripts/make_depth_dataset.py writes recorded sequences (kind "views") and
scripts/train_depth.py reads them back, bit for bit, from training worlds only (a tiny run: 1 world per split)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pybullet as p
import pytest

from trade_gym.bench.splits import TRAINING
from trade_gym.recording.format import load_schema
from trade_gym.recording.reader import open_sequence

ROOT = Path(__file__).resolve().parents[2]
VIEWS = 2


def _script(name: str, monkeypatch):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, name, module)  # dataclasses resolve annotations through sys.modules
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def dataset(tmp_path, monkeypatch):
    make = _script("make_depth_dataset", monkeypatch)
    make.main(["--out-dir", str(tmp_path), "--train-worlds", "1", "--heldout-worlds", "1",
               "--views-per-world", str(VIEWS)])
    return make, tmp_path


def test_dataset_is_one_views_sequence_per_training_world(dataset):
    make, out = dataset
    for split, seed in (("train", make.TRAIN_SEED_BASE), ("heldout", make.HELDOUT_SEED_BASE)):
        folders = sorted((out / split).iterdir())
        assert [f.name for f in folders] == [f"world_{seed}"] and seed in TRAINING
        sequence = open_sequence(folders[0])
        meta = json.loads((folders[0] / "meta.json").read_text())
        jsonschema.validate(meta, load_schema("meta"))
        assert sequence.kind == "views" and len(sequence) == VIEWS and meta["layers"]["depth"]["no_hit_m"] == 1000.0
        assert all(sequence.depth_m(f) is not None and f.T_world_cam_true is not None for f in sequence)


def test_train_depth_reads_back_the_rendered_views_exactly(dataset, monkeypatch):
    make, out = dataset
    train = _script("train_depth", monkeypatch)
    data = train.load_split(out / "train")
    cfg = make.ViewConfig()
    cid = p.connect(p.DIRECT)
    try:
        views = make.render_world_views(cid, "desert", make.TRAIN_SEED_BASE, VIEWS, cfg)
    finally:
        p.disconnect(physicsClientId=cid)
    assert data["rgb"].shape == (VIEWS, cfg.size_px, cfg.size_px, 3) and float(data["far_m"]) == cfg.far_m
    assert np.array_equal(data["rgb"], np.stack([v.rgb for v in views]))
    assert np.array_equal(data["depth_m"], np.stack([np.minimum(v.depth_m, cfg.far_m) for v in views]))
    assert data["scene"].tolist() == ["desert"] * VIEWS and data["seed"].tolist() == [make.TRAIN_SEED_BASE] * VIEWS


def test_train_depth_refuses_a_sequence_of_a_development_world(dataset, monkeypatch):
    _, out = dataset
    folder = next((out / "train").iterdir())
    meta = json.loads((folder / "meta.json").read_text())
    (folder / "meta.json").write_text(json.dumps(dict(meta, seeds={"world_seed": 3})))
    train = _script("train_depth", monkeypatch)
    with pytest.raises(ValueError, match="world seed 3 is not a training world"):
        train.load_split(out / "train")
