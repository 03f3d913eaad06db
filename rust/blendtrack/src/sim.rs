//! Closed-loop simulation: path + vehicle + controller + alpha schedule +
//! noise + delay, stepped at a fixed `dt`, returning a column-wise time series.
//!
//! Each step: the sensor measures the true state (with noise), the controller
//! turns the measurement into a command, the command enters the delay line,
//! the vehicle's actuators move toward the command that leaves it, and the
//! pose is integrated along the exact arc. The recorded errors are those of
//! the TRUE control point `P(alpha)` (what a ground-truth observer measures),
//! not of the noisy measurement.

use crate::config::{validate_vehicle, ControllerConfig};
use crate::controller::{Controller, Track};
use crate::error::{Error, StateError};
use crate::lateral::AlphaSchedule;
use crate::limits::{count_within, fmt_number, MAX_SIM_STEPS};
use crate::longitudinal::Obstacle;
use crate::path::wrap_angle;
use crate::vehicle::{
    Command, Direction, NoiseModel, Sensor, Vehicle, VehicleParams, VehicleState,
};
use std::f64::consts::PI;
use std::sync::Arc;

/// How a run is set up.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    pub dt_s: f64,
    /// Stop after this much simulated time.
    pub duration_s: f64,
    /// Stop earlier once this many laps (of the path length) are driven.
    pub laps: Option<f64>,
    pub noise: NoiseModel,
    /// Actuation delay (s); `round(delay / dt)` steps.
    pub delay_s: f64,
    pub seed: u64,
    /// Arc length of the start point.
    pub start_s_m: f64,
    /// Initial lateral offset of the rear axle (m, > 0 left of the path).
    pub initial_offset_m: f64,
    /// Initial heading error (deg) relative to the direction of travel.
    pub initial_heading_error_deg: f64,
    /// Initial speed magnitude (m/s).
    pub initial_speed_mps: f64,
    /// Hold this speed magnitude instead of running the longitudinal law.
    pub fixed_speed_mps: Option<f64>,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            dt_s: 0.01,
            duration_s: 60.0,
            laps: None,
            noise: NoiseModel::None,
            delay_s: 0.0,
            seed: 0,
            start_s_m: 0.0,
            initial_offset_m: 0.0,
            initial_heading_error_deg: 0.0,
            initial_speed_mps: 0.0,
            fixed_speed_mps: None,
        }
    }
}

impl SimOptions {
    pub fn validate(&self) -> Result<(), StateError> {
        let check = |name: &'static str, v: f64, ok: bool, message: &'static str| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(StateError::Parameter {
                    name,
                    value: v,
                    message,
                })
            }
        };
        check(
            "dt_s",
            self.dt_s,
            self.dt_s > 0.0 && self.dt_s <= 1.0,
            "must be in (0, 1] s",
        )?;
        check(
            "duration_s",
            self.duration_s,
            self.duration_s > 0.0,
            "must be > 0",
        )?;
        if let Some(l) = self.laps {
            check("laps", l, l > 0.0, "must be > 0")?;
        }
        check("delay_s", self.delay_s, self.delay_s >= 0.0, "must be >= 0")?;
        check("start_s_m", self.start_s_m, true, "must be finite")?;
        check(
            "initial_offset_m",
            self.initial_offset_m,
            true,
            "must be finite",
        )?;
        check(
            "initial_heading_error_deg",
            self.initial_heading_error_deg,
            true,
            "must be finite",
        )?;
        check(
            "initial_speed_mps",
            self.initial_speed_mps,
            self.initial_speed_mps >= 0.0,
            "must be >= 0 (a magnitude)",
        )?;
        if let Some(v) = self.fixed_speed_mps {
            check("fixed_speed_mps", v, v >= 0.0, "must be >= 0 (a magnitude)")?;
        }
        let noise_ok = self.noise.is_valid();
        if !noise_ok {
            return Err(StateError::Parameter {
                name: "noise",
                value: f64::NAN,
                message: "amplitudes must be >= 0 and the interval > 0",
            });
        }
        Ok(())
    }
}

