//! Kinematic bicycle model with actuator limits, actuation delay and sensor noise (SPEC §2).
//!
//! The reference point is the middle of the rear axle:
//! `x' = v cos(theta)`, `y' = v sin(theta)`, `theta' = v tan(delta) / E`.
//! For constant `(v, delta)` over a step the motion is an exact circular arc
//! ([`integrate_pose`]). Each [`Vehicle::step`] first moves the actuators
//! toward the (possibly delayed) command within their limits, then integrates
//! the pose along the arc with the new speed and steering.
//!
//! Speeds are signed (`v < 0` drives backwards). The acceleration command is
//! along the direction of travel of the selected [`Direction`] (a "gear"):
//! braking brings the vehicle to a stop and holds it there, it never reverses
//! it, exactly as brakes do.

use crate::error::StateError;
use crate::path::wrap_angle;
use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Direction of travel ("gear").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    #[default]
    Forward,
    Backward,
}

impl Direction {
    /// +1 forward, -1 backward.
    #[inline]
    pub fn sign(self) -> f64 {
        match self {
            Direction::Forward => 1.0,
            Direction::Backward => -1.0,
        }
    }
}

/// Full state of the vehicle (true, not measured).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleState {
    /// Rear-axle position, world frame (m).
    pub x_m: f64,
    pub y_m: f64,
    /// Heading (rad, CCW from +x, wrapped to (-pi, pi]).
    pub theta_rad: f64,
    /// Signed speed (m/s); < 0 backwards.
    pub v_mps: f64,
    /// Steering angle (rad), > 0 turns left.
    pub delta_rad: f64,
}

impl VehicleState {
    pub fn rear(&self) -> Point2<f64> {
        Point2::new(self.x_m, self.y_m)
    }
    pub fn heading_vec(&self) -> Vector2<f64> {
        Vector2::new(self.theta_rad.cos(), self.theta_rad.sin())
    }
    /// Point at fraction `alpha` of the wheelbase from the rear axle: P(alpha).
    pub fn control_point(&self, wheelbase_m: f64, alpha: f64) -> Point2<f64> {
        self.rear() + self.heading_vec() * (alpha * wheelbase_m)
    }
    /// Returns an error naming the first non-finite field.
    pub fn check_finite(&self) -> Result<(), StateError> {
        for (field, value) in [
            ("x_m", self.x_m),
            ("y_m", self.y_m),
            ("theta_rad", self.theta_rad),
            ("v_mps", self.v_mps),
            ("delta_rad", self.delta_rad),
        ] {
            if !value.is_finite() {
                return Err(StateError::NonFinite { field, value });
            }
        }
        Ok(())
    }
}

/// Exact pose after `dt` seconds at constant speed and steering.
#[inline]
pub fn integrate_pose(
    x: f64,
    y: f64,
    theta: f64,
    v: f64,
    delta: f64,
    wheelbase_m: f64,
    dt: f64,
) -> (f64, f64, f64) {
    integrate_pose_trig(
        x,
        y,
        theta,
        || (theta.sin(), theta.cos()),
        v,
        delta,
        wheelbase_m,
        dt,
    )
    .0
}

/// An angle with its sine and cosine (`theta_rad.sin()`, `theta_rad.cos()`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HeadingTrig {
    pub theta_rad: f64,
    pub sin: f64,
    pub cos: f64,
}

impl HeadingTrig {
    /// `(cos, sin)` of `theta_rad` ([`VehicleState::heading_vec`]): these
    /// if `trig` is of that very angle (the same bits), else computed.
    #[inline]
    pub fn heading_vec(trig: Option<HeadingTrig>, theta_rad: f64) -> Vector2<f64> {
        match trig {
            Some(t) if t.theta_rad.to_bits() == theta_rad.to_bits() => Vector2::new(t.cos, t.sin),
            _ => Vector2::new(theta_rad.cos(), theta_rad.sin()),
        }
    }
}

