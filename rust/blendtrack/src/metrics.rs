//! Tracking metrics of a run: how far, how straight and how smoothly the
//! control point followed the path, over the whole run and after settling.
//!
//! Computed from a [`Trace`] (or any column-wise series with the same
//! meaning) and the wheelbase. Definitions, with `e` the signed lateral
//! error of the control point, `e_theta` its heading error, `delta` the
//! applied steering angle and `v` the signed speed, one sample per step:
//!
//! - The sums and maxima are a [`TrackingStats`] over the window.
//! - `lateral_error_mean_abs_m` = mean |e|, `lateral_error_rms_m` =
//!   sqrt(mean e^2), `lateral_error_max_abs_m` = max |e|.
//! - `heading_error_rms_deg` = sqrt(mean e_theta^2), in degrees.
//! - Steering rate: backward differences `(delta_i - delta_{i-1}) / (t_i -
//!   t_{i-1})` between consecutive samples of the window (a window of one
//!   sample has no rate: 0). `steering_rate_rms_deg_s`, `steering_rate_max_deg_s`
//!   (max of the magnitude), in deg/s.
//! - `lateral_accel_max_mps2` = max |v^2 tan(delta) / E| (kinematic bicycle,
//!   yaw rate times speed).
//! - `mean_speed_mps` = mean |v|; `distance_m` = the distance driven within
//!   the window, from the trace's cumulative `distance_m` column (the
//!   difference between the window's last value and the value just before
//!   the window, 0 before the first sample).
//! - Settling: the run has settled at sample `k`, the first sample from which
//!   |e| stays below [`SETTLING_THRESHOLD_M`] (0.1 m) up to and including the
//!   last sample ("settled for good": a later excursion above the threshold
//!   moves `k` after it). `settling_time_s` = `t_k - t_0 + (t_1 - t_0)`, the
//!   time since the start of the run, taking the first sample as one step
//!   after the start (as [`crate::sim::simulate`] records them): a run that
//!   starts on the path settles at time `t_0` = one step. A run whose last
//!   sample is still at or above the threshold never settles:
//!   `settling_time_s` is `None` (NaN in Python, `null` in JSON) and so are
//!   the after-settling metrics.
//! - `initial_overshoot_m`: the overshoot of the initial approach. With
//!   `side = sign(e_0)`, the first crossing is the first sample `c` on the
//!   other side (`side e_c < 0`); the overshoot is the peak
//!   `max(-side e_i)` over the samples from `c` up to (not including) the next
//!   sample back on the starting side. 0 if `e_0 = 0` (no side to overshoot
//!   from) or the error never crosses. Later excursions (a corner cut a lap
//!   later) do not count: `opposite_side_max_m` is the largest excursion to
//!   the opposite side anywhere in the run, `max(0, max_i(-side e_i))`.
//! - Per axle (when the series carries the true front and rear axle errors,
//!   the same two points whatever alpha is, so runs with different alphas
//!   compare there; NaN otherwise):
//!   `lateral_error_front_axle_mean_abs_m` = mean |e_front|,
//!   `lateral_error_rear_axle_mean_abs_m` = mean |e_rear|,
//!   `body_error_mean_m` = mean over the run of `max(|e_front|, |e_rear|)`
//!   (for a rigid body on a kinematic bicycle, the larger of the two axles'
//!   errors bounds how far the wheelbase strays from the path: every point
//!   between the axles is within it when the path is nearly straight
//!   there), `body_error_max_m` its maximum.
//! - Reaching: the first sample `r` with |e| below the threshold, even if the
//!   error leaves it again later (`reached_time_s`, same time convention).
//!   [`RunMetrics::reached`] = the window metrics over samples `r..n`: a
//!   reading of the paper's "after initialization" (its figures split each
//!   test into "when reaching" and "after reaching the target trajectory")
//!   that stays defined for a controller whose error keeps brushing past
//!   0.1 m in curves, where "settled for good" never happens. It is not one
//!   of the `metrics.json` keys; [`RunMetrics::to_named_extra`] lists it.
//! - "After settling" ([`RunMetrics::settled`]) = the same window metrics over
//!   samples `k..n`: the quantity the paper's Table 2 reports as "average
//!   distance after initialization" is `settled.lateral_error_mean_abs_m`.
//!   A lap with corners keeps brushing past 0.1 m, so "settled for good" can
//!   come late (the last seconds of a lap); the report reads "after reaching".

