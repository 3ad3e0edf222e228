"""docs/results.md is generated from the committed results under docs/results/: it matches a fresh render,
names the commit of every run it shows, and every figure it links exists."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _renderer():
    path = ROOT / "scripts" / "render_results_doc.py"
    spec = importlib.util.spec_from_file_location("render_results_doc", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["render_results_doc"] = module
    spec.loader.exec_module(module)
    return module


def test_results_doc_is_the_render_of_the_committed_results():
    doc = _renderer()
    assert doc.DOC.read_text() == doc.render(), "stale: run python scripts/render_results_doc.py"


def test_results_doc_names_a_commit_per_run_and_links_existing_figures():
    text = (ROOT / "docs" / "results.md").read_text()
    runs = text.count("Command: `trade-bench")
    assert runs >= 1 and len(re.findall(r"^commit `[0-9a-f]{7}`", text, re.MULTILINE)) == runs
    assert "+dirty" not in text
    for target in re.findall(r"!\[[^]]*\]\(([^)]+)\)", text):
        assert (ROOT / "docs" / target).is_file(), target
