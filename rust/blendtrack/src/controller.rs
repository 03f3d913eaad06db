//! One full controller step: hinted projections, blended lateral command,
//! ray cast and longitudinal law (the unit the benchmark measures).
//!
//! A [`Track`] is a path with its virtual borders. A [`Controller`] holds one
//! vehicle's persistent state between steps (the projection hints of the rear
//! axle, front axle and control point) and turns a measured state into a
//! [`ControlOutput`]: the steering and acceleration commands plus the errors
//! of the control point `P(alpha)` that studies report.

use crate::config::{validate_vehicle, AlphaMode, ControllerConfig, LateralKind};
use crate::curve_speed::{curve_accel, CurveProfile};
use crate::error::{ConfigError, StateError};
use crate::lateral::{
    auto_alpha, blend, lookahead_forcing, pure_pursuit_command_from, rear_command_from,
    stanley_command, steady_curvature, travel_heading, AutoAlphaInputs, AutoAlphaParams,
    LateralGains, Travel,
};
use crate::longitudinal::{longitudinal_accel, relevance_distance, Corridor, Obstacle};
use crate::path::{wrap_angle, Path};
use crate::vehicle::{VehicleParams, VehicleState};
use nalgebra::{Point2, Vector2};
use std::sync::Arc;

/// Largest spacing (m) of the curvature samples automatic alpha reads its
/// steady curvature from (a few samples per wheelbase: a curve or a straight
/// piece shorter than this may fall between two samples).
pub const STEADY_SAMPLE_M: f64 = 0.5;

/// How many equal intervals the steady-curvature window `[from, to]` (m of
/// arc) is sampled in: at most [`STEADY_SAMPLE_M`] apart, between 1 and 256
/// (a window over 128 m is sampled more coarsely).
fn steady_intervals(from: f64, to: f64) -> usize {
    ((to - from) / STEADY_SAMPLE_M).ceil().clamp(1.0, 256.0) as usize
}

/// A path, its virtual borders and its curvature profile.
#[derive(Debug, Clone)]
pub struct Track {
    pub path: Path,
    pub corridor: Corridor,
    /// For the curve speeds (`curve_lateral_accel` > 0).
    pub curves: CurveProfile,
}

impl Track {
    /// Builds the borders from the path's widths or `cfg.path_width_m`.
    pub fn new(path: Path, cfg: &ControllerConfig) -> Self {
        let corridor = Corridor::new(&path, cfg);
        let curves = CurveProfile::new(&path, cfg.curve_smoothing_m);
        Track {
            path,
            corridor,
            curves,
        }
    }
}

/// What one controller step decided and measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOutput {
    /// Steering command (rad), clamped to the vehicle's limit.
    pub steering_rad: f64,
    /// Acceleration command along the direction of travel (m/s^2), before vehicle limits.
    pub accel_mps2: f64,
    /// Blend factor used.
    pub alpha: f64,
    /// Front (Stanley) and rear (curvature-based) commands before blending (rad).
    pub steering_front_rad: f64,
    pub steering_rear_rad: f64,
    /// Arc length of the rear axle's foot point.
    pub s_rear_m: f64,
    /// Signed lateral errors of the rear and the front axle: the same two
    /// points whatever alpha is, so runs with different alphas compare there.
    pub lateral_error_rear_m: f64,
    pub lateral_error_front_m: f64,
    /// Arc length, signed lateral error and heading error of the control point P(alpha).
    pub s_m: f64,
    pub lateral_error_m: f64,
    pub heading_error_rad: f64,
    /// Path curvature at the control point's foot.
    pub curvature_per_m: f64,
    /// Distance to the virtual obstacle (m); +inf on free road and when the
    /// first border crossing lies beyond the distance at which it could change
    /// the command ([`crate::longitudinal::relevance_distance`] plus the corridor width).
    pub virtual_obstacle_m: f64,
}

