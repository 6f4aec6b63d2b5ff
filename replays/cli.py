"""``python -m replays <command>``: fetch a data set's files (ETH/UCY, or CITR with ``--dataset citr``) into a data
root, verify a data root.

Every failure prints one ``error: ...`` line and exits with code 1; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import os
import sys

from replays.data_root import DATASETS, ETH_UCY, data_root, verify_data_root
from replays.errors import DataFormatError, DataRootError
from replays.fetch import FetchError, fetch

USER_ERRORS = (FetchError, DataRootError, DataFormatError, OSError)  # OSError: a folder cannot be written


def run_fetch(args: argparse.Namespace) -> int:
    """Fetch and verify every file; an interrupted run resumes where it stopped."""
    dataset = DATASETS[args.dataset]
    try:
        report = fetch(args.source, args.dest, quiet=args.quiet, dataset=dataset)
    except KeyboardInterrupt:
        if args.debug:
            raise
        print("error: interrupted; run the same command again to resume (finished files are kept)", file=sys.stderr)
        return 1
    for path in report.moved_aside:
        print(f"note: a file with other bytes than the project's sum was in the way; it is kept as {path}",
              file=sys.stderr)
    if not args.quiet:
        print(f"OK: {report.fetched} files fetched, {report.skipped} already present, "
              f"{report.bytes_moved / 1e6:.1f} MB moved, into {report.dest}")
        env_root = os.environ.get(dataset.env_var)
        if env_root and data_root(env_root, check=False) != report.dest:
            print(f"note: ${dataset.env_var}={env_root} takes precedence over {report.dest}; unset it to use this copy")
    return 0


def run_verify(args: argparse.Namespace) -> int:
    """Check every file's SHA-256; print OK or the first bad file."""
    dataset = DATASETS[args.dataset]
    root = data_root(args.root, check=False, dataset=dataset)
    verify_data_root(root, dataset)
    print(f"OK: every file in {root} matches the project's {dataset.title} SHA-256 sums")
    return 0


COMMANDS = {"fetch": run_fetch, "verify": run_verify}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m replays", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", help="show tracebacks instead of one error line (default: off)")
    common.add_argument("--dataset", choices=list(DATASETS), default=ETH_UCY.key,
                        help="eth_ucy: the ETH/UCY benchmark; citr: CITR's pedestrians and vehicle (Yang et al., IV "
                             "2019), which validate the reactive pedestrians (default: eth_ucy)")

    fetch_cmd = commands.add_parser("fetch", parents=[common],
                                    help="download or copy a data set's files and verify their SHA-256")
    fetch_cmd.add_argument("--from", dest="source", metavar="DIR_OR_ARCHIVE_OR_URL", default=None,
                           help="a folder laid out like the data root, a .zip/.tar(.gz) archive of one, or an "
                                "http(s) base URL (default: the public mirrors: for ETH/UCY Social-STGCNN and "
                                "LMTrajectory on GitHub, for CITR its authors' repository at commit b6a9806)")
    fetch_cmd.add_argument("--dest", metavar="DIR", default=None,
                           help="data root to fill (default: ~/.cache/stcrowd/<dataset>)")
    fetch_cmd.add_argument("--quiet", action="store_true", help="no progress bar or summary (default: off)")

    verify = commands.add_parser("verify", parents=[common],
                                 help="check every file of a data root against the project's SHA-256 sums")
    verify.add_argument("--root", metavar="DIR", default=None,
                        help="data root to check (default: $STCROWD_DATA for eth_ucy, $STCROWD_CITR for citr, if "
                             "set, else ~/.cache/stcrowd/<dataset>)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except USER_ERRORS as err:
        if args.debug:
            raise
        print(f"error: {err}", file=sys.stderr)
        return 1
