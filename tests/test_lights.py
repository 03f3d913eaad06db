"""SignalAhead: the state a light will have while SUMO moves the vehicles in
its next step, predicted only where the program makes it certain (a fake
traffic-light domain; the real one is in test_sumo_incidents.py)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from blendtrack.sumo.lights import STATIC_PROGRAM, SignalAhead

ACTUATED = 3


def phase(state: str, dur: float, min_dur: float | None = None, max_dur: float | None = None, nxt: tuple[int, ...] = ()) -> Any:
    return SimpleNamespace(state=state, duration=dur, minDur=dur if min_dur is None else min_dur,
                           maxDur=dur if max_dur is None else max_dur, next=nxt)


class FakeLights:
    """One light "a" running program "0" of the given phases."""

    def __init__(self, phases: list[Any], kind: int = STATIC_PROGRAM) -> None:
        self.logic = SimpleNamespace(programID="0", type=kind, phases=phases)
        self.phase, self.switch, self.program = 0, 10.0, "0"
        self.calls: dict[str, int] = {}

    def _count(self, name: str) -> None:
        self.calls[name] = self.calls.get(name, 0) + 1

    def getNextSwitch(self, tls: str) -> float:
        self._count("getNextSwitch")
        if tls != "a":
            raise KeyError(tls)
        return self.switch

    def getPhase(self, tls: str) -> int:
        return self.phase

    def getProgram(self, tls: str) -> str:
        return self.program

    def getAllProgramLogics(self, tls: str) -> list[Any]:
        self._count("getAllProgramLogics")
        return [SimpleNamespace(programID="other", type=STATIC_PROGRAM, phases=[]), self.logic]


def test_a_fixed_time_program_gives_the_next_phase_from_the_switch_on() -> None:
    tl = FakeLights([phase("Gr", 10), phase("yr", 3), phase("rG", 10), phase("ry", 3)])
    ahead = SignalAhead(tl)
    assert ahead.coming("a", "Gr", 8.0) == "Gr"
    assert ahead.coming("a", "Gr", 9.0) == "Gr"
    # SUMO switches at the start of its step from 10 s: that step runs under yellow.
    assert ahead.coming("a", "Gr", 10.0) == "yr"
    tl.phase, tl.switch = 1, 13.0
    assert ahead.coming("a", "yr", 11.0) == "yr"
    assert ahead.coming("a", "yr", 13.0) == "rG"
    # The last phase wraps round to the first.
    tl.phase, tl.switch = 3, 26.0
    assert ahead.coming("a", "ry", 26.0) == "Gr"
    # Times are read when the state changes, not every step; the program once.
    assert tl.calls == {"getNextSwitch": 3, "getAllProgramLogics": 1}


def test_a_switch_time_passed_without_a_change_is_read_again() -> None:
    """Another client extended the phase (setPhaseDuration): the switch time
    blendtrack knew passes with the state unchanged, and is read anew."""
    tl = FakeLights([phase("Gr", 10), phase("yr", 3)])
    ahead = SignalAhead(tl)
    assert ahead.coming("a", "Gr", 9.0) == "Gr"
    tl.switch = 20.0
    assert ahead.coming("a", "Gr", 10.0) == "yr"  # one step wrong at most
    assert ahead.coming("a", "Gr", 11.0) == "Gr"
    assert ahead.coming("a", "Gr", 20.0) == "yr"


def test_a_phase_that_may_be_extended_is_not_predicted() -> None:
    """Actuated: the green's switch time moves with the traffic, so the
    state read stands; its yellow (minDur == maxDur) is certain."""
    tl = FakeLights([phase("Gr", 30, 5, 60), phase("yr", 3), phase("rG", 30, 5, 60), phase("ry", 3)], kind=ACTUATED)
    ahead = SignalAhead(tl)
    assert ahead.coming("a", "Gr", 10.0) == "Gr"
    tl.phase, tl.switch = 1, 14.0
    assert ahead.coming("a", "yr", 14.0) == "rG"


def test_next_phases_are_followed_and_must_agree() -> None:
    tl = FakeLights([phase("Gr", 10, nxt=(2,)), phase("xx", 3), phase("rG", 10, nxt=(0, 3)), phase("rg", 3)])
    ahead = SignalAhead(tl)
    assert ahead.coming("a", "Gr", 10.0) == "rG"
    tl.phase = 2
    # Two next phases of different states: no prediction.
    assert ahead.coming("a", "rG", 10.0) == "rG"


def test_a_state_not_the_programs_is_not_predicted() -> None:
    """Another client set the state (setRedYellowGreenState): SUMO's phase
    does not hold it, and nothing is predicted."""
    tl = FakeLights([phase("Gr", 10), phase("yr", 3)])
    ahead = SignalAhead(tl)
    assert ahead.coming("a", "rr", 10.0) == "rr"


def test_a_light_sumo_cannot_answer_for_keeps_its_state() -> None:
    tl = FakeLights([phase("Gr", 10), phase("yr", 3)])
    ahead = SignalAhead(tl)
    assert ahead.coming("b", "Gr", 10.0) == "Gr"
    # A program SUMO does not list, a phase index outside it.
    tl.program = "gone"
    assert ahead.coming("a", "Gr", 10.0) == "Gr"
    tl.program, tl.phase = "0", 7
    assert ahead.coming("a", "yr", 10.0) == "yr"
