//! `RouteFleet` for Python: the route-driving batch stepper of the
//! `blendtrack-traffic` crate, which the SUMO plugin calls twice per
//! simulation step (`plan`, then `step`) for all controlled vehicles at once.
//!
//! Lanes, edges, junction lanes and traffic lights are integers the caller
//! interns; traffic-light states are SUMO state strings (`"rrGGy..."`).
//! Errors: bad arguments raise `InputError` naming the argument or slot; a
//! bad controller configuration raises `ConfigError`.

use crate::config::{ControllerConfig, VehicleParams};
use crate::errors::{config_error, fleet_error, input_error};
use crate::path::Path;
use blendtrack::{StatValue, VehicleState};
use blendtrack_traffic::{
    Body, DriveStats, LaneChangeDue, Move, Observations, Piece, Route,
    RouteFleet as CoreRouteFleet, Signal, SoftLeaders, Stations, StopLine, TrafficError,
    TrafficSettings,
};
use numpy::ndarray::Array2;
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLike1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};
use rustc_hash::FxHashMap;

type F64In<'py> = PyArrayLike1<'py, f64, AllowTypeChange>;
type I64In<'py> = PyArrayLike1<'py, i64, AllowTypeChange>;

fn traffic_error(e: TrafficError) -> PyErr {
    match e {
        TrafficError::Fleet(e) => fleet_error(e),
        other => input_error(other.to_string()),
    }
}

fn vec_of<T: numpy::Element + Copy>(a: &PyArrayLike1<'_, T, AllowTypeChange>) -> Vec<T> {
    a.as_array().to_vec()
}

fn same_len(name: &str, expected: usize, got: usize) -> PyResult<()> {
    if expected == got {
        Ok(())
    } else {
        Err(input_error(format!(
            "argument `{name}` has {got} entries, expected {expected}"
        )))
    }
}

fn u32_of(name: &str, i: usize, x: i64) -> PyResult<u32> {
    u32::try_from(x).map_err(|_| input_error(format!("{name}[{i}] = {x}: must be in [0, 2^32)")))
}

/// `add_route`'s `lane_change`: (edge, target lane index) or (edge, target
/// lane index, occurrence of the edge).
fn lane_change_due(items: &[i64]) -> PyResult<LaneChangeDue> {
    let (&[e, t] | &[e, t, _]) = items else {
        return Err(input_error(format!(
            "lane_change has {} items, expected (edge, target lane index[, occurrence])",
            items.len()
        )));
    };
    Ok(LaneChangeDue {
        edge: u32_of("lane_change edge", 0, e)?,
        target_index: u32_of("lane_change target", 1, t)?,
        occurrence: match items {
            &[_, _, k] => Some(u32_of("lane_change occurrence", 2, k)?),
            _ => None,
        },
    })
}

/// A vehicle's statistics as a dict, every entry the traffic crate names
/// (raw sums and maxima, finished means and RMS, counts), built generically.
fn stats_dict<'py>(py: Python<'py>, s: &DriveStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (key, value) in s.entries() {
        match value {
            StatValue::Count(n) => d.set_item(key, n)?,
            StatValue::Value(x) => d.set_item(key, x)?,
        }
    }
    Ok(d)
}

/// Vehicles driving road routes among other traffic, stepped together.
///
/// Per simulation step: `plan(...)` with the leaders the simulator reports
/// returns the indices of the vehicles that must ask the simulator whether to
/// give way; `step(answers, dt)` runs the controllers and bicycle models and
/// returns how to put each new pose into the simulator (`move`: 0 speed only
/// (`sumo_speed_mps`), 1 lane + position, 2 x/y/angle, 3 invalid: hand the
/// vehicle back, 4 nothing to send).
#[pyclass(module = "blendtrack")]
pub struct RouteFleet {
    inner: CoreRouteFleet,
    /// The simulator's vehicle ids of the slots that were given one, both
    /// ways (`plan_sumo` reads leaders by id). SUMO's vehicle ids are short
    /// strings hashed a few thousand times a step: FxHash (rustc-hash), not
    /// the DoS-resistant, slower SipHash.
    slot_of: FxHashMap<String, i64>,
    name_of: Vec<Option<String>>,
    /// What `leaders_on_lanes` found for the slots it was given, kept for
    /// the next `plan_sumo` with the same slots: (slots, leader per slot).
    listed: Option<(Vec<i64>, Vec<ListedLeader>)>,
}

/// A leader read off a lane list: (its slot, the gap in m), or None.
type ListedLeader = Option<(i64, f64)>;

