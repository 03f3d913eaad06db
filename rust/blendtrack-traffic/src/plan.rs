//! The first half of a step ([`RouteFleet::plan`]): the simulator's
//! [`Observations`] (leaders, [`SoftLeaders`], read-back lane positions)
//! become each vehicle's leader, stop line and yield questions.

use crate::error::check_len;
use crate::route::Route;
use crate::signal::{signal_at, Signal};
use crate::stops::{halt_gap, nearer};
use crate::{Driven, RouteFleet, TrafficError, TrafficSettings};
use blendtrack::longitudinal::stopping_accel;
use blendtrack::{ControllerConfig, FleetError};

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
    /// The simulator's own gap to the leader where `leader_gap_m` is shorter
    /// (the bridge shortens gaps to leaders it drives for what the stopping
    /// law's picture of their braking misses); None or NaN: `leader_gap_m`.
    /// Only a move by lane position is bounded by it (the simulator puts the
    /// vehicle there before anyone moves): the stopping law takes the
    /// shortened gap.
    pub leader_room_m: Option<&'a [f64]>,
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
/// bounded at `max_deceleration` (a soft [`blendtrack::Obstacle`]): the vehicle
/// falls back at most at its planning deceleration and never brakes as in an
/// emergency for a vehicle that is not on its lane.
#[derive(Debug, Clone, Copy)]
pub struct SoftLeaders<'a> {
    pub gap_m: &'a [f64],
    pub slot: &'a [i64],
    pub speed_mps: &'a [f64],
}

#[derive(Debug, Clone, Default)]
pub(crate) struct Plan {
    pub(crate) slots: Vec<i64>,
    pub(crate) leader_gap: Vec<f64>,
    /// How far the front may be put before the leader as it stands (the
    /// simulator's gap less the standstill margin; NaN: no leader).
    pub(crate) leader_room: Vec<f64>,
    pub(crate) leader_speed: Vec<f64>,
    /// The leader is driven by the simulator, not here: over a long step its
    /// worst stop point is held (see [`crate::substep::leader_advance_speed`]).
    pub(crate) leader_external: Vec<bool>,
    /// The leader's entry in this plan when it is driven here and planned
    /// too ([`NO_ENTRY`] otherwise): over a long step the follower sees it
    /// move with its own control steps.
    pub(crate) leader_entry: Vec<usize>,
    pub(crate) stop_gap: Vec<f64>,
    pub(crate) soft_gap: Vec<f64>,
    pub(crate) soft_speed: Vec<f64>,
    pub(crate) limit: Vec<f64>,
    /// Gap to the stop line of a link that waits for the simulator's word on foes.
    pub(crate) yield_gap: Vec<f64>,
    pub(crate) queries: Vec<usize>,
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
    /// The vehicle in `slot` when it is driven here (a leader's slot may be
    /// anything: < 0 for the simulator's).
    fn driven_at(&self, slot: i64) -> Option<&Driven> {
        usize::try_from(slot)
            .ok()
            .and_then(|l| self.driven.get(l))
            .and_then(Option::as_ref)
    }

    /// A leader's speed: its state's where it is driven here (`slot` >= 0),
    /// else `given`.
    fn speed_of(&self, slot: i64, given: f64) -> f64 {
        self.driven_at(slot).map_or(given, |d| {
            if d.lead_speed.is_finite() {
                d.lead_speed
            } else {
                d.state.v_mps
            }
        })
    }

