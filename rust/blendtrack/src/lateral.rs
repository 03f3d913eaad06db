//! Lateral control: Stanley (front axle), the curvature-based rear-axle law,
//! pure pursuit, the barycentric blend and alpha schedules (SPEC §4).
//!
//! All laws are pure functions of errors measured on the path and return a
//! steering angle (rad, > 0 turns left); the caller clamps it.
//!
//! # Rear-axle curvature-based law (paper eq. 5)
//! `delta_rear = delta_1 + delta_2`:
//! - `delta_1` is the pure-pursuit steering of the rear axle toward the target
//!   point `T = foot + d t(s)` on the TANGENT LINE at the rear axle's foot
//!   point, `d` metres ahead. In the path frame the rear axle sits at lateral
//!   offset `e` with heading error `e_t`, so in the vehicle frame
//!   `T = (d cos e_t - e sin e_t, -d sin e_t - e cos e_t)` and
//!   `delta_1 = atan(2 E y_T / (x_T^2 + y_T^2))`, with `x_T^2 + y_T^2 = d^2 + e^2`.
//!   This equals the printed `s atan(2E cos(e_t - atan(d/e_d)) / sqrt(e_d^2 + d^2))`
//!   up to the paper's conventions: with `s = sign(e)`, `e_d = |e|`, the
//!   printed `e_t` measured in the frame mirrored so that the vehicle is on the
//!   left (`s e_t` here), and the paper's steering sign opposite to ours:
//!   `delta_1 = -s atan(2E cos(s e_t - atan(d/e_d)) / sqrt(e_d^2 + d^2))`
//!   wherever `e_d > 0` ([`rear_first_term_printed`], tested). Because `T` lies
//!   on the tangent line, `delta_1` carries no curvature: on a circle with zero
//!   errors it is 0.
//! - `delta_2 = atan((2E / L) asin(kappa / 2)) = atan(E dtheta / L)` with
//!   `dtheta = wrap(theta_path(s + L) - theta)`: the chord `kappa = 2 sin(dtheta/2)`
//!   between the heading and the tangent `L` metres ahead (SPEC). On a circle
//!   of radius R with zero errors `dtheta = L / R` and `delta_rear = atan(E / R)`.
//!
//! # Backward driving (paper eq. 6)
//! For `v < 0` write `theta' = theta + pi`, `v' = -v > 0`. Then
//! `x' = v' cos theta'`, `y' = v' sin theta'` and
//! `theta'' = theta' = v tan(delta)/E = v' tan(-delta)/E`: reversing is a forward
//! bicycle with heading `theta'`, speed `|v|` and steering `-delta` whose
//! non-steered axle (the real rear axle) LEADS. Every law is therefore
//! evaluated with the flipped heading `theta'` (errors along the direction of
//! travel, the path being traversed in its own direction) and its output is
//! negated: `delta = -law(theta')`.
//! - Rear-axle laws (curvature-based, pure pursuit) only use the kinematics of
//!   the non-steered axle, which are the same as forward: they keep their
//!   stability as is.
//! - Stanley at the front axle: reversing, the front axle TRAILS. Linearised on
//!   a straight path with `delta = -(-e_t' - atan(k e_f / (k_soft + |v|)))`,
//!   `b = k / (k_soft + |v|)`: `d/dt (e_f, e_t') = |v| [[b, 2], [-b/E, -1/E]] (e_f, e_t')`,
//!   trace `|v| (b - 1/E)`, determinant `|v|^2 b / E`. It is stable iff
//!   `0 < b < 1/E`, i.e. `k < (k_soft + |v|) / E`. Forward gains (2 to 3) break
//!   this, so reversing uses `stanley_gain_reverse` (default 0.3 < k_soft / E,
//!   stable at every speed). The slow, weakly damped convergence that results
//!   is the reason the paper's test #6 (backward, alpha = 1) tracks worst.
//!   With a weak gain the heading term alone would leave a large steady offset
//!   in curves: reversing, the front axle moves along `theta' + delta`, so on a
//!   path of curvature `kappa` the equilibrium with the front axle ON the path
//!   has `delta = -asin(E kappa)` and `e_t' = asin(E kappa)`, while the
//!   flipped law gives `delta = e_t' + atan(...)`. The reverse Stanley command
//!   therefore adds the feed-forward `-2 asin(E kappa_front)`, which makes that
//!   equilibrium exact without changing the linearised stability.

