"""``python -m st_sim benchmark`` (a policy through the suite) and ``python -m st_sim leaderboard`` (results side by
side).

    python -m st_sim benchmark --policy mypkg.policy:MyPolicy [--suite val|test] [--episodes N] \\
        [--scenarios NAME ...] [--predictor singular] [--record failures] [--trust-policy-file] --out DIR
    python -m st_sim leaderboard DIR [DIR ...] [--out board.md] [--chart board.png] [--no-baselines] \\
        [--common-scenarios]
    python -m st_sim leaderboard --paired DIR_A DIR_B [--scenarios PATTERN ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from replays.atomic import write_text_atomic
from st_sim.apps.navigation.episode_recording import RECORD_CHOICES
from st_sim.apps.navigation.policies import SPEC_HELP, TRUST_HELP
from st_sim.apps.navigation.predictors import predictor_argument
from st_sim.command_line import CliError, add_grid_arguments, check_writable, positive_int
from st_sim.perception import SENSING_LEVELS
from st_sim.sim.robot import ROBOTS


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``benchmark`` and ``leaderboard`` subcommands."""
    bench = subparsers.add_parser("benchmark", help="navigation benchmark: a policy through the suite's scenarios on "
                                                    "its published seeds, the field's metrics per episode")
    bench.add_argument("--policy", default=None, help=f"the policy (required unless --list): {SPEC_HELP}")
    bench.add_argument("--trust-policy-file", action="store_true", help=TRUST_HELP)
    bench.add_argument("--suite", choices=["val", "test"], default="test", dest="split",
                       help="seed list: val to tune on, test for the figures you report (default: test)")
    bench.add_argument("--suite-file", default=None, metavar="PATH",
                       help="a suite file of your own (default: the shipped suite)")
    bench.add_argument("--episodes", type=positive_int, default=None,
                       help="episodes per scenario, the first N seeds of the list (default: the suite's, 100)")
    bench.add_argument("--scenarios", nargs="+", default=None, metavar="NAME",
                       help="run only these scenarios (default: all; `--list` names them)")
    bench.add_argument("--predictor", type=predictor_argument, default="singular",
                       help="forecasts in the observation: singular, cvm, cvm-s, linear, a plug-in "
                            "package.module:name, or none (no forecasts: the fastest for a policy that does not read "
                            "them) (default: singular)")
    bench.add_argument("--out", default=None, metavar="DIR", help="output folder (required unless --list)")
    bench.add_argument("--list", action="store_true", help="print the suite's scenarios and exit")
    bench.add_argument("--record", choices=list(RECORD_CHOICES), default="none",
                       help="write a Rerun recording of these episodes into DIR/recordings/<scenario>/<episode>.rrd: "
                            "failures (every episode that did not reach the goal), all, or none (default: none)")
    add_grid_arguments(bench)
    bench.add_argument("--robot", choices=list(ROBOTS), default="holonomic",
                       help="the robot of every scenario (its kind with the documented default limits, docs: The "
                       "robot); each kind is a track of its own on the leaderboard")
    bench.add_argument("--sensing", choices=list(SENSING_LEVELS), default="oracle",
                       help="what the robot senses in every scenario (docs: What the robot senses): oracle (every "
                       "pedestrian's exact past), or a sensor and a tracker; each level is a track of its own")
    bench.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    bench.add_argument("--quiet", action="store_true", help="no progress bar")

    board = subparsers.add_parser("leaderboard", help="benchmark results side by side: a table per metric group, "
                                                      "outcomes and success per scenario, a chart; or two runs "
                                                      "paired episode by episode (--paired)")
    board.add_argument("results", nargs="*", metavar="DIR",
                       help="benchmark output folders (from anyone: each is read within fixed caps, checked field by "
                            "field, and its figures computed again from its episodes)")
    board.add_argument("--paired", nargs=2, default=None, metavar=("A", "B"),
                       help="instead of the tables: two runs on the same episodes (benchmark folders, or navigate "
                            "--json files) paired, successes and at-fault collisions with one-sided exact McNemar "
                            "tests both ways")
    board.add_argument("--scenarios", nargs="+", default=["*"], metavar="PATTERN",
                       help="--paired: pool only the scenarios matching these glob patterns (default: all)")
    board.add_argument("--common-scenarios", action="store_true",
                       help="pool every result over the scenarios they all ran (default: refuse results over "
                            "different scenario sets, whose pooled figures do not compare)")
    board.add_argument("--no-baselines", action="store_true",
                       help="leave out the shipped planners' committed results (default: include those measured "
                            "on the same episodes: suite version and content, version of the metrics, split and "
                            "episode count)")
    board.add_argument("--ran-on", action="store_true",
                       help="also a table of where each result ran: STCrowd's commit, package versions, CPU and SIMD "
                            "levels (docs: Reproducing a result)")
    board.add_argument("--out", default=None, metavar="FILE", help="also write the tables to this markdown file")
    board.add_argument("--chart", default=None, metavar="PNG", help="also draw success against at-fault collisions")


