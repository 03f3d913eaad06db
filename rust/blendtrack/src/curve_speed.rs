//! Curve speeds previewed along the path's arc (beyond the paper; offered as
//! the `arc` corridor).
//!
//! The paper's virtual obstacle is where a ray along the heading leaves a
//! corridor of the path's widths. On a curve of radius R in a corridor of
//! half width w that is `sqrt(2 R w + w^2)` ahead, and the stopping law for
//! a standing obstacle there caps the speed at about
//! `v tau + v^2 / (-2 b_f) = sqrt(2 R w)`: it grows like `R^(1/4)`, so a lane
//! (w = 1.75 m) holds a vehicle to about 14.7 m/s through an R = 500 m curve
//! that takes 31 m/s at 2 m/s^2 of lateral acceleration.
//!
//! Instead, with `curve_lateral_accel` = `a_y` > 0 every point of the path
//! has a curve speed `v_c(s) = sqrt(a_y / |kappa(s)|)` (the speed at which
//! the lateral acceleration `v^2 |kappa|` is `a_y`; unbounded on a straight)
//! and the speed allowed at `x` is the lowest curve speed ahead brought back
//! to `x` by braking at `b_c = curve_deceleration`:
//!
//! `v_allow(x)^2 = min over s >= x of v_c(s)^2 + 2 |b_c| (s - x)`.
//!
//! The command tracks that envelope with its slope as a feed-forward and
//! the reaction time `tau` as the time constant of the feedback:
//!
//! `a_curve = g / 2 + (v_allow(s)^2 - v^2) / (2 v tau)`, at least `b_f`,
//!
//! with `g = d(v_allow^2)/ds` at the vehicle (`-2 |b_c|` on a braking branch,
//! 0 inside a curve of constant curvature). The squared gap
//! `e = v_allow^2 - v^2` then obeys `de/ds = -e / (v tau)`: a vehicle under
//! the envelope stays under it (up to the integration step) and so reaches
//! every curve at no more than its curve speed, braking at no more than
//! `|b_c|` for it; inside a steady curve the steady speed is `v_c` exactly.
//! Like the paper's virtual obstacle, a curve is a comfort limit: the
//! command is bounded below by `max_deceleration`.

use crate::config::ControllerConfig;
use crate::path::Path;

/// |curvature| at each vertex of a path, for the curve-speed preview.
#[derive(Debug, Clone)]
pub struct CurveProfile {
    s: Vec<f64>,
    kappa: Vec<f64>,
    closed: bool,
    length: f64,
}

impl CurveProfile {
    /// The path's |curvature| (as the controllers read it,
    /// [`Path::curvature_at`]) at each vertex; with `smoothing_m` > 0 that
    /// |curvature| averaged first with a Gaussian of that standard deviation
    /// along the arc (see [`ControllerConfig::curve_smoothing_m`]).
    ///
    /// The magnitude is averaged, not the signed curvature: in an S-shaped
    /// jog the two bends' curvatures cancel in a signed average, which read
    /// a straight road there. Bologna's junction 37 takes its one lane in
    /// to the rightmost of three out with a 7.6 m sideways jog over 9 m;
    /// under the `road` corridor cars went through it at 11.4 m/s, 4-5 m off
    /// their track, and were handed back as placement faults (276 over
    /// seeds 0-35 at 30 %, most there). Where the curvature keeps its sign
    /// (a curve drawn as a polyline) both averages are the same.
    pub fn new(path: &Path, smoothing_m: f64) -> Self {
        let s = path.vertex_s().to_vec();
        let magnitude: Vec<f64> = s.iter().map(|&si| path.curvature_at(si).abs()).collect();
        let closed = path.is_closed();
        let length = path.length();
        let kappa = if smoothing_m > 0.0 && smoothing_m.is_finite() && s.len() > 2 {
            let mean = gaussian_mean(&s, &magnitude, smoothing_m, closed, length);
            // The average comes up to a curve's own over about two standard
            // deviations into it: its largest within that reach keeps the
            // curve's whole length (and a little before and after) at the
            // curve's curvature, so the vehicle is at the curve speed where
            // the curve begins, not 2 sigma into it.
            sliding_max(&s, &mean, 2.0 * smoothing_m, closed, length)
        } else {
            magnitude
        };
        CurveProfile {
            s,
            kappa,
            closed,
            length,
        }
    }

