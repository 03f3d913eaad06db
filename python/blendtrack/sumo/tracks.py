"""The controlled vehicles' reference tracks: each route (from a lane, with
its lane pieces and stop lines) registered once with the RouteFleet and
shared by every vehicle on it (kept while driven, and a bounded number of
the ones left for later vehicles), a track of its own for a vehicle changing
lanes, putting a vehicle on another track (retracking, rebuilding after a
reroute), and SUMO's string ids interned as the integers RouteFleet takes."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import blendtrack
from blendtrack import ControllerConfig, RouteFleet
from blendtrack.sumo.geometry import RouteGeometry, route_geometry
from blendtrack.sumo.network import Network
from blendtrack.sumo.records import VehicleRecord

#: Shared tracks nobody drives kept for the next vehicle on the same route
#: and lane, at most this many (the one left longest ago goes first): a long
#: run's track registry stays bounded by the tracks driven at once plus
#: this, and a route driven now and then is not rebuilt for each vehicle.
IDLE_TRACKS = 64
#: ... and for at most this long (simulated s) since their last vehicle left:
#: a track of a few km holds about 0.6 MB (its points, widths, corridor and
#: curve profile in Rust, the geometry in Python), so a day's morning peak
#: would otherwise leave its tracks held through the night (issue 22).
IDLE_TRACK_S = 120.0
#: A vehicle leaves its own lane-change track for a shared one once its
#: front is this far (m) into an edge after the change's: the shared track
#: starts at the edge's start, and the vehicle's rear axle (up to about 4 m
#: behind the front) and the smoothing of the track's first metres must be
#: on it (switched at 0.4 m in, a vehicle's rear axle projected before the
#: track's start and SUMO lost it off the road a few seconds later).
SHARE_AFTER_M = 15.0
#: A vehicle on a lane that fans out is put on the track of SUMO's choice
#: of junction lane (``Tracks.follow_fanout``) once its front is this far
#: (m) into the lane: its rear axle then on the lane too.
FANOUT_AFTER_M = 5.0

_Key = tuple[tuple[str, ...], int, tuple[tuple[int, int], ...]]


class Interned:
    """String ids as small integers (RouteFleet takes integers), both ways."""

    def __init__(self) -> None:
        self.ids: dict[str, int] = {}
        self.names: list[str] = []

    def id(self, name: str) -> int:
        i = self.ids.get(name)
        if i is None:
            i = self.ids[name] = len(self.names)
            self.names.append(name)
        return i

    def get(self, name: str, default: int) -> int:
        return self.ids.get(name, default)

    def name(self, i: int) -> str:
        return self.names[i]


@dataclass
class Active:
    """A vehicle under control (its state and statistics live in the RouteFleet)."""

    vid: str
    slot: int
    geo: RouteGeometry
    route_id: str
    record: VehicleRecord
    trajectory: list[tuple[float, float, float, float, float, float]] | None = None
    #: While a lane change is under way: (+1 left or -1 right, target lane index).
    changing: tuple[int, int] | None = None
    #: The change under way is one the route does not need (checked every step, see LaneChanges.changing_leader).
    tactical: bool = False
    #: The change under way: (SUMO lane position of the front where it
    #: starts, its length in m) on the lane it leaves.
    change_span: tuple[float, float] | None = None
    #: The lane index the change under way started from.
    change_from: int = -1
    #: The edge the change under way is made on.
    change_edge: str = ""
    #: The track built for this vehicle alone (a lane change in it), removed
    #: from the RouteFleet once the vehicle leaves it; None on a shared track.
    own_track: int | None = None
    #: The track the vehicle drives (shared, or its own).
    track: int = -1
    #: SUMO's route index of the first edge of the vehicle's track: its route
    #: index where blendtrack has it is this plus ``RouteFleet.occurrence``.
    route_base: int = 0


class Tracks:
    """The tracks registered with ``fleet`` and the interned lane, edge and light ids."""

    def __init__(
        self, fleet: RouteFleet, network: Network, config: ControllerConfig, border_margin_m: float, corridor: str = "lane"
    ) -> None:
        self.fleet = fleet
        self.network = network
        self.config = config
        self.border_margin_m = border_margin_m
        #: "carriageway": the virtual borders at the edges of each lane's whole edge.
        self.carriageway = corridor == "carriageway"
        #: (edges, lane index) -> the shared track of that route from that lane.
        self.geo_cache: dict[_Key, tuple[RouteGeometry, int]] = {}
        #: Shared track -> its key in geo_cache, and the vehicles on it.
        self._key: dict[int, _Key] = {}
        self._users: dict[int, int] = {}
        #: The keys of the shared tracks nobody drives, the one left longest
        #: ago first, with the simulated time it was left.
        self._idle: OrderedDict[_Key, float] = OrderedDict()
        #: The simulated time (``expire`` keeps it).
        self.now = 0.0
        self.lanes = Interned()
        self.edges = Interned()
        self.lights = Interned()
        #: The vehicles whose track has a change due early (``pending_early``),
        #: by id: ``retry_early_change`` looks at these only.
        self.early: dict[str, Active] = {}

    def note_track(self, act: Active) -> None:
        """``act`` has a new track (``act.geo``): keeps ``early`` up to date."""
        if act.geo.pending_early:
            self.early[act.vid] = act
        else:
            self.early.pop(act.vid, None)

    def geometry(
        self, edges: tuple[str, ...], lane_index: int, change: tuple[float, float] | tuple[float, float, int] | None = None,
        prefer: tuple[tuple[int, int], ...] = (),
    ) -> tuple[RouteGeometry, int]:
        """The track of a route from a lane, registered with its lane pieces and
        stop lines; shared by every vehicle on the same route and lane (a track
        with a lane change in it belongs to one vehicle). ``prefer``: (edge
        index, lane index) pairs, lanes to take where the route allows (a
        stop's; see ``geometry._pieces``), part of what is shared."""
        key = (edges, lane_index, prefer)
        hit = self.geo_cache.get(key) if change is None else None
        if hit is None:
            network = self.network
            geo = route_geometry(
                network.net(), edges, lane_index, defer_changes=True, change=change,
                border_margin_m=self.border_margin_m,
                carriageway=self.carriageway,
                prefer=dict(prefer) if prefer else None,
            )
            path = blendtrack.Path(geo.points, geo.widths, closed=False)
            lanes, edge_ids = self.lanes, self.edges
            stops = geo.stops
            network.internal_vias.update(st[4] for st in stops if st[2] < 0 and network.after_internal_junction(st[4]))
            track = self.fleet.add_route(
                path,
                self.config,
                piece_start_m=geo.piece_start_s,
                piece_scale=geo.piece_scale,
                piece_offset_m=geo.piece_offset,
                piece_lane_length_m=geo.piece_lane_length,
                piece_lane_pos_m=geo.piece_lane_pos,
                piece_speed_mps=geo.piece_speed,
                piece_lane=[lanes.id(x) for x in geo.piece_lane],
                piece_edge=[edge_ids.id(x) for x in geo.piece_edge],
                piece_lane_index=geo.piece_index,
                length_m=geo.length_m,
                stop_s_m=[st[0] for st in stops],
                stop_light=[self.lights.id(st[1]) if st[1] else -1 for st in stops],
                stop_link=[st[2] for st in stops],
                stop_major=[int(st[3]) for st in stops],
                stop_via=[lanes.id(st[4]) for st in stops],
                stop_exit_m=[st[5] for st in stops],
                stop_check_inside=[int(bool(network.junction_lanes(st[4])[1])) for st in stops],
                lane_change=(
                    (edge_ids.id(geo.edges[geo.pending_change[0]]), geo.pending_change[1], geo.pending_change[0])
                    if geo.pending_change is not None
                    else None
                ),
                piece_occurrence=geo.piece_occurrence,
                # SUMO's stations only where a turn was rounded off (the
                # track cuts inside it and SUMO's lane position jumps ahead;
                # Bologna's 58[0]). Elsewhere they follow the arc length
                # within centimetres a metre, and converting every gap with
                # them cost Eccles (no rounded turn) arrivals and collisions
                # (seeds 0-11: 0.491 -> 0.467 of plain's, 3 -> 14).
                station_m=geo.station if geo.rounded and len(geo.station) else None,
            )
            fanouts = network.fanouts()
            normal = [x for x in dict.fromkeys(geo.piece_lane) if not x.startswith(":")]
            geo.fanout_next = {a: b for a, b in zip(normal, normal[1:]) if a in fanouts}
            hit = (geo, track)
            if change is None:
                self.geo_cache[key] = hit
                self._key[track] = key
                self._idle[key] = self.now
                self._trim()
        return hit

    def enter(self, track: int) -> None:
        """A vehicle is put on ``track`` (shared ones are kept while driven)."""
        key = self._key.get(track)
        if key is not None:
            self._users[track] = self._users.get(track, 0) + 1
            self._idle.pop(key, None)

    def leave(self, track: int) -> None:
        """A vehicle left ``track`` (a shared one nobody drives is kept for
        later among the last ``IDLE_TRACKS`` left)."""
        key = self._key.get(track)
        if key is None:
            return
        n = self._users.pop(track) - 1
        if n:
            self._users[track] = n
        else:
            self._idle[key] = self.now
            self._trim()

    def expire(self, t: float) -> None:
        """At simulated time ``t``: the shared tracks nobody has driven for
        ``IDLE_TRACK_S`` go."""
        self.now = t
        idle = self._idle
        while idle and next(iter(idle.values())) < t - IDLE_TRACK_S:
            self._evict(idle.popitem(last=False)[0])

    def _trim(self) -> None:
        while len(self._idle) > IDLE_TRACKS:
            self._evict(self._idle.popitem(last=False)[0])

    def _evict(self, key: _Key) -> None:
        _, track = self.geo_cache.pop(key)
        del self._key[track]
        self.fleet.remove_route(track)

    def leave_own_track(self, act: Active) -> bool:
        """Puts ``act`` back on a shared track once it is on a track of its
        own (a lane change in it), no longer changing lanes, and on a normal
        lane of an edge after the change's (``SHARE_AFTER_M`` into it): from there on its own track is
        that lane's centreline, as the shared track of its route from that
        lane is. Its own track, about 0.6 MB for a few km of route, is freed
        now instead of when the vehicle arrives (issue 22). Where the vehicle
        is comes from blendtrack, not SUMO: just past a junction SUMO's
        ``moveToXY`` can have it on the lane beside for a step, and a track
        built from there put it a lane over. True when it was moved."""
        if act.own_track is None or act.changing is not None:
            return False
        return self.onto_shared_track(act, 1) is not None

    def retry_early_change(self, act: Active) -> bool:
        """A vehicle whose track has a change due early (``pending_early``)
        and that has passed that edge without making it: a new track from
        the lane it is on, ``SHARE_AFTER_M`` into the edge it has reached (as
        ``leave_own_track``, where blendtrack has it), with the change due on
        this edge if it still is. True when it was moved."""
        geo = act.geo
        if not geo.pending_early or geo.pending_change is None or act.changing is not None or act.own_track is not None:
            return False
        return self.onto_shared_track(act, geo.pending_change[0] + 1) is not None

    def onto_shared_track(self, act: Active, first_edge: int, stop_lane: tuple[str, int] | None = None,
                          after_m: float = SHARE_AFTER_M) -> RouteGeometry | None:
        """Puts ``act`` on the shared track of its route from the lane it is
        on, once blendtrack has its front ``SHARE_AFTER_M`` into a normal
        lane of its track's edge ``first_edge`` or a later one; with
        ``stop_lane`` (edge, lane index), the track that needs that lane at
        the next occurrence of that edge (``geometry``'s ``prefer``: a
        stop's lane). The track it is on then (moved only when that is
        another), None when it was not put on one. ``after_m``: how far into
        the lane the front must be."""
        slot = act.slot
        k = self.fleet.occurrence(slot)
        edges = act.geo.edges
        if k < first_edge or k >= len(edges):
            return None
        prefer: tuple[tuple[int, int], ...] = ()
        if stop_lane is not None:
            at = next((j for j in range(k + 1, len(edges)) if edges[j] == stop_lane[0]), None)
            if at is None:
                return None
            prefer = ((at - k, stop_lane[1]),)
        lane_id, pos = self.fleet.front_lane_position(slot)
        lane = self.lanes.names[lane_id]
        edge, _, index = lane.rpartition("_")
        if lane.startswith(":") or edges[k] != edge or not index.isdigit() or pos < after_m:
            return None
        geo, track = self.geometry(edges[k:], int(index), prefer=prefer)
        if geo is not act.geo:
            base = act.route_base + k
            self.retrack(act, geo, track, owned=False, base=base, route_index=base)
        return geo

    def fanout_lane(self, act: Active) -> str | None:
        """The lane of ``act``'s track that fans out its front is on, at
        least ``FANOUT_AFTER_M`` into it (where ``follow_fanout`` acts), or
        None."""
        if not act.geo.fanout_next:
            return None
        lane_id, pos = self.fleet.front_lane_position(act.slot)
        lane = self.lanes.names[lane_id]
        return lane if lane in act.geo.fanout_next and pos >= FANOUT_AFTER_M else None

    def follow_fanout(self, act: Active, best_lanes: Any) -> bool:
        """``act``'s front is on a lane of its track that fans out: where
        SUMO's driver will take another junction lane at its end than the
        track's (its best lanes' continuation, ``vehicle.getBestLanes``,
        which is what SUMO's movement follows), the vehicle is put on the
        track that takes that one. Otherwise SUMO carried it onto the other
        junction lane and the next move by (x, y) put it back across onto
        the track's, into whoever was there (Bologna, 30 %, seed 0, 290 s:
        43[0]_1 onto :34_0_2 instead of :34_0_1, 2.5 m across onto 43[1]_1).
        True when it was moved."""
        lane = self.fanout_lane(act)
        if lane is None or act.changing is not None or act.own_track is not None:
            return False
        ours = act.geo.fanout_next[lane]
        sumo_next = next((bl[5][1] for bl in best_lanes if bl[0] == lane and len(bl[5]) > 1), None)
        if sumo_next is None or sumo_next == ours:
            return False
        edge, _, index = sumo_next.rpartition("_")
        if edge != ours.rpartition("_")[0] or not index.isdigit():
            return False
        moved = self.onto_shared_track(act, 0, (edge, int(index)), after_m=FANOUT_AFTER_M)
        return moved is not None and moved.fanout_next.get(lane) == sumo_next

    def retrack(self, act: Active, geo: RouteGeometry, track: int, owned: bool, base: int, route_index: int | None = None) -> None:
        """Puts ``act`` on ``track`` (``owned``: built for it alone), whose
        first edge is SUMO's route index ``base``, on the lap where the
        vehicle is: its route index ``route_index``, by default the one
        blendtrack has it at (a track that drives an edge more than once
        passes its place once per lap). A track it owned before goes (nobody
        else drives it), so a long run's lane changes do not pile up tracks."""
        if route_index is None:
            route_index = act.route_base + self.fleet.occurrence(act.slot)
        occurrence = route_index - base
        self.fleet.retrack(act.slot, track, occurrence=occurrence if occurrence >= 0 else None)
        act.route_base = base
        old, act.own_track = act.own_track, (track if owned else None)
        left, act.track = act.track, track
        act.geo = geo
        self.note_track(act)
        if not owned:
            self.enter(track)
        if old is not None and old != track:
            self.fleet.remove_route(old)
        elif old is None:
            self.leave(left)

    def rebuild(self, act: Active, vehicle: Any) -> None:
        """The route changed (rerouting): a new track from where the vehicle
        is (``vehicle``: SUMO's vehicle domain)."""
        route = tuple(vehicle.getRoute(act.vid))
        idx = max(int(vehicle.getRouteIndex(act.vid)), 0)
        geo, track = self.geometry(route[idx:], max(int(vehicle.getLaneIndex(act.vid)), 0))
        # A new route: SUMO's index on it is the only one there is.
        self.retrack(act, geo, track, owned=False, base=idx, route_index=idx)
        act.route_id = vehicle.getRouteID(act.vid)
