//! The control rate inside one simulator step ([`RouteFleet::step`]): a
//! step of `dt` is `n = ceil(dt / control_dt)` control steps of `h = dt / n`
//! with what the simulator reported held for the step (see the crate docs),
//! each control step but the last taken into the statistics here; the last
//! one goes on to the choice of the move ([`LastStep`]).

use crate::plan::{Plan, NO_ENTRY};
use crate::stats::StepRecord;
use crate::{Route, RouteFleet, TrafficError};
use blendtrack::{FleetOutputs, NextStates, VehicleState};
use std::sync::Arc;

/// A few parts per billion of `control_dt` are forgiven, so that a step of
/// exactly `k control_dt` in floating point is `k` control steps, not `k + 1`.
const RATE_SLACK: f64 = 1e-9;

/// The number of control steps in a simulator step of `dt_s`:
/// `ceil(dt / control_dt)` (less [`RATE_SLACK`]), at least 1.
pub(crate) fn substeps(dt_s: f64, control_dt_s: f64) -> usize {
    let n = (dt_s / control_dt_s - RATE_SLACK).ceil();
    if n >= 1.0 {
        n as usize
    } else {
        1
    }
}

/// The speed an obstacle is held at: its observed speed, forwards only
/// (the fleet takes a NaN speed as standing, and so does this).
pub(crate) fn held_speed(v_mps: f64) -> f64 {
    if v_mps.is_finite() {
        v_mps.max(0.0)
    } else {
        0.0
    }
}

/// The shortest simulator step (s) over which leaders are held by what they
/// can still do within the step: one braking at its mean speed, one driven
/// here moved with its own control steps, one the simulator drives at its
/// stop point. Below it a leader is seen again before it gets far. The SUMO
/// bridge reads it from the binding.
pub const HOLD_BRAKING_MIN_STEP_S: f64 = 0.5;

/// The speed to hold a leader at over a step of `dt_s`, given its speed
/// `v_mps` and its acceleration over the last step: its mean speed over the
/// step if it goes on braking so (stopping within the step, if it does),
/// else its speed. Held at its speed, a leader braking into a queue gains on
/// its follower all step, and at a 1 s step the follower, re-planning at
/// every control step against where the leader is not, ran into it; at the
/// mean speed it is never ahead of where it gets braking so (`v t` with
/// `v = v0 + a dt / 2` against `v0 t + a t^2 / 2`, for `t` up to `dt`).
/// The simulator's drivers get the same from the bridge. Only for steps of
/// [`HOLD_BRAKING_MIN_STEP_S`] or more: below, the speed hold is off by at
/// most `a dt^2 / 2` (2 cm at 0.1 s and 4.5 m/s^2), and the mean speed, fed
/// from follower to follower down a platoon, cost the highway with every
/// vehicle controlled 7 of its 151 arrivals in 300 s.
pub(crate) fn braking_mean_speed(v_mps: f64, accel_mps2: f64, dt_s: f64) -> f64 {
    if !(accel_mps2 < 0.0 && v_mps > 0.0 && dt_s >= HOLD_BRAKING_MIN_STEP_S) {
        return v_mps;
    }
    if v_mps + accel_mps2 * dt_s <= 0.0 {
        v_mps * v_mps / (-2.0 * accel_mps2) / dt_s
    } else {
        v_mps + 0.5 * accel_mps2 * dt_s
    }
}

/// The speed at which a leader's gap grows over a step of `dt_s`, in the
/// control steps after the first: its held speed (`v_mps`, see
/// [`held_speed`]) for a leader driven here, whose control steps are known
/// to move at that speed or its mean while braking. A leader the simulator
/// drives is not held to anything inside the step: SUMO's driver picks its
/// speed for the whole step at its start, and may brake at its decel (or
/// harder) then, where the follower's control steps cannot see it until
/// the next step. The stopping law depends on a leader only through its
/// stop point (`gap + v_l^2 / (2 b_l)`); holding the gap still over the step
/// (speed 0 here, the law's leader speed kept) holds that stop point where
/// it was at the start of the step: the follower stays able to stop behind
/// a leader that began braking then, as SUMO's own drivers do (their safe
/// speed is chosen for the whole step from the leader's state at its start).
/// Only for steps of [`HOLD_BRAKING_MIN_STEP_S`] or more: at 0.1 s the leader
/// is seen again before it gets far.
pub(crate) fn leader_advance_speed(v_mps: f64, external: bool, dt_s: f64) -> f64 {
    if external && dt_s >= HOLD_BRAKING_MIN_STEP_S {
        0.0
    } else {
        held_speed(v_mps)
    }
}

/// The stopping law's reaction time for a leader the simulator drives, `t`
/// into a step of [`HOLD_BRAKING_MIN_STEP_S`] or more (control steps of
/// `h`): the vehicle's reaction time `tau_s` counted from when the leader
/// was seen, at the start of the step, never under one control step.
///
/// The leader is held at its worst over the step (its stop point where it
/// was then, [`leader_advance_speed`]), so whatever it did since is already
/// allowed for; what is left is to react by `tau` after the sighting. With
/// the whole `tau` at every control step the two add up: a follower kept
/// `tau + dt` of headway (2 s at a 1 s step, where SUMO's driver keeps its
/// `tau`, 1 s) and crossed a stop line 3.8-4.0 s after the driver ahead
/// (Bologna, light 235; plain SUMO 2.0 s). Counted down, a follower at a
/// steady speed behind a steady leader keeps `tau` of headway, and the law
/// still guarantees that braking at `b_f` from the end of the step stops it
/// before the held stop point (the reaction left is at least `h`, the time
/// its acceleration is held). The emergency branch (no plan) has no
/// reaction time and is not touched.
pub(crate) fn reaction_left(tau_s: f64, t_s: f64, h_s: f64) -> f64 {
    (tau_s - t_s).max(h_s)
}