    /// |curvature| at `x`, linear between vertices (0 past an open path's ends).
    fn kappa_at(&self, x: f64) -> f64 {
        let n = self.s.len();
        let i = self.s.partition_point(|&si| si <= x);
        if i == 0 {
            return if self.closed { self.kappa[n - 1] } else { 0.0 };
        }
        let (s0, k0) = (self.s[i - 1], self.kappa[i - 1]);
        let (s1, k1) = if i < n {
            (self.s[i], self.kappa[i])
        } else if self.closed {
            (self.length, self.kappa[0])
        } else {
            return if x <= s0 { k0 } else { 0.0 };
        };
        let u = if s1 > s0 {
            ((x - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        k0 + u * (k1 - k0)
    }

    /// `v_allow^2` at `x` and at `x + h`: the least of
    /// `a_y / |kappa(s)| + 2 b (s - y)` over `s = y` and the vertices
    /// `s` in `(y, x + horizon]`, for `y = x` and `y = x + h` (`a_y > 0`,
    /// `b > 0` a deceleration's magnitude, `0 <= h < horizon`); +inf where the
    /// path is straight. Both see the same far end, so a vertex entering the
    /// preview moves neither alone. `x` is an arc length of the path.
    pub fn allowed_speed_sq(&self, x: f64, h: f64, horizon_m: f64, a_y: f64, b: f64) -> (f64, f64) {
        let vc2 = |k: f64| if k > 0.0 { a_y / k } else { f64::INFINITY };
        let x = if self.closed {
            x.rem_euclid(self.length)
        } else {
            x
        };
        let mut at_x = vc2(self.kappa_at(x));
        let mut at_xh = vc2(self.kappa_at(if self.closed {
            (x + h).rem_euclid(self.length)
        } else {
            x + h
        }));
        let n = self.s.len();
        let mut i = self.s.partition_point(|&si| si <= x);
        let mut offset = 0.0;
        for _ in 0..n {
            if i == n {
                if !self.closed {
                    break;
                }
                i = 0;
                offset = self.length;
            }
            let d = self.s[i] + offset - x;
            if d > horizon_m {
                break;
            }
            let k = vc2(self.kappa[i]);
            at_x = at_x.min(k + 2.0 * b * d);
            if d > h {
                at_xh = at_xh.min(k + 2.0 * b * (d - h));
            }
            i += 1;
        }
        (at_x, at_xh)
    }
}

/// How far ahead a curve can matter: a vertex further than this, were it the
/// lowest of the envelope, would ask (slope `-2 b` plus the feedback) for
/// `-b + (2 b d - v^2) / (2 v tau)` or more, at least `preferred_acceleration`,
/// which free flow never exceeds; without it the envelope is only higher.
fn preview_m(speed_abs: f64, b: f64, cfg: &ControllerConfig) -> f64 {
    let tau = cfg.reaction_time;
    (speed_abs * speed_abs + 2.0 * speed_abs * tau * (cfg.preferred_acceleration + b)) / (2.0 * b)
        + 1.0
}

/// Calls `visit(k, d)` for each sample `k` within `reach` (m of arc) of
/// sample `i`, `d` its signed arc distance from it: `i` itself, then the
/// samples behind it going back, then the ones ahead going on. A closed path
/// wraps around (`length`), each sample met at most once.
fn for_each_within(
    s: &[f64],
    i: usize,
    reach: f64,
    closed: bool,
    length: f64,
    mut visit: impl FnMut(usize, f64),
) {
    let n = s.len() as isize;
    for dir in [-1isize, 1] {
        let mut j = if dir < 0 { i as isize } else { i as isize + 1 };
        while (closed || (0..n).contains(&j)) && (j - i as isize).abs() < n {
            let k = j.rem_euclid(n) as usize;
            let d = s[k] + j.div_euclid(n) as f64 * length - s[i];
            if d.abs() > reach {
                break;
            }
            visit(k, d);
            j += dir;
        }
    }
}

/// `values` (one per arc length of `s`, increasing) averaged with a Gaussian
/// of standard deviation `sigma` (m) along the arc, each sample weighted by
/// the arc it stands for (half the distance to each neighbour), out to
/// `3 sigma`; a closed path wraps around (`length`).
fn gaussian_mean(s: &[f64], values: &[f64], sigma: f64, closed: bool, length: f64) -> Vec<f64> {
    let n = s.len();
    let span: Vec<f64> = (0..n)
        .map(|k| match (k, closed) {
            (0, false) => 0.5 * (s[1] - s[0]),
            (k, false) if k == n - 1 => 0.5 * (s[n - 1] - s[n - 2]),
            (0, true) => 0.5 * (s[1] - (s[n - 1] - length)),
            (k, true) if k == n - 1 => 0.5 * (s[0] + length - s[n - 2]),
            (k, _) => 0.5 * (s[k + 1] - s[k - 1]),
        })
        .collect();
    (0..n)
        .map(|i| {
            let (mut num, mut den) = (0.0, 0.0);
            for_each_within(s, i, 3.0 * sigma, closed, length, |k, d| {
                let w = (-0.5 * (d / sigma).powi(2)).exp() * span[k];
                num += w * values[k];
                den += w;
            });
            if den > 0.0 {
                num / den
            } else {
                values[i]
            }
        })
        .collect()
}

/// The largest of `values` within `reach` (m of arc) of each sample (a
/// closed path wraps around).
fn sliding_max(s: &[f64], values: &[f64], reach: f64, closed: bool, length: f64) -> Vec<f64> {
    (0..s.len())
        .map(|i| {
            let mut best = values[i];
            for_each_within(s, i, reach, closed, length, |k, _| {
                best = best.max(values[k])
            });
            best
        })
        .collect()
}

/// Step (m) of the forward difference for the envelope's slope `g`: a kink
/// of the envelope (where a braking branch meets a curve) is seen this much
/// early, which lets the speed there overshoot by about `|b_c| h / (2 v)`.
const SLOPE_STEP_M: f64 = 0.05;

/// The curve-speed acceleration at arc length `s` (see the module docs):
/// +inf when `curve_lateral_accel` is 0 (off) or no curve is near.
pub fn curve_accel(profile: &CurveProfile, s: f64, speed_abs: f64, cfg: &ControllerConfig) -> f64 {
    let a_y = cfg.curve_lateral_accel;
    if !(a_y > 0.0) {
        return f64::INFINITY;
    }
    let b = -cfg.curve_deceleration;
    let tau = cfg.reaction_time;
    let v = speed_abs.max(0.0);
    if v * tau <= 1e-9 {
        // Standing: any curve speed is above zero.
        return f64::INFINITY;
    }
    let h = SLOPE_STEP_M;
    let (here, ahead) = profile.allowed_speed_sq(s, h, preview_m(v, b, cfg) + h, a_y, b);
    if !here.is_finite() || !ahead.is_finite() {
        return f64::INFINITY;
    }
    let slope = (ahead - here) / h;
    (0.5 * slope + (here - v * v) / (2.0 * v * tau)).max(cfg.max_deceleration)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(a_y: f64) -> ControllerConfig {
        ControllerConfig {
            curve_lateral_accel: a_y,
            curve_deceleration: -2.0,
            preferred_speed: 25.0,
            ..Default::default()
        }
    }

    /// Drives a point mass along `path` from `s0` at `v0` under
    /// `min(free flow, curve)` for `t_end` s; returns (s, v) per step.
    fn drive(path: &Path, c: &ControllerConfig, s0: f64, v0: f64, t_end: f64) -> Vec<(f64, f64)> {
        let profile = CurveProfile::new(path, c.curve_smoothing_m);
        let dt = 0.01;
        let (mut s, mut v) = (s0, v0);
        let mut out = vec![(s, v)];
        for _ in 0..(t_end / dt) as usize {
            let a = crate::longitudinal::free_flow_accel(v, c).min(curve_accel(&profile, s, v, c));
            v = (v + a * dt).max(0.0);
            s += v * dt;
            out.push((s, v));
        }
        out
    }

    #[test]
    fn steady_speed_on_a_circle_is_the_curve_speed() {
        // v^2 / R = a_y: v = sqrt(a_y R), from below and from above.
        for &r in &[30.0, 100.0, 200.0] {
            for &a_y in &[1.5, 2.0, 3.0] {
                let path = Path::circle(r, 1e-3).unwrap();
                let c = cfg(a_y);
                let expected = (a_y * r).sqrt();
                assert!(expected < c.preferred_speed);
                for v0 in [0.5 * expected, 1.3 * expected] {
                    let run = drive(&path, &c, 0.0, v0, 60.0);
                    let v = run.last().unwrap().1;
                    assert!(
                        (v - expected).abs() < 0.01 * expected,
                        "R={r} a_y={a_y} from {v0}: {v} vs {expected}"
                    );
                }
                // And the command is zero right at it (up to the polygon's curvature).
                let at = curve_accel(&CurveProfile::new(&path, 0.0), 10.0, expected, &c);
                assert!(at.abs() < 1e-3, "R={r}: {at}");
            }
        }
    }

    #[test]
    fn an_s_shaped_jog_keeps_its_curve_speed_once_smoothed() {
        // A straight road with a sideways jog of 7.6 m over 9 m in the
        // middle (Bologna's junction 37: one lane in, the rightmost of three
        // out), two bends of opposite sign. Averaged signed, they cancel and
        // the jog reads as straight; averaged as magnitudes, the curve speed
        // there stays about what each bend alone allows, far below free flow.
        let mut pts: Vec<[f64; 2]> = (0..=100).map(|k| [k as f64, 0.0]).collect();
        for k in 1..=9 {
            let u = k as f64 / 9.0;
            let smooth = u * u * (3.0 - 2.0 * u);
            pts.push([100.0 + k as f64, -7.6 * smooth]);
        }
        pts.extend((1..=100).map(|k| [109.0 + k as f64, -7.6]));
        let path = Path::new(&pts, None, false).unwrap();
        let profile = CurveProfile::new(&path, 10.0);
        let (at_jog, _) = profile.allowed_speed_sq(104.5, 0.0, 1.0, 2.0, 2.0);
        let v_jog = at_jog.sqrt();
        assert!(v_jog < 8.0, "curve speed at the jog: {v_jog} m/s");
        // Far from it the road is straight.
        let (far, _) = profile.allowed_speed_sq(20.0, 0.0, 1.0, 2.0, 2.0);
        assert!(far.sqrt() > 30.0, "{}", far.sqrt());
    }

    #[test]
    fn a_curve_drawn_as_a_polyline_is_driven_at_its_curve_speed_once_smoothed() {
        // An arc of R = 230 m drawn with vertices every 20 m (a motorway
        // loop in SUMO's lane shapes), filled in with points every metre
        // along the chords: the turning sits in kinks of 20 / 230 rad. Read
        // as it is, each kink is a curve of about 40 m radius (a Gaussian
        // over the controllers' 2 m tangent width), and the vehicle crawls;
        // averaged over 10 m (about half the vertex spacing) the curvature
        // is the arc's and the steady speed sqrt(a_y R) within 3 %.
        let (r, chord) = (230.0_f64, 20.0_f64);
        let dtheta = 2.0 * (0.5 * chord / r).asin();
        let corners: Vec<[f64; 2]> = (0..=24)
            .map(|k| {
                let t = dtheta * k as f64;
                [r * t.sin(), r - r * t.cos()]
            })
            .collect();
        let mut pts = vec![];
        for w in corners.windows(2) {
            for m in 0..20 {
                let u = m as f64 / 20.0;
                pts.push([
                    w[0][0] + u * (w[1][0] - w[0][0]),
                    w[0][1] + u * (w[1][1] - w[0][1]),
                ]);
            }
        }
        pts.push(*corners.last().unwrap());
        let path = Path::new(&pts, None, false).unwrap();
        let vc = (2.0 * r).sqrt();
        // The speed over the middle of the arc, from the curve speed.
        let middle = |smoothing: f64| {
            let c = ControllerConfig {
                curve_smoothing_m: smoothing,
                preferred_speed: 30.0,
                ..cfg(2.0)
            };
            let run = drive(&path, &c, 0.0, vc, 25.0);
            let mid: Vec<f64> = run
                .iter()
                .filter(|(s, _)| *s > 200.0 && *s < 300.0)
                .map(|&(_, v)| v)
                .collect();
            assert!(!mid.is_empty());
            (
                mid.iter().cloned().fold(f64::INFINITY, f64::min),
                mid.iter().cloned().fold(0.0, f64::max),
            )
        };
        let (low, _) = middle(0.0);
        assert!(low < 0.5 * vc, "read as drawn: {low} vs {vc}");
        let (low, high) = middle(10.0);
        assert!(
            low > 0.97 * vc && high < 1.03 * vc,
            "smoothed: {low}..{high} vs {vc}"
        );
        // On an arc drawn densely the smoothing changes nothing (steady
        // speed as without it, within 1 %).
        let circle = Path::circle(100.0, 1e-3).unwrap();
        let c = ControllerConfig {
            curve_smoothing_m: 10.0,
            ..cfg(2.0)
        };
        let v = drive(&circle, &c, 0.0, 10.0, 60.0).last().unwrap().1;
        assert!(
            (v - (200.0_f64).sqrt()).abs() < 0.01 * (200.0_f64).sqrt(),
            "{v}"
        );
    }

    #[test]
    fn a_straight_road_sets_no_limit() {
        let path = Path::straight(2000.0, 1.0).unwrap();
        let c = cfg(2.0);
        let p = CurveProfile::new(&path, 0.0);
        for v in [0.0, 5.0, 25.0, 40.0] {
            assert_eq!(curve_accel(&p, 100.0, v, &c), f64::INFINITY);
        }
        // Driven: free flow up to the road speed.
        let run = drive(&path, &c, 0.0, 0.0, 150.0);
        assert!((run.last().unwrap().1 - c.preferred_speed).abs() < 0.3);
        // Off (a_y = 0, the paper's law): never a limit, even on a circle.
        let circle = CurveProfile::new(&Path::circle(30.0, 1e-3).unwrap(), 0.0);
        assert_eq!(curve_accel(&circle, 5.0, 20.0, &cfg(0.0)), f64::INFINITY);
    }

    /// A straight of `lead` m, then a left arc of radius `r` over `angle` rad.
    fn straight_then_arc(lead: f64, r: f64, angle: f64) -> Path {
        let mut pts = vec![];
        let mut x = 0.0;
        while x < lead {
            pts.push([x, 0.0]);
            x += 1.0;
        }
        let n = (r * angle).ceil() as usize;
        for k in 0..=n {
            let t = angle * k as f64 / n as f64;
            pts.push([lead + r * t.sin(), r - r * t.cos()]);
        }
        Path::new(&pts, None, false).unwrap()
    }

    #[test]
    fn curve_entry_brakes_early_enough() {
        // From the road speed on a 600 m straight into an arc (R = 30 m is
        // 7.75 m/s at 2 m/s^2): at every point, the arc's start included, the
        // speed is at most the curve speed of the path's curvature there
        // (as the controllers read it: it ramps up over the 2 m tangent
        // sampling width around the joint), i.e. v^2 |kappa| <= a_y (0.5 %
        // for the 0.01 s Euler step); the braking before it is never harder
        // than curve_deceleration (plus 1 % for the step), and in the arc the
        // speed settles at sqrt(a_y R).
        for &(r, a_y) in &[(30.0, 2.0), (60.0, 3.0), (120.0, 2.0)] {
            let lead = 600.0;
            let path = straight_then_arc(lead, r, 2.5);
            let c = cfg(a_y);
            let vc = (a_y * r).sqrt();
            let run = drive(&path, &c, 0.0, c.preferred_speed, 80.0);
            let in_path: Vec<_> = run.iter().filter(|(s, _)| *s < path.length()).collect();
            let worst = in_path
                .iter()
                .map(|(s, v)| v * v * path.curvature_at(*s).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= a_y * 1.005,
                "R={r}: lateral acceleration {worst} > {a_y}"
            );
            let at_entry = in_path.iter().find(|(s, _)| *s >= lead + 2.0).unwrap().1;
            assert!(
                at_entry <= vc * 1.0025,
                "R={r}: {at_entry} in the arc, curve speed {vc}"
            );
            assert!(
                at_entry >= vc * 0.99,
                "R={r}: {at_entry} in the arc: crawls below {vc}"
            );
            let hardest = run
                .windows(2)
                .filter(|w| w[1].0 < lead)
                .map(|w| (w[1].1 - w[0].1) / 0.01)
                .fold(f64::INFINITY, f64::min);
            assert!(
                hardest >= c.curve_deceleration * 1.01,
                "R={r}: braked at {hardest}"
            );
            // ...and it did not brake needlessly early: still at the road speed
            // 200 m before the arc (braking from 25 to 7.75 m/s at 2 m/s^2 takes 141 m).
            let early = run.iter().find(|(s, _)| *s >= lead - 200.0).unwrap().1;
            assert!(
                early > 0.99 * c.preferred_speed,
                "R={r}: {early} 200 m before"
            );
        }
    }

    #[test]
    fn the_paper_corridor_caps_large_radii_far_below_the_curve_speed() {
        // The reason for the arc corridor, in numbers: at R = 500 m and a lane's
        // half width (1.75 m), the ray cast sees sqrt(2 R w + w^2) = 41.9 m
        // and the steady speed of the stopping law for it solves
        // v tau + v^2 / (-2 b_f) = d - s0 (14.7 m/s with tau = 1, b_f = -4);
        // the curve speed at 2 m/s^2 is sqrt(1000) = 31.6 m/s.
        let (r, w) = (500.0_f64, 1.75_f64);
        let d = (2.0 * r * w + w * w).sqrt();
        let c = ControllerConfig::default();
        let steady = {
            // v^2 / 8 + v - d = 0
            let b = -2.0 * c.max_deceleration;
            -c.reaction_time * b / 2.0 + ((c.reaction_time * b / 2.0).powi(2) + b * d).sqrt()
        };
        let law = crate::longitudinal::stopping_accel(
            steady,
            d,
            0.0,
            0.0,
            1.0,
            c.max_deceleration,
            c.max_obs_deceleration,
        );
        assert!(law.abs() < 1e-9, "{law}");
        assert!((steady - 14.74).abs() < 0.01, "{steady}");
        assert!((2.0 * r).sqrt() > 2.0 * steady);
    }
}
