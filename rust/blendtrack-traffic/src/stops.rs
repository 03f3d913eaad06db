//! Halts: a place on the track where the caller wants a vehicle to stop
//! with its front bumper (a SUMO `<stop>`: a bus stop, a parking area, a
//! lane position). The halt is a standing obstacle for the longitudinal law,
//! braked for at the planning deceleration like a red stop line, placed so
//! the front comes to rest at the halt itself: the gap handed to the law is
//! `halt - front + preferred_stop_dist` (the law keeps `preferred_stop_dist`
//! to a standing obstacle, so the front ends at the halt whatever it is).
//! The law's last creep at walking pace carries the front a little past the
//! obstacle: [`HALT_CREEP_M`] at most (0.155 to 0.207 m measured from 3 to
//! 19 m/s with control steps of 0.05 and 0.1 s); a caller that needs the
//! front at or before a position aims that much short.
//! No standstill margin: a stop is a position to reach, not a vehicle to
//! keep clear of. The caller decides when the dwell is over and clears the
//! halt; a retrack clears it too (arc lengths are the old track's).

use crate::{Driven, RouteFleet, TrafficError};
use blendtrack::ControllerConfig;

/// How far past its halt the front may come to rest (m): the stopping law's
/// last creep (see the module docs), with a margin.
pub const HALT_CREEP_M: f64 = 0.25;

impl RouteFleet {
    /// Sets the arc length (m) on the vehicle's track where its front is to
    /// stop, or clears it (NaN). Anything else not finite is an error.
    pub fn set_halt(&mut self, slot: i64, s_m: f64) -> Result<(), TrafficError> {
        self.driven(slot)?;
        if s_m.is_infinite() {
            return Err(TrafficError::Parameter {
                name: "s_m",
                value: s_m,
                message: "must be finite (NaN: no halt)",
            });
        }
        self.driven[slot as usize]
            .as_mut()
            .expect("checked above")
            .halt_m = s_m;
        Ok(())
    }

    /// The vehicle's halt (arc length, m), NaN when it has none.
    pub fn halt(&self, slot: i64) -> Result<f64, TrafficError> {
        Ok(self.driven(slot)?.halt_m)
    }
}

/// The gap the law brakes for to bring `d`'s front to rest at its halt
/// (NaN: no halt).
pub(crate) fn halt_gap(d: &Driven, cfg: &ControllerConfig) -> f64 {
    d.halt_m - d.s_front_m + cfg.preferred_stop_dist
}

/// `a` and `b` as stop gaps: the nearer, NaN meaning none.
pub(crate) fn nearer(a: f64, b: f64) -> f64 {
    if a.is_nan() {
        b
    } else if b.is_nan() {
        a
    } else {
        a.min(b)
    }
}

#[cfg(test)]
mod tests {
    use super::HALT_CREEP_M;
    use crate::testkit::*;
    use crate::*;

    /// Steps until the vehicle has stood still for a while; returns the
    /// front's arc length and the number of steps taken.
    fn run_to_rest(f: &mut RouteFleet, slot: i64, max_steps: usize) -> (f64, usize) {
        let mut still = 0;
        for k in 0..max_steps {
            step(f, &[slot], false);
            if f.state(slot).unwrap().v_mps.abs() < 1e-3 {
                still += 1;
                if still > 50 {
                    return (f.s_front(slot).unwrap(), k);
                }
            } else {
                still = 0;
            }
        }
        panic!("never came to rest");
    }