/// [`integrate_pose`] for a caller that has `(theta.sin(), theta.cos())`
/// already (`sin_cos` gives them, asked only on an arc; the same doubles),
/// and on an arc the sine and cosine it took of the end heading before
/// wrapping it (the next step's heading, when the wrap leaves it as it is).
#[inline]
#[allow(clippy::too_many_arguments)]
pub(crate) fn integrate_pose_trig(
    x: f64,
    y: f64,
    theta: f64,
    sin_cos: impl FnOnce() -> (f64, f64),
    v: f64,
    delta: f64,
    wheelbase_m: f64,
    dt: f64,
) -> ((f64, f64, f64), Option<HeadingTrig>) {
    let omega = v * delta.tan() / wheelbase_m;
    let dth = omega * dt;
    if dth.abs() < 1e-9 {
        // Second-order expansion of the arc: exact to O(dth^2) which is ~1e-18 here.
        let th_mid = theta + 0.5 * dth;
        (
            (
                x + v * dt * th_mid.cos(),
                y + v * dt * th_mid.sin(),
                wrap_angle(theta + dth),
            ),
            None,
        )
    } else {
        let r = v / omega;
        let th1 = theta + dth;
        let (sin_theta, cos_theta) = sin_cos();
        let (sin1, cos1) = (th1.sin(), th1.cos());
        (
            (
                x + r * (sin1 - sin_theta),
                y - r * (cos1 - cos_theta),
                wrap_angle(th1),
            ),
            Some(HeadingTrig {
                theta_rad: th1,
                sin: sin1,
                cos: cos1,
            }),
        )
    }
}

/// One step of a vehicle without delay (what [`Vehicle::step`] does with
/// the command it applies): the actuators move toward `cmd` within their
/// limits, then the pose is integrated. Returns the next state and the
/// acceleration applied along travel, and the end heading's sine and
/// cosine when it has them ([`integrate_pose_trig`]). `sin_cos`: as
/// [`integrate_pose_trig`].
#[inline]
pub(crate) fn advance(
    state: &VehicleState,
    p: &VehicleParams,
    direction: Direction,
    cmd: Command,
    dt: f64,
    sin_cos: impl FnOnce() -> (f64, f64),
) -> (VehicleState, f64, Option<HeadingTrig>) {
    let dmax = p.max_steering_rad();
    let rate = p.max_steering_rate_rad_s() * dt;
    let target = if cmd.steering_rad.is_finite() {
        cmd.steering_rad.clamp(-dmax, dmax)
    } else {
        state.delta_rad
    };
    let delta =
        (state.delta_rad + (target - state.delta_rad).clamp(-rate, rate)).clamp(-dmax, dmax);
    let a = if cmd.accel_mps2.is_finite() {
        cmd.accel_mps2
    } else {
        0.0
    };
    let a = a.clamp(p.max_braking_mps2, p.max_acceleration_mps2);
    let sgn = direction.sign();
    let v_travel = state.v_mps * sgn;
    let v_new = (v_travel + a * dt).clamp(0.0, p.max_speed_mps);
    let applied = (v_new - v_travel) / dt;
    let v = v_new * sgn;
    let ((x, y, th), trig) = integrate_pose_trig(
        state.x_m,
        state.y_m,
        state.theta_rad,
        sin_cos,
        v,
        delta,
        p.wheelbase_m,
        dt,
    );
    (
        VehicleState {
            x_m: x,
            y_m: y,
            theta_rad: th,
            v_mps: v,
            delta_rad: delta,
        },
        applied,
        trig,
    )
}

/// Physical limits of the vehicle and its actuators.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleParams {
    /// Wheelbase E (m).
    pub wheelbase_m: f64,
    /// Largest steering angle magnitude (deg).
    pub max_steering_deg: f64,
    /// Largest steering rate magnitude (deg/s).
    pub max_steering_rate_deg_s: f64,
    /// Largest acceleration along the direction of travel (m/s^2, > 0).
    pub max_acceleration_mps2: f64,
    /// Strongest braking (m/s^2, < 0).
    pub max_braking_mps2: f64,
    /// Speed cap (m/s, > 0).
    pub max_speed_mps: f64,
}

impl Default for VehicleParams {
    fn default() -> Self {
        VehicleParams {
            wheelbase_m: 2.6,
            max_steering_deg: 40.0,
            max_steering_rate_deg_s: 30.0,
            max_acceleration_mps2: 3.0,
            max_braking_mps2: -9.0,
            max_speed_mps: 70.0,
        }
    }
}

impl VehicleParams {
    pub fn max_steering_rad(&self) -> f64 {
        self.max_steering_deg.to_radians()
    }
    pub fn max_steering_rate_rad_s(&self) -> f64 {
        self.max_steering_rate_deg_s.to_radians()
    }
}