use crate::sim::Trace;
use crate::stats::{TrackingSample, TrackingStats};

/// |e| below this (m), for good, means settled.
pub const SETTLING_THRESHOLD_M: f64 = 0.1;

/// Metrics of one window (a contiguous range of samples).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WindowMetrics {
    pub lateral_error_mean_abs_m: f64,
    pub lateral_error_rms_m: f64,
    pub lateral_error_max_abs_m: f64,
    pub heading_error_rms_deg: f64,
    pub steering_rate_rms_deg_s: f64,
    pub steering_rate_max_deg_s: f64,
    pub lateral_accel_max_mps2: f64,
    pub mean_speed_mps: f64,
    pub distance_m: f64,
    /// Number of samples in the window.
    pub samples: usize,
}

/// Metrics of a whole run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunMetrics {
    pub whole: WindowMetrics,
    /// Time from the start at which the run settled for good (`None`: never).
    pub settling_time_s: Option<f64>,
    /// Index of the first settled sample (`None`: never settled).
    pub settled_index: Option<usize>,
    /// Overshoot of the initial approach (see the module docs).
    pub initial_overshoot_m: f64,
    /// Largest excursion to the side opposite the start, anywhere in the run.
    pub opposite_side_max_m: f64,
    /// Per-axle and body errors over the whole run (NaN without axle columns).
    pub axles: AxleMetrics,
    /// The window after settling (`None`: never settled).
    pub settled: Option<WindowMetrics>,
    /// Time from the start at which |e| first fell below the threshold.
    pub reached_time_s: Option<f64>,
    /// The window from that first time on.
    pub reached: Option<WindowMetrics>,
}

/// Errors of the true front and rear axles over a run (NaN when the series
/// has no axle columns).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxleMetrics {
    pub lateral_error_front_axle_mean_abs_m: f64,
    pub lateral_error_rear_axle_mean_abs_m: f64,
    /// Mean of `max(|e_front|, |e_rear|)`.
    pub body_error_mean_m: f64,
    /// Max of `max(|e_front|, |e_rear|)`.
    pub body_error_max_m: f64,
}

impl Default for AxleMetrics {
    fn default() -> Self {
        AxleMetrics {
            lateral_error_front_axle_mean_abs_m: f64::NAN,
            lateral_error_rear_axle_mean_abs_m: f64::NAN,
            body_error_mean_m: f64::NAN,
            body_error_max_m: f64::NAN,
        }
    }
}

/// The columns the metrics read, borrowed from a trace or built by hand.
/// `lateral_error_front_m` and `lateral_error_rear_m` may be empty (not
/// recorded): the axle metrics are then NaN.
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    pub t_s: &'a [f64],
    pub lateral_error_m: &'a [f64],
    pub lateral_error_front_m: &'a [f64],
    pub lateral_error_rear_m: &'a [f64],
    pub heading_error_rad: &'a [f64],
    pub delta_rad: &'a [f64],
    pub v_mps: &'a [f64],
    pub distance_m: &'a [f64],
}

impl<'a> From<&'a Trace> for Series<'a> {
    fn from(t: &'a Trace) -> Self {
        Series {
            t_s: &t.t_s,
            lateral_error_m: &t.lateral_error_m,
            lateral_error_front_m: &t.lateral_error_front_m,
            lateral_error_rear_m: &t.lateral_error_rear_m,
            heading_error_rad: &t.heading_error_rad,
            delta_rad: &t.delta_rad,
            v_mps: &t.v_mps,
            distance_m: &t.distance_m,
        }
    }
}