    /// First half of a step: stop lines and leaders. Returns the indices (into
    /// `obs.slots`) of the vehicles approaching a link without priority:
    /// [`RouteFleet::step`] needs, for each, whether it must give way.
    pub fn plan(&mut self, obs: &Observations<'_>) -> Result<Vec<usize>, TrafficError> {
        self.check_observations(obs)?;
        let n = obs.slots.len();
        let mut plan = Plan {
            slots: obs.slots.to_vec(),
            leader_gap: vec![f64::NAN; n],
            leader_room: vec![f64::NAN; n],
            leader_speed: vec![f64::NAN; n],
            leader_external: vec![false; n],
            leader_entry: vec![NO_ENTRY; n],
            stop_gap: vec![f64::NAN; n],
            soft_gap: vec![f64::NAN; n],
            soft_speed: vec![f64::NAN; n],
            limit: vec![f64::NAN; n],
            yield_gap: vec![f64::NAN; n],
            queries: Vec::new(),
        };
        for i in 0..n {
            self.plan_leaders(obs, i, &mut plan);
            self.plan_vehicle(obs, i, &mut plan)?;
        }
        plan.leader_entry = leader_entries(obs, self.driven.len());
        let queries = plan.queries.clone();
        self.plan = Some(plan);
        Ok(queries)
    }

    /// One entry per slot in every column, each slot driven here and listed once.
    fn check_observations(&self, obs: &Observations<'_>) -> Result<(), TrafficError> {
        let n = obs.slots.len();
        check_len("leader_gap", n, obs.leader_gap_m.len())?;
        check_len("leader_slot", n, obs.leader_slot.len())?;
        check_len("leader_speed", n, obs.leader_speed_mps.len())?;
        if let Some(room) = obs.leader_room_m {
            check_len("leader_room", n, room.len())?;
        }
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
        Ok(())
    }

    /// The leader and the soft leader of entry `i`, kept a margin behind.
    fn plan_leaders(&self, obs: &Observations<'_>, i: usize, plan: &mut Plan) {
        let margin = self.settings.standstill_margin_m;
        let gap = obs.leader_gap_m[i];
        if gap.is_finite() {
            // The simulator's gap leaves out minGap, and the simulator
            // counts anything closer as a collision: stop further back.
            plan.leader_gap[i] = gap - margin;
            // A room shorter than the gap, or none (NaN), leaves the gap.
            let room = obs.leader_room_m.map_or(f64::NAN, |r| r[i]);
            plan.leader_room[i] = gap.max(room) - margin;
            plan.leader_speed[i] = self.speed_of(obs.leader_slot[i], obs.leader_speed_mps[i]);
            plan.leader_external[i] = self.driven_at(obs.leader_slot[i]).is_none();
        }
        if let Some(sl) = &obs.soft {
            if sl.gap_m[i].is_finite() {
                plan.soft_gap[i] = sl.gap_m[i] - margin;
                plan.soft_speed[i] = self.speed_of(sl.slot[i], sl.speed_mps[i]);
            }
        }
    }

    /// Entry `i`'s speed limit, stop line (or the yield question it asks),
    /// and the lane position the simulator reported for it.
    fn plan_vehicle(
        &mut self,
        obs: &Observations<'_>,
        i: usize,
        plan: &mut Plan,
    ) -> Result<(), TrafficError> {
        let st = self.settings;
        let slot = obs.slots[i] as usize;
        let cfg = self.fleet.vehicle_config(slot as i64)?;
        let d = self.driven[slot].as_ref().expect("checked above");
        let route = &d.route;
        let sf = d.s_front_m;
        plan.limit[i] = route.pieces[route.piece_at(sf)].speed_mps;
        let mut next = d.next_stop;
        while next < route.stops.len() && route.stops[next].s_m < sf - 0.5 {
            next += 1;
        }
        let leader = (plan.leader_gap[i], plan.leader_speed[i]);
        let mut dec = decide_stop(d, next, cfg, &self.signals, leader, &st);
        if dec.stop_gap.is_nan() {
            dec.stop_gap = light_beyond(d, next, cfg, &self.signals, &st);
        }
        if let Some(gap) = dec.yield_gap {
            plan.yield_gap[i] = gap;
            plan.queries.push(i);
        }
        let end_gap = route_end_gap(route, sf, &st);
        if end_gap < st.route_end_horizon_m {
            dec.stop_gap = if dec.stop_gap.is_nan() {
                end_gap
            } else {
                dec.stop_gap.min(end_gap)
            };
        }
        if d.halt_m.is_finite() {
            dec.stop_gap = nearer(dec.stop_gap, halt_gap(d, cfg));
        }
        plan.stop_gap[i] = dec.stop_gap;
        let lane = obs.lane[i];
        let known =
            (lane >= 0 && obs.lane_pos_m[i].is_finite()).then(|| (lane as u32, obs.lane_pos_m[i]));
        let d = self.driven[slot].as_mut().expect("checked above");
        d.next_stop = next;
        d.yellow = dec.yellow;
        d.holding = dec.holding;
        if known.is_some() {
            d.known = known;
        }
        Ok(())
    }
}

