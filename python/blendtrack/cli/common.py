"""What the subcommands share: the one-line-error parser, argparse types
for bounded numbers, seeds and alpha, file checks and SIGTERM as Ctrl-C."""

from __future__ import annotations

import argparse
import math
import shlex
from typing import NoReturn


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors; subcommand parsers inherit it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def sumo_args(text: str) -> tuple[str, ...]:
    """``--sumo-args``: the options split as a shell would."""
    try:
        return tuple(shlex.split(text))
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"--sumo-args {text!r}: {e}") from None


def require_file(name: str, kind: str, error: type[Exception]) -> None:
    """Raises ``error`` naming ``name`` and why it cannot be read as a ``kind`` file."""
    from blendtrack.simulation import file_problem

    problem = file_problem(name)
    if problem:
        raise error(f"cannot read {kind} file {name}: {problem}")


def bounded(kind: str, whole: bool, low: float | None, high: float | None, strict: bool = False, bounds: str | None = None):  # type: ignore[no-untyped-def]
    """argparse type: a finite number (a whole one with ``whole``) in
    [low, high] (low excluded with ``strict``); ``bounds`` words the range in
    the error instead of the two separate limits."""

    def parse(text: str) -> float | int:
        try:
            value: float | int = int(text) if whole else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} must be a {'whole number' if whole else 'number'}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{kind} must be finite, got {text!r}")
        below = low is not None and (value <= low if strict else value < low)
        above = high is not None and value > high
        if bounds is not None and (below or above):
            raise argparse.ArgumentTypeError(f"{kind} must be in {bounds}, got {text}")
        if below:
            raise argparse.ArgumentTypeError(f"{kind} must be {'>' if strict else '>='} {low:g}, got {text}")
        if above:
            raise argparse.ArgumentTypeError(f"{kind} must be <= {high:g}, got {text}")
        return value

    parse.__name__ = kind
    return parse


def finite(kind: str, low: float | None = None, strict: bool = False, high: float | None = None):  # type: ignore[no-untyped-def]
    """argparse type: a finite float within bounds."""
    return bounded(kind, False, low, high, strict)


def end_time(text: str) -> float:
    """argparse type of ``--end``: a time after 0 as SUMO reads one
    (seconds, ``H:M:S`` or ``D:H:M:S``: a scenario that begins at
    ``15:0:0`` ends at ``15:05:00``)."""
    from blendtrack.sumo.sumocfg import sumo_seconds

    try:
        value = sumo_seconds(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"end time must be a time (seconds, H:M:S or D:H:M:S), got {text!r}") from None
    checked: float = finite("end time", 0.0, strict=True)(repr(value))
    return checked


def whole(what: str, low: int = 1, high: int | None = None, bounds: str | None = None):  # type: ignore[no-untyped-def]
    """argparse type: a whole number in [low, high]."""
    return bounded(what, True, low, high, bounds=bounds)


#: argparse type of a seed: the core's u64.
seed = whole("seed", 0, 2**64 - 1, bounds="[0, 2**64)")
#: argparse type of compare's --seeds.
seeds = whole("seeds")


def alpha_value(text: str) -> float | str:
    """argparse type of ``--alpha``: a number in [0, 1] or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    value: float = finite("alpha", 0.0, high=1.0)(text)
    return value


def raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt
