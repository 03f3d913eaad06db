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

use crate::config::ControllerConfig;
use crate::fleet::{Fleet, FleetError, FleetInputs};
use crate::longitudinal::stopping_accel;
use crate::path::{wrap_angle, Path};
use crate::vehicle::{VehicleParams, VehicleState};
use nalgebra::Point2;
use std::sync::Arc;
use thiserror::Error;

/// An error of a route-fleet call; nothing was changed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrafficError {
    #[error(transparent)]
    Fleet(#[from] FleetError),
    #[error("route: {0}")]
    Route(String),
    #[error("argument `{argument}` has {got} entries, expected {expected}")]
    Length {
        argument: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("slot {slot} has no route (added through the inner fleet?)")]
    NoRoute { slot: i64 },
    #[error("traffic light number {light} is too large (lights are numbered below 2^20)")]
    UnknownLight { light: usize },
    #[error("step() called without a plan() before it")]
    NoPlan,
    #[error("argument `{name}` = {value}: {message}")]
    Parameter {
        name: &'static str,
        value: f64,
        message: &'static str,
    },
}

/// What a stop line's signal (or the road's right of way) says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Signal {
    /// Red, or red-yellow: stop.
    Stop = 0,
    /// Yellow: stop if that is comfortably possible, else clear the junction.
    Yellow = 1,
    /// Green with priority, or a major road: go.
    Priority = 2,
    /// Go but give way (green without priority, a minor road, a light that
    /// is off or blinking): wait while the simulator reports foes.
    Yield = 3,
}

impl Signal {
    /// The signal of a SUMO link state character (`r`, `y`, `G`, `g`, ...).
    pub fn from_sumo(c: u8) -> Signal {
        match c {
            b'r' | b'R' | b'u' => Signal::Stop,
            b'y' | b'Y' => Signal::Yellow,
            b'G' | b'M' => Signal::Priority,
            _ => Signal::Yield,
        }
    }
}

/// One lane along a route's track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// Arc length where the piece starts on the track (m).
    pub start_m: f64,
    /// The simulator's lane position at `start_m` (m; 0 when the piece
    /// starts where its lane starts).
    pub lane_pos_start_m: f64,
    /// Simulator lane length per metre of track.
    pub scale: f64,
    /// The simulator's length of the lane (m).
    pub lane_length_m: f64,
    /// Largest distance between the track and the lane's centreline over the
    /// piece (m); +inf where the track leaves the lane (a lane change). A
    /// vehicle is handed to the simulator as (lane, position) only while its
    /// lateral error plus this stays under the settings' bound.
    pub offset_m: f64,
    /// Speed limit (m/s).
    pub speed_mps: f64,
    /// The caller's ids of the lane and its edge, and the lane's index on the edge.
    pub lane: u32,
    pub edge: u32,
    pub lane_index: u32,
}

/// A junction entry along a route's track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopLine {
    /// Arc length of the stop line (m).
    pub s_m: f64,
    /// (light, link index) when signalised.
    pub signal: Option<(usize, usize)>,
    /// Right of way by the network, for an unsignalised link.
    pub major: bool,
    /// The caller's id of the first junction lane (to ask about foes).
    pub via: u32,
    /// Arc length where the junction is left (m; +inf when unknown).
    pub exit_m: f64,
    /// Ask the caller before entering even with the right of way: the
    /// junction has other vehicles' lanes crossing or touching this one, and
    /// a vehicle standing inside it (a left turner at its waiting point, a
    /// vehicle left over from a jam) may be in the way.
    pub check_inside: bool,
}

/// A lane change the route needs on one edge, made when the simulator says
/// there is room: until then the track ends early on the current lane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LaneChangeDue {
    pub edge: u32,
    pub target_index: u32,
}

/// Lanes and stop lines along a track (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    pieces: Vec<Piece>,
    stops: Vec<StopLine>,
    length_m: f64,
    lane_change: Option<LaneChangeDue>,
}

impl Route {
    /// Checks the tables: at least one piece, finite increasing piece starts,
    /// positive scales, positive speed limits, finite stop lines sorted by arc
    /// length, a finite positive length.
    pub fn new(
        pieces: Vec<Piece>,
        stops: Vec<StopLine>,
        length_m: f64,
        lane_change: Option<LaneChangeDue>,
    ) -> Result<Route, TrafficError> {
        let bad = |m: String| Err(TrafficError::Route(m));
        if pieces.is_empty() {
            return bad("no lane pieces".into());
        }
        if !(length_m.is_finite() && length_m > 0.0) {
            return bad(format!("length {length_m} m is not finite and > 0"));
        }
        for (i, p) in pieces.iter().enumerate() {
            if !p.start_m.is_finite() || (i > 0 && p.start_m < pieces[i - 1].start_m) {
                return bad(format!(
                    "piece {i} starts at {} m: starts must be finite and increasing",
                    p.start_m
                ));
            }
            // (what, value, unit, allowed, rule)
            let checks = [
                (
                    "has lane scale",
                    p.scale,
                    "",
                    p.scale > 0.0,
                    "finite and > 0",
                ),
                (
                    "starts at lane position",
                    p.lane_pos_start_m,
                    " m",
                    p.lane_pos_start_m >= 0.0,
                    "finite and >= 0",
                ),
                (
                    "has lane length",
                    p.lane_length_m,
                    " m",
                    p.lane_length_m > 0.0,
                    "finite and > 0",
                ),
            ];
            for (what, value, unit, ok, rule) in checks {
                if !(value.is_finite() && ok) {
                    return bad(format!("piece {i} {what} {value}{unit}: must be {rule}"));
                }
            }
            if p.offset_m.is_nan() || p.offset_m < 0.0 {
                return bad(format!(
                    "piece {i} has offset {} m: must be >= 0 (+inf: off the lane)",
                    p.offset_m
                ));
            }
            if !(p.speed_mps > 0.0) {
                return bad(format!(
                    "piece {i} has speed limit {} m/s: must be > 0",
                    p.speed_mps
                ));
            }
        }
        for (i, s) in stops.iter().enumerate() {
            if !s.s_m.is_finite() || (i > 0 && s.s_m < stops[i - 1].s_m) {
                return bad(format!(
                    "stop line {i} at {} m: must be finite and sorted",
                    s.s_m
                ));
            }
            if s.exit_m.is_nan() {
                return bad(format!("stop line {i} has a NaN exit"));
            }
        }
        Ok(Route {
            pieces,
            stops,
            length_m,
            lane_change,
        })
    }

    /// Index of the piece holding arc length `s` (clamped to the pieces).
    pub fn piece_at(&self, s: f64) -> usize {
        self.pieces
            .partition_point(|p| p.start_m <= s)
            .saturating_sub(1)
    }

    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }
    pub fn stops(&self) -> &[StopLine] {
        &self.stops
    }
    pub fn length_m(&self) -> f64 {
        self.length_m
    }
}

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
        }
    }
}

/// A driven vehicle's statistics since it was added.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveStats {
    pub steps: u64,
    pub sum_abs_e: f64,
    pub sum_e2: f64,
    pub max_abs_e: f64,
    /// Sums of |lateral error| at the rear and at the front axle: the same
    /// points for every alpha (`sum_abs_e` is of the control point P(alpha)).
    pub sum_abs_e_rear: f64,
    pub sum_abs_e_front: f64,
    pub sum_eth2: f64,
    pub sum_v: f64,
    pub distance_m: f64,
    pub max_lat_acc: f64,
    pub time_above_comfort_s: f64,
    pub sum_jerk2: f64,
    pub jerk_n: u64,
    /// Last step's acceleration (NaN before the first step).
    pub last_acc: f64,
    /// Steps faster than the lane's limit, and steps driving backwards.
    pub speed_warnings: u64,
    pub reverse_warnings: u64,
    pub red_light_violations: u64,
}

impl Default for DriveStats {
    fn default() -> Self {
        DriveStats {
            steps: 0,
            sum_abs_e: 0.0,
            sum_e2: 0.0,
            max_abs_e: 0.0,
            sum_abs_e_rear: 0.0,
            sum_abs_e_front: 0.0,
            sum_eth2: 0.0,
            sum_v: 0.0,
            distance_m: 0.0,
            max_lat_acc: 0.0,
            time_above_comfort_s: 0.0,
            sum_jerk2: 0.0,
            jerk_n: 0,
            last_acc: f64::NAN,
            speed_warnings: 0,
            reverse_warnings: 0,
            red_light_violations: 0,
        }
    }
}

