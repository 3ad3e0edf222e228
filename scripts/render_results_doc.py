"""Writes the results pages from the committed benchmark results (never by hand): a per-suite page
docs/results/<suite>.md with each run's full report, and the summary docs/results.md.

Each per-suite page holds one or more `trade-bench` runs: their results.json, re-summarised by the current code,
rendered as trade-bench renders results.md, with the run's own command, commit, date and machine. The figures
beside each results.json were drawn by `trade-bench --report` from the run's per-frame series. The summary gives
one compact table per headline question (`trade_gym.bench.headlines`), computed from the same results.json
files and the speed records of `benchmarks/speed.py`; a question whose source file is missing is left out.

Usage: python scripts/render_results_doc.py [--check]   (--check: exit 1 when any page is stale)
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from trade_gym.bench import headlines  # noqa: E402
from trade_gym.bench.report import render_markdown  # noqa: E402
from trade_gym.bench.results import load_results  # noqa: E402
from trade_gym.bench.runner import RunResult  # noqa: E402
from trade_gym.bench.suites import SUITES  # noqa: E402
from trade_gym.bench.summary import summarise  # noqa: E402

DOC = ROOT / "docs" / "results.md"  # the summary
RESULTS_DIR = ROOT / "docs" / "results"  # the committed runs, and the per-suite pages beside their folders
SPEED_DIR = ROOT / "benchmarks" / "results"  # benchmarks/speed.py's records, speed_<scene>.json
SPEED_SCENES = ("desert", "city", "mountain")
SUMMARY_MAX_WORDS = 1500  # as `wc -w` counts them: a page a newcomer reads through
FIGURE_SUFFIXES = (".png", ".jpg")  # plots, and the depth finder's strips
DATE_CHARS = len("YYYY-MM-DD")  # the day of a run's UTC timestamp


@dataclass(frozen=True)
class Section:
    """One per-suite page: docs/results/<page>.md, its title, what it is, and its runs (folders under
    docs/results, in the order the page shows them)."""

    page: str
    title: str
    about: str
    folders: tuple[str, ...]

    @property
    def path(self) -> Path:
        return RESULTS_DIR / f"{self.page}.md"

    def present(self) -> list[str]:
        """The folders whose results.json is committed."""
        return [f for f in self.folders if (RESULTS_DIR / f / "results.json").is_file()]


SECTIONS = (
    Section("unseen", "Unseen worlds (evaluation split)",
        "The paper's protocol on the 20 evaluation worlds per scene, which no parameter, threshold or test was "
        "chosen on (`trade_gym.bench.splits`): one run per world, first frame shifted within 10 frames, initial "
        "box perturbed within 5 px and snapped, 450 frames at 256 px, flown in closed loop by the scripted "
        "follower. Then Table 1's ablation rows on the first 5 evaluation worlds (the `unseen_table1` group of "
        "an unseen run, rendered with `trade-bench --report DIR --tables unseen_table1`; its commit may be an "
        "earlier one than the main table's: each names its own).", ("unseen", "unseen_table1")),
    Section("unseen_depth", "Depth failure finder (training and evaluation worlds)",
        "`trade-bench --suite unseen-depth`: ground depth under full TRADE on every evaluation world and on training "
        "worlds 10000-10039 (the ones to tune on), flown by the scripted and the learned follower with ground-truth "
        "and VIO pose from a clean start, 300 frames at 256 px; one run per world, each report rendered for its group "
        "and scenes. \"Plane off\" is the fraction of a world's frames whose ground estimate misses the true ground "
        "by more than 1 m. Each world whose ground RMSE exceeds 2 m has a strip of its worst frames (ground mask "
        "cyan, plane inliers circled, estimated and true ground depth under each frame).",
        ("unseen_depth/evaluation", "unseen_depth/training_city", "unseen_depth/training_desert_mountain")),
    Section("paper", "Development world (the paper's reproduction)",
        "The paper's tables on one development world per scene (`world_seed=0`, the world the stack's parameters "
        "were tuned on), 5 runs per cell for depth and 10 for tracking, each with its own start shift, box "
        "perturbation, sensor noise and VIO drift. A table re-run for some scenes only is shown as two reports, "
        "each rendered for its scenes (`trade-bench --report DIR --scenes ...`) with its own commit.",
        ("paper/table1", "paper/table1_city", "paper/table2", "paper/tracking")),
    Section("latency", "Perception latency (development world)",
        "Full TRADE with ground-truth pose on development world 0 of each scene, 450 frames at 256 px, flown by "
        "the scripted and the learned follower with a fixed perception latency (`perception_latency=\"fixed\"`): "
        "the estimate of a frame reaches the observation 0, 33, 100, 200 or 400 ms later. Scores are of the "
        "estimate the policy holds against the current frame's truth (VOT's real-time rule). One run per cell.",
        ("latency",)),
    Section("unseen_follow", "Followers on unseen worlds (evaluation split)",
        "The scripted and the learned follower flown under full TRADE with ground-truth and VIO pose on the 20 "
        "evaluation worlds per scene, 450 frames at 256 px (the `unseen_follow` group of an unseen run, rendered "
        "with `trade-bench --report DIR --tables unseen_follow`). The learned follower is the shipped "
        "`assets/policies/follower_ppo.onnx` of the named commit.", ("unseen_follow",)),
    Section("breadth", "Scenario breadth (evaluation worlds)",
        "`trade-bench --suite breadth`: each decoy tier (`decoys=`), target motion (`target_motion=`) and appearance "
        "(`appearance=`), flown by the scripted and the learned follower with full TRADE and with DCF, VIO pose, one "
        "450-frame run per configuration on the first evaluation world of each scene. Success, following and "
        "collision rate are EVT-Bench's episode scores (`trade_gym.metrics`).", ("breadth",)),
    Section("real_flight", "Real flight: thermal camera, light stack, waypoint follower (evaluation worlds)",
        "`trade-bench --suite real-flight`: the paper's onboard setup (its real-time implementation): a Boson-like "
        "thermal camera at 45 deg pitch (`camera_modality=\"thermal\"`), the light TRADE stack of the Voxl 2 "
        "(`stack=\"light\"`: no ground mask or single-image depth, estimates one 7.5 fps period late) and the "
        "waypoint follower (`action_mode=\"waypoint\"`, PX4-style position setpoints), with VIO pose as in the "
        "flight; TRADE against DCF at night (2 h), at the scene's morning crossover (the hour at which its target's "
        "parked twin comes nearest the terrain's temperature, `trade_gym.sim.thermal_crossover`) and by day (13 h); "
        "one 450-frame run at 256 px per evaluation world, the paper's start protocol. What the camera sees at those "
        "hours: [environment.md](../environment.md#thermal-camera). The following band (and so success) is centred on "
        "the camera's standoff, h / tan(45 deg) = h behind the target (`trade_gym.scoring.FollowBand`); the gate is "
        "on the tracked fraction and collisions.", ("real_flight",)),
    Section("thermal", "Thermal camera: full TRADE and the light stack (evaluation worlds)",
        "`trade-bench --suite thermal`: the unseen suite's full TRADE runs (scripted follower, downward camera, "
        "ground-truth pose, the paper's start protocol) on the Boson-like thermal camera (`camera_modality=\"thermal\"`) "
        "at night (2 h), at the scene's morning crossover and by day (13 h) in every scene; then the light stack "
        "(`stack=\"light\"`: no ground mask or single-image depth, estimates one 7.5 fps period late) at night and by "
        "day in desert and mountain, for its ground depth. One 450-frame run at 256 px per evaluation world. What the "
        "camera sees at those hours: [environment.md](../environment.md#thermal-camera).", ("thermal",)),
)


@dataclass(frozen=True)
class Headline:
    """One question of the summary: answered by a table computed from one run (a folder under docs/results),
    shown with one of that run's figures and a link to the per-suite page with the full report."""

    question: str
    about: str
    folder: str
    table: Callable[[Sequence[RunResult]], list[str]]
    figure: str  # relative to the folder
    page: str  # a Section.page


HEADLINES = (
    Headline("Does TRADE reproduce the paper's Table 1 on unseen worlds?",
             "The paper's protocol, scripted follower, on the evaluation worlds, which nothing was tuned on: "
             "full TRADE's ground-depth RMSE pooled over every frame of every world, with ground-truth (gt) and "
             "VIO pose, beside the paper's; then tracking with VIO pose, TRADE against the DCF baseline: tracked "
             "fraction (mean over worlds) and decoy switches (total).",
             "unseen", headlines.paper_protocol_table, "unseen_per_world.png", "unseen"),
    Headline("Does ground depth hold on every unseen world?",
             "A pooled RMSE can hide one bad world. The depth failure finder flies every evaluation world with the "
             "scripted and the learned follower (a flight each) under full TRADE from a clean start; per scene and "
             "pose: the pooled RMSE, the median flight, the worst flight and how many flights miss the failure "
             "threshold. The training worlds' runs are on the full page.",
             "unseen_depth/evaluation", headlines.depth_spread_table, "depth_evaluation_per_world.png",
             "unseen_depth"),
    Headline("Does the learned follower follow better than the scripted one?",
             "Both followers under full TRADE on the evaluation worlds, each cell 'scripted / learned': EVT-Bench "
             "success and following rates and the mean horizontal following error, means over worlds.",
             "unseen_follow", headlines.follower_table, "unseen_follow_paths.png", "unseen_follow"),
    Headline("How often does following succeed across scenarios?",
             "The breadth suite: decoy tiers, target motions and appearances on the first evaluation world of each "
             "scene, VIO pose, one run per configuration. EVT-Bench success rate per target motion and per "
             "appearance, pooled over scenes and decoy tiers; (n) = runs.",
             "breadth", headlines.breadth_success_table, "breadth_success.png", "breadth"),
    Headline("How much perception latency can following take?",
             "Full TRADE with gt pose on the development world of each scene, the estimate of each frame held back "
             "by a fixed latency: mean horizontal following error and tracked fraction over the scenes' runs, "
             "scored against the current frame's truth; (n) = runs. A mean over scenes hides the one that breaks "
             "first: the full page has a row per scene.",
             "latency", headlines.latency_table, "latency_vs_latency.png", "latency"),
    Headline("Does TRADE track on a thermal camera?",
             "The unseen suite's full TRADE runs on the thermal camera at night, at the scene's morning crossover "
             "(target and terrain nearest in temperature) and by day, one run per evaluation world: the worlds "
             "tracked >= 0.95 with no decoy switch, of those flown (mean tracked fraction); then the light stack's "
             "ground-depth RMSE pooled over its night and day runs.",
             "thermal", headlines.thermal_table, "thermal_by_time_of_day.png", "thermal"),
)
SPEED_ABOUT = ("Env steps per second in one process, measured by `benchmarks/speed.py` on one machine at one moment: "
               "with oracle perception and no rendering, with rendering at 256 px, and with full TRADE perception at 256 px, the camera's rate being 30 (records "
               "`benchmarks/results/speed_<scene>.json`; how to run it: [benchmark.md](benchmark.md#speed)).")


