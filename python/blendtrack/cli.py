"""Command-line interface: ``blendtrack SUBCOMMAND ...``.

Each subcommand is a function ``_cmd_NAME(args) -> int`` registered in
``_build_parser`` with its own arguments; ``main`` returns its exit code.
Argument errors exit with code 2 and print exactly one line to stderr (no
usage block, no traceback), so scripts and logs show the reason and nothing
else.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

import blendtrack


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors; subcommand parsers inherit it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _cmd_version(args: argparse.Namespace) -> int:
    print(blendtrack.__version__)
    return 0


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="blendtrack",
        description="Path tracking with dynamic control point blending.",
    )
    subcommands = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True
    )

    version = subcommands.add_parser("version", help="print the version and exit")
    version.set_defaults(run=_cmd_version)

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the CLI on ``argv`` (default: ``sys.argv[1:]``); returns the exit code."""
    args = _build_parser().parse_args(argv)
    exit_code: int = args.run(args)
    return exit_code


if __name__ == "__main__":
    sys.exit(main())
