"""`trade-bench`: parse and validate the command line (every argument before any episode runs),
run the chosen suite or grid, and write results.json, results.md, plots and optionally a video.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from trade_gym.bench import depth_strips, plots, reference, report
from trade_gym.bench.executors import (BACKENDS, DEFAULT_RAY_ADDRESS, RAY_LOCAL, BackendUnavailable, Executor,
                                       LocalExecutor, RayExecutor, check_ray_address)
from trade_gym.bench.policies import POLICY_NAMES, available_policies, learned_unavailable_reason
from trade_gym.bench.results import (SERIES_FILE, build_document, collect_meta, load_results, load_schema,
                                     to_json_safe, write_json, write_series)
from trade_gym.bench.runner import RunResult, run_all, run_spec
from trade_gym.bench.splits import EVALUATION, TRAINING
from trade_gym.bench.suites import (BOOL_SWITCHES, EVALUATION_SUITES, NAMED_AXES, SUITE_JOBS, SUITES, RunSpec,
                                    Selection, expand_suite, named_axis_kwargs)
from trade_gym.bench.summary import summarise
from trade_gym.cli_args import OneLineParser, UsageError, parse_switch
from trade_gym.config import PERCEPTION_MODES, POSE_SOURCES, SCENE_NAMES, EnvConfig

PROG = "trade-bench"
EXIT_USAGE, EXIT_FAILED = 2, 1
DEFAULT_CUSTOM_JOBS = 1
REFERENCE_SUITE = "quick"  # the suite the regression reference records
MIN_STEPS, MIN_CAMERA_PX, MIN_JOBS = 1, 16, 1  # EnvConfig's camera_size floor is 16 px


# --suite's help: each suite and its duration on 2 cores
SUITE_HELP = ("quick (make demo, ~1-3 min), paper (the paper's "
              "tables on its development worlds, ~1 h on 2 cores), unseen (the paper's protocol on the 20 "
              "evaluation worlds per scene, ~1.5 h), tuning (the unseen grid on 20 development worlds, to tune "
              "on), latency (full TRADE, scripted and learned followers, every scene, fixed perception latency "
              "0-400 ms, 30 runs, ~15 min), breadth (every decoy tier x target motion x appearance, scripted and "
              "learned, TRADE and DCF, 5 evaluation worlds per scene, 1080 runs, ~2.6 h with --jobs 2), breadth-tuning "
              "(the breadth grid on 5 training worlds per scene, to find failures and tune on), unseen-depth "
              "(the depth failure finder: ground depth on 40 training and the 20 evaluation worlds per scene, "
              "720 runs; a strip of frames per failed world), real-flight (the paper's onboard setup: thermal camera at "
              "45 deg, light stack, waypoint follower, vio pose, TRADE and DCF at night, the morning crossover and "
              "by day on the 20 evaluation worlds per scene, 360 runs, ~1.5 h with --jobs 2), real-flight-tuning (the "
              "real-flight grid on 10 training worlds per scene, to tune on), thermal (full TRADE on the thermal camera, "
              "scripted, gt pose, at night, the crossover and by day, every evaluation world, and the light stack's "
              "ground depth at night and by day in desert and mountain, 260 runs, ~45 min with --jobs 2), "
              "thermal-tuning (the thermal grid on the tuning suite's development worlds), full "
              "(paper tables at full length plus all followers, hours)")


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog=PROG, description="Score follower policies and perception variants on TradeFollow-v0. "
                "With --suite, --scenes/--policies/--perceptions/--pose-sources/--ablation/--tables filter the "
                "suite and --seeds/--steps/--camera-size override it; without, they define one grid.")
    p.add_argument("--suite", choices=tuple(SUITES), help=SUITE_HELP)
    p.add_argument("--tables", nargs="+", metavar="GROUP", help="groups of the suite to run (see --list); with "
                   "--report, the groups of the earlier run to render (and --scenes its scenes)")
    p.add_argument("--scenes", nargs="+", choices=SCENE_NAMES)
    p.add_argument("--policies", nargs="+", metavar="POLICY", help=f"any of {', '.join(POLICY_NAMES)}")
    p.add_argument("--perceptions", nargs="+", choices=PERCEPTION_MODES)
    p.add_argument("--pose-sources", nargs="+", choices=POSE_SOURCES)
    p.add_argument("--ablation", action="append", default=[], metavar="SWITCH=VALUE",
                   help=f"env switch ({', '.join(BOOL_SWITCHES)}) = true|false|both, or a named axis = one or more of "
                   f"its names, comma-separated ({'; '.join(f'{n}: ' + '|'.join(a.names) for n, a in NAMED_AXES.items())}"
                   "; the real-flight suite's); repeatable")
    p.add_argument("--seeds", nargs=2, type=int, metavar=("FIRST", "LAST"), help="seed range, inclusive")
    p.add_argument("--steps", type=int, help="episode length [frames at 30 Hz]")
    p.add_argument("--camera-size", type=int, help="camera image side [px]")
    p.add_argument("--jobs", type=int, help="worker processes (default: the suite's, or 1); with --backend ray, "
                   "only with --ray-address local: the CPUs of its one-node cluster (default: all cores)")
    p.add_argument("--backend", choices=BACKENDS, default="local", help="local: --jobs processes on this machine "
                   "(default); ray: one task per run on a Ray cluster (docs/cluster.md)")
    p.add_argument("--ray-address", metavar="ADDR", help="with --backend ray: auto (default: the cluster this "
                   "machine joined with `ray start`), local (start a one-node cluster) or ray://HOST:PORT")
    p.add_argument("--out", type=Path, help="output folder (created; its parent must exist)")
    p.add_argument("--record", type=Path, metavar="DIR", help="also write every run as a recorded sequence, "
                   "DIR/<run id>/episode_0000/ (docs/sequence_format.md; replay with trade-replay); the folder is "
                   "created, no run's folder may exist yet")
    p.add_argument("--video", action="store_true", help="also write a video of the first run (flown again "
                   "with rendering on; mp4, or GIF without an mp4 encoder)")
    p.add_argument("--list", action="store_true", help="print the runs and exit without running them")
    p.add_argument("--report", type=Path, metavar="RESULTS_JSON", help="run nothing: render results.md and the "
                   "plots of an earlier run's results.json (and its series.npz, when beside it) into --out")
    p.add_argument("--write-reference", nargs="?", const=reference.reference_path(), type=Path, metavar="PATH",
                   help="the whole quick suite only, from a clean git tree (its commit is recorded): write its "
                   "metrics as the regression reference")
    p.add_argument("--check-reference", nargs="?", const=reference.reference_path(), type=Path, metavar="PATH",
                   help="quick suite (filters allowed, no overrides): compare every run with the regression "
                   "reference; exit 1 on a change beyond float drift, better or worse, or on a missing run")
    return p


def _selection(args: argparse.Namespace) -> Selection:
    if args.policies:
        for name in args.policies:
            if name not in POLICY_NAMES:
                raise UsageError(f"unknown policy {name!r} (choose from {', '.join(POLICY_NAMES)})")
        if "learned" in args.policies and (reason := learned_unavailable_reason()) is not None:
            raise UsageError(f"policy 'learned' is not available: {reason}")
    switches = [_ablation(item) for item in args.ablation]
    if args.seeds is not None and not 0 <= args.seeds[0] <= args.seeds[1]:
        raise UsageError(f"--seeds FIRST LAST needs 0 <= FIRST <= LAST, got {args.seeds[0]} {args.seeds[1]}")
    minimums = (("--steps", args.steps, MIN_STEPS), ("--camera-size", args.camera_size, MIN_CAMERA_PX),
                ("--jobs", args.jobs, MIN_JOBS))
    for flag, value, low in minimums:
        if value is not None and value < low:
            raise UsageError(f"{flag} must be >= {low}, got {value}")
    if args.tables is not None:
        if args.suite is None:
            raise UsageError("--tables needs --suite")
        names = [g.name for g in SUITES[args.suite]]
        if unknown := [t for t in args.tables if t not in names]:
            raise UsageError(f"suite {args.suite} has no group {unknown[0]!r} (choose from {', '.join(names)})")
    return Selection(_tuple(args.scenes), _tuple(args.policies), _tuple(args.perceptions), _tuple(args.pose_sources),
                     tuple(switches), _tuple(args.tables), None if args.seeds is None else tuple(args.seeds),
                     args.steps, args.camera_size)


def _ablation(item: str) -> tuple[str, tuple[Any, ...]]:
    """`--ablation NAME=VALUE`: a bool switch (`parse_switch`), or a named axis (`NAMED_AXES`) with one or more of
    its names, comma-separated; a UsageError naming the item otherwise."""
    name, _, value = item.partition("=")
    axis = NAMED_AXES.get(name)
    if axis is None:
        return parse_switch(item, (*BOOL_SWITCHES, *NAMED_AXES), allow_both=True)
    names = tuple(dict.fromkeys(value.split(",")))
    if unknown := [n for n in names if n not in axis.names]:
        raise UsageError(f"--ablation {item!r}: {name} takes {', '.join(axis.names)} (comma-separated), "
                         f"got {unknown[0]!r}")
    return name, names


def _listed(spec: RunSpec) -> str:
    """A run's line of --list: its id, length and camera size, and what its named axes resolve to (e.g. the hour)."""
    named = "".join(f", {k}={v:g}" for k, v in named_axis_kwargs(spec.scene, spec.switches).items())
    return f"{spec.run_id} ({spec.steps} steps, {spec.camera_size} px{named})"


