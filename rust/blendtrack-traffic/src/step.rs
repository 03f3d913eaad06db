//! The second half of a step ([`RouteFleet::step`]): the yield answers, the
//! fleet's controllers and bicycle models, the choice of each [`Move`], and
//! the statistics; results in [`RouteOutputs`].

use crate::error::check_len;
use crate::placement::*;
use crate::signal::{signal_at, Signal};
use crate::{RouteFleet, TrafficError};
use blendtrack::path::wrap_angle;
use blendtrack::{FleetInputs, VehicleState};
use nalgebra::Point2;

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

impl RouteFleet {
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