use crate::config::ControllerConfig;
use crate::path::{wrap_angle, Path, Projection};
use crate::vehicle::Direction;
use serde::{Deserialize, Serialize};

/// Stanley's law at the front axle: `-e_theta - atan(k e / (k_soft + |v|))`.
#[inline]
pub fn stanley(
    e_front_m: f64,
    e_theta_front_rad: f64,
    speed_abs_mps: f64,
    gain: f64,
    softening_mps: f64,
) -> f64 {
    -e_theta_front_rad - (gain * e_front_m / (softening_mps + speed_abs_mps)).atan()
}

/// Steering that puts the rear axle on a circle through a target at
/// `(x, y)` in the vehicle frame: `atan(2 E y / (x^2 + y^2))`; 0 at the target itself.
#[inline]
pub fn pursuit_steering(wheelbase_m: f64, x: f64, y: f64) -> f64 {
    let d2 = x * x + y * y;
    if d2 < 1e-12 {
        0.0
    } else {
        (2.0 * wheelbase_m * y / d2).atan()
    }
}

/// First term of the rear law, geometric form (see module docs).
#[inline]
pub fn rear_first_term(wheelbase_m: f64, e_m: f64, e_theta_rad: f64, d_m: f64) -> f64 {
    let (s, c) = e_theta_rad.sin_cos();
    pursuit_steering(wheelbase_m, d_m * c - e_m * s, -d_m * s - e_m * c)
}

/// First term of the rear law exactly as printed in the paper (eq. 5), mapped
/// to our conventions; defined only for `e != 0`.
pub fn rear_first_term_printed(
    wheelbase_m: f64,
    e_m: f64,
    e_theta_rad: f64,
    d_m: f64,
) -> Option<f64> {
    if e_m == 0.0 {
        return None;
    }
    let s = e_m.signum();
    let e_d = e_m.abs();
    let arg = 2.0 * wheelbase_m * (s * e_theta_rad - (d_m / e_d).atan()).cos()
        / (e_d * e_d + d_m * d_m).sqrt();
    Some(-s * arg.atan())
}

/// Second term of the rear law: `atan((2E/L) asin(kappa/2))` with the chord
/// `kappa = 2 sin(dtheta/2)`, i.e. `atan(E dtheta / L)`.
#[inline]
pub fn rear_second_term(wheelbase_m: f64, dtheta_rad: f64, lookahead_m: f64) -> f64 {
    let kappa = 2.0 * (0.5 * dtheta_rad).sin();
    (2.0 * wheelbase_m / lookahead_m * (0.5 * kappa).clamp(-1.0, 1.0).asin()).atan()
}

/// Tuning of the lateral laws: the controller's config (its `stanley_*`,
/// `target_distance_*`, `curvature_lookahead_gain_s` and `pure_pursuit_*`
/// keys, read where the laws use them, so they are listed once) and the
/// vehicle's wheelbase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LateralGains<'a> {
    pub wheelbase_m: f64,
    pub cfg: &'a ControllerConfig,
}

impl<'a> LateralGains<'a> {
    /// The gains of `cfg` for a vehicle of wheelbase `wheelbase_m`.
    pub fn new(cfg: &'a ControllerConfig, wheelbase_m: f64) -> Self {
        LateralGains { wheelbase_m, cfg }
    }

    /// Target distance `d` of the rear law.
    pub fn target_distance(&self, speed_abs: f64) -> f64 {
        self.cfg
            .target_distance_min_m
            .max(self.cfg.target_distance_gain_s * speed_abs)
    }
    /// Curvature look-ahead `L` of the rear law.
    pub fn curvature_lookahead(&self, speed_abs: f64) -> f64 {
        (2.0 * self.wheelbase_m).max(self.cfg.curvature_lookahead_gain_s * speed_abs)
    }
}

/// Heading along the direction of travel (flipped by pi when reversing).
#[inline]
pub fn travel_heading(theta_rad: f64, direction: Direction) -> f64 {
    match direction {
        Direction::Forward => theta_rad,
        Direction::Backward => wrap_angle(theta_rad + std::f64::consts::PI),
    }
}

/// How the vehicle moves, as the laws see it: its heading `theta_rad`
/// (rad, the body's, whatever the direction), its speed magnitude
/// `speed_abs` (m/s) and its direction of travel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Travel {
    pub theta_rad: f64,
    pub speed_abs: f64,
    pub direction: Direction,
}

