//! Driving road routes inside a traffic simulator, many vehicles per call.
//!
//! [`RouteFleet`] wraps a [`Fleet`] with what a vehicle needs to drive a road
//! route among other traffic, so that a simulator bridge (the SUMO plugin)
//! is left with reading the simulator and writing poses back:
//!
//! - a [`Route`] per track: the lane pieces along the track (where each lane
//!   starts in arc length, its speed limit, how arc length maps to the
//!   simulator's lane position, how far the track strays from that lane's
//!   centreline) and the stop lines of the junctions ahead, each
//!   with its traffic light link or its right of way by the road network;
//! - per vehicle: its state (blendtrack's state is authoritative: the bridge
//!   never passes it back in), the arc length of its front bumper, the next
//!   stop line, a yellow-light decision that holds until the light changes,
//!   and the statistics a report needs (lateral error, jerk, lateral
//!   acceleration against a comfort limit, warnings, red-light crossings).
//!
//! One simulation step is two calls:
//! 1. [`RouteFleet::plan`] takes the leaders the simulator reports (gap, and
//!    either the leader's slot when blendtrack drives it or its speed) and
//!    decides each vehicle's stop line: red stops; yellow stops when the
//!    stopping law manages it at the planning deceleration; a link without
//!    priority needs the simulator's word on approaching foes, so `plan`
//!    returns the vehicles to ask about; any link waits when the vehicle's
//!    leader leaves no room behind it beyond the junction (keep the junction
//!    clear); the end of the route is a standing obstacle only with
//!    `stop_at_route_end` (SUMO's drivers leave at speed).
//! 2. [`RouteFleet::step`] takes the answers, runs the controllers and the
//!    bicycle model for everyone, and returns for each vehicle how to put the
//!    new pose into the simulator, cheapest first: [`Move::Hold`] (nothing to
//!    send), [`Move::Speed`] (only a speed: the simulator's own movement
//!    carries the vehicle to its new place), [`Move::Lane`] (lane and lane
//!    position, then the speed), [`Move::Xy`] (front-bumper point and
//!    heading, then the speed), or [`Move::Invalid`] (unusable state: hand
//!    the vehicle back).
//!
//! Control rate. The controllers and the bicycle model run at their own
//! rate, not the simulator's: [`RouteFleet::step`] over a simulator step of
//! `dt` runs `n = ceil(dt / control_dt)` control steps of `h = dt / n`
//! (`control_dt` in [`TrafficSettings`]). What the simulator reported at the
//! start of its step is held for the whole step: each leader drives on at
//! the speed it was observed at (its gap grows by its speed times `h` and
//! shrinks by the vehicle's own advance each control step), stop lines stay
//! where they are (their gap shrinks by the vehicle's advance), the stop-line
//! decisions and speed limits of the plan hold. A leader's gap is the
//! simulator's, so the vehicle's advance it loses is the simulator's too: on
//! a track with [`Stations`] the gain of the simulator's station, not the arc
//! length, and the control law is given the arc length that uses the gap up
//! ([`Route::arc_gap`]; where the track cuts a sharp corner the simulator has
//! the vehicle jump ahead). Statistics take every control
//! step (weighted by `h` where they are times or distances, one sample each
//! in the means, so means are time-weighted). The move into the simulator is
//! chosen once, from the final state. With `control_dt >= dt` (`n = 1`) a step
//! is one control step over `dt`.
//!
//! Lane positions. A vehicle is given to the simulator by lane while its
//! control point is within `lane_move_lateral_m` (minus the track's own
//! offset from the lane's centreline, [`Piece::offset_m`]) and
//! `lane_move_heading_rad` of the track, and by (x, y) otherwise (lane
//! changes, junction lanes the track does not follow, larger errors).
//! By lane, blendtrack knows where the simulator has the front after its
//! movement (`known`): a simulator that moves a vehicle `speed x dt` along
//! its lanes in a step (SUMO with speed mode 0, Euler update) then needs no
//! position at all, only the speed that makes up the distance from there to
//! the front's new lane position (within `GLIDE_TOLERANCE_*` of the
//! vehicle's own, which keeps the simulator's reported speed honest); one
//! that would need more is placed with [`Move::Lane`] at the new position
//! minus `v dt` (before the simulator's movement), never behind where the
//! simulator already has it, so a follower never sees its leader jump
//! backwards. After a move over a lane end, an (x, y) move or a placement
//! onto another lane, the position is unknown until the bridge reports it
//! ([`RouteOutputs::read_position`]); every `verify_every` steps it reports
//! it anyway, so a prediction that went wrong is corrected.
//!
//! Lanes, edges, junction lanes and traffic lights are small integers of the
//! caller's choosing (the bridge interns the simulator's string ids).
//! Signal states are [`Signal`]s, one per link of a light.