/// No entry of the plan.
pub(crate) const NO_ENTRY: usize = usize::MAX;

/// Each entry's leader's entry in `obs` (the leader driven here, listed,
/// and with a finite gap), else [`NO_ENTRY`]. `n_slots` bounds the slots.
fn leader_entries(obs: &Observations<'_>, n_slots: usize) -> Vec<usize> {
    let mut entry_of = vec![NO_ENTRY; n_slots];
    for (i, &slot) in obs.slots.iter().enumerate() {
        entry_of[slot as usize] = i;
    }
    (0..obs.slots.len())
        .map(|i| {
            let l = obs.leader_slot[i];
            if l < 0 || l as usize >= n_slots || !obs.leader_gap_m[i].is_finite() {
                return NO_ENTRY;
            }
            let j = entry_of[l as usize];
            if j == i {
                NO_ENTRY
            } else {
                j
            }
        })
        .collect()
}

/// A leader slower than this (m/s; SUMO's halting speed) stands: it can
/// block the far side of a junction.
const LEADER_STANDING_MPS: f64 = 0.1;

/// What a vehicle does at the stop line it approaches.
#[derive(Debug, Clone, Copy)]
struct StopDecision {
    /// (stop index, stop?) decided at a yellow light.
    yellow: Option<(usize, bool)>,
    /// The stop line it waits at to give way or keep the junction clear.
    holding: Option<usize>,
    /// Gap to where it stops (m; NaN: no stop).
    stop_gap: f64,
    /// Gap to the line of a link that needs the simulator's word on foes.
    yield_gap: Option<f64>,
}