impl Travel {
    /// The heading along the direction of travel and its error against the
    /// path's heading at the projection `at` (rad, wrapped).
    #[inline]
    fn heading_and_error(&self, at: &Projection) -> (f64, f64) {
        let th = travel_heading(self.theta_rad, self.direction);
        (th, wrap_angle(th - at.heading_rad))
    }
}

/// Stanley command at the front axle for either direction.
#[inline]
pub fn stanley_command(front: &Projection, m: &Travel, g: &LateralGains) -> f64 {
    let (_, e_theta) = m.heading_and_error(front);
    let k = match m.direction {
        Direction::Forward => g.cfg.stanley_gain,
        Direction::Backward => g.cfg.stanley_gain_reverse,
    };
    let law = stanley(
        front.lateral_m,
        e_theta,
        m.speed_abs,
        k,
        g.cfg.stanley_softening_mps,
    );
    match m.direction {
        Direction::Forward => law,
        Direction::Backward => {
            // Feed-forward that makes "front axle on the path" the equilibrium (see module docs).
            let ff = 2.0
                * (g.wheelbase_m * front.curvature_per_m)
                    .clamp(-1.0, 1.0)
                    .asin();
            -law - ff
        }
    }
}

/// Curvature-based command at the rear axle for either direction.
#[inline]
pub fn rear_command(path: &Path, rear: &Projection, m: &Travel, g: &LateralGains) -> f64 {
    rear_command_from(path, rear, m, g, usize::MAX).0
}

/// [`rear_command`] with a guess of the segment holding the look-ahead
/// point `rear.s + L` (any value; the last step's saves the look-up), and
/// that point's segment.
#[inline(always)]
pub(crate) fn rear_command_from(
    path: &Path,
    rear: &Projection,
    m: &Travel,
    g: &LateralGains,
    lookahead_segment: usize,
) -> (f64, usize) {
    let (th, e_theta) = m.heading_and_error(rear);
    let d = g.target_distance(m.speed_abs);
    let l = g.curvature_lookahead(m.speed_abs);
    let (ahead, segment) = path.heading_and_segment_at_from(rear.s + l, lookahead_segment);
    let dtheta = wrap_angle(ahead - th);
    let law = rear_first_term(g.wheelbase_m, rear.lateral_m, e_theta, d)
        + rear_second_term(g.wheelbase_m, dtheta, l);
    (m.direction.sign() * law, segment)
}

/// Pure pursuit at the rear axle toward the path point `l_d` ahead of the foot.
pub fn pure_pursuit_command(
    path: &Path,
    rear_xy: (f64, f64),
    rear: &Projection,
    m: &Travel,
    g: &LateralGains,
) -> f64 {
    pure_pursuit_command_from(path, rear_xy, rear, m, g, usize::MAX).0
}

/// [`pure_pursuit_command`] with a guess of the segment holding the target
/// point `rear.s + l_d` (as [`rear_command_from`]), and that point's segment.
#[inline(always)]
pub(crate) fn pure_pursuit_command_from(
    path: &Path,
    rear_xy: (f64, f64),
    rear: &Projection,
    m: &Travel,
    g: &LateralGains,
    lookahead_segment: usize,
) -> (f64, usize) {
    let th = travel_heading(m.theta_rad, m.direction);
    let ld = g.cfg.pure_pursuit_gain_s * m.speed_abs + g.cfg.pure_pursuit_min_lookahead_m;
    let (t, segment) = path.point_and_segment_at_from(rear.s + ld, lookahead_segment);
    let (dx, dy) = (t.x - rear_xy.0, t.y - rear_xy.1);
    let (s, c) = th.sin_cos();
    let law = pursuit_steering(g.wheelbase_m, c * dx + s * dy, -s * dx + c * dy);
    (m.direction.sign() * law, segment)
}

/// The paper's blend (eq. 4).
#[inline]
pub fn blend(alpha: f64, delta_front: f64, delta_rear: f64) -> f64 {
    alpha * delta_front + (1.0 - alpha) * delta_rear
}

/// Parameters of the automatic blend factor (the `auto_alpha_*` config keys).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutoAlphaParams {
    /// Alpha in a steady curve (constant curvature, small errors), forward
    /// and backward.
    pub base_forward: f64,
    pub base_backward: f64,
    /// Weight of the path's curvature ahead (dimensionless, on `E |kappa|`).
    pub curve_gain: f64,
    /// Weight of the rear law's predicted look-ahead error (dimensionless).
    pub curvature_change_gain: f64,
    /// Axle error (m) from which the leading axle's law takes over fully.
    pub large_error_m: f64,
    /// Weight of the axle-error balance (1/m).
    pub error_gain: f64,
}

