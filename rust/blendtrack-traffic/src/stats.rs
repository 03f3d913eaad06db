//! Per-vehicle statistics of a driven vehicle ([`DriveStats`]): the core's
//! [`TrackingStats`] accumulator plus the road's counts (speed limit,
//! reversing, red lights), one step at a time.

use crate::TrafficSettings;
use blendtrack::{StatValue, TrackingSample, TrackingStats};

/// A driven vehicle's statistics since it was added: the core's tracking
/// accumulator and the counts of the road's rules.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveStats {
    pub tracking: TrackingStats,
    /// Steps faster than the lane's limit, and steps driving backwards.
    pub speed_warnings: u64,
    pub reverse_warnings: u64,
    /// Stop lines crossed at red.
    pub red_light_violations: u64,
}

/// One step of a driven vehicle, as its statistics take it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StepRecord {
    pub lateral_error_m: f64,
    pub lateral_error_rear_m: f64,
    pub lateral_error_front_m: f64,
    pub heading_error_rad: f64,
    pub v_mps: f64,
    pub accel_mps2: f64,
    pub lateral_accel_mps2: f64,
    pub curvature_per_m: f64,
    pub speed_limit_mps: f64,
    pub dt_s: f64,
}

impl DriveStats {
    /// Adds one step; returns the `(|curvature|, |v|, |e|, |lateral
    /// acceleration|)` sample when one is due (every `sample_every` steps).
    pub(crate) fn add_step(&mut self, r: &StepRecord, st: &TrafficSettings) -> Option<[f64; 4]> {
        let (v, lat_acc) = (r.v_mps, r.lateral_accel_mps2);
        let t = &mut self.tracking;
        t.add(&TrackingSample {
            lateral_error_m: r.lateral_error_m,
            heading_error_rad: r.heading_error_rad,
            v_mps: v,
            lateral_accel_mps2: lat_acc,
        });
        t.add_axles(r.lateral_error_rear_m, r.lateral_error_front_m);
        t.add_motion(
            v,
            r.accel_mps2,
            lat_acc,
            st.comfort_lateral_accel_mps2,
            r.dt_s,
        );
        if v.abs() > r.speed_limit_mps * 1.0001 {
            self.speed_warnings += 1;
        }
        if v < 0.0 {
            self.reverse_warnings += 1;
        }
        (t.steps % st.sample_every == 0).then(|| {
            [
                r.curvature_per_m.abs(),
                v.abs(),
                r.lateral_error_m.abs(),
                lat_acc.abs(),
            ]
        })
    }

    /// Every value under a stable name: the tracking accumulator's raw and
    /// finished values ([`TrackingStats::entries`]), then the counts.
    pub fn entries(&self) -> Vec<(&'static str, StatValue)> {
        let mut e = self.tracking.entries();
        e.extend([
            ("speed_warnings", StatValue::Count(self.speed_warnings)),
            ("reverse_warnings", StatValue::Count(self.reverse_warnings)),
            (
                "red_light_violations",
                StatValue::Count(self.red_light_violations),
            ),
        ]);
        e
    }
}

#[cfg(test)]
mod tests {
    use crate::testkit::*;
    use crate::*;
    use blendtrack::StatValue;

