//! Running statistics of a tracked drive: sums and maxima accumulated one
//! step at a time ([`TrackingStats`]), and the finished values (means, RMS)
//! computed from them.
//!
//! One accumulator serves every place that sums a drive up: the window
//! metrics of a closed-loop run ([`crate::metrics`]) add the tracking part of
//! each sample ([`TrackingStats::add`]); a vehicle driven step by step among
//! other traffic also adds its axle errors ([`TrackingStats::add_axles`]) and
//! its motion over time ([`TrackingStats::add_motion`]: distance, time above
//! a comfort bound of lateral acceleration, longitudinal jerk).
//! [`TrackingStats::entries`] lists every raw and finished value under a
//! stable name, so a binding can hand them on without naming each.

/// One step's tracking sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackingSample {
    /// Signed lateral error of the control point (m).
    pub lateral_error_m: f64,
    /// Heading error (rad).
    pub heading_error_rad: f64,
    /// Signed speed (m/s).
    pub v_mps: f64,
    /// Kinematic lateral acceleration `v^2 tan(delta) / E` (m/s^2, signed).
    pub lateral_accel_mps2: f64,
}

/// Sums and maxima of a drive since it started (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingStats {
    /// Samples added ([`TrackingStats::add`]).
    pub steps: u64,
    pub sum_abs_e: f64,
    pub sum_e2: f64,
    pub max_abs_e: f64,
    /// Sums of |lateral error| at the rear and at the front axle: the same
    /// points for every alpha (`sum_abs_e` is of the control point P(alpha)).
    pub sum_abs_e_rear: f64,
    pub sum_abs_e_front: f64,
    pub sum_eth2: f64,
    /// Sum of |v| (m/s).
    pub sum_v: f64,
    /// Distance driven, sum of |v| dt (m).
    pub distance_m: f64,
    /// Largest |lateral acceleration| (m/s^2).
    pub max_lat_acc: f64,
    /// Time with |lateral acceleration| above the comfort bound (s).
    pub time_above_comfort_s: f64,
    /// Sum of squared longitudinal jerk, over `jerk_n` steps.
    pub sum_jerk2: f64,
    pub jerk_n: u64,
    /// Last step's acceleration (NaN before the first step).
    pub last_acc: f64,
}

impl Default for TrackingStats {
    fn default() -> Self {
        TrackingStats {
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
        }
    }
}

/// A value of [`TrackingStats::entries`]: a count or a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StatValue {
    Count(u64),
    Value(f64),
}

impl TrackingStats {
    /// Adds one step's tracking sample.
    pub fn add(&mut self, s: &TrackingSample) {
        let ae = s.lateral_error_m.abs();
        self.steps += 1;
        self.sum_abs_e += ae;
        self.sum_e2 += ae * ae;
        self.max_abs_e = self.max_abs_e.max(ae);
        self.sum_eth2 += s.heading_error_rad * s.heading_error_rad;
        self.sum_v += s.v_mps.abs();
        self.max_lat_acc = self.max_lat_acc.max(s.lateral_accel_mps2.abs());
    }

    /// Adds one step's lateral errors at the rear and the front axle (m).
    pub fn add_axles(&mut self, rear_m: f64, front_m: f64) {
        self.sum_abs_e_rear += rear_m.abs();
        self.sum_abs_e_front += front_m.abs();
    }

    /// Adds one step of `dt_s` at speed `v_mps` with acceleration
    /// `accel_mps2` and lateral acceleration `lateral_accel_mps2`: the
    /// distance, the time above `comfort_mps2`, and the jerk from the last
    /// step's acceleration (none for the first step).
    pub fn add_motion(
        &mut self,
        v_mps: f64,
        accel_mps2: f64,
        lateral_accel_mps2: f64,
        comfort_mps2: f64,
        dt_s: f64,
    ) {
        self.distance_m += v_mps.abs() * dt_s;
        if lateral_accel_mps2.abs() > comfort_mps2 {
            self.time_above_comfort_s += dt_s;
        }
        if self.last_acc.is_finite() {
            let jerk = (accel_mps2 - self.last_acc) / dt_s;
            self.sum_jerk2 += jerk * jerk;
            self.jerk_n += 1;
        }
        self.last_acc = accel_mps2;
    }

    /// `sum / steps`, NaN before the first step.
    fn per_step(&self, sum: f64) -> f64 {
        if self.steps == 0 {
            f64::NAN
        } else {
            sum / self.steps as f64
        }
    }

    /// Mean |lateral error| of the control point (m; NaN without steps).
    pub fn lateral_error_mean_abs_m(&self) -> f64 {
        self.per_step(self.sum_abs_e)
    }
    /// RMS lateral error of the control point (m; NaN without steps).
    pub fn lateral_error_rms_m(&self) -> f64 {
        self.per_step(self.sum_e2).sqrt()
    }
    /// RMS heading error (deg; NaN without steps).
    pub fn heading_error_rms_deg(&self) -> f64 {
        self.per_step(self.sum_eth2).sqrt().to_degrees()
    }
    /// Mean |v| (m/s; NaN without steps).
    pub fn mean_speed_mps(&self) -> f64 {
        self.per_step(self.sum_v)
    }
    /// Mean |lateral error| at the rear axle (m; NaN without steps).
    pub fn lateral_error_rear_axle_mean_abs_m(&self) -> f64 {
        self.per_step(self.sum_abs_e_rear)
    }
    /// Mean |lateral error| at the front axle (m; NaN without steps).
    pub fn lateral_error_front_axle_mean_abs_m(&self) -> f64 {
        self.per_step(self.sum_abs_e_front)
    }
    /// RMS longitudinal jerk (m/s^3; NaN before two steps of motion).
    pub fn long_jerk_rms_mps3(&self) -> f64 {
        if self.jerk_n == 0 {
            f64::NAN
        } else {
            (self.sum_jerk2 / self.jerk_n as f64).sqrt()
        }
    }

