"""The benchmark scripts' own argument handling (their measurements are not
tests: see docs/performance.md)."""

from __future__ import annotations

import csv
import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    # (Registered first: a dataclass looks its module up while it is made.)
    sys.modules[name] = mod
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


def _trip(vid: str, arrival: float, time_loss: float) -> str:
    return f'<tripinfo id="{vid}" arrival="{arrival}" duration="10" timeLoss="{time_loss}"/>'


def _seed_dir(root: Path, seed: int, treat_trips: list[str], base_trips: list[str], vehicles: list[tuple[str, float, int]],
              summary: dict[str, int]) -> Path:
    """A seed's two runs as the study reads them: the treatment's summary,
    vehicles.csv (id, mean abs lateral error, missed exits) and trip info,
    and the baseline's trip info."""
    d = root / f"seed{seed}"
    for kind, trips in (("treatment", treat_trips), ("baseline", base_trips)):
        (d / kind / "sumo").mkdir(parents=True)
        (d / kind / "sumo" / "tripinfo.xml").write_text("<tripinfos>" + "".join(trips) + "</tripinfos>")
    full = {"collisions_with_controlled": 0, "red_light_crossings_sumo": 0, "teleports_controlled": 0,
            "placement_faults": 0, "emergency_brakings": 0, **summary}
    (d / "treatment" / "summary.json").write_text(json.dumps(full))
    rows = "".join(f"{vid},{lat},{missed}\n" for vid, lat, missed in vehicles)
    (d / "treatment" / "vehicles.csv").write_text("id,lateral_error_mean_abs_m,missed_exits\n" + rows)
    return d


def test_study_pools_the_acceptance_figures_over_seeds(tmp_path):
    """Arrivals count a controlled vehicle only at its own destination (a
    missed exit is not one), against the same vehicles under plain SUMO; the
    background time loss is the mean over every background vehicle in both
    runs of every seed; the lateral error the mean of the vehicles' own."""
    s = _script("study_real_scenarios")
    d0 = _seed_dir(tmp_path, 0,
                   [_trip("c1", 50, 5), _trip("c2", 60, 5), _trip("c3", -1, 9), _trip("b1", 40, 12), _trip("b2", 45, 8),
                    _trip("only_t", 30, 100)],
                   [_trip("c1", 50, 1), _trip("c2", 60, 1), _trip("c3", 70, 1), _trip("b1", 40, 10), _trip("b2", 45, 6)],
                   [("c1", 0.02, 0), ("c2", 0.04, 1), ("c3", 0.06, 0)],
                   {"collisions_with_controlled": 2, "red_light_crossings_sumo": 1, "emergency_brakings": 3})
    d1 = _seed_dir(tmp_path, 1,
                   [_trip("c9", 20, 2), _trip("b9", 20, 30)],
                   [_trip("c9", 20, 2), _trip("b9", 20, 20)],
                   [("c9", 0.08, 0)], {"teleports_controlled": 1})
    f0 = s.seed_figures(d0)
    # c1 arrived; c2 arrived elsewhere (missed exit); c3 did not arrive. Plain: all three.
    assert (f0["arrived"], f0["arrived_plain"], f0["missed_exits"], f0["controlled"]) == (1, 3, 1, 3)
    # Background in both runs: b1, b2 (only_t is not in the baseline).
    assert (f0["background"], f0["time_loss"], f0["time_loss_plain"]) == (2, 20.0, 16.0)
    p = s.pool({0: f0, 1: s.seed_figures(d1)})
    fig = p.figures()
    assert fig["arrivals_ratio"] == pytest.approx(2 / 4)
    assert fig["background_time_loss_change"] == pytest.approx((20 + 30) / (16 + 20) - 1)
    assert fig["lateral_error_mean_abs_m"] == pytest.approx((0.02 + 0.04 + 0.06 + 0.08) / 4)
    assert (fig["collisions_with_controlled"], fig["red_light_crossings"], fig["teleports_controlled"],
            fig["emergency_brakings"]) == (2, 1, 1, 3)
    text = s.table({"x": p})
    assert "| collisions with a controlled vehicle | 0 | 2 (**not met**) |" in text
    assert "| 0.500 (**not met**) |" in text and "+38.9 % (**not met**)" in text and "0.050 (met)" in text
    assert "| 0-1; 4 |" in text