    #[test]
    fn the_front_comes_to_rest_at_the_halt_and_leaves_once_cleared() {
        // 150 m on a major road (no stop line before it): from 12 m/s the
        // front rests at the halt, no more than the law's creep past it,
        // and never further.
        for preferred_stop_dist in [0.0, 2.0] {
            let (path, route) = road(None, true);
            let mut f = RouteFleet::new(one_control_step()).unwrap();
            let cfg = ControllerConfig {
                preferred_speed: 15.0,
                preferred_stop_dist,
                ..Default::default()
            };
            let t = f.add_route(path, cfg, route).unwrap() as i64;
            let slot = f
                .add_vehicle(t, None, None, body(), at(20.0, 12.0), None)
                .unwrap() as i64;
            f.set_halt(slot, 150.0).unwrap();
            let mut fastest_decel: f64 = 0.0;
            let mut still = 0;
            let mut rest = None;
            for _ in 0..2000 {
                let (_, out) = step(&mut f, &[slot], false);
                fastest_decel = fastest_decel.min(out.accel_mps2[0]);
                assert!(f.s_front(slot).unwrap() <= 150.0 + HALT_CREEP_M);
                if out.v_mps[0].abs() < 1e-3 {
                    still += 1;
                    if still > 50 {
                        rest = Some(f.s_front(slot).unwrap());
                        break;
                    }
                }
            }
            let sf = rest.expect("came to rest");
            assert!(
                (150.0..=150.0 + HALT_CREEP_M).contains(&sf),
                "s0 = {preferred_stop_dist}: front at {sf} m, halt 150 m"
            );
            // Braked for at the planning deceleration (-3 m/s^2 by default)
            // or gentler, like a red line the vehicle can stop for.
            let b_f = f.vehicle_config(slot).unwrap().max_deceleration;
            assert!(
                fastest_decel >= b_f - 1e-9,
                "braked at {fastest_decel} m/s^2"
            );
            assert_eq!(f.halt(slot).unwrap(), 150.0);
            f.set_halt(slot, f64::NAN).unwrap();
            for _ in 0..200 {
                step(&mut f, &[slot], false);
            }
            assert!(f.s_front(slot).unwrap() > 170.0, "cleared: drives on");
        }
    }

    #[test]
    fn a_halt_behind_a_red_line_or_beyond_it_stops_where_the_nearer_is() {
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        f.set_signal(0, &[Signal::Stop]).unwrap();
        let a = f
            .add_vehicle(t, None, None, body(), at(20.0, 10.0), None)
            .unwrap() as i64;
        f.set_halt(a, 120.0).unwrap();
        let (sf, _) = run_to_rest(&mut f, a, 3000);
        assert!(
            (120.0..=120.0 + HALT_CREEP_M).contains(&sf),
            "halt first: {sf}"
        );
        f.set_halt(a, 300.0).unwrap();
        let (sf, _) = run_to_rest(&mut f, a, 3000);
        assert!(sf < 200.0, "red line first: {sf}");
    }

    #[test]
    fn a_retrack_clears_the_halt_and_bad_halts_are_errors() {
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(20.0, 10.0), None)
            .unwrap() as i64;
        assert!(f.halt(a).unwrap().is_nan(), "none at first");
        for bad in [f64::INFINITY, f64::NEG_INFINITY] {
            assert!(matches!(
                f.set_halt(a, bad),
                Err(TrafficError::Parameter { name: "s_m", .. })
            ));
        }
        assert!(f.set_halt(99, 10.0).is_err());
        f.set_halt(a, 100.0).unwrap();
        f.retrack(a, t).unwrap();
        assert!(f.halt(a).unwrap().is_nan());
    }

    #[test]
    fn a_halt_just_ahead_at_speed_is_braked_for_not_jumped() {
        // Too close to stop at the planning deceleration (12 m/s needs 24 m
        // at 3 m/s^2, it has 20): the law brakes harder, as for a red line
        // it has to stop at, and the front still rests at the halt.
        let (mut f, t) = fleet_on(road(None, true));
        let a = f
            .add_vehicle(t, None, None, body(), at(100.0, 12.0), None)
            .unwrap() as i64;
        f.set_halt(a, 100.0 + 3.5 + 20.0).unwrap();
        let (sf, _) = run_to_rest(&mut f, a, 3000);
        assert!((123.5..=123.5 + HALT_CREEP_M).contains(&sf), "front {sf}");
    }
}
