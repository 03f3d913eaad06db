"""Scenario intake: any configuration name, gzipped inputs, vTypes wherever
they are defined, and a run configuration that keeps every output out of
the scenario's folder (issue 17). SUMO itself runs the written
configurations, so what is checked is what SUMO does with them."""

from __future__ import annotations

import gzip
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from blendtrack.sumo import ScenarioError, resolve_scenario
from blendtrack.sumo.connection import sumo_binary

REPO = Path(__file__).resolve().parents[1]
RING = REPO / "sumo_scenarios" / "ring_single_lane"
REAL = Path(os.environ.get("BLENDTRACK_SHARED_DIR") or REPO.parent / "shared") / "scenarios_real"

needs_real = pytest.mark.skipif(not REAL.is_dir(), reason="../shared/scenarios_real is not beside the repo")


def _tree_hash(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def _config(inputs: str, extra: str = "", root: str = "configuration") -> str:
    return f'<?xml version="1.0"?>\n<{root}>\n<input>{inputs}</input>\n<time><end value="20"/><step-length value="0.5"/></time>\n{extra}\n</{root}>\n'


def _scenario_folder(tmp_path: Path, name: str = "scn", gz: bool = False) -> Path:
    """A small scenario of the shipped ring's network and demand, routes
    gzipped on request, one vType distribution in an additional file and an
    induction loop writing to a relative file."""
    d = tmp_path / name
    d.mkdir()
    shutil.copy(RING / "ring_single_lane.net.xml", d / "ring.net.xml")
    routes = (RING / "ring_single_lane.rou.xml").read_bytes()
    if gz:
        (d / "ring.rou.xml.gz").write_bytes(gzip.compress(routes))
    else:
        (d / "ring.rou.xml").write_bytes(routes)
    add = (
        '<additional>\n<vTypeDistribution id="mix"><vType id="calm" accel="1.0"><param key="blendtrack.controlled" value="true"/></vType>'
        '<vType id="brisk" accel="2.5"/></vTypeDistribution>\n'
        '<vTypeDistribution id="listed" vTypes="calm brisk"/>\n'
        '<inductionLoop id="loop0" lane="ring_n_0" pos="10" period="10" file="det/loop0.xml"/>\n</additional>\n'
    )
    (d / "extra.add.xml.gz").write_bytes(gzip.compress(add.encode()))
    return d


def _inputs(gz: bool = False) -> str:
    rou = "ring.rou.xml.gz" if gz else "ring.rou.xml"
    return f'<net-file value="ring.net.xml"/><route-files value="{rou}"/><additional-files value="extra.add.xml.gz"/>'


@pytest.mark.parametrize("name", ["run.sumocfg", "interchangeSim.cfg", "scenario.xml"])
def test_a_configuration_is_known_by_its_content_not_its_name(tmp_path: Path, name: str) -> None:
    d = _scenario_folder(tmp_path)
    (d / name).write_text(_config(_inputs()))
    for spec in (d / name, d):  # the file, and the folder holding one configuration
        sc = resolve_scenario(spec)
        assert sc.sumocfg == (d / name).absolute()
        assert sc.step_length_s == 0.5 and sc.end_s == 20.0
        assert [p.name for p in sc.additional_files] == ["extra.add.xml.gz"]


def test_sumoConfiguration_roots_and_symlinks_are_configurations_too(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path)
    (d / "a.sumocfg").write_text(_config(_inputs(), root="sumoConfiguration"))
    # A link beside it (SUMO resolves relative paths from the link's folder,
    # as it does here).
    link = d / "link.whatever"
    link.symlink_to(d / "a.sumocfg")
    assert resolve_scenario(link).net_file == (d / "ring.net.xml").absolute()
    far = tmp_path / "far.cfg"
    far.symlink_to(d / "a.sumocfg")
    with pytest.raises(ScenarioError, match="net-file 'ring.net.xml' does not exist"):
        resolve_scenario(far)


def test_folders_with_no_or_two_configurations_and_non_configurations_are_refused(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path)
    with pytest.raises(ScenarioError, match="no SUMO configuration"):
        resolve_scenario(d)
    (d / "a.cfg").write_text(_config(_inputs()))
    (d / "b.sumocfg").write_text(_config(_inputs()))
    with pytest.raises(ScenarioError, match=r"2 SUMO configurations \(a\.cfg, b\.sumocfg\)"):
        resolve_scenario(d)
    with pytest.raises(ScenarioError, match=r"not a SUMO configuration \(root element <net>"):
        resolve_scenario(d / "ring.net.xml")
    (d / "broken.cfg").write_text("<configuration><input>")
    with pytest.raises(ScenarioError, match="broken.cfg: malformed XML"):
        resolve_scenario(d / "broken.cfg")
    (d / "missing.cfg").write_text(_config('<net-file value="ring.net.xml"/><route-files value="nope.rou.xml"/>'))
    with pytest.raises(ScenarioError, match="route-files 'nope.rou.xml' does not exist"):
        resolve_scenario(d / "missing.cfg")


def test_vtypes_come_from_gzipped_route_and_additional_files_with_distributions(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path, gz=True)
    (d / "run.cfg").write_text(_config(_inputs(gz=True)))
    vt = resolve_scenario(d).vtypes()
    assert {"auto", "human", "calm", "brisk"} <= set(vt.types)
    assert vt.types["calm"] == {"blendtrack.controlled": "true"}
    assert vt.members("mix") == ["calm", "brisk"]
    assert vt.members("listed") == ["calm", "brisk"]
    assert vt.members("human") == ["human"] and vt.members("DEFAULT_VEHTYPE") == ["DEFAULT_VEHTYPE"]
    assert vt.members("nope") is None
    assert "mix" in vt.known() and "nope" not in vt.known()


def test_declares_finds_text_in_gzipped_files_and_across_the_scan_s_chunks(tmp_path: Path) -> None:
    from blendtrack.sumo.sumocfg import mentions

    d = _scenario_folder(tmp_path, gz=True)
    (d / "run.cfg").write_text(_config(_inputs(gz=True)))
    sc = resolve_scenario(d)
    assert sc.declares("blendtrack.controlled")  # in the gzipped route file's vType 'calm'
    assert not sc.declares("blendtrack.alpha")
    # The scan reads 1 MiB at a time: text across the boundary is found,
    # text only split by it is not made up.
    big = tmp_path / "big.xml"
    big.write_bytes(b" " * ((1 << 20) - 5) + b"blendtrack." + b" " * 10)
    assert mentions(big, b"blendtrack.") and not mentions(big, b"blendtrack.x")
    assert mentions(tmp_path / "gone.xml", b"x")  # unreadable: the parse after it says why


def test_the_run_configuration_keeps_every_output_out_of_the_scenario(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path, gz=True)
    elsewhere = tmp_path / "elsewhere"
    outputs = (
        '<output><tripinfo-output value="data/trips.xml"/><summary-output value="'
        f'{elsewhere}/summary.xml"/><precision value="3"/></output><report><log value="sumo.log"/></report>'
    )
    (d / "run.cfg").write_text(_config(_inputs(gz=True), outputs))
    before = _tree_hash(d)
    out = tmp_path / "out" / "sumo"
    cfg = resolve_scenario(d / "run.cfg").run_config(out)
    proc = subprocess.run([sumo_binary(False), "-c", str(cfg), "--no-step-log", "true"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert _tree_hash(d) == before, "SUMO wrote into the scenario folder"
    assert not elsewhere.exists(), "an absolute output path outside --out was written"
    for f in ("data/trips.xml", "summary.xml", "sumo.log", "det/loop0.xml"):
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    # The ring's vehicles drove (nobody leaves it: the summary shows them running).
    assert 'running="22"' in (out / "summary.xml").read_text()
    assert 'precision value="3"' in cfg.read_text()  # a non-file <output> option is kept as it is


def test_two_runs_of_one_scenario_share_no_file(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path)
    (d / "run.cfg").write_text(_config(_inputs(), '<output><tripinfo-output value="trips.xml"/></output>'))
    sc = resolve_scenario(d)
    a, b = sc.run_config(tmp_path / "a"), sc.run_config(tmp_path / "b")
    files_a = {p for p in (tmp_path / "a").rglob("*") if p.is_file()}
    files_b = {p for p in (tmp_path / "b").rglob("*") if p.is_file()}
    assert a != b and not files_a & files_b
    assert str(tmp_path / "a" / "trips.xml") in a.read_text() and str(tmp_path / "b" / "trips.xml") in b.read_text()


@needs_real
@pytest.mark.parametrize("spec", ["eccles_interchange/interchangeSim.cfg", "bologna_acosta/run.sumocfg", "bologna_acosta"])
def test_the_public_scenarios_load_unedited_and_their_folders_stay_untouched(tmp_path: Path, spec: str) -> None:
    sc = resolve_scenario(REAL / spec)
    before = _tree_hash(sc.folder)
    cfg = sc.run_config(tmp_path / "sumo")
    proc = subprocess.run([sumo_binary(False), "-c", str(cfg), "--end", "30", "--no-step-log", "true"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert _tree_hash(sc.folder) == before
    assert any(p.name.startswith("trip") for p in (tmp_path / "sumo").rglob("*.xml"))


def _cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    import os
    import sys

    full = {**os.environ, **(env or {})}
    for k in [k for k, v in full.items() if v == ""]:
        del full[k]
    return subprocess.run([sys.executable, "-m", "blendtrack.cli", *args], capture_output=True, text=True, timeout=300, env=full)


def _one_line_error(proc: subprocess.CompletedProcess[str], expect: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and expect in lines[0], proc.stderr


def test_gui_without_a_display_is_a_one_line_error(tmp_path: Path) -> None:
    proc = _cli("sumo", "run", "rural_loop", "--gui", "--end", "5", "--out", str(tmp_path / "o"), env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
    _one_line_error(proc, "--gui needs a display")


def test_selections_that_match_nothing_are_errors_naming_what_exists(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path)
    (d / "run.cfg").write_text(_config(_inputs()))
    out = str(tmp_path / "o")
    # A type nobody drives, an unknown type, and no selector where no vType is marked.
    _one_line_error(_cli("sumo", "run", str(d), "--controlled-type", "brisk", "--out", out), "no vehicle of scn is of that type (its vehicles' types: auto, human)")
    _one_line_error(_cli("sumo", "run", str(d), "--controlled-type", "nope", "--out", out), "no such vType or vTypeDistribution")
    # The ring marks 'auto'; strip the mark: nothing selects a vehicle.
    routes = (d / "ring.rou.xml").read_text().replace('<param key="blendtrack.controlled" value="true"/>', "")
    (d / "ring.rou.xml").write_text(routes)
    _one_line_error(_cli("sumo", "run", str(d), "--out", out), "nothing selects a vehicle to control")


def test_a_distribution_selects_its_members_and_unknown_params_are_named(tmp_path: Path) -> None:
    d = _scenario_folder(tmp_path)
    routes = (d / "ring.rou.xml").read_text().replace('type="human"', 'type="mix"', 3)
    (d / "ring.rou.xml").write_text(routes)
    (d / "run.cfg").write_text(_config(_inputs()))
    before = _tree_hash(d)
    proc = _cli("sumo", "run", str(d), "--controlled-type", "mix", "--end", "10", "--quiet", "--out", str(tmp_path / "o"))
    assert proc.returncode == 0, proc.stderr
    import json

    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["controlled_vehicles"] == 3  # the three vehicles drawn from 'mix', nobody else
    assert _tree_hash(d) == before, "the run wrote into the scenario folder"
    assert (tmp_path / "o" / "sumo" / "det" / "loop0.xml").is_file()  # the scenario's detector output, redirected
    # A misspelt blendtrack.* parameter is an error naming it, not ignored.
    add = gzip.decompress((d / "extra.add.xml.gz").read_bytes()).decode()
    add = add.replace('<vType id="brisk" accel="2.5"/>', '<vType id="brisk" accel="2.5"><param key="blendtrack.lat_blend_fator" value="0.3"/></vType>')
    (d / "extra.add.xml.gz").write_bytes(gzip.compress(add.encode()))
    proc = _cli("sumo", "run", str(d), "--controlled-type", "mix", "--end", "10", "--quiet", "--out", str(tmp_path / "o2"))
    _one_line_error(proc, "unknown parameter 'blendtrack.lat_blend_fator' (did you mean blendtrack.lat_blend_factor?)")


@needs_real
@pytest.mark.parametrize(
    "spec, own_output",
    [("eccles_interchange/interchangeSim.cfg", "data/vehicle_routes.xml"), ("bologna_acosta/run.sumocfg", "e1_output.xml")],
)
def test_sumo_run_on_the_public_scenarios_leaves_their_folders_untouched(tmp_path: Path, spec: str, own_output: str) -> None:
    sc = resolve_scenario(REAL / spec)
    before = _tree_hash(sc.folder)
    proc = _cli("sumo", "run", str(sc.sumocfg), "--controlled-fraction", "0.3", "--end", "30", "--quiet", "--out", str(tmp_path / "o"))
    assert proc.returncode == 0, proc.stderr
    assert _tree_hash(sc.folder) == before
    assert (tmp_path / "o" / "sumo" / own_output).is_file()  # its own configured output, under --out
