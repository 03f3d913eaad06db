//! The second half of a step ([`RouteFleet::step`]): the yield answers, the
//! fleet's controllers and bicycle models, the choice of each [`Move`], and
//! the statistics; results in [`RouteOutputs`].

use crate::error::check_len;
use crate::placement::{choose_move, Motion, Move};
use crate::plan::Plan;
use crate::route::Route;
use crate::signal::{signal_at, Signal};
use crate::substep::{
    advance, braking_mean_speed, control_record, held_speed, past_route_end, state_at,
    stepped_finite, substeps, Front, HeldGaps, LastStep,
};
use crate::{Driven, RouteFleet, TrafficError, ADVANCE_MAX_M};
use blendtrack::path::wrap_angle;
use blendtrack::{Fleet, FleetInputs, FleetOutputs, NextStates, VehicleState};
use nalgebra::Point2;

/// A vehicle moved by (x, y) whose front is further than this (m) off its
/// track is put into the simulator at the track's point at the front's arc
/// length instead: the simulator maps a front point onto the nearest lane,
/// and where a turn is tighter than the vehicle can drive (at Bologna's
/// junction 47 a 2.4 m junction lane turns about 170 deg) the front, swung
/// 2-3 m wide, mapped onto the start of the junction lane, metres behind
/// the vehicle's progress, into the minGap of the vehicle behind.
pub const XY_ON_TRACK_M: f64 = 1.0;

/// One step's results, one entry per planned slot, in the plan's order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RouteOutputs {
    pub moves: Vec<Move>,
    /// For [`Move::Lane`]: lane and position; for [`Move::Xy`]: edge and lane index.
    pub lane: Vec<u32>,
    pub lane_pos_m: Vec<f64>,
    pub edge: Vec<u32>,
    pub lane_index: Vec<u32>,
    /// Front-bumper point and SUMO angle (deg, clockwise from north); for
    /// a [`Move::Xy`] with the front over [`XY_ON_TRACK_M`] off the track,
    /// the track's point and heading at the front's arc length instead
    /// (`xy_on_track`).
    pub x_front_m: Vec<f64>,
    pub y_front_m: Vec<f64>,
    pub angle_deg: Vec<f64>,
    /// The new state.
    pub x_m: Vec<f64>,
    pub y_m: Vec<f64>,
    pub theta_rad: Vec<f64>,
    pub v_mps: Vec<f64>,
    pub delta_rad: Vec<f64>,
    /// The blend factor the controller used (the last control step's).
    pub alpha: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    pub lateral_error_m: Vec<f64>,
    /// The body is past the route's end (the track ends there: the lateral
    /// error is then the distance past it, not an error).
    pub past_route_end: Vec<bool>,
    pub heading_error_rad: Vec<f64>,
    pub s_rear_m: Vec<f64>,
    pub curvature_per_m: Vec<f64>,
    pub virtual_obstacle_m: Vec<f64>,
    /// The gap to the leader at the end of the step, the leader held at the
    /// speed it was observed at (m; less the standstill margin; NaN: none).
    pub leader_gap_m: Vec<f64>,
    /// The front crossed a stop line whose light is red in this step.
    pub red_light: Vec<bool>,
    /// A lane change is due where the vehicle now is: ask the simulator for room.
    pub lane_change_due: Vec<bool>,
    /// Report the simulator's lane and lane position next step: unknown to
    /// blendtrack, or due for a check of the prediction.
    pub read_position: Vec<bool>,
    /// A move by (x, y) given the track's point, not the front (see `x_front_m`).
    pub xy_on_track: Vec<bool>,
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
            alpha: Vec::with_capacity(n),
            accel_mps2: Vec::with_capacity(n),
            lateral_error_m: Vec::with_capacity(n),
            past_route_end: Vec::with_capacity(n),
            heading_error_rad: Vec::with_capacity(n),
            s_rear_m: Vec::with_capacity(n),
            curvature_per_m: Vec::with_capacity(n),
            virtual_obstacle_m: Vec::with_capacity(n),
            leader_gap_m: Vec::with_capacity(n),
            red_light: Vec::with_capacity(n),
            lane_change_due: Vec::with_capacity(n),
            read_position: Vec::with_capacity(n),
            xy_on_track: Vec::with_capacity(n),
            sumo_speed_mps: Vec::with_capacity(n),
        }
    }
}

