"""The results pages are generated from the committed results under docs/results/: each per-suite page and the
summary docs/results.md match a fresh render, the summary stays short and its numbers are those of the
results.json files, every page it links exists, and every figure any page links exists."""

from __future__ import annotations

import importlib.util
import json
import math
import re
import shutil
import sys
from pathlib import Path

from trade_gym.bench import headlines, runner
from trade_gym.bench.failures import FAIL_GROUND_RMSE_M
from trade_gym.bench.report import fmt
from trade_gym.bench.suites import RunSpec
from trade_gym.metrics import METRIC_NAMES

ROOT = Path(__file__).resolve().parents[2]
SUMMARY = ROOT / "docs" / "results.md"
IMAGE_LINK = re.compile(r"!\[[^]]*\]\(([^)]+)\)")
PAGE_LINK = re.compile(r"(?<!!)\[[^]]*\]\((results/[^)#]+\.md)\)")


def load_renderer():
    """scripts/render_results_doc.py as a module (scripts/ is no package)."""
    path = ROOT / "scripts" / "render_results_doc.py"
    spec = importlib.util.spec_from_file_location("render_results_doc", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["render_results_doc"] = module
    spec.loader.exec_module(module)
    return module


def render_page_of(results_dir: Path, page: str, monkeypatch) -> tuple[str, str]:
    """(title, text) of the per-suite page `page` as scripts/render_results_doc.py renders it from the runs under
    `results_dir` (a test's own run in place of the committed ones)."""
    doc = load_renderer()
    monkeypatch.setattr(doc, "RESULTS_DIR", results_dir)
    section = next(s for s in doc.SECTIONS if s.page == page)
    return section.title, doc.render_section(section)


def _pages() -> list[Path]:
    """The summary and every committed per-suite page."""
    doc = load_renderer()
    return [SUMMARY] + [s.path for s in doc.SECTIONS if s.path.is_file()]


def _raw_runs(folder: str) -> list[dict]:
    return json.loads((ROOT / "docs" / "results" / folder / "results.json").read_text())["runs"]


def _row(text: str, prefix: str) -> str:
    """The one table row of `text` starting with `prefix`."""
    rows = [line for line in text.splitlines() if line.startswith(prefix)]
    assert len(rows) == 1, (prefix, rows)
    return rows[0]


def test_every_results_page_is_the_render_of_the_committed_results():
    doc = load_renderer()
    pages = doc.render()
    assert SUMMARY in pages and {s.path for s in doc.SECTIONS if s.present()} <= set(pages)
    assert doc.stale_pages(pages) == [], "stale: run python scripts/render_results_doc.py"


def test_check_exits_1_naming_a_stale_page_and_0_when_all_are_current(tmp_path, monkeypatch, capsys):
    doc = load_renderer()
    current, stale, missing = tmp_path / "current.md", tmp_path / "stale.md", tmp_path / "missing.md"
    current.write_text("same\n")
    stale.write_text("old\n")
    monkeypatch.setattr(doc, "render", lambda: {current: "same\n", stale: "new\n", missing: "new\n"})
    assert doc.main(["--check"]) == 1
    out = capsys.readouterr().out
    assert f"{stale} is stale" in out and f"{missing} is stale" in out and f"{current} is stale" not in out
    monkeypatch.setattr(doc, "render", lambda: {current: "same\n"})
    assert doc.main(["--check"]) == 0


def test_summary_is_at_most_the_word_budget_with_a_table_date_and_full_report_per_question():
    doc = load_renderer()
    text = SUMMARY.read_text()
    assert len(text.split()) <= doc.SUMMARY_MAX_WORDS  # as `wc -w` counts
    present = [h for h in doc.HEADLINES if (doc.RESULTS_DIR / h.folder / "results.json").is_file()]
    assert present, "no committed run to summarise"
    for headline in present:
        section = text.split(f"## {headline.question}\n", 1)[1].split("\n## ", 1)[0]
        assert "\n| " in section and re.search(r"`, \d{4}-\d\d-\d\d, .*Full report: \[", section), headline.question
    assert "+dirty" not in text and not re.search(r"`[0-9a-f]{7}`", text)  # commits are on the per-suite pages


def test_every_page_the_summary_links_exists_and_every_per_suite_page_is_linked():
    doc = load_renderer()
    linked = set(PAGE_LINK.findall(SUMMARY.read_text()))
    for target in linked:
        assert (SUMMARY.parent / target).is_file(), target
    assert {f"results/{s.page}.md" for s in doc.SECTIONS if s.present()} <= linked


def test_every_image_link_of_every_page_resolves_from_the_page():
    links = 0
    for page in _pages():
        for target in IMAGE_LINK.findall(page.read_text()):
            assert (page.parent / target).is_file(), f"{page.name}: {target}"
            links += 1
    assert links >= len(_pages())


def test_every_run_on_a_per_suite_page_names_its_command_and_commit():
    for page in _pages()[1:]:
        text = page.read_text()
        runs = text.count("Command: `trade-bench")
        assert runs >= 1 and len(re.findall(r"^commit `[0-9a-f]{7}`", text, re.MULTILINE)) == runs, page.name
        assert "+dirty" not in text


def test_summary_table1_rmse_is_the_pooled_rmse_of_the_committed_unseen_runs():
    runs = [r for r in _raw_runs("unseen") if r["error"] is None and r["perception"] == "trade"]
    text = SUMMARY.read_text()
    for scene, (paper_gt_m, paper_vio_m) in headlines.PAPER_TABLE1_RMSE_M.items():
        pooled, worlds = {}, sum(r["scene"] == scene and r["pose_source"] == "gt" for r in runs)
        for pose in headlines.POSES:
            mine = [r["metrics"] for r in runs if r["scene"] == scene and r["pose_source"] == pose]
            frames = sum(m["ground_depth_frames"] for m in mine)
            # RMSE over the union of frames: sqrt(sum_i rmse_i^2 n_i / sum_i n_i)
            pooled[pose] = math.sqrt(sum(m["ground_depth_rmse_m"] ** 2 * m["ground_depth_frames"] for m in mine)
                                     / frames)
        cells = f"| {fmt(pooled['gt'])} | {fmt(paper_gt_m)} | {fmt(pooled['vio'])} | {fmt(paper_vio_m)} |"
        assert _row(text, f"| {scene} | {worlds} |").startswith(f"| {scene} | {worlds} {cells}")


def test_summary_depth_flights_above_threshold_are_counted_from_the_committed_runs():
    runs = [r for r in _raw_runs("unseen_depth/evaluation") if r["error"] is None and r["perception"] == "trade"]
    text = SUMMARY.read_text()
    for scene, pose in {(r["scene"], r["pose_source"]) for r in runs}:
        rmses = [r["metrics"]["ground_depth_rmse_m"] for r in runs if (r["scene"], r["pose_source"]) == (scene, pose)]
        above = sum(v is None or v > FAIL_GROUND_RMSE_M for v in rmses)
        assert _row(text, f"| {scene} | {pose} | {len(rmses)} |").endswith(f"| {above} of {len(rmses)} |")


def test_summary_leaves_out_a_question_whose_results_are_missing(tmp_path, monkeypatch):
    doc = load_renderer()
    shutil.copytree(doc.RESULTS_DIR / "latency", tmp_path / "latency", ignore=shutil.ignore_patterns("*.png"))
    monkeypatch.setattr(doc, "RESULTS_DIR", tmp_path)
    monkeypatch.setattr(doc, "SPEED_DIR", tmp_path)
    text = doc.render_summary([])
    questions = re.findall(r"^## (.+)$", text, re.MULTILINE)
    latency = next(h for h in doc.HEADLINES if h.folder == "latency")
    assert questions == [latency.question, "Full reports"]
    assert "![" not in text  # its figure was not copied: no link to a missing file


def _depth_run(seed: int, policy: str, rmse_m: float, frames: int) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {"ground_depth_rmse_m": rmse_m, "ground_depth_frames": frames}
    spec = RunSpec("depth_evaluation", "unseen", "city", policy, "trade", "vio", seed, 300, 256)
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 20.0), None)