#[pymethods]
impl RouteFleet {
    #[new]
    #[pyo3(signature = (*, standstill_margin_m = 1.0, yield_lookahead_m = 30.0, lane_change_room_m = 15.0, stop_at_route_end = false, route_end_extra_m = 5.0, route_end_horizon_m = 200.0, lane_move_lateral_m = 0.15, lane_move_heading_deg = 2.0, comfort_lateral_accel_mps2 = 2.0, sample_every = 10, verify_every = 10, control_dt_s = 0.05))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        standstill_margin_m: f64,
        yield_lookahead_m: f64,
        lane_change_room_m: f64,
        stop_at_route_end: bool,
        route_end_extra_m: f64,
        route_end_horizon_m: f64,
        lane_move_lateral_m: f64,
        lane_move_heading_deg: f64,
        comfort_lateral_accel_mps2: f64,
        sample_every: u64,
        verify_every: u64,
        control_dt_s: f64,
    ) -> PyResult<Self> {
        let inner = CoreRouteFleet::new(TrafficSettings {
            standstill_margin_m,
            yield_lookahead_m,
            lane_change_room_m,
            stop_at_route_end,
            route_end_extra_m,
            route_end_horizon_m,
            lane_move_lateral_m,
            lane_move_heading_rad: lane_move_heading_deg.to_radians(),
            comfort_lateral_accel_mps2,
            sample_every,
            verify_every,
            control_dt_s,
            ballistic: false,
        })
        .map_err(|e| match e {
            TrafficError::Parameter {
                name,
                value,
                message,
            } => config_error(blendtrack::ConfigError::Invalid {
                key: name.into(),
                value: value.to_string(),
                message: message.into(),
            }),
            other => traffic_error(other),
        })?;
        Ok(RouteFleet {
            inner,
            slot_of: FxHashMap::default(),
            name_of: Vec::new(),
            listed: None,
        })
    }

    /// Registers a track with its lane pieces and stop lines; returns its id.
    /// `station_m`: the simulator's station at each point of the path (see
    /// `blendtrack_traffic::Stations`; `polyline_join`'s `station`), so that
    /// gaps the simulator reports are used up where it will see them used
    /// up; without it a station is the arc length.
    #[pyo3(signature = (path, config, *, piece_start_m, piece_scale, piece_offset_m, piece_lane_length_m, piece_speed_mps, piece_lane, piece_edge, piece_lane_index, length_m, piece_lane_pos_m = None, stop_s_m = None, stop_light = None, stop_link = None, stop_major = None, stop_via = None, stop_exit_m = None, stop_check_inside = None, lane_change = None, piece_occurrence = None, station_m = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_route(
        &mut self,
        py: Python<'_>,
        path: &Path,
        config: Option<ControllerConfig>,
        piece_start_m: F64In<'_>,
        piece_scale: F64In<'_>,
        piece_offset_m: F64In<'_>,
        piece_lane_length_m: F64In<'_>,
        piece_speed_mps: F64In<'_>,
        piece_lane: I64In<'_>,
        piece_edge: I64In<'_>,
        piece_lane_index: I64In<'_>,
        length_m: f64,
        piece_lane_pos_m: Option<F64In<'_>>,
        stop_s_m: Option<F64In<'_>>,
        stop_light: Option<I64In<'_>>,
        stop_link: Option<I64In<'_>>,
        stop_major: Option<I64In<'_>>,
        stop_via: Option<I64In<'_>>,
        stop_exit_m: Option<F64In<'_>>,
        stop_check_inside: Option<I64In<'_>>,
        lane_change: Option<Vec<i64>>,
        piece_occurrence: Option<I64In<'_>>,
        station_m: Option<F64In<'_>>,
    ) -> PyResult<usize> {
        let starts = vec_of(&piece_start_m);
        let n = starts.len();
        let scale = vec_of(&piece_scale);
        let offset = vec_of(&piece_offset_m);
        let lane_length = vec_of(&piece_lane_length_m);
        let lane_pos = piece_lane_pos_m
            .as_ref()
            .map(vec_of)
            .unwrap_or_else(|| vec![0.0; n]);
        let speed = vec_of(&piece_speed_mps);
        let lane = vec_of(&piece_lane);
        let edge = vec_of(&piece_edge);
        let index = vec_of(&piece_lane_index);
        let occurrence = piece_occurrence
            .as_ref()
            .map(vec_of)
            .unwrap_or_else(|| vec![0; n]);
        for (name, got) in [
            ("piece_occurrence", occurrence.len()),
            ("piece_scale", scale.len()),
            ("piece_offset_m", offset.len()),
            ("piece_lane_length_m", lane_length.len()),
            ("piece_lane_pos_m", lane_pos.len()),
            ("piece_speed_mps", speed.len()),
            ("piece_lane", lane.len()),
            ("piece_edge", edge.len()),
            ("piece_lane_index", index.len()),
        ] {
            same_len(name, n, got)?;
        }
        let mut pieces = Vec::with_capacity(n);
        for i in 0..n {
            pieces.push(Piece {
                start_m: starts[i],
                lane_pos_start_m: lane_pos[i],
                scale: scale[i],
                lane_length_m: lane_length[i],
                offset_m: offset[i],
                speed_mps: speed[i],
                lane: u32_of("piece_lane", i, lane[i])?,
                edge: u32_of("piece_edge", i, edge[i])?,
                lane_index: u32_of("piece_lane_index", i, index[i])?,
                occurrence: u32_of("piece_occurrence", i, occurrence[i])?,
            });
        }
        let s = stop_s_m.as_ref().map(vec_of).unwrap_or_default();
        let m = s.len();
        let col_i = |c: &Option<I64In<'_>>, default: i64| {
            c.as_ref().map(vec_of).unwrap_or_else(|| vec![default; m])
        };
        let light = col_i(&stop_light, -1);
        let link = col_i(&stop_link, 0);
        let major = col_i(&stop_major, 0);
        let via = col_i(&stop_via, 0);
        let check_inside = col_i(&stop_check_inside, 0);
        let exit = stop_exit_m
            .as_ref()
            .map(vec_of)
            .unwrap_or_else(|| vec![f64::INFINITY; m]);
        for (name, got) in [
            ("stop_light", light.len()),
            ("stop_link", link.len()),
            ("stop_major", major.len()),
            ("stop_via", via.len()),
            ("stop_exit_m", exit.len()),
            ("stop_check_inside", check_inside.len()),
        ] {
            same_len(name, m, got)?;
        }
        let mut stops = Vec::with_capacity(m);
        for i in 0..m {
            let signal = if light[i] >= 0 {
                Some((light[i] as usize, u32_of("stop_link", i, link[i])? as usize))
            } else {
                None
            };
            stops.push(StopLine {
                s_m: s[i],
                signal,
                major: major[i] != 0,
                via: u32_of("stop_via", i, via[i])?,
                exit_m: exit[i],
                check_inside: check_inside[i] != 0,
            });
        }
        let lane_change = lane_change.as_deref().map(lane_change_due).transpose()?;
        let mut route = Route::new(pieces, stops, length_m, lane_change).map_err(traffic_error)?;
        if let Some(c) = station_m.as_ref().map(vec_of) {
            // One station per point of the path, at the path's own arc lengths.
            let stations =
                Stations::new(path.inner.vertex_s().to_vec(), c).map_err(traffic_error)?;
            route = route.with_stations(stations);
        }
        let cfg = config.map(|c| c.to_core()).transpose()?.unwrap_or_default();
        let p = path.inner.clone();
        let inner = &mut self.inner;
        py.detach(|| inner.add_route(p, cfg, route))
            .map_err(traffic_error)
    }

    /// Adds a vehicle (rear-axle state) on a track; returns its slot.
    /// `name` (the simulator's id, unique among the vehicles here) lets
    /// `plan_sumo` recognise it as a leader.
    /// `occurrence`: which time the track drives the vehicle's edge (SUMO's
    /// route index less that of the track's first edge); on a track that
    /// drives an edge more than once the vehicle is placed on that lap.
    #[pyo3(signature = (track_id, config, vehicle, *, reach_m, length_m, min_gap_m, x, y, theta, v, delta = 0.0, name = None, occurrence = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_vehicle(
        &mut self,
        track_id: i64,
        config: Option<ControllerConfig>,
        vehicle: Option<VehicleParams>,
        reach_m: f64,
        length_m: f64,
        min_gap_m: f64,
        x: f64,
        y: f64,
        theta: f64,
        v: f64,
        delta: f64,
        name: Option<String>,
        occurrence: Option<i64>,
    ) -> PyResult<usize> {
        if let Some(n) = &name {
            if self.slot_of.contains_key(n) {
                return Err(input_error(format!(
                    "name {n:?} is already the vehicle in slot {}",
                    self.slot_of[n]
                )));
            }
        }
        let cfg = config.map(|c| c.to_core()).transpose()?;
        let params = vehicle.map(|v| v.to_core()).transpose()?;
        let body = Body {
            reach_m,
            length_m,
            min_gap_m,
        };
        let state = VehicleState {
            x_m: x,
            y_m: y,
            theta_rad: theta,
            v_mps: v,
            delta_rad: delta,
        };
        let occurrence = occurrence.map(|k| u32_of("occurrence", 0, k)).transpose()?;
        let slot = self
            .inner
            .add_vehicle(track_id, cfg, params, body, state, occurrence)
            .map_err(traffic_error)?;
        if self.name_of.len() <= slot {
            self.name_of.resize(slot + 1, None);
        }
        if let Some(n) = name {
            self.slot_of.insert(n.clone(), slot as i64);
            self.name_of[slot] = Some(n);
        }
        Ok(slot)
    }

    /// Moves a vehicle to another track; its state and statistics stay.
    /// `occurrence` as for `add_vehicle`, on the new track.
    #[pyo3(signature = (slot, track_id, occurrence = None))]
    fn retrack(&mut self, slot: i64, track_id: i64, occurrence: Option<i64>) -> PyResult<()> {
        let occurrence = occurrence.map(|k| u32_of("occurrence", 0, k)).transpose()?;
        self.inner
            .retrack_at(slot, track_id, occurrence)
            .map_err(traffic_error)
    }

    /// Moves the vehicle's state ``by_m`` metres on along its heading (0 to
    /// 5 m), before a ``retrack`` onto a lane change, to where SUMO has its
    /// front; ValueError out of range.
    fn advance_state(&mut self, slot: i64, by_m: f64) -> PyResult<()> {
        self.inner.advance_state(slot, by_m).map_err(traffic_error)
    }

    /// Which time the track drives the edge of the vehicle's front (see
    /// `add_vehicle`'s `occurrence`): SUMO's route index of the vehicle,
    /// less that of the track's first edge, where blendtrack has it.
    fn occurrence(&self, slot: i64) -> PyResult<u32> {
        self.inner.occurrence(slot).map_err(traffic_error)
    }

    /// The simulator's (lane id, lane position) of the vehicle's front where
    /// blendtrack has it: on the piece of its track holding the front, the
    /// position clamped to the lane.
    fn front_lane_position(&self, slot: i64) -> PyResult<(u32, f64)> {
        self.inner.front_lane_position(slot).map_err(traffic_error)
    }

    /// The occurrences (see `occurrence`) of the pieces of the vehicle's
    /// track within `slack_m` of its front, in track order.
    fn occurrences_near_front(&self, slot: i64, slack_m: f64) -> PyResult<Vec<u32>> {
        self.inner
            .occurrences_near_front(slot, slack_m)
            .map_err(traffic_error)
    }

    /// The arc length on the vehicle's track of lane position `pos_m` on
    /// lane `lane` (an id of `add_route`'s `piece_lane`): on the first piece
    /// of that lane covering the position at or after `s_from_m`; None where
    /// none does.
    fn arc_at_lane_position(
        &self,
        slot: i64,
        lane: i64,
        pos_m: f64,
        s_from_m: f64,
    ) -> PyResult<Option<f64>> {
        let Ok(lane) = u32::try_from(lane) else {
            return Ok(None);
        };
        self.inner
            .arc_at_lane_position(slot, lane, pos_m, s_from_m)
            .map_err(traffic_error)
    }

    /// Removes a track no vehicle drives any more (its memory is freed; a
    /// later add_route may reuse the id). One still driven raises InputError naming a slot.
    fn remove_route(&mut self, track_id: i64) -> PyResult<()> {
        self.inner.remove_route(track_id).map_err(traffic_error)
    }

    /// Frees a slot; returns the vehicle's statistics (a dict).
    fn remove_vehicle<'py>(&mut self, py: Python<'py>, slot: i64) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.remove_vehicle(slot).map_err(traffic_error)?;
        if let Some(n) = self.name_of.get_mut(slot as usize).and_then(Option::take) {
            self.slot_of.remove(&n);
        }
        stats_dict(py, &s)
    }

    /// The vehicle's statistics so far (a dict).
    fn stats<'py>(&self, py: Python<'py>, slot: i64) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.stats(slot).map_err(traffic_error)?;
        stats_dict(py, &s)
    }

    /// (x, y, theta, v, delta) of the vehicle's rear axle.
    fn state(&self, slot: i64) -> PyResult<(f64, f64, f64, f64, f64)> {
        let s = self.inner.state(slot).map_err(traffic_error)?;
        Ok((s.x_m, s.y_m, s.theta_rad, s.v_mps, s.delta_rad))
    }

    /// Sets where on its track (arc length, m) the vehicle's front is to
    /// stop, a standing obstacle braked for like a red line; NaN clears it.
    /// The front rests up to ``HALT_CREEP_M`` past it. A retrack clears it.
    fn set_halt(&mut self, slot: i64, s_m: f64) -> PyResult<()> {
        self.inner.set_halt(slot, s_m).map_err(traffic_error)
    }

    /// The vehicle's halt (arc length, m), NaN when none.
    fn halt(&self, slot: i64) -> PyResult<f64> {
        self.inner.halt(slot).map_err(traffic_error)
    }

    /// Arc length of the vehicle's front bumper on its track (m).
    fn s_front(&self, slot: i64) -> PyResult<f64> {
        self.inner.s_front(slot).map_err(traffic_error)
    }

    /// The stop line ahead of the vehicle as (s_m, light, link, major, via,
    /// exit_m), light = -1 when unsignalised; None past the last one.
    #[allow(clippy::type_complexity)]
    fn next_stop(&self, slot: i64) -> PyResult<Option<(f64, i64, i64, bool, i64, f64)>> {
        let s = self.inner.next_stop(slot).map_err(traffic_error)?;
        Ok(s.map(|s| {
            let (light, link) = s.signal.map_or((-1, 0), |(l, k)| (l as i64, k as i64));
            (s.s_m, light, link, s.major, i64::from(s.via), s.exit_m)
        }))
    }

    /// Where the tracks of `slots` enter junctions within `max_m` ahead of
    /// the fronts: three arrays, the index into `slots`, the first junction
    /// lane's id and the distance from the front to the line.
    #[allow(clippy::type_complexity)]
    fn stops_ahead<'py>(
        &self,
        py: Python<'py>,
        slots: I64In<'py>,
        max_m: f64,
    ) -> PyResult<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<f64>>,
    )> {
        let sl = vec_of(&slots);
        let found = self.inner.stops_ahead(&sl, max_m).map_err(traffic_error)?;
        let index: Vec<i64> = found.iter().map(|f| f.0 as i64).collect();
        let via: Vec<i64> = found.iter().map(|f| i64::from(f.1)).collect();
        let gap: Vec<f64> = found.iter().map(|f| f.2).collect();
        Ok((
            index.into_pyarray(py),
            via.into_pyarray(py),
            gap.into_pyarray(py),
        ))
    }

    fn vehicle_config(&self, slot: i64) -> PyResult<ControllerConfig> {
        self.inner
            .vehicle_config(slot)
            .map(ControllerConfig::from)
            .map_err(traffic_error)
    }

    fn vehicle_params(&self, slot: i64) -> PyResult<VehicleParams> {
        self.inner
            .vehicle_params(slot)
            .map(VehicleParams::from)
            .map_err(traffic_error)
    }

    fn vehicle_track(&self, slot: i64) -> PyResult<usize> {
        self.inner.fleet().vehicle_track(slot).map_err(fleet_error)
    }

    /// Sets a light's state from its SUMO state string (one character per
    /// link). Lights are numbered from 0 in the order first set.
    fn set_signal(&mut self, light: usize, state: &str) -> PyResult<()> {
        let links: Vec<Signal> = state.bytes().map(Signal::from_sumo).collect();
        self.inner.set_signal(light, &links).map_err(traffic_error)
    }

    /// First half of a step. `leader_gap` (NaN: none), `leader_slot` (< 0:
    /// not driven here), `leader_speed` (used when not driven here), and the
    /// simulator's `lane` (< 0: not read) and `lane_pos` of each vehicle.
    /// Returns the indices into `slots` of the vehicles that must ask the
    /// simulator whether to give way.
    #[allow(clippy::too_many_arguments)]
    fn plan<'py>(
        &mut self,
        py: Python<'py>,
        slots: I64In<'py>,
        leader_gap: F64In<'py>,
        leader_slot: I64In<'py>,
        leader_speed: F64In<'py>,
        lane: I64In<'py>,
        lane_pos: F64In<'py>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let (sl, lg, ls, lv, ln, lp) = (
            vec_of(&slots),
            vec_of(&leader_gap),
            vec_of(&leader_slot),
            vec_of(&leader_speed),
            vec_of(&lane),
            vec_of(&lane_pos),
        );
        let obs = Observations {
            slots: &sl,
            leader_gap_m: &lg,
            leader_slot: &ls,
            leader_speed_mps: &lv,
            leader_room_m: None,
            lane: &ln,
            lane_pos_m: &lp,
            soft: None,
        };
        self.run_plan(py, &obs)
    }

    /// `plan` with the leaders as SUMO's `vehicle.getLeader` gives them: one
    /// entry per slot, `None` or `(leader id, gap)` (an empty id, or a gap
    /// below -100 m, is no leader), or `(leader id, gap, room)` where the
    /// caller shortened SUMO's gap for the stopping law: `room` is SUMO's own,
    /// which bounds only how far a move by lane position may put the vehicle
    /// (SUMO puts it there before anyone moves). A leader added here with its `name` is
    /// known by its slot; for any other `speed_of(leader id)` is called (a
    /// leader whose speed cannot be read counts as standing). The lanes and
    /// lane positions read from the simulator are given sparsely: for the
    /// vehicles at `read_index` (indices into `slots`).
    ///
    /// With `leader_index`, `leaders` holds only the entries at those indices
    /// (the ones `leaders_on_lanes` could not read off the lane lists, for
    /// these same `slots`); the others are the ones it found.
    ///
    /// `soft_leaders`: `(index into slots, id, gap)` of vehicles to line up
    /// behind besides the leader (a soft obstacle: braked for at
    /// `max_deceleration` at most); ids and gaps read as the leaders'.
    #[pyo3(signature = (slots, leaders, speed_of, read_index = None, read_lane = None, read_pos = None, leader_index = None, soft_leaders = None))]
    #[allow(clippy::too_many_arguments)]
    fn plan_sumo<'py>(
        &mut self,
        py: Python<'py>,
        slots: I64In<'py>,
        leaders: &Bound<'py, PyAny>,
        speed_of: &Bound<'py, PyAny>,
        read_index: Option<I64In<'py>>,
        read_lane: Option<I64In<'py>>,
        read_pos: Option<F64In<'py>>,
        leader_index: Option<I64In<'py>>,
        soft_leaders: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let sl = vec_of(&slots);
        let n = sl.len();
        let items: Vec<Bound<'py, PyAny>> = leaders.try_iter()?.collect::<PyResult<_>>()?;
        let soft = match soft_leaders {
            Some(list) => Some(self.soft_leaders(list, n, speed_of)?),
            None => None,
        };
        let mut gaps = vec![f64::NAN; n];
        let mut lslots = vec![-1i64; n];
        let mut lspeeds = vec![f64::NAN; n];
        let mut rooms = vec![f64::NAN; n];
        let listed = self.listed.take();
        let at: Vec<usize> = match &leader_index {
            None => {
                same_len("leaders", n, items.len())?;
                (0..n).collect()
            }
            Some(idx) => {
                let Some((listed_slots, found)) = listed else {
                    return Err(input_error(
                        "leader_index given without a leaders_on_lanes call for these slots before"
                            .to_string(),
                    ));
                };
                if listed_slots != sl {
                    return Err(input_error(
                        "leader_index: the slots differ from the last leaders_on_lanes call"
                            .to_string(),
                    ));
                }
                for (i, f) in found.into_iter().enumerate() {
                    if let Some((l, gap)) = f {
                        gaps[i] = gap;
                        lslots[i] = l;
                    }
                }
                let idx = vec_of(idx);
                same_len("leaders", idx.len(), items.len())?;
                idx.iter()
                    .enumerate()
                    .map(|(k, &i)| {
                        usize::try_from(i).ok().filter(|&i| i < n).ok_or_else(|| {
                            input_error(format!("leader_index[{k}] = {i}: not an index into slots"))
                        })
                    })
                    .collect::<PyResult<_>>()?
            }
        };
        for (k, item) in items.iter().enumerate() {
            let i = at[k];
            // An entry given here is the leader, whatever the lane lists said.
            gaps[i] = f64::NAN;
            lslots[i] = -1;
            if item.is_none() {
                continue;
            }
            let t = item.cast::<PyTuple>().map_err(|_| {
                input_error(format!("leaders[{k}] is not None or an (id, gap) tuple"))
            })?;
            if t.len() != 2 && t.len() != 3 {
                return Err(input_error(format!(
                    "leaders[{k}] has {} items, expected 2 (id, gap) or 3 (id, gap, room)",
                    t.len()
                )));
            }
            let id = t.get_item(0)?;
            let id = id
                .cast::<PyString>()
                .map_err(|_| input_error(format!("leaders[{k}]: the id is not a string")))?;
            let gap: f64 = t
                .get_item(1)?
                .extract()
                .map_err(|_| input_error(format!("leaders[{k}]: the gap is not a number")))?;
            if let Some((slot, speed)) = self.leader_of(id, gap, speed_of)? {
                (gaps[i], lslots[i], lspeeds[i]) = (gap, slot, speed);
                if t.len() == 3 {
                    rooms[i] = t.get_item(2)?.extract().map_err(|_| {
                        input_error(format!("leaders[{k}]: the room is not a number"))
                    })?;
                }
            }
        }
        let mut ln = vec![-1i64; n];
        let mut lp = vec![f64::NAN; n];
        let ri = read_index.as_ref().map(vec_of).unwrap_or_default();
        let rl = read_lane.as_ref().map(vec_of).unwrap_or_default();
        let rp = read_pos.as_ref().map(vec_of).unwrap_or_default();
        same_len("read_lane", ri.len(), rl.len())?;
        same_len("read_pos", ri.len(), rp.len())?;
        for (k, &i) in ri.iter().enumerate() {
            let i = usize::try_from(i).ok().filter(|&i| i < n).ok_or_else(|| {
                input_error(format!("read_index[{k}] = {i}: not an index into slots"))
            })?;
            ln[i] = rl[k];
            lp[i] = rp[k];
        }
        let obs = Observations {
            slots: &sl,
            leader_gap_m: &gaps,
            leader_slot: &lslots,
            leader_speed_mps: &lspeeds,
            leader_room_m: Some(&rooms),
            lane: &ln,
            lane_pos_m: &lp,
            soft: soft.as_ref().map(|(g, s, v)| SoftLeaders {
                gap_m: g,
                slot: s,
                speed_mps: v,
            }),
        };
        self.run_plan(py, &obs)
    }

    /// The lanes (the caller's ids) on which at least two of `slots` are where
    /// blendtrack knows the simulator has them: the lanes worth listing for
    /// `leaders_on_lanes`.
    fn lanes_with_followers<'py>(
        &self,
        py: Python<'py>,
        slots: I64In<'py>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let sl = vec_of(&slots);
        let lanes = self
            .inner
            .lanes_with_followers(&sl)
            .map_err(traffic_error)?;
        Ok(lanes
            .into_iter()
            .map(i64::from)
            .collect::<Vec<_>>()
            .into_pyarray(py))
    }

    /// Leaders read off SUMO's `lane.getLastStepVehicleIDs` of `lanes` (one
    /// sequence of vehicle ids per lane, back to front): for each entry of
    /// `slots`, the leader and gap `vehicle.getLeader` would give when the
    /// vehicle in front of it on its lane is one added here with a name and
    /// both places are known. They are kept for the next `plan_sumo` with
    /// these `slots` and `leader_index`; returns the indices (into `slots`)
    /// of the vehicles whose leader only SUMO can tell.
    fn leaders_on_lanes<'py>(
        &mut self,
        py: Python<'py>,
        slots: I64In<'py>,
        lanes: I64In<'py>,
        vehicles: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let sl = vec_of(&slots);
        let ln = vec_of(&lanes);
        let mut lists = Vec::with_capacity(ln.len());
        for (k, seq) in vehicles.try_iter()?.enumerate() {
            let seq = seq?;
            let mut list = Vec::with_capacity(seq.len().unwrap_or(0));
            for id in seq.try_iter()? {
                let id = id?;
                let id = id
                    .cast::<PyString>()
                    .map_err(|_| input_error(format!("vehicles[{k}]: an id is not a string")))?;
                list.push(self.slot_of.get(id.to_str()?).copied());
            }
            lists.push(list);
        }
        let lanes_u32 = ln
            .iter()
            .enumerate()
            .map(|(i, &l)| u32_of("lanes", i, l))
            .collect::<PyResult<Vec<u32>>>()?;
        let found = self
            .inner
            .leaders_on_lanes(&sl, &lanes_u32, &lists)
            .map_err(traffic_error)?;
        let ask: Vec<i64> = (0..found.len())
            .filter(|&i| found[i].is_none())
            .map(|i| i as i64)
            .collect();
        self.listed = Some((sl, found));
        Ok(ask.into_pyarray(py))
    }

    /// What the last `leaders_on_lanes` read off the lane lists, per slot:
    /// `(leader id, gap)`, or None where SUMO must be asked (for inspection;
    /// `plan_sumo` uses them itself).
    fn listed_leaders<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyList>> {
        let out = pyo3::types::PyList::empty(py);
        if let Some((_, found)) = &self.listed {
            for f in found {
                match f.and_then(|(l, gap)| {
                    self.name_of
                        .get(l as usize)
                        .and_then(Option::as_ref)
                        .map(|n| (n, gap))
                }) {
                    Some((name, gap)) => out.append((name.as_str(), gap))?,
                    None => out.append(py.None())?,
                }
            }
        }
        Ok(out)
    }

    /// Second half of a step: `must_yield[j]` answers the j-th index `plan`
    /// returned. Returns a dict of arrays in the plan's order (see the class docs).
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        must_yield: PyArrayLike1<'py, bool, AllowTypeChange>,
        dt: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let answers = vec_of(&must_yield);
        let inner = &mut self.inner;
        let r = py
            .detach(|| inner.step(&answers, dt))
            .map_err(traffic_error)?;
        let d = PyDict::new(py);
        let moves: Vec<u8> = r.moves.iter().map(|m| *m as u8).collect();
        d.set_item("move", moves.into_pyarray(py))?;
        let ints = |v: Vec<u32>| v.into_iter().map(i64::from).collect::<Vec<i64>>();
        d.set_item("lane", ints(r.lane).into_pyarray(py))?;
        d.set_item("edge", ints(r.edge).into_pyarray(py))?;
        d.set_item("lane_index", ints(r.lane_index).into_pyarray(py))?;
        for (k, col) in [
            ("lane_pos_m", r.lane_pos_m),
            ("x_front_m", r.x_front_m),
            ("y_front_m", r.y_front_m),
            ("angle_deg", r.angle_deg),
            ("x_m", r.x_m),
            ("y_m", r.y_m),
            ("theta_rad", r.theta_rad),
            ("v_mps", r.v_mps),
            ("delta_rad", r.delta_rad),
            ("alpha", r.alpha),
            ("accel_mps2", r.accel_mps2),
            ("lateral_error_m", r.lateral_error_m),
            ("heading_error_rad", r.heading_error_rad),
            ("s_rear_m", r.s_rear_m),
            ("curvature_per_m", r.curvature_per_m),
            ("virtual_obstacle_m", r.virtual_obstacle_m),
            ("sumo_speed_mps", r.sumo_speed_mps),
        ] {
            d.set_item(k, col.into_pyarray(py))?;
        }
        for (k, col) in [
            ("red_light", r.red_light),
            ("past_route_end", r.past_route_end),
            ("lane_change_due", r.lane_change_due),
            ("read_position", r.read_position),
            ("xy_on_track", r.xy_on_track),
        ] {
            d.set_item(k, col.into_pyarray(py))?;
        }
        Ok(d)
    }

    /// The (|curvature|, |v|, |lateral error|, |lateral acceleration|)
    /// samples kept since the last call, as an (N, 4) array.
    fn take_samples<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let s = self.inner.take_samples();
        let flat: Vec<f64> = s.iter().flatten().copied().collect();
        Array2::from_shape_vec((s.len(), 4), flat)
            .expect("rows of 4")
            .into_pyarray(py)
    }

    #[getter]
    fn n_tracks(&self) -> usize {
        self.inner.fleet().n_tracks()
    }

    /// Track ids in the registry, removed ones included: the most tracks
    /// registered at once (removed ids are handed out again).
    #[getter]
    fn track_capacity(&self) -> usize {
        self.inner.fleet().track_capacity()
    }

    /// Threads a step of many vehicles is split over: 0 (the default) for
    /// one per core, 1 to stay on the calling thread.
    #[getter]
    fn threads(&self) -> usize {
        self.inner.fleet().threads()
    }
    #[setter]
    fn set_threads(&mut self, threads: usize) {
        self.inner.set_threads(threads);
    }

    /// Whether the simulator moves a vehicle over a step at the mean of
    /// its speeds at the step's start and end (SUMO's
    /// `--step-method.ballistic`) rather than at its new speed (False, the
    /// default): speed-only and lane-position moves are worked out for it.
    #[getter]
    fn ballistic(&self) -> bool {
        self.inner.settings().ballistic
    }
    #[setter]
    fn set_ballistic(&mut self, ballistic: bool) {
        self.inner.set_ballistic(ballistic);
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "RouteFleet(tracks={}, vehicles={})",
            self.inner.fleet().n_tracks(),
            self.inner.len()
        )
    }
}