/// How far a vehicle got from `from` to `to` (m): the rear axle's
/// displacement. The bicycle model never drives against its direction of
/// travel, so this is its advance along it (a chord of the arc it drove,
/// shorter than the arc by under 0.1 mm at 30 m/s, h = 0.05 s, 1/100 m curvature).
pub(crate) fn advance(from: &VehicleState, to: &VehicleState) -> f64 {
    (to.x_m - from.x_m).hypot(to.y_m - from.y_m)
}

/// Row `i` of the fleet's next states.
pub(crate) fn state_at(next: &NextStates, i: usize) -> VehicleState {
    VehicleState {
        x_m: next.x_m[i],
        y_m: next.y_m[i],
        theta_rad: next.theta_rad[i],
        v_mps: next.v_mps[i],
        delta_rad: next.delta_rad[i],
    }
}

/// The statistics' record of one control step of `h_s` of row `i` of
/// `out`, from `before` to `state`.
pub(crate) fn control_record(
    out: &FleetOutputs,
    i: usize,
    before: &VehicleState,
    state: &VehicleState,
    wheelbase_m: f64,
    speed_limit_mps: f64,
    h_s: f64,
) -> StepRecord {
    let v = state.v_mps;
    StepRecord {
        lateral_error_m: out.lateral_error_m[i],
        lateral_error_rear_m: out.lateral_error_rear_m[i],
        lateral_error_front_m: out.lateral_error_front_m[i],
        heading_error_rad: out.heading_error_rad[i],
        v_mps: v,
        accel_mps2: (v - before.v_mps) / h_s,
        lateral_accel_mps2: v * v * state.delta_rad.tan() / wheelbase_m,
        curvature_per_m: out.curvature_per_m[i],
        speed_limit_mps,
        dt_s: h_s,
    }
}

/// The gaps of one control step, one per planned slot (NaN/inf: none).
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeldGaps<'a> {
    pub(crate) leader: &'a [f64],
    /// The leaders' speeds as the stopping law takes them.
    pub(crate) leader_speed: &'a [f64],
    /// The stopping law's reaction time for each leader (NaN: the
    /// vehicle's own), or None for every vehicle's own.
    pub(crate) leader_reaction: Option<&'a [f64]>,
    pub(crate) stop: &'a [f64],
    pub(crate) soft: &'a [f64],
}

impl<'a> HeldGaps<'a> {
    /// The plan's own gaps: those at the start of the step.
    pub(crate) fn of_plan(plan: &'a Plan) -> Self {
        HeldGaps {
            leader: &plan.leader_gap,
            leader_speed: &plan.leader_speed,
            leader_reaction: None,
            stop: &plan.stop_gap,
            soft: &plan.soft_gap,
        }
    }
}

/// The last control step of a simulator step.
#[derive(Debug, Clone)]
pub(crate) struct LastStep {
    /// The fleet's outputs (errors of `before`, next states).
    pub(crate) out: FleetOutputs,
    /// The states it started from, one per planned slot.
    pub(crate) before: Vec<VehicleState>,
    /// Each vehicle's advance from the start of the simulator step to `before` (m).
    pub(crate) advance: Vec<f64>,
    /// Its length (s).
    pub(crate) h: f64,
    /// Control steps that start with the front past the route's end are
    /// left out of the statistics (see [`past_route_end`]); false with one
    /// control step per simulator step, which takes every step as before.
    pub(crate) skip_past_end: bool,
}

/// A planned vehicle's route, where its front is on it at the plan (arc
/// length) and the simulator's station there.
pub(crate) struct Front {
    pub(crate) route: Arc<Route>,
    pub(crate) s_m: f64,
    pub(crate) station_m: f64,
}

/// The front is past the end of its route at the start of a control step
/// whose rear axle is at arc length `s_rear_m`: the simulator takes the
/// vehicle out at its next step, and until then its controller tracks past
/// the end of its path (errors of metres at a 1 s step), nothing to measure.
pub(crate) fn past_route_end(d: &crate::Driven, s_rear_m: f64) -> bool {
    s_rear_m + d.body.reach_m > d.route.length_m
}

impl RouteFleet {
    /// Each planned vehicle's [`Front`], in the plan's order.
    pub(crate) fn fronts(&self, plan: &Plan) -> Vec<Front> {
        plan.slots
            .iter()
            .map(|&slot| {
                let d = self.driven[slot as usize]
                    .as_ref()
                    .expect("planned slots are driven");
                Front {
                    route: d.route.clone(),
                    s_m: d.s_front_m,
                    station_m: d.route.station_at(d.s_front_m),
                }
            })
            .collect()
    }

