//! How a vehicle's new pose goes into the simulator ([`Move`]): by its
//! speed alone while the simulator's own movement carries it there
//! ([`glide_distance`]), by lane position, or by (x, y).

use crate::route::Route;
use crate::{Driven, TrafficSettings};

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
pub(crate) const GLIDE_TOLERANCE_MPS: f64 = 0.1;
pub(crate) const GLIDE_TOLERANCE_REL: f64 = 0.02;
/// A simulator that has the front more than this (m) behind where a
/// speed-only move can bring it is placed with a [`Move::Lane`].
pub(crate) const GLIDE_BEHIND_M: f64 = 0.5;
/// Below this change of the speed (m/s) no speed command is sent ([`Move::Hold`]):
/// the simulator's speed then differs from the vehicle's by less than this,
/// its position by less than this times dt (2 mm at 0.1 s), made up in the
/// next step. 13 % fewer speed commands than at 0.005 m/s on the highway.
pub(crate) const HOLD_SPEED_MPS: f64 = 0.02;
/// A speed-only move whose new place is on the simulator's lane leaves the
/// front at least this far (m) before the lane's end (a position at the end
/// itself may be rounded over it).
pub(crate) const LANE_END_MARGIN_M: f64 = 1e-3;
/// Under the ballistic update a speed-only move that would carry the front
/// more than this (m) past its new place is a [`Move::Lane`] instead.
pub(crate) const BALLISTIC_AHEAD_M: f64 = 0.05;
/// A speed-only move may carry the front over at most this many lane ends
/// (short junction lanes at speed).
pub(crate) const GLIDE_MAX_LANE_ENDS: usize = 3;

/// How far (m) the simulator moves a vehicle over a step of `dt_s` that
/// it is sent `sent` m/s for, having `prev` m/s: at `sent` (Euler, SUMO's
/// default) or at the mean of the two (ballistic; SUMO's `getDeltaPos`
/// for a speed that stays >= 0).
pub(crate) fn sim_displacement(ballistic: bool, prev: f64, sent: f64, dt_s: f64) -> f64 {
    if ballistic {
        0.5 * (prev + sent) * dt_s
    } else {
        sent * dt_s
    }
}

/// The speed (m/s) to send for the simulator to move a vehicle that has
/// `prev` m/s `dist` m over a step of `dt_s` (the inverse of
/// [`sim_displacement`]; below 0 where no speed >= 0 moves it so little).
pub(crate) fn speed_for(ballistic: bool, prev: f64, dist: f64, dt_s: f64) -> f64 {
    if ballistic {
        2.0 * dist / dt_s - prev
    } else {
        dist / dt_s
    }
}

/// The distance the simulator must move the front, along its lanes, from
/// where it has it (`known`: lane, position) to lane position `target` on
/// piece `k`, and whether that passes a lane end; None when it cannot tell
/// (unknown position, or a lane the route's pieces do not lead from).
pub(crate) fn glide_distance(
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
    // Already over the lane's end, on the next piece's lane (entered at its
    // start): ahead of the target by the rest of this lane and its position
    // there. Slowed, never put back: a vehicle standing at a junction's
    // entry that the simulator had 1 cm into the junction was moved back
    // onto the lane before it, where the simulator then found the vehicle
    // behind within its minGap and called it a collision (Eccles).
    if let Some(next) = pieces.get(k + 1) {
        if next.lane == lane && next.lane_pos_start_m == 0.0 {
            return Some((target - pieces[k].lane_length_m - p, false));
        }
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
        // Not back over a whole edge: on a track that drives the lane
        // again, that could be another lap's piece of it.
        if q.lane == pieces[j + 1].lane
            || !q.offset_m.is_finite()
            || q.occurrence + 1 < pieces[k].occurrence
        {
            return None;
        }
        if q.lane == lane {
            return Some((dist + q.lane_length_m - p, true));
        }
        dist += q.lane_length_m;
    }
    None
}

/// A vehicle's step as the choice of its move sees it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Motion {
    /// The fleet's outputs and the new state are usable (finite, ok).
    pub usable: bool,
    /// Errors of the control point (m, rad), the new speed (m/s).
    pub lateral_error_m: f64,
    pub heading_error_rad: f64,
    pub v_mps: f64,
    /// Arc length of the front at the new state (m).
    pub s_front_m: f64,
    pub dt_s: f64,
    /// How far the front may go before the leader at the start of the step
    /// (its gap less the standstill margin; inf: no leader).
    pub leader_room_m: f64,
}

/// The chosen move with what goes with it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Placement {
    pub mv: Move,
    /// Lane position for [`Move::Lane`] (m, before the simulator's movement).
    pub pos: f64,
    /// The speed to give the simulator (m/s).
    pub sumo_speed: f64,
    /// Where the simulator will have the front after its movement, when
    /// blendtrack can tell without asking: (lane, position).
    pub predicted: Option<(u32, f64)>,
}