impl RouteFleet {
    /// `plan_sumo`'s `soft_leaders` as columns (gap, slot, speed) over `n` slots.
    fn soft_leaders(
        &self,
        list: &Bound<'_, PyAny>,
        n: usize,
        speed_of: &Bound<'_, PyAny>,
    ) -> PyResult<(Vec<f64>, Vec<i64>, Vec<f64>)> {
        let mut gaps = vec![f64::NAN; n];
        let mut slots = vec![-1i64; n];
        let mut speeds = vec![f64::NAN; n];
        for (k, item) in list.try_iter()?.enumerate() {
            let item = item?;
            let bad = || {
                input_error(format!(
                    "soft_leaders[{k}] is not an (index, id, gap) tuple"
                ))
            };
            let t = item.cast::<PyTuple>().map_err(|_| bad())?;
            if t.len() != 3 {
                return Err(bad());
            }
            let i: i64 = t.get_item(0)?.extract().map_err(|_| bad())?;
            let i = usize::try_from(i).ok().filter(|&i| i < n).ok_or_else(|| {
                input_error(format!(
                    "soft_leaders[{k}]: index {i} is not an index into slots"
                ))
            })?;
            let id = t.get_item(1)?;
            let id = id.cast::<PyString>().map_err(|_| bad())?;
            let gap: f64 = t.get_item(2)?.extract().map_err(|_| bad())?;
            if let Some((slot, speed)) = self.leader_of(id, gap, speed_of)? {
                (gaps[i], slots[i], speeds[i]) = (gap, slot, speed);
            }
        }
        Ok((gaps, slots, speeds))
    }

