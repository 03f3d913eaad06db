"""The benchmark scripts' own argument handling (their measurements are not
tests: see docs/performance.md)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_bench_sumo_counts_take_numbers_all_and_percentages():
    b = _script("bench_sumo")
    counts = b.parse_counts("0,10, 10%,all,100%")
    assert counts == [0, 10, 0.1, b.ALL, 1.0]
    assert [b.label(n) for n in counts] == ["0", "10", "10%", "all", "100%"]
    # A percentage is the plugin's own selection (a seeded share), a number the first to depart.
    share = b._options(60.0, 1.0, 0.1)
    assert (share.controlled_fraction, share.max_controlled) == (0.1, None)
    first = b._options(60.0, 1.0, 10)
    assert (first.controlled_fraction, first.max_controlled) == (1.0, 10)
    everyone = b._options(60.0, 1.0, b.ALL)
    assert (everyone.controlled_fraction, everyone.max_controlled) == (1.0, None)
    assert b._options(60.0, 1.0, 0).controlled_fraction == 0.0


@pytest.mark.parametrize("bad", ["x", "-3", "0%", "150%", "ten%", ""])
def test_bench_sumo_counts_reject_what_is_not_a_count(bad):
    b = _script("bench_sumo")
    with pytest.raises(SystemExit, match="--counts"):
        b.parse_counts(f"10,{bad}")