def run_report(folder: str, link_prefix: str) -> list[str]:
    """One run's report (results.md as trade-bench renders it, without its title), after its command; figure
    links start with `link_prefix`, the folder seen from the page."""
    source = RESULTS_DIR / folder / "results.json"
    results, meta = load_results(source)
    titles = {g.name: g.title for g in SUITES.get(meta["suite"] or "", ())}
    plots = sorted(p.relative_to(RESULTS_DIR / folder).as_posix() for p in (RESULTS_DIR / folder).rglob("*")
                   if p.suffix in FIGURE_SUFFIXES)
    failures = [f"{r.spec.run_id}: {r.error}" for r in results if r.error]
    body = render_markdown(summarise(results), meta, titles, failures, plots, results).splitlines()
    out = [f"Command: `trade-bench {' '.join(meta['argv'])}`.", ""]
    for line in body[1:]:  # the report's own title: the page's heading stands for it
        out.append(line.replace("](", f"]({link_prefix}") if line.startswith("![") else line)
    return out


def render_section(section: Section) -> str:
    """A per-suite page: the section's title and about-text, then each of its runs' reports."""
    lines = [f"# {section.title}", "",
             "Generated by `python scripts/render_results_doc.py` from the committed runs under `docs/results/`; "
             "the [results summary](../results.md) has the headline numbers.", "", section.about, ""]
    for folder in section.present():
        lines += run_report(folder, f"{folder}/") + [""]
    return "\n".join(lines).rstrip() + "\n"


