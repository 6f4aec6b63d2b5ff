"""What every STCrowd command line shares: one ``error: ...`` line and exit code 1 on failure (``--debug``
shows the traceback instead), argument types that name the flag, and output paths checked before work."""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path


class CliError(RuntimeError):
    """A command cannot run as asked (the message names the flag and what to do)."""


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be at least 1")
    return value


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"{value} must be a finite number >= 0")
    return value


def check_writable(folder: Path) -> None:
    """Fail before any work if files cannot be written into ``folder``: the folder itself if it exists, else the
    nearest folder above it that does (nothing is created, so a run refused later leaves no empty folder behind)."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise CliError(f"{folder}: cannot write there ({existing} is not a folder)")
    try:
        with tempfile.TemporaryFile(dir=existing):  # leaves nothing behind
            pass
    except OSError as err:
        raise CliError(f"{folder}: cannot write there ({err.strerror or err})") from err


def add_grid_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of commands that run a grid of jobs (``st_sim.apps.grid``)."""
    parser.add_argument("--executor", choices=["local", "ray"], default="local",
                        help="local: a process pool on this machine; ray: a Ray cluster (pip install -e \".[ray]\") "
                             "(default: local)")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="parallel jobs, one thread each: the local pool's size, or the CPUs of a Ray started "
                             "here when --ray-address is not given (default: the number of cores)")
    parser.add_argument("--ray-address", default=None,
                        help="ray: cluster address, auto or HOST:PORT (default: start Ray on this machine)")


def add_debug_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--debug", action="store_true", help="show the Python traceback on errors")


def run_guarded(command: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run ``command(args)``; any error becomes one ``error: ...`` line on stderr and exit code 1."""
    try:
        return command(args)
    except KeyboardInterrupt:
        print("error: interrupted; run the same command again to resume (finished work is kept)", file=sys.stderr)
        return 130
    except Exception as err:
        if getattr(args, "debug", False):
            raise
        message = err.args[0] if isinstance(err, KeyError) and err.args else str(err)
        print(f"error: {message or type(err).__name__}", file=sys.stderr)
        return 1
