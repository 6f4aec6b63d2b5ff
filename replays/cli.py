"""``python -m replays <command>``: fetch the ETH/UCY files into a data root, verify a data root."""

from __future__ import annotations

import argparse
import os
import sys

from replays.data_root import DEFAULT_CACHE, ENV_VAR, data_root, verify_data_root
from replays.errors import DataRootError
from replays.fetch import FetchError, fetch


def run_fetch(args: argparse.Namespace) -> int:
    """Fetch and verify every file; an interrupted run resumes where it stopped."""
    try:
        report = fetch(args.source, args.dest, quiet=args.quiet)
    except (FetchError, OSError) as err:  # OSError: the destination cannot be written
        print(f"error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted; run the same command again to resume (finished files are kept)", file=sys.stderr)
        return 1
    if not args.quiet:
        print(f"OK: {report.fetched} files fetched, {report.skipped} already present, "
              f"{report.bytes_moved / 1e6:.1f} MB moved, into {report.dest}")
        env_root = os.environ.get(ENV_VAR)
        if env_root and data_root(env_root, check=False) != report.dest:
            print(f"note: ${ENV_VAR}={env_root} takes precedence over {report.dest}; unset it to use this copy")
    return 0


def run_verify(args: argparse.Namespace) -> int:
    """Check every file's SHA-256; print OK or the first bad file."""
    try:
        root = data_root(args.root, check=False)
        verify_data_root(root)
    except DataRootError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    print(f"OK: every file in {root} matches the project's SHA-256 sums")
    return 0


COMMANDS = {"fetch": run_fetch, "verify": run_verify}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m replays", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    fetch_cmd = commands.add_parser("fetch", help="download or copy the ETH/UCY files and verify their SHA-256")
    fetch_cmd.add_argument("--from", dest="source", metavar="DIR_OR_ARCHIVE_OR_URL", default=None,
                           help="a folder laid out like the data root, a .zip/.tar(.gz) archive of one, or an "
                                "http(s) base URL (default: the public mirrors, Social-STGCNN and LMTrajectory "
                                "on GitHub)")
    fetch_cmd.add_argument("--dest", metavar="DIR", default=str(DEFAULT_CACHE),
                           help=f"data root to fill (default: {DEFAULT_CACHE})")
    fetch_cmd.add_argument("--quiet", action="store_true", help="no progress bar or summary (default: off)")

    verify = commands.add_parser("verify", help="check every file of a data root against the project's SHA-256 sums")
    verify.add_argument("--root", metavar="DIR", default=None,
                        help=f"data root to check (default: ${ENV_VAR} if set, else {DEFAULT_CACHE})")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return COMMANDS[args.command](args)
