"""`blendtrack batch`: sweep files, executors, failures, SIGKILL and resume.

The batches run as subprocesses of the real CLI (`python -m blendtrack.cli
batch ...`), mostly with short `sim` runs on the built-in test track (each
run is a process of its own, about a second), and one small SUMO sweep.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
import psutil
import pytest

from blendtrack.batch import SweepError, load_sweep

SCENARIOS = Path(__file__).resolve().parents[1] / "sumo_scenarios"

CHILD = "blendtrack.batch._child"


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "blendtrack.cli", *args], capture_output=True, text=True, timeout=timeout, check=False)


def _popen(*args: str) -> subprocess.Popen[str]:
    # A session of its own: the test can kill the batch with everything it started.
    return subprocess.Popen(
        [sys.executable, "-m", "blendtrack.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def _records(out: Path) -> dict[str, dict[str, Any]]:
    return {p.stem: json.loads(p.read_text()) for p in (out / "runs").glob("*.json")}


def _sweep(tmp: Path, text: str, name: str = "sweep.toml") -> Path:
    file = tmp / name
    file.write_text(text)
    return file


SIM_SWEEP = """
kind = "sim"
scenarios = ["test_track"]
seeds = 2
[fixed]
duration_s = 25
noise = "uniform:0.05:0.5"
[grid]
alpha = [0.2, 0.8]
"""


def _processes_under(path: Path) -> list[psutil.Process]:
    """Live processes whose command line mentions ``path`` (run processes, SUMO)."""
    found = []
    for p in psutil.process_iter():
        try:
            if p.status() != psutil.STATUS_ZOMBIE and str(path) in " ".join(p.cmdline()):
                found.append(p)
        except psutil.Error:
            pass
    return found


# ------------------------------------------------------------ sweep files
@pytest.mark.parametrize(
    ("text", "expect"),
    [
        ('kind = "sim"\nscenarios = ["test_track"]\nsede = 2\n', "unknown key 'sede'"),
        ('kind = "simulation"\nscenarios = ["test_track"]\n', "kind: unknown run kind 'simulation'"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalpha = []\n', "grid.alpha: empty list"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalpha = [0.5, 1.5]\n', "grid.alpha: alpha must be <= 1, got 1.5"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[grid]\npreferred_speed = ["fast"]\n', "grid.preferred_speed: preferred_speed must be a number"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalfa = [0.5]\n', "unknown parameter 'alfa' for kind 'sim' (did you mean 'alpha'?"),
        ('kind = "sumo"\nscenarios = ["rural_loop"]\n[grid]\nduration_s = [10.0]\n', "unknown parameter 'duration_s' for kind 'sumo'"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[fixed]\nalpha = 0.5\n[grid]\nalpha = [0.1]\n', "grid.alpha: alpha is already set in [fixed]"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[zip]\nalpha = [0.1, 0.2]\nreaction_time = [1.0]\n', "zip: the lists must have the same length"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[[cases]]\nalpha = 0.1\n[[cases]]\nalpha = 0.1\n', "a parameter set is listed twice"),
        ('kind = "sim"\nscenarios = ["test_track"]\nseeds = 0\n', "seeds: must be >= 1"),
        ('kind = "sim"\nscenarios = []\n', "scenarios: must be a non-empty list"),
        ('kind = "sim"\nscenarios = ["no_such_track.csv"]\n', "track 'no_such_track.csv': no such file"),
        ('kind = "sumo"\nscenarios = ["rual_loop"]\n', "scenario 'rual_loop' not found"),
        ('kind = "compare"\nscenarios = ["rural_loop"]\n[grid]\nbaseline = ["idm", "wiedemann"]\n', "baseline must be one of krauss, idm, eidm, acc"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[fixed]\ndirection = "sideways"\n', "unknown variant `sideways`"),
        ('kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalpha = { start = 0.0, stop = 1.0 }\n', "a range is { start = A, stop = B, step = S }"),
        ('kind = "sim"\nscenarios = ["test_track"\n', "malformed TOML"),
        ('scenarios = ["test_track"]\n', "missing key 'kind'"),
    ],
)
def test_bad_sweep_files_are_one_clear_error(tmp_path: Path, text: str, expect: str) -> None:
    file = _sweep(tmp_path, text)
    with pytest.raises(SweepError) as info:
        load_sweep(file)
    message = str(info.value)
    assert expect in message
    assert message.startswith(str(file)) and "\n" not in message


def test_sweep_expansion_grid_zip_cases_and_stable_ids(tmp_path: Path) -> None:
    text = """