/// A small, seeded, reproducible PRNG (SplitMix64). Our own so that noise
/// sequences stay identical across dependency upgrades and platforms.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Uniform in [-a, a).
    pub fn symmetric(&mut self, a: f64) -> f64 {
        (2.0 * self.next_f64() - 1.0) * a
    }
}

/// Sensor noise on the measured pose (x, y, theta). Speed and steering are
/// measured exactly.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum NoiseModel {
    #[default]
    None,
    /// i.i.d. uniform noise, new sample every step: position in [-pos, pos] on
    /// each axis, heading in [-heading, heading].
    Uniform { position_m: f64, heading_deg: f64 },
    /// Clamped random walk per component: `e <- clamp(e + U(-step, step), -max, max)`,
    /// updated every `interval_s`.
    RandomWalk {
        position_step_m: f64,
        position_max_m: f64,
        heading_step_deg: f64,
        heading_max_deg: f64,
        interval_s: f64,
    },
}

impl NoiseModel {
    /// Every magnitude non-negative and the random walk's interval positive
    /// (NaN fails, as any comparison with it does).
    pub fn is_valid(&self) -> bool {
        match *self {
            NoiseModel::None => true,
            NoiseModel::Uniform {
                position_m: p,
                heading_deg: h,
            } => p >= 0.0 && h >= 0.0,
            NoiseModel::RandomWalk {
                position_step_m: ps,
                position_max_m: pm,
                heading_step_deg: hs,
                heading_max_deg: hm,
                interval_s: dt,
            } => [ps, pm, hs, hm].iter().all(|&x| x >= 0.0) && dt > 0.0,
        }
    }
}

/// Stateful sensor: applies a [`NoiseModel`] with its own seeded generator.
#[derive(Debug, Clone)]
pub struct Sensor {
    model: NoiseModel,
    rng: SplitMix64,
    offset: [f64; 3],
    since_update_s: f64,
}

impl Sensor {
    pub fn new(model: NoiseModel, seed: u64) -> Self {
        Sensor {
            model,
            rng: SplitMix64::new(seed),
            offset: [0.0; 3],
            since_update_s: f64::INFINITY,
        }
    }

    /// The measured state after `dt` seconds since the last measurement.
    pub fn measure(&mut self, truth: &VehicleState, dt: f64) -> VehicleState {
        match self.model {
            NoiseModel::None => return *truth,
            NoiseModel::Uniform {
                position_m,
                heading_deg,
            } => {
                self.offset = [
                    self.rng.symmetric(position_m),
                    self.rng.symmetric(position_m),
                    self.rng.symmetric(heading_deg.to_radians()),
                ];
            }
            NoiseModel::RandomWalk {
                position_step_m,
                position_max_m,
                heading_step_deg,
                heading_max_deg,
                interval_s,
            } => {
                self.since_update_s += dt;
                if self.since_update_s >= interval_s - 1e-9 || !self.since_update_s.is_finite() {
                    self.since_update_s = 0.0;
                    let steps = [
                        position_step_m,
                        position_step_m,
                        heading_step_deg.to_radians(),
                    ];
                    let maxs = [position_max_m, position_max_m, heading_max_deg.to_radians()];
                    for i in 0..3 {
                        self.offset[i] = (self.offset[i] + self.rng.symmetric(steps[i]))
                            .clamp(-maxs[i], maxs[i]);
                    }
                }
            }
        }
        VehicleState {
            x_m: truth.x_m + self.offset[0],
            y_m: truth.y_m + self.offset[1],
            theta_rad: wrap_angle(truth.theta_rad + self.offset[2]),
            ..*truth
        }
    }
}

/// A command to the actuators.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    /// Requested steering angle (rad).
    pub steering_rad: f64,
    /// Requested acceleration along the direction of travel (m/s^2).
    pub accel_mps2: f64,
}

/// The simulated vehicle: true state, limits, gear and the delay line.
#[derive(Debug, Clone)]
pub struct Vehicle {
    pub state: VehicleState,
    pub params: VehicleParams,
    pub direction: Direction,
    /// Commands sent but not yet applied (at most `delay_steps`).
    delay: VecDeque<Command>,
    delay_steps: usize,
    /// The priming "hold" command, and how many of it are still to come out
    /// of the line before the first queued command: the line fills as steps
    /// are taken, so a long delay allocates nothing up front.
    hold: Command,
    hold_left: usize,
    /// Acceleration actually applied in the last step (after limits), along travel.
    pub applied_accel_mps2: f64,
}