impl RouteFleet {
    /// Second half of a step: `must_yield[j]` answers the `j`-th index
    /// returned by [`RouteFleet::plan`]. Steps every planned vehicle over `dt_s`.
    ///
    /// Stages: the yield answers become stop lines ([`Self::answer_yields`]),
    /// the planned vehicles' states are packed into the fleet's inputs and
    /// stepped (at the control rate: [`Self::control_steps`]), then each
    /// vehicle's move is chosen, its red-light crossing detected and its
    /// statistics accumulated ([`Self::step_vehicle`]).
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
        self.answer_yields(&mut plan, must_yield);
        let n = substeps(dt_s, self.settings.control_dt_s);
        let last = if n == 1 {
            let states = self.planned_states(&plan);
            let advance = vec![0.0; plan.slots.len()];
            let fronts = self.fronts(&plan);
            let gaps = HeldGaps::of_plan(&plan);
            let out = self.step_fleet(&plan, &states, gaps, &fronts, &advance, dt_s)?;
            LastStep {
                out,
                before: states,
                advance,
                h: dt_s,
                skip_past_end: false,
            }
        } else {
            self.control_steps(&plan, dt_s, n)?
        };
        let next = last.out.next.as_ref().expect("dt was given");
        let mut r = RouteOutputs::with_capacity(plan.slots.len());
        for i in 0..plan.slots.len() {
            self.step_vehicle(&plan, i, &last, next, dt_s, &mut r)?;
        }
        Ok(r)
    }

    /// Stage 1: a vehicle told to give way stops at the line it asked about
    /// (and holds there while the reason lasts); one told it may go does not.
    fn answer_yields(&mut self, plan: &mut Plan, must_yield: &[bool]) {
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
    }

    /// The planned vehicles' states, in the plan's order.
    pub(crate) fn planned_states(&self, plan: &Plan) -> Vec<VehicleState> {
        plan.slots
            .iter()
            .map(|&slot| {
                self.driven[slot as usize]
                    .as_ref()
                    .expect("planned slots are driven")
                    .state
            })
            .collect()
    }

    /// Stage 2: `states` (one per planned slot) and the plan's leaders, stop
    /// lines and limits (with the gaps of `gaps`) packed into the fleet's
    /// inputs, stepped over `dt_s`. The leaders' and soft leaders' gaps are
    /// the simulator's; each becomes the distance along the vehicle's track
    /// that uses it up ([`crate::Route::arc_gap`]: less any jump of the
    /// simulator's station in it), the front being `advance` (m, one per
    /// planned slot) past where `fronts` has it.
    pub(crate) fn step_fleet(
        &mut self,
        plan: &Plan,
        states: &[VehicleState],
        gaps: HeldGaps<'_>,
        fronts: &[Front],
        advance: &[f64],
        dt_s: f64,
    ) -> Result<FleetOutputs, TrafficError> {
        let n = plan.slots.len();
        let with_stations = fronts.iter().any(|f| f.route.stations.is_some());
        let along = |g: &[f64]| -> Vec<f64> {
            fronts
                .iter()
                .zip(advance)
                .zip(g)
                .map(|((f, a), &g)| f.route.arc_gap(f.s_m + a, g))
                .collect()
        };
        // A moving leader: its stop point through the stations, as the
        // stopping law sees it (`Route::arc_gap_moving`).
        let leaders_along = || -> Result<Vec<f64>, TrafficError> {
            let mut out = Vec::with_capacity(n);
            for (i, ((f, a), &g)) in fronts.iter().zip(advance).zip(gaps.leader).enumerate() {
                let b_l = self
                    .fleet
                    .vehicle_config(plan.slots[i])?
                    .max_obs_deceleration;
                let v_l = gaps.leader_speed[i].max(0.0);
                out.push(
                    f.route
                        .arc_gap_moving(f.s_m + a, g, v_l * v_l / (-2.0 * b_l)),
                );
            }
            Ok(out)
        };
        let converted = if with_stations {
            Some((leaders_along()?, along(gaps.soft)))
        } else {
            None
        };
        let gaps = match &converted {
            Some((leader, soft)) => HeldGaps {
                leader,
                soft,
                ..gaps
            },
            None => gaps,
        };
        let mut cols: [Vec<f64>; 5] = std::array::from_fn(|_| Vec::with_capacity(n));
        for s in states {
            for (c, x) in cols
                .iter_mut()
                .zip([s.x_m, s.y_m, s.theta_rad, s.v_mps, s.delta_rad])
            {
                c.push(x);
            }
        }
        let inputs = FleetInputs {
            leader_gap_m: Some(gaps.leader),
            leader_speed_mps: Some(gaps.leader_speed),
            leader_reaction_s: gaps.leader_reaction,
            stop_gap_m: Some(gaps.stop),
            soft_gap_m: Some(gaps.soft),
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
        Ok(self.fleet.step(&inputs)?)
    }

    /// Stage 3, per vehicle: where its front is on its track after the
    /// step, the move that puts it into the simulator, a red-light
    /// crossing, its statistics (of the last control step), and its row of
    /// the outputs.
    fn step_vehicle(
        &mut self,
        plan: &Plan,
        i: usize,
        last: &LastStep,
        next: &NextStates,
        dt_s: f64,
        r: &mut RouteOutputs,
    ) -> Result<(), TrafficError> {
        let out = &last.out;
        let slot = plan.slots[i] as usize;
        let params = *self.fleet.vehicle_params(slot as i64)?;
        let d = self.driven[slot]
            .as_mut()
            .expect("planned slots are driven");
        let mut state = state_at(next, i);
        let finite = stepped_finite(&state, out.s_rear_m[i]);
        let (v, th) = (state.v_mps, state.theta_rad);
        let reach = d.body.reach_m;
        let (mut xf, mut yf) = (state.x_m + reach * th.cos(), state.y_m + reach * th.sin());
        // The front's arc length at the NEW state (the controller's
        // outputs are of the state it was given, one step behind).
        let mut sf_new = if finite {
            front_arc_after(&self.fleet, slot, d, Point2::new(xf, yf), v * dt_s)?
        } else {
            f64::NAN
        };
        let mut k = if finite { d.route.piece_at(sf_new) } else { 0 };
        let motion = Motion {
            usable: out.ok[i] && finite,
            lateral_error_m: out.lateral_error_m[i],
            heading_error_rad: out.heading_error_rad[i],
            v_mps: v,
            s_front_m: sf_new,
            dt_s,
            leader_room_m: if plan.leader_room[i].is_finite() {
                plan.leader_room[i]
            } else {
                f64::INFINITY
            },
        };
        let st = self.settings;
        let mut p = choose_move(d, k, &st, &motion);
        if v < CATCH_UP_BELOW_MPS {
            if let Some(ahead) = simulator_ahead(d, k, sf_new).filter(|&ahead| {
                (p.mv == Move::Xy && (v > 0.0 || ahead > catch_up_standing_m(&d.route, sf_new)))
                    || ((p.mv == Move::Speed || p.mv == Move::Hold)
                        && ahead > CATCH_UP_SPEED_MOVE_M)
            }) {
                // A crawl: never put back (see `simulator_ahead`); the new
                // state goes on to where the simulator has the front. Not
                // a vehicle standing: SUMO maps the front it is put at a few
                // centimetres on along a curved junction lane, and caught
                // up with every step, a left turner waiting at its internal
                // point on the grid crept 0.8 m in 3 s over it; SUMO's
                // oncoming drivers then stopped for it inside the junction,
                // in its way, and neither moved again (junctions B0 and C1,
                // seed 2). Standing, it is held where it was put.
                state.x_m += ahead * th.cos();
                state.y_m += ahead * th.sin();
                (xf, yf) = (xf + ahead * th.cos(), yf + ahead * th.sin());
                sf_new += ahead;
                k = d.route.piece_at(sf_new);
                p = choose_move(
                    d,
                    k,
                    &st,
                    &Motion {
                        s_front_m: sf_new,
                        ..motion
                    },
                );
            }
        }
        // What the simulator is given for a move by (x, y): the front, or,
        // with the front further off the track than XY_ON_TRACK_M (a turn
        // tighter than the vehicle can drive), the track's point at the
        // front's arc length; the angle is the vehicle's own heading either
        // way. The simulator draws the body back from the front along the
        // angle: given the track's heading at the front, a 12 m bus coming
        // out of a turn at Bologna's 39a (its body 112 deg, the lane ahead
        // 70 deg) swung its back 41 deg across the minor road, onto the car
        // waiting at the line there (30 %, seed 27, 225 s).
        let (mut x_put, mut y_put, th_put) = (xf, yf, th);
        let mut on_track = false;
        if p.mv == Move::Xy {
            let path = &self
                .fleet
                .track(self.fleet.vehicle_track(slot as i64)? as i64)?
                .path;
            let at = path.point_at(sf_new);
            if (at - Point2::new(xf, yf)).norm() > XY_ON_TRACK_M {
                (x_put, y_put) = (at.x, at.y);
                on_track = true;
            }
        }
        // A vehicle standing where the last move by (x, y) put it, still
        // told to stand, needs nothing sent: the simulator keeps it there.
        // Sent again every step, the move also undid the simulator's own
        // teleport of a vehicle that had waited too long (SUMO applies a
        // remote move after the step's teleports): a car waiting 300 s to
        // turn left was teleported onward, put back at its line as one of
        // SUMO's (no longer controlled), and run into 11 s later (Bologna,
        // 34_2).
        let pose = (x_put, y_put, th_put);
        // (A move by (x, y) sends the speed v, here 0, so the Hold keeps it.)
        if p.mv == Move::Xy && v == 0.0 && d.sumo_speed == 0.0 && d.placed_xy == Some(pose) {
            p.mv = Move::Hold;
        }
        let piece = d.route.pieces[k];
        let mut red = false;
        let mut due = false;
        if p.mv != Move::Invalid {
            red = crossed_red(&self.signals, d, sf_new);
            if red {
                d.stats.red_light_violations += 1;
            }
            if let Some(lc) = d.route.lane_change {
                due = piece.edge == lc.edge
                    && piece.lane_index != lc.target_index
                    && lc.occurrence.map_or(true, |k| k == piece.occurrence);
            }
            let step = control_record(
                out,
                i,
                &last.before[i],
                &state,
                params.wheelbase_m,
                plan.limit[i],
                last.h,
            );
            let past_end = last.skip_past_end && past_route_end(d, out.s_rear_m[i]);
            if !past_end {
                if let Some(sample) = d.stats.add_step(&step, &st) {
                    self.samples.push(sample);
                }
            }
            // Over the whole step (the last control step's with one).
            let accel = (v - d.state.v_mps) / dt_s;
            r.accel_mps2.push(accel);
            d.lead_speed = braking_mean_speed(v, accel, dt_s);
            d.steps += 1;
            d.state = state;
            d.s_front_m = sf_new;
            d.known = p.predicted;
            d.sumo_speed = p.sumo_speed;
            match p.mv {
                Move::Xy => d.placed_xy = Some(pose),
                Move::Hold => {}
                _ => d.placed_xy = None,
            }
        } else {
            r.accel_mps2.push(f64::NAN);
        }
        r.moves.push(p.mv);
        r.lane.push(piece.lane);
        r.lane_pos_m.push(p.pos);
        r.edge.push(piece.edge);
        r.lane_index.push(piece.lane_index);
        r.x_front_m.push(x_put);
        r.y_front_m.push(y_put);
        r.angle_deg
            .push((90.0 - wrap_angle(th_put).to_degrees()).rem_euclid(360.0));
        r.xy_on_track.push(on_track);
        r.x_m.push(state.x_m);
        r.y_m.push(state.y_m);
        r.theta_rad.push(th);
        r.v_mps.push(v);
        r.delta_rad.push(state.delta_rad);
        r.alpha.push(out.alpha[i]);
        r.lateral_error_m.push(motion.lateral_error_m);
        r.past_route_end.push(past_route_end(d, out.s_rear_m[i]));
        r.heading_error_rad.push(motion.heading_error_rad);
        r.s_rear_m.push(out.s_rear_m[i]);
        r.curvature_per_m.push(out.curvature_per_m[i]);
        r.virtual_obstacle_m.push(out.virtual_obstacle_m[i]);
        let moved = advance(&last.before[i], &state);
        r.leader_gap_m.push(
            plan.leader_gap[i] + held_speed(plan.leader_speed[i]) * dt_s
                - (last.advance[i] + moved),
        );
        r.red_light.push(red);
        r.lane_change_due.push(due);
        // Read back where the prediction ends, and now and then to check it.
        let verify = st.verify_every > 0 && d.steps % st.verify_every == 0;
        r.read_position
            .push(p.mv != Move::Invalid && (d.known.is_none() || verify));
        r.sumo_speed_mps.push(p.sumo_speed);
        Ok(())
    }
}