/// Per-vehicle controller state.
#[derive(Debug, Clone)]
pub struct Controller {
    track: Arc<Track>,
    cfg: ControllerConfig,
    wheelbase_m: f64,
    auto: AutoAlphaParams,
    max_steering_rad: f64,
    hint_rear: Option<f64>,
    hint_front: Option<f64>,
    hint_cp: Option<f64>,
    /// The segments of the last step's foot points (rear, front, control
    /// point) and of the rear law's or pure pursuit's look-ahead point:
    /// where the look-up of each starts (`usize::MAX`: none).
    hint_segments: [usize; 4],
    /// The rear axle and heading of the last step: the hints are moved on by
    /// the distance travelled along that heading since, so each projection
    /// starts next to its foot point.
    last_rear: Option<(Point2<f64>, Vector2<f64>)>,
    /// The border vertices (left, right) where the last ray cast's scans
    /// started: where the next one's look-ups start.
    ray_hints: [usize; 2],
}

impl Controller {
    /// Validates the configuration and vehicle; errors name the key.
    pub fn new(
        track: Arc<Track>,
        cfg: ControllerConfig,
        vehicle: &VehicleParams,
    ) -> Result<Self, ConfigError> {
        cfg.validate()?;
        validate_vehicle(vehicle)?;
        let auto = AutoAlphaParams {
            base_forward: cfg.auto_alpha_forward,
            base_backward: cfg.auto_alpha_backward,
            curve_gain: cfg.auto_alpha_curve_gain,
            curvature_change_gain: cfg.auto_alpha_curvature_change_gain,
            large_error_m: cfg.auto_alpha_large_error_m,
            error_gain: cfg.auto_alpha_error_gain,
        };
        Ok(Controller {
            track,
            cfg,
            wheelbase_m: vehicle.wheelbase_m,
            auto,
            max_steering_rad: vehicle.max_steering_rad(),
            hint_rear: None,
            hint_front: None,
            hint_cp: None,
            hint_segments: [usize::MAX; 4],
            last_rear: None,
            ray_hints: [usize::MAX; 2],
        })
    }

    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }
    fn gains(&self) -> LateralGains<'_> {
        LateralGains::new(&self.cfg, self.wheelbase_m)
    }
    pub fn track(&self) -> &Arc<Track> {
        &self.track
    }

    /// Forgets the projection hints (the next step searches the whole path).
    pub fn reset(&mut self) {
        self.hint_rear = None;
        self.hint_front = None;
        self.hint_cp = None;
        self.hint_segments = [usize::MAX; 4];
        self.last_rear = None;
        self.ray_hints = [usize::MAX; 2];
    }

    /// Starts the projections of the next step from the rear axle at arc
    /// length `s_rear_m` (and the front axle a wheelbase on) instead of a
    /// search of the whole path: on a track that passes the same place more
    /// than once (laps), the whole-path search may pick another lap.
    pub fn seed_hints(&mut self, s_rear_m: f64) {
        self.reset();
        if s_rear_m.is_finite() {
            self.hint_rear = Some(s_rear_m);
            self.hint_front = Some(s_rear_m + self.wheelbase_m);
        }
    }

    /// One step with the configured blend factor.
    pub fn step(
        &mut self,
        measured: &VehicleState,
        obstacles: &[Obstacle],
    ) -> Result<ControlOutput, StateError> {
        self.step_with_alpha(measured, self.cfg.lat_blend_factor, obstacles)
    }

    /// One step under a speed limit: the free-flow law aims at
    /// `min(preferred_speed, speed_limit_mps)` (road lanes carry their limit).
    pub fn step_limited(
        &mut self,
        measured: &VehicleState,
        alpha: f64,
        obstacles: &[Obstacle],
        speed_limit_mps: Option<f64>,
    ) -> Result<ControlOutput, StateError> {
        self.step_limited_along(
            measured,
            measured.heading_vec(),
            alpha,
            obstacles,
            speed_limit_mps,
        )
    }

    /// [`Self::step_limited`] given the measured heading's `(cos, sin)`
    /// ([`VehicleState::heading_vec`]), for a caller that needs it too.
    pub(crate) fn step_limited_along(
        &mut self,
        measured: &VehicleState,
        heading: Vector2<f64>,
        alpha: f64,
        obstacles: &[Obstacle],
        speed_limit_mps: Option<f64>,
    ) -> Result<ControlOutput, StateError> {
        match speed_limit_mps {
            Some(limit) if limit > 0.0 => {
                // Under `curve_lift_min_limit_mps` the curve speeds do not
                // lift the ray's cap: the ray cast alone (curves off).
                let unlifted = self.cfg.curve_with_ray && limit < self.cfg.curve_lift_min_limit_mps;
                let capped = limit < self.cfg.preferred_speed;
                if !(unlifted || capped) {
                    return self.step_along(measured, heading, alpha, obstacles);
                }
                let (saved_v0, saved_ay) = (self.cfg.preferred_speed, self.cfg.curve_lateral_accel);
                if capped {
                    self.cfg.preferred_speed = limit;
                }
                if unlifted {
                    self.cfg.curve_lateral_accel = 0.0;
                }
                let out = self.step_along(measured, heading, alpha, obstacles);
                self.cfg.preferred_speed = saved_v0;
                self.cfg.curve_lateral_accel = saved_ay;
                out
            }
            _ => self.step_along(measured, heading, alpha, obstacles),
        }
    }

    /// The automatic blend factor for this step (`alpha_mode = "auto"`): the
    /// rear law's largest forcing over the preview window ahead of the rear
    /// axle's foot (4 points over `P = max(E, auto_alpha_preview_s |v|)`), the
    /// path's [`steady_curvature`] from the trailing axle's foot to `P` ahead
    /// of the leading axle's (samples at most [`STEADY_SAMPLE_M`] apart) and
    /// the axle errors, through [`auto_alpha`].
    fn auto_alpha(&self, s_rear: f64, e_front: f64, e_rear: f64, speed: f64) -> f64 {
        let g = self.gains();
        let path = &self.track.path;
        let e = g.wheelbase_m;
        let l = g.curvature_lookahead(speed);
        let preview = e.max(self.cfg.auto_alpha_preview_s * speed);
        let mut forcing = 0.0f64;
        for k in 0..4 {
            let s = s_rear + preview * k as f64 / 3.0;
            forcing = forcing.max(lookahead_forcing(path, s, l).abs());
        }
        // Arc length grows along the direction of travel: forward the front
        // axle leads (at s_rear + E), backward it trails (at s_rear - E).
        let (from, to) = match self.cfg.direction {
            crate::vehicle::Direction::Forward => (s_rear, s_rear + e + preview),
            crate::vehicle::Direction::Backward => (s_rear - e, s_rear + preview),
        };
        let n = steady_intervals(from, to);
        let kappa = steady_curvature(
            (0..=n).map(|k| path.curvature_at(from + (to - from) * k as f64 / n as f64)),
        );
        auto_alpha(
            &self.auto,
            &AutoAlphaInputs {
                direction: self.cfg.direction,
                wheelbase_m: g.wheelbase_m,
                target_distance_m: g.target_distance(speed),
                curvature_abs_per_m: kappa,
                forcing_per_m: forcing,
                front_error_abs_m: e_front.abs(),
                rear_error_abs_m: e_rear.abs(),
            },
        )
    }

    /// One step with blend factor `alpha` (in [0, 1]; it may change every
    /// step). With `alpha_mode = "auto"` the blend uses the automatic alpha
    /// instead (still checked: the caller's value must be in [0, 1]).
    pub fn step_with_alpha(
        &mut self,
        measured: &VehicleState,
        alpha: f64,
        obstacles: &[Obstacle],
    ) -> Result<ControlOutput, StateError> {
        self.step_along(measured, measured.heading_vec(), alpha, obstacles)
    }

    /// [`Self::step_with_alpha`] given the measured heading's `(cos, sin)`
    /// (`heading`, [`VehicleState::heading_vec`]).
    #[inline(always)]
    fn step_along(
        &mut self,
        measured: &VehicleState,
        heading: Vector2<f64>,
        alpha: f64,
        obstacles: &[Obstacle],
    ) -> Result<ControlOutput, StateError> {
        check_step_inputs(measured, alpha)?;
        // Borrowed, not cloned: an Arc clone per step is an atomic write to
        // a counter every vehicle on the track shares, which makes threads
        // stepping vehicles of one track fight over its cache line.
        let track: &Track = &self.track;
        let path = &track.path;
        let e = self.wheelbase_m;
        let dir = self.cfg.direction;
        let speed = measured.v_mps.abs();
        let rear_pt = measured.rear();
        let h = heading;
        let front_pt: Point2<f64> = rear_pt + h * e;

        // Hints moved on by the distance travelled since the last step; a
        // projection then starts next to its foot point (Path::project_near).
        let moved = self
            .last_rear
            .map_or(0.0, |(p, h_last)| (rear_pt - p).dot(&h_last));
        self.last_rear = Some((rear_pt, h));
        let near = |hint: Option<f64>| hint.map_or(f64::NAN, |s| s + moved);
        let [seg_rear, seg_front, seg_cp, seg_look] = self.hint_segments;
        let rear = path.project_near_from(&rear_pt, near(self.hint_rear), seg_rear);
        self.hint_rear = Some(rear.s);
        // Every controller projects the front axle: its error is reported.
        // Its curvature is only used (by the reverse Stanley feed-forward)
        // when driving backwards.
        let mut front = path.project_near_from(&front_pt, near(self.hint_front), seg_front);
        if dir == crate::vehicle::Direction::Backward {
            front.curvature_per_m = path.curvature_at_from(front.s, front.segment);
        }
        self.hint_front = Some(front.s);
        let alpha = match self.cfg.alpha_mode {
            AlphaMode::Fixed => alpha,
            AlphaMode::Auto => self.auto_alpha(rear.s, front.lateral_m, rear.lateral_m, speed),
        };
        let (alpha, d_front, d_rear, raw, seg_look) = self.lateral_commands(
            path,
            &front,
            &rear,
            rear_pt,
            measured.theta_rad,
            speed,
            alpha,
            seg_look,
        );
        let steering = raw.clamp(-self.max_steering_rad, self.max_steering_rad);

        let cp_pt = rear_pt + h * (alpha * e);
        let (cp_hint, cp_seg) = match self.hint_cp {
            Some(s) => (s + moved, seg_cp),
            None => (rear.s + alpha * e, rear.segment),
        };
        let mut cp = path.project_near_from(&cp_pt, cp_hint, cp_seg);
        cp.curvature_per_m = path.curvature_at_from(cp.s, cp.segment);
        self.hint_cp = Some(cp.s);
        self.hint_segments = [rear.segment, front.segment, cp.segment, seg_look];
        let th_travel = travel_heading(measured.theta_rad, dir);

        let curves = self.cfg.curve_lateral_accel > 0.0;
        let (d_obs, accel) = if curves && !self.cfg.curve_with_ray {
            // Curve speeds previewed along the arc instead of the virtual obstacle.
            let lon = longitudinal_accel(speed, None, obstacles, &self.cfg);
            let curve = curve_accel(&track.curves, rear.s, speed, &self.cfg);
            (None, lon.accel_mps2.min(curve))
        } else {
            // Crossings beyond the relevance distance cannot change the command.
            let horizon = self
                .cfg
                .ray_horizon_m
                .min(relevance_distance(speed, &self.cfg) + 2.0 * track.corridor.max_width() + 5.0);
            // Forward, the ray runs along the heading: its (cos, sin) is `h`.
            let u = match dir {
                crate::vehicle::Direction::Forward => h,
                crate::vehicle::Direction::Backward => {
                    Vector2::new(th_travel.cos(), th_travel.sin())
                }
            };
            let d_obs = self.track.corridor.ray_cast_along_from(
                path,
                &rear_pt,
                &u,
                rear.s,
                horizon,
                &mut self.ray_hints,
            );
            let lon = longitudinal_accel(speed, d_obs, obstacles, &self.cfg);
            if curves && d_obs.is_some() {
                // The faster of the ray's command and the curve speeds', never
                // above the command without the border (the obstacles' and
                // free flow's): max(ray, min(no border, curve)).
                let free = longitudinal_accel(speed, None, obstacles, &self.cfg).accel_mps2;
                let curve = curve_accel(&track.curves, rear.s, speed, &self.cfg);
                (d_obs, lon.accel_mps2.max(free.min(curve)))
            } else {
                (d_obs, lon.accel_mps2)
            }
        };
        // A finite state within range gives a finite command; should a
        // corner of the geometry still overflow, say so rather than return NaN.
        if !all_finite([steering, accel]) {
            for (field, value) in [
                ("steering command", steering),
                ("acceleration command", accel),
            ] {
                if !value.is_finite() {
                    return Err(StateError::NonFinite { field, value });
                }
            }
        }
        Ok(ControlOutput {
            steering_rad: steering,
            accel_mps2: accel,
            alpha,
            steering_front_rad: d_front,
            steering_rear_rad: d_rear,
            s_rear_m: rear.s,
            lateral_error_rear_m: rear.lateral_m,
            lateral_error_front_m: front.lateral_m,
            s_m: cp.s,
            lateral_error_m: cp.lateral_m,
            heading_error_rad: wrap_angle(th_travel - cp.heading_rad),
            curvature_per_m: cp.curvature_per_m,
            virtual_obstacle_m: d_obs.unwrap_or(f64::INFINITY),
        })
    }

    /// The blend's two commands (NaN for a law a baseline does not use),
    /// the alpha it used, the unclamped steering and the segment of the
    /// rear law's or pure pursuit's look-ahead point (`seg_look`, its
    /// guess: the last step's; unchanged for Stanley).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn lateral_commands(
        &self,
        path: &Path,
        front: &crate::path::Projection,
        rear: &crate::path::Projection,
        rear_pt: Point2<f64>,
        theta_rad: f64,
        speed: f64,
        alpha: f64,
        seg_look: usize,
    ) -> (f64, f64, f64, f64, usize) {
        let dir = self.cfg.direction;
        let travel = Travel {
            theta_rad,
            speed_abs: speed,
            direction: dir,
        };
        let (alpha, d_front, d_rear, seg_look) = match self.cfg.lateral_controller {
            LateralKind::Blend => {
                let df = stanley_command(front, &travel, &self.gains());
                let (dr, look) = rear_command_from(path, rear, &travel, &self.gains(), seg_look);
                (alpha, df, dr, look)
            }
            LateralKind::Stanley => {
                let df = stanley_command(front, &travel, &self.gains());
                (1.0, df, f64::NAN, seg_look)
            }
            LateralKind::PurePursuit => {
                let (dr, look) = pure_pursuit_command_from(
                    path,
                    (rear_pt.x, rear_pt.y),
                    rear,
                    &travel,
                    &self.gains(),
                    seg_look,
                );
                (0.0, f64::NAN, dr, look)
            }
        };
        let raw = match self.cfg.lateral_controller {
            LateralKind::Blend => blend(alpha, d_front, d_rear),
            LateralKind::Stanley => d_front,
            LateralKind::PurePursuit => d_rear,
        };
        (alpha, d_front, d_rear, raw, seg_look)
    }
}