/// What the automatic blend factor is chosen from (one step's state).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutoAlphaInputs {
    pub direction: Direction,
    pub wheelbase_m: f64,
    /// Target distance `d` of the rear law at the current speed (m).
    pub target_distance_m: f64,
    /// Steady |curvature| of the path (1/m): [`steady_curvature`] of the
    /// curvature sampled from the trailing axle's foot to the end of the
    /// preview ahead of the leading axle's foot.
    pub curvature_abs_per_m: f64,
    /// Largest |forcing| of the rear law over the preview window ahead (1/m):
    /// [`lookahead_forcing`] at the rear axle's foot and a few points ahead.
    pub forcing_per_m: f64,
    /// |lateral error| of the front and rear axle (m).
    pub front_error_abs_m: f64,
    pub rear_error_abs_m: f64,
}

/// The rear law's curvature forcing at arc length `s`: the curvature its
/// look-ahead term feeds forward, `(theta_path(s + L) - theta_path(s)) / L`
/// (the mean curvature over the next `L` metres), minus the curvature at
/// `s`. Zero on a circle or a straight line; `c L / 2` on a clothoid whose
/// curvature grows at `c` per metre. Linearised about the path, the rear
/// axle's error obeys `e'' + (2/d + 1/L) e' + (2/d^2) e = forcing(s)` (primes:
/// d/ds), so a forcing `f` held long enough leaves the error `d^2 f / 2`.
pub fn lookahead_forcing(path: &Path, s: f64, lookahead_m: f64) -> f64 {
    let dtheta = wrap_angle(path.heading_at(s + lookahead_m) - path.heading_at(s));
    dtheta / lookahead_m - path.curvature_at(s)
}

/// The curvature the whole vehicle and the preview ahead of it share: the
/// smallest |curvature| of the samples, or 0 when they change sign (an
/// S-bend) or any is 0 (a straight within the window); NaN if any is NaN.
/// On a circle of radius R, 1/R; at a curve's entry or exit (part of the
/// window still on the straight) and in a chicane, 0. An empty window gives 0.
pub fn steady_curvature(samples: impl IntoIterator<Item = f64>) -> f64 {
    let (mut min_abs, mut pos, mut neg, mut any) = (f64::INFINITY, false, false, false);
    for k in samples {
        if k.is_nan() {
            return f64::NAN;
        }
        any = true;
        pos |= k > 0.0;
        neg |= k < 0.0;
        min_abs = min_abs.min(k.abs());
    }
    if !any || (pos && neg) {
        0.0
    } else {
        min_abs
    }
}