/// The arc length of vehicle `d`'s front at `front`, its new place after
/// about `advance` metres (the look-up starts from the old one's segment).
fn front_arc_after(
    fleet: &Fleet,
    slot: usize,
    d: &mut Driven,
    front: Point2<f64>,
    advance: f64,
) -> Result<f64, TrafficError> {
    let path = &fleet.track(fleet.vehicle_track(slot as i64)? as i64)?.path;
    let (s, seg) = path.arc_near_from(&front, d.s_front_m + advance, d.seg_front);
    d.seg_front = seg;
    Ok(s)
}

/// Stage 4: the front passed, over the step, the stop line ahead while its
/// light is red (from arc length `d.s_front_m` to `s_new`).
fn crossed_red(signals: &[Vec<Signal>], d: &Driven, s_new: f64) -> bool {
    d.route.stops.get(d.next_stop).is_some_and(|stop| {
        stop.signal.is_some()
            && d.s_front_m < stop.s_m
            && stop.s_m <= s_new
            && signal_at(signals, stop) == Signal::Stop
    })
}

/// Below this speed (m/s) a move by (x, y) never puts a vehicle back behind
/// where the simulator has its front ([`simulator_ahead`]).
const CATCH_UP_BELOW_MPS: f64 = 2.0;

/// A crawl's speed-only move lets the simulator stay this far (m) ahead of
/// the front's new place before the state goes on to where the simulator
/// has it: slowed within its speed tolerance only, in a stop-and-go queue
/// the simulator drifted 5 m ahead and the car was handed back for a
/// placement fault (Eccles, 145868728, most of the 49 faults over seeds
/// 0-23).
const CATCH_UP_SPEED_MOVE_M: f64 = 1.0;