impl Series<'_> {
    fn len(&self) -> usize {
        // Columns of unequal length are cut to the shortest: never index past one.
        [
            self.t_s.len(),
            self.lateral_error_m.len(),
            self.heading_error_rad.len(),
            self.delta_rad.len(),
            self.v_mps.len(),
            self.distance_m.len(),
        ]
        .into_iter()
        .min()
        .unwrap_or(0)
    }
}

fn rms(sum_sq: f64, n: usize) -> f64 {
    if n == 0 {
        0.0
    } else {
        (sum_sq / n as f64).sqrt()
    }
}

/// Metrics over samples `range` of `s`.
pub fn window_metrics(
    s: &Series<'_>,
    range: std::ops::Range<usize>,
    wheelbase_m: f64,
) -> WindowMetrics {
    let n_all = s.len();
    let range = range.start.min(n_all)..range.end.min(n_all);
    let n = range.len();
    if n == 0 {
        return WindowMetrics::default();
    }
    let mut acc = TrackingStats::default();
    let (mut sum_rate2, mut max_rate, mut n_rate) = (0.0, 0.0f64, 0usize);
    for i in range.clone() {
        let v = s.v_mps[i];
        acc.add(&TrackingSample {
            lateral_error_m: s.lateral_error_m[i],
            heading_error_rad: s.heading_error_rad[i],
            v_mps: v,
            lateral_accel_mps2: v * v * s.delta_rad[i].tan() / wheelbase_m,
        });
        if i > range.start {
            let dt = s.t_s[i] - s.t_s[i - 1];
            if dt > 0.0 {
                let rate = (s.delta_rad[i] - s.delta_rad[i - 1]) / dt;
                sum_rate2 += rate * rate;
                max_rate = max_rate.max(rate.abs());
                n_rate += 1;
            }
        }
    }
    let before = if range.start == 0 {
        0.0
    } else {
        s.distance_m[range.start - 1]
    };
    WindowMetrics {
        lateral_error_mean_abs_m: acc.lateral_error_mean_abs_m(),
        lateral_error_rms_m: acc.lateral_error_rms_m(),
        lateral_error_max_abs_m: acc.max_abs_e,
        heading_error_rms_deg: acc.heading_error_rms_deg(),
        steering_rate_rms_deg_s: rms(sum_rate2, n_rate).to_degrees(),
        steering_rate_max_deg_s: max_rate.to_degrees(),
        lateral_accel_max_mps2: acc.max_lat_acc,
        mean_speed_mps: acc.mean_speed_mps(),
        distance_m: s.distance_m[range.end - 1] - before,
        samples: n,
    }
}

/// Index of the first sample from which |e| < `threshold_m` up to the end.
pub fn settled_index(lateral_error_m: &[f64], threshold_m: f64) -> Option<usize> {
    // NaN compares false, so a NaN error counts as "not settled".
    let last_bad = lateral_error_m
        .iter()
        .rposition(|e| !(e.abs() < threshold_m));
    match last_bad {
        None if lateral_error_m.is_empty() => None,
        None => Some(0),
        Some(i) if i + 1 < lateral_error_m.len() => Some(i + 1),
        Some(_) => None,
    }
}

/// `max(0, max_i(-sign(e_0) e_i))` over the whole run, 0 if `e_0 = 0`.
pub fn opposite_side_max(lateral_error_m: &[f64]) -> f64 {
    let Some(side) = start_side(lateral_error_m) else {
        return 0.0;
    };
    lateral_error_m
        .iter()
        .filter(|e| e.is_finite())
        .fold(0.0f64, |m, e| m.max(-side * e))
}

fn start_side(lateral_error_m: &[f64]) -> Option<f64> {
    let &e0 = lateral_error_m.first()?;
    (e0 != 0.0 && e0.is_finite()).then(|| e0.signum())
}