/// Lights are numbered below this.
const MAX_LIGHTS: usize = 1 << 20;

/// How to put a vehicle's new pose into the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Move {
    /// Only set the speed ([`RouteOutputs::sumo_speed_mps`]): the
    /// simulator's own movement over the step carries the front exactly to
    /// its new place on the lane (or over a lane end onto the next lane of
    /// the route); also when the vehicle is about to arrive.
    Speed = 0,
    /// (lane, lane position) then the speed.
    Lane = 1,
    /// (edge, lane index, front-bumper x, y, angle) then the speed.
    Xy = 2,
    /// The state is unusable: hand the vehicle back, do not move it.
    Invalid = 3,
    /// Nothing to send: the speed the simulator already has carries the
    /// front to within `HOLD_SPEED_MPS * dt` of its new place (the rest is
    /// made up in the next step).
    Hold = 4,
}

/// The speed of a speed-only move stays within this (m/s, plus the relative
/// part below) of the vehicle's own speed in the simulator's lane
/// coordinates (speed x the piece's scale): what the simulator reports to
/// other drivers stays honest.
const GLIDE_TOLERANCE_MPS: f64 = 0.1;
const GLIDE_TOLERANCE_REL: f64 = 0.02;
/// A simulator that has the front more than this (m) behind where a
/// speed-only move can bring it is placed with a [`Move::Lane`].
const GLIDE_BEHIND_M: f64 = 0.5;
/// Below this change of the speed (m/s) no speed command is sent ([`Move::Hold`]):
/// the simulator's speed then differs from the vehicle's by less than this,
/// its position by less than this times dt (2 mm at 0.1 s), made up in the
/// next step. 13 % fewer speed commands than at 0.005 m/s on the highway.
const HOLD_SPEED_MPS: f64 = 0.02;
/// A speed-only move may carry the front over at most this many lane ends
/// (short junction lanes at speed).
const GLIDE_MAX_LANE_ENDS: usize = 3;

/// The distance the simulator must move the front, along its lanes, from
/// where it has it (`known`: lane, position) to lane position `target` on
/// piece `k`, and whether that passes a lane end; None when it cannot tell
/// (unknown position, or a lane the route's pieces do not lead from).
fn glide_distance(
    route: &Route,
    k: usize,
    target: f64,
    known: Option<(u32, f64)>,
) -> Option<(f64, bool)> {
    let (lane, p) = known?;
    let pieces = &route.pieces;
    if pieces[k].lane == lane {
        return Some((target - p, false));
    }
    // Over lane ends: each piece from the known lane on must be a whole lane
    // that the simulator enters at its start.
    let mut dist = target;
    let mut j = k;
    for _ in 0..GLIDE_MAX_LANE_ENDS {
        if j == 0 || pieces[j].lane_pos_start_m != 0.0 {
            return None;
        }
        j -= 1;
        let q = &pieces[j];
        if q.lane == pieces[j + 1].lane || !q.offset_m.is_finite() {
            return None;
        }
        if q.lane == lane {
            return Some((dist + q.lane_length_m - p, true));
        }
        dist += q.lane_length_m;
    }
    None
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
    stats: DriveStats,
}

/// One step's observations from the simulator, one entry per listed slot.
#[derive(Debug, Clone, Copy)]
pub struct Observations<'a> {
    pub slots: &'a [i64],
    /// Gap to the leader (m; NaN = none), the simulator's (minGap left out).
    pub leader_gap_m: &'a [f64],
    /// The leader's slot when it is driven here (its speed is known), else < 0.
    pub leader_slot: &'a [i64],
    /// The leader's speed when it is not driven here (m/s; NaN = unknown: standing).
    pub leader_speed_mps: &'a [f64],
    /// The simulator's lane and lane position of the front, where the bridge
    /// read them (`lane` < 0 where not read).
    pub lane: &'a [i64],
    pub lane_pos_m: &'a [f64],
    /// Vehicles to line up behind, beside the leader (None: nobody has one).
    pub soft: Option<SoftLeaders<'a>>,
}

/// A vehicle each slot lines up behind without it being in the way: one on
/// the lane beside, ahead of a vehicle that waits to change onto that lane
/// (or one that is to be let in). Columns as the leader's in
/// [`Observations`], one entry per slot (gap NaN = none). Braking for it is
/// bounded at `max_deceleration` (a soft [`crate::Obstacle`]): the vehicle
/// falls back at most at its planning deceleration and never brakes as in an
/// emergency for a vehicle that is not on its lane.
#[derive(Debug, Clone, Copy)]
pub struct SoftLeaders<'a> {
    pub gap_m: &'a [f64],
    pub slot: &'a [i64],
    pub speed_mps: &'a [f64],
}

#[derive(Debug, Clone, Default)]
struct Plan {
    slots: Vec<i64>,
    leader_gap: Vec<f64>,
    leader_speed: Vec<f64>,
    stop_gap: Vec<f64>,
    soft_gap: Vec<f64>,
    soft_speed: Vec<f64>,
    limit: Vec<f64>,
    /// Gap to the stop line of a link that waits for the simulator's word on foes.
    yield_gap: Vec<f64>,
    queries: Vec<usize>,
}

/// One step's results, one entry per planned slot, in the plan's order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RouteOutputs {
    pub moves: Vec<Move>,
    /// For [`Move::Lane`]: lane and position; for [`Move::Xy`]: edge and lane index.
    pub lane: Vec<u32>,
    pub lane_pos_m: Vec<f64>,
    pub edge: Vec<u32>,
    pub lane_index: Vec<u32>,
    /// Front-bumper point and SUMO angle (deg, clockwise from north).
    pub x_front_m: Vec<f64>,
    pub y_front_m: Vec<f64>,
    pub angle_deg: Vec<f64>,
    /// The new state.
    pub x_m: Vec<f64>,
    pub y_m: Vec<f64>,
    pub theta_rad: Vec<f64>,
    pub v_mps: Vec<f64>,
    pub delta_rad: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    pub lateral_error_m: Vec<f64>,
    pub heading_error_rad: Vec<f64>,
    pub s_rear_m: Vec<f64>,
    pub curvature_per_m: Vec<f64>,
    pub virtual_obstacle_m: Vec<f64>,
    /// The front crossed a stop line whose light is red in this step.
    pub red_light: Vec<bool>,
    /// A lane change is due where the vehicle now is: ask the simulator for room.
    pub lane_change_due: Vec<bool>,
    /// Report the simulator's lane and lane position next step: unknown to
    /// blendtrack, or due for a check of the prediction.
    pub read_position: Vec<bool>,
    /// The speed to give the simulator (m/s): the vehicle's own, or for a
    /// speed-only move the one that carries the front to its new place.
    pub sumo_speed_mps: Vec<f64>,
}

impl RouteOutputs {
    /// Empty columns with room for `n` vehicles (no growing in the step loop).
    fn with_capacity(n: usize) -> Self {
        RouteOutputs {
            moves: Vec::with_capacity(n),
            lane: Vec::with_capacity(n),
            lane_pos_m: Vec::with_capacity(n),
            edge: Vec::with_capacity(n),
            lane_index: Vec::with_capacity(n),
            x_front_m: Vec::with_capacity(n),
            y_front_m: Vec::with_capacity(n),
            angle_deg: Vec::with_capacity(n),
            x_m: Vec::with_capacity(n),
            y_m: Vec::with_capacity(n),
            theta_rad: Vec::with_capacity(n),
            v_mps: Vec::with_capacity(n),
            delta_rad: Vec::with_capacity(n),
            accel_mps2: Vec::with_capacity(n),
            lateral_error_m: Vec::with_capacity(n),
            heading_error_rad: Vec::with_capacity(n),
            s_rear_m: Vec::with_capacity(n),
            curvature_per_m: Vec::with_capacity(n),
            virtual_obstacle_m: Vec::with_capacity(n),
            red_light: Vec::with_capacity(n),
            lane_change_due: Vec::with_capacity(n),
            read_position: Vec::with_capacity(n),
            sumo_speed_mps: Vec::with_capacity(n),
        }
    }
}

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

fn check_len(argument: &'static str, expected: usize, got: usize) -> Result<(), TrafficError> {
    if expected == got {
        Ok(())
    } else {
        Err(TrafficError::Length {
            argument,
            expected,
            got,
        })
    }
}

