"""What every study's command line shares: its arguments, its report folder, its ending.

A study's ``main`` builds its :func:`parser` (run directories, ``--out``, ``--seed``,
``--resamples`` and, unless told not to, ``--first``), makes its output folder with
:func:`report_folder` and ends in :func:`run_report`, which prints the report's path or
the user's mistake in one line, so that every study answers a bad input alike.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from analysis.load import RunDirectoryError
from analysis.stats import Resampling


def report_folder(out: str | Path) -> Path:
    """``out``, created if need be, as a report folder.

    Raises:
        RunDirectoryError: If it exists and is not a folder, or cannot be created.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out}: exists and is not a folder; give a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RunDirectoryError(f"--out {out}: cannot create it ({err.strerror or err})") from None
    return out


def parser(description: str, prog: str | None = None,
           first: bool = True) -> argparse.ArgumentParser:
    """The arguments every report CLI takes: run directories, ``--out``, ``--seed``,
    ``--resamples`` (and ``--first``, unless ``first`` is false)."""
    cli = argparse.ArgumentParser(prog=prog, description=description)
    cli.add_argument("runs", nargs="+", type=Path,
                     help="run directories, or folders holding them (a multirun folder)")
    cli.add_argument("--out", type=Path, required=True, help="report folder (created)")
    cli.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    cli.add_argument("--resamples", type=int, default=2000,
                     help="bootstrap resamples per confidence interval")
    if not first:
        return cli
    cli.add_argument("--first", type=positive, default=None, metavar="N",
                     help="only each run's first N robots (runs of different lengths "
                          "compared over the same robots)")
    return cli


def resampling_of(args: argparse.Namespace) -> Resampling:
    """The resampling a :func:`parser` command line asks for (``--seed``, ``--resamples``)."""
    return Resampling.seeded(args.seed, args.resamples)


def positive(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text}")
    return value


def run_report(write: Callable[[], Path]) -> int:
    """A report CLI's ending: print the written report's path, or the user's mistake.

    Args:
        write: Loads the runs, writes the report and returns its path; raises
            FileNotFoundError or RunDirectoryError on a bad input.

    Returns:
        The exit status: 0, or 2 on a bad input (one ``error:`` line on stderr).
    """
    try:
        report = write()
    except (FileNotFoundError, RunDirectoryError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"report: {report}")
    return 0