def test_study_reports_a_failed_run_and_leaves_its_seed_out(tmp_path, monkeypatch, capsys):
    s = _script("study_real_scenarios")
    monkeypatch.setattr(s, "_run", lambda kind, scen, seed, out, args: (kind == "baseline", "SUMO crashed"))
    code = s.main(["--scenario", "ring_single_lane", "--seeds", "2", "--jobs", "1", "--out", str(tmp_path)])
    assert code == 1
    text = (tmp_path / "study.md").read_text()
    assert "ring_single_lane seed 0 left out: treatment: SUMO crashed" in text
    assert "ring_single_lane seed 1 left out" in text and "none; 0" in text
    assert "FAILED: SUMO crashed" in capsys.readouterr().out


@pytest.mark.parametrize("bad", [["--seeds", "0"], ["--jobs", "0"], ["--fraction", "1.5"], ["--end", "-1"],
                                 ["--", "--sumo-args", "--scale 2"], ["--scenario", "/no/such/file.sumocfg"]])
def test_study_rejects_bad_options(bad, tmp_path):
    s = _script("study_real_scenarios")
    with pytest.raises(SystemExit) as e:
        s.main([*bad, "--out", str(tmp_path)] if bad[0] != "--" else ["--out", str(tmp_path), *bad])
    assert e.value.code == 2


def test_study_runs_a_shipped_scenario_and_reuses_finished_runs(tmp_path):
    """End to end on the shipped ring, 30 s, one seed: both runs made, the
    table, per-seed rows and plot written; run again, the finished runs are
    reused (their outputs untouched)."""
    s = _script("study_real_scenarios")
    argv = ["--scenario", "ring_single_lane", "--end", "30", "--seeds", "1", "--jobs", "2", "--out", str(tmp_path)]
    assert s.main(argv) == 0
    seed = tmp_path / "ring_single_lane" / "seed0"
    assert (seed / "baseline" / s.DONE).exists() and (seed / "treatment" / s.DONE).exists()
    text = (tmp_path / "study.md").read_text()
    assert "| | target | ring_single_lane |" in text and "| 0; " in text
    with open(tmp_path / "per_seed.csv") as f:
        assert [r["seed"] for r in csv.DictReader(f)] == ["0"]
    assert (tmp_path / "study.png").stat().st_size > 0
    summary = seed / "treatment" / "summary.json"
    before = summary.stat().st_mtime_ns
    assert s.main(argv) == 0
    assert summary.stat().st_mtime_ns == before


def test_study_gives_its_sumo_args_to_both_runs(tmp_path, monkeypatch):
    """--sumo-args (e.g. the sublane model) reaches the plain run and the
    blendtrack run of a seed alike (the plain run's code reads it as its
    last argument); given after -- it is refused (only one run would get it)."""
    import argparse
    import shlex
    import subprocess

    s = _script("study_real_scenarios")
    seen = []

    def fake(cmd, **kw):
        seen.append(cmd)
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(s.subprocess, "run", fake)
    args = argparse.Namespace(end=30.0, fraction=0.3, extra=[], sumo_args="--lateral-resolution 0.8")
    for kind in ("baseline", "treatment"):
        assert s._run(kind, "ring_single_lane", 0, tmp_path / kind, args) == (True, "")
    base, treat = seen
    assert "sumo_args=shlex.split(sys.argv[5])" in base[2] and shlex.split(base[-1]) == ["--lateral-resolution", "0.8"]
    assert shlex.split(treat[treat.index("--sumo-args") + 1])[-2:] == ["--lateral-resolution", "0.8"]