// Checks are written `!(x > 0.0)` on purpose: a NaN fails every comparison,
// so it takes the "bad input" branch; `x <= 0.0` would let it through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod error;
mod placement;
mod plan;
mod route;
mod signal;
mod stats;
mod step;
mod stops;
mod substep;
#[cfg(test)]
mod testkit;

pub use error::TrafficError;
pub use placement::Move;
pub use plan::{can_stop, Observations, SoftLeaders};
pub use route::{LaneChangeDue, Piece, Route, Stations, StopLine};
pub use signal::Signal;
pub use stats::DriveStats;
pub use step::RouteOutputs;
pub use stops::HALT_CREEP_M;
pub use substep::HOLD_BRAKING_MIN_STEP_S;

use blendtrack::{ControllerConfig, Fleet, Path, VehicleParams, VehicleState};
use error::check_len;
use nalgebra::Point2;
use plan::Plan;
use signal::MAX_LIGHTS;
use std::sync::Arc;

/// Dimensions of a driven vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Rear axle to front bumper (m).
    pub reach_m: f64,
    pub length_m: f64,
    /// The simulator's standstill gap (m).
    pub min_gap_m: f64,
}

/// Thresholds of the bridge; the defaults are the SUMO plugin's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrafficSettings {
    /// Extra distance kept to leaders and stop lines at standstill (m).
    pub standstill_margin_m: f64,
    /// How far before a link without priority foes are asked about (m).
    pub yield_lookahead_m: f64,
    /// Room kept before a lane's end when a lane change is due (m).
    pub lane_change_room_m: f64,
    /// Whether the end of the route is a standing obstacle. SUMO's drivers
    /// leave the network at their route's end without slowing down (its
    /// default `arrivalSpeed="current"`), so by default blendtrack's do too;
    /// with this set a vehicle stops at its route's end, like the end of a
    /// race track's path in the paper.
    pub stop_at_route_end: bool,
    /// With `stop_at_route_end`, the end of the route is an obstacle this far
    /// past the track's end (m)...
    pub route_end_extra_m: f64,
    /// ... once it is closer than this (m).
    pub route_end_horizon_m: f64,
    /// Below these errors of the control point a vehicle moves as (lane, position).
    pub lane_move_lateral_m: f64,
    pub lane_move_heading_rad: f64,
    /// Lateral acceleration above which time is counted as uncomfortable (m/s^2).
    pub comfort_lateral_accel_mps2: f64,
    /// Every this many steps of a vehicle, one (|curvature|, |v|, |e|, |a_lat|) sample is kept.
    pub sample_every: u64,
    /// Every this many steps of a vehicle the bridge reads where the
    /// simulator has it, to check the prediction (0: only where unknown).
    pub verify_every: u64,
    /// The control rate (s, > 0): a [`RouteFleet::step`] over `dt` runs the
    /// controllers and the bicycle model `n = ceil(dt / control_dt)` times
    /// over `dt / n` each, with leaders and stop lines held for the step
    /// (see the module docs); `control_dt >= dt` gives one control step.
    pub control_dt_s: f64,
    /// How the simulator moves a vehicle over a step it was sent a speed
    /// for: false, at that speed (SUMO's default, semi-implicit Euler);
    /// true, at the mean of its speeds at the step's start and end (SUMO's
    /// `--step-method.ballistic`). Speed-only and lane-position moves are
    /// worked out for it ([`RouteFleet::set_ballistic`]).
    pub ballistic: bool,
}

impl Default for TrafficSettings {
    fn default() -> Self {
        TrafficSettings {
            standstill_margin_m: 1.0,
            yield_lookahead_m: 30.0,
            lane_change_room_m: 15.0,
            stop_at_route_end: false,
            route_end_extra_m: 5.0,
            route_end_horizon_m: 200.0,
            lane_move_lateral_m: 0.15,
            lane_move_heading_rad: 2.0_f64.to_radians(),
            comfort_lateral_accel_mps2: 2.0,
            sample_every: 10,
            verify_every: 10,
            control_dt_s: 0.05,
            ballistic: false,
        }
    }
}

#[derive(Debug, Clone)]
struct Driven {
    route: Arc<Route>,
    body: Body,
    state: VehicleState,
    s_front_m: f64,
    /// The segment of the path holding `s_front_m` (a look-up guess).
    seg_front: usize,
    next_stop: usize,
    /// (stop index, stop?) decided when the light ahead turned yellow.
    yellow: Option<(usize, bool)>,
    /// The stop line the vehicle waits at to give way or keep the junction
    /// clear. Once decided it holds while the reason lasts, even where the
    /// stopping law brakes harder than the planning deceleration (it does,
    /// just before the line): re-deciding "can it still stop?" every step
    /// would let the vehicle roll into the junction at the last moment.
    holding: Option<usize>,
    /// Where the simulator has the front after its movement over the last
    /// step, (lane, position): predicted from the last move, or read back by
    /// the bridge; None when unknown.
    known: Option<(u32, f64)>,
    /// The speed last sent to the simulator (NaN before the first).
    sumo_speed: f64,
    /// The front pose (x, y, heading) the last move by (x, y) sent, while
    /// no other move has followed it (a [`Move::Hold`] keeps it).
    placed_xy: Option<(f64, f64, f64)>,
    /// Arc length where the caller wants the front to stop (a SUMO
    /// `<stop>`), NaN when none; see [`RouteFleet::set_halt`].
    halt_m: f64,
    /// The speed a follower holds this vehicle at over the next step (see
    /// [`substep::braking_mean_speed`]); NaN before its first step.
    lead_speed: f64,
    /// Simulator steps the vehicle was moved in (its statistics count
    /// control steps, more than these when a step is sub-stepped).
    steps: u64,
    stats: DriveStats,
}