    /// Stage 2 at the control rate, `n` > 1 control steps of `dt_s / n`:
    /// every control step but the last is stepped and taken into the
    /// statistics; the last is stepped and returned. Leaders drive on at their
    /// observed speed, stop lines stay, so each gap at time `t` into the step
    /// is the plan's gap, plus the obstacle's speed times `t`, less the
    /// vehicle's advance (a leader's and a soft leader's gap: less the gain
    /// of the simulator's station, [`Route::station_at`], and a leader driven
    /// here gains its own). The speed limits and stop-line decisions are the
    /// plan's. A vehicle whose state turns unusable stays so (NaN) to the
    /// last control step, which hands it back.
    pub(crate) fn control_steps(
        &mut self,
        plan: &Plan,
        dt_s: f64,
        n: usize,
    ) -> Result<LastStep, TrafficError> {
        let h = dt_s / n as f64;
        let m = plan.slots.len();
        let mut states = self.planned_states(plan);
        let mut moved = vec![0.0; m];
        let mut leader = plan.leader_gap.clone();
        let mut leader_speed = plan.leader_speed.clone();
        let lock_step = dt_s >= HOLD_BRAKING_MIN_STEP_S;
        let mut stop = plan.stop_gap.clone();
        let mut soft = plan.soft_gap.clone();
        // The reaction times of vehicles behind a leader the simulator
        // drives, counted down over a long step (NaN: the vehicle's own).
        let mut reaction = vec![f64::NAN; m];
        let mut tau = vec![f64::NAN; m];
        if lock_step {
            for ((t, &external), &slot) in
                tau.iter_mut().zip(&plan.leader_external).zip(&plan.slots)
            {
                if external {
                    *t = self.fleet.vehicle_config(slot)?.reaction_time;
                }
            }
        }
        let fronts = self.fronts(plan);
        // How far the simulator will have the front of entry `i` moved.
        let gain = |i: usize, moved: &[f64]| {
            let f = &fronts[i];
            if f.route.stations.is_some() {
                f.route.station_at(f.s_m + moved[i]) - f.station_m
            } else {
                moved[i]
            }
        };
        let mut gained = vec![0.0; m];
        for k in 0..n {
            if k > 0 {
                let t = k as f64 * h;
                for (i, g) in gained.iter_mut().enumerate() {
                    *g = gain(i, &moved);
                }
                for i in 0..m {
                    let j = plan.leader_entry[i];
                    let moved_i = gained[i];
                    if lock_step && j != NO_ENTRY {
                        // A leader driven here: where its own control steps
                        // took it, at the speed they left it.
                        leader[i] = plan.leader_gap[i] + gained[j] - moved_i;
                        leader_speed[i] = held_speed(states[j].v_mps);
                    } else {
                        let v_adv = leader_advance_speed(
                            plan.leader_speed[i],
                            plan.leader_external[i],
                            dt_s,
                        );
                        leader[i] = plan.leader_gap[i] + v_adv * t - moved_i;
                        if !tau[i].is_nan() {
                            reaction[i] = reaction_left(tau[i], t, h);
                        }
                    }
                    soft[i] = plan.soft_gap[i] + held_speed(plan.soft_speed[i]) * t - moved_i;
                    stop[i] = plan.stop_gap[i] - moved[i];
                }
            }
            let gaps = HeldGaps {
                leader: &leader,
                leader_speed: &leader_speed,
                leader_reaction: Some(&reaction),
                stop: &stop,
                soft: &soft,
            };
            let out = self.step_fleet(plan, &states, gaps, &fronts, &moved, h)?;
            if k + 1 == n {
                return Ok(LastStep {
                    out,
                    before: states,
                    advance: moved,
                    h,
                    skip_past_end: true,
                });
            }
            let next = out.next.as_ref().expect("dt was given");
            for (i, before) in states.iter_mut().enumerate() {
                let state = state_at(next, i);
                self.record_control_step(plan, i, &out, before, &state, h)?;
                moved[i] += advance(before, &state);
                *before = state;
            }
        }
        unreachable!("n > 1 control steps return at the last")
    }

    /// A control step (not the last of its simulator step) of planned entry
    /// `i` into its statistics, when it is usable.
    fn record_control_step(
        &mut self,
        plan: &Plan,
        i: usize,
        out: &FleetOutputs,
        before: &VehicleState,
        state: &VehicleState,
        h: f64,
    ) -> Result<(), TrafficError> {
        let finite = stepped_finite(state, out.s_rear_m[i]);
        if !(out.ok[i] && finite) {
            return Ok(());
        }
        let slot = plan.slots[i];
        let wheelbase = self.fleet.vehicle_params(slot)?.wheelbase_m;
        let step = control_record(out, i, before, state, wheelbase, plan.limit[i], h);
        let st = self.settings;
        let d = self.driven[slot as usize]
            .as_mut()
            .expect("planned slots are driven");
        if past_route_end(d, out.s_rear_m[i]) {
            return Ok(());
        }
        if let Some(sample) = d.stats.add_step(&step, &st) {
            self.samples.push(sample);
        }
        Ok(())
    }
}