/// True when the stopping law stops a vehicle at speed `v` within `gap` at
/// no more than the planning deceleration.
pub fn can_stop(cfg: &ControllerConfig, v: f64, gap_m: f64) -> bool {
    let a = stopping_accel(
        v,
        gap_m,
        0.0,
        cfg.preferred_stop_dist,
        cfg.reaction_time,
        cfg.max_deceleration,
        cfg.max_obs_deceleration,
    );
    a >= cfg.max_deceleration
}

impl RouteFleet {
    pub fn new(settings: TrafficSettings) -> Result<Self, TrafficError> {
        let checks: [(&'static str, f64, bool); 8] = [
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

    fn front_arc(
        &self,
        track_id: i64,
        state: &VehicleState,
        reach_m: f64,
    ) -> Result<f64, TrafficError> {
        let path = &self.fleet.track(track_id)?.path;
        let front = Point2::new(
            state.x_m + reach_m * state.theta_rad.cos(),
            state.y_m + reach_m * state.theta_rad.sin(),
        );
        Ok(path.project(&front).s)
    }

    /// Adds a vehicle at `state` (its rear axle) on a track; returns its slot.
    pub fn add_vehicle(
        &mut self,
        track_id: i64,
        config: Option<ControllerConfig>,
        params: Option<VehicleParams>,
        body: Body,
        state: VehicleState,
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
        let s_front_m = self.front_arc(track_id, &state, body.reach_m)?;
        let slot = self.fleet.add_vehicle(track_id, config, params)?;
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
    /// state and statistics stay, its stop lines start over.
    pub fn retrack(&mut self, slot: i64, track_id: i64) -> Result<(), TrafficError> {
        let route = self.route_of_track(track_id)?;
        let d = self.driven(slot)?;
        let s_front_m = self.front_arc(track_id, &d.state, d.body.reach_m)?;
        self.fleet.set_vehicle_track(slot, track_id)?;
        let d = self.driven[slot as usize].as_mut().expect("checked above");
        d.route = route;
        d.s_front_m = s_front_m;
        d.seg_front = usize::MAX;
        d.next_stop = 0;
        d.yellow = None;
        d.holding = None;
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
    /// The stop line ahead of the vehicle (the one its plan looked at).
    pub fn next_stop(&self, slot: i64) -> Result<Option<StopLine>, TrafficError> {
        let d = self.driven(slot)?;
        Ok(d.route.stops.get(d.next_stop).copied())
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

    /// A leader's speed: its state's where it is driven here (`slot` >= 0),
    /// else `given`.
    fn speed_of(&self, slot: i64, given: f64) -> f64 {
        usize::try_from(slot)
            .ok()
            .and_then(|l| self.driven.get(l))
            .and_then(Option::as_ref)
            .map_or(given, |d| d.state.v_mps)
    }

    /// First half of a step: stop lines and leaders. Returns the indices (into
    /// `obs.slots`) of the vehicles approaching a link without priority:
    /// [`RouteFleet::step`] needs, for each, whether it must give way.
    pub fn plan(&mut self, obs: &Observations<'_>) -> Result<Vec<usize>, TrafficError> {
        let n = obs.slots.len();
        check_len("leader_gap", n, obs.leader_gap_m.len())?;
        check_len("leader_slot", n, obs.leader_slot.len())?;
        check_len("leader_speed", n, obs.leader_speed_mps.len())?;
        check_len("lane", n, obs.lane.len())?;
        check_len("lane_pos", n, obs.lane_pos_m.len())?;
        if let Some(sl) = &obs.soft {
            check_len("soft_gap", n, sl.gap_m.len())?;
            check_len("soft_slot", n, sl.slot.len())?;
            check_len("soft_speed", n, sl.speed_mps.len())?;
        }
        let mut seen = vec![false; self.driven.len()];
        for &slot in obs.slots {
            self.driven(slot)?;
            if std::mem::replace(&mut seen[slot as usize], true) {
                return Err(FleetError::DuplicateSlot { slot }.into());
            }
        }
        let st = self.settings;
        let margin = st.standstill_margin_m;
        let mut plan = Plan {
            slots: obs.slots.to_vec(),
            leader_gap: vec![f64::NAN; n],
            leader_speed: vec![f64::NAN; n],
            stop_gap: vec![f64::NAN; n],
            soft_gap: vec![f64::NAN; n],
            soft_speed: vec![f64::NAN; n],
            limit: vec![f64::NAN; n],
            yield_gap: vec![f64::NAN; n],
            queries: Vec::new(),
        };
        for i in 0..n {
            let slot = obs.slots[i] as usize;
            let gap = obs.leader_gap_m[i];
            if gap.is_finite() {
                // The simulator's gap leaves out minGap, and the simulator
                // counts anything closer as a collision: stop further back.
                plan.leader_gap[i] = gap - margin;
                plan.leader_speed[i] = self.speed_of(obs.leader_slot[i], obs.leader_speed_mps[i]);
            }
            if let Some(sl) = &obs.soft {
                if sl.gap_m[i].is_finite() {
                    plan.soft_gap[i] = sl.gap_m[i] - margin;
                    plan.soft_speed[i] = self.speed_of(sl.slot[i], sl.speed_mps[i]);
                }
            }
            let cfg = self.fleet.vehicle_config(slot as i64)?;
            let d = self.driven[slot].as_ref().expect("checked above");
            let route = d.route.clone();
            let sf = d.s_front_m;
            plan.limit[i] = route.pieces[route.piece_at(sf)].speed_mps;
            let mut next = d.next_stop;
            while next < route.stops.len() && route.stops[next].s_m < sf - 0.5 {
                next += 1;
            }
            let v = d.state.v_mps.abs();
            let mut yellow = d.yellow;
            let mut holding = d.holding.filter(|&k| k == next);
            let mut stop_gap = f64::NAN;
            if let Some(stop) = route.stops.get(next) {
                let gap = stop.s_m - sf - margin;
                let sig = signal_at(&self.signals, stop);
                if sig != Signal::Yellow {
                    yellow = None;
                }
                let lg = plan.leader_gap[i];
                let lv = plan.leader_speed[i];
                let lv = if lv.is_finite() { lv.max(0.0) } else { 0.0 };
                match sig {
                    Signal::Stop => stop_gap = gap,
                    Signal::Yellow => {
                        // The decision holds until the light changes: decided
                        // anew every step it flips to "go" as the line nears
                        // (the law brakes harder than b_f at the end) and then
                        // fails to stop at red.
                        let decision = match yellow {
                            Some((k, stop_here)) if k == next => stop_here,
                            _ => can_stop(cfg, v, gap),
                        };
                        yellow = Some((next, decision));
                        if decision {
                            stop_gap = gap;
                        }
                    }
                    Signal::Priority | Signal::Yield => {
                        let near = gap < st.yield_lookahead_m;
                        let held = d.holding == Some(next);
                        // Where the leader's back would stop if it braked now at 4 m/s^2.
                        let blocked = lg.is_finite()
                            && sf + lg + margin + lv * lv / 8.0 - stop.exit_m
                                < d.body.length_m + d.body.min_gap_m + margin;
                        if near && blocked && (held || can_stop(cfg, v, gap)) {
                            // Keep the junction clear: no room behind the
                            // leader on the far side, so wait at the line.
                            stop_gap = gap;
                            holding = Some(next);
                        } else if (sig == Signal::Yield || stop.check_inside)
                            && near
                            && (held || can_stop(cfg, v, gap))
                        {
                            // Give way while the simulator reports foes (or,
                            // with the right of way, while the caller sees a
                            // vehicle inside the junction in the way); too
                            // late to stop, clear the junction instead.
                            plan.yield_gap[i] = gap;
                            plan.queries.push(i);
                        } else {
                            holding = None;
                        }
                    }
                }
            }
            // A track that stops where a lane change is due ends
            // lane_change_room_m early: the vehicle waits there for a gap.
            // The end of the route (with stop_at_route_end): a standing
            // obstacle a little past the track's end, so the vehicle slows
            // down and the simulator sees it arrive. Otherwise the vehicle
            // drives through its route's end and the simulator's own movement
            // (a speed move near a lane's end) carries it out.
            let end_gap = if route.lane_change.is_some() {
                route.length_m - st.lane_change_room_m - sf - margin
            } else if st.stop_at_route_end {
                route.length_m + st.route_end_extra_m - sf
            } else {
                f64::INFINITY
            };
            if end_gap < st.route_end_horizon_m {
                stop_gap = if stop_gap.is_nan() {
                    end_gap
                } else {
                    stop_gap.min(end_gap)
                };
            }
            plan.stop_gap[i] = stop_gap;
            let lane = obs.lane[i];
            let known = (lane >= 0 && obs.lane_pos_m[i].is_finite())
                .then(|| (lane as u32, obs.lane_pos_m[i]));
            let d = self.driven[slot].as_mut().expect("checked above");
            d.next_stop = next;
            d.yellow = yellow;
            d.holding = holding;
            if known.is_some() {
                d.known = known;
            }
        }
        let queries = plan.queries.clone();
        self.plan = Some(plan);
        Ok(queries)
    }

    /// Second half of a step: `must_yield[j]` answers the `j`-th index
    /// returned by [`RouteFleet::plan`]. Steps every planned vehicle over `dt_s`.
    pub fn step(&mut self, must_yield: &[bool], dt_s: f64) -> Result<RouteOutputs, TrafficError> {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(TrafficError::Parameter {
                name: "dt",
                value: dt_s,
                message: "must be finite and > 0",
            });
        }
        let Some(plan) = self.plan.as_ref() else {
            return Err(TrafficError::NoPlan);
        };
        check_len("must_yield", plan.queries.len(), must_yield.len())?;
        let mut plan = self.plan.take().expect("checked above");
        for (&i, &y) in plan.queries.iter().zip(must_yield) {
            let d = self.driven[plan.slots[i] as usize]
                .as_mut()
                .expect("planned slots are driven");
            if y {
                let g = plan.yield_gap[i];
                plan.stop_gap[i] = if plan.stop_gap[i].is_nan() {
                    g
                } else {
                    plan.stop_gap[i].min(g)
                };
                d.holding = Some(d.next_stop);
            } else {
                d.holding = None;
            }
        }
        let n = plan.slots.len();
        let mut cols: [Vec<f64>; 5] = std::array::from_fn(|_| Vec::with_capacity(n));
        for &slot in &plan.slots {
            let s = self.driven[slot as usize]
                .as_ref()
                .expect("planned slots are driven")
                .state;
            for (c, x) in cols
                .iter_mut()
                .zip([s.x_m, s.y_m, s.theta_rad, s.v_mps, s.delta_rad])
            {
                c.push(x);
            }
        }
        let inputs = FleetInputs {
            leader_gap_m: Some(&plan.leader_gap),
            leader_speed_mps: Some(&plan.leader_speed),
            stop_gap_m: Some(&plan.stop_gap),
            soft_gap_m: Some(&plan.soft_gap),
            soft_speed_mps: Some(&plan.soft_speed),
            speed_limit_mps: Some(&plan.limit),
            dt_s: Some(dt_s),
            ..FleetInputs::new(
                &plan.slots,
                &cols[0],
                &cols[1],
                &cols[2],
                &cols[3],
                &cols[4],
            )
        };
        let out = self.fleet.step(&inputs)?;
        let next = out.next.expect("dt was given");
        let mut r = RouteOutputs::with_capacity(n);
        let st = self.settings;
        for i in 0..n {
            let slot = plan.slots[i] as usize;
            let params = *self.fleet.vehicle_params(slot as i64)?;
            let d = self.driven[slot]
                .as_mut()
                .expect("planned slots are driven");
            let state = VehicleState {
                x_m: next.x_m[i],
                y_m: next.y_m[i],
                theta_rad: next.theta_rad[i],
                v_mps: next.v_mps[i],
                delta_rad: next.delta_rad[i],
            };
            let finite = [
                state.x_m,
                state.y_m,
                state.theta_rad,
                state.v_mps,
                state.delta_rad,
                out.s_rear_m[i],
            ]
            .iter()
            .all(|x| x.is_finite());
            let e = out.lateral_error_m[i];
            let eth = out.heading_error_rad[i];
            let (v, th) = (state.v_mps, state.theta_rad);
            let reach = d.body.reach_m;
            let (xf, yf) = (state.x_m + reach * th.cos(), state.y_m + reach * th.sin());
            // The front's arc length at the NEW state (the controller's
            // outputs are of the state it was given, one step behind).
            let sf_new = if finite {
                let path = &self
                    .fleet
                    .track(self.fleet.vehicle_track(slot as i64)? as i64)?
                    .path;
                let (s, seg) =
                    path.arc_near_from(&Point2::new(xf, yf), d.s_front_m + v * dt_s, d.seg_front);
                d.seg_front = seg;
                s
            } else {
                f64::NAN
            };
            let route = &d.route;
            let k = if finite { route.piece_at(sf_new) } else { 0 };
            let piece = route.pieces[k];
            // Where the front must be on the piece's lane after the
            // simulator's own movement over the step.
            let target = piece.lane_pos_start_m + (sf_new - piece.start_m) * piece.scale;
            let mut pos = target - v * dt_s;
            let mut sumo_speed = v;
            let on_lane = e.abs() + piece.offset_m < st.lane_move_lateral_m
                && eth.abs() < st.lane_move_heading_rad
                && v >= 0.0;
            // (distance the simulator must move the front, crosses a lane end)
            let glide = if on_lane {
                glide_distance(route, k, target, d.known)
            } else {
                None
            };
            // Where the simulator will have the front after its movement,
            // when blendtrack can tell without asking: (lane, position).
            let mut predicted = None;
            let mv = if !(out.ok[i] && finite) {
                Move::Invalid
            } else if k == route.pieces.len() - 1
                && route.lane_change.is_none()
                && sf_new > route.length_m - 2.0 * v * dt_s - 2.0
            {
                // About to arrive: a deferred (x, y) move would be applied
                // after the simulator removed the vehicle.
                Move::Speed
            } else if let Some((dist, cross)) =
                glide.filter(|&(dist, _)| dist - v * piece.scale * dt_s <= GLIDE_BEHIND_M)
            {
                // The simulator's own movement carries the front to its new
                // place at the speed that makes up the distance, kept within
                // GLIDE_TOLERANCE_* of the vehicle's own speed (in the
                // simulator's lane coordinates): a simulator a little off
                // (ahead, or behind by up to GLIDE_BEHIND_M) is brought back
                // over a few steps; it is never moved backwards.
                let expect = v * piece.scale;
                let tol = GLIDE_TOLERANCE_MPS + GLIDE_TOLERANCE_REL * expect;
                sumo_speed = (dist / dt_s).clamp((expect - tol).max(0.0), expect + tol);
                // A standstill is always sent: a held creep speed would let
                // the simulator drift ahead (0.4 mm a step at 4 mm/s), and
                // it is never moved back.
                let hold = !cross
                    && (sumo_speed - d.sumo_speed).abs() < HOLD_SPEED_MPS
                    && (sumo_speed > 0.0 || d.sumo_speed == 0.0);
                if hold {
                    sumo_speed = d.sumo_speed;
                }
                if !cross {
                    // Exact; after a lane end the simulator's choice of the
                    // next lane is read back instead.
                    predicted = d.known.map(|(lane, p)| (lane, p + sumo_speed * dt_s));
                }
                if hold {
                    Move::Hold
                } else {
                    Move::Speed
                }
            } else if on_lane && pos >= d.body.length_m {
                if let Some((lane, p)) = d.known {
                    if lane == piece.lane {
                        pos = pos.max(p);
                    }
                }
                predicted = Some((piece.lane, pos + v * dt_s));
                Move::Lane
            } else {
                Move::Xy
            };
            let mut red = false;
            let mut due = false;
            if mv != Move::Invalid {
                // Red-light crossing: the front passed a stop line whose light is red.
                if let Some(stop) = route.stops.get(d.next_stop) {
                    if stop.signal.is_some()
                        && d.s_front_m < stop.s_m
                        && stop.s_m <= sf_new
                        && signal_at(&self.signals, stop) == Signal::Stop
                    {
                        red = true;
                        d.stats.red_light_violations += 1;
                    }
                }
                if let Some(lc) = route.lane_change {
                    due = piece.edge == lc.edge && piece.lane_index != lc.target_index;
                }
                let prev_v = d.state.v_mps;
                let acc = (v - prev_v) / dt_s;
                let lat_acc = v * v * state.delta_rad.tan() / params.wheelbase_m;
                let s = &mut d.stats;
                let ae = e.abs();
                s.steps += 1;
                s.sum_abs_e += ae;
                s.sum_e2 += ae * ae;
                s.max_abs_e = s.max_abs_e.max(ae);
                s.sum_abs_e_rear += out.lateral_error_rear_m[i].abs();
                s.sum_abs_e_front += out.lateral_error_front_m[i].abs();
                s.sum_eth2 += eth * eth;
                s.sum_v += v.abs();
                s.distance_m += v.abs() * dt_s;
                s.max_lat_acc = s.max_lat_acc.max(lat_acc.abs());
                if lat_acc.abs() > st.comfort_lateral_accel_mps2 {
                    s.time_above_comfort_s += dt_s;
                }
                if s.last_acc.is_finite() {
                    let jerk = (acc - s.last_acc) / dt_s;
                    s.sum_jerk2 += jerk * jerk;
                    s.jerk_n += 1;
                }
                s.last_acc = acc;
                if v.abs() > plan.limit[i] * 1.0001 {
                    s.speed_warnings += 1;
                }
                if v < 0.0 {
                    s.reverse_warnings += 1;
                }
                if s.steps % st.sample_every == 0 {
                    self.samples
                        .push([out.curvature_per_m[i].abs(), v.abs(), ae, lat_acc.abs()]);
                }
                r.accel_mps2.push(acc);
                d.state = state;
                d.s_front_m = sf_new;
                d.known = predicted;
                d.sumo_speed = sumo_speed;
            } else {
                r.accel_mps2.push(f64::NAN);
            }
            r.moves.push(mv);
            r.lane.push(piece.lane);
            r.lane_pos_m.push(pos);
            r.edge.push(piece.edge);
            r.lane_index.push(piece.lane_index);
            r.x_front_m.push(xf);
            r.y_front_m.push(yf);
            r.angle_deg
                .push((90.0 - wrap_angle(th).to_degrees()).rem_euclid(360.0));
            r.x_m.push(state.x_m);
            r.y_m.push(state.y_m);
            r.theta_rad.push(th);
            r.v_mps.push(v);
            r.delta_rad.push(state.delta_rad);
            r.lateral_error_m.push(e);
            r.heading_error_rad.push(eth);
            r.s_rear_m.push(out.s_rear_m[i]);
            r.curvature_per_m.push(out.curvature_per_m[i]);
            r.virtual_obstacle_m.push(out.virtual_obstacle_m[i]);
            r.red_light.push(red);
            r.lane_change_due.push(due);
            // Read back where the prediction ends, and now and then to check it.
            let verify = st.verify_every > 0 && d.stats.steps % st.verify_every == 0;
            r.read_position
                .push(mv != Move::Invalid && (d.known.is_none() || verify));
            r.sumo_speed_mps.push(sumo_speed);
        }
        Ok(r)
    }
}

/// The signal at a stop line, from the light table (a free function, so the
/// step loop can borrow a vehicle mutably meanwhile). A light never reported
/// counts as green with priority, as the simulator without the light would.
fn signal_at(signals: &[Vec<Signal>], stop: &StopLine) -> Signal {
    match stop.signal {
        Some((light, link)) => signals
            .get(light)
            .and_then(|l| l.get(link))
            .copied()
            .unwrap_or(Signal::Priority),
        None if stop.major => Signal::Priority,
        None => Signal::Yield,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.1;

    /// A 600 m straight road: lane 10 (plain) up to a junction at 200 m,
    /// junction lane 11 (not plain) to 210 m, then lane 12 (plain, scale 1.01).
    fn road(signal: Option<(usize, usize)>, major: bool) -> (Path, Route) {
        let path = Path::straight(600.0, 1.0).unwrap();
        let piece = |start_m: f64, plain: bool, lane, edge, scale: f64, lane_length_m| Piece {
            start_m,
            lane_pos_start_m: 0.0,
            scale,
            lane_length_m,
            offset_m: if plain { 0.0 } else { f64::INFINITY },
            speed_mps: 20.0,
            lane,
            edge,
            lane_index: 0,
        };
        let route = Route::new(
            vec![
                piece(0.0, true, 10, 1, 1.0, 200.0),
                piece(200.0, false, 11, 2, 1.0, 10.0),
                piece(210.0, true, 12, 3, 1.01, 390.0 * 1.01),
            ],
            vec![StopLine {
                s_m: 200.0,
                signal,
                major,
                via: 11,
                exit_m: 210.0,
                check_inside: false,
            }],
            600.0,
            None,
        )
        .unwrap();
        (path, route)
    }

    fn body() -> Body {
        Body {
            reach_m: 3.5,
            length_m: 4.5,
            min_gap_m: 2.5,
        }
    }

    fn at(x: f64, v: f64) -> VehicleState {
        VehicleState {
            x_m: x,
            y_m: 0.0,
            theta_rad: 0.0,
            v_mps: v,
            delta_rad: 0.0,
        }
    }

    fn fleet_on(route: (Path, Route)) -> (RouteFleet, i64) {
        fleet_with(route, TrafficSettings::default())
    }

    fn fleet_with(route: (Path, Route), settings: TrafficSettings) -> (RouteFleet, i64) {
        let mut f = RouteFleet::new(settings).unwrap();
        let cfg = ControllerConfig {
            preferred_speed: 15.0,
            ..Default::default()
        };
        let t = f.add_route(route.0, cfg, route.1).unwrap() as i64;
        (f, t)
    }

    /// One plan + step for the listed slots, with no leaders; `yield_to`
    /// answers every query.
    fn step(f: &mut RouteFleet, slots: &[i64], yield_to: bool) -> (Vec<usize>, RouteOutputs) {
        let n = slots.len();
        let nan = vec![f64::NAN; n];
        let q = f
            .plan(&Observations {
                slots,
                leader_gap_m: &nan,
                leader_slot: &vec![-1; n],
                leader_speed_mps: &nan,
                lane: &vec![-1; n],
                lane_pos_m: &nan,
                soft: None,
            })
            .unwrap();
        let out = f.step(&vec![yield_to; q.len()], DT).unwrap();
        (q, out)
    }

    #[test]
    fn route_tables_are_checked() {
        let p = |start_m| Piece {
            start_m,
            lane_pos_start_m: 0.0,
            scale: 1.0,
            lane_length_m: 100.0,
            offset_m: 0.0,
            speed_mps: 10.0,
            lane: 0,
            edge: 0,
            lane_index: 0,
        };
        assert!(matches!(
            Route::new(vec![], vec![], 10.0, None),
            Err(TrafficError::Route(_))
        ));
        let e = Route::new(vec![p(0.0), p(5.0), p(3.0)], vec![], 10.0, None).unwrap_err();
        assert!(e.to_string().contains("piece 2"), "{e}");
        assert!(Route::new(vec![p(0.0)], vec![], f64::NAN, None).is_err());
        let r = Route::new(vec![p(0.0), p(5.0), p(5.0), p(9.0)], vec![], 10.0, None).unwrap();
        assert_eq!(
            [
                r.piece_at(-1.0),
                r.piece_at(4.99),
                r.piece_at(5.0),
                r.piece_at(9.5),
                r.piece_at(99.0)
            ],
            [0, 0, 2, 3, 3]
        );
    }

    #[test]
    fn red_light_stops_the_vehicle_before_the_line_then_green_lets_it_go() {
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        let slot = f
            .add_vehicle(t, None, None, body(), at(100.0, 12.0))
            .unwrap() as i64;
        f.set_signal(0, &[Signal::Stop]).unwrap();
        for _ in 0..400 {
            let (_, out) = step(&mut f, &[slot], false);
            assert!(!out.red_light[0]);
        }
        let sf = f.s_front(slot).unwrap();
        let v = f.state(slot).unwrap().v_mps;
        assert!(v.abs() < 0.05, "stands at red: v = {v}");
        assert!(
            (195.0..200.0).contains(&sf),
            "front {sf} m stops before the line"
        );
        f.set_signal(0, &[Signal::Priority]).unwrap();
        for _ in 0..200 {
            step(&mut f, &[slot], false);
        }
        assert!(f.s_front(slot).unwrap() > 220.0, "green: drives on");
        assert_eq!(f.stats(slot).unwrap().red_light_violations, 0);
    }

    #[test]
    fn a_light_turning_red_too_late_to_stop_is_counted_as_a_crossing() {
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        // Front 1.5 m before the line at 15 m/s: no law can stop that.
        let slot = f
            .add_vehicle(t, None, None, body(), at(200.0 - 3.5 - 1.5, 15.0))
            .unwrap() as i64;
        f.set_signal(0, &[Signal::Stop]).unwrap();
        let mut crossed = 0;
        for _ in 0..10 {
            crossed += step(&mut f, &[slot], false).1.red_light[0] as u64;
        }
        assert_eq!(crossed, 1);
        assert_eq!(f.stats(slot).unwrap().red_light_violations, 1);
    }

    #[test]
    fn a_yellow_decision_holds_until_the_light_changes() {
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        let slot = f
            .add_vehicle(t, None, None, body(), at(120.0, 12.0))
            .unwrap() as i64;
        f.set_signal(0, &[Signal::Yellow]).unwrap();
        for _ in 0..300 {
            let (_, out) = step(&mut f, &[slot], false);
            assert!(!out.red_light[0]);
        }
        // Far enough to stop comfortably: it stopped, and the decision did
        // not flip to "go" as the line came near.
        let sf = f.s_front(slot).unwrap();
        assert!(
            sf < 200.0 && f.state(slot).unwrap().v_mps.abs() < 0.05,
            "front {sf}"
        );
        // Close to the line at speed when it turns yellow: it goes through.
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        let slot = f
            .add_vehicle(t, None, None, body(), at(200.0 - 3.5 - 4.0, 14.0))
            .unwrap() as i64;
        f.set_signal(0, &[Signal::Yellow]).unwrap();
        for _ in 0..20 {
            step(&mut f, &[slot], false);
        }
        assert!(f.s_front(slot).unwrap() > 210.0);
    }

    #[test]
    fn a_junction_checked_for_vehicles_inside_asks_even_with_the_right_of_way() {
        // A major road and a green light: without the check neither asks
        // (see links_without_priority_ask_and_wait_only_when_told_to); with
        // it the vehicle asks near the line and waits only when told to.
        for signal in [None, Some((0, 0))] {
            for blocked in [true, false] {
                let (path, mut route) = road(signal, true);
                route.stops[0].check_inside = true;
                let (mut f, t) = fleet_on((path, route));
                if signal.is_some() {
                    f.set_signal(0, &[Signal::Priority]).unwrap();
                }
                let slot = f
                    .add_vehicle(t, None, None, body(), at(150.0, 8.0))
                    .unwrap() as i64;
                let mut asked = 0;
                for _ in 0..300 {
                    asked += step(&mut f, &[slot], blocked).0.len();
                }
                assert!(asked > 0, "{signal:?}: asks within the look-ahead");
                let sf = f.s_front(slot).unwrap();
                if blocked {
                    assert!(
                        sf < 200.0 && f.state(slot).unwrap().v_mps.abs() < 0.05,
                        "{signal:?}: waits at the line, front {sf}"
                    );
                } else {
                    assert!(sf > 300.0, "{signal:?}: clear, drives through: front {sf}");
                }
            }
        }
    }

    #[test]
    fn links_without_priority_ask_and_wait_only_when_told_to() {
        for must_yield in [true, false] {
            let (mut f, t) = fleet_on(road(None, false));
            let slot = f
                .add_vehicle(t, None, None, body(), at(150.0, 8.0))
                .unwrap() as i64;
            let mut asked = 0;
            for _ in 0..300 {
                let (q, _) = step(&mut f, &[slot], must_yield);
                asked += q.len();
            }
            assert!(asked > 0, "within the look-ahead the vehicle asks");
            let sf = f.s_front(slot).unwrap();
            if must_yield {
                assert!(sf < 200.0, "waits at the line: front {sf}");
            } else {
                assert!(sf > 300.0, "no foes: drives through, front {sf}");
            }
        }
        // A major road never asks.
        let (mut f, t) = fleet_on(road(None, true));
        let slot = f
            .add_vehicle(t, None, None, body(), at(150.0, 8.0))
            .unwrap() as i64;
        for _ in 0..100 {
            assert!(step(&mut f, &[slot], true).0.is_empty());
        }
    }

    #[test]
    fn the_junction_is_kept_clear_when_the_leader_leaves_no_room_beyond_it() {
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        f.set_signal(0, &[Signal::Priority]).unwrap();
        let slot = f
            .add_vehicle(t, None, None, body(), at(160.0, 8.0))
            .unwrap() as i64;
        for _ in 0..300 {
            let sf = f.s_front(slot).unwrap();
            // A standing leader whose back is 3 m past the junction's exit.
            let gap = 213.0 - sf;
            f.plan(&Observations {
                slots: &[slot],
                leader_gap_m: &[gap],
                leader_slot: &[-1],
                leader_speed_mps: &[0.0],
                lane: &[-1],
                lane_pos_m: &[f64::NAN],
                soft: None,
            })
            .unwrap();
            f.step(&[], DT).unwrap();
        }
        let sf = f.s_front(slot).unwrap();
        assert!(
            sf < 200.0,
            "waits before the line, not inside the junction: front {sf}"
        );
    }

    #[test]
    fn a_driven_leader_s_speed_comes_from_its_state() {
        let (mut f, t) = fleet_on(road(None, true));
        let lead = f
            .add_vehicle(t, None, None, body(), at(60.0, 14.0))
            .unwrap() as i64;
        let fol = f
            .add_vehicle(t, None, None, body(), at(40.0, 14.0))
            .unwrap() as i64;
        let accel = |f: &mut RouteFleet, leader_slot: i64| {
            let mut g = f.clone();
            g.plan(&Observations {
                slots: &[fol],
                leader_gap_m: &[12.0],
                leader_slot: &[leader_slot],
                leader_speed_mps: &[f64::NAN],
                lane: &[-1],
                lane_pos_m: &[f64::NAN],
                soft: None,
            })
            .unwrap();
            g.step(&[], DT).unwrap().accel_mps2[0]
        };
        let moving = accel(&mut f, lead);
        let unknown = accel(&mut f, -1);
        assert!(
            moving > unknown + 0.5,
            "a leader at 14 m/s ({moving}) is not a standing one ({unknown})"
        );
    }

    #[test]
    fn moves_follow_the_lane_when_centred_and_xy_otherwise() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0))
            .unwrap() as i64;
        let mut off = at(50.0, 10.0);
        off.y_m = 2.0;
        let b = f.add_vehicle(t, None, None, body(), off).unwrap() as i64;
        let c = f
            .add_vehicle(t, None, None, body(), at(594.0, 10.0))
            .unwrap() as i64;
        let (_, out) = step(&mut f, &[a, b, c], false);
        assert_eq!(out.moves, [Move::Lane, Move::Xy, Move::Speed]);
        // Lane position: the new front minus v dt (placed before the simulator moves it).
        let sf = f.s_front(a).unwrap();
        assert!((out.lane_pos_m[0] - (sf - out.v_mps[0] * DT)).abs() < 1e-9);
        assert_eq!((out.lane[0], out.edge[1]), (10, 1));
        assert!(
            (out.y_front_m[1]
                - f.state(b).unwrap().y_m
                - 3.5 * f.state(b).unwrap().theta_rad.sin())
            .abs()
                < 1e-9
        );
        assert_eq!(out.read_position, [false, true, true]);
        // On the junction lane (not plain) even a centred vehicle moves by (x, y).
        let d = f
            .add_vehicle(t, None, None, body(), at(200.0, 10.0))
            .unwrap() as i64;
        assert_eq!(step(&mut f, &[d], false).1.moves, [Move::Xy]);
        // The scale maps arc length to lane position on lane 12.
        let e = f
            .add_vehicle(t, None, None, body(), at(300.0, 10.0))
            .unwrap() as i64;
        let out = step(&mut f, &[e], false).1;
        let sf = f.s_front(e).unwrap();
        assert!((out.lane_pos_m[0] - ((sf - 210.0) * 1.01 - out.v_mps[0] * DT)).abs() < 1e-9);
    }

    #[test]
    fn a_placement_never_goes_back_behind_where_the_simulator_has_the_vehicle() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0))
            .unwrap() as i64;
        let sf = f.s_front(a).unwrap();
        let slots = [a];
        let plan = |f: &mut RouteFleet, pos: f64| {
            f.plan(&Observations {
                slots: &slots,
                leader_gap_m: &[f64::NAN],
                leader_slot: &[-1],
                leader_speed_mps: &[f64::NAN],
                lane: &[10],
                lane_pos_m: &[pos],
                soft: None,
            })
            .unwrap();
        };
        // The simulator reports the front 0.5 m further on lane 10: it is
        // slowed down (a speed move), not put back.
        plan(&mut f, sf + 0.5);
        let out = f.step(&[], DT).unwrap();
        assert_eq!(out.moves, [Move::Speed]);
        assert!(out.sumo_speed_mps[0] < out.v_mps[0] && out.sumo_speed_mps[0] >= 0.0);
        // Reported 20 m further (a lost vehicle): it waits there, never backwards.
        plan(&mut f, sf + 20.0);
        let out = f.step(&[], DT).unwrap();
        assert!(matches!(out.moves[0], Move::Speed | Move::Hold));
        assert!(out.sumo_speed_mps[0] >= 0.0);
        // Reported 2 m behind: placed where it must be.
        let sf = f.s_front(a).unwrap();
        plan(&mut f, sf - 2.0);
        let out = f.step(&[], DT).unwrap();
        assert_eq!(out.moves, [Move::Lane]);
        assert!((out.lane_pos_m[0] + out.v_mps[0] * DT - f.s_front(a).unwrap()).abs() < 1e-9);
    }