/// The most (m) [`RouteFleet::advance_state`] moves a vehicle on: further
/// is a lost vehicle, not a lag (the bridge's placement check hands back
/// one more than 5 m off).
pub const ADVANCE_MAX_M: f64 = 5.0;

/// A [`Fleet`] driving road routes (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct RouteFleet {
    fleet: Fleet,
    settings: TrafficSettings,
    routes: Vec<Option<Arc<Route>>>,
    driven: Vec<Option<Driven>>,
    signals: Vec<Vec<Signal>>,
    plan: Option<Plan>,
    samples: Vec<[f64; 4]>,
}

impl RouteFleet {
    pub fn new(settings: TrafficSettings) -> Result<Self, TrafficError> {
        let checks: [(&'static str, f64, bool); 9] = [
            ("standstill_margin_m", settings.standstill_margin_m, false),
            ("yield_lookahead_m", settings.yield_lookahead_m, false),
            ("lane_change_room_m", settings.lane_change_room_m, false),
            ("route_end_extra_m", settings.route_end_extra_m, false),
            ("route_end_horizon_m", settings.route_end_horizon_m, false),
            ("lane_move_lateral_m", settings.lane_move_lateral_m, false),
            (
                "lane_move_heading_rad",
                settings.lane_move_heading_rad,
                false,
            ),
            (
                "comfort_lateral_accel_mps2",
                settings.comfort_lateral_accel_mps2,
                true,
            ),
            ("control_dt_s", settings.control_dt_s, true),
        ];
        for (name, value, strict) in checks {
            if !(value.is_finite() && if strict { value > 0.0 } else { value >= 0.0 }) {
                return Err(TrafficError::Parameter {
                    name,
                    value,
                    message: if strict {
                        "must be finite and > 0"
                    } else {
                        "must be finite and >= 0"
                    },
                });
            }
        }
        Ok(RouteFleet {
            settings: TrafficSettings {
                sample_every: settings.sample_every.max(1),
                ..settings
            },
            ..Default::default()
        })
    }

    pub fn settings(&self) -> &TrafficSettings {
        &self.settings
    }
    /// Whether the simulator's position update is ballistic (see
    /// [`TrafficSettings::ballistic`]): the bridge knows only once the
    /// simulator runs.
    pub fn set_ballistic(&mut self, ballistic: bool) {
        self.settings.ballistic = ballistic;
    }
    pub fn fleet(&self) -> &Fleet {
        &self.fleet
    }
    /// See [`Fleet::set_threads`].
    pub fn set_threads(&mut self, threads: usize) {
        self.fleet.set_threads(threads);
    }
    pub fn len(&self) -> usize {
        self.fleet.len()
    }
    pub fn is_empty(&self) -> bool {
        self.fleet.is_empty()
    }

    /// Registers a track with its route; returns the track id.
    pub fn add_route(
        &mut self,
        path: Path,
        config: ControllerConfig,
        route: Route,
    ) -> Result<usize, TrafficError> {
        let id = self.fleet.add_track(path, config)?;
        if self.routes.len() <= id {
            self.routes.resize(id + 1, None);
        }
        self.routes[id] = Some(Arc::new(route));
        Ok(id)
    }

    /// Removes a track (and its route) that no vehicle drives any more,
    /// e.g. one built for a single vehicle's lane change once it has moved
    /// on; see [`Fleet::remove_track`].
    pub fn remove_route(&mut self, track_id: i64) -> Result<(), TrafficError> {
        self.fleet.remove_track(track_id)?;
        self.routes[track_id as usize] = None;
        Ok(())
    }

    fn route_of_track(&self, track_id: i64) -> Result<Arc<Route>, TrafficError> {
        self.fleet.track(track_id)?;
        Ok(self.routes[track_id as usize]
            .clone()
            .expect("every track is added with a route"))
    }

    /// The arc length of the front of a vehicle at `state` on a track. On a
    /// track that drives an edge more than once it is searched among the
    /// pieces of `occurrence` only (when given and on the track): the other
    /// laps pass the same place. Elsewhere it is the nearest point of the
    /// whole track. Also says whether the search was so limited.
    fn front_arc(
        &self,
        track_id: i64,
        state: &VehicleState,
        reach_m: f64,
        occurrence: Option<u32>,
    ) -> Result<(f64, bool), TrafficError> {
        let path = &self.fleet.track(track_id)?.path;
        let route = self.route_of_track(track_id)?;
        let front = Point2::new(
            state.x_m + reach_m * state.theta_rad.cos(),
            state.y_m + reach_m * state.theta_rad.sin(),
        );
        if route.revisits_an_edge() {
            if let Some((from, to)) = occurrence.and_then(|k| route.occurrence_span(k)) {
                return Ok((path.project_between(&front, from, to).s, true));
            }
        }
        Ok((path.project(&front).s, false))
    }

    /// Adds a vehicle at `state` (its rear axle) on a track; returns its
    /// slot. `occurrence`: on a track that drives its edge more than once
    /// (see [`Piece::occurrence`]), the lap the vehicle is placed on, where
    /// its controller's first projections start; None: the first.
    pub fn add_vehicle(
        &mut self,
        track_id: i64,
        config: Option<ControllerConfig>,
        params: Option<VehicleParams>,
        body: Body,
        state: VehicleState,
        occurrence: Option<u32>,
    ) -> Result<usize, TrafficError> {
        for (name, value) in [
            ("x", state.x_m),
            ("y", state.y_m),
            ("theta", state.theta_rad),
            ("v", state.v_mps),
            ("delta", state.delta_rad),
            ("reach_m", body.reach_m),
            ("length_m", body.length_m),
            ("min_gap_m", body.min_gap_m),
        ] {
            if !value.is_finite() {
                return Err(TrafficError::Parameter {
                    name,
                    value,
                    message: "must be finite",
                });
            }
        }
        let route = self.route_of_track(track_id)?;
        let (s_front_m, on_lap) = self.front_arc(track_id, &state, body.reach_m, occurrence)?;
        let slot = self.fleet.add_vehicle(track_id, config, params)?;
        if on_lap {
            self.fleet
                .seed_vehicle_hints(slot as i64, s_front_m - body.reach_m)?;
        }
        if self.driven.len() <= slot {
            self.driven.resize(slot + 1, None);
        }
        self.driven[slot] = Some(Driven {
            route,
            body,
            state,
            s_front_m,
            seg_front: usize::MAX,
            next_stop: 0,
            yellow: None,
            holding: None,
            known: None,
            sumo_speed: f64::NAN,
            placed_xy: None,
            halt_m: f64::NAN,
            lead_speed: f64::NAN,
            steps: 0,
            stats: DriveStats::default(),
        });
        Ok(slot)
    }

    fn driven(&self, slot: i64) -> Result<&Driven, TrafficError> {
        self.fleet.vehicle_track(slot)?;
        self.driven[slot as usize]
            .as_ref()
            .ok_or(TrafficError::NoRoute { slot })
    }

    /// Moves a vehicle to another track (a lane change, a new route); its
    /// state and statistics stay, its stop lines start over, its halt goes.
    pub fn retrack(&mut self, slot: i64, track_id: i64) -> Result<(), TrafficError> {
        self.retrack_at(slot, track_id, None)
    }

    /// [`Self::retrack`] onto occurrence `occurrence` of the vehicle's edge
    /// on the new track (see [`Self::add_vehicle`]).
    pub fn retrack_at(
        &mut self,
        slot: i64,
        track_id: i64,
        occurrence: Option<u32>,
    ) -> Result<(), TrafficError> {
        let route = self.route_of_track(track_id)?;
        let d = self.driven(slot)?;
        let reach_m = d.body.reach_m;
        let (s_front_m, on_lap) = self.front_arc(track_id, &d.state, reach_m, occurrence)?;
        self.fleet.set_vehicle_track(slot, track_id)?;
        if on_lap {
            self.fleet.seed_vehicle_hints(slot, s_front_m - reach_m)?;
        }
        let d = self.driven[slot as usize].as_mut().expect("checked above");
        d.route = route;
        d.s_front_m = s_front_m;
        d.seg_front = usize::MAX;
        d.next_stop = 0;
        d.yellow = None;
        d.holding = None;
        d.halt_m = f64::NAN;
        d.placed_xy = None;
        self.plan = None;
        Ok(())
    }

    /// Moves vehicle `slot`'s state `by_m` metres on along its heading
    /// (`0 <= by_m <=` [`ADVANCE_MAX_M`]), to where the simulator has its
    /// front, before a [`Self::retrack`] onto a lane change: a speed-only
    /// move lets the simulator run a little ahead in a stop-and-go crawl,
    /// and the change's first move by (x, y), from blendtrack's state, put
    /// the car back onto the driver behind it (Eccles, seed 0, 459 s: 2.2 m
    /// back, a collision). Its front's place on the track is found again by
    /// the retrack; call one after this. An argument out of range changes
    /// nothing and is an error.
    pub fn advance_state(&mut self, slot: i64, by_m: f64) -> Result<(), TrafficError> {
        if !(0.0..=ADVANCE_MAX_M).contains(&by_m) {
            return Err(TrafficError::Parameter {
                name: "by_m",
                value: by_m,
                message: "must be between 0 and 5 m",
            });
        }
        self.driven(slot)?;
        let d = self.driven[slot as usize].as_mut().expect("checked above");
        d.state.x_m += by_m * d.state.theta_rad.cos();
        d.state.y_m += by_m * d.state.theta_rad.sin();
        d.placed_xy = None;
        self.plan = None;
        Ok(())
    }

    /// Frees a slot; returns the vehicle's statistics.
    pub fn remove_vehicle(&mut self, slot: i64) -> Result<DriveStats, TrafficError> {
        let stats = self.driven(slot)?.stats;
        self.fleet.remove_vehicle(slot)?;
        self.driven[slot as usize] = None;
        self.plan = None;
        Ok(stats)
    }

    pub fn stats(&self, slot: i64) -> Result<DriveStats, TrafficError> {
        Ok(self.driven(slot)?.stats)
    }
    pub fn state(&self, slot: i64) -> Result<VehicleState, TrafficError> {
        Ok(self.driven(slot)?.state)
    }
    /// Arc length of the vehicle's front bumper on its track (m).
    pub fn s_front(&self, slot: i64) -> Result<f64, TrafficError> {
        Ok(self.driven(slot)?.s_front_m)
    }
    /// The occurrence (see [`Piece::occurrence`]) of the piece holding the
    /// vehicle's front: the simulator's route index, less that of the
    /// track's first edge, where blendtrack has the vehicle.
    pub fn occurrence(&self, slot: i64) -> Result<u32, TrafficError> {
        let d = self.driven(slot)?;
        Ok(d.route.occurrence_at(d.s_front_m))
    }
    /// The simulator's lane and lane position of the vehicle's front, where
    /// blendtrack has it (see [`Route::lane_position`]).
    pub fn front_lane_position(&self, slot: i64) -> Result<(u32, f64), TrafficError> {
        let d = self.driven(slot)?;
        Ok(d.route.lane_position(d.s_front_m))
    }
    /// The occurrences of the pieces of the vehicle's track within `slack_m`
    /// of its front (see [`Route::occurrences_near`]).
    pub fn occurrences_near_front(
        &self,
        slot: i64,
        slack_m: f64,
    ) -> Result<Vec<u32>, TrafficError> {
        let d = self.driven(slot)?;
        Ok(d.route.occurrences_near(d.s_front_m, slack_m).collect())
    }
    /// The arc length on the vehicle's track of lane position `pos` on lane
    /// `lane`, at or after `s_from` (see [`Route::arc_at_lane_position`]).
    pub fn arc_at_lane_position(
        &self,
        slot: i64,
        lane: u32,
        pos: f64,
        s_from: f64,
    ) -> Result<Option<f64>, TrafficError> {
        Ok(self
            .driven(slot)?
            .route
            .arc_at_lane_position(lane, pos, s_from))
    }
    /// The stop line ahead of the vehicle (the one its plan looked at).
    pub fn next_stop(&self, slot: i64) -> Result<Option<StopLine>, TrafficError> {
        let d = self.driven(slot)?;
        Ok(d.route.stops.get(d.next_stop).copied())
    }
    /// Where the tracks of `slots` enter junctions ahead: for each stop line
    /// at most `max_m` ahead of a vehicle's front and not behind it, (the
    /// index into `slots`, the line's [`StopLine::via`], the distance from
    /// the front to the line), each vehicle's nearest first. A caller asks
    /// which of its own vehicles approach a link, wherever the simulator
    /// has them (a foe a link's lane in does not show).
    pub fn stops_ahead(
        &self,
        slots: &[i64],
        max_m: f64,
    ) -> Result<Vec<(usize, u32, f64)>, TrafficError> {
        if max_m.is_nan() {
            return Err(TrafficError::Parameter {
                name: "max_m",
                value: max_m,
                message: "must not be NaN",
            });
        }
        let mut out = Vec::new();
        for (k, &slot) in slots.iter().enumerate() {
            let d = self.driven(slot)?;
            let stops = &d.route.stops;
            for stop in &stops[d.next_stop.min(stops.len())..] {
                let gap = stop.s_m - d.s_front_m;
                if gap > max_m {
                    break;
                }
                if gap >= 0.0 {
                    out.push((k, stop.via, gap));
                }
            }
        }
        Ok(out)
    }
    pub fn vehicle_config(&self, slot: i64) -> Result<&ControllerConfig, TrafficError> {
        Ok(self.fleet.vehicle_config(slot)?)
    }
    pub fn vehicle_params(&self, slot: i64) -> Result<&VehicleParams, TrafficError> {
        Ok(self.fleet.vehicle_params(slot)?)
    }

    /// Sets the state of every link of a light. Lights are the caller's small
    /// integers (below 2^20); one never set counts as green with priority.
    pub fn set_signal(&mut self, light: usize, links: &[Signal]) -> Result<(), TrafficError> {
        if light >= MAX_LIGHTS {
            return Err(TrafficError::UnknownLight { light });
        }
        if light >= self.signals.len() {
            self.signals.resize(light + 1, Vec::new());
        }
        self.signals[light].clear();
        self.signals[light].extend_from_slice(links);
        Ok(())
    }

    /// The lanes on which at least two of `slots` are, where blendtrack knows
    /// where the simulator has them (sorted, each once): the lanes whose
    /// vehicle lists [`RouteFleet::leaders_on_lanes`] can read leaders from.
    pub fn lanes_with_followers(&self, slots: &[i64]) -> Result<Vec<u32>, TrafficError> {
        let mut lanes = Vec::with_capacity(slots.len());
        for &slot in slots {
            if let Some((lane, _)) = self.driven(slot)?.known {
                lanes.push(lane);
            }
        }
        lanes.sort_unstable();
        let mut out = Vec::new();
        let mut k = 0;
        while k < lanes.len() {
            let j = lanes[k..].iter().take_while(|&&l| l == lanes[k]).count();
            if j >= 2 {
                out.push(lanes[k]);
            }
            k += j;
        }
        Ok(out)
    }

    /// Leaders read off the simulator's lists of the vehicles on lanes (back
    /// to front; an entry is the slot of a vehicle driven here, or None for
    /// any other): where a listed slot's lane is one of `lanes` and the
    /// vehicle in front of it there is one driven here whose place is known,
    /// its leader is that vehicle and the gap is the simulator's (the
    /// leader's back minus the front minus minGap), exactly what the
    /// simulator's own leader query gives for a leader on the same lane.
    /// Returns, per entry of `slots`, (leader slot, gap) or None where only
    /// the simulator can tell (first on its lane, a leader not driven here,
    /// a place not known or not where the list has it).
    pub fn leaders_on_lanes(
        &self,
        slots: &[i64],
        lanes: &[u32],
        vehicles: &[Vec<Option<i64>>],
    ) -> Result<Vec<Option<(i64, f64)>>, TrafficError> {
        check_len("vehicles", lanes.len(), vehicles.len())?;
        let mut index = vec![usize::MAX; self.driven.len()];
        for (i, &slot) in slots.iter().enumerate() {
            self.driven(slot)?;
            index[slot as usize] = i;
        }
        let known_on = |slot: i64, lane: u32| -> Option<&Driven> {
            let d = usize::try_from(slot)
                .ok()
                .and_then(|s| self.driven.get(s))
                .and_then(Option::as_ref)?;
            matches!(d.known, Some((l, _)) if l == lane).then_some(d)
        };
        let mut out = vec![None; slots.len()];
        for (&lane, list) in lanes.iter().zip(vehicles) {
            for pair in list.windows(2) {
                let (Some(f), Some(l)) = (pair[0], pair[1]) else {
                    continue;
                };
                let Some(&i) = usize::try_from(f).ok().and_then(|f| index.get(f)) else {
                    continue;
                };
                if i == usize::MAX {
                    continue;
                }
                if let (Some(df), Some(dl)) = (known_on(f, lane), known_on(l, lane)) {
                    let (pf, pl) = (df.known.expect("matched").1, dl.known.expect("matched").1);
                    out[i] = Some((l, pl - dl.body.length_m - pf - df.body.min_gap_m));
                }
            }
        }
        Ok(out)
    }

    /// Takes the `(|curvature|, |v|, |e|, |lateral acceleration|)` samples kept so far.
    pub fn take_samples(&mut self) -> Vec<[f64; 4]> {
        std::mem::take(&mut self.samples)
    }
}

#[cfg(test)]
mod tests {
    use crate::testkit::*;
    use crate::*;
    use blendtrack::FleetError;