/// Whether a stepped vehicle's state and its foot point on the track are
/// all finite (else the step is not used).
pub(crate) fn stepped_finite(state: &VehicleState, s_rear_m: f64) -> bool {
    [
        state.x_m,
        state.y_m,
        state.theta_rad,
        state.v_mps,
        state.delta_rad,
        s_rear_m,
    ]
    .iter()
    .all(|x| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::{braking_mean_speed, reaction_left, substeps};
    use crate::testkit::*;
    use crate::*;
    use blendtrack::ControllerConfig;
    use blendtrack::{Fleet, FleetInputs};

    const H: f64 = 0.05;

    fn settings(control_dt_s: f64) -> TrafficSettings {
        TrafficSettings {
            control_dt_s,
            ..Default::default()
        }
    }

    /// One plan + step of `dt` for one vehicle behind a leader (gap, speed;
    /// NaN: none).
    fn step_behind(f: &mut RouteFleet, slot: i64, leader: (f64, f64), dt: f64) -> RouteOutputs {
        step_behind_slot(f, slot, (leader.0, leader.1, -1), dt)
    }

    /// `step_behind` with the leader's slot given (>= 0: driven here).
    fn step_behind_slot(
        f: &mut RouteFleet,
        slot: i64,
        leader: (f64, f64, i64),
        dt: f64,
    ) -> RouteOutputs {
        f.plan(&Observations {
            slots: &[slot],
            leader_gap_m: &[leader.0],
            leader_slot: &[leader.2],
            leader_speed_mps: &[leader.1],
            leader_room_m: None,
            lane: &[-1],
            lane_pos_m: &[f64::NAN],
            soft: None,
        })
        .unwrap();
        f.step(&[], dt).unwrap()
    }

    /// The core fleet on `road(None, true)`'s path with the test config,
    /// stepped `n` times over `h` from `s0` behind a leader at `gap(k, x_k)`
    /// (NaN: none) driving at `v_leader`: the final state.
    fn reference(
        s0: VehicleState,
        n: usize,
        gap: impl Fn(usize, f64) -> f64,
        v_leader: f64,
    ) -> VehicleState {
        *reference_states(s0, n, |k, x| (gap(k, x), v_leader))
            .last()
            .unwrap()
    }

    /// [`reference`] behind a leader `gap_m` ahead at the start (the
    /// standstill margin off) driving on at `v_leader`.
    fn behind_driving_on(s0: VehicleState, n: usize, gap_m: f64, v_leader: f64) -> VehicleState {
        let margin = TrafficSettings::default().standstill_margin_m;
        reference(
            s0,
            n,
            |k, x| gap_m - margin + v_leader * k as f64 * H - (x - s0.x_m),
            v_leader,
        )
    }

    /// As [`reference`], the leader's (gap, speed) at control step `k` from
    /// `leader(k, x_k)`: every state from `s0` on (`n + 1` of them).
    fn reference_states(
        s0: VehicleState,
        n: usize,
        leader: impl Fn(usize, f64) -> (f64, f64),
    ) -> Vec<VehicleState> {
        reference_states_reacting(s0, n, leader, |_| f64::NAN)
    }

    /// The stopping law's reaction time for a leader the simulator drives
    /// at control step `k` of a 1 s step of control steps of `H`, as
    /// `control_steps` sets it (the test config's, counted from the
    /// sighting; NaN at the first: the config's own).
    fn counted_down(k: usize) -> f64 {
        if k == 0 {
            f64::NAN
        } else {
            reaction_left(ControllerConfig::default().reaction_time, k as f64 * H, H)
        }
    }

    /// [`reference_states`] with the stopping law's reaction time for the
    /// leader at control step `k` from `reaction(k)` (NaN: the config's).
    fn reference_states_reacting(
        s0: VehicleState,
        n: usize,
        leader: impl Fn(usize, f64) -> (f64, f64),
        reaction: impl Fn(usize) -> f64,
    ) -> Vec<VehicleState> {
        let mut fleet = Fleet::new();
        let cfg = ControllerConfig {
            preferred_speed: 15.0,
            ..Default::default()
        };
        let t = fleet.add_track(road(None, true).0, cfg).unwrap() as i64;
        let slot = [fleet.add_vehicle(t, None, None).unwrap() as i64];
        let mut s = s0;
        let mut all = vec![s0];
        for k in 0..n {
            let (gap, v_leader) = leader(k, s.x_m);
            let out = fleet
                .step(&FleetInputs {
                    leader_gap_m: Some(&[gap]),
                    leader_speed_mps: Some(&[v_leader]),
                    leader_reaction_s: Some(&[reaction(k)]),
                    stop_gap_m: Some(&[f64::NAN]),
                    soft_gap_m: Some(&[f64::NAN]),
                    soft_speed_mps: Some(&[f64::NAN]),
                    speed_limit_mps: Some(&[20.0]),
                    dt_s: Some(H),
                    ..FleetInputs::new(
                        &slot,
                        &[s.x_m],
                        &[s.y_m],
                        &[s.theta_rad],
                        &[s.v_mps],
                        &[s.delta_rad],
                    )
                })
                .unwrap();
            let next = out.next.unwrap();
            s = VehicleState {
                x_m: next.x_m[0],
                y_m: next.y_m[0],
                theta_rad: next.theta_rad[0],
                v_mps: next.v_mps[0],
                delta_rad: next.delta_rad[0],
            };
            all.push(s);
        }
        all
    }

    #[test]
    fn a_step_is_ceil_dt_over_control_dt_control_steps() {
        assert_eq!(substeps(0.1, 0.05), 2);
        assert_eq!(substeps(1.0, 0.05), 20);
        assert_eq!(substeps(0.1, 0.1), 1);
        assert_eq!(substeps(0.3, 0.1), 3, "0.3 / 0.1 = 2.9999999999999996");
        assert_eq!(substeps(0.25, 0.1), 3);
        assert_eq!(substeps(0.01, 0.05), 1);
        assert_eq!(substeps(0.1, 1.0), 1);
        assert!(matches!(
            RouteFleet::new(settings(0.0)),
            Err(TrafficError::Parameter {
                name: "control_dt_s",
                ..
            })
        ));
        assert!(RouteFleet::new(settings(f64::NAN)).is_err());
    }

    #[test]
    fn n_control_steps_are_n_steps_of_the_fleet() {
        // Off the centreline and below its preferred speed: it steers and
        // accelerates in every control step.
        let mut s0 = at(50.0, 10.0);
        s0.y_m = 0.4;
        let (mut f, t) = fleet_with(road(None, true), settings(H));
        let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        let out = step_behind(&mut f, a, (f64::NAN, f64::NAN), 8.0 * H);
        let want = reference(s0, 8, |_, _| f64::NAN, f64::NAN);
        assert_eq!(f.state(a).unwrap(), want);
        assert_eq!(
            (out.x_m[0], out.y_m[0], out.v_mps[0]),
            (want.x_m, want.y_m, want.v_mps)
        );
        let stats = f.stats(a).unwrap().tracking;
        assert_eq!(stats.steps, 8, "each control step is counted");
        // Mean acceleration over the step in the outputs.
        assert!((out.accel_mps2[0] - (want.v_mps - 10.0) / (8.0 * H)).abs() < 1e-9);
        // The same step at control_dt = dt is one step of the fleet over dt:
        // a different (coarser) state.
        let (mut g, t) = fleet_with(road(None, true), settings(8.0 * H));
        let b = g.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        step_behind(&mut g, b, (f64::NAN, f64::NAN), 8.0 * H);
        assert_ne!(g.state(b).unwrap(), want);
        assert_eq!(g.stats(b).unwrap().tracking.steps, 1);
    }

    #[test]
    fn a_braking_leader_is_held_at_its_mean_speed_never_ahead_of_where_it_gets() {
        // Closed forms: 10 m/s braking at 2 m/s^2 over 1 s averages 9 m/s;
        // at 20 m/s^2 it stops after 0.5 s and 2.5 m, 2.5 m/s over the step.
        assert_eq!(braking_mean_speed(10.0, -2.0, 1.0), 9.0);
        assert_eq!(braking_mean_speed(10.0, -20.0, 1.0), 2.5);
        // Not braking, standing, no step: its speed.
        assert_eq!(braking_mean_speed(10.0, 1.5, 1.0), 10.0);
        assert_eq!(braking_mean_speed(0.0, -3.0, 1.0), 0.0);
        assert_eq!(braking_mean_speed(10.0, f64::NAN, 1.0), 10.0);
        // Short steps: held at its speed.
        assert_eq!(braking_mean_speed(10.0, -4.5, 0.1), 10.0);
        // Held at it over the step, the leader is never ahead of where it
        // gets going on braking so (the follower's side of safety).
        for &(v, a, dt) in &[
            (30.0, -4.5, 1.0),
            (5.0, -9.0, 1.0),
            (12.0, -1.0, 0.5),
            (2.0, -4.0, 1.0),
        ] {
            let held = braking_mean_speed(v, a, dt);
            for k in 0..=20 {
                let t = dt * k as f64 / 20.0;
                let stop = v / -a;
                let real = if t < stop {
                    v * t + 0.5 * a * t * t
                } else {
                    v * v / (-2.0 * a)
                };
                assert!(
                    held * t <= real + 1e-9,
                    "v {v} a {a} t {t}: {} > {real}",
                    held * t
                );
            }
        }
    }

    #[test]
    fn a_held_leader_drives_on_at_its_observed_speed() {
        // Far behind a slower leader, at its preferred speed: no braking, so
        // over the step the gap shrinks by exactly (v - v_leader) dt.
        let margin = TrafficSettings::default().standstill_margin_m;
        let (mut f, t) = fleet_with(road(None, true), settings(H));
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 15.0), None)
            .unwrap() as i64;
        let out = step_behind(&mut f, a, (300.0, 10.0), 1.0);
        assert_eq!(f.state(a).unwrap().v_mps, 15.0);
        let want = 300.0 - margin - (15.0 - 10.0) * 1.0;
        assert!(
            (out.leader_gap_m[0] - want).abs() < 1e-9,
            "{}",
            out.leader_gap_m[0]
        );
        // Close behind a leader driven here: it brakes, and each control step
        // sees the gap the leader's held speed and the vehicle's own advance
        // leave.
        let s0 = at(50.0, 15.0);
        let g0 = 25.0;
        let (mut f, t) = fleet_with(road(None, true), settings(H));
        let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        let b = f
            .add_vehicle(t, None, None, body(), at(80.0, 10.0), None)
            .unwrap() as i64;
        let out = step_behind_slot(&mut f, a, (g0, f64::NAN, b), 1.0);
        let held = |k: usize, x: f64| g0 - margin + 10.0 * k as f64 * H - (x - s0.x_m);
        let want = reference(s0, 20, held, 10.0);
        let got = f.state(a).unwrap();
        for (g, w) in [
            (got.x_m, want.x_m),
            (got.v_mps, want.v_mps),
            (got.y_m, want.y_m),
        ] {
            assert!((g - w).abs() < 1e-9, "{g} vs {w}");
        }
        assert!(got.v_mps < 14.0, "it braked: {}", got.v_mps);
        let moved = got.x_m - s0.x_m;
        assert!((out.leader_gap_m[0] - (g0 - margin + 10.0 - moved)).abs() < 1e-9);
        // A leader held in place (its gap at the start all step long) is another thing.
        let stale = reference(s0, 20, |_, _| g0 - margin, 10.0);
        assert!((stale.v_mps - got.v_mps).abs() > 1e-3);
        // A leader the simulator drives, at a step shorter than
        // HOLD_BRAKING_MIN_STEP_S, drives on as well (8 control steps of 0.4 s).
        let (mut f, t) = fleet_with(road(None, true), settings(H));
        let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        step_behind(&mut f, a, (g0, 10.0), 8.0 * H);
        let want = reference(s0, 8, held, 10.0);
        assert!((f.state(a).unwrap().v_mps - want.v_mps).abs() < 1e-9);
    }

    #[test]
    fn over_a_long_step_a_leader_the_simulator_drives_keeps_its_stop_point() {
        // At a 1 s step the simulator's driver may brake at the start of the
        // step: the follower's control steps see the leader's gap where it
        // was (the leader's stop point gap + v^2 / (2 b_l) held), not moved
        // on at its speed.
        let margin = TrafficSettings::default().standstill_margin_m;
        let s0 = at(50.0, 15.0);
        let g0 = 25.0;
        let (mut f, t) = fleet_with(road(None, true), settings(H));
        let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        let out = step_behind(&mut f, a, (g0, 10.0), 1.0);
        let still = |_: usize, x: f64| (g0 - margin - (x - s0.x_m), 10.0);
        let want = *reference_states_reacting(s0, 20, still, counted_down)
            .last()
            .unwrap();
        let got = f.state(a).unwrap();
        for (g, w) in [(got.x_m, want.x_m), (got.v_mps, want.v_mps)] {
            assert!((g - w).abs() < 1e-9, "{g} vs {w}");
        }
        // Braking harder than behind a leader driving on.
        let on = behind_driving_on(s0, 20, g0, 10.0);
        assert!(got.v_mps < on.v_mps - 0.1, "{} vs {}", got.v_mps, on.v_mps);
        // Closed form of the guarantee: were the leader to brake at b_l from
        // the step's start, it stops at g0 - margin + v^2 / (2 |b_l|) ahead of
        // where the follower was; the follower can still stop before it from
        // its state at the end of the step, braking at b_l.
        let b_l = -ControllerConfig::default().max_obs_deceleration;
        let leader_stop = g0 - margin + 10.0 * 10.0 / (2.0 * b_l);
        let moved = got.x_m - s0.x_m;
        let own_stop = got.v_mps * got.v_mps / (2.0 * b_l);
        assert!(
            moved + own_stop <= leader_stop,
            "{moved} + {own_stop} > {leader_stop}"
        );
        // The reported gap is still the leader's observed motion's.
        assert!((out.leader_gap_m[0] - (g0 - margin + 10.0 - moved)).abs() < 1e-9);
    }

    /// The jump of the simulator's station in [`jumping_at_100`] (m).
    const JUMP_M: f64 = 7.0;

    /// A track that cuts a corner between 100 and 101 m: the simulator's
    /// station jumps [`JUMP_M`] ahead there (Bologna's 58[0] and junction 47
    /// after it: 3.5 and 5.4 m, see `Stations`).
    fn jumping_at_100() -> Stations {
        let s: Vec<f64> = (0..=600).map(f64::from).collect();
        let c: Vec<f64> = s
            .iter()
            .map(|&x| if x <= 100.0 { x } else { x + JUMP_M })
            .collect();
        Stations::new(s, c).unwrap()
    }

    /// Drives a vehicle from 40 m at 10 m/s up to a standing leader, 1 s
    /// steps, in a simulator whose stations are [`jumping_at_100`]'s: the
    /// leader's front is at arc length 103 m, past the jump, and the
    /// simulator puts its back a length (4.5 m) behind the front's station,
    /// so where the track has the back before the jump (SUMO measures a
    /// vehicle it placed by (x, y) so). The gap is observed each step from
    /// the station of the follower's front. The follower's route knows the
    /// stations when `knows` is true. Returns the simulator's gap (minGap
    /// left out) once the follower stands.
    fn standing_gap_in_the_simulator(knows: bool) -> f64 {
        let world = jumping_at_100();
        let (path, route) = road(None, true);
        let route = if knows {
            route.with_stations(jumping_at_100())
        } else {
            route
        };
        let (mut f, t) = fleet_with((path, route), settings(H));
        let a = f
            .add_vehicle(t, None, None, body(), at(40.0, 10.0), None)
            .unwrap() as i64;
        let leader_back = world.at(103.0) - 4.5;
        let sim_gap =
            |f: &RouteFleet| leader_back - world.at(f.s_front(a).unwrap()) - body().min_gap_m;
        for _ in 0..40 {
            let g = sim_gap(&f);
            step_behind(&mut f, a, (g, 0.0), 1.0);
        }
        assert!(f.state(a).unwrap().v_mps.abs() < 1e-3, "stands");
        sim_gap(&f)
    }

    #[test]
    fn a_follower_stops_short_of_its_leader_in_the_simulator_s_stations_too() {
        // Measured along the track alone, the follower runs over the jump
        // and the simulator has it over its leader's back (within minGap:
        // a collision by SUMO's rule; Bologna's 58[1], see `Stations`).
        let blind = standing_gap_in_the_simulator(false);
        assert!(blind < 0.0, "without stations, {blind} m in the simulator");
        // Knowing the stations it stops before the jump, as far back in
        // the simulator as on a road without one.
        let seen = standing_gap_in_the_simulator(true);
        let plain = {
            let (path, route) = road(None, true);
            let (mut f, t) = fleet_with((path, route), settings(H));
            let a = f
                .add_vehicle(t, None, None, body(), at(40.0, 10.0), None)
                .unwrap() as i64;
            for _ in 0..40 {
                let g = 100.0 - f.s_front(a).unwrap() - body().min_gap_m;
                step_behind(&mut f, a, (g, 0.0), 1.0);
            }
            100.0 - f.s_front(a).unwrap() - body().min_gap_m
        };
        assert!(
            seen >= 0.0 && (seen - plain).abs() < 0.3,
            "{seen} vs {plain}"
        );
    }

    #[test]
    fn over_a_long_step_a_leader_driven_here_moves_with_its_own_control_steps() {
        // b, 15 m/s, 25 m behind a standing vehicle of the simulator's, brakes
        // hard within the 1 s step; a follows b at 33 m, also at 15 m/s. Each
        // of a's control steps sees b where b's control steps took it, at
        // b's speed then (closed form: the core fleet stepped against b's
        // own trajectory), not b held at 15 m/s.
        let margin = TrafficSettings::default().standstill_margin_m;
        let (sa, sb) = (at(60.0, 15.0), at(100.0, 15.0));
        let (ga, gb) = (33.0, 25.0);
        // a behind b, b behind the standing vehicle, one step of dt.
        let pair = |dt: f64| {
            let (mut f, t) = fleet_with(road(None, true), settings(H));
            let a = f.add_vehicle(t, None, None, body(), sa, None).unwrap() as i64;
            let b = f.add_vehicle(t, None, None, body(), sb, None).unwrap() as i64;
            f.plan(&Observations {
                slots: &[a, b],
                leader_gap_m: &[ga, gb],
                leader_slot: &[b, -1],
                leader_speed_mps: &[f64::NAN, 0.0],
                leader_room_m: None,
                lane: &[-1, -1],
                lane_pos_m: &[f64::NAN; 2],
                soft: None,
            })
            .unwrap();
            f.step(&[], dt).unwrap();
            (f, a, b)
        };
        let (f, a, b) = pair(1.0);
        // b alone: its standing leader's gap shrinks by b's advance only.
        let b_states = reference_states_reacting(
            sb,
            20,
            |_, x| (gb - margin - (x - sb.x_m), 0.0),
            counted_down,
        );
        let got_b = f.state(b).unwrap();
        assert!((got_b.x_m - b_states[20].x_m).abs() < 1e-9);
        assert!(got_b.v_mps < 11.0, "b braked hard: {}", got_b.v_mps);
        let want = reference_states(sa, 20, |k, x| {
            let lb = &b_states[k];
            (ga - margin + (lb.x_m - sb.x_m) - (x - sa.x_m), lb.v_mps)
        });
        let got_a = f.state(a).unwrap();
        for (g, w) in [(got_a.x_m, want[20].x_m), (got_a.v_mps, want[20].v_mps)] {
            assert!((g - w).abs() < 1e-9, "{g} vs {w}");
        }
        // Held at its speed at the step's start, b would have left a unaware.
        let held = behind_driving_on(sa, 20, ga, 15.0);
        assert_eq!(held.v_mps, 15.0, "held, b seemed no reason to brake");
        assert!(got_a.v_mps < 14.8, "a braked with b: {}", got_a.v_mps);
        // At a step below HOLD_BRAKING_MIN_STEP_S the leader is held as before.
        let (f, a, _) = pair(8.0 * H);
        let held = behind_driving_on(sa, 8, ga, 15.0);
        assert!((f.state(a).unwrap().x_m - held.x_m).abs() < 1e-9);
    }

    #[test]
    fn behind_a_steady_leader_the_simulator_drives_a_long_step_keeps_the_law_s_own_headway() {
        // Closed form: at equal speeds v the law asks for no acceleration at
        // s* = s0 + v tau + v^2 / (2 |b_f|) - v^2 / (2 |b_l|) (the
        // stopping-law identity with a = 0). With the reaction time counted
        // from the sighting, a follower at 1 s steps settles there, as at
        // 0.1 s steps; with the whole tau at every control step it kept
        // v dt more (26.25 m instead of 16.25 m at 10 m/s).
        let cfg = ControllerConfig::default();
        let margin = TrafficSettings::default().standstill_margin_m;
        let v = 10.0;
        let s_star =
            cfg.preferred_stop_dist + v * cfg.reaction_time + v * v / (-2.0 * cfg.max_deceleration)
                - v * v / (-2.0 * cfg.max_obs_deceleration);
        for dt in [1.0_f64, 0.1] {
            let s0 = at(50.0, v);
            let (mut f, t) = fleet_with(road(None, true), settings(H));
            let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
            // The leader, driven elsewhere at v, 30 m ahead at first.
            let (mut lead, mut gap) = (0.0, 30.0);
            // 40 s: 450 m of the 600 m road.
            let steps = (40.0_f64 / dt).round() as usize;
            for _ in 0..steps {
                step_behind(&mut f, a, (gap, v), dt);
                lead += v * dt;
                gap = 30.0 + lead - (f.state(a).unwrap().x_m - s0.x_m);
                assert!(gap > margin, "dt {dt}: closed in to {gap}");
            }
            let got = f.state(a).unwrap();
            assert!((got.v_mps - v).abs() < 0.05, "dt {dt}: {}", got.v_mps);
            assert!(
                (gap - margin - s_star).abs() < 0.3,
                "dt {dt}: gap {} vs s* {s_star}",
                gap - margin
            );
        }
    }

    #[test]
    fn the_reaction_time_left_counts_down_from_the_sighting_to_one_control_step() {
        assert_eq!(reaction_left(1.0, 0.0, 0.05), 1.0);
        assert!((reaction_left(1.0, 0.4, 0.05) - 0.6).abs() < 1e-12);
        assert_eq!(reaction_left(1.0, 0.99, 0.05), 0.05);
        assert_eq!(reaction_left(0.5, 0.75, 0.05), 0.05);
    }

    #[test]
    fn at_one_second_steps_a_red_light_still_stops_the_vehicle_before_its_line() {
        let (mut f, t) = fleet_with(road(Some((0, 0)), false), settings(H));
        let slot = f
            .add_vehicle(t, None, None, body(), at(100.0, 12.0), None)
            .unwrap() as i64;
        f.set_signal(0, &[Signal::Stop]).unwrap();
        for _ in 0..40 {
            let out = step_behind(&mut f, slot, (f64::NAN, f64::NAN), 1.0);
            assert!(!out.red_light[0]);
        }
        let sf = f.s_front(slot).unwrap();
        assert!((195.0..200.0).contains(&sf), "front {sf} m");
        assert!(f.state(slot).unwrap().v_mps.abs() < 0.05);
        assert_eq!(f.stats(slot).unwrap().tracking.steps, 40 * 20);
    }

    #[test]
    fn at_one_second_steps_an_offset_vehicle_settles_as_at_a_tenth() {
        // 0.5 m off the centreline: after 10 s the lateral error and the
        // speed are those of the 0.1 s run, at a control rate of 0.05 s.
        let run = |dt: f64, control_dt: f64| {
            let (mut f, t) = fleet_with(road(None, true), settings(control_dt));
            let mut s0 = at(20.0, 12.0);
            s0.y_m = 0.5;
            let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
            for _ in 0..(10.0 / dt).round() as usize {
                step_behind(&mut f, a, (f64::NAN, f64::NAN), dt);
            }
            let s = f.stats(a).unwrap().tracking;
            (s.lateral_error_mean_abs_m(), f.state(a).unwrap())
        };
        let (e_fine, fine) = run(0.1, H);
        let (e_coarse, coarse) = run(1.0, H);
        assert!((e_fine - e_coarse).abs() < 1e-9, "{e_fine} vs {e_coarse}");
        assert_eq!(fine, coarse, "the same control steps");
        let (e_old, _) = run(1.0, 1.0);
        assert!(
            e_old > e_fine + 0.01,
            "one control step per second: {e_old}"
        );
    }

    #[test]
    fn control_steps_past_the_route_s_end_are_not_measured() {
        // Front at 563.5 m at 15 m/s, route end 600 m: the control steps
        // starting with the front at 563.5 + 0.75 k <= 600 m (k = 0..=48) are
        // measured, the 31 after it (the simulator would have taken it out) not.
        let (mut f, t) = fleet_with(road(None, true), settings(H));
        let a = f
            .add_vehicle(t, None, None, body(), at(560.0, 15.0), None)
            .unwrap() as i64;
        for _ in 0..4 {
            step_behind(&mut f, a, (f64::NAN, f64::NAN), 1.0);
        }
        assert_eq!(f.stats(a).unwrap().tracking.steps, 49);
        assert_eq!(f.driven(a).unwrap().steps, 4);
        // One control step per step takes every step, as before.
        let (mut f, t) = fleet_with(road(None, true), settings(1.0));
        let a = f
            .add_vehicle(t, None, None, body(), at(560.0, 15.0), None)
            .unwrap() as i64;
        for _ in 0..4 {
            step_behind(&mut f, a, (f64::NAN, f64::NAN), 1.0);
        }
        assert_eq!(f.stats(a).unwrap().tracking.steps, 4);
    }
}