def run_benchmark_command(args: argparse.Namespace) -> int:
    """Run (or resume) the benchmark, print its grouped summary; exit code 0."""
    from envs.suite import load_suite
    from st_sim.apps.navigation.benchmark import BenchmarkRun, run_benchmark
    from st_sim.apps.navigation.leaderboard import markdown

    if args.list:
        suite = load_suite(args.suite_file)
        print(f"suite {suite.name} {suite.version}: {len(suite.scenarios)} scenarios, {suite.episodes} episodes "
              f"each by default; seeds: " + ", ".join(f"{k} {len(v)}" for k, v in suite.seeds.items()))
        for scenario in suite.scenarios:
            print(f"  {scenario.name:<18} {scenario.env} {scenario.env_kwargs or ''}  {scenario.description}")
        return 0
    if args.policy is None:
        raise CliError(f"--policy is required (unless --list): {SPEC_HELP}")
    if args.out is None:
        raise CliError("--out DIR is required: the folder that keeps the episodes (and resumes them)")
    check_writable(Path(args.out))
    run = BenchmarkRun(policy=args.policy, out=args.out, predictor=args.predictor, split=args.split,
                       episodes=args.episodes, scenarios=None if args.scenarios is None else tuple(args.scenarios),
                       suite_file=args.suite_file, data_root=args.data_root, record=args.record,
                       trust_policy_file=args.trust_policy_file, robot=args.robot, sensing=args.sensing)
    summary = run_benchmark(run, executor=args.executor, workers=args.workers, address=args.ray_address,
                            progress=not args.quiet)
    print(markdown([summary]))
    print(f"wrote {args.out}/episodes.jsonl and {args.out}/summary.json; compare: python -m st_sim leaderboard "
          f"{args.out}")
    return 0


def run_leaderboard_command(args: argparse.Namespace) -> int:
    """Print the tables (and write them, and the chart), or the paired comparison; exit code 0."""
    from st_sim.apps.navigation.leaderboard import baseline_results, chart, comparable, label, markdown, ran_on_table
    from st_sim.apps.navigation.result_folder import load_result

    if args.paired:
        if args.results:
            raise CliError("--paired A B compares two runs; give no other folder")
        from st_sim.apps.navigation.paired import paired_text

        print(paired_text(*args.paired, tuple(args.scenarios)))
        return 0
    if not args.results:
        raise CliError("give benchmark output folders (DIR ...), or --paired A B")
    results = [load_result(folder) for folder in args.results]
    note = None
    if not args.no_baselines:
        own = {label(result) for result in results}
        baselines, note = baseline_results(results[0], common_scenarios=args.common_scenarios)
        results += [r for r in baselines if label(r) not in own]
    results = comparable(results, args.common_scenarios)
    text = markdown(results, note) + ("\n" + ran_on_table(results) if args.ran_on else "")
    print(text)
    if args.out:
        write_text_atomic(Path(args.out), text)
        print(f"wrote {args.out}")
    if args.chart:
        print(f"wrote {chart(results, args.chart)}")
    return 0