    /// Every raw value (under its field's name) and every finished value
    /// (under its method's name).
    pub fn entries(&self) -> Vec<(&'static str, StatValue)> {
        use StatValue::{Count, Value};
        vec![
            ("steps", Count(self.steps)),
            ("sum_abs_e", Value(self.sum_abs_e)),
            ("sum_e2", Value(self.sum_e2)),
            ("max_abs_e", Value(self.max_abs_e)),
            ("sum_abs_e_rear", Value(self.sum_abs_e_rear)),
            ("sum_abs_e_front", Value(self.sum_abs_e_front)),
            ("sum_eth2", Value(self.sum_eth2)),
            ("sum_v", Value(self.sum_v)),
            ("distance_m", Value(self.distance_m)),
            ("max_lat_acc", Value(self.max_lat_acc)),
            ("time_above_comfort_s", Value(self.time_above_comfort_s)),
            ("sum_jerk2", Value(self.sum_jerk2)),
            ("jerk_n", Count(self.jerk_n)),
            ("last_acc", Value(self.last_acc)),
            (
                "lateral_error_mean_abs_m",
                Value(self.lateral_error_mean_abs_m()),
            ),
            ("lateral_error_rms_m", Value(self.lateral_error_rms_m())),
            ("heading_error_rms_deg", Value(self.heading_error_rms_deg())),
            ("mean_speed_mps", Value(self.mean_speed_mps())),
            (
                "lateral_error_rear_axle_mean_abs_m",
                Value(self.lateral_error_rear_axle_mean_abs_m()),
            ),
            (
                "lateral_error_front_axle_mean_abs_m",
                Value(self.lateral_error_front_axle_mean_abs_m()),
            ),
            ("long_jerk_rms_mps3", Value(self.long_jerk_rms_mps3())),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(e: f64, h: f64, v: f64, lat: f64) -> TrackingSample {
        TrackingSample {
            lateral_error_m: e,
            heading_error_rad: h,
            v_mps: v,
            lateral_accel_mps2: lat,
        }
    }

    #[test]
    fn finished_values_are_those_of_the_samples_by_hand() {
        let mut s = TrackingStats::default();
        assert!(s.lateral_error_rms_m().is_nan() && s.long_jerk_rms_mps3().is_nan());
        // e = 0.3, -0.4; heading 0.1, 0.1 rad; v = 2, -4; lat 1, -3.
        s.add(&sample(0.3, 0.1, 2.0, 1.0));
        s.add(&sample(-0.4, 0.1, -4.0, -3.0));
        assert_eq!(s.steps, 2);
        assert!((s.lateral_error_mean_abs_m() - 0.35).abs() < 1e-12);
        assert!((s.lateral_error_rms_m() - (0.125f64).sqrt()).abs() < 1e-12);
        assert_eq!(s.max_abs_e, 0.4);
        assert!((s.heading_error_rms_deg() - 0.1f64.to_degrees()).abs() < 1e-9);
        assert!((s.mean_speed_mps() - 3.0).abs() < 1e-12);
        assert_eq!(s.max_lat_acc, 3.0);
        s.add_axles(-0.2, 0.6);
        s.add_axles(0.4, 0.0);
        assert!((s.lateral_error_rear_axle_mean_abs_m() - 0.3).abs() < 1e-12);
        assert!((s.lateral_error_front_axle_mean_abs_m() - 0.3).abs() < 1e-12);
    }

    #[test]
    fn motion_adds_distance_comfort_time_and_jerk_from_the_second_step() {
        let mut s = TrackingStats::default();
        // Accelerations 1, 3, 0 m/s^2 over 0.5 s steps: jerks 4 and -6 m/s^3.
        s.add_motion(2.0, 1.0, 0.5, 2.0, 0.5);
        assert_eq!(s.jerk_n, 0, "no jerk from the first step");
        s.add_motion(-4.0, 3.0, -2.5, 2.0, 0.5);
        s.add_motion(1.0, 0.0, 2.0, 2.0, 0.5);
        assert!((s.distance_m - 3.5).abs() < 1e-12);
        assert_eq!(s.time_above_comfort_s, 0.5, "only |-2.5| > 2 counts");
        assert_eq!(s.jerk_n, 2);
        assert!((s.long_jerk_rms_mps3() - 26.0f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.last_acc, 0.0);
    }

    #[test]
    fn entries_name_every_field_once() {
        let mut s = TrackingStats::default();
        s.add(&sample(0.5, 0.0, 1.0, 0.0));
        let e = s.entries();
        let mut names: Vec<_> = e.iter().map(|(k, _)| *k).collect();
        assert_eq!(e[0], ("steps", StatValue::Count(1)));
        assert!(e.contains(&("lateral_error_rms_m", StatValue::Value(0.5))));
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), e.len());
    }
}