    #[test]
    fn stops_ahead_lists_the_lines_within_reach_of_each_front() {
        // The road's one line is at 200 m; a front at 150 + 3.5 m is
        // 46.5 m from it, one at 205 + 3.5 m is past it.
        let (mut f, t) = fleet_on(road(None, false));
        let a = f
            .add_vehicle(t, None, None, body(), at(150.0, 0.0), None)
            .unwrap() as i64;
        let b = f
            .add_vehicle(t, None, None, body(), at(205.0, 0.0), None)
            .unwrap() as i64;
        let got = f.stops_ahead(&[b, a], 100.0).unwrap();
        assert_eq!(got.len(), 1);
        assert_eq!((got[0].0, got[0].1), (1, 11));
        assert!((got[0].2 - 46.5).abs() < 1e-9, "{}", got[0].2);
        assert!(f.stops_ahead(&[a], 46.0).unwrap().is_empty());
        assert!(matches!(
            f.stops_ahead(&[a], f64::NAN),
            Err(TrafficError::Parameter { name: "max_m", .. })
        ));
        assert!(f.stops_ahead(&[a, 99], 100.0).is_err());
    }

    #[test]
    fn settings_are_the_fleets_own() {
        let (f, _) = fleet_with(road(None, true), one_control_step());
        assert_eq!(f.settings().control_dt_s, DT);
        assert_ne!(TrafficSettings::default().control_dt_s, DT);
    }