kind = "sim"
scenarios = ["test_track", "circle:40"]
seeds = [3, 5]
[fixed]
duration_s = 10
[grid]
alpha = { start = 0.0, stop = 1.0, step = 0.25 }
[zip]
reaction_time = [0.5, 1.0]
preferred_stop_dist = [1, 2]
[[cases]]
lateral_controller = "blend"
[[cases]]
lateral_controller = "stanley"
"""
    sweep = load_sweep(_sweep(tmp_path, text))
    assert sweep.swept["alpha"] == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert len(sweep.runs) == 2 * 5 * 2 * 2 * 2
    ids = [r.run_id for r in sweep.runs]
    assert len(set(ids)) == len(ids)
    # zipped values go together, never crossed
    assert {(r.params["reaction_time"], r.params["preferred_stop_dist"]) for r in sweep.runs} == {(0.5, 1.0), (1.0, 2.0)}
    assert all(r.params["duration_s"] == 10.0 and r.seed in (3, 5) for r in sweep.runs)
    # the same runs get the same ids from another file with the same content, in another order
    reordered = text.replace('seeds = [3, 5]', 'seeds = [5, 3]').replace('scenarios = ["test_track", "circle:40"]', 'scenarios = ["circle:40", "test_track"]')
    again = load_sweep(_sweep(tmp_path, reordered, "other.toml"))
    assert {r.run_id for r in again.runs} == set(ids)


def test_alpha_auto_is_a_sweep_value_that_runs_the_automatic_alpha(tmp_path: Path) -> None:
    """A sweep over alpha = [1.0, "auto"]: each run's metrics equal a direct
    simulate() with ``ControllerConfig().with_alpha(value)`` under the sweep
    defaults (an independent call of the same law), and auto differs from 1."""
    import blendtrack

    sweep = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["test_track"]\n[fixed]\nduration_s = 60\n[grid]\nalpha = [1.0, "auto"]\n')
    out = tmp_path / "out"
    r = _cli("batch", str(sweep), "--workers", "1", "--quiet", "--out", str(out))
    assert r.returncode == 0, r.stderr
    got = {rec["params"]["alpha"]: rec["metrics"]["lateral_error_mean_abs_m"] for rec in _records(out).values()}
    assert set(got) == {1.0, "auto"}
    path = blendtrack.load_track("test_track")
    for alpha in (1.0, "auto"):
        _, m = blendtrack.simulate(path, blendtrack.ControllerConfig().with_alpha(alpha), duration_s=60, offset_m=4.0, seed=0)
        assert got[alpha] == pytest.approx(m["lateral_error_mean_abs_m"], rel=1e-12), alpha
    assert got["auto"] != pytest.approx(got[1.0], rel=1e-6)
    bad = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalpha = ["Auto"]\n', "bad.toml")
    with pytest.raises(SweepError, match="alpha must be a number or one of 'auto', got 'Auto'"):
        load_sweep(bad)


# ------------------------------------------------- executors, same results
@pytest.fixture(scope="module")
def local_batch(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, subprocess.CompletedProcess[str]]:
    tmp = tmp_path_factory.mktemp("local")
    sweep = _sweep(tmp, SIM_SWEEP)
    out = tmp / "out"
    r = _cli("batch", str(sweep), "--workers", "2", "--out", str(out))
    return sweep, out, r


def test_local_batch_writes_one_record_and_one_row_per_run(local_batch: tuple[Path, Path, subprocess.CompletedProcess[str]]) -> None:
    sweep, out, r = local_batch
    assert r.returncode == 0, r.stderr
    runs = load_sweep(sweep).runs
    recs = _records(out)
    assert set(recs) == {run.run_id for run in runs}
    for run in runs:
        rec = recs[run.run_id]
        assert rec["status"] == "ok" and rec["error"] == ""
        assert rec["params"] == run.params and rec["seed"] == run.seed
        assert rec["wall_time_s"] > 0 and rec["attempt"] == 1
        assert math.isfinite(rec["metrics"]["lateral_error_mean_abs_m"])
    csv = pd.read_csv(out / "results.csv")
    parquet = pd.read_parquet(out / "results.parquet")
    assert len(csv) == len(parquet) == len(runs)
    assert sorted(csv["run_id"]) == sorted(recs)
    for _, row in parquet.iterrows():
        assert row["lateral_error_mean_abs_m"] == recs[row["run_id"]]["metrics"]["lateral_error_mean_abs_m"]
        assert row["alpha"] == recs[row["run_id"]]["params"]["alpha"]
    # with noise, the seed matters: otherwise "identical for identical seeds" below would prove nothing
    by_alpha = parquet[parquet["alpha"] == 0.2]
    assert by_alpha["lateral_error_rms_m"].nunique() == 2


def test_summary_has_plots_best_sets_and_numbers_from_the_records(local_batch: tuple[Path, Path, subprocess.CompletedProcess[str]]) -> None:
    from blendtrack.reporting import fmt, mean_ci

    _, out, _ = local_batch
    summary = (out / "summary.md").read_text()
    png = out / "plots" / "lateral_error_mean_abs_m.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "![lateral_error_mean_abs_m](plots/lateral_error_mean_abs_m.png)" in summary
    assert "| ok | 4 |" in summary
    recs = list(_records(out).values())
    # the best alpha for the mean lateral error, from the records: lower is better
    means = {}
    for alpha in (0.2, 0.8):
        vals = [r["metrics"]["lateral_error_mean_abs_m"] for r in recs if r["params"]["alpha"] == alpha]
        means[alpha] = mean_ci(vals)
    best = min(means, key=lambda a: means[a][0])
    m, lo, hi = means[best]
    row = f"| lateral_error_mean_abs_m | lower | test_track | alpha={fmt(best)} | {fmt(m)} | [{fmt(lo)}, {fmt(hi)}] | 2 |"
    assert row in summary
    assert "| mean_speed_mps | higher |" in summary


def test_dask_local_cluster_gives_the_same_metrics_as_local_processes(
    local_batch: tuple[Path, Path, subprocess.CompletedProcess[str]], tmp_path: Path
) -> None:
    sweep, local_out, _ = local_batch
    out = tmp_path / "dask"
    # Dask's scheduler serves HTTP on 8787 by default and warns when the port
    # is taken (another batch, a notebook's cluster): held here if free.
    with socket.socket() as held:
        try:
            held.bind(("", 8787))
            held.listen()
        except OSError:
            pass  # taken already: the case this checks
        r = _cli("batch", str(sweep), "--dask-local", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "Dask LocalCluster, 2 worker processes" in r.stdout
    # Nothing from the cluster's start or shutdown (a worker's last heartbeat
    # racing the scheduler's close printed a traceback once in CI).
    assert "traceback" not in r.stderr.lower() and "warning" not in r.stderr.lower(), r.stderr
    local, dask = _records(local_out), _records(out)
    assert set(dask) == set(local) and len(dask) == 4
    for rid, rec in dask.items():
        assert rec["status"] == "ok"
        assert rec["metrics"] == local[rid]["metrics"], rec["name"]


def test_an_output_folder_of_a_batch_is_not_reused_by_accident(local_batch: tuple[Path, Path, subprocess.CompletedProcess[str]], tmp_path: Path) -> None:
    sweep, out, _ = local_batch
    before = {rid: rec["finished_at"] for rid, rec in _records(out).items()}
    r = _cli("batch", str(sweep), "--out", str(out))
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "pass --resume" in r.stderr
    other = _sweep(tmp_path, SIM_SWEEP.replace("alpha = [0.2, 0.8]", "alpha = [0.3]"))
    r = _cli("batch", str(other), "--resume", "--out", str(out))
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "different sweep" in r.stderr
    # nothing was run or rewritten
    assert {rid: rec["finished_at"] for rid, rec in _records(out).items()} == before
    assert (out / "summary.md").is_file()


def test_a_run_s_process_gets_one_blas_thread_unless_told_otherwise() -> None:
    from blendtrack.batch.executor import child_env

    env = child_env({"PATH": "/bin", "MPLBACKEND": "TkAgg"})
    assert env["OPENBLAS_NUM_THREADS"] == "1" and env["PATH"] == "/bin"
    assert env["MPLBACKEND"] == "Agg" and env["PYTHONUNBUFFERED"] == "1"
    assert child_env({"OPENBLAS_NUM_THREADS": "4"})["OPENBLAS_NUM_THREADS"] == "4"


def test_bad_sweep_on_the_command_line_is_one_line_and_exit_2(tmp_path: Path) -> None:
    file = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalpha = []\n')
    r = _cli("batch", str(file), "--out", str(tmp_path / "o"))
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "grid.alpha: empty list" in r.stderr and str(file) in r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------- failures and resume
def test_sigkill_midway_then_resume_ends_with_exactly_one_result_per_run(tmp_path: Path) -> None:
    sweep = _sweep(tmp_path, SIM_SWEEP.replace("seeds = 2", "seeds = 4"))
    out = tmp_path / "out"
    n = len(load_sweep(sweep).runs)
    proc = _popen("batch", str(sweep), "--workers", "2", "--quiet", "--out", str(out))
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        if len(list((out / "runs").glob("*.json"))) >= 1:
            os.killpg(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.005)
    proc.communicate()
    assert proc.returncode == -signal.SIGKILL, "the batch ended before it could be killed"
    first = _records(out)
    assert 1 <= len(first) < n
    assert all(rec["status"] == "ok" for rec in first.values())
    assert not (out / "summary.md").exists() and not (out / "results.csv").exists()
    time.sleep(0.2)
    assert not _processes_under(out), "run processes outlived the killed batch"

    r = _cli("batch", str(sweep), "--workers", "2", "--resume", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert f"({len(first)} from before)" in r.stdout
    recs = _records(out)
    assert set(recs) == {run.run_id for run in load_sweep(sweep).runs}
    assert all(rec["status"] == "ok" and rec["attempt"] == 1 for rec in recs.values())
    # the runs recorded before the kill were not run again
    assert all(recs[rid]["finished_at"] == rec["finished_at"] for rid, rec in first.items())
    assert not [p for p in (out / "runs").iterdir() if p.name.startswith(".")]
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == n and csv["run_id"].is_unique and set(csv["run_id"]) == set(recs)


def test_a_run_that_raises_is_recorded_as_failed_while_the_others_finish(tmp_path: Path) -> None:
    (tmp_path / "broken.csv").write_text("x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\nnot,a,track,row\n")
    sweep = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["test_track", "broken.csv"]\nseeds = 2\n[fixed]\nduration_s = 20\n')
    out = tmp_path / "out"
    r = _cli("batch", str(sweep), "--workers", "2", "--out", str(out))
    assert r.returncode == 1, r.stderr
    recs = _records(out)
    assert len(recs) == 4
    failed = {rid: rec for rid, rec in recs.items() if rec["status"] != "ok"}
    assert {rec["scenario"] for rec in failed.values()} == {"broken.csv"} and len(failed) == 2
    for rec in failed.values():
        assert rec["status"] == "failed"
        assert rec["error"].startswith("PathError:") and "broken.csv" in rec["error"], rec["error"]
        assert rec["metrics"] == {}
        assert "Traceback" in (out / "work" / rec["run_id"] / "run.log").read_text()
    assert all(math.isfinite(rec["metrics"]["distance_m"]) for rec in recs.values() if rec["status"] == "ok")
    summary = (out / "summary.md").read_text()
    assert "| failed | 2 |" in summary
    for rec in failed.values():
        assert rec["run_id"] in summary.split("## Failed runs")[1]
    csv = pd.read_csv(out / "results.csv")
    assert sorted(csv["status"]) == ["failed", "failed", "ok", "ok"]

    # --resume runs the failed runs again, and only those
    r = _cli("batch", str(sweep), "--workers", "2", "--resume", "--out", str(out))
    assert r.returncode == 1
    again = _records(out)
    for rid, rec in again.items():
        if rid in failed:
            assert rec["attempt"] == 2 and rec["status"] == "failed" and rec["finished_at"] > failed[rid]["finished_at"]
        else:
            assert rec == recs[rid]
    assert len(pd.read_csv(out / "results.csv")) == 4


def test_a_worker_process_that_dies_is_recorded_and_resume_runs_it_again(tmp_path: Path) -> None:
    sweep = _sweep(tmp_path, SIM_SWEEP)
    out = tmp_path / "out"
    proc = _popen("batch", str(sweep), "--workers", "2", "--quiet", "--out", str(out))
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and proc.poll() is None and time.monotonic() < deadline:
        # A segmentation fault of the first run process (as SUMO may crash).
        for child in psutil.Process(proc.pid).children(recursive=True):
            try:
                if CHILD in " ".join(child.cmdline()):
                    child.send_signal(signal.SIGSEGV)
                    killed = child.pid
                    break
            except psutil.Error:
                pass
        time.sleep(0.005)
    _, err = proc.communicate(timeout=120)
    assert killed is not None
    assert proc.returncode == 1, err
    recs = _records(out)
    assert len(recs) == 4
    dead = [rec for rec in recs.values() if rec["status"] != "ok"]
    assert len(dead) == 1
    assert dead[0]["status"] == "failed" and dead[0]["error"].startswith("worker process died (SIGSEGV, signal 11)")
    assert dead[0]["exit_code"] == -signal.SIGSEGV

    r = _cli("batch", str(sweep), "--workers", "2", "--resume", "--out", str(out))
    assert r.returncode == 0, r.stderr
    recs = _records(out)
    assert all(rec["status"] == "ok" for rec in recs.values())
    assert recs[dead[0]["run_id"]]["attempt"] == 2


def test_sumo_runs_in_a_worker_and_a_run_over_its_time_limit_is_killed(tmp_path: Path) -> None:
    # A copy of the ring whose routes repeat 600 times (about 52,000 s of
    # driving, over 2 minutes even at the ~420x real time the CI machine ran
    # the shipped ring's 194 laps, which it finished within the 40 s limit),
    # so "1000000 s" runs until it is killed. "10 s" is SUMO's start, the
    # long route's track and 100 steps: a few seconds even on a loaded
    # machine. The limit sits between the two with room both ways.
    ring = tmp_path / "ring_forever"
    shutil.copytree(SCENARIOS / "ring_single_lane", ring)
    routes = ring / "ring_single_lane.rou.xml"
    text = routes.read_text()
    assert text.count('repeat="194"') == 2
    routes.write_text(text.replace('repeat="194"', 'repeat="600"'))
    sweep = _sweep(tmp_path, 'kind = "sumo"\nscenarios = ["ring_forever"]\ntimeout_s = 40\n[grid]\nend = [10, 1000000]\n')
    out = tmp_path / "out"
    r = _cli("batch", str(sweep), "--workers", "2", "--out", str(out))
    assert r.returncode == 1, r.stderr
    recs = {rec["params"]["end"]: rec for rec in _records(out).values()}
    short, long_ = recs[10.0], recs[1000000.0]
    assert short["status"] == "ok", short["error"]
    assert short["metrics"]["controlled_vehicles"] >= 1
    # Within its lane: the ring's lane is 3.5 m wide and the vehicle 1.8 m
    # (ring_single_lane's network and vType), so its centre stays within
    # (3.5 - 1.8) / 2 = 0.85 m of the lane's centreline.
    assert 0 < short["metrics"]["lateral_error_mean_abs_m"] < (3.5 - 1.8) / 2
    assert (out / "work" / short["run_id"] / "vehicles.csv").is_file()
    assert long_["status"] == "timeout" and long_["error"].startswith("timed out after 40 s")
    # A killed run wrote no result: its folder says INCOMPLETE, has no summary,
    # and vehicles.csv (written as vehicles finish) no row: no ring vehicle finished.
    killed = out / "work" / long_["run_id"]
    assert (killed / "INCOMPLETE").is_file() and not (killed / "summary.json").exists()
    rows = killed / "vehicles.csv"
    assert not rows.exists() or rows.read_text().count("\n") <= 1
    assert not _processes_under(out), "the timed-out run left processes behind"
    assert "| timeout | 1 |" in (out / "summary.md").read_text()