def _provenance(meta: dict) -> str:
    """Which command made the numbers, when and where; the commit is on the full report (the summary keeps none)."""
    return (f"Numbers from `trade-bench {' '.join(meta['argv'])}`, {meta['date_utc'][:DATE_CHARS]}, {meta['cpu']} "
            f"({meta['cores']} cores).")


def render_headline(headline: Headline) -> list[str]:
    """A summary section: the question, its table, the command and date of its numbers, a figure and the full
    report's link (which names the commit);
    nothing when the run's results.json is missing."""
    source = RESULTS_DIR / headline.folder / "results.json"
    if not source.is_file():
        return []
    results, meta = load_results(source)
    section = next(s for s in SECTIONS if s.page == headline.page)
    lines = [f"## {headline.question}", "", headline.about, ""] + headline.table(results) + [""]
    lines += [f"{_provenance(meta)} Full report: [{section.title}](results/{section.page}.md).", ""]
    if (RESULTS_DIR / headline.folder / headline.figure).is_file():
        lines += [f"![{headline.figure}](results/{headline.folder}/{headline.figure})", ""]
    return lines


def render_speed() -> list[str]:
    """The speed section from the committed speed records (nothing when there is none)."""
    paths = [SPEED_DIR / f"speed_{scene}.json" for scene in SPEED_SCENES]
    records = [json.loads(p.read_text()) for p in paths if p.is_file()]
    if not records:
        return []
    return ["## How fast is the env?", "", SPEED_ABOUT, ""] + headlines.speed_table(records) + [""]


def render_intro() -> list[str]:
    paper = headlines.PAPER_TABLE1_RMSE_M
    gt, vio = (" / ".join(f"{pair[i]:g}" for pair in paper.values()) for i in range(len(headlines.POSES)))
    return ["# Results", "",
            "What the committed benchmark runs say, one table per question. Generated by "
            "`python scripts/render_results_doc.py` from the `results.json` files under `docs/results/` and the "
            "speed records under `benchmarks/results/` (do not edit by hand); each table names the command and date "
            "of its numbers, and links the per-suite page with the full report (its commit, every configuration, "
            "failed worlds, all plots). Depth RMSE is pooled over every frame of every run (the paper's Tables 1 and 2); "
            "`gt` and `vio` name the camera pose the stack was given. The paper's own numbers, for comparison: "
            f"Table 1 full TRADE {gt} m with ground-truth pose and {vio} m with VIO ({' / '.join(paper)}).", ""]


def render_summary(sections: Sequence[Section]) -> str:
    """docs/results.md: the intro, one section per headline question, speed, and the list of full reports."""
    lines = render_intro()
    for headline in HEADLINES:
        lines += render_headline(headline)
    lines += render_speed()
    lines += ["## Full reports", ""] + [f"- [{s.title}](results/{s.page}.md)" for s in sections]
    return "\n".join(lines).rstrip() + "\n"


def render() -> dict[Path, str]:
    """Every generated page by its path: the per-suite pages with a committed run, and the summary."""
    sections = [s for s in SECTIONS if s.present()]
    pages = {s.path: render_section(s) for s in sections}
    return pages | {DOC: render_summary(sections)}


def stale_pages(pages: dict[Path, str]) -> list[Path]:
    """The pages whose file is missing or differs from its render."""
    return [path for path, text in pages.items() if not path.is_file() or path.read_text() != text]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when any generated page differs from a render")
    args = parser.parse_args(argv)
    pages = render()
    if args.check:
        stale = stale_pages(pages)
        for path in stale:
            print(f"{path} is stale: run python scripts/render_results_doc.py")
        print(f"{len(pages) - len(stale)} of {len(pages)} results pages current")
        return int(bool(stale))
    for path, text in pages.items():
        path.write_text(text)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