    /// A leader as SUMO names it: None if it is no leader (empty id, gap
    /// below -100 m), else (its slot, -1 if not driven here; its speed, NaN
    /// if driven here or unreadable).
    fn leader_of(
        &self,
        id: &Bound<'_, PyString>,
        gap: f64,
        speed_of: &Bound<'_, PyAny>,
    ) -> PyResult<Option<(i64, f64)>> {
        let name = id.to_str()?;
        if name.is_empty() || !(gap >= -100.0) {
            return Ok(None);
        }
        Ok(Some(match self.slot_of.get(name) {
            Some(&s) => (s, f64::NAN),
            None => (
                -1,
                speed_of
                    .call1((id,))
                    .and_then(|v| v.extract::<f64>())
                    .unwrap_or(f64::NAN),
            ),
        }))
    }

    /// The core's plan with the interpreter released; the query indices as an array.
    fn run_plan<'py>(
        &mut self,
        py: Python<'py>,
        obs: &Observations<'_>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let inner = &mut self.inner;
        let q = py.detach(|| inner.plan(obs)).map_err(traffic_error)?;
        Ok(q.into_iter()
            .map(|i| i as i64)
            .collect::<Vec<_>>()
            .into_pyarray(py))
    }
}

#[allow(dead_code)]
fn _move_codes_are_stable() {
    // The Python side relies on these numbers.
    const _: () = assert!(
        Move::Speed as u8 == 0
            && Move::Lane as u8 == 1
            && Move::Xy as u8 == 2
            && Move::Invalid as u8 == 3
            && Move::Hold as u8 == 4
    );
}