/// Automatic blend factor, a pure function of the step's state:
///
/// `alpha = clamp(lead + (base - lead) c (1 - w_k) (1 - w_e) + g_e (|e_front| - |e_rear|), 0, 1)`
///
/// - `lead`: the law of the LEADING axle, which brings the vehicle onto the
///   path fastest and is the most precise on a straight: Stanley (1) forward,
///   the rear law (0) backward (reversing, the rear axle leads and Stanley's
///   gain must stay weak, see the module docs).
/// - `base`: `base_forward` / `base_backward`, the alpha in a steady curve.
///   There a rigid vehicle cannot keep both axles on the path: Stanley puts
///   the front axle on it and the rear axle cuts the curve by about
///   `E^2 |kappa| / 2`; the rear law does the opposite. A control point
///   between them splits the difference (about `E^2 |kappa| / 4` each).
/// - `c = min(1, curve_gain E |kappa|)`, `kappa` the [`steady_curvature`]
///   over the vehicle and the preview ahead of it: how much of a curve there
///   is to balance. Only a curve that holds under both axles and ahead
///   counts: where the curvature changes (entries, exits, chicanes shorter
///   than the window) the vehicle is in a transient, not in the steady curve
///   where moving the control point splits the cut; there the leading law.
/// - `w_k = min(1, curvature_change_gain (d^2 |f| / 2) / E)`: the rear law's
///   predicted steady error where the curvature changes ahead
///   ([`lookahead_forcing`]), in wheelbases; there the leading law keeps the
///   vehicle (Stanley's front error does not depend on the curvature).
/// - `w_e = min(1, max(|e_front|, |e_rear|) / large_error_m)`: far from the
///   path (the initial approach), the leading law.
/// - `g_e (|e_front| - |e_rear|)`: the control point moves toward the axle
///   that is further off the path (`g_e = error_gain`, 1/m).
///
/// Limits (tested): always in [0, 1]; `lead` on a straight path with zero
/// errors, with a saturated forcing, or with an error of `large_error_m` or
/// more on both axles; `base` in a curve with `c = 1`, no forcing and zero
/// errors. A NaN input gives `lead`.
pub fn auto_alpha(p: &AutoAlphaParams, x: &AutoAlphaInputs) -> f64 {
    let (lead, base) = match x.direction {
        Direction::Forward => (1.0, p.base_forward),
        Direction::Backward => (0.0, p.base_backward),
    };
    let inputs = [
        x.wheelbase_m,
        x.target_distance_m,
        x.curvature_abs_per_m,
        x.forcing_per_m,
        x.front_error_abs_m,
        x.rear_error_abs_m,
    ];
    if !inputs.iter().all(|v| v.is_finite()) {
        return lead;
    }
    let e = x.wheelbase_m;
    let d = x.target_distance_m;
    let c = (p.curve_gain * e * x.curvature_abs_per_m.abs()).min(1.0);
    let predicted = 0.5 * d * d * x.forcing_per_m.abs();
    let w_k = (p.curvature_change_gain * predicted / e).min(1.0);
    let (ef, er) = (x.front_error_abs_m.abs(), x.rear_error_abs_m.abs());
    let w_e = (ef.max(er) / p.large_error_m).min(1.0);
    let balance = p.error_gain * (ef - er);
    let a = lead + (base - lead) * c * (1.0 - w_k) * (1.0 - w_e) + balance;
    if a.is_finite() {
        a.clamp(0.0, 1.0)
    } else {
        lead
    }
}

/// How alpha evolves over time. Values are clamped to [0, 1].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum AlphaSchedule {
    Constant {
        alpha: f64,
    },
    /// The paper's moving point: `0.5 (sin(omega t) + 1)`.
    Sine {
        omega_rad_s: f64,
    },
    /// Piecewise linear through `(t, alpha)` knots sorted by time; held
    /// constant before the first and after the last knot.
    Piecewise {
        knots: Vec<(f64, f64)>,
    },
}

impl AlphaSchedule {
    pub fn alpha_at(&self, t: f64) -> f64 {
        let a = match self {
            AlphaSchedule::Constant { alpha } => *alpha,
            AlphaSchedule::Sine { omega_rad_s } => 0.5 * ((omega_rad_s * t).sin() + 1.0),
            AlphaSchedule::Piecewise { knots } => {
                if knots.is_empty() {
                    return 0.5;
                }
                let i = knots.partition_point(|k| k.0 <= t);
                if i == 0 {
                    knots[0].1
                } else if i == knots.len() {
                    knots[knots.len() - 1].1
                } else {
                    let (t0, a0) = knots[i - 1];
                    let (t1, a1) = knots[i];
                    a0 + (a1 - a0) * (t - t0) / (t1 - t0)
                }
            }
        };
        if a.is_finite() {
            a.clamp(0.0, 1.0)
        } else {
            0.5
        }
    }