/// A standing vehicle moved by (x, y) is caught up only when the simulator
/// has its front more than this (m) ahead: SUMO maps a front put on a
/// curved junction lane up to about 0.3 m further on (caught up at any
/// distance, a left turner on the grid crept over its waiting point), but
/// a car that had stopped 0.99 m behind where SUMO had it after a crawl
/// was put back onto the driver behind it (Eccles, 30 %, seed 17, 342 s,
/// 145852815_3).
const CATCH_UP_STANDING_M: f64 = 0.75;

/// The same off junction lanes, where the track lies on a lane SUMO maps
/// a front onto exactly: a car that had stopped 0.65 m behind where SUMO
/// had it after a crawl, 2.4 deg off its track (so moved by (x, y)), was
/// put back into the minGap of the driver behind it (Eccles, 30 %, seed
/// 17, 397 s, 296702213_0).
const CATCH_UP_STANDING_ROAD_M: f64 = 0.3;

/// How far ahead (m) the simulator may have a standing vehicle's front
/// before a move by (x, y) catches up with it, at arc length `s` of `route`:
/// [`CATCH_UP_STANDING_M`] inside a junction (from a stop line to where the
/// junction is left), [`CATCH_UP_STANDING_ROAD_M`] elsewhere.
fn catch_up_standing_m(route: &Route, s: f64) -> f64 {
    if route
        .stops()
        .iter()
        .any(|stop| stop.s_m <= s && s < stop.exit_m)
    {
        CATCH_UP_STANDING_M
    } else {
        CATCH_UP_STANDING_ROAD_M
    }
}