/// The decision of vehicle `d` at stop line `next` of its route (if any),
/// behind a leader (gap, speed; NaN: none) at the planning deceleration.
fn decide_stop(
    d: &Driven,
    next: usize,
    cfg: &ControllerConfig,
    signals: &[Vec<Signal>],
    (lg, lv): (f64, f64),
    st: &TrafficSettings,
) -> StopDecision {
    let margin = st.standstill_margin_m;
    let sf = d.s_front_m;
    let v = d.state.v_mps.abs();
    let mut dec = StopDecision {
        yellow: d.yellow,
        holding: d.holding.filter(|&k| k == next),
        stop_gap: f64::NAN,
        yield_gap: None,
    };
    let Some(stop) = d.route.stops.get(next) else {
        return dec;
    };
    let gap = stop.s_m - sf - margin;
    let sig = signal_at(signals, stop);
    if sig != Signal::Yellow {
        dec.yellow = None;
    }
    let lv = if lv.is_finite() { lv.max(0.0) } else { 0.0 };
    match sig {
        Signal::Stop => dec.stop_gap = gap,
        Signal::Yellow => {
            // The decision holds until the light changes: decided
            // anew every step it flips to "go" as the line nears
            // (the law brakes harder than b_f at the end) and then
            // fails to stop at red.
            let decision = match dec.yellow {
                Some((k, stop_here)) if k == next => stop_here,
                _ => can_stop(cfg, v, gap),
            };
            dec.yellow = Some((next, decision));
            if decision {
                dec.stop_gap = gap;
            }
        }
        Signal::Priority | Signal::Yield => {
            // A link is asked about from where the vehicle could still stop
            // for it (reaction time at its speed, braking at its planning
            // deceleration) plus the look-ahead: asked from the look-ahead
            // alone, a vehicle at 13.9 m/s (it needs 38 m) was never asked
            // and crossed a busy major road at speed. The same holds for a
            // link with priority whose way inside the junction is checked
            // for bodies in it: at 13.5 m/s a controlled car was never
            // asked, and ran into a left turner standing at its waiting
            // point across the shared start of the two ways (Bologna,
            // junction 50, seed 10).
            let ask_reach = st.yield_lookahead_m + stopping_distance(cfg, v);
            let near = gap
                < if sig == Signal::Yield {
                    ask_reach
                } else {
                    st.yield_lookahead_m
                };
            let held = d.holding == Some(next);
            // A standing leader (below SUMO's halting speed) whose back
            // leaves no room for the vehicle beyond the junction's exit. A
            // moving leader makes room as it goes: it is followed into the
            // junction, as SUMO's drivers do (they count the space up to
            // the last standing vehicle beyond the link). Traced on
            // Bologna: held until a leader pulling away at 1 m/s^2 was a
            // body length past the exit, a queue crossed a green light one
            // vehicle every 9 s, each stopping at the line.
            let blocked = lg.is_finite()
                && lv < LEADER_STANDING_MPS
                && sf + lg + margin - stop.exit_m < d.body.length_m + d.body.min_gap_m + margin;
            if near && blocked && (held || can_stop(cfg, v, gap)) {
                // Keep the junction clear: no room behind the
                // leader on the far side, so wait at the line.
                dec.stop_gap = gap;
                dec.holding = Some(next);
            } else if (sig == Signal::Yield || stop.check_inside)
                && gap < ask_reach
                && (held || can_stop(cfg, v, gap))
            {
                // Give way while the simulator reports foes (or,
                // with the right of way, while the caller sees a
                // vehicle inside the junction in the way); too
                // late to stop, clear the junction instead.
                dec.yield_gap = Some(gap);
            } else {
                dec.holding = None;
            }
        }
    }
    dec
}

/// How far a vehicle at speed `v` travels until it stands: its reaction
/// time at `v`, then braking at its planning deceleration.
fn stopping_distance(cfg: &ControllerConfig, v: f64) -> f64 {
    v * cfg.reaction_time + v * v / (-2.0 * cfg.max_deceleration.min(-0.5))
}

/// The gap to the line of a red light (or of a yellow one it can stop
/// for) beyond stop line `next`, within the distance vehicle `d` needs to
/// stop (its reaction time at its speed, braking at its planning
/// deceleration, plus the yield look-ahead); NaN: none. Where two junctions
/// follow closely (31 m apart on Bologna), the light at the second turned
/// red while the vehicle, at 13.8 m/s, still had the first one's line ahead
/// and looked no further: it saw the red 8 m before the line and crossed it.
fn light_beyond(
    d: &Driven,
    next: usize,
    cfg: &ControllerConfig,
    signals: &[Vec<Signal>],
    st: &TrafficSettings,
) -> f64 {
    let sf = d.s_front_m;
    let v = d.state.v_mps.abs();
    let horizon = v * cfg.reaction_time
        + v * v / (-2.0 * cfg.max_deceleration.min(-0.5))
        + st.yield_lookahead_m;
    for stop in d.route.stops.iter().skip(next + 1) {
        let gap = stop.s_m - sf - st.standstill_margin_m;
        if gap > horizon {
            break;
        }
        match signal_at(signals, stop) {
            Signal::Stop => return gap,
            Signal::Yellow if can_stop(cfg, v, gap) => return gap,
            _ => {}
        }
    }
    f64::NAN
}