    #[test]
    fn a_light_turning_red_too_late_to_stop_is_counted_as_a_crossing() {
        let (mut f, t) = fleet_on(road(Some((0, 0)), false));
        // Front 1.5 m before the line at 15 m/s: no law can stop that.
        let slot = f
            .add_vehicle(t, None, None, body(), at(200.0 - 3.5 - 1.5, 15.0), None)
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
    fn statistics_add_up_the_outputs() {
        // One control step per step (each sub-step would count).
        let (mut f, t) = fleet_with(road(None, true), one_control_step());
        let mut s0 = at(50.0, 10.0);
        s0.y_m = 0.7;
        let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        let (mut sum_e, mut sum_e2, mut max_lat, mut dist) = (0.0, 0.0, 0.0_f64, 0.0);
        for _ in 0..50 {
            let out = step(&mut f, &[a], false).1;
            sum_e += out.lateral_error_m[0].abs();
            sum_e2 += out.lateral_error_m[0].powi(2);
            let v = out.v_mps[0];
            max_lat = max_lat.max((v * v * out.delta_rad[0].tan() / 2.6).abs());
            dist += v.abs() * DT;
        }
        let all = f.remove_vehicle(a).unwrap();
        let s = all.tracking;
        assert_eq!(s.steps, 50);
        // Finished values, from the outputs by hand.
        assert!((s.lateral_error_rms_m() - (sum_e2 / 50.0).sqrt()).abs() < 1e-12);
        assert!((s.lateral_error_mean_abs_m() - sum_e / 50.0).abs() < 1e-12);
        let entries = all.entries();
        assert!(entries.contains(&("red_light_violations", StatValue::Count(0))));
        assert!(entries.contains(&("steps", StatValue::Count(50))));
        assert!((s.sum_abs_e - sum_e).abs() < 1e-9 && s.sum_abs_e > 1.0);
        assert!((s.max_lat_acc - max_lat).abs() < 1e-9 && max_lat > 0.0);
        assert!((s.distance_m - dist).abs() < 1e-9);
        assert_eq!(s.jerk_n, 49);
        assert_eq!(f.take_samples().len(), 5);
        assert!(f.is_empty());
    }

    #[test]
    fn acceleration_and_jerk_are_the_differences_of_the_speeds() {
        // One control step of DT per step, from 10 m/s towards the preferred
        // 15 m/s: each step's acceleration is (v_k - v_{k-1}) / DT from the
        // speeds the outputs report, the jerk the difference of two
        // accelerations over DT; the statistics hold the last acceleration
        // and the sum of squared jerks over the 29 steps after the first.
        let (mut f, t) = fleet_with(road(None, true), one_control_step());
        let a = f
            .add_vehicle(t, None, None, body(), at(50.0, 10.0), None)
            .unwrap() as i64;
        let mut v0 = 10.0;
        let mut acc = Vec::new();
        for _ in 0..30 {
            let v = step(&mut f, &[a], false).1.v_mps[0];
            acc.push((v - v0) / DT);
            v0 = v;
        }
        let jerk2: f64 = acc.windows(2).map(|w| ((w[1] - w[0]) / DT).powi(2)).sum();
        let s = f.stats(a).unwrap().tracking;
        assert!(acc[0] > 0.1, "accelerating: {}", acc[0]);
        assert!(
            (s.last_acc - acc[29]).abs() < 1e-9,
            "{} vs {}",
            s.last_acc,
            acc[29]
        );
        assert_eq!(s.jerk_n, 29);
        assert!(
            (s.sum_jerk2 - jerk2).abs() <= 1e-9 * jerk2.max(1.0),
            "{} vs {jerk2}",
            s.sum_jerk2
        );
    }

    #[test]
    fn axle_errors_are_those_of_the_fixed_points() {
        // On the centreline, yawed by 0.1 rad: the rear axle is on the path,
        // the front axle (wheelbase 2.6 m ahead) 2.6 sin(0.1) m to the left,
        // the control point P(0.5) half of that.
        let (mut f, t) = fleet_with(road(None, true), one_control_step());
        let mut s0 = at(50.0, 10.0);
        s0.theta_rad = 0.1;
        let a = f.add_vehicle(t, None, None, body(), s0, None).unwrap() as i64;
        step(&mut f, &[a], false);
        let s = f.remove_vehicle(a).unwrap().tracking;
        let front = 2.6 * 0.1_f64.sin();
        assert!(s.sum_abs_e_rear < 1e-9, "{}", s.sum_abs_e_rear);
        assert!(
            (s.sum_abs_e_front - front).abs() < 1e-9,
            "{}",
            s.sum_abs_e_front
        );
        assert!((s.sum_abs_e - 0.5 * front).abs() < 1e-9, "{}", s.sum_abs_e);
    }
}
