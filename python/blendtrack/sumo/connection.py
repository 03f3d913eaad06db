"""The connection to SUMO: starting and closing a simulation (in-process
through libsumo, or over TraCI sockets, which sumo-gui needs), the SUMO
binary and command line (option overrides), the check that a scenario loads
before libsumo gets it (and its cache, :func:`loads_ok_marker`), the
per-vehicle calls of the hot loop, and the per-step caches."""

from __future__ import annotations

import functools
import hashlib
import math
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Callable

from blendtrack._blendtrack import HOLD_BRAKING_MIN_STEP_S
from blendtrack.sumo.options import RunOptions
from blendtrack.sumo.scenario import Scenario, ScenarioError

# True once this process has started a libsumo simulation (see SumoConnection.start).
_LIBSUMO_STARTED = False


def libsumo_started() -> bool:
    """Has this process run a libsumo simulation already (see ``SumoConnection.start``)?"""
    return _LIBSUMO_STARTED


def _sumo_home() -> str:
    home = os.environ.get("SUMO_HOME")
    if home:
        return home
    import sumo  # the eclipse-sumo wheel

    home = str(sumo.SUMO_HOME)
    os.environ["SUMO_HOME"] = home
    return home


def sumo_binary(gui: bool = False) -> str:
    """Path of the ``sumo`` (or ``sumo-gui``) binary of the installed SUMO:
    the eclipse-sumo wheel's, else ``$SUMO_HOME/bin``, else the one on PATH."""
    import shutil

    name = "sumo-gui" if gui else "sumo"
    homes = []
    try:
        import sumo  # the eclipse-sumo wheel

        homes.append(str(sumo.SUMO_HOME))
    except ImportError:
        pass
    homes.append(_sumo_home())
    for home in homes:
        path = Path(home) / "bin" / name
        if path.exists():
            return str(path)
    return shutil.which(name) or name


def _cache_dir() -> Path:
    env = os.environ.get("BLENDTRACK_CACHE_DIR")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "blendtrack"