def _tuple(values: Sequence[str] | None) -> tuple[str, ...] | None:
    return None if values is None else tuple(dict.fromkeys(values))


def validate_runs(specs: Sequence[RunSpec]) -> None:
    """Build every distinct env configuration (and the stack's configuration) without running it."""
    from trade_gym.perception.trade_stack import pipeline_config

    if not specs:
        raise UsageError("the selection matches no run")
    seen = set()
    for spec in specs:
        kwargs = spec.env_kwargs()
        key = tuple(sorted(kwargs.items()))
        if key in seen:
            continue
        seen.add(key)
        try:
            config = EnvConfig(**kwargs)
            if config.perception != "oracle":
                pipeline_config(config)
        except (TypeError, ValueError) as exc:
            raise UsageError(f"run {spec.config_id}: the env rejects its configuration: {exc}") from None


def check_worlds(suite: str | None, specs: Sequence[RunSpec]) -> None:
    """Evaluation worlds are flown by the evaluation suites only, and those fly nothing else but training worlds."""
    for spec in specs:
        on_evaluation = spec.world_seed in EVALUATION
        if suite in EVALUATION_SUITES and not (on_evaluation or spec.world_seed in TRAINING):
            raise UsageError(f"suite {suite} flies evaluation worlds {EVALUATION.first}..{EVALUATION.last} (and "
                             f"training worlds from {TRAINING.first}) only; run {spec.run_id} is on world "
                             f"{spec.world_seed}")
        if suite not in EVALUATION_SUITES and on_evaluation:
            raise UsageError(f"run {spec.run_id} is on world {spec.world_seed}, an evaluation world "
                             f"({EVALUATION.first}..{EVALUATION.last}); only --suite "
                             f"{' or '.join(EVALUATION_SUITES)} flies those")