impl Vehicle {
    /// `delay_steps` = round(delay / dt) commands are held back; the line is
    /// primed with "hold the current steering, zero acceleration".
    pub fn new(
        state: VehicleState,
        params: VehicleParams,
        direction: Direction,
        delay_steps: usize,
    ) -> Self {
        let hold = Command {
            steering_rad: state.delta_rad,
            accel_mps2: 0.0,
        };
        Vehicle {
            state,
            params,
            direction,
            delay: VecDeque::new(),
            delay_steps,
            hold,
            hold_left: delay_steps,
            applied_accel_mps2: 0.0,
        }
    }

    pub fn delay_steps(&self) -> usize {
        self.delay_steps
    }

    /// Advances one step of `dt` seconds with `cmd` entering the delay line.
    pub fn step(&mut self, cmd: Command, dt: f64) {
        let cmd = if self.delay_steps == 0 {
            cmd
        } else {
            self.delay.push_back(cmd);
            if self.hold_left > 0 {
                self.hold_left -= 1;
                self.hold
            } else {
                self.delay.pop_front().unwrap_or(cmd)
            }
        };
        let theta = self.state.theta_rad;
        let (state, applied, _) =
            advance(&self.state, &self.params, self.direction, cmd, dt, || {
                (theta.sin(), theta.cos())
            });
        self.state = state;
        self.applied_accel_mps2 = applied;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn the_end_headings_sine_and_cosine_are_the_next_states_heading_vec() {
        let mut reused = 0;
        for i in 0..20_000 {
            let f = i as f64;
            let theta = (f * 0.618_033_988_7).fract() * 7.0 - 3.5;
            let delta = ((f * 0.414_213_562).fract() - 0.5) * 0.8;
            let v = ((f * 0.732_050_807).fract() - 0.3) * 40.0;
            let st = VehicleState {
                x_m: 3.0,
                y_m: -2.0,
                theta_rad: theta,
                v_mps: v,
                delta_rad: delta,
            };
            let (x, y, th) = integrate_pose(3.0, -2.0, theta, v, delta, 2.7, 0.1);
            let ((x2, y2, th2), trig) =
                integrate_pose_trig(3.0, -2.0, theta, || theta.sin_cos(), v, delta, 2.7, 0.1);
            assert_eq!(
                [x, y, th].map(f64::to_bits),
                [x2, y2, th2].map(f64::to_bits)
            );
            let next = VehicleState {
                theta_rad: th,
                ..st
            };
            let h = HeadingTrig::heading_vec(trig, th);
            assert_eq!(
                [h.x.to_bits(), h.y.to_bits()],
                [
                    next.heading_vec().x.to_bits(),
                    next.heading_vec().y.to_bits()
                ],
                "theta {theta} v {v} delta {delta}"
            );
            reused += trig.is_some_and(|t| t.theta_rad == th) as usize;
        }
        assert!(reused > 10_000, "{reused}");
    }

    #[test]
    fn noise_models_with_a_negative_nan_or_zero_interval_are_invalid() {
        let walk = |ps: f64, dt: f64| NoiseModel::RandomWalk {
            position_step_m: ps,
            position_max_m: 1.0,
            heading_step_deg: 0.1,
            heading_max_deg: 1.0,
            interval_s: dt,
        };
        let uniform = |p: f64| NoiseModel::Uniform {
            position_m: p,
            heading_deg: 0.5,
        };
        assert!(NoiseModel::None.is_valid());
        assert!(uniform(0.0).is_valid() && walk(0.0, 0.1).is_valid());
        for bad in [
            uniform(-0.1),
            uniform(f64::NAN),
            walk(-1.0, 0.1),
            walk(0.1, 0.0),
            walk(0.1, f64::NAN),
        ] {
            assert!(!bad.is_valid(), "{bad:?}");
        }
    }

    #[test]
    fn integrator_matches_closed_form_circle() {
        // Constant steering: the rear axle moves on a circle of radius E / tan(delta).
        let e = 2.6;
        let delta: f64 = 0.2;
        let v = 5.0;
        let r = e / delta.tan();
        let dt = 0.01;
        let (mut x, mut y, mut th) = (0.0, 0.0, 0.0);
        let n = 3000;
        for _ in 0..n {
            (x, y, th) = integrate_pose(x, y, th, v, delta, e, dt);
        }
        let t = n as f64 * dt;
        let phi = v * t / r;
        let (xe, ye) = (r * phi.sin(), r * (1.0 - phi.cos()));
        assert!(
            (x - xe).abs() < 1e-9 && (y - ye).abs() < 1e-9,
            "({x},{y}) vs ({xe},{ye})"
        );
        assert!(wrap_angle(th - phi).abs() < 1e-9);
        // Backwards: retraces the same circle.
        for _ in 0..n {
            (x, y, th) = integrate_pose(x, y, th, -v, delta, e, dt);
        }
        assert!(x.abs() < 1e-8 && y.abs() < 1e-8 && th.abs() < 1e-8);
    }

    #[test]
    fn actuator_limits_and_delay() {
        let params = VehicleParams::default();
        let mut veh = Vehicle::new(VehicleState::default(), params, Direction::Forward, 3);
        let cmd = Command {
            steering_rad: 1.0,
            accel_mps2: 100.0,
        };
        for _ in 0..3 {
            veh.step(cmd, 0.1);
            assert_eq!(veh.state.delta_rad, 0.0, "delay holds the command back");
            assert_eq!(veh.state.v_mps, 0.0);
        }
        veh.step(cmd, 0.1);
        let rate = params.max_steering_rate_rad_s() * 0.1;
        assert!((veh.state.delta_rad - rate).abs() < 1e-12, "rate limited");
        assert!(
            (veh.state.v_mps - params.max_acceleration_mps2 * 0.1).abs() < 1e-12,
            "accel limited"
        );
        for _ in 0..100 {
            veh.step(cmd, 0.1);
        }
        assert!(
            (veh.state.delta_rad - params.max_steering_rad()).abs() < 1e-12,
            "angle limited"
        );
    }

    #[test]
    fn braking_stops_and_holds_both_directions() {
        for dir in [Direction::Forward, Direction::Backward] {
            let s = VehicleState {
                v_mps: 1.0 * dir.sign(),
                ..Default::default()
            };
            let mut veh = Vehicle::new(s, VehicleParams::default(), dir, 0);
            for _ in 0..50 {
                veh.step(
                    Command {
                        steering_rad: 0.0,
                        accel_mps2: -5.0,
                    },
                    0.1,
                );
            }
            assert_eq!(veh.state.v_mps, 0.0);
            veh.step(
                Command {
                    steering_rad: 0.0,
                    accel_mps2: 1.0,
                },
                0.1,
            );
            assert!((veh.state.v_mps - 0.1 * dir.sign()).abs() < 1e-12);
        }
    }

    #[test]
    fn noise_is_seeded_bounded_and_walk_is_clamped() {
        let truth = VehicleState {
            x_m: 1.0,
            y_m: 2.0,
            theta_rad: 0.5,
            v_mps: 3.0,
            delta_rad: 0.1,
        };
        let m = NoiseModel::Uniform {
            position_m: 0.1,
            heading_deg: 2.0,
        };
        let mut a = Sensor::new(m, 7);
        let mut b = Sensor::new(m, 7);
        let mut c = Sensor::new(m, 8);
        let mut differs = false;
        for _ in 0..1000 {
            let ma = a.measure(&truth, 0.01);
            assert_eq!(ma, b.measure(&truth, 0.01));
            differs |= ma != c.measure(&truth, 0.01);
            assert!((ma.x_m - 1.0).abs() <= 0.1 && (ma.theta_rad - 0.5).abs() <= 2f64.to_radians());
            assert_eq!(ma.v_mps, 3.0);
        }
        assert!(differs);
        let w = NoiseModel::RandomWalk {
            position_step_m: 0.05,
            position_max_m: 0.2,
            heading_step_deg: 1.0,
            heading_max_deg: 3.0,
            interval_s: 0.1,
        };
        let mut s = Sensor::new(w, 1);
        let mut maxdev: f64 = 0.0;
        let mut prev = s.measure(&truth, 0.01);
        let mut changes = 0;
        for _ in 0..10_000 {
            let m = s.measure(&truth, 0.01);
            maxdev = maxdev.max((m.x_m - 1.0).abs());
            if m != prev {
                changes += 1;
            }
            prev = m;
        }
        assert!(
            maxdev <= 0.2 + 1e-12 && maxdev > 0.15,
            "walk reaches but never exceeds its clamp: {maxdev}"
        );
        assert!(
            (900..=1100).contains(&changes),
            "updates every interval: {changes}"
        );
        let _ = PI;
    }
}
