"""The state a traffic light's links will have while SUMO moves the
vehicles in its next step.

blendtrack's moves for a step are pushed after SUMO's step to ``t`` and
take effect in SUMO's step from ``t`` to ``t + dt``. SUMO switches a light
at the start of that step, before it moves any vehicle, whenever the
light's next switch (``trafficlight.getNextSwitch``) is at ``t`` or before:
the move then runs under the next phase's state, not the state read at
``t``. SUMO's own drivers plan under the new state. Planned under the old
one, a controlled car saw each yellow one step late; at Bologna's 1 s step
a 3 s yellow left it two steps. It went at yellow because it could not stop,
braked for the tight turn just past the line, and its front crossed the
line in the step that ran under red (tls 210, link 15, seed 26 at 582 s).

:class:`SignalAhead` gives that coming state where it is certain:

- a static program (its phases keep their durations), or a phase whose
  ``minDur`` equals its ``maxDur`` in any other program (an actuated
  program's yellow and all-red phases): the switch is at the time SUMO
  reports;
- the next phase is the one after it in the program (or its single
  ``next``; several ``next`` phases only where they agree on the state).

Anywhere else (an actuated green that may be extended, a state set by
another client with ``setRedYellowGreenState``, a program unknown) the
state read now stands, as before. The times are read only when a light's
state changes or its last known switch has passed (``getNextSwitch``,
``getPhase``, ``getProgram``; the programs once each), so another client's
``setPhaseDuration`` is seen at the latest one step after the switch time
blendtrack knew.
"""

from __future__ import annotations

from typing import Any

#: libsumo's type of a static (fixed-time) program.
STATIC_PROGRAM = 0
#: Times closer than this are equal (s).
TIME_EPS_S = 1e-6


class SignalAhead:
    """Per light: the state its links will have during SUMO's next step."""

    def __init__(self, trafficlight: Any) -> None:
        self._tl = trafficlight
        #: light -> (state read, next switch (s), the next phase's state or None).
        self._known: dict[str, tuple[str, float, str | None]] = {}
        #: (light, program) -> (program type, phases as (state, fixed, next indices)).
        self._programs: dict[tuple[str, str], tuple[int, list[tuple[str, bool, tuple[int, ...]]]]] = {}

    def coming(self, tls: str, state: str, t: float) -> str:
        """The state of light ``tls`` (read as ``state`` at time ``t``)
        during SUMO's step from ``t``: the next phase's if the light
        certainly switches at the start of it, else ``state``."""
        known = self._known.get(tls)
        if known is None or known[0] != state or t > known[1] + TIME_EPS_S:
            known = self._read(tls, state)
            self._known[tls] = known
        nxt = known[2]
        if nxt is not None and known[1] <= t + TIME_EPS_S:
            return nxt
        return state

    def _read(self, tls: str, state: str) -> tuple[str, float, str | None]:
        tl = self._tl
        try:
            switch = float(tl.getNextSwitch(tls))
            phase = int(tl.getPhase(tls))
            program = str(tl.getProgram(tls))
            kind, phases = self._program(tls, program)
        except Exception:
            # A light SUMO no longer knows, a program it cannot list: the
            # state read stands.
            return (state, float("inf"), None)
        if not 0 <= phase < len(phases):
            return (state, switch, None)
        here, fixed, nexts = phases[phase]
        if here != state or not (kind == STATIC_PROGRAM or fixed):
            # Another client's state, or a phase that may be extended.
            return (state, switch, None)
        targets = {phases[j][0] for j in nexts if 0 <= j < len(phases)}
        if len(targets) != 1 or len(next(iter(targets))) != len(state):
            return (state, switch, None)
        return (state, switch, targets.pop())

    def _program(self, tls: str, program: str) -> tuple[int, list[tuple[str, bool, tuple[int, ...]]]]:
        key = (tls, program)
        cached = self._programs.get(key)
        if cached is not None:
            return cached
        found: tuple[int, list[tuple[str, bool, tuple[int, ...]]]] = (-1, [])
        for logic in self._tl.getAllProgramLogics(tls):
            if str(logic.programID) != program:
                continue
            raw = list(logic.phases)
            phases = []
            for k, p in enumerate(raw):
                nexts = tuple(int(j) for j in (p.next or ()) if int(j) >= 0) or ((k + 1) % len(raw),)
                phases.append((str(p.state), float(p.minDur) == float(p.maxDur), nexts))
            found = (int(logic.type), phases)
            break
        self._programs[key] = found
        return found