/// The initial approach's overshoot: the peak on the other side between the
/// first crossing and the next one back (see the module docs).
pub fn initial_overshoot(lateral_error_m: &[f64]) -> f64 {
    let Some(side) = start_side(lateral_error_m) else {
        return 0.0;
    };
    let Some(c) = lateral_error_m.iter().position(|e| side * e < 0.0) else {
        return 0.0;
    };
    lateral_error_m[c..]
        .iter()
        .take_while(|e| !(side * **e > 0.0))
        .filter(|e| e.is_finite())
        .fold(0.0f64, |m, e| m.max(-side * e))
}

/// Front, rear and body errors of the first `n` samples (NaN when either
/// axle column is shorter than `n` or `n = 0`).
pub fn axle_metrics(front: &[f64], rear: &[f64], n: usize) -> AxleMetrics {
    if n == 0 || front.len() < n || rear.len() < n {
        return AxleMetrics::default();
    }
    let (mut sf, mut sr, mut sb, mut mb) = (0.0, 0.0, 0.0, 0.0f64);
    for (f, r) in front[..n].iter().zip(&rear[..n]) {
        let b = f.abs().max(r.abs());
        sf += f.abs();
        sr += r.abs();
        sb += b;
        mb = mb.max(b);
    }
    let k = n as f64;
    AxleMetrics {
        lateral_error_front_axle_mean_abs_m: sf / k,
        lateral_error_rear_axle_mean_abs_m: sr / k,
        body_error_mean_m: sb / k,
        body_error_max_m: mb,
    }
}

/// All metrics of a series (see the module docs for the definitions).
pub fn run_metrics(s: &Series<'_>, wheelbase_m: f64) -> RunMetrics {
    let n = s.len();
    let errs = &s.lateral_error_m[..n];
    let k = settled_index(errs, SETTLING_THRESHOLD_M);
    let step0 = if n >= 2 { s.t_s[1] - s.t_s[0] } else { 0.0 };
    let r = errs.iter().position(|e| e.abs() < SETTLING_THRESHOLD_M);
    RunMetrics {
        reached_time_s: r.map(|r| s.t_s[r] - s.t_s[0] + step0),
        reached: r.map(|r| window_metrics(s, r..n, wheelbase_m)),
        whole: window_metrics(s, 0..n, wheelbase_m),
        settling_time_s: k.map(|k| s.t_s[k] - s.t_s[0] + step0),
        settled_index: k,
        initial_overshoot_m: initial_overshoot(errs),
        opposite_side_max_m: opposite_side_max(errs),
        axles: axle_metrics(s.lateral_error_front_m, s.lateral_error_rear_m, n),
        settled: k.map(|k| window_metrics(s, k..n, wheelbase_m)),
    }
}

/// Metrics of a simulated trace.
pub fn trace_metrics(trace: &Trace, wheelbase_m: f64) -> RunMetrics {
    run_metrics(&Series::from(trace), wheelbase_m)
}