def loads_ok_marker(scenario: Scenario, binary: str, sumo_args: tuple[str, ...] = ()) -> Path | None:
    """Where the runner notes that SUMO loaded ``scenario`` without error: a
    file named by a hash of the SUMO binary (path, size, modification time),
    the .sumocfg and every file its ``<input>`` names (the network, routes,
    additional files) and the extra SUMO options, under
    ``$BLENDTRACK_CACHE_DIR`` (default ``~/.cache/blendtrack``). Any change to
    them is another name, so the child check runs again. None when a file
    cannot be read (no caching)."""
    try:
        h = hashlib.sha256()
        st = os.stat(binary)
        h.update(f"{os.path.realpath(binary)}:{st.st_size}:{st.st_mtime_ns}\n".encode())
        cfg = scenario.sumocfg
        h.update(cfg.read_bytes())
        h.update(("\n".join(sumo_args) + "\n").encode())
        files = {scenario.net_file, *scenario.route_files, *scenario.additional_files}
        for f in sorted(files):
            h.update(f"\n{f}\n".encode())
            with open(f, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
    except OSError:
        return None
    return _cache_dir() / "sumo-loads-ok" / h.hexdigest()


class SumoConnection:
    """One SUMO simulation: its process (or libsumo), the TraCI constants,
    the bound per-vehicle calls and the per-step caches."""

    def __init__(self, scenario: Scenario, options: RunOptions, out_dir: Path | None) -> None:
        self.scenario = scenario
        self.opt = options
        self.out_dir = out_dir
        self.sumo: Any = None
        self.tc: Any = None
        self.backend = "libsumo"
        self.backend_note = ""
        self.dt = math.nan
        self.has_tls = False
        #: Subscribe to every light's state (set before ``start``)? Needed
        #: where a light can be switched between SUMO's step and the
        #: control step's reading of it (TraCI, where another client may;
        #: a step hook): the subscription then keeps the state SUMO's step
        #: moved the vehicles under. With libsumo and no step hook nothing
        #: can, and each light's state is read directly (``lights``,
        #: ``light_state``): about 60 % fewer instructions for the lights
        #: than subscribing to them and reading the subscriptions' dict.
        self.subscribe_lights = True
        #: The traffic lights (SUMO's ids, in ``getIDList``'s order).
        self.lights: tuple[str, ...] = ()
        #: Whether the lights are subscribed to in this simulation.
        self.light_subscriptions = False
        # The hot loop's per-vehicle calls (see _bind_calls).
        self.get_leader: Any = None
        self.get_speed: Any = None
        self.get_accel: Any = None
        self.get_lane_id: Any = None
        self.get_lane_pos: Any = None
        self.get_position: Any = None
        self.get_route_id: Any = None
        self.set_speed: Any = None
        self.move_to: Any = None
        self.move_to_xy: Any = None
        self.lane_change_state: Any = None
        self.lane_vehicles: Any = None
        self.light_state: Any = None
        #: SUMO's list of the vehicles on a lane this step, read once a step
        #: (several vehicles ask about the lanes of one junction):
        #: ``lane_vehicles`` behind an unbounded ``functools.lru_cache``
        #: emptied by ``new_step`` (set by ``start``). Hit or miss, no Python
        #: frame: a cache of a dict subclass with ``__missing__`` ran one per
        #: lane read (325,000 on the grid in 120 s with every vehicle).
        self.vehicles_on: Any = _no_simulation
        #: Speeds of SUMO's leaders read this step (``leader_speed``).
        self.leader_speeds: dict[str, float] = {}
        self._tmp: tempfile.TemporaryDirectory[str] | None = None

    def _sumo_dir(self) -> Path:
        """Where SUMO writes: ``OUT/sumo``, or a temporary folder for a run
        with no output folder (removed on close)."""
        if self.out_dir is not None:
            return self.out_dir / "sumo"
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="blendtrack-sumo-")
        return Path(self._tmp.name)

    def command(self) -> list[str]:
        """The ``sumo`` command line of the run. SUMO reads the run's own copy
        of the configuration (``Scenario.run_config``): the scenario's inputs
        by absolute path and every output it configures under the run's
        folder, so nothing is written into the scenario's folder."""
        o = self.opt
        outputs = self.out_dir / "sumo" if self.out_dir is not None else None
        return sumo_command(self.scenario, self._sumo_dir(), o.seed, o.end_s, outputs,
                            gui=o.gui, fcd=o.fcd, ssm=o.ssm, sumo_args=o.sumo_args)

    def start(self) -> None:
        global _LIBSUMO_STARTED
        _sumo_home()
        if self.opt.gui and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ScenarioError(
                "--gui needs a display and none is set (DISPLAY and WAYLAND_DISPLAY are empty): "
                "run without --gui, or under a virtual display (xvfb-run)"
            )
        self.backend = "traci" if (self.opt.backend == "traci" or self.opt.gui) else "libsumo"
        if self.backend == "libsumo" and _LIBSUMO_STARTED:
            # libsumo 1.28 keeps state across simulations in one process: a
            # second simulation of the urban grid after one with every
            # vehicle moved by moveToXY crashed (segmentation fault). A
            # second run in a process therefore drives SUMO over TraCI (its
            # own process; same results, slower); run_scenario avoids this by
            # running it in a fresh process instead.
            self.backend = "traci"
            self.backend_note = "libsumo was already used in this process: TraCI instead"
        if self.backend == "traci":
            import traci
            import traci.constants as tc

            self.sumo = traci
            self.tc = tc
            label = f"blendtrack-{os.getpid()}-{id(self)}"
            try:
                traci.start(self.command(), label=label)
            except Exception as e:  # SUMO refused the configuration
                raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {_first_line(e)}") from None
            self.sumo = traci.getConnection(label)
        else:
            import libsumo
            import traci.constants as tc  # the same constants libsumo uses

            # libsumo runs SUMO inside this process, and SUMO 1.28 crashes it
            # (segmentation fault) on some malformed networks: load the
            # configuration once in a child process first, so a bad scenario
            # is a clear error and not a dead interpreter.
            self.check_loads()

            self.sumo = libsumo
            self.tc = tc
            _LIBSUMO_STARTED = True
            try:
                libsumo.start(self.command())
            except Exception as e:
                raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {_first_line(e)}") from None
        self.dt = float(self.sumo.simulation.getDeltaT())
        tc = self.tc
        self.sumo.simulation.subscribe(
            [
                tc.VAR_DEPARTED_VEHICLES_IDS,
                tc.VAR_ARRIVED_VEHICLES_IDS,
                tc.VAR_TELEPORT_STARTING_VEHICLES_IDS,
                tc.VAR_COLLIDING_VEHICLES_IDS,
            ]
        )
        types = set(self.sumo.vehicletype.getIDList())
        t = self.opt.controlled_type
        if t is not None and t not in types and self.scenario.vtypes().members(t) is None:
            self.close()
            known = sorted(types | set(self.scenario.vtypes().distributions))
            raise ScenarioError(
                f"--controlled-type {t!r}: no such vType or vTypeDistribution in {self.scenario.sumocfg.name} "
                f"(known: {', '.join(known)})"
            )
        lights = self.sumo.trafficlight.getIDList()
        self.lights = tuple(lights)
        self.light_subscriptions = self.subscribe_lights or self.backend != "libsumo"
        if self.light_subscriptions:
            for tls in lights:
                self.sumo.trafficlight.subscribe(tls, [tc.TL_RED_YELLOW_GREEN_STATE])
        self.has_tls = bool(lights)
        self._bind_calls()

    def _bind_calls(self) -> None:
        """The per-vehicle SUMO calls of the hot loop. With libsumo, its SWIG
        functions themselves: the Python wrappers around them add about a
        third to each call (measured: setSpeed 405 vs 279 ns)."""
        v = self.sumo.vehicle
        #: What a call on a vehicle that has left raises (libsumo's or TraCI's
        #: TraCIException); a lost connection raises something else and ends the run.
        self.errors: type[Exception] = getattr(self.sumo, "TraCIException", Exception)
        raw: Any = None
        if self.backend == "libsumo":
            try:
                import libsumo._libsumo

                raw = libsumo._libsumo
            except ImportError:  # a libsumo built differently: its wrappers then
                raw = None

        def pick(name: str) -> Any:
            f = getattr(raw, "vehicle_" + name, None)
            return f if callable(f) else getattr(v, name)

        self.get_leader = pick("getLeader")
        self.get_speed = pick("getSpeed")
        self.get_accel = pick("getAcceleration")
        self.get_lane_id = pick("getLaneID")
        self.get_lane_pos = pick("getLanePosition")
        self.get_position = pick("getPosition")
        self.get_route_id = pick("getRouteID")
        self.set_speed = pick("setSpeed")
        self.move_to = pick("moveTo")
        self.move_to_xy = pick("moveToXY")
        self.lane_change_state = pick("getLaneChangeState")
        lane_ids = getattr(raw, "lane_getLastStepVehicleIDs", None)
        self.lane_vehicles = lane_ids if callable(lane_ids) else self.sumo.lane.getLastStepVehicleIDs
        state = getattr(raw, "trafficlight_getRedYellowGreenState", None)
        self.light_state = state if callable(state) else self.sumo.trafficlight.getRedYellowGreenState
        self.vehicles_on = functools.lru_cache(maxsize=None)(self.lane_vehicles)

    def vehicles_on_lanes(self, lanes: list[str]) -> list[Any]:
        """``vehicles_on`` of each of ``lanes``."""
        return list(map(self.vehicles_on, lanes))

    def leader_speed(self, vid: str) -> float:
        """``vid``'s speed (a leader SUMO drives), read from SUMO once a step."""
        v = self.leader_speeds.get(vid)
        if v is None:
            v = self.leader_speeds[vid] = float(self.get_speed(vid))
        return v

    def step_speed(self, vid: str) -> float:
        """The speed of ``vid`` (a leader SUMO drives) to hold it at over the
        coming step: its mean speed over the step if it goes on braking as it
        did in the last one (SUMO's ``getAcceleration``), else its speed.
        Held at its speed, a leader braking into a queue gained on its
        follower all step, and at a 1 s step the follower, re-planning at
        every control step against that leader, ran into it (Eccles: 27 of
        30 collisions, the leader braking at 2-4 m/s^2 step after step).
        Held at the mean speed it is never ahead of where it gets braking so
        (``v t`` with ``v = v0 + a dt / 2`` against ``v0 t + a t^2 / 2``, for
        ``t`` up to ``dt``). Only at steps of ``HOLD_BRAKING_MIN_STEP_S`` or
        more, as the traffic engine does for the leaders it drives (see
        ``braking_mean_speed`` there)."""
        v = self.leader_speed(vid)
        dt = self.dt
        if not dt >= HOLD_BRAKING_MIN_STEP_S:
            return v
        a = float(self.get_accel(vid))
        if not a < 0.0 or not v > 0.0:
            return v
        if v + a * dt <= 0.0:
            return v * v / (-2.0 * a) / dt  # it stops within the step
        return v + 0.5 * a * dt

    def check_loads(self) -> None:
        """Loads the scenario once in a child ``sumo`` (see ``start``), with
        the run's own time window: SUMO is started with TraCI, takes one step
        (the run's first, which reads the first of the routes) and is closed.
        An end before the run's own would make SUMO refuse scenarios it runs:
        an ``<edgeData>`` dump or a ``<flow>`` without an end of its own takes
        the run's, and SUMO refuses one that ends at or before its begin (the
        scenarios of SUMO's ``tools/game`` did so with ``--end 0``). A
        scenario that loaded before, byte for byte with the same SUMO binary
        and options, is not loaded again (``loads_ok_marker``): the check
        costs a second on the highway, once per run otherwise (batch sweeps,
        benchmarks)."""
        binary = sumo_binary(False)
        # SUMO refuses an option given twice: the user's extra options replace
        # the check's quiet flags, and the run's end replaces theirs.
        quiet = ["--no-step-log", "true", "--duration-log.disable", "true", "--no-warnings", "true"]
        end = ["--end", str(self.opt.end_s)] if self.opt.end_s is not None else []
        opts = override_options(override_options(quiet, list(self.opt.sumo_args)), end)
        marker = loads_ok_marker(self.scenario, binary, tuple(self.opt.sumo_args) + tuple(end))
        if marker is not None and marker.exists():
            return
        try:
            with tempfile.TemporaryDirectory(prefix="blendtrack-check-") as tmp:
                cmd = [binary, "-c", str(self.scenario.run_config(Path(tmp))), *opts]
                code, lines = _load_once(cmd, Path(tmp) / "check.log")
        except (OSError, TimeoutError) as e:
            raise ScenarioError(f"{self.scenario.sumocfg}: cannot run SUMO to check the scenario: {e}") from None
        if code != 0:
            crash = f"SUMO crashed while loading it (signal {-code})" if code < 0 else f"exit code {code}"
            errors = [ln for ln in lines if "Error" in ln] or lines or [crash]
            raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {errors[0].strip()}")
        if marker is not None:
            try:
                marker.parent.mkdir(parents=True, exist_ok=True)
                tmp = marker.with_name(marker.name + f".{os.getpid()}.tmp")
                tmp.write_text(str(self.scenario.sumocfg) + "\n")
                os.replace(tmp, marker)
            except OSError:
                pass  # no cache: the check runs again next time

    def close(self) -> None:
        if self.sumo is not None:
            try:
                self.sumo.close()
            except Exception:
                pass
            self.sumo = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def time(self) -> float:
        """SUMO's simulation time, NaN once closed (or when SUMO cannot say)."""
        try:
            return float(self.sumo.simulation.getTime()) if self.sumo is not None else math.nan
        except Exception:
            return math.nan

    def new_step(self) -> None:
        """A new control step: the per-step caches start empty."""
        if self.vehicles_on is not _no_simulation:
            self.vehicles_on.cache_clear()
        self.leader_speeds.clear()

    def hand_back(self, vid: str) -> None:
        """SUMO's own driving for ``vid`` again (each call on its own: one
        failing, say on a vehicle gone meanwhile, does not skip the rest)."""
        v = self.sumo.vehicle
        for call, args in ((v.setSpeed, (-1.0,)), (v.setSpeedMode, (31,)), (v.setLaneChangeMode, (1621,))):
            try:
                call(vid, *args)
            except Exception:
                pass


