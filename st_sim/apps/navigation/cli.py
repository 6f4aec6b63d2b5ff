"""``python -m st_sim navigate``: run a policy with a predictor through seeded episodes and print the metrics.

    python -m st_sim navigate --env STCrowd-SimCrossing-v1 --policy mpc --predictor singular \\
        --episodes 100 --seed 0 --json nav.json [--rerun DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from replays import strict_json
from replays.atomic import write_text_atomic
from st_sim.apps.navigation.planners import READS_POLICY_FILE
from st_sim.apps.navigation.policies import SPEC_HELP, TRUST_HELP, check_policy_spec
from st_sim.apps.navigation.predictors import predictor_argument
from st_sim.perception import SENSING_LEVELS
from st_sim.sim.robot import ROBOTS

SEE_EGO_CHOICES = {"yes": True, "no": False, "default": None}


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``navigate`` subcommand."""
    nav = subparsers.add_parser("navigate", help="navigation benchmark: a planner with a predictor, metrics with "
                                                 "95 %% confidence intervals")
    nav.add_argument("--env", default="STCrowd-SimCrossing-v1", help="env id (default: STCrowd-SimCrossing-v1)")
    nav.add_argument("--policy", default="mpc", help=f"the policy: {SPEC_HELP} (default: mpc)")
    nav.add_argument("--trust-policy-file", action="store_true", help=TRUST_HELP)
    nav.add_argument("--predictor", type=predictor_argument, default="singular",
                     help="predictor in the observation: none (pedestrians assumed to stand still), cvm, cvm-s, "
                          "singular, or a plug-in package.module:name, called with task=stochastic, the replay's "
                          "scene (None in a simulated env), its train/val windows and --data-root "
                          "(default: singular)")
    nav.add_argument("--episodes", type=int, default=100, help="episodes (default: 100)")
    nav.add_argument("--seed", type=int, default=0, help="episode i resets with seed + i (default: 0)")
    nav.add_argument("--pedestrians-see-ego", choices=list(SEE_EGO_CHOICES), default="default",
                     help="simulated envs that offer it: pedestrians steer around the robot (yes) or not (no); "
                          "default: the env's own setting")
    nav.add_argument("--pedestrians", choices=["log", "reactive"], default=None,
                     help="replays: log = the recording exactly, reactive = recorded pedestrians step round the "
                          "robot (default: log)")
    nav.add_argument("--sensor-range", type=float, default=None,
                     help="the robot senses, and the env forecasts, only the pedestrians within this many metres "
                          "(default: inf, everyone)")
    nav.add_argument("--policy-file", default=None, metavar="PATH",
                     help=f"with --policy {', '.join(READS_POLICY_FILE)}: a trained policy (train_ppo's policy.pt) "
                          "instead of the shipped one")
    nav.add_argument("--json", default=None, help="write settings, per-episode figures and the summary here")
    nav.add_argument("--rerun", default=None, help="write one Rerun recording per episode into this folder")
    nav.add_argument("--robot", choices=list(ROBOTS), default="holonomic",
                     help="the robot's kind, with its documented default limits (docs: The robot)")
    nav.add_argument("--sensing", choices=list(SENSING_LEVELS), default="oracle",
                     help="what the robot senses (docs: What the robot senses; default: oracle)")
    nav.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    nav.add_argument("--quiet", action="store_true", help="no progress bar")
    return nav


def run(args: argparse.Namespace) -> int:
    """Run the episodes, print the metric table, optionally write JSON; exit code 0."""
    from st_sim.apps.navigation.episodes import NavRun, run_navigation
    from st_sim.apps.navigation.report import summary_text

    if args.episodes < 1:
        raise SystemExit("--episodes must be at least 1")
    check_policy_spec(args.policy)
    if args.sensor_range is not None and not args.sensor_range > 0:  # also refuses NaN
        raise SystemExit(f"--sensor-range={args.sensor_range}: expected a distance in metres > 0 (or inf)")
    nav_run = NavRun(env_id=args.env, policy=args.policy, predictor=args.predictor, episodes=args.episodes,
                     seed=args.seed, pedestrians_see_ego=SEE_EGO_CHOICES[args.pedestrians_see_ego],
                     pedestrians=args.pedestrians, sensor_range_m=args.sensor_range,
                     rerun_dir=args.rerun, data_root=args.data_root, policy_file=args.policy_file,
                     trust_policy_file=args.trust_policy_file, robot=args.robot, sensing=args.sensing)
    result = run_navigation(nav_run, progress=not args.quiet)
    print(summary_text(result))
    if args.json:
        write_text_atomic(Path(args.json), strict_json.dumps(result, indent=1))
        print(f"wrote {args.json}")
    if args.rerun:
        print(f"wrote {args.episodes} recording(s) into {args.rerun}/")
    return 0