/// The most (m) a piece's track may lie off its lane's centreline for
/// [`simulator_ahead`] to compare lane positions there.
const CATCH_UP_OFFSET_M: f64 = 0.1;

/// How far (m of track, `0 < x <=` [`ADVANCE_MAX_M`]) the simulator has the
/// front of `d` ahead of arc length `sf_new` on piece `k`'s lane, when it
/// has it on that lane and the track lies on the lane there; None
/// otherwise. In a stop-and-go crawl the speed-only moves let the
/// simulator run ahead of blendtrack's state (it is slowed, never put
/// back: `placement::glide_move`), and the next move by (x, y) put the car
/// back onto the driver behind it: at Eccles (30 %, seed 8, 393 s; seed 6,
/// 408 s) a controlled car creeping onto 145852815's lane 3 just past the
/// junction was moved 0.5 m back, a collision each time.
pub(crate) fn simulator_ahead(d: &Driven, k: usize, sf_new: f64) -> Option<f64> {
    let (lane, at) = d.known?;
    let piece = &d.route.pieces[k];
    // Only where the track lies on the lane: where it cuts a corner (a
    // rounded turn, a junction lane it leaves) SUMO's lane position runs
    // ahead of the arc length by design (`Route::arc_gap`).
    if piece.lane != lane
        || !sf_new.is_finite()
        || !(piece.scale > 0.0)
        || !(piece.offset_m <= CATCH_UP_OFFSET_M)
    {
        return None;
    }
    let ahead = (at - piece.lane_pos_at(sf_new)) / piece.scale;
    (ahead > 0.0 && ahead <= ADVANCE_MAX_M).then_some(ahead)
}