    #[test]
    fn the_vehicle_stops_at_the_end_of_its_route_when_set_to() {
        let settings = TrafficSettings {
            stop_at_route_end: true,
            ..Default::default()
        };
        let (mut f, t) = fleet_with(road(None, true), settings);
        let a = f
            .add_vehicle(t, None, None, body(), at(400.0, 15.0))
            .unwrap() as i64;
        for _ in 0..400 {
            step(&mut f, &[a], false);
        }
        let sf = f.s_front(a).unwrap();
        assert!(
            sf > 590.0 && sf < 605.0,
            "stops around the route's end (+5 m): {sf}"
        );
    }

    #[test]
    fn by_default_the_vehicle_drives_through_the_end_of_its_route() {
        // Like SUMO's drivers (arrivalSpeed "current"): no slowing down for
        // the route's end at 600 m; the simulator takes the vehicle out there.
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(400.0, 15.0))
            .unwrap() as i64;
        let mut slowest = f64::INFINITY;
        while f.s_front(a).unwrap() < 600.0 {
            let out = step(&mut f, &[a], false).1;
            assert!(out.moves[0] != Move::Invalid);
            slowest = slowest.min(out.v_mps[0]);
        }
        assert!(
            slowest > 14.5,
            "kept its speed to the end: slowest {slowest} m/s"
        );
        // A few steps past the end (the simulator is late to take it out):
        // still a usable move, no panic.
        for _ in 0..10 {
            let out = step(&mut f, &[a], false).1;
            assert!(out.moves[0] != Move::Invalid && out.v_mps[0].is_finite());
        }
    }

    #[test]
    fn statistics_add_up_the_outputs() {
        let (mut f, t) = fleet_on(road(None, true));
        let mut s0 = at(50.0, 10.0);
        s0.y_m = 0.7;
        let a = f.add_vehicle(t, None, None, body(), s0).unwrap() as i64;
        let (mut sum_e, mut max_lat, mut dist) = (0.0, 0.0_f64, 0.0);
        for _ in 0..50 {
            let out = step(&mut f, &[a], false).1;
            sum_e += out.lateral_error_m[0].abs();
            let v = out.v_mps[0];
            max_lat = max_lat.max((v * v * out.delta_rad[0].tan() / 2.6).abs());
            dist += v.abs() * DT;
        }
        let s = f.remove_vehicle(a).unwrap();
        assert_eq!(s.steps, 50);
        assert!((s.sum_abs_e - sum_e).abs() < 1e-9 && s.sum_abs_e > 1.0);
        assert!((s.max_lat_acc - max_lat).abs() < 1e-9 && max_lat > 0.0);
        assert!((s.distance_m - dist).abs() < 1e-9);
        assert_eq!(s.jerk_n, 49);
        assert_eq!(f.take_samples().len(), 5);
        assert!(f.is_empty());
    }

    #[test]
    fn axle_errors_are_those_of_the_fixed_points() {
        // On the centreline, yawed by 0.1 rad: the rear axle is on the path,
        // the front axle (wheelbase 2.6 m ahead) 2.6 sin(0.1) m to the left,
        // the control point P(0.5) half of that.
        let (mut f, t) = fleet_on(road(None, true));
        let mut s0 = at(50.0, 10.0);
        s0.theta_rad = 0.1;
        let a = f.add_vehicle(t, None, None, body(), s0).unwrap() as i64;
        step(&mut f, &[a], false);
        let s = f.remove_vehicle(a).unwrap();
        let front = 2.6 * 0.1_f64.sin();
        assert!(s.sum_abs_e_rear < 1e-9, "{}", s.sum_abs_e_rear);
        assert!(
            (s.sum_abs_e_front - front).abs() < 1e-9,
            "{}",
            s.sum_abs_e_front
        );
        assert!((s.sum_abs_e - 0.5 * front).abs() < 1e-9, "{}", s.sum_abs_e);
    }

    #[test]
    fn retrack_keeps_state_and_statistics() {
        let (mut f, t) = fleet_on(road(None, true));
        let t2 = f
            .add_route(
                road(None, true).0,
                ControllerConfig::default(),
                road(None, true).1,
            )
            .unwrap() as i64;
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0))
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
    fn bad_calls_are_errors_and_change_nothing() {
        let (mut f, t) = fleet_on(road(None, false));
        let a = f
            .add_vehicle(t, None, None, body(), at(150.0, 8.0))
            .unwrap() as i64;
        assert_eq!(f.step(&[], DT), Err(TrafficError::NoPlan));
        assert!(matches!(
            f.add_vehicle(t, None, None, body(), at(f64::NAN, 1.0)),
            Err(TrafficError::Parameter { name: "x", .. })
        ));
        assert!(matches!(
            f.add_vehicle(9, None, None, body(), at(0.0, 1.0)),
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

    /// A stand-in for the simulator's own movement: it keeps each vehicle's
    /// (lane, position, speed), applies the moves, then moves it `speed x dt`
    /// along `lanes` (id, length) in order, as SUMO does with speed mode 0.
    struct Sim {
        lanes: Vec<(u32, f64)>,
        lane: usize,
        pos: f64,
        speed: f64,
    }

    impl Sim {
        /// The simulator's view of the road's first lane (10, 200 m), nothing known yet.
        fn on_lane_10() -> Sim {
            Sim {
                lanes: vec![(10, 200.0)],
                lane: 0,
                pos: 0.0,
                speed: 0.0,
            }
        }

        fn apply(&mut self, out: &RouteOutputs, i: usize) {
            match out.moves[i] {
                Move::Hold => {}
                Move::Speed => self.speed = out.sumo_speed_mps[i],
                Move::Lane => {
                    self.lane = self.lanes.iter().position(|l| l.0 == out.lane[i]).unwrap();
                    self.pos = out.lane_pos_m[i];
                    self.speed = out.sumo_speed_mps[i];
                }
                m => panic!("unexpected move {m:?}"),
            }
            self.pos += self.speed * DT;
            while self.pos > self.lanes[self.lane].1 && self.lane + 1 < self.lanes.len() {
                self.pos -= self.lanes[self.lane].1;
                self.lane += 1;
            }
        }
        fn obs(&self) -> (i64, f64) {
            (self.lanes[self.lane].0 as i64, self.pos)
        }
    }

    /// One plan + step for one vehicle that reports the simulator's lane
    /// position when asked to; returns the outputs.
    fn sim_step(f: &mut RouteFleet, slot: i64, sim: &mut Sim, report: bool) -> RouteOutputs {
        let (lane, pos) = if report { sim.obs() } else { (-1, f64::NAN) };
        f.plan(&Observations {
            slots: &[slot],
            leader_gap_m: &[f64::NAN],
            leader_slot: &[-1],
            leader_speed_mps: &[f64::NAN],
            lane: &[lane],
            lane_pos_m: &[pos],
            soft: None,
        })
        .unwrap();
        let out = f.step(&[], DT).unwrap();
        sim.apply(&out, 0);
        out
    }

    /// One vehicle at `x` (rear axle) and `v` on `road(None, true)`, five
    /// steps into a simulator that reports every step: its place is known.
    fn settled_on_lane_10(x: f64, v: f64) -> (RouteFleet, i64, Sim) {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f.add_vehicle(t, None, None, body(), at(x, v)).unwrap() as i64;
        let mut sim = Sim::on_lane_10();
        for _ in 0..5 {
            sim_step(&mut f, a, &mut sim, true);
        }
        (f, a, sim)
    }

    /// Where the front must be on `lane`, from its arc length on `road(..)`.
    fn front_lane_pos(f: &RouteFleet, slot: i64) -> (u32, f64) {
        let sf = f.s_front(slot).unwrap();
        let d = f.driven(slot).unwrap();
        let p = d.route.pieces[d.route.piece_at(sf)];
        (p.lane, p.lane_pos_start_m + (sf - p.start_m) * p.scale)
    }

    #[test]
    fn on_its_lane_a_vehicle_is_moved_by_its_speed_alone() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(20.0, 14.5))
            .unwrap() as i64;
        let mut sim = Sim::on_lane_10();
        let mut read = true;
        let mut counts = [0usize; 5];
        for k in 0..500 {
            if f.s_front(a).unwrap() > 190.0 {
                break; // the junction lane is not plain: (x, y) moves there
            }
            let out = sim_step(&mut f, a, &mut sim, read);
            read = out.read_position[0];
            counts[out.moves[0] as usize] += 1;
            if k == 0 {
                assert_eq!(
                    out.moves[0],
                    Move::Lane,
                    "the first move places the vehicle"
                );
            }
            let (lane, want) = front_lane_pos(&f, a);
            assert_eq!(lane, 10);
            // Speed-only moves land the front where blendtrack has it (a
            // hold to within HOLD_SPEED_MPS * dt).
            assert!(
                (sim.pos - want).abs() <= HOLD_SPEED_MPS * DT + 1e-9,
                "step {k}: simulator {} vs {want}",
                sim.pos
            );
            // The speed sent is the vehicle's own (here scale 1).
            assert!((out.sumo_speed_mps[0] - out.v_mps[0]).abs() <= HOLD_SPEED_MPS + 1e-9);
            // Checked every verify_every steps, else not asked for.
            assert_eq!(read, f.stats(a).unwrap().steps % 10 == 0, "step {k}");
        }
        assert!(counts[Move::Speed as usize] > 20, "{counts:?}");
        assert!(
            counts[Move::Hold as usize] > 10,
            "cruising needs no command: {counts:?}"
        );
        assert_eq!(counts[Move::Lane as usize], 1, "{counts:?}");
        assert_eq!(counts[Move::Xy as usize], 0, "{counts:?}");
    }

    #[test]
    fn a_speed_move_carries_the_vehicle_over_a_lane_end_and_the_position_is_read_back() {
        // The junction lane follows its lane's centreline within 2 cm: plain enough.
        let (path, mut route) = road(None, true);
        route.pieces[1].offset_m = 0.02;
        let (mut f, t) = fleet_on((path, route));
        let a = f
            .add_vehicle(t, None, None, body(), at(150.0, 10.0))
            .unwrap() as i64;
        let mut sim = Sim {
            lanes: vec![(10, 200.0), (11, 10.0), (12, 390.0 * 1.01)],
            lane: 0,
            pos: 0.0,
            speed: 0.0,
        };
        let mut read = true;
        let mut crossings = 0;
        for k in 0..120 {
            let before = sim.lane;
            let out = sim_step(&mut f, a, &mut sim, read);
            read = out.read_position[0];
            if k > 0 {
                assert!(
                    matches!(out.moves[0], Move::Speed | Move::Hold),
                    "step {k}: {:?}",
                    out.moves[0]
                );
            }
            if sim.lane != before {
                crossings += 1;
                assert!(read, "after a lane end the simulator's lane is read back");
            }
            let (lane, want) = front_lane_pos(&f, a);
            assert_eq!(lane, sim.lanes[sim.lane].0, "step {k}");
            assert!(
                (sim.pos - want).abs() <= HOLD_SPEED_MPS * DT + 1e-9,
                "step {k}: {} vs {want}",
                sim.pos
            );
        }
        assert_eq!(crossings, 2);
        // On lane 12 (scale 1.01) the speed sent is in its lane coordinates.
        let out = sim_step(&mut f, a, &mut sim, read);
        assert!((out.sumo_speed_mps[0] / out.v_mps[0] - 1.01).abs() < 1e-3);
    }

    #[test]
    fn a_simulator_that_lags_the_prediction_gets_the_vehicle_placed_again() {
        let (mut f, a, mut sim) = settled_on_lane_10(40.0, 8.0);
        // The simulator held the vehicle back 1 m (it could not move it).
        sim.pos -= 1.0;
        let out = sim_step(&mut f, a, &mut sim, true);
        assert_eq!(
            out.moves[0],
            Move::Lane,
            "no speed command catches up 1 m in a step: it is placed"
        );
        let (_, want) = front_lane_pos(&f, a);
        assert!((sim.pos - want).abs() < 1e-9);
    }

    #[test]
    fn a_simulator_a_little_off_is_brought_back_by_the_speed_never_moved_back() {
        for offset in [0.3, -0.3] {
            let (mut f, a, mut sim) = settled_on_lane_10(40.0, 8.0);
            // The simulator has the front 0.3 m ahead of (or behind) blendtrack's.
            sim.pos += offset;
            let mut err = offset;
            for k in 0..40 {
                let before = sim.pos;
                let out = sim_step(&mut f, a, &mut sim, true);
                assert!(
                    matches!(out.moves[0], Move::Speed | Move::Hold),
                    "offset {offset}, step {k}: {:?}",
                    out.moves[0]
                );
                assert!(sim.pos >= before, "never backwards");
                let v = out.v_mps[0];
                assert!(
                    (out.sumo_speed_mps[0] - v).abs()
                        <= GLIDE_TOLERANCE_MPS + GLIDE_TOLERANCE_REL * v + 1e-9,
                    "the speed SUMO reports stays near the vehicle's"
                );
                let (_, want) = front_lane_pos(&f, a);
                let now = sim.pos - want;
                assert!(
                    now.abs() <= err.abs() + 1e-9,
                    "offset {offset}, step {k}: {now} vs {err}"
                );
                err = now;
            }
            assert!(
                err.abs() < 1e-6,
                "offset {offset}: made up after 40 steps, {err} left"
            );
        }
    }

    #[test]
    fn a_vehicle_that_stops_leaves_the_simulator_standing_not_creeping() {
        // A red light ahead: the vehicle brakes to a stop at the line and
        // waits; the simulator, moved by the speeds sent, ends where it is.
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        f.set_signal(0, &[Signal::Stop]).unwrap();
        let a = f
            .add_vehicle(t, None, None, body(), at(150.0, 10.0))
            .unwrap() as i64;
        let mut sim = Sim::on_lane_10();
        let mut read = true;
        for _ in 0..3000 {
            read = sim_step(&mut f, a, &mut sim, read).read_position[0];
        }
        let (_, want) = front_lane_pos(&f, a);
        assert!(f.state(a).unwrap().v_mps.abs() < 1e-3);
        assert_eq!(sim.speed, 0.0, "the simulator's speed is a standstill");
        assert!(
            (sim.pos - want).abs() < 1e-3,
            "simulator {} vs {want} after 300 s",
            sim.pos
        );
        // The last speed sent was a creep of 4 mm/s (the end of a gentle
        // approach): the standstill is still sent, no drift for 100 s.
        sim.speed = 0.004;
        f.driven[a as usize].as_mut().unwrap().sumo_speed = 0.004;
        for _ in 0..1000 {
            read = sim_step(&mut f, a, &mut sim, read).read_position[0];
        }
        assert!(
            (sim.pos - want).abs() < 1e-3,
            "simulator drifted to {} vs {want}",
            sim.pos
        );
    }

    #[test]
    fn leaders_come_off_the_lane_lists_where_both_places_are_known() {
        let (mut f, t) = fleet_on(road(None, true));
        // Three on lane 10 (30, 60, 90 m rear axles), known to the simulator
        // after one step; one more not yet known.
        let s: Vec<i64> = [30.0, 60.0, 90.0]
            .iter()
            .map(|&x| f.add_vehicle(t, None, None, body(), at(x, 10.0)).unwrap() as i64)
            .collect();
        step(&mut f, &s, false);
        let late = f
            .add_vehicle(t, None, None, body(), at(120.0, 10.0))
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

    #[test]
    fn piece_tables_with_bad_lane_positions_lengths_or_offsets_are_rejected() {
        let (_, route) = road(None, true);
        for (k, bad) in [
            (
                0,
                Piece {
                    lane_pos_start_m: -1.0,
                    ..route.pieces[0]
                },
            ),
            (
                1,
                Piece {
                    lane_length_m: 0.0,
                    ..route.pieces[1]
                },
            ),
            (
                2,
                Piece {
                    offset_m: f64::NAN,
                    ..route.pieces[2]
                },
            ),
        ] {
            let mut pieces = route.pieces.clone();
            pieces[k] = bad;
            let e = Route::new(pieces, route.stops.clone(), 600.0, None).unwrap_err();
            assert!(e.to_string().contains(&format!("piece {k}")), "{e}");
        }
    }
}