/// Column-wise time series of a run (one entry per step, after the step).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    pub t_s: Vec<f64>,
    pub x_m: Vec<f64>,
    pub y_m: Vec<f64>,
    pub theta_rad: Vec<f64>,
    pub v_mps: Vec<f64>,
    pub delta_rad: Vec<f64>,
    pub alpha: Vec<f64>,
    pub s_m: Vec<f64>,
    /// Signed lateral error of the true control point (m).
    pub lateral_error_m: Vec<f64>,
    /// Signed lateral errors of the true front and rear axles (m): the same
    /// two points whatever alpha is (the body error is the larger of the two).
    pub lateral_error_front_m: Vec<f64>,
    pub lateral_error_rear_m: Vec<f64>,
    /// Heading error along the direction of travel at the control point (rad).
    pub heading_error_rad: Vec<f64>,
    /// Applied acceleration along the direction of travel (m/s^2).
    pub accel_mps2: Vec<f64>,
    /// Distance to the virtual obstacle seen by the controller (m, inf = free).
    pub virtual_obstacle_m: Vec<f64>,
    /// Path curvature at the control point (1/m).
    pub curvature_per_m: Vec<f64>,
    /// Distance driven so far (m).
    pub distance_m: Vec<f64>,
}

impl Trace {
    pub fn len(&self) -> usize {
        self.t_s.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
    fn reserve(&mut self, n: usize) {
        for c in [
            &mut self.t_s,
            &mut self.x_m,
            &mut self.y_m,
            &mut self.theta_rad,
            &mut self.v_mps,
            &mut self.delta_rad,
            &mut self.alpha,
            &mut self.s_m,
            &mut self.lateral_error_m,
            &mut self.lateral_error_front_m,
            &mut self.lateral_error_rear_m,
            &mut self.heading_error_rad,
            &mut self.accel_mps2,
            &mut self.virtual_obstacle_m,
            &mut self.curvature_per_m,
            &mut self.distance_m,
        ] {
            c.reserve(n);
        }
    }
}

/// Initial true state: rear axle at `start_s` offset laterally, heading along
/// the direction of travel plus the heading error.
pub fn initial_state(track: &Track, cfg: &ControllerConfig, opts: &SimOptions) -> VehicleState {
    let p = track.path.point_at(opts.start_s_m);
    let h = track.path.heading_at(opts.start_s_m);
    let n = (-h.sin(), h.cos());
    let travel = h + opts.initial_heading_error_deg.to_radians();
    let theta = match cfg.direction {
        Direction::Forward => travel,
        Direction::Backward => travel + PI,
    };
    let speed = opts.fixed_speed_mps.unwrap_or(opts.initial_speed_mps);
    VehicleState {
        x_m: p.x + opts.initial_offset_m * n.0,
        y_m: p.y + opts.initial_offset_m * n.1,
        theta_rad: wrap_angle(theta),
        v_mps: cfg.direction.sign() * speed,
        delta_rad: 0.0,
    }
}

/// Runs one closed-loop simulation entirely in Rust.
pub fn simulate(
    track: Arc<Track>,
    cfg: &ControllerConfig,
    vehicle_params: &VehicleParams,
    schedule: &AlphaSchedule,
    opts: &SimOptions,
) -> Result<Trace, Error> {
    cfg.validate()?;
    validate_vehicle(vehicle_params)?;
    opts.validate()?;
    schedule.validate().map_err(|_| StateError::Parameter {
        name: "alpha_schedule",
        value: f64::NAN,
        message: "invalid schedule (alpha outside [0, 1] or bad knots)",
    })?;
    let dt = opts.dt_s;
    let (n_steps, must_reach_laps) = step_budget(opts, track.path.length(), vehicle_params)?;
    let delay_steps = delay_steps(opts)?;
    let mut vehicle = Vehicle::new(
        initial_state(&track, cfg, opts),
        *vehicle_params,
        cfg.direction,
        delay_steps,
    );
    let mut ctrl = Controller::new(track.clone(), cfg.clone(), vehicle_params)?;
    // The observer of the true control point keeps its own projection hint.
    let mut truth_hint: Option<f64> = None;
    let mut axle_hints: [Option<f64>; 2] = [None, None];
    let mut sensor = Sensor::new(opts.noise, opts.seed);
    let lap_target = opts.laps.map(|l| l * track.path.length());
    let mut trace = Trace::default();
    trace.reserve(n_steps);
    let mut distance = 0.0;
    let no_obstacles: [Obstacle; 0] = [];
    for i in 0..n_steps {
        let t = i as f64 * dt;
        let alpha = schedule.alpha_at(t);
        if let Some(v) = opts.fixed_speed_mps {
            vehicle.state.v_mps = cfg.direction.sign() * v;
        }
        let measured = sensor.measure(&vehicle.state, dt);
        let out = ctrl.step_with_alpha(&measured, alpha, &no_obstacles)?;
        let accel = if opts.fixed_speed_mps.is_some() {
            0.0
        } else {
            out.accel_mps2
        };
        vehicle.step(
            Command {
                steering_rad: out.steering_rad,
                accel_mps2: accel,
            },
            dt,
        );
        if let Some(v) = opts.fixed_speed_mps {
            vehicle.state.v_mps = cfg.direction.sign() * v;
        }
        vehicle.state.check_finite()?;
        distance += vehicle.state.v_mps.abs() * dt;
        let st = vehicle.state;
        let cp = track.path.project_with(
            &st.control_point(vehicle_params.wheelbase_m, out.alpha),
            truth_hint,
        );
        truth_hint = Some(cp.s);
        // The true front (alpha = 1) and rear (alpha = 0) axles, each with its own hint.
        let [front_e, rear_e] = [(0, 1.0), (1, 0.0)].map(|(i, a)| {
            let p = st.control_point(vehicle_params.wheelbase_m, a);
            let pr = track.path.project_with_no_curvature(&p, axle_hints[i]);
            axle_hints[i] = Some(pr.s);
            pr.lateral_m
        });
        let th_travel = crate::lateral::travel_heading(st.theta_rad, cfg.direction);
        trace.t_s.push(t + dt);
        trace.x_m.push(st.x_m);
        trace.y_m.push(st.y_m);
        trace.theta_rad.push(st.theta_rad);
        trace.v_mps.push(st.v_mps);
        trace.delta_rad.push(st.delta_rad);
        trace.alpha.push(out.alpha);
        trace.s_m.push(cp.s);
        trace.lateral_error_m.push(cp.lateral_m);
        trace.lateral_error_front_m.push(front_e);
        trace.lateral_error_rear_m.push(rear_e);
        trace
            .heading_error_rad
            .push(wrap_angle(th_travel - cp.heading_rad));
        trace.accel_mps2.push(vehicle.applied_accel_mps2);
        trace.virtual_obstacle_m.push(out.virtual_obstacle_m);
        trace.curvature_per_m.push(cp.curvature_per_m);
        trace.distance_m.push(distance);
        if lap_target.is_some_and(|l| distance >= l) {
            break;
        }
        if !track.path.is_closed() && out.s_rear_m >= track.path.length() - 1e-6 {
            break;
        }
        if must_reach_laps && i + 1 == n_steps {
            return Err(StateError::TooLarge {
                name: "laps",
                value: opts.laps.unwrap_or(f64::NAN),
                message: format!(
                    "not driven within the limit of {MAX_SIM_STEPS} steps (of the duration's {}): fewer laps or a larger dt",
                    fmt_number((opts.duration_s / dt).round())
                ),
            }
            .into());
        }
    }
    Ok(trace)
}

/// How many steps to run, checked against [`MAX_SIM_STEPS`] before anything
/// is allocated; and whether the run was cut to the limit, so that it must
/// reach its laps within it (or fail, rather than stop early silently).
///
/// Without laps, `duration / dt` steps must fit. With laps, the laps alone
/// must fit at the vehicle's top speed; a longer duration (a generous cap)
/// is then cut to the limit.
fn step_budget(
    opts: &SimOptions,
    path_length_m: f64,
    params: &VehicleParams,
) -> Result<(usize, bool), StateError> {
    let wanted = (opts.duration_s / opts.dt_s).round().max(1.0);
    if let Some(n) = count_within(wanted, MAX_SIM_STEPS) {
        return Ok((n, false));
    }
    let Some(laps) = opts.laps else {
        return Err(StateError::TooLarge {
            name: "duration_s",
            value: opts.duration_s,
            message: format!(
                "{} steps of dt_s = {}, more than the limit of {MAX_SIM_STEPS} steps",
                fmt_number(wanted),
                fmt_number(opts.dt_s)
            ),
        });
    };
    let top_speed = opts.fixed_speed_mps.unwrap_or(params.max_speed_mps);
    let fewest = (laps * path_length_m / (top_speed * opts.dt_s)).ceil();
    if count_within(fewest, MAX_SIM_STEPS).is_none() {
        return Err(StateError::TooLarge {
            name: "laps",
            value: laps,
            message: format!(
                "at least {} steps of dt_s = {} even at {top_speed} m/s, more than the limit of {MAX_SIM_STEPS} steps",
                fmt_number(fewest),
                fmt_number(opts.dt_s)
            ),
        });
    }
    Ok((MAX_SIM_STEPS, true))
}

/// `round(delay / dt)` commands held in the delay line, within [`MAX_SIM_STEPS`].
fn delay_steps(opts: &SimOptions) -> Result<usize, StateError> {
    let n = (opts.delay_s / opts.dt_s).round();
    count_within(n, MAX_SIM_STEPS).ok_or_else(|| StateError::TooLarge {
        name: "delay_s",
        value: opts.delay_s,
        message: format!(
            "{} steps of dt_s = {}, more than the limit of {MAX_SIM_STEPS} steps",
            fmt_number(n),
            fmt_number(opts.dt_s)
        ),
    })
}