/// How to put vehicle `d`'s new pose (on piece `k` of its route) into the
/// simulator, cheapest first (see the crate docs).
pub(crate) fn choose_move(d: &Driven, k: usize, st: &TrafficSettings, m: &Motion) -> Placement {
    let route = &d.route;
    let piece = route.pieces[k];
    let (v, dt_s, sf_new) = (m.v_mps, m.dt_s, m.s_front_m);
    // Where the front must be on the piece's lane after the
    // simulator's own movement over the step.
    let target = piece.lane_pos_at(sf_new);
    let mut p = Placement {
        mv: Move::Xy,
        pos: target - v * dt_s,
        sumo_speed: v,
        predicted: None,
    };
    let on_lane = m.lateral_error_m.abs() + piece.offset_m < st.lane_move_lateral_m
        && m.heading_error_rad.abs() < st.lane_move_heading_rad
        && v >= 0.0;
    // (distance the simulator must move the front, crosses a lane end)
    let glide = if on_lane {
        glide_distance(route, k, target, d.known)
    } else {
        None
    };
    // The front's speed in the simulator's lane coordinates: v times the
    // piece's scale, or, over a step that crosses a lane end, the lane
    // distance from its last place on the track to the new one over the
    // step. At the scale of the piece it ends on alone, a step ending on a
    // 0.48 m junction lane under 0.12 m of track (scale 4) sent a vehicle
    // at 7.4 m/s to the simulator at 28.6 m/s for the whole step, 23 m too
    // far, into the vehicle ahead (Eccles).
    // (That lane distance over the step is a mean speed: the speed that
    // has a ballistic move cover it ends the step at about the vehicle's.)
    let prev = sim_speed(d);
    let expect = match glide {
        Some((_, true)) => {
            crossing_lane_speed(route, k, target, d.s_front_m, dt_s).map_or(v, |mean| {
                if st.ballistic {
                    speed_for(true, prev, mean * dt_s, dt_s).max(0.0)
                } else {
                    mean
                }
            })
        }
        _ => v * piece.scale,
    };
    // Placed by lane position, the simulator then moves the front over the
    // step at the speed sent.
    let moved = sim_displacement(st.ballistic, prev, v, dt_s);
    let lane_ok =
        on_lane && target - moved >= d.body.length_m && !laps_back_onto_the_lane_before(d, k);
    p.mv = if !m.usable {
        Move::Invalid
    } else if k == route.pieces.len() - 1
        && route.lane_change.is_none()
        && sf_new > route.length_m - 2.0 * v * dt_s - 2.0
    {
        // About to arrive: a deferred (x, y) move would be applied
        // after the simulator removed the vehicle.
        Move::Speed
    } else if let Some((dist, cross)) = glide.filter(|&(dist, _)| {
        dist - sim_displacement(st.ballistic, prev, expect, dt_s) <= GLIDE_BEHIND_M
    }) {
        // Room to the end of the lane the simulator has the front on, when
        // the new place is on that lane: a speed-only move stays on it.
        let room = match d.known {
            Some((lane, at)) if !cross && lane == piece.lane => piece.lane_length_m - at,
            _ => f64::INFINITY,
        };
        // Nor past the leader's back as it stood at the start of the step,
        // unless blendtrack's own move goes there (a leader moving off).
        let room = room.min(dist.max(m.leader_room_m) + LANE_END_MARGIN_M);
        let glide = glide_move(
            d,
            (st.ballistic, prev),
            &mut p,
            expect,
            (dist, room),
            cross,
            dt_s,
        );
        if st.ballistic
            && lane_ok
            && !cross
            && dist >= 0.0
            && sim_displacement(true, prev, p.sumo_speed, dt_s) > dist + BALLISTIC_AHEAD_M
        {
            // A ballistic move covers at least half the speed the simulator
            // has, whatever speed >= 0 it is sent, and the mean of the two
            // speeds where blendtrack's braking over the step is not even:
            // further than the front goes (the last step of a stop, hard
            // braking early in the step). Placed that much behind, it ends
            // the step where blendtrack has it (ahead of where the
            // simulator had it: never moved back).
            p.sumo_speed = v;
            p.pos = target - moved;
            p.predicted = Some((piece.lane, p.pos + moved));
            Move::Lane
        } else {
            glide
        }
    } else if lane_ok {
        p.pos = target - moved;
        if let Some((lane, known)) = d.known {
            if lane == piece.lane {
                // Not past the leader's back as it stands (less the
                // margin): the simulator puts the vehicle there at once,
                // before anyone moves, and checks for collisions. Put
                // 0.72 m on from where SUMO had it, a controlled car landed
                // 0.7 m inside the minGap of a driver that had changed
                // onto its junction lane just ahead of it in that step
                // (Bologna, 30 %, seed 25, 113 s, :9_12_1). The rest of the
                // way is made up once the leader has moved on.
                p.pos = p.pos.min(known + m.leader_room_m.max(0.0)).max(known);
            }
        }
        p.predicted = Some((piece.lane, p.pos + moved));
        Move::Lane
    } else {
        Move::Xy
    };
    p
}

/// The speed the simulator has the vehicle at: the last sent, or before
/// the first, the vehicle's own (taken over at the simulator's).
fn sim_speed(d: &Driven) -> f64 {
    if d.sumo_speed.is_finite() {
        d.sumo_speed
    } else {
        d.state.v_mps.max(0.0)
    }
}

/// Whether the simulator has the vehicle on the lane of piece `k` with its
/// back still over the lane's start, on the route's lane before (SUMO calls
/// it a partial occupant there). A lane-position move on the same lane then leaves that lane
/// believing the vehicle is still on it: SUMO's `moveTo` onto the lane a
/// vehicle is already on only sets its position (libsumo's
/// `Vehicle::moveTo` calls `setTentativeLaneAndPosition` and returns),
/// so the lane before keeps it as a partial occupant whose position there
/// SUMO can no longer work out, and takes its position on its own lane
/// instead. SUMO's next collision check put a controlled vehicle 5 m into
/// the junction lane behind it, behind the follower there, 14 m back, and
/// called that a collision (Bologna, :23_3_0); the follower's leader
/// search saw it behind. A move by (x, y) goes through SUMO's remote
/// control, which updates the lanes the vehicle laps onto.
fn laps_back_onto_the_lane_before(d: &Driven, k: usize) -> bool {
    k > 0 && matches!(d.known, Some((l, at)) if l == d.route.pieces[k].lane && at < d.body.length_m)
}