    #[test]
    fn the_front_is_reach_ahead_along_the_heading() {
        // Rear axle at x = 50 on the straight road, heading 0.5 rad off it:
        // the front point, 3.5 m ahead along the heading, projects to
        // x = 50 + 3.5 cos 0.5.
        let (mut f, t) = fleet_on(road(None, true));
        let mut st = at(50.0, 0.0);
        st.theta_rad = 0.5;
        let a = f.add_vehicle(t, None, None, body(), st, None).unwrap() as i64;
        let want = 50.0 + 3.5 * 0.5f64.cos();
        assert!(
            (f.s_front(a).unwrap() - want).abs() < 1e-9,
            "{}",
            f.s_front(a).unwrap()
        );
    }

    #[test]
    fn the_lane_speed_limit_caps_a_faster_preferred_speed() {
        // The road's lanes allow 20 m/s; the driver would go 30. Starting
        // at 19 m/s, 40 s later it drives at the limit, not above it.
        let mut f = RouteFleet::new(one_control_step()).unwrap();
        let cfg = ControllerConfig {
            preferred_speed: 30.0,
            ..Default::default()
        };
        let (path, route) = road(None, true);
        let t = f.add_route(path, cfg, route).unwrap() as i64;
        let a = f
            .add_vehicle(t, None, None, body(), at(10.0, 19.0), None)
            .unwrap() as i64;
        let mut top: f64 = 0.0;
        for _ in 0..400 {
            step(&mut f, &[a], false);
            top = top.max(f.state(a).unwrap().v_mps);
        }
        assert!(top <= 20.0 + 1e-9 && top > 19.0, "{top}");
    }

