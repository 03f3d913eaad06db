//! Per-vehicle statistics of a driven vehicle ([`DriveStats`]).

use crate::TrafficSettings;

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
        let (v, dt_s, lat_acc) = (r.v_mps, r.dt_s, r.lateral_accel_mps2);
        let ae = r.lateral_error_m.abs();
        self.steps += 1;
        self.sum_abs_e += ae;
        self.sum_e2 += ae * ae;
        self.max_abs_e = self.max_abs_e.max(ae);
        self.sum_abs_e_rear += r.lateral_error_rear_m.abs();
        self.sum_abs_e_front += r.lateral_error_front_m.abs();
        self.sum_eth2 += r.heading_error_rad * r.heading_error_rad;
        self.sum_v += v.abs();
        self.distance_m += v.abs() * dt_s;
        self.max_lat_acc = self.max_lat_acc.max(lat_acc.abs());
        if lat_acc.abs() > st.comfort_lateral_accel_mps2 {
            self.time_above_comfort_s += dt_s;
        }
        if self.last_acc.is_finite() {
            let jerk = (r.accel_mps2 - self.last_acc) / dt_s;
            self.sum_jerk2 += jerk * jerk;
            self.jerk_n += 1;
        }
        self.last_acc = r.accel_mps2;
        if v.abs() > r.speed_limit_mps * 1.0001 {
            self.speed_warnings += 1;
        }
        if v < 0.0 {
            self.reverse_warnings += 1;
        }
        (self.steps % st.sample_every == 0)
            .then(|| [r.curvature_per_m.abs(), v.abs(), ae, lat_acc.abs()])
    }
}

#[cfg(test)]
mod tests {
    use crate::testkit::*;
    use crate::*;

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
}