def _identity(spec: RunSpec) -> tuple[Any, ...]:
    """What a run's episode depends on: two specs with the same identity fly the same episode."""
    return spec.policy, spec.seed, spec.steps, EnvConfig(**spec.env_kwargs())


def run_once_each(specs: Sequence[RunSpec], executor: Executor,
                  on_done: Callable[[int, int, RunResult], None] | None = None) -> list[RunResult]:
    """Results of `specs` in their order, flying each distinct episode once (groups of a suite may share
    runs, e.g. full TRADE in both the unseen table and its Table 1 rows)."""
    keys = [_identity(spec) for spec in specs]
    index: dict[tuple[Any, ...], int] = {}
    distinct: list[RunSpec] = []
    for spec, key in zip(specs, keys):
        if key not in index:
            index[key] = len(distinct)
            distinct.append(spec)
    flown = run_all(distinct, on_done=on_done, executor=executor)
    return [dataclasses.replace(flown[index[key]], spec=spec) for spec, key in zip(specs, keys)]


def _check_paths(args: argparse.Namespace, selection: Selection) -> None:
    if args.out is None:
        raise UsageError("--out DIR is required")
    if not args.out.parent.is_dir():
        raise UsageError(f"--out {args.out}: parent folder {args.out.parent} does not exist")
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} exists and is not a folder")
    _check_reference_args(args, selection)


def _check_reference_args(args: argparse.Namespace, selection: Selection) -> None:
    """--write-reference: the whole quick suite, from a clean git tree (the reference records its commit).
    --check-reference: the quick suite, filtered or not, but with its own seeds, steps and camera size."""
    if args.write_reference is not None:
        if args.suite != REFERENCE_SUITE or selection != Selection():
            raise UsageError(f"--write-reference needs --suite {REFERENCE_SUITE} without filters or overrides")
        if not args.write_reference.parent.is_dir():
            raise UsageError(f"--write-reference {args.write_reference}: parent folder does not exist")
        try:
            reference.clean_commit()
        except reference.UncleanTree as exc:
            raise UsageError(f"--write-reference: {exc}") from None
    if args.check_reference is not None:
        overrides = [flag for flag, value in (("--seeds", selection.seeds), ("--steps", selection.steps),
                                              ("--camera-size", selection.camera_size)) if value is not None]
        if args.suite != REFERENCE_SUITE or overrides:
            raise UsageError(f"--check-reference needs --suite {REFERENCE_SUITE} without overrides"
                             + (f" (got {' '.join(overrides)})" if overrides else ""))
        if not args.check_reference.is_file():
            raise UsageError(f"--check-reference {args.check_reference}: no such file")