/// The gap to where the route's end stops a vehicle whose front is at `sf`.
/// A track that stops where a lane change is due ends `lane_change_room_m`
/// early: the vehicle waits there for a gap. The end of the route (with
/// `stop_at_route_end`): a standing obstacle a little past the track's end,
/// so the vehicle slows down and the simulator sees it arrive. Otherwise
/// (+inf) the vehicle drives through its route's end and the simulator's own
/// movement (a speed move near a lane's end) carries it out.
fn route_end_gap(route: &Route, sf: f64, st: &TrafficSettings) -> f64 {
    if route.lane_change.is_some() {
        route.length_m - st.lane_change_room_m - sf - st.standstill_margin_m
    } else if st.stop_at_route_end {
        route.length_m + st.route_end_extra_m - sf
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use crate::testkit::*;
    use crate::*;

    #[test]
    fn red_light_stops_the_vehicle_before_the_line_then_green_lets_it_go() {
        let (mut f, slot) = before_light(Signal::Stop, 100.0, 12.0);
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
    fn a_red_light_just_past_a_junction_with_the_right_of_way_is_seen_in_time() {
        // A major road's junction at 200 m, then a light 9 m further on.
        // Looking only at the next line the vehicle would see the red once
        // past 200 m, 8 m (less the 1 m margin) before the line at 15 m/s,
        // where even braking at 9 m/s^2 takes 12.5 m: it looks past the
        // first line and stops in time.
        let (path, route) = road(None, true);
        let mut stops = route.stops.clone();
        stops.push(route::StopLine {
            s_m: 209.0,
            signal: Some((0, 0)),
            major: false,
            via: 12,
            exit_m: 220.0,
            check_inside: false,
        });
        let route = route::Route::new(route.pieces.clone(), stops, 600.0, None).unwrap();
        let (mut f, t) = fleet_on((path, route));
        f.set_signal(0, &[Signal::Stop]).unwrap();
        let slot = f
            .add_vehicle(t, None, None, body(), at(150.0, 15.0), None)
            .unwrap() as i64;
        for _ in 0..300 {
            let (_, out) = step(&mut f, &[slot], false);
            assert!(!out.red_light[0]);
        }
        let sf = f.s_front(slot).unwrap();
        assert!(
            sf < 209.0 && f.state(slot).unwrap().v_mps.abs() < 0.05,
            "stands before the second line: front {sf}"
        );
    }

    #[test]
    fn a_yellow_decision_holds_until_the_light_changes() {
        let (mut f, slot) = before_light(Signal::Yellow, 120.0, 12.0);
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
        let (mut f, slot) = before_light(Signal::Yellow, 200.0 - 3.5 - 4.0, 14.0);
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
                    .add_vehicle(t, None, None, body(), at(150.0, 8.0), None)
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
    fn a_fast_vehicle_asks_about_a_junction_checked_for_vehicles_inside_while_it_can_stop() {
        // At 19 m/s the vehicle needs more than the 30 m look-ahead to stop
        // (its reaction time, then its planning deceleration). Asked only
        // within the look-ahead, where it can no longer stop, it was never
        // asked, and drove through a junction with a car standing across
        // its way: asked from where it can still stop, it waits.
        let (path, mut route) = road(None, true);
        route.stops[0].check_inside = true;
        let (mut f, t) = fleet_on((path, route));
        let v = 19.0;
        let slot = f
            .add_vehicle(t, None, None, body(), at(60.0, v), None)
            .unwrap() as i64;
        let cfg = f.fleet.vehicle_config(slot).unwrap();
        assert!(super::stopping_distance(cfg, v) > TrafficSettings::default().yield_lookahead_m);
        let mut asked = 0;
        for _ in 0..300 {
            asked += step(&mut f, &[slot], true).0.len();
        }
        assert!(asked > 0);
        let sf = f.s_front(slot).unwrap();
        assert!(
            sf < 200.0 && f.state(slot).unwrap().v_mps.abs() < 0.05,
            "waits at the line: front {sf}"
        );
    }

    #[test]
    fn links_without_priority_ask_and_wait_only_when_told_to() {
        for must_yield in [true, false] {
            let (mut f, t) = fleet_on(road(None, false));
            let slot = f
                .add_vehicle(t, None, None, body(), at(150.0, 8.0), None)
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
            .add_vehicle(t, None, None, body(), at(150.0, 8.0), None)
            .unwrap() as i64;
        for _ in 0..100 {
            assert!(step(&mut f, &[slot], true).0.is_empty());
        }
    }

    #[test]
    fn the_junction_is_kept_clear_when_the_leader_leaves_no_room_beyond_it() {
        let (mut f, slot) = before_light(Signal::Priority, 160.0, 8.0);
        for _ in 0..300 {
            let sf = f.s_front(slot).unwrap();
            // A standing leader whose back is 3 m past the junction's exit.
            let gap = 213.0 - sf;
            plan_one(&mut f, slot, (gap, 0.0), (-1, f64::NAN));
            f.step(&[], DT).unwrap();
        }
        let sf = f.s_front(slot).unwrap();
        assert!(
            sf < 200.0,
            "waits before the line, not inside the junction: front {sf}"
        );
    }

    #[test]
    fn a_leader_pulling_away_beyond_the_junction_is_followed_through_it() {
        // The leader's back starts 1 m past the exit and creeps away at
        // 0.3 m/s: in the 20 s it never leaves the room a standing vehicle
        // needs (body 4.5 + minGap 2.5 + margin 1 m past the exit), yet it
        // moves, so the vehicle is not held at the line: it follows
        // through the junction, never closer than the standstill margin.
        let (mut f, slot) = before_light(Signal::Priority, 180.0, 3.0);
        let mut closest = f64::INFINITY;
        for k in 0..200 {
            let back = 211.0 + 0.3 * k as f64 * DT;
            let gap = back - f.s_front(slot).unwrap();
            closest = closest.min(gap);
            plan_one(&mut f, slot, (gap, 0.3), (-1, f64::NAN));
            f.step(&[], DT).unwrap();
        }
        let sf = f.s_front(slot).unwrap();
        assert!(sf > 204.0, "followed into the junction: front {sf}");
        assert!(closest > 0.5, "kept its distance: closest gap {closest}");
    }

    #[test]
    fn a_driven_leader_s_speed_comes_from_its_state() {
        let (mut f, t) = fleet_on(road(None, true));
        let lead = f
            .add_vehicle(t, None, None, body(), at(60.0, 14.0), None)
            .unwrap() as i64;
        let fol = f
            .add_vehicle(t, None, None, body(), at(40.0, 14.0), None)
            .unwrap() as i64;
        let accel = |f: &mut RouteFleet, leader_slot: i64| {
            let mut g = f.clone();
            g.plan(&Observations {
                slots: &[fol],
                leader_gap_m: &[12.0],
                leader_slot: &[leader_slot],
                leader_speed_mps: &[f64::NAN],
                leader_room_m: None,
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
    fn the_vehicle_stops_at_the_end_of_its_route_when_set_to() {
        let settings = TrafficSettings {
            stop_at_route_end: true,
            ..Default::default()
        };
        let (mut f, t) = fleet_with(road(None, true), settings);
        let a = f
            .add_vehicle(t, None, None, body(), at(400.0, 15.0), None)
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
    fn the_route_end_is_a_planned_stop_within_its_horizon() {
        // With stop_at_route_end the end of the 600 m route is a stop
        // route_end_extra_m (5 m) past it, planned once the gap to it is
        // below route_end_horizon_m (200 m): gap = 605 - s_front within the
        // horizon, no stop (NaN) beyond it, on both sides of the boundary
        // (fronts at 405.5 and 404.5 m: gaps 199.5 and 200.5 m). The front
        // is the rear axle plus the body's reach (3.5 m); the road's
        // junction is on the major road (no stop of its own).
        let settings = TrafficSettings {
            stop_at_route_end: true,
            ..Default::default()
        };
        let st = settings;
        for (x, planned) in [(402.0, true), (401.0, false), (450.0, true), (200.0, false)] {
            let (mut f, t) = fleet_with(road(None, true), settings);
            let a = f
                .add_vehicle(t, None, None, body(), at(x, 15.0), None)
                .unwrap() as i64;
            let sf = f.s_front(a).unwrap();
            plan_one(&mut f, a, (f64::NAN, f64::NAN), (-1, f64::NAN));
            let gap = f.plan.as_ref().unwrap().stop_gap[0];
            let want = 600.0 + st.route_end_extra_m - sf;
            assert_eq!(want < st.route_end_horizon_m, planned, "x {x}: {want}");
            if planned {
                assert!(
                    (gap - want).abs() < 1e-9,
                    "x {x}: planned {gap}, want {want}"
                );
            } else {
                assert!(
                    gap.is_nan(),
                    "x {x}: {want} m is beyond the horizon, planned {gap}"
                );
            }
        }
    }

    #[test]
    fn a_soft_leader_is_braked_for_as_the_core_s_law_says_at_b_f_at_most() {
        // A vehicle at its preferred speed (15 m/s, free flow 0) behind a soft
        // leader (one on the lane beside, to line up behind) observed at
        // `gap` m and `speed` m/s: the command is the core's law for a soft
        // obstacle a standstill margin nearer, computed here from
        // longitudinal_accel, and the step's acceleration (one control step,
        // dv / dt) is that command. A standing one 20 m ahead asks for more
        // than b_f: capped at max_deceleration (-4). One at 12 m/s 25 m
        // ahead asks for less. Without the soft gap passed to the core the
        // vehicle would not brake; without its speed, the moving one would be
        // taken as standing.
        let mut checked = 0;
        for (gap, speed) in [(20.0, 0.0), (25.0, 12.0), (40.0, 15.0)] {
            let (mut f, t) = fleet_with(road(None, true), one_control_step());
            let a = f
                .add_vehicle(t, None, None, body(), at(50.0, 15.0), None)
                .unwrap() as i64;
            let cfg = f.fleet.vehicle_config(a).unwrap().clone();
            f.plan(&Observations {
                slots: &[a],
                leader_gap_m: &[f64::NAN],
                leader_slot: &[-1],
                leader_speed_mps: &[f64::NAN],
                leader_room_m: None,
                lane: &[-1],
                lane_pos_m: &[f64::NAN],
                soft: Some(SoftLeaders {
                    gap_m: &[gap],
                    slot: &[-1],
                    speed_mps: &[speed],
                }),
            })
            .unwrap();
            let got = f.step(&[], DT).unwrap().accel_mps2[0];
            let margin = f.settings().standstill_margin_m;
            let want = blendtrack::longitudinal::longitudinal_accel(
                15.0,
                None,
                &[blendtrack::Obstacle::soft(gap - margin, speed)],
                &cfg,
            )
            .accel_mps2;
            assert!(
                (got - want).abs() < 1e-9,
                "gap {gap}, speed {speed}: {got} vs {want}"
            );
            if speed == 0.0 {
                assert_eq!(want, cfg.max_deceleration);
            } else if speed == 12.0 {
                assert!(want < 0.0 && want > cfg.max_deceleration, "{want}");
                checked += 1;
            }
        }
        assert_eq!(checked, 1);
    }

    #[test]
    fn by_default_the_vehicle_drives_through_the_end_of_its_route() {
        // Like SUMO's drivers (arrivalSpeed "current"): no slowing down for
        // the route's end at 600 m; the simulator takes the vehicle out there.
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(400.0, 15.0), None)
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
}