    /// Checks the schedule; the error text names what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            AlphaSchedule::Constant { alpha } => {
                if !(0.0..=1.0).contains(alpha) {
                    return Err(format!("alpha = {alpha} must be in [0, 1]"));
                }
            }
            AlphaSchedule::Sine { omega_rad_s } => {
                if !omega_rad_s.is_finite() {
                    return Err(format!("omega = {omega_rad_s} must be finite"));
                }
            }
            AlphaSchedule::Piecewise { knots } => {
                if knots.is_empty() {
                    return Err("a piecewise schedule needs at least one (t, alpha) knot".into());
                }
                for (i, (t, a)) in knots.iter().enumerate() {
                    if !t.is_finite() || !(0.0..=1.0).contains(a) {
                        return Err(format!(
                            "knot {i} = ({t}, {a}): t must be finite and alpha in [0, 1]"
                        ));
                    }
                    if i > 0 && *t <= knots[i - 1].0 {
                        return Err(format!("knot {i}: times must increase strictly"));
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn travel(theta_rad: f64, speed_abs: f64, direction: Direction) -> Travel {
        Travel {
            theta_rad,
            speed_abs,
            direction,
        }
    }

    /// The default config but a stiffer forward Stanley gain (with E = 2.6 m).
    fn stiff_config() -> ControllerConfig {
        ControllerConfig {
            stanley_gain: 2.5,
            ..Default::default()
        }
    }

    #[test]
    fn geometric_first_term_equals_printed_formula() {
        let mut n = 0;
        for &e in &[-4.0, -1.0, -0.01, 0.02, 0.5, 3.0, 10.0] {
            for &et in &[-1.2, -0.3, 0.0, 0.1, 0.7, 1.4] {
                for &d in &[0.5, 2.0, 6.0, 30.0] {
                    let g = rear_first_term(2.6, e, et, d);
                    let p = rear_first_term_printed(2.6, e, et, d).unwrap();
                    assert!((g - p).abs() < 1e-12, "e={e} et={et} d={d}: {g} vs {p}");
                    n += 1;
                }
            }
        }
        assert_eq!(n, 168);
        assert_eq!(rear_first_term_printed(2.6, 0.0, 0.1, 2.0), None);
        assert!(rear_first_term(2.6, 0.0, 0.0, 0.0).is_finite());
    }

    #[test]
    fn first_term_steers_back_toward_the_path() {
        assert!(
            rear_first_term(2.6, 1.0, 0.0, 3.0) < 0.0,
            "left of the path: steer right"
        );
        assert!(rear_first_term(2.6, -1.0, 0.0, 3.0) > 0.0);
        assert!(stanley(1.0, 0.0, 3.0, 2.5, 1.0) < 0.0);
        assert!(stanley(0.0, 0.2, 3.0, 2.5, 1.0) < 0.0);
    }

    #[test]
    fn second_term_is_ackermann_of_chord() {
        for &dth in &[-1.0, -0.2, 0.0, 0.3, 1.5] {
            let l = 6.0;
            assert!((rear_second_term(2.6, dth, l) - (2.6 * dth / l).atan()).abs() < 1e-12);
        }
    }

    #[test]
    fn curvature_lookahead_is_twice_the_wheelbase_or_the_speed_term() {
        // L = max(2 E, 2 s * |v|) with the default gain of 2 s, E = 2.5 m.
        let cfg = ControllerConfig::default();
        assert_eq!(cfg.curvature_lookahead_gain_s, 2.0);
        let g = LateralGains::new(&cfg, 2.5);
        assert_eq!(g.curvature_lookahead(0.0), 5.0);
        assert_eq!(g.curvature_lookahead(1.0), 5.0);
        assert_eq!(g.curvature_lookahead(10.0), 20.0);
    }

    #[test]
    fn pure_pursuit_aims_at_the_point_l_d_ahead_of_the_foot() {
        // Straight path along +x, rear axle 1 m to its left heading +x at
        // 10 m/s: l_d = 0.5 s * 10 + 2 = 7 m, the target 7 m ahead on the
        // path, at (7, -1) in the vehicle frame: atan(2 E (-1) / (49 + 1)).
        let cfg = ControllerConfig {
            pure_pursuit_gain_s: 0.5,
            pure_pursuit_min_lookahead_m: 2.0,
            ..Default::default()
        };
        let g = LateralGains::new(&cfg, 2.6);
        let path = Path::straight(200.0, 1.0).unwrap();
        let rear = (50.0, 1.0);
        let pr = path.project(&nalgebra::Point2::new(rear.0, rear.1));
        let d = pure_pursuit_command(&path, rear, &pr, &travel(0.0, 10.0, Direction::Forward), &g);
        let expected = (-(2.0 * 2.6) / 50.0f64).atan();
        assert!((d - expected).abs() < 1e-12, "{d} vs {expected}");
    }

    #[test]
    fn rear_law_on_circle_with_zero_errors_gives_ackermann() {
        let cfg = stiff_config();
        let g = LateralGains::new(&cfg, 2.6);
        for r in [10.0, 50.0, 200.0] {
            let path = Path::circle(r, 1e-4).unwrap();
            for &v in &[1.0, 3.0, 10.0] {
                for s in [0.0, 17.0, 40.0] {
                    let p = path.point_at(s);
                    let th = path.heading_at(s);
                    let pr = path.project(&p);
                    let d = rear_command(&path, &pr, &travel(th, v, Direction::Forward), &g);
                    let expected = (2.6 / r).atan();
                    assert!(
                        (d - expected).abs() < 1e-3,
                        "R={r} v={v} s={s}: {d} vs {expected}"
                    );
                    // Backwards along the same path (heading flipped): the
                    // steering that keeps the rear axle on the circle is the negative.
                    let db = rear_command(&path, &pr, &travel(th + PI, v, Direction::Backward), &g);
                    assert!((db + expected).abs() < 1e-3, "backward R={r}: {db}");
                }
            }
        }
    }

    #[test]
    fn schedules() {
        let s = AlphaSchedule::Sine { omega_rad_s: 0.2 };
        assert!((s.alpha_at(0.0) - 0.5).abs() < 1e-12);
        assert!((s.alpha_at(PI / 0.4) - 1.0).abs() < 1e-12);
        let p = AlphaSchedule::Piecewise {
            knots: vec![(0.0, 0.0), (10.0, 1.0), (20.0, 0.5)],
        };
        assert_eq!(p.alpha_at(-1.0), 0.0);
        assert!((p.alpha_at(5.0) - 0.5).abs() < 1e-12);
        assert!((p.alpha_at(15.0) - 0.75).abs() < 1e-12);
        assert_eq!(p.alpha_at(99.0), 0.5);
        assert!(p.validate().is_ok());
        assert!(AlphaSchedule::Piecewise {
            knots: vec![(1.0, 0.0), (1.0, 1.0)]
        }
        .validate()
        .is_err());
        assert!(AlphaSchedule::Constant { alpha: 1.2 }.validate().is_err());
        assert_eq!(
            AlphaSchedule::Constant { alpha: f64::NAN }.alpha_at(0.0),
            0.5
        );
    }

    fn auto_inputs(
        direction: Direction,
        kappa: f64,
        forcing: f64,
        e_f: f64,
        e_r: f64,
    ) -> AutoAlphaInputs {
        AutoAlphaInputs {
            direction,
            wheelbase_m: 2.6,
            target_distance_m: 4.0,
            curvature_abs_per_m: kappa,
            forcing_per_m: forcing,
            front_error_abs_m: e_f,
            rear_error_abs_m: e_r,
        }
    }

    #[test]
    fn auto_alpha_limits() {
        let p = AutoAlphaParams {
            base_forward: 0.4,
            base_backward: 0.7,
            curve_gain: 10.0,
            curvature_change_gain: 2.0,
            large_error_m: 0.5,
            error_gain: 0.0,
        };
        let (fw, bw) = (Direction::Forward, Direction::Backward);
        // Straight path, on it: the leading axle's law.
        assert_eq!(auto_alpha(&p, &auto_inputs(fw, 0.0, 0.0, 0.0, 0.0)), 1.0);
        assert_eq!(auto_alpha(&p, &auto_inputs(bw, 0.0, 0.0, 0.0, 0.0)), 0.0);
        // Steady curve (c = min(1, 10 * 2.6 * 0.05) = 1), no forcing, on the path: the base.
        assert!((auto_alpha(&p, &auto_inputs(fw, 0.05, 0.0, 0.0, 0.0)) - 0.4).abs() < 1e-12);
        assert!((auto_alpha(&p, &auto_inputs(bw, 0.05, 0.0, 0.0, 0.0)) - 0.7).abs() < 1e-12);
        // A gentle curve: c = 10 * 2.6 * 0.01 = 0.26 of the way to the base.
        let a = auto_alpha(&p, &auto_inputs(fw, 0.01, 0.0, 0.0, 0.0));
        assert!((a - (1.0 - 0.6 * 0.26)).abs() < 1e-12, "{a}");
        // Forcing f: predicted error d^2 f / 2 = 8 f; w_k = 2 * 8 f / 2.6.
        let f = 0.01;
        let w_k = 2.0 * 8.0 * f / 2.6;
        let a = auto_alpha(&p, &auto_inputs(fw, 0.05, -f, 0.0, 0.0));
        assert!((a - (1.0 - 0.6 * (1.0 - w_k))).abs() < 1e-12, "{a}");
        // Saturated forcing, or far from the path: the leading law.
        assert_eq!(auto_alpha(&p, &auto_inputs(fw, 0.05, 1.0, 0.0, 0.0)), 1.0);
        assert_eq!(auto_alpha(&p, &auto_inputs(fw, 0.05, 0.0, 0.5, 0.6)), 1.0);
        assert_eq!(auto_alpha(&p, &auto_inputs(bw, 0.05, 0.0, 3.0, 0.0)), 0.0);
        // Half way to the large error: half way back from the base.
        let a = auto_alpha(&p, &auto_inputs(fw, 0.05, 0.0, 0.25, 0.25));
        assert!((a - 0.7).abs() < 1e-12, "{a}");
        // Error balance: toward the axle that is further off.
        let pe = AutoAlphaParams {
            error_gain: 2.0,
            ..p
        };
        let a = auto_alpha(&pe, &auto_inputs(fw, 0.05, 0.0, 0.15, 0.05));
        let w_e = 0.15 / 0.5;
        assert!((a - (1.0 - 0.6 * (1.0 - w_e) + 0.2)).abs() < 1e-12, "{a}");
        let a = auto_alpha(&pe, &auto_inputs(bw, 0.05, 0.0, 0.05, 0.15));
        assert!((a - (0.7 * (1.0 - w_e) - 0.2)).abs() < 1e-12, "{a}");
        // Always in [0, 1], whatever the inputs; NaN gives the leading law.
        for &k in &[0.0, 0.02, 1.0] {
            for &f in &[0.0, 1e-3, 10.0] {
                for &ef in &[0.0, 0.1, 5.0] {
                    for &er in &[0.0, 0.1, 5.0] {
                        for dir in [fw, bw] {
                            let a = auto_alpha(&pe, &auto_inputs(dir, k, f, ef, er));
                            assert!((0.0..=1.0).contains(&a), "{k} {f} {ef} {er}: {a}");
                        }
                    }
                }
            }
        }
        assert_eq!(
            auto_alpha(&p, &auto_inputs(fw, f64::NAN, 0.0, 0.0, 0.0)),
            1.0
        );
        assert_eq!(
            auto_alpha(&p, &auto_inputs(bw, 0.05, f64::NAN, 0.0, 0.0)),
            0.0
        );
    }

    #[test]
    fn steady_curvature_is_the_curve_the_whole_window_shares() {
        // One sign: the smallest magnitude (the curve under the whole window).
        assert_eq!(steady_curvature([0.05, 0.04, 0.06]), 0.04);
        assert_eq!(steady_curvature([-0.05, -0.04, -0.06]), 0.04);
        assert_eq!(steady_curvature([0.025]), 0.025);
        // A straight piece inside (an entry or exit), or a change of sign (an
        // S-bend): no steady curve.
        assert_eq!(steady_curvature([0.0, 0.02, 0.05]), 0.0);
        assert_eq!(steady_curvature([0.05, 0.05, -0.001]), 0.0);
        assert_eq!(steady_curvature(std::iter::empty()), 0.0);
        assert!(steady_curvature([0.05, f64::NAN, 0.05]).is_nan());
        // The old reading (largest |kappa|) would give 0.06 and 0.05 here.
        assert!(steady_curvature([0.0, 0.06]) < steady_curvature([0.01, 0.06]));
    }

    #[test]
    fn lookahead_forcing_closed_forms() {
        // Zero on a circle (constant curvature) and on a straight line.
        let c = Path::circle(40.0, 1e-4).unwrap();
        for s in [0.0, 30.0, 100.0] {
            assert!(lookahead_forcing(&c, s, 8.0).abs() < 1e-4);
        }
        let st = Path::straight(200.0, 1.0).unwrap();
        assert!(lookahead_forcing(&st, 50.0, 8.0).abs() < 1e-12);
        // Clothoid kappa(s) = c s: forcing c L / 2.
        let (cc, l) = (1.0 / 2000.0, 10.0);
        let pts = clothoid(cc, 0.05, 100.0);
        let path = Path::new(&pts, None, false).unwrap();
        for s in [20.0, 50.0, 80.0] {
            let f = lookahead_forcing(&path, s, l);
            assert!(
                (f - cc * l / 2.0).abs() < 2e-4,
                "s={s}: {f} vs {}",
                cc * l / 2.0
            );
        }
    }

    /// Points of the clothoid `kappa(s) = c s` from the origin heading +x, every `ds` up to `len`.
    fn clothoid(c: f64, ds: f64, len: f64) -> Vec<[f64; 2]> {
        let n = (len / ds).round() as usize;
        let (mut x, mut y) = (0.0, 0.0);
        let mut out = vec![[x, y]];
        for i in 0..n {
            // Heading at the middle of the step: c s^2 / 2.
            let sm = (i as f64 + 0.5) * ds;
            let th = 0.5 * c * sm * sm;
            x += ds * th.cos();
            y += ds * th.sin();
            out.push([x, y]);
        }
        out
    }
}