def _check_record(args: argparse.Namespace, specs: Sequence[RunSpec]) -> None:
    """--record DIR: its parent exists, and no run's sequence folder is there yet (so nothing is overwritten)."""
    root: Path | None = args.record
    if root is None:
        return
    if not root.parent.is_dir():
        raise UsageError(f"--record {root}: parent folder {root.parent} does not exist")
    if root.exists() and not root.is_dir():
        raise UsageError(f"--record {root} exists and is not a folder")
    if taken := next((root / s.run_id for s in specs if (root / s.run_id).exists()), None):
        raise UsageError(f"--record {root}: {taken} exists already; record into another folder")


def _check_backend(args: argparse.Namespace) -> None:
    """--ray-address only with --backend ray (resolved to its default there); --jobs only where it applies."""
    if args.backend != "ray":
        if args.ray_address is not None:
            raise UsageError(f"--ray-address {args.ray_address} needs --backend ray")
        return
    args.ray_address = args.ray_address or DEFAULT_RAY_ADDRESS
    try:
        check_ray_address(args.ray_address)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.jobs is not None and args.ray_address != RAY_LOCAL:
        raise UsageError(f"--jobs {args.jobs} with --backend ray needs --ray-address {RAY_LOCAL} "
                         f"(a cluster runs one run per CPU)")


def _executor(args: argparse.Namespace) -> Executor:
    """The backend's executor; a Ray cluster is connected (or started) here, before any episode runs."""
    task = run_spec if args.record is None else functools.partial(run_spec, record_root=args.record.resolve())
    if args.backend == "local":
        return LocalExecutor(args.jobs or SUITE_JOBS.get(args.suite or "", DEFAULT_CUSTOM_JOBS), task=task)
    try:
        executor = RayExecutor(args.ray_address, num_cpus=args.jobs, task=task)
        executor.connect()
    except BackendUnavailable as exc:
        raise UsageError(str(exc)) from None
    return executor


def _progress(start: float) -> Callable[[int, int, RunResult], None]:
    tty = sys.stderr.isatty()

    def show(done: int, total: int, result: RunResult) -> None:
        elapsed = time.perf_counter() - start
        eta = elapsed / done * (total - done)
        status = "FAILED" if result.error else f"{result.metrics['steps']} steps"
        line = (f"[{done:>{len(str(total))}}/{total}] {100 * done // total:3d}% {elapsed:6.1f} s, eta {eta:5.0f} s  "
                f"{result.spec.run_id} ({status})")
        sys.stderr.write(("\r\033[K" if tty else "") + line + ("" if tty and done < total else "\n"))
        sys.stderr.flush()
    return show


VIDEO_PERCEPTION = "trade"


def write_outputs(args: argparse.Namespace, results: list[RunResult], meta: dict[str, Any],
                  strips: bool = True) -> dict:
    """results.json, results.md, the plots, the optional video and (`strips`) a strip of frames for each per-world
    run whose ground depth failed (`trade_gym.bench.depth_strips`, flown again); returns the JSON document."""
    out: Path = args.out
    summary = summarise(results)
    written = []
    for group in dict.fromkeys(r.spec.group for r in results):
        runs = [r for r in results if r.spec.group == group]
        written += plots.plot_group(runs, group, runs[0].spec.depth_kind, out)
    written += plots.plot_suite(results, out)
    if strips:
        written += depth_strips.write_strips(results, out)
    video = None
    flown = [r for r in results if r.error is None]
    # the video shows the first run with the TRADE stack (its overlays), else the first run at all
    shown = next((r for r in flown if r.spec.perception == VIDEO_PERCEPTION), flown[0] if flown else None)
    if args.video and shown is not None:
        from trade_gym.bench.video import record_video

        video = record_video(shown.spec, out / "video").name
    names = [p.relative_to(out).as_posix() for p in written]
    document = build_document(results, summary, meta, names, video)
    titles = {g.name: g.title for g in SUITES.get(meta["suite"] or "", ())}
    failures = [f"{r.spec.run_id}: {r.error}" for r in results if r.error]
    markdown = report.render_markdown(summary, meta, titles, failures, names, results)
    (out / "results.md").write_text(markdown)
    print(report.headline(markdown))  # the score tables on stdout; progress and errors go to stderr
    write_json(out / "results.json", document)
    if any(r.series is not None for r in results):
        write_series(out / SERIES_FILE, results)
    _validate_schema(to_json_safe(document))
    return document