/// The front's speed in the simulator's lane coordinates over a step that
/// crosses a lane end: the lane distance from its old place on the track
/// (`s_old`) to lane position `target` on piece `k`, over `dt_s`; None
/// when the route cannot tell.
fn crossing_lane_speed(route: &Route, k: usize, target: f64, s_old: f64, dt_s: f64) -> Option<f64> {
    let (dist, _) = glide_distance(route, k, target, Some(route.lane_position(s_old)))?;
    (dist.is_finite() && dist >= 0.0 && dt_s > 0.0).then(|| dist / dt_s)
}

/// A speed-only move: the simulator's own movement carries the front
/// `dist` along its lanes at the speed that makes it up, kept within
/// GLIDE_TOLERANCE_* of the vehicle's own speed in the simulator's lane
/// coordinates (`expect`): a simulator a little off (ahead, or behind by up
/// to GLIDE_BEHIND_M) is brought back over a few steps; it is never moved
/// backwards. Nor is it carried over the end of its lane (`room` ahead of
/// it) while the new place is still on that lane: a simulator ahead of
/// blendtrack (a step of 1 s from a standstill, its Euler move against
/// blendtrack's sub-steps) was carried 1 cm over a stop line where
/// blendtrack stopped 20 cm before it, stood there inside the junction, and
/// the crossing traffic waited for it while it waited for them. Nor past
/// the leader's back where it stood (`room` is the nearer of the two): a
/// vehicle pulling away from a standstill at 2.6 m/s^2 behind a car still
/// standing at a light, 0.66 m beyond SUMO's minGap, was sent at 1.08 m/s
/// (its own speed at the end of the step, 1.2 m/s, less the tolerance)
/// where blendtrack moved it 0.32 m, and SUMO called the 1.08 m a
/// collision (Bologna, 203[0], seed 2 at 185 s).
/// [`Move::Hold`] when the speed it has will do. `ballistic`, `prev`: the
/// simulator's position update and the speed it has the vehicle at
/// ([`sim_speed`]).
fn glide_move(
    d: &Driven,
    (ballistic, prev): (bool, f64),
    p: &mut Placement,
    expect: f64,
    (dist, room): (f64, f64),
    cross: bool,
    dt_s: f64,
) -> Move {
    let tol = GLIDE_TOLERANCE_MPS + GLIDE_TOLERANCE_REL * expect;
    p.sumo_speed =
        speed_for(ballistic, prev, dist, dt_s).clamp((expect - tol).max(0.0), expect + tol);
    if sim_displacement(ballistic, prev, p.sumo_speed, dt_s) > room - LANE_END_MARGIN_M {
        p.sumo_speed = speed_for(ballistic, prev, room - LANE_END_MARGIN_M, dt_s).max(0.0);
    }
    // A standstill is always sent: a held creep speed would let
    // the simulator drift ahead (0.4 mm a step at 4 mm/s), and
    // it is never moved back.
    let hold = !cross
        && (p.sumo_speed - d.sumo_speed).abs() < HOLD_SPEED_MPS
        && (p.sumo_speed > 0.0 || d.sumo_speed == 0.0);
    if hold {
        p.sumo_speed = d.sumo_speed;
    }
    if !cross {
        // Exact; after a lane end the simulator's choice of the
        // next lane is read back instead.
        let moved = sim_displacement(ballistic, prev, p.sumo_speed, dt_s);
        p.predicted = d.known.map(|(lane, at)| (lane, at + moved));
    }
    if hold {
        Move::Hold
    } else {
        Move::Speed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testkit::*;
    use crate::*;

    #[test]
    fn moves_follow_the_lane_when_centred_and_xy_otherwise() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0), None)
            .unwrap() as i64;
        let mut off = at(50.0, 10.0);
        off.y_m = 0.5;
        let b = f.add_vehicle(t, None, None, body(), off, None).unwrap() as i64;
        let c = f
            .add_vehicle(t, None, None, body(), at(594.0, 10.0), None)
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
        assert_eq!(out.xy_on_track, [false, false, false]);
        // On the junction lane (not plain) even a centred vehicle moves by (x, y).
        let d = f
            .add_vehicle(t, None, None, body(), at(200.0, 10.0), None)
            .unwrap() as i64;
        assert_eq!(step(&mut f, &[d], false).1.moves, [Move::Xy]);
        // The scale maps arc length to lane position on lane 12.
        let e = f
            .add_vehicle(t, None, None, body(), at(300.0, 10.0), None)
            .unwrap() as i64;
        let out = step(&mut f, &[e], false).1;
        let sf = f.s_front(e).unwrap();
        assert!((out.lane_pos_m[0] - ((sf - 210.0) * 1.01 - out.v_mps[0] * DT)).abs() < 1e-9);
    }

    #[test]
    fn a_front_far_off_its_track_is_put_on_the_track() {
        // The road's track runs along y = 0 heading east. A front 2.5 m off
        // it (more than XY_ON_TRACK_M) is given to the simulator at the
        // track's point at the front's arc length, at the vehicle's own
        // heading (the simulator draws the body back along it); one 0.8 m
        // off keeps its own place.
        let (mut f, t) = fleet_on(road(None, true));
        let mut far = at(50.0, 10.0);
        far.y_m = 2.5;
        let mut near = at(80.0, 10.0);
        near.y_m = 0.8;
        let a = f.add_vehicle(t, None, None, body(), far, None).unwrap() as i64;
        let b = f.add_vehicle(t, None, None, body(), near, None).unwrap() as i64;
        let (_, out) = step(&mut f, &[a, b], false);
        assert_eq!(out.moves, [Move::Xy, Move::Xy]);
        assert_eq!(out.xy_on_track, [true, false]);
        let sf = f.s_front(a).unwrap();
        assert!(
            (out.x_front_m[0] - sf).abs() < 1e-6 && out.y_front_m[0].abs() < 1e-9,
            "{out:?}"
        );
        // Steering back toward the track, it heads off the track's
        // direction (east, 90 deg): that heading is what is sent.
        let th = f.state(a).unwrap().theta_rad;
        assert!(th.abs() > 1e-3, "{th}");
        assert!(
            (out.angle_deg[0] - (90.0 - th.to_degrees())).abs() < 1e-9,
            "{out:?}"
        );
        let s = f.state(b).unwrap();
        assert!((out.y_front_m[1] - s.y_m - 3.5 * s.theta_rad.sin()).abs() < 1e-9);
        const { assert!(crate::step::XY_ON_TRACK_M > 0.8 && crate::step::XY_ON_TRACK_M < 2.5) };
    }

    #[test]
    fn a_placement_never_goes_back_behind_where_the_simulator_has_the_vehicle() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0), None)
            .unwrap() as i64;
        let sf = f.s_front(a).unwrap();
        let slots = [a];
        let plan = |f: &mut RouteFleet, pos: f64| {
            f.plan(&Observations {
                slots: &slots,
                leader_gap_m: &[f64::NAN],
                leader_slot: &[-1],
                leader_speed_mps: &[f64::NAN],
                leader_room_m: None,
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
    fn a_placement_never_jumps_past_the_leader_where_it_stands() {
        // The simulator has the front 2 m behind blendtrack's, and a leader
        // 1.5 m ahead of that front (SUMO's gap, after its minGap): put at
        // once where blendtrack has it, the front would land in the
        // leader. It goes no further than the gap less the standstill
        // margin; with the leader 5 m ahead it is placed where it must be.
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0), None)
            .unwrap() as i64;
        let margin = f.settings().standstill_margin_m;
        for (gap, capped) in [(1.5, true), (5.0, false)] {
            let sf = f.s_front(a).unwrap();
            let known = sf - 2.0;
            plan_one(&mut f, a, (gap, 10.0), (10, known));
            let out = f.step(&[], DT).unwrap();
            assert_eq!(out.moves, [Move::Lane]);
            let want = f.s_front(a).unwrap() - out.v_mps[0] * DT;
            if capped {
                assert!(want > known + gap, "{want} {known}");
                assert!(
                    (out.lane_pos_m[0] - (known + gap - margin)).abs() < 1e-9,
                    "{out:?}"
                );
            } else {
                assert!((out.lane_pos_m[0] - want).abs() < 1e-9, "{out:?}");
            }
        }
    }

    #[test]
    fn a_placement_is_bounded_by_the_simulators_gap_not_the_stopping_laws() {
        // The bridge shortens the gap to a leader SUMO drives (1.5 m) for
        // the stopping law and hands SUMO's own (5 m) along: the law brakes
        // for the shortened gap, but the move puts the front where
        // blendtrack has it, as with a leader 5 m ahead. Held at the
        // shortened gap, the vehicle stood in SUMO while blendtrack moved
        // it on, and a controlled follower planning with that advance ran
        // into it (Eccles, seed 13, 24 s).
        let run = |room: f64| {
            let (mut f, t) = fleet_on(road(None, true));
            let a = f
                .add_vehicle(t, None, None, body(), at(50.0, 10.0), None)
                .unwrap() as i64;
            let known = f.s_front(a).unwrap() - 2.0;
            plan_one_with_room(&mut f, a, (1.5, 10.0), room, (10, known));
            let out = f.step(&[], DT).unwrap();
            assert_eq!(out.moves, [Move::Lane]);
            let want = f.s_front(a).unwrap() - out.v_mps[0] * DT;
            let margin = f.settings().standstill_margin_m;
            (out.v_mps[0], out.lane_pos_m[0], want, known - margin)
        };
        let (v_short, pos_short, want_short, known_less_margin) = run(f64::NAN);
        assert!(want_short > known_less_margin + 1.5);
        assert!((pos_short - (known_less_margin + 1.5)).abs() < 1e-9);
        let (v_room, pos_room, want_room, _) = run(5.0);
        assert_eq!(v_room, v_short, "the law takes the shortened gap");
        assert!(
            (pos_room - want_room).abs() < 1e-9,
            "{pos_room} {want_room}"
        );
        // A room shorter than the gap is no room: the gap bounds.
        let (_, pos_less, _, _) = run(1.0);
        assert!((pos_less - pos_short).abs() < 1e-12);
    }

    #[test]
    fn a_vehicle_standing_where_a_move_by_xy_put_it_is_sent_nothing_more() {
        // On the junction piece (200-210 m, not plain) every move is by
        // (x, y). Behind a leader standing 0.5 m ahead the vehicle stands:
        // the first step's move puts it, the next ones send nothing (the
        // simulator keeps it there; sent again, the move would undo the
        // simulator's own teleport of a vehicle that waited too long). Once
        // the leader is gone it moves by (x, y) again.
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(201.0, 0.0), None)
            .unwrap() as i64;
        let mut moves = Vec::new();
        for _ in 0..4 {
            plan_one(&mut f, a, (0.5, 0.0), (-1, f64::NAN));
            let out = f.step(&[], DT).unwrap();
            assert_eq!(out.v_mps[0], 0.0);
            moves.push(out.moves[0]);
        }
        assert_eq!(moves, [Move::Xy, Move::Hold, Move::Hold, Move::Hold]);
        plan_one(&mut f, a, (f64::NAN, f64::NAN), (-1, f64::NAN));
        let out = f.step(&[], DT).unwrap();
        assert!(out.v_mps[0] > 0.0);
        assert_eq!(out.moves[0], Move::Xy);
        // Moved on by the bridge (advance_state), it is put again even standing.
        let b = f
            .add_vehicle(t, None, None, body(), at(202.0, 0.0), None)
            .unwrap() as i64;
        for _ in 0..2 {
            plan_one(&mut f, b, (0.5, 0.0), (-1, f64::NAN));
            f.step(&[], DT).unwrap();
        }
        f.advance_state(b, 0.3).unwrap();
        plan_one(&mut f, b, (0.5, 0.0), (-1, f64::NAN));
        assert_eq!(f.step(&[], DT).unwrap().moves[0], Move::Xy);
    }

    #[test]
    fn a_crawl_moved_by_xy_is_never_put_back_behind_the_simulator() {
        // 0.6 m off its lane's centreline: moved by (x, y). The simulator
        // has the front `ahead` m further on lane 10 than blendtrack: at a
        // crawl (1 m/s) the new front goes at least there (up to 5 m;
        // further is a lost vehicle, left to the placement check), and the
        // state with it; at 5 m/s it is placed where blendtrack has it.
        for (speed, ahead, caught) in [
            (1.0, 1.0, true),
            (1.0, 4.9, true),
            (1.0, 0.0, false),
            (1.0, 5.5, false),
            (5.0, 1.0, false),
        ] {
            let (mut f, t) = fleet_on(road(None, true));
            let mut st = at(50.0, speed);
            st.y_m = 0.6;
            let a = f.add_vehicle(t, None, None, body(), st, None).unwrap() as i64;
            let sf = f.s_front(a).unwrap();
            plan_one(&mut f, a, (f64::NAN, f64::NAN), (10, sf + ahead));
            let out = f.step(&[], DT).unwrap();
            assert_eq!(out.moves, [Move::Xy]);
            let front = out.x_front_m[0];
            if caught {
                assert!(
                    (front - (sf + ahead)).abs() < 1e-4,
                    "{speed} m/s, {ahead} m: {front} vs {}",
                    sf + ahead
                );
            } else {
                assert!(
                    front < sf + speed * DT + 0.01,
                    "{speed} m/s, {ahead} m: {front}"
                );
            }
            assert!((f.s_front(a).unwrap() - front).abs() < 1e-4);
        }
    }

    #[test]
    fn a_standing_vehicle_moved_by_xy_does_not_creep_to_where_the_simulator_maps_it() {
        // Standing 1 m behind a standing leader, 0.6 m off its lane's
        // centreline (moved by (x, y)), with the simulator's front a few
        // centimetres ahead, as SUMO maps a front put on a curved junction
        // lane: the state stays where it stands, step after step (caught
        // up every step, a left turner crept over its waiting point). On a
        // road's lane (10) up to 0.3 m, on a junction lane (11, here lying
        // on the track) up to 0.75 m.
        for (lane, x, ahead) in [
            (10, 50.0, 0.03),
            (10, 50.0, 0.25),
            (11, 201.0, 0.03),
            (11, 201.0, 0.5),
        ] {
            let (path, mut route) = road(None, true);
            if lane == 11 {
                let mut pieces = route.pieces().to_vec();
                pieces[1].offset_m = 0.0;
                route = Route::new(pieces, route.stops().to_vec(), 600.0, None).unwrap();
            }
            let (mut f, t) = fleet_on((path, route));
            let mut st = at(x, 0.0);
            st.y_m = 0.6;
            let a = f.add_vehicle(t, None, None, body(), st, None).unwrap() as i64;
            let sf = f.s_front(a).unwrap();
            for _ in 0..5 {
                let now = f.s_front(a).unwrap();
                let pos = if lane == 10 { now } else { now - 200.0 };
                plan_one(&mut f, a, (1.0, 0.0), (lane, pos + ahead));
                let out = f.step(&[], DT).unwrap();
                assert_eq!(out.v_mps[0], 0.0);
                assert!(
                    matches!(out.moves[0], Move::Xy | Move::Hold),
                    "{:?}",
                    out.moves[0]
                );
            }
            let crept = f.s_front(a).unwrap() - sf;
            assert!(
                crept.abs() < 1e-9,
                "lane {lane}, {ahead} m ahead: crept {crept} m"
            );
        }
    }

    #[test]
    fn a_standing_vehicle_moved_by_xy_is_not_put_back_a_metre_behind_the_simulator() {
        // As above, but the simulator has the front 1 m ahead (a crawl it
        // ran ahead of, then a stop): the state goes on to where the
        // simulator has it once, and stays there; put back, the car landed
        // on the driver behind it (Eccles, seed 17, 342 s). On a road's lane
        // from 0.3 m: put back 0.65 m, another landed inside the minGap of
        // the driver behind (Eccles, seed 17, 397 s).
        for ahead in [1.0, 0.65, 0.31] {
            let (mut f, t) = fleet_on(road(None, true));
            let mut st = at(50.0, 0.0);
            st.y_m = 0.6;
            let a = f.add_vehicle(t, None, None, body(), st, None).unwrap() as i64;
            let sf = f.s_front(a).unwrap();
            plan_one(&mut f, a, (1.0, 0.0), (10, sf + ahead));
            let out = f.step(&[], DT).unwrap();
            assert_eq!((out.v_mps[0], out.moves[0]), (0.0, Move::Xy));
            let moved = f.s_front(a).unwrap() - sf;
            assert!((moved - ahead).abs() < 1e-6, "{ahead}: moved {moved}");
            assert!(out.x_front_m[0] >= sf + ahead - 1e-6, "{out:?}");
            for _ in 0..3 {
                let now = f.s_front(a).unwrap();
                plan_one(&mut f, a, (1.0, 0.0), (10, now));
                f.step(&[], DT).unwrap();
            }
            assert!((f.s_front(a).unwrap() - sf - ahead).abs() < 1e-6);
        }
    }

    #[test]
    fn a_crawl_the_simulator_runs_ahead_of_by_speed_moves_catches_up() {
        // On its lane's centreline: speed-only moves. The simulator has the
        // front `ahead` m further on lane 10 than blendtrack. At a crawl
        // (1 m/s) more than CATCH_UP_SPEED_MOVE_M (1 m) ahead, blendtrack's
        // state goes on to where the simulator has it (up to 5 m); less,
        // or faster, it is only slowed (it stays behind).
        for (speed, ahead, caught) in [
            (1.0, 2.0, true),
            (1.0, 4.9, true),
            (1.0, 0.9, false),
            (1.0, 5.5, false),
            (5.0, 2.0, false),
        ] {
            let (mut f, t) = fleet_on(road(None, true));
            let a = f
                .add_vehicle(t, None, None, body(), at(50.0, speed), None)
                .unwrap() as i64;
            let sf = f.s_front(a).unwrap();
            plan_one(&mut f, a, (f64::NAN, f64::NAN), (10, sf + ahead));
            let out = f.step(&[], DT).unwrap();
            assert!(
                matches!(out.moves[0], Move::Speed | Move::Hold),
                "{:?}",
                out.moves[0]
            );
            let moved = f.s_front(a).unwrap() - sf;
            if caught {
                assert!(
                    moved >= ahead - 1e-6,
                    "{speed} m/s, {ahead} m: moved {moved}"
                );
            } else {
                assert!(
                    moved < speed * DT + 0.01,
                    "{speed} m/s, {ahead} m: moved {moved}"
                );
            }
        }
    }

    #[test]
    fn a_vehicle_whose_back_the_simulator_has_on_the_lane_before_is_placed_by_xy() {
        // Lane 12 starts at arc length 210 (after junction lane 11). The
        // simulator lags 3 m behind on lane 12: no speed move makes that
        // up, the vehicle is placed. With the simulator's front 3 m into
        // lane 12 (its back, 4.5 m behind, on lane 11) it goes by (x, y),
        // which has SUMO update the lanes it laps onto; with the back on
        // lane 12 too, by lane position.
        for (x, behind_front, want) in [(212.0, 3.0, Move::Xy), (222.0, 9.0, Move::Lane)] {
            let (mut f, t) = fleet_on(road(None, true));
            let a = f
                .add_vehicle(t, None, None, body(), at(x, 10.0), None)
                .unwrap() as i64;
            let sf = f.s_front(a).unwrap();
            let on_12 = (sf - 210.0) * 1.01;
            assert!(
                on_12 - behind_front > 2.0,
                "lagging: {on_12} vs {behind_front}"
            );
            plan_one(&mut f, a, (f64::NAN, f64::NAN), (12, behind_front));
            let out = f.step(&[], DT).unwrap();
            assert_eq!(out.moves, [want], "front at {behind_front} on lane 12");
        }
    }

    #[test]
    fn a_vehicle_the_simulator_has_just_past_its_lane_end_is_not_put_back() {
        // Stopped at a red light 1 m short of the line (lane 10 ends at
        // 200 m); the simulator reports the front 0.01 m into the junction
        // lane (11): the move keeps it there (speed 0), it is not placed
        // back onto lane 10.
        let (mut f, a) = before_light(Signal::Stop, 180.0, 5.0);
        for _ in 0..300 {
            step(&mut f, &[a], false);
        }
        assert!(f.state(a).unwrap().v_mps.abs() < 1e-3);
        for (lane, pos) in [(11, 0.01), (11, 0.4)] {
            plan_one(&mut f, a, (f64::NAN, f64::NAN), (lane, pos));
            let out = f.step(&[], DT).unwrap();
            assert!(
                matches!(out.moves[0], Move::Speed | Move::Hold),
                "{:?}",
                out.moves
            );
            assert_eq!(out.sumo_speed_mps[0], 0.0);
        }
    }

    #[test]
    fn a_step_ending_on_a_short_lane_of_large_scale_is_not_sped_up_by_it() {
        // Lane 10 to 200 m, then a 0.48 m junction lane under 0.12 m of
        // track (scale 4), then lane 12. A 1 s step from a front at 192.6 m at
        // 7 m/s ends on the short lane: the front covers about 7 m of lane
        // (7 m of lane 10, 0.05 m of track = 0.2 m of the short lane), so the
        // speed sent stays within the tolerance of that, not near 4 x 7.
        let path = Path::straight(600.0, 1.0).unwrap();
        let piece = |start_m: f64, lane, scale: f64, lane_length_m: f64| Piece {
            start_m,
            lane_pos_start_m: 0.0,
            scale,
            lane_length_m,
            offset_m: 0.0,
            speed_mps: 20.0,
            lane,
            edge: lane,
            lane_index: 0,
            occurrence: 0,
        };
        let pieces = vec![
            piece(0.0, 10, 1.0, 200.0),
            piece(200.0, 11, 4.0, 0.48),
            piece(200.12, 12, 1.0, 399.88),
        ];
        let route = Route::new(pieces, vec![], 600.0, None).unwrap();
        let (mut f, t) = fleet_on((path, route));
        let a = f
            .add_vehicle(t, None, None, body(), at(192.6 - 3.5, 7.0), None)
            .unwrap() as i64;
        let sf = f.s_front(a).unwrap();
        plan_one(&mut f, a, (f64::NAN, f64::NAN), (10, sf));
        let out = f.step(&[], 1.0).unwrap();
        let sf_new = f.s_front(a).unwrap();
        assert!(
            (200.0..200.12).contains(&sf_new),
            "ends on the short lane: {sf_new}"
        );
        let lane_dist = (200.0 - sf) + (sf_new - 200.0) * 4.0;
        assert_eq!(out.moves, [Move::Speed]);
        let tol = GLIDE_TOLERANCE_MPS + GLIDE_TOLERANCE_REL * lane_dist;
        assert!(
            (out.sumo_speed_mps[0] - lane_dist).abs() <= tol + 1e-9,
            "sent {} for {lane_dist} m of lane",
            out.sumo_speed_mps[0]
        );
    }

    #[test]
    fn on_its_lane_a_vehicle_is_moved_by_its_speed_alone() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(20.0, 14.5), None)
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
            // Checked every verify_every (simulator) steps, else not asked for.
            assert_eq!(read, f.driven(a).unwrap().steps % 10 == 0, "step {k}");
            assert_eq!(f.driven(a).unwrap().steps, k as u64 + 1);
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
            .add_vehicle(t, None, None, body(), at(150.0, 10.0), None)
            .unwrap() as i64;
        let mut sim = Sim::on_road();
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
    fn a_speed_change_of_hold_speed_or_more_is_sent_below_it_held() {
        // A vehicle the simulator has standing (speed 0) on lane 10, whose
        // front is to move `dist` in a step of 1 s at an expected speed of
        // `dist` m/s: the speed-only move is dist / dt = dist, a change of
        // exactly `dist` from the simulator's 0. HOLD_SPEED_MPS is the
        // smallest change that is sent ("below this ... no speed command"):
        // 0.02 exactly is a Speed move, the next double below it a Hold.
        let (f, a) = {
            let (mut f, t) = fleet_on(road(None, true));
            let a = f
                .add_vehicle(t, None, None, body(), at(50.0, 0.0), None)
                .unwrap() as i64;
            (f, a)
        };
        let mut d = f.driven(a).unwrap().clone();
        d.sumo_speed = 0.0;
        d.known = Some((10, 53.5));
        let glide = |dist: f64| {
            let mut p = Placement {
                mv: Move::Xy,
                pos: 0.0,
                sumo_speed: f64::NAN,
                predicted: None,
            };
            let mv = glide_move(
                &d,
                (false, sim_speed(&d)),
                &mut p,
                dist,
                (dist, f64::INFINITY),
                false,
                1.0,
            );
            (mv, p.sumo_speed, p.predicted)
        };
        let (mv, speed, predicted) = glide(HOLD_SPEED_MPS);
        assert_eq!(mv, Move::Speed);
        assert_eq!(speed, HOLD_SPEED_MPS);
        assert_eq!(predicted, Some((10, 53.5 + HOLD_SPEED_MPS)));
        let below = f64::from_bits(HOLD_SPEED_MPS.to_bits() - 1);
        let (mv, speed, predicted) = glide(below);
        assert_eq!(mv, Move::Hold);
        assert_eq!(speed, 0.0, "held: the simulator keeps its speed");
        assert_eq!(predicted, Some((10, 53.5)));
    }

    #[test]
    fn a_vehicle_that_stops_leaves_the_simulator_standing_not_creeping() {
        // A red light ahead: the vehicle brakes to a stop at the line and
        // waits; the simulator, moved by the speeds sent, ends where it is.
        let (mut f, a) = before_light(Signal::Stop, 150.0, 10.0);
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
    fn pulling_away_behind_a_close_leader_the_simulator_is_not_sent_past_it() {
        // 1 s steps from a standstill at 2.6 m/s^2, a leader 1.2 m ahead
        // (beyond minGap) pulling away at 3 m/s: blendtrack's own move is
        // short of the leader's back, and the speed sent (kept near the
        // vehicle's speed at the end of the step) must not carry the
        // simulator past where the leader stood.
        let cfg = ControllerConfig {
            preferred_speed: 15.0,
            preferred_acceleration: 2.6,
            ..Default::default()
        };
        let (path, route) = road(None, true);
        let mut f = RouteFleet::new(TrafficSettings::default()).unwrap();
        let t = f.add_route(path, cfg, route).unwrap() as i64;
        let a = f
            .add_vehicle(t, None, None, body(), at(100.0, 0.0), None)
            .unwrap() as i64;
        let margin = TrafficSettings::default().standstill_margin_m;
        let gap = 1.2;
        let sf = f.s_front(a).unwrap();
        plan_one(&mut f, a, (gap, 3.0), (10, sf));
        let out = f.step(&[], 1.0).unwrap();
        let moved = f.s_front(a).unwrap() - sf;
        assert!(out.v_mps[0] > 1.0, "it pulls away: {}", out.v_mps[0]);
        assert_eq!(out.moves, [Move::Speed]);
        let room = (gap - margin).max(moved);
        assert!(
            out.sumo_speed_mps[0] * 1.0 <= room + 1e-9,
            "sent {} m/s for a step, room {room} m (blendtrack moved {moved} m)",
            out.sumo_speed_mps[0]
        );
    }

    #[test]
    fn a_simulator_ahead_is_not_carried_over_the_line_blendtrack_stops_before() {
        // A red light at the junction (200 m). Near the line the simulator
        // has the front 0.9 m ahead of blendtrack's (as after a 1 s step
        // from a standstill). Blendtrack stops before the line; the
        // simulator must too: over it, it stands inside the junction.
        let (mut f, a) = before_light(Signal::Stop, 150.0, 10.0);
        let mut sim = Sim::on_road();
        let mut read = true;
        let mut pushed = false;
        for k in 0..600 {
            read = sim_step(&mut f, a, &mut sim, read).read_position[0];
            let (_, front) = front_lane_pos(&f, a);
            if !pushed && front > 199.0 {
                sim.pos = (sim.pos + 0.9).min(199.99);
                pushed = true;
                read = true; // and blendtrack hears of it
            }
            assert_eq!(
                sim.lane, 0,
                "step {k}: the simulator took the front over the line"
            );
            assert!(front < 200.0, "step {k}: blendtrack crossed at red");
        }
        assert!(pushed, "never near");
        assert!(f.state(a).unwrap().v_mps.abs() < 1e-3, "it stopped");
        assert!(
            sim.pos > 199.0,
            "the simulator stands at the line: {}",
            sim.pos
        );
    }

    /// Drives a vehicle from a standstill on lane 10 up to a standing
    /// leader (its back at lane position 120) in steps of 1 s, the fleet
    /// told `fleet_ballistic`, the simulator moving the front by SUMO's
    /// ballistic update (the mean of its old and new speed over the step)
    /// or by its Euler update (the new speed); returns the largest distance
    /// between the simulator's front and blendtrack's after a step, the
    /// last such distance, and blendtrack's last speed.
    fn drive_to_a_standing_leader(fleet_ballistic: bool, sim_ballistic: bool) -> (f64, f64, f64) {
        let dt = 1.0;
        let (mut f, t) = fleet_on(road(None, true));
        f.set_ballistic(fleet_ballistic);
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 0.0), None)
            .unwrap() as i64;
        let (lane, mut pos) = front_lane_pos(&f, a);
        let (mut speed, mut worst, mut last, mut v) = (0.0, 0.0_f64, 0.0, 0.0);
        for _ in 0..40 {
            plan_one(&mut f, a, (120.0 - pos, 0.0), (lane as i64, pos));
            let out = f.step(&[], dt).unwrap();
            let sent = match out.moves[0] {
                Move::Speed | Move::Lane => out.sumo_speed_mps[0],
                Move::Hold => speed,
                m => panic!("{m:?}"),
            };
            if out.moves[0] == Move::Lane {
                pos = out.lane_pos_m[0];
            }
            pos += if sim_ballistic {
                0.5 * (speed + sent) * dt
            } else {
                sent * dt
            };
            speed = sent;
            v = out.v_mps[0];
            last = pos - front_lane_pos(&f, a).1;
            worst = worst.max(last.abs());
        }
        (worst, last, v)
    }

    #[test]
    fn under_the_ballistic_update_the_simulator_has_the_front_where_blendtrack_has_it() {
        // Told that SUMO moves vehicles ballistically, the fleet's speeds
        // and lane positions bring the front where blendtrack has it after
        // every step of 1 s, pulling away and stopping behind the leader.
        let (worst, last, v) = drive_to_a_standing_leader(true, true);
        assert_eq!(v, 0.0, "it stopped behind the leader");
        assert!(worst <= BALLISTIC_AHEAD_M + 1e-9, "{worst}");
        assert!(
            last.abs() <= 1e-9,
            "at rest where blendtrack has it: {last}"
        );
        // The Euler fleet in a ballistic simulator: SUMO ran ahead (a
        // metre and more, into the leader's minGap: 240 collisions with a
        // controlled vehicle at Bologna, seed 0, against 1).
        // At rest the crawl's catch-up has since put blendtrack's state
        // where SUMO has the front (`step::CATCH_UP_SPEED_MOVE_M`).
        let (worst, _, _) = drive_to_a_standing_leader(false, true);
        assert!(worst > 0.5, "{worst}");
        // The default, for SUMO's default (Euler): at rest where
        // blendtrack has it. Pulling away SUMO runs ahead (it moves at the
        // end speed less the glide tolerance, blendtrack at the step's
        // mean: 2.35 m here, a known limit, docs/sumo.md "SUMO a little
        // ahead"), within the placement check's 5 m.
        let (worst, last, v) = drive_to_a_standing_leader(false, false);
        assert_eq!(v, 0.0);
        assert!(last.abs() <= 1e-9 && worst < 5.0, "{worst} {last}");
    }
}