/// A finite state within range and an alpha in [0, 1], or the error naming what is not.
#[inline(always)]
fn check_step_inputs(measured: &VehicleState, alpha: f64) -> Result<(), StateError> {
    // The common case in a few comparisons.
    let m = measured;
    let finite = all_finite([m.x_m, m.y_m, m.theta_rad, m.v_mps, m.delta_rad]);
    let lim = crate::limits::MAX_COORDINATE_M;
    if finite && m.x_m.abs() <= lim && m.y_m.abs() <= lim && (0.0..=1.0).contains(&alpha) {
        return Ok(());
    }
    check_step_inputs_in_full(measured, alpha)
}

/// True when every value is finite, in one comparison: `v - v` is 0 for a
/// finite `v` and NaN otherwise, so the sum is 0 exactly when all are.
#[inline(always)]
#[allow(clippy::eq_op)]
fn all_finite<const N: usize>(values: [f64; N]) -> bool {
    let mut sum = values[0] - values[0];
    for v in &values[1..] {
        sum += v - v;
    }
    sum == 0.0
}

/// [`check_step_inputs`] field by field: the error names the first bad one.
#[cold]
#[inline(never)]
fn check_step_inputs_in_full(measured: &VehicleState, alpha: f64) -> Result<(), StateError> {
    measured.check_finite()?;
    for (name, value) in [("x_m", measured.x_m), ("y_m", measured.y_m)] {
        if value.abs() > crate::limits::MAX_COORDINATE_M {
            return Err(StateError::Parameter {
                name,
                value,
                message: "position beyond 1e9 m: too far out for f64 to resolve the path",
            });
        }
    }
    if !(0.0..=1.0).contains(&alpha) {
        return Err(StateError::Parameter {
            name: "alpha",
            value: alpha,
            message: "must be in [0, 1]",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_steady_curvature_window_is_sampled_at_most_half_a_metre_apart() {
        for (from, to) in [
            (100.0, 110.0),
            (0.0, 3.2),
            (-5.0, 5.0),
            (1000.0, 1000.1),
            (7.0, 70.0),
        ] {
            let n = steady_intervals(from, to);
            let spacing = (to - from) / n as f64;
            assert!(
                n >= 1 && spacing <= STEADY_SAMPLE_M + 1e-12,
                "{from}..{to}: {n}"
            );
            // And no more than needed: one interval fewer would be too far apart.
            assert!(
                n == 1 || (to - from) / (n - 1) as f64 > STEADY_SAMPLE_M,
                "{from}..{to}: {n}"
            );
        }
        assert_eq!(steady_intervals(0.0, 1000.0), 256);
        assert_eq!(steady_intervals(5.0, 5.0), 1);
    }

    /// On a circle of R = 200 m in a lane of half width 1.75 m the ray's
    /// stopping law settles at 11.2 m/s and the curve speed at 2 m/s^2 is
    /// 20 m/s: at 15 m/s the paper's law brakes and the lifted one does not.
    /// Under `curve_lift_min_limit_mps` the lifted controller's output is the
    /// paper's (ray cast alone) bit for bit; at or above it, and without a
    /// limit, it is the lifted one's; the configuration is as it was after.
    #[test]
    fn the_curve_lift_applies_only_at_or_above_its_speed_limit() {
        let path = Path::circle(200.0, 1e-4).unwrap();
        let base = ControllerConfig {
            preferred_speed: 30.0,
            path_width_m: 3.5,
            ..Default::default()
        };
        let lifted = ControllerConfig {
            curve_lateral_accel: 2.0,
            curve_with_ray: true,
            ..base.clone()
        };
        let gated = ControllerConfig {
            curve_lift_min_limit_mps: 60.0 / 3.6,
            ..lifted.clone()
        };
        let make = |cfg: &ControllerConfig| {
            let track = Arc::new(Track::new(path.clone(), cfg));
            Controller::new(track, cfg.clone(), &VehicleParams::default()).unwrap()
        };
        let p0 = path.point_at(0.0);
        let state = VehicleState {
            x_m: p0.x,
            y_m: p0.y,
            theta_rad: path.heading_at(0.0),
            v_mps: 15.0,
            delta_rad: 0.0,
        };
        let bits = |o: &ControlOutput| (o.accel_mps2.to_bits(), o.steering_rad.to_bits());
        for limit in [13.9, 16.0] {
            let paper = make(&base)
                .step_limited(&state, 0.5, &[], Some(limit))
                .unwrap();
            let mut c = make(&gated);
            let out = c.step_limited(&state, 0.5, &[], Some(limit)).unwrap();
            assert_eq!(bits(&out), bits(&paper), "limit {limit}");
            assert!(
                paper.accel_mps2 < 0.0,
                "the ray brakes at 15 m/s: {}",
                paper.accel_mps2
            );
            assert_eq!(c.config().curve_lateral_accel, 2.0);
            assert_eq!(c.config().preferred_speed, 30.0);
        }
        for limit in [Some(60.0 / 3.6), Some(25.0), None] {
            let lift = make(&lifted).step_limited(&state, 0.5, &[], limit).unwrap();
            let out = make(&gated).step_limited(&state, 0.5, &[], limit).unwrap();
            assert_eq!(bits(&out), bits(&lift), "limit {limit:?}");
            assert!(
                lift.accel_mps2 > 0.0,
                "lifted at 15 m/s under 20: {}",
                lift.accel_mps2
            );
        }
        // Without `curve_with_ray` the key changes nothing (the arc corridor).
        let arc = ControllerConfig {
            curve_with_ray: false,
            ..gated.clone()
        };
        let arc_plain = ControllerConfig {
            curve_with_ray: false,
            ..lifted
        };
        let a = make(&arc)
            .step_limited(&state, 0.5, &[], Some(13.9))
            .unwrap();
        let b = make(&arc_plain)
            .step_limited(&state, 0.5, &[], Some(13.9))
            .unwrap();
        assert_eq!(bits(&a), bits(&b));
    }
}