#: How long the load check waits for SUMO (s).
CHECK_TIMEOUT_S = 600.0


def _load_once(cmd: list[str], log: Path) -> tuple[int, list[str]]:
    """Runs ``cmd`` (a ``sumo`` command) as a TraCI server in a child
    process, connects, takes one step and closes: SUMO's exit code (negative:
    killed by that signal) and the non-empty lines it wrote. A ``TimeoutError``
    when SUMO neither connects nor ends within ``CHECK_TIMEOUT_S``."""
    import contextlib
    import io
    import subprocess

    import traci
    from sumolib.miscutils import getFreeSocketPort  # type: ignore[import-untyped]

    port = getFreeSocketPort()
    with open(log, "w") as out:
        proc = subprocess.Popen([*cmd, "--remote-port", str(port)], stdout=out, stderr=subprocess.STDOUT)
        try:
            wait_s = 0.05
            try:
                # (traci prints each retry: kept out of the user's terminal.)
                with contextlib.redirect_stdout(io.StringIO()):
                    conn = traci.connect(port, numRetries=int(CHECK_TIMEOUT_S / wait_s), proc=proc, waitBetweenRetries=wait_s)
                conn.simulationStep()
                conn.close()
            except (traci.TraCIException, traci.FatalTraCIError, OSError):
                pass  # SUMO quit: its exit code and output say why
            try:
                code = proc.wait(timeout=CHECK_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                raise TimeoutError(f"SUMO did not end within {CHECK_TIMEOUT_S:g} s") from None
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    lines = [ln for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    return code, lines


def _no_simulation(lane: str) -> Any:
    """``vehicles_on`` before the simulation has started."""
    raise RuntimeError(f"lane {lane!r}: SUMO has not started")


def sumo_command(scenario: Scenario, config_dir: Path, seed: int, end_s: float | None, outputs: Path | None, *,
                 gui: bool = False, fcd: bool = False, ssm: bool = False, ours: Sequence[str] = (),
                 sumo_args: Sequence[str] = ()) -> list[str]:
    """A ``sumo`` command line of a run, the blendtrack run's and the plain
    baseline's alike: the scenario's run configuration written under
    ``config_dir``; SUMO's outputs (trip info, collisions, log, and the FCD
    and SSM device when asked) under ``outputs`` (none without it); ``ours``,
    further options of the caller; the end time; the junction collision
    check; then the user's ``sumo_args``, which replace any of ours they name
    (SUMO refuses an option given twice)."""
    cmd = [sumo_binary(gui), "-c", str(scenario.run_config(config_dir)), "--seed", str(seed)]
    cmd += ["--no-step-log", "true", "--duration-log.disable", "true"]
    if outputs is not None:
        outputs.mkdir(parents=True, exist_ok=True)
        cmd += ["--tripinfo-output", str(outputs / "tripinfo.xml"), "--device.emissions.probability", "1"]
        cmd += ["--collision-output", str(outputs / "collisions.xml"), "--log", str(outputs / "sumo.log")]
        if fcd:
            cmd += ["--fcd-output", str(outputs / "fcd.xml")]
        if ssm:
            cmd += [
                "--device.ssm.probability", "1",
                "--device.ssm.file", str(outputs / "ssm.xml"),
                "--device.ssm.measures", "TTC DRAC PET",
                "--device.ssm.thresholds", "3.0 3.0 2.0",
            ]
    cmd += list(ours)
    if end_s is not None:
        cmd += ["--end", str(end_s)]
    cmd += junction_check_args(scenario)
    return cmd[:3] + override_options(cmd[3:], list(sumo_args))


def junction_check_args(scenario: Scenario) -> list[str]:
    """``--collision.check-junctions true`` unless the scenario's configuration
    sets it: SUMO checks for collisions along lanes only unless told to look
    inside junctions too (by overlap of the vehicles' shapes); off, a
    controlled vehicle that ran into another in a junction went uncounted
    (Bologna, 600 s, seeds 0-2: 12 such collisions). Both runs of a compare
    take it; the user's --sumo-args replace it (``override_options``)."""
    if scenario.config().option("collision.check-junctions") is not None:
        return []
    return ["--collision.check-junctions", "true"]


def override_options(base: list[str], extra: list[str]) -> list[str]:
    """SUMO command-line options ``base`` with ``extra`` added, an option in
    both taken from ``extra`` only (SUMO refuses one given twice). An option
    is a token starting with ``-`` and the tokens after it up to the next
    such token (its values; none for a bare flag)."""

    given = {name for a in extra if (name := _option_name(a)) is not None}
    kept: list[str] = []
    skipping = False
    for a in base:
        name = _option_name(a)
        if name is not None:
            skipping = name in given
        if not skipping:
            kept.append(a)
    return kept + extra


def _option_name(token: str) -> str | None:
    """The option a command-line token names (``--end=5`` -> ``end``), or
    None for a value (a negative number is a value)."""
    if not token.startswith("-"):
        return None
    try:
        float(token)
        return None
    except ValueError:
        return token.split("=", 1)[0].lstrip("-")


def _first_line(e: BaseException) -> str:
    text = str(e).strip() or type(e).__name__
    return text.splitlines()[0]
