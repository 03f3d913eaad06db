"""Command-line interface: ``blendtrack SUBCOMMAND ...``.

Each subcommand is a function ``_cmd_NAME(args) -> int`` registered in
``_build_parser`` with its own arguments; ``main`` returns its exit code.
Argument errors exit with code 2 and print exactly one line to stderr (no
usage block, no traceback), so scripts and logs show the reason and nothing
else. Errors that blendtrack raises for bad input (``BlendtrackError``: an
unknown track, an unreadable file, an out-of-range value) are argument
errors too.

Subcommands:
- ``version``: print the version.
- ``sim``: one closed-loop run; writes timeseries.csv, metrics.json and plots.
- ``paper``: reproduces the paper's experiments; writes report.md and figures.
- ``sumo``: the SUMO plugin (``sumo run``, ``sumo list``).
- ``compare``: blendtrack against SUMO's own drivers on a scenario, paired by
  vehicle over several seeds; writes report.md, report.html, comparison.csv.
- ``batch``: a parameter sweep from a TOML file, each run in its own worker
  process (local, or on a Dask cluster); resumable; writes results.parquet,
  results.csv and summary.md. Exits with code 1 when a run failed.

Ctrl-C prints one line and exits with code 130.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence

import blendtrack
from blendtrack.cli.batch import add_batch_parser
from blendtrack.cli.common import Parser
from blendtrack.cli.sim import add_paper_parser, add_sim_parser
from blendtrack.cli.sumo import add_compare_parser, add_sumo_parser


def _cmd_version(args: argparse.Namespace) -> int:
    print(blendtrack.__version__)
    return 0


def _build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="blendtrack",
        description="Path tracking with dynamic control point blending.",
    )
    subcommands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    version = subcommands.add_parser("version", help="print the version and exit")
    version.set_defaults(run=_cmd_version)
    add_sim_parser(subcommands)
    add_paper_parser(subcommands)
    add_sumo_parser(subcommands)
    add_compare_parser(subcommands)
    add_batch_parser(subcommands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the CLI on ``argv`` (default: ``sys.argv[1:]``); returns the exit code."""
    args = _build_parser().parse_args(argv)
    # A warning is one line too, saying what happened (no source line).
    command = args.command

    def one_line(message: Warning | str, category: type[Warning], filename: str, lineno: int, line: str | None = None) -> str:
        return f"blendtrack {command}: warning: {message}\n"

    warnings.formatwarning = one_line
    try:
        exit_code: int = args.run(args)
    except blendtrack.BlendtrackError as e:
        message = " ".join(str(e).split())
        print(f"blendtrack {args.command}: error: {message}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"blendtrack {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"blendtrack {args.command}: interrupted", file=sys.stderr)
        return 130
    return exit_code