    /// A fleet on the test road, with a second track of the same road.
    fn fleet_on_two_tracks() -> (RouteFleet, i64, i64) {
        let (mut f, t) = fleet_on(road(None, true));
        let (path, route) = road(None, true);
        let t2 = f
            .add_route(path, ControllerConfig::default(), route)
            .unwrap() as i64;
        (f, t, t2)
    }

    #[test]
    fn retrack_keeps_state_and_statistics() {
        let (mut f, t, t2) = fleet_on_two_tracks();
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0), None)
            .unwrap() as i64;
        for _ in 0..5 {
            step(&mut f, &[a], false);
        }
        let before = (
            f.state(a).unwrap(),
            f.stats(a).unwrap(),
            f.s_front(a).unwrap(),
        );
        f.retrack(a, t2).unwrap();
        assert_eq!(f.fleet().vehicle_track(a).unwrap(), t2 as usize);
        assert_eq!(
            (f.state(a).unwrap(), f.stats(a).unwrap()),
            (before.0, before.1)
        );
        assert!(
            (f.s_front(a).unwrap() - before.2).abs() < 1e-6,
            "{} {}",
            f.s_front(a).unwrap(),
            before.2
        );
        assert_eq!(
            f.vehicle_config(a).unwrap().preferred_speed,
            15.0,
            "the vehicle's own config stays"
        );
    }

    #[test]
    fn advance_state_moves_the_state_on_along_its_heading_then_retrack_finds_the_front() {
        // The test road runs along x: 2.5 m on is 2.5 m of x and of the
        // front's arc length once retracked; out of range changes nothing.
        let (mut f, t, t2) = fleet_on_two_tracks();
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 1.0), None)
            .unwrap() as i64;
        let (s0, sf0) = (f.state(a).unwrap(), f.s_front(a).unwrap());
        for bad in [-0.1, 5.0 + 1e-9, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                f.advance_state(a, bad),
                Err(TrafficError::Parameter { name: "by_m", .. })
            ));
            assert_eq!(f.state(a).unwrap(), s0, "{bad}");
        }
        assert!(f.advance_state(99, 1.0).is_err());
        f.advance_state(a, 2.5).unwrap();
        let s1 = f.state(a).unwrap();
        assert!((s1.x_m - s0.x_m - 2.5).abs() < 1e-12 && (s1.y_m - s0.y_m).abs() < 1e-12);
        assert_eq!((s1.v_mps, s1.theta_rad), (s0.v_mps, s0.theta_rad));
        f.retrack(a, t2).unwrap();
        assert!((f.s_front(a).unwrap() - sf0 - 2.5).abs() < 1e-6);
    }

    #[test]
    fn bad_calls_are_errors_and_change_nothing() {
        let (mut f, t) = fleet_on(road(None, false));
        let a = f
            .add_vehicle(t, None, None, body(), at(150.0, 8.0), None)
            .unwrap() as i64;
        assert_eq!(f.step(&[], DT), Err(TrafficError::NoPlan));
        assert!(matches!(
            f.add_vehicle(t, None, None, body(), at(f64::NAN, 1.0), None),
            Err(TrafficError::Parameter { name: "x", .. })
        ));
        assert!(matches!(
            f.add_vehicle(9, None, None, body(), at(0.0, 1.0), None),
            Err(TrafficError::Fleet(FleetError::UnknownTrack { .. }))
        ));
        assert_eq!(
            f.set_signal(1 << 20, &[]),
            Err(TrafficError::UnknownLight { light: 1 << 20 })
        );
        assert!(
            f.set_signal(3, &[Signal::Stop]).is_ok(),
            "lights need not be set in order"
        );
        let obs = |slots: &'static [i64]| Observations {
            slots,
            leader_gap_m: &[f64::NAN, f64::NAN][..slots.len()],
            leader_slot: &[-1, -1][..slots.len()],
            leader_speed_mps: &[f64::NAN, f64::NAN][..slots.len()],
            leader_room_m: None,
            lane: &[-1, -1][..slots.len()],
            lane_pos_m: &[f64::NAN, f64::NAN][..slots.len()],
            soft: None,
        };
        assert!(matches!(
            f.plan(&obs(&[7])),
            Err(TrafficError::Fleet(FleetError::UnknownSlot { slot: 7 }))
        ));
        assert!(matches!(
            f.plan(&obs(&[0, 0])),
            Err(TrafficError::Fleet(FleetError::DuplicateSlot { slot: 0 }))
        ));
        let short = Observations {
            leader_gap_m: &[],
            ..obs(&[0])
        };
        assert!(matches!(
            f.plan(&short),
            Err(TrafficError::Length {
                argument: "leader_gap",
                ..
            })
        ));
        // A plan that asks (a minor link 50 - 3.5 m ahead) needs one answer per question.
        let a_state = f.state(a).unwrap();
        for _ in 0..20 {
            step(&mut f, &[a], false);
        }
        let q = f.plan(&obs(&[0])).unwrap();
        assert_eq!(q, [0]);
        assert!(matches!(
            f.step(&[], DT),
            Err(TrafficError::Length {
                argument: "must_yield",
                ..
            })
        ));
        assert!(matches!(
            f.step(&[true], f64::NAN),
            Err(TrafficError::Parameter { name: "dt", .. })
        ));
        assert!(
            f.step(&[true], DT).is_ok(),
            "the plan survives a rejected step"
        );
        assert_ne!(f.state(a).unwrap(), a_state);
        assert!(matches!(
            RouteFleet::new(TrafficSettings {
                comfort_lateral_accel_mps2: 0.0,
                ..Default::default()
            }),
            Err(TrafficError::Parameter { .. })
        ));
    }

    #[test]
    fn leaders_come_off_the_lane_lists_where_both_places_are_known() {
        let (mut f, t) = fleet_on(road(None, true));
        // Three on lane 10 (30, 60, 90 m rear axles), known to the simulator
        // after one step; one more not yet known.
        let s: Vec<i64> = [30.0, 60.0, 90.0]
            .iter()
            .map(|&x| {
                f.add_vehicle(t, None, None, body(), at(x, 10.0), None)
                    .unwrap() as i64
            })
            .collect();
        step(&mut f, &s, false);
        let late = f
            .add_vehicle(t, None, None, body(), at(120.0, 10.0), None)
            .unwrap() as i64;
        let all = [s[0], s[1], s[2], late];
        assert_eq!(f.lanes_with_followers(&all).unwrap(), vec![10]);
        let pos = |slot: i64| f.driven(slot).unwrap().known.unwrap().1;
        // The simulator's list of lane 10, back to front: a background
        // vehicle sits between s[1] and s[2].
        let list = vec![Some(s[0]), Some(s[1]), None, Some(s[2]), Some(late)];
        let got = f.leaders_on_lanes(&all, &[10], &[list]).unwrap();
        let gap = pos(s[1]) - 4.5 - pos(s[0]) - 2.5;
        assert_eq!(got[0], Some((s[1], gap)));
        assert_eq!(got[1], None, "a background leader: the simulator tells");
        assert_eq!(got[2], None, "the leader's place is not known yet");
        assert_eq!(got[3], None, "first on its lane");
        // A list of another lane than the one blendtrack knows: nothing read off it.
        let got = f
            .leaders_on_lanes(&all, &[11], &[vec![Some(s[0]), Some(s[1])]])
            .unwrap();
        assert!(got.iter().all(Option::is_none));
        assert!(f.leaders_on_lanes(&all, &[10, 11], &[vec![]]).is_err());
    }
}