def test_depth_spread_table_names_the_worst_flight_and_counts_a_flight_without_depth_as_above():
    runs = [_depth_run(7, "scripted", 0.5, 400), _depth_run(8, "learned", 3.0, 400),
            _depth_run(9, "scripted", math.nan, 0)]
    pooled = math.sqrt((0.5 ** 2 * 400 + 3.0 ** 2 * 400) / 800)
    row = headlines.depth_spread_table(runs)[-1]
    assert row == f"| city | vio | 3 | {fmt(pooled)} | 1.75 | 3 (world 8, learned) | 2 of 3 |"


def _breadth_run(policy: str, motion: str, appearance: str, success: bool) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {"success": success, "ground_depth_frames": 0,
                                                  "target_depth_frames": 0, "decoy_switches": 0, "crashed": False}
    spec = RunSpec("breadth_none", "breadth", "desert", policy, "trade", "vio", 5000, 450, 256,
                   (("target_motion", motion), ("appearance", appearance)), (("decoys", "none"),))
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 20.0), None)


def test_breadth_success_table_pools_each_motion_and_each_appearance_with_its_run_count():
    runs = [_breadth_run("scripted", "cruise", "fixed", True), _breadth_run("scripted", "cruise", "randomized", False),
            _breadth_run("scripted", "evasive", "fixed", True), _breadth_run("scripted", "evasive", "randomized", True)]
    lines = headlines.breadth_success_table(runs)
    assert lines[0] == "| follower (perception) | cruise | evasive | fixed | randomized | all |"
    assert lines[-1] == "| scripted (trade) | 0.5 (2) | 1 (2) | 1 (2) | 0.5 (2) | 0.75 (4) |"