impl RunMetrics {
    /// The flat `(key, value)` list written to `metrics.json` (NaN where a
    /// metric does not exist: never settled, never reached, no axle columns).
    pub fn to_named(&self) -> Vec<(&'static str, f64)> {
        let w = &self.whole;
        let nan = f64::NAN;
        let sv = |f: fn(&WindowMetrics) -> f64| self.settled.as_ref().map(f).unwrap_or(nan);
        let rv = |f: fn(&WindowMetrics) -> f64| self.reached.as_ref().map(f).unwrap_or(nan);
        let ax = &self.axles;
        vec![
            ("lateral_error_mean_abs_m", w.lateral_error_mean_abs_m),
            ("lateral_error_rms_m", w.lateral_error_rms_m),
            ("lateral_error_max_abs_m", w.lateral_error_max_abs_m),
            ("heading_error_rms_deg", w.heading_error_rms_deg),
            ("steering_rate_rms_deg_s", w.steering_rate_rms_deg_s),
            ("steering_rate_max_deg_s", w.steering_rate_max_deg_s),
            ("lateral_accel_max_mps2", w.lateral_accel_max_mps2),
            ("reached_time_s", self.reached_time_s.unwrap_or(nan)),
            ("settling_time_s", self.settling_time_s.unwrap_or(nan)),
            ("initial_overshoot_m", self.initial_overshoot_m),
            ("mean_speed_mps", w.mean_speed_mps),
            ("distance_m", w.distance_m),
            (
                "lateral_error_mean_abs_m_reached",
                rv(|m| m.lateral_error_mean_abs_m),
            ),
            (
                "lateral_error_mean_abs_m_settled",
                sv(|m| m.lateral_error_mean_abs_m),
            ),
            ("lateral_error_rms_m_settled", sv(|m| m.lateral_error_rms_m)),
            (
                "lateral_error_max_abs_m_settled",
                sv(|m| m.lateral_error_max_abs_m),
            ),
            (
                "heading_error_rms_deg_settled",
                sv(|m| m.heading_error_rms_deg),
            ),
            (
                "lateral_error_front_axle_mean_abs_m",
                ax.lateral_error_front_axle_mean_abs_m,
            ),
            (
                "lateral_error_rear_axle_mean_abs_m",
                ax.lateral_error_rear_axle_mean_abs_m,
            ),
            ("body_error_mean_m", ax.body_error_mean_m),
            ("body_error_max_m", ax.body_error_max_m),
        ]
    }

