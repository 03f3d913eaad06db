//! Fixtures shared by the crate's unit tests: a straight road with a
//! junction, a vehicle body, and a stand-in for the simulator's movement.

use crate::*;
use blendtrack::{ControllerConfig, Path, VehicleState};

pub(crate) const DT: f64 = 0.1;

/// A 600 m straight road: lane 10 (plain) up to a junction at 200 m,
/// junction lane 11 (not plain) to 210 m, then lane 12 (plain, scale 1.01).
pub(crate) fn road(signal: Option<(usize, usize)>, major: bool) -> (Path, Route) {
    let path = Path::straight(600.0, 1.0).unwrap();
    let piece =
        |start_m: f64, plain: bool, lane, edge, scale: f64, lane_length_m, occurrence| Piece {
            start_m,
            lane_pos_start_m: 0.0,
            scale,
            lane_length_m,
            offset_m: if plain { 0.0 } else { f64::INFINITY },
            speed_mps: 20.0,
            lane,
            edge,
            lane_index: 0,
            occurrence,
        };
    let route = Route::new(
        vec![
            piece(0.0, true, 10, 1, 1.0, 200.0, 0),
            piece(200.0, false, 11, 2, 1.0, 10.0, 0),
            piece(210.0, true, 12, 3, 1.01, 390.0 * 1.01, 1),
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

pub(crate) fn body() -> Body {
    Body {
        reach_m: 3.5,
        length_m: 4.5,
        min_gap_m: 2.5,
    }
}

pub(crate) fn at(x: f64, v: f64) -> VehicleState {
    VehicleState {
        x_m: x,
        y_m: 0.0,
        theta_rad: 0.0,
        v_mps: v,
        delta_rad: 0.0,
    }
}

pub(crate) fn fleet_on(route: (Path, Route)) -> (RouteFleet, i64) {
    fleet_with(route, TrafficSettings::default())
}

/// One vehicle at `x` (rear axle) and `v` on `road(Some((0, 0)), false)`,
/// the light's one link showing `signal`.
pub(crate) fn before_light(signal: Signal, x: f64, v: f64) -> (RouteFleet, i64) {
    let (mut f, t) = fleet_on(road(Some((0, 0)), false));
    f.set_signal(0, &[signal]).unwrap();
    let a = f
        .add_vehicle(t, None, None, body(), at(x, v), None)
        .unwrap() as i64;
    (f, a)
}

/// Settings with one control step per step of `DT`.
pub(crate) fn one_control_step() -> TrafficSettings {
    TrafficSettings {
        control_dt_s: DT,
        ..Default::default()
    }
}

pub(crate) fn fleet_with(route: (Path, Route), settings: TrafficSettings) -> (RouteFleet, i64) {
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
pub(crate) fn step(
    f: &mut RouteFleet,
    slots: &[i64],
    yield_to: bool,
) -> (Vec<usize>, RouteOutputs) {
    let n = slots.len();
    let nan = vec![f64::NAN; n];
    let q = f
        .plan(&Observations {
            slots,
            leader_gap_m: &nan,
            leader_slot: &vec![-1; n],
            leader_speed_mps: &nan,
            leader_room_m: None,
            lane: &vec![-1; n],
            lane_pos_m: &nan,
            soft: None,
        })
        .unwrap();
    let out = f.step(&vec![yield_to; q.len()], DT).unwrap();
    (q, out)
}

/// A stand-in for the simulator's own movement: it keeps each vehicle's
/// (lane, position, speed), applies the moves, then moves it `speed x dt`
/// along `lanes` (id, length) in order, as SUMO does with speed mode 0.
pub(crate) struct Sim {
    pub(crate) lanes: Vec<(u32, f64)>,
    pub(crate) lane: usize,
    pub(crate) pos: f64,
    pub(crate) speed: f64,
}

impl Sim {
    /// The simulator's view of the whole road (lanes 10, 11, 12), nothing known yet.
    pub(crate) fn on_road() -> Sim {
        Sim {
            lanes: vec![(10, 200.0), (11, 10.0), (12, 390.0 * 1.01)],
            lane: 0,
            pos: 0.0,
            speed: 0.0,
        }
    }

    /// The simulator's view of the road's first lane (10, 200 m), nothing known yet.
    pub(crate) fn on_lane_10() -> Sim {
        Sim {
            lanes: vec![(10, 200.0)],
            lane: 0,
            pos: 0.0,
            speed: 0.0,
        }
    }

    pub(crate) fn apply(&mut self, out: &RouteOutputs, i: usize) {
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
    pub(crate) fn obs(&self) -> (i64, f64) {
        (self.lanes[self.lane].0 as i64, self.pos)
    }
}

/// Plans vehicle `slot` alone, behind a leader at `leader` (gap m, speed
/// m/s; a NaN gap: none), the simulator having its front at `at` (lane,
/// position; lane < 0: not read); returns the yield questions.
pub(crate) fn plan_one(
    f: &mut RouteFleet,
    slot: i64,
    leader: (f64, f64),
    at: (i64, f64),
) -> Vec<usize> {
    plan_one_with_room(f, slot, leader, f64::NAN, at)
}

/// [`plan_one`] with the simulator's own gap to the leader, `room` (m), where
/// the leader's gap is shortened for the stopping law (NaN: not shortened).
pub(crate) fn plan_one_with_room(
    f: &mut RouteFleet,
    slot: i64,
    leader: (f64, f64),
    room: f64,
    at: (i64, f64),
) -> Vec<usize> {
    f.plan(&Observations {
        slots: &[slot],
        leader_gap_m: &[leader.0],
        leader_slot: &[-1],
        leader_speed_mps: &[leader.1],
        leader_room_m: Some(&[room]),
        lane: &[at.0],
        lane_pos_m: &[at.1],
        soft: None,
    })
    .unwrap()
}

/// One plan + step for one vehicle that reports the simulator's lane
/// position when asked to; returns the outputs.
pub(crate) fn sim_step(f: &mut RouteFleet, slot: i64, sim: &mut Sim, report: bool) -> RouteOutputs {
    let at = if report { sim.obs() } else { (-1, f64::NAN) };
    plan_one(f, slot, (f64::NAN, f64::NAN), at);
    let out = f.step(&[], DT).unwrap();
    sim.apply(&out, 0);
    out
}

/// One vehicle at `x` (rear axle) and `v` on `road(None, true)`, five
/// steps into a simulator that reports every step: its place is known.
pub(crate) fn settled_on_lane_10(x: f64, v: f64) -> (RouteFleet, i64, Sim) {
    let (mut f, t) = fleet_on(road(None, true));
    let a = f
        .add_vehicle(t, None, None, body(), at(x, v), None)
        .unwrap() as i64;
    let mut sim = Sim::on_lane_10();
    for _ in 0..5 {
        sim_step(&mut f, a, &mut sim, true);
    }
    (f, a, sim)
}

/// Where the front must be on `lane`, from its arc length on `road(..)`.
pub(crate) fn front_lane_pos(f: &RouteFleet, slot: i64) -> (u32, f64) {
    let sf = f.s_front(slot).unwrap();
    let d = f.driven(slot).unwrap();
    let p = d.route.pieces[d.route.piece_at(sf)];
    (p.lane, p.lane_pos_at(sf))
}

/// A circle of radius `LAP_RADIUS_M` driven three times (an open path of
/// three laps, one lane piece per lap: lane 20 on edge 5, occurrences 0, 1
/// and 2): every place on it is on the track three times.
pub(crate) const LAP_RADIUS_M: f64 = 50.0;
pub(crate) fn laps() -> (Path, Route) {
    let n = 400;
    let pts: Vec<[f64; 2]> = (0..=3 * n)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            [LAP_RADIUS_M * a.cos(), LAP_RADIUS_M * a.sin()]
        })
        .collect();
    let path = Path::new(&pts, None, false).unwrap();
    let lap = path.length() / 3.0;
    let pieces = (0..3)
        .map(|k| Piece {
            start_m: k as f64 * lap,
            lane_pos_start_m: 0.0,
            scale: 1.0,
            lane_length_m: lap,
            offset_m: 0.0,
            speed_mps: 15.0,
            lane: 20,
            edge: 5,
            lane_index: 0,
            occurrence: k,
        })
        .collect();
    let route = Route::new(pieces, vec![], path.length(), None).unwrap();
    (path, route)
}

/// A vehicle's rear axle on the circle of [`laps`] at angle `a` (rad),
/// driving counter-clockwise at `v`.
pub(crate) fn on_circle(a: f64, v: f64) -> VehicleState {
    VehicleState {
        x_m: LAP_RADIUS_M * a.cos(),
        y_m: LAP_RADIUS_M * a.sin(),
        theta_rad: a + std::f64::consts::FRAC_PI_2,
        v_mps: v,
        delta_rad: 0.0,
    }
}