def _validate_schema(document: dict) -> None:
    try:
        import jsonschema  # test extra; results are still written without it
    except ImportError:
        return
    jsonschema.validate(document, load_schema())


def render_report(args: argparse.Namespace) -> int:
    """--report: the outputs of an earlier run rendered again (with its own meta: commit, date, machine)."""
    source = args.report / "results.json" if args.report.is_dir() else args.report
    if not source.is_file():
        raise UsageError(f"--report {args.report}: no results.json there")
    if args.out is None:
        raise UsageError("--out DIR is required")
    if args.out.resolve() == source.parent.resolve():
        raise UsageError(f"--out {args.out} is the folder of --report; render into another one")
    if not args.out.parent.is_dir():
        raise UsageError(f"--out {args.out}: parent folder {args.out.parent} does not exist")
    try:
        results, meta = load_results(source)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UsageError(f"--report {source}: not a trade-bench results.json ({type(exc).__name__}: {exc})") from None
    if args.tables is not None:  # render only these groups of the run
        present = list(dict.fromkeys(r.spec.group for r in results))
        if unknown := [t for t in args.tables if t not in present]:
            raise UsageError(f"--tables {' '.join(unknown)}: not in {source} (its groups: {', '.join(present)})")
        results = [r for r in results if r.spec.group in args.tables]
    if args.scenes is not None:  # ... and only these scenes
        present = sorted({r.spec.scene for r in results})
        if unknown := [s for s in args.scenes if s not in present]:
            raise UsageError(f"--scenes {' '.join(unknown)}: not in {source} (its scenes: {', '.join(present)})")
        results = [r for r in results if r.spec.scene in args.scenes]
    args.out.mkdir(exist_ok=True)
    write_outputs(args, results, meta, strips=False)
    print(f"{len(results)} runs of {source} -> {args.out / 'results.md'}")
    return 0


def _reference_steps(args: argparse.Namespace, results: list[RunResult], filtered: bool) -> int:
    """--write-reference and --check-reference after the runs; their exit status (0 when fine or not asked)."""
    status = 0
    if args.write_reference is not None:
        if any(r.error for r in results):
            print(f"{PROG}: reference not written: some runs failed", file=sys.stderr)
        else:
            try:
                reference.write_reference(results, args.write_reference)
                print(f"wrote reference {args.write_reference}", file=sys.stderr)
            except (reference.UncleanTree, reference.OffStack) as exc:  # the tree changed while the suite ran
                print(f"{PROG}: error: reference not written: {exc}", file=sys.stderr)
                status = EXIT_USAGE
    if args.check_reference is not None:
        check = reference.check_against_reference(results, reference.load_reference(args.check_reference), filtered)
        print(check.summary_line(), file=sys.stderr)
        for note in (check.simd_note, check.stack_note):
            if note is not None:
                print(note, file=sys.stderr)
        for line in check.path_dependent:
            print(f"  expected on these SIMD paths: {line}", file=sys.stderr)
        for line in check.problems:
            print(f"  {line}", file=sys.stderr)
        if check.problems:
            print(f"  a change either way fails; if intended, re-record: {reference.REGENERATE_COMMAND}",
                  file=sys.stderr)
            status = status or EXIT_FAILED
    return status


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
        if args.report is not None:
            return render_report(args)
        selection = _selection(args)
        _check_backend(args)
        specs = expand_suite(args.suite, selection, available_policies())
        validate_runs(specs)
        check_worlds(args.suite, specs)
        if args.list:
            print("\n".join(_listed(s) for s in specs))
            return 0
        _check_paths(args, selection)
        _check_record(args, specs)
        executor = _executor(args)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    jobs = executor.workers()
    args.out.mkdir(exist_ok=True)
    start = time.perf_counter()
    try:
        results = run_once_each(specs, executor, _progress(start))
    finally:
        executor.close()
    wall_s = time.perf_counter() - start
    write_outputs(args, results, collect_meta(args.suite, argv, jobs, len(results), wall_s, args.backend,
                                              args.ray_address, [r.spec.switch_value("renderer") for r in results]))
    status = 0
    if failed := [r for r in results if r.error]:
        print(f"{PROG}: {len(failed)} of {len(results)} runs failed (see results.md)", file=sys.stderr)
        status = EXIT_FAILED
    status = _reference_steps(args, results, selection != Selection()) or status
    if args.record is not None:
        print(f"sequences of the runs recorded under {args.record} (replay: trade-replay SEQUENCE --out DIR)",
              file=sys.stderr)
    print(f"{len(results)} runs in {wall_s:.1f} s -> {args.out / 'results.md'}")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