    /// Metrics beyond the `metrics.json` keys: the largest opposite-side
    /// excursion and the rest of the window after first reaching the
    /// threshold (NaN where it never does).
    pub fn to_named_extra(&self) -> Vec<(&'static str, f64)> {
        let nan = f64::NAN;
        let rv = |f: fn(&WindowMetrics) -> f64| self.reached.as_ref().map(f).unwrap_or(nan);
        vec![
            ("opposite_side_max_m", self.opposite_side_max_m),
            ("lateral_error_rms_m_reached", rv(|m| m.lateral_error_rms_m)),
            (
                "lateral_error_max_abs_m_reached",
                rv(|m| m.lateral_error_max_abs_m),
            ),
            (
                "heading_error_rms_deg_reached",
                rv(|m| m.heading_error_rms_deg),
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Cols {
        t: Vec<f64>,
        e: Vec<f64>,
        front: Vec<f64>,
        rear: Vec<f64>,
        h: Vec<f64>,
        d: Vec<f64>,
        v: Vec<f64>,
        dist: Vec<f64>,
    }

    impl Cols {
        /// Samples at t = 0.1, 0.2, ... with the given errors, zero heading
        /// error and steering, constant speed 2 m/s.
        fn new(e: &[f64]) -> Self {
            let n = e.len();
            let t: Vec<f64> = (1..=n).map(|i| i as f64 * 0.1).collect();
            let dist: Vec<f64> = (1..=n).map(|i| i as f64 * 0.2).collect();
            Cols {
                t,
                e: e.to_vec(),
                front: vec![],
                rear: vec![],
                h: vec![0.0; n],
                d: vec![0.0; n],
                v: vec![2.0; n],
                dist,
            }
        }
        fn series(&self) -> Series<'_> {
            Series {
                t_s: &self.t,
                lateral_error_m: &self.e,
                lateral_error_front_m: &self.front,
                lateral_error_rear_m: &self.rear,
                heading_error_rad: &self.h,
                delta_rad: &self.d,
                v_mps: &self.v,
                distance_m: &self.dist,
            }
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn error_statistics_by_hand() {
        // |e| = 3, 4, 0, 0 -> mean 1.75, rms sqrt(25/4) = 2.5, max 4.
        let c = Cols::new(&[3.0, -4.0, 0.0, 0.0]);
        let m = run_metrics(&c.series(), 2.6);
        assert!(close(m.whole.lateral_error_mean_abs_m, 1.75));
        assert!(close(m.whole.lateral_error_rms_m, 2.5));
        assert!(close(m.whole.lateral_error_max_abs_m, 4.0));
        assert!(close(m.whole.mean_speed_mps, 2.0));
        assert!(close(m.whole.distance_m, 0.8));
        assert_eq!(m.whole.samples, 4);
    }

    #[test]
    fn settling_is_for_good() {
        // Dips below 0.1 at sample 2, leaves again at 3, settles for good at 4.
        let c = Cols::new(&[1.0, 0.5, 0.05, 0.2, 0.09, -0.05, 0.0]);
        let m = run_metrics(&c.series(), 2.6);
        assert_eq!(m.settled_index, Some(4));
        // t_4 = 0.5 s, first sample = one step (0.1 s) after the start.
        assert!(
            close(m.settling_time_s.unwrap(), 0.5),
            "{:?}",
            m.settling_time_s
        );
        let s = m.settled.unwrap();
        assert_eq!(s.samples, 3);
        assert!(close(s.lateral_error_mean_abs_m, (0.09 + 0.05 + 0.0) / 3.0));
        assert!(close(s.lateral_error_max_abs_m, 0.09));
        // Distance within the window: samples 4..7 at 2 m/s * 0.1 s.
        assert!(close(s.distance_m, 0.6), "{}", s.distance_m);
        // First reached at sample 2 (t = 0.3 s), even though it leaves again.
        assert!(close(m.reached_time_s.unwrap(), 0.3));
        let r = m.reached.unwrap();
        assert_eq!(r.samples, 5);
        assert!(close(r.lateral_error_max_abs_m, 0.2));
        // Exactly at the threshold is not below it.
        assert_eq!(settled_index(&[0.5, 0.1, 0.0], 0.1), Some(2));
    }

    #[test]
    fn never_settled_and_always_settled() {
        let c = Cols::new(&[1.0, 0.05, 0.3]);
        let m = run_metrics(&c.series(), 2.6);
        assert_eq!(m.settling_time_s, None);
        assert!(m.settled.is_none());
        assert!(close(m.reached_time_s.unwrap(), 0.2));
        let named = m.to_named();
        assert!(named
            .iter()
            .find(|(k, _)| *k == "lateral_error_rms_m_settled")
            .unwrap()
            .1
            .is_nan());
        let c = Cols::new(&[0.01, -0.02, 0.0]);
        let m = run_metrics(&c.series(), 2.6);
        assert_eq!(m.settled_index, Some(0));
        assert!(close(m.settling_time_s.unwrap(), 0.1));
        assert_eq!(m.settled.unwrap(), m.whole);
        assert_eq!(settled_index(&[0.0, f64::NAN, 0.0], 0.1), Some(2));
        assert_eq!(settled_index(&[], 0.1), None);
    }

    #[test]
    fn initial_overshoot_is_the_peak_between_the_first_two_crossings() {
        // Starts left (+4), crosses at sample 2, peaks at -0.7, crosses back
        // at sample 5; a later corner cut to -1.5 is not the initial overshoot.
        let e = [4.0, 2.0, -0.3, -0.7, -0.2, 0.05, 0.0, -1.5, 0.0];
        assert!(close(initial_overshoot(&e), 0.7));
        assert!(close(opposite_side_max(&e), 1.5));
        let m = run_metrics(&Cols::new(&e).series(), 2.6);
        assert!(close(m.initial_overshoot_m, 0.7));
        assert!(close(m.opposite_side_max_m, 1.5));
        // Samples at exactly 0 do not end the excursion; only a sample back
        // on the starting side does.
        assert!(close(
            initial_overshoot(&[1.0, -0.2, 0.0, -0.4, 0.3, -2.0]),
            0.4
        ));
        // Starts right: the overshoot is on the left.
        assert!(close(initial_overshoot(&[-4.0, -1.0, 0.4, 0.1]), 0.4));
        // Never crosses.
        assert_eq!(initial_overshoot(&[4.0, 2.0, 0.5, 0.0]), 0.0);
        // No initial offset, no side to overshoot from.
        assert_eq!(initial_overshoot(&[0.0, 1.0, -1.0]), 0.0);
        assert_eq!(opposite_side_max(&[0.0, 1.0, -1.0]), 0.0);
        assert_eq!(initial_overshoot(&[]), 0.0);
        // A damped oscillation e_i = 2 (-0.5)^i: first crossing at i = 1,
        // peak 1.0 there (the next crossing back is at i = 2).
        let e: Vec<f64> = (0..10).map(|i| 2.0 * (-0.5f64).powi(i)).collect();
        assert!(close(initial_overshoot(&e), 1.0));
    }

    #[test]
    fn axle_and_body_errors_by_hand() {
        let mut c = Cols::new(&[0.0; 4]);
        // Body = max(|front|, |rear|) = 0.3, 0.2, 0.5, 0.0.
        c.front = vec![0.3, -0.1, 0.0, 0.0];
        c.rear = vec![-0.1, 0.2, -0.5, 0.0];
        let m = run_metrics(&c.series(), 2.6);
        assert!(close(m.axles.lateral_error_front_axle_mean_abs_m, 0.1));
        assert!(close(m.axles.lateral_error_rear_axle_mean_abs_m, 0.2));
        assert!(close(m.axles.body_error_mean_m, 0.25));
        assert!(close(m.axles.body_error_max_m, 0.5));
        let named = m.to_named();
        let get = |k: &str| named.iter().find(|(n, _)| *n == k).unwrap().1;
        assert!(close(get("body_error_mean_m"), 0.25));
        assert!(close(get("lateral_error_front_axle_mean_abs_m"), 0.1));
        // Without axle columns: NaN, not 0.
        let m = run_metrics(&Cols::new(&[0.0; 4]).series(), 2.6);
        assert!(m.axles.body_error_mean_m.is_nan());
    }

    #[test]
    fn steering_rate_heading_and_lateral_accel() {
        let mut c = Cols::new(&[0.0; 5]);
        // Steering ramps 0, 0.01, 0.02, 0.02, 0.0 rad at 0.1 s steps:
        // rates 0.1, 0.1, 0, -0.2 rad/s.
        c.d = vec![0.0, 0.01, 0.02, 0.02, 0.0];
        c.h = vec![0.1, -0.1, 0.1, -0.1, 0.1];
        let m = run_metrics(&c.series(), 2.0);
        let rms = ((0.01 + 0.01 + 0.0 + 0.04) / 4.0f64).sqrt().to_degrees();
        assert!(
            (m.whole.steering_rate_rms_deg_s - rms).abs() < 1e-9,
            "{} vs {rms}",
            m.whole.steering_rate_rms_deg_s
        );
        assert!((m.whole.steering_rate_max_deg_s - 0.2f64.to_degrees()).abs() < 1e-9);
        assert!((m.whole.heading_error_rms_deg - 0.1f64.to_degrees()).abs() < 1e-9);
        // v = 2 m/s, E = 2 m: a_lat = 4 tan(0.02) / 2.
        assert!((m.whole.lateral_accel_max_mps2 - 2.0 * 0.02f64.tan()).abs() < 1e-12);
        // Backwards: same magnitude.
        c.v = vec![-2.0; 5];
        let mb = run_metrics(&c.series(), 2.0);
        assert!(close(
            mb.whole.lateral_accel_max_mps2,
            m.whole.lateral_accel_max_mps2
        ));
        assert!(close(mb.whole.mean_speed_mps, 2.0));
    }

    #[test]
    fn empty_and_ragged_series_do_not_panic() {
        let c = Cols::new(&[]);
        let m = run_metrics(&c.series(), 2.6);
        assert_eq!(m.whole.samples, 0);
        assert_eq!(m.settling_time_s, None);
        let mut c = Cols::new(&[1.0, 0.0, 0.0]);
        c.v.truncate(1);
        let m = run_metrics(&c.series(), 2.6);
        assert_eq!(m.whole.samples, 1);
    }
}
