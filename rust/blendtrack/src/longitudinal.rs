//! Curvature-aware longitudinal control: virtual borders, ray cast, IDM free
//! flow and the reaction-time stopping law (SPEC §5, paper section IV-C).
//!
//! The corridor around the path ([`Corridor`]) has a left border
//! `C(s) + w_l(s) n(s)` and a right border `C(s) - w_r(s) n(s)`, with `n` the
//! unit normal at each vertex (perpendicular to the interpolated tangent). A
//! ray from the vehicle along its direction of travel gives the distance to
//! the first border it LEAVES the corridor through ([`Corridor::ray_cast`]);
//! crossings that enter the corridor are ignored, so a vehicle that starts
//! outside the corridor still sees the border ahead of it and not the one it
//! is about to cross inward. That distance is a virtual obstacle standing
//! still; the tighter the curve, the closer it is, so the speed follows the
//! curvature without any curvature threshold.
//!
//! Acceleration (along the direction of travel):
//! `a = min(a_free, a_r(virtual obstacle), a_r(each real obstacle))`, where
//! - `a_free = a (1 - (|v|/v0)^delta_idm)` (IDM free road, Treiber 2000),
//!   bounded below by `deceleration_factor * preferred_deceleration` so that
//!   being above the preferred speed (after a lowered speed limit, say) brakes
//!   comfortably instead of at the IDM's unbounded rate;
//! - `a_r` is the reaction-time stopping law ([`stopping_accel`]).

use crate::config::ControllerConfig;
use crate::path::Path;
use nalgebra::{Point2, Vector2};

#[inline]
fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// A real obstacle ahead on the path: a leader vehicle, a stop line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    /// Bumper-to-bumper gap along the path (m).
    pub gap_m: f64,
    /// Its speed along the direction of travel (m/s, >= 0; 0 for a stop line).
    pub speed_mps: f64,
}

/// IDM free-flow acceleration with the comfort bound of [`ControllerConfig::deceleration_factor`].
#[inline]
pub fn free_flow_accel(speed_abs: f64, cfg: &ControllerConfig) -> f64 {
    let a = cfg.preferred_acceleration
        * (1.0 - (speed_abs / cfg.preferred_speed).powf(cfg.acceleration_exp));
    a.max(cfg.deceleration_factor * cfg.preferred_deceleration)
}

/// The reaction-time stopping law (the larger root): the acceleration that,
/// held for `tau` and followed by braking at `b_f`, stops exactly where an
/// obstacle at `gap_m` moving at `v_l` and braking at `b_l` stops, keeping
/// `s0`. Falls back to `b_l` when no such acceleration exists (`U < 0`).
///
/// `v` is the speed along the direction of travel (>= 0), `b_f`, `b_l` < 0.
#[inline]
pub fn stopping_accel(v: f64, gap_m: f64, v_l: f64, s0: f64, tau: f64, b_f: f64, b_l: f64) -> f64 {
    let u = (b_f * b_l * tau * tau + 4.0 * b_l * v * tau + 4.0 * v_l * v_l
        - 8.0 * b_l * (gap_m - s0))
        / (4.0 * b_f * b_l);
    if !(u >= 0.0) {
        return b_l;
    }
    (b_f * tau - 2.0 * v - 2.0 * b_f * u.sqrt()) / (2.0 * tau)
}

/// Longitudinal command and what decided it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LongitudinalOutput {
    pub accel_mps2: f64,
    pub free_flow_mps2: f64,
    /// Acceleration the virtual obstacle alone would ask for (+inf if none).
    pub virtual_obstacle_mps2: f64,
}

/// `min(a_free, a_r(virtual obstacle at d_obs), a_r(obstacles))`.
pub fn longitudinal_accel(
    speed_abs: f64,
    d_obs: Option<f64>,
    obstacles: &[Obstacle],
    cfg: &ControllerConfig,
) -> LongitudinalOutput {
    let free = free_flow_accel(speed_abs, cfg);
    let law = |gap: f64, vl: f64| {
        stopping_accel(
            speed_abs,
            gap,
            vl.max(0.0),
            cfg.preferred_stop_dist,
            cfg.reaction_time,
            cfg.max_deceleration,
            cfg.max_obs_deceleration,
        )
    };
    let virt = d_obs.map(|d| law(d, 0.0)).unwrap_or(f64::INFINITY);
    let mut a = free.min(virt);
    for o in obstacles {
        if o.gap_m.is_finite() && o.speed_mps.is_finite() {
            a = a.min(law(o.gap_m, o.speed_mps));
        } else if o.gap_m.is_nan() || o.speed_mps.is_nan() {
            // An obstacle we cannot read is treated as a wall right here.
            a = a.min(cfg.max_obs_deceleration);
        }
    }
    LongitudinalOutput {
        accel_mps2: a,
        free_flow_mps2: free,
        virtual_obstacle_mps2: virt,
    }
}

/// The virtual borders of a path.
#[derive(Debug, Clone)]
pub struct Corridor {
    left: Vec<Point2<f64>>,
    right: Vec<Point2<f64>>,
    max_width_m: f64,
}

impl Corridor {
    /// Borders from the path's own widths (plus `margin_m` each side) when it
    /// has them and `use_path_widths`, else `path_width_m / 2` each side.
    pub fn new(path: &Path, cfg: &ControllerConfig) -> Self {
        let vs = path.vertex_s();
        let half = 0.5 * cfg.path_width_m;
        let mut left = Vec::with_capacity(vs.len());
        let mut right = Vec::with_capacity(vs.len());
        let mut max_w: f64 = 0.0;
        for (i, p) in path.points().iter().enumerate() {
            let h = path.heading_at(vs[i]);
            let n = Vector2::new(-h.sin(), h.cos());
            let (wr, wl) = match (cfg.use_path_widths, path.widths()) {
                (true, Some(w)) => (
                    (w[i].right_m + cfg.border_margin_m).max(0.0),
                    (w[i].left_m + cfg.border_margin_m).max(0.0),
                ),
                _ => (half, half),
            };
            max_w = max_w.max(wr).max(wl);
            left.push(p + n * wl);
            right.push(p - n * wr);
        }
        Corridor {
            left,
            right,
            max_width_m: max_w,
        }
    }

    pub fn left(&self) -> &[Point2<f64>] {
        &self.left
    }
    pub fn right(&self) -> &[Point2<f64>] {
        &self.right
    }

    /// Distance along the ray from `origin` in direction `heading_rad` to the
    /// first border segment it leaves the corridor through, looking at border
    /// segments from a little behind `s_origin` up to `horizon_m` ahead along
    /// the path. `None` = free road.
    ///
    /// Scanning stops early once the scanned arc length exceeds
    /// `2 t_best + 2 w_max + 5 m`: a border segment that far along the path
    /// can only be closer along the ray if the track folds back on itself
    /// within that distance, which the tests check against [`Self::ray_cast_all`]
    /// on real tracks.
    pub fn ray_cast(
        &self,
        path: &Path,
        origin: &Point2<f64>,
        heading_rad: f64,
        s_origin: f64,
        horizon_m: f64,
    ) -> Option<f64> {
        let u = Vector2::new(heading_rad.cos(), heading_rad.sin());
        let n_seg = path.n_segments();
        let vs = path.vertex_s();
        let back = self.max_width_m + 1.0;
        let start_s = if path.is_closed() {
            s_origin - back
        } else {
            (s_origin - back).max(0.0)
        };
        let mut k = path.segment_at(start_s);
        let mut best = f64::INFINITY;
        let mut scanned_len = 0.0;
        let total = back + horizon_m;
        for _ in 0..n_seg {
            if let Some(t) = self.segment_exit(k, &u, origin) {
                best = best.min(t);
            }
            let k1 = if k + 1 < vs.len() { k + 1 } else { 0 };
            let seg_len = if k1 == 0 {
                path.length() - vs[k]
            } else {
                vs[k1] - vs[k]
            };
            scanned_len += seg_len;
            if scanned_len > total || scanned_len - back > 2.0 * best + 2.0 * self.max_width_m + 5.0
            {
                break;
            }
            if !path.is_closed() && k + 1 >= n_seg {
                break;
            }
            k = (k + 1) % n_seg;
        }
        if best.is_finite() {
            Some(best)
        } else {
            None
        }
    }

    /// Ray cast against every border segment (reference for tests).
    pub fn ray_cast_all(&self, path: &Path, origin: &Point2<f64>, heading_rad: f64) -> Option<f64> {
        let u = Vector2::new(heading_rad.cos(), heading_rad.sin());
        let best = (0..path.n_segments())
            .filter_map(|k| self.segment_exit(k, &u, origin))
            .fold(f64::INFINITY, f64::min);
        if best.is_finite() {
            Some(best)
        } else {
            None
        }
    }

    /// Smallest ray parameter at which the ray leaves the corridor through
    /// segment `k` of either border.
    #[inline]
    fn segment_exit(&self, k: usize, u: &Vector2<f64>, o: &Point2<f64>) -> Option<f64> {
        let n = self.left.len();
        let k1 = (k + 1) % n;
        let mut best: Option<f64> = None;
        // Left border: leaving = ray crosses it from its right to its left.
        for (a, b, leaving_sign) in [
            (&self.left[k], &self.left[k1], 1.0),
            (&self.right[k], &self.right[k1], -1.0),
        ] {
            let e = b - a;
            let denom = cross(u, &e);
            if denom.abs() < 1e-15 || cross(&e, u) * leaving_sign <= 0.0 {
                continue;
            }
            let ao = a - o;
            let t = cross(&ao, &e) / denom;
            let lam = cross(&ao, u) / denom;
            if t >= 0.0 && (0.0..=1.0).contains(&lam) {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stopping_law_identity_on_a_grid() {
        // v tau + a tau^2/2 + (v + a tau)^2 / (-2 b_f) = s - s0 + v_l^2 / (-2 b_l)
        let mut checked = 0;
        for &v in &[0.0, 1.0, 5.0, 20.0] {
            for &gap in &[5.0, 30.0, 100.0] {
                for &vl in &[0.0, 3.0, 15.0] {
                    for &(tau, bf, bl) in &[(1.0, -4.0, -8.0), (0.5, -3.0, -6.0), (1.5, -2.0, -9.0)]
                    {
                        let s0 = 2.0;
                        let u = (bf * bl * tau * tau + 4.0 * bl * v * tau + 4.0 * vl * vl
                            - 8.0 * bl * (gap - s0))
                            / (4.0 * bf * bl);
                        let a = stopping_accel(v, gap, vl, s0, tau, bf, bl);
                        if u < 0.0 {
                            assert_eq!(a, bl);
                            continue;
                        }
                        let lhs =
                            v * tau + a * tau * tau / 2.0 + (v + a * tau).powi(2) / (-2.0 * bf);
                        let rhs = gap - s0 + vl * vl / (-2.0 * bl);
                        assert!(
                            (lhs - rhs).abs() < 1e-9 * rhs.abs().max(1.0),
                            "v={v} gap={gap} vl={vl}: {lhs} vs {rhs}"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 80);
    }

    #[test]
    fn stopping_law_u_negative_brakes_at_bl() {
        // Fast, obstacle standing, almost no gap, gap below s0.
        let a = stopping_accel(30.0, 0.5, 0.0, 2.0, 1.0, -4.0, -8.0);
        assert_eq!(a, -8.0);
    }

    #[test]
    fn free_flow_and_comfort_bound() {
        let cfg = ControllerConfig::default();
        assert_eq!(free_flow_accel(0.0, &cfg), 1.0);
        assert!(free_flow_accel(cfg.preferred_speed, &cfg).abs() < 1e-12);
        // At twice v0 the IDM alone asks 1 - 2^3 = -7 m/s^2; the bound is 2 x -1.
        assert_eq!(free_flow_accel(2.0 * cfg.preferred_speed, &cfg), -2.0);
        let slightly = free_flow_accel(1.1 * cfg.preferred_speed, &cfg);
        assert!(
            (slightly - (1.0 - 1.1f64.powi(3))).abs() < 1e-12,
            "bound inactive near v0"
        );
    }

    #[test]
    fn min_over_obstacles() {
        let cfg = ControllerConfig::default();
        let far = longitudinal_accel(3.0, None, &[], &cfg);
        assert_eq!(far.accel_mps2, far.free_flow_mps2);
        let near = longitudinal_accel(3.0, Some(4.0), &[], &cfg);
        assert!(near.accel_mps2 < 0.0 && near.accel_mps2 == near.virtual_obstacle_mps2);
        let leader = longitudinal_accel(
            3.0,
            None,
            &[
                Obstacle {
                    gap_m: 3.0,
                    speed_mps: 0.0,
                },
                Obstacle {
                    gap_m: 50.0,
                    speed_mps: 0.0,
                },
            ],
            &cfg,
        );
        let expected = stopping_accel(3.0, 3.0, 0.0, 0.0, 1.0, -4.0, -8.0);
        assert_eq!(leader.accel_mps2, expected);
        let nan = longitudinal_accel(
            3.0,
            None,
            &[Obstacle {
                gap_m: f64::NAN,
                speed_mps: 0.0,
            }],
            &cfg,
        );
        assert_eq!(nan.accel_mps2, cfg.max_obs_deceleration);
    }

    #[test]
    fn ray_cast_circle_closed_form() {
        for &r in &[10.0, 50.0, 200.0] {
            for &w in &[1.0, 3.0, 6.0] {
                let path = Path::circle(r, 1e-4).unwrap();
                let cfg = ControllerConfig {
                    path_width_m: 2.0 * w,
                    ..Default::default()
                };
                let cor = Corridor::new(&path, &cfg);
                for s in [0.0, 20.0, 55.0] {
                    let p = path.point_at(s);
                    let h = path.heading_at(s);
                    let d = cor
                        .ray_cast(&path, &p, h, s, 500.0)
                        .expect("a curve always has a hit");
                    let expected = (2.0 * r * w + w * w).sqrt();
                    assert!(
                        (d - expected).abs() < 2e-3 * expected,
                        "R={r} w={w}: {d} vs {expected}"
                    );
                    assert_eq!(Some(d), cor.ray_cast_all(&path, &p, h));
                }
            }
        }
    }

    #[test]
    fn straight_corridor_is_free_road_and_exits_only() {
        let path = Path::straight(1000.0, 5.0).unwrap();
        let cor = Corridor::new(&path, &ControllerConfig::default());
        assert_eq!(
            cor.ray_cast(&path, &Point2::new(10.0, 0.0), 0.0, 10.0, 200.0),
            None
        );
        // Heading 30 deg left from the centre: leaves through the left border at y = 6.
        let d = cor
            .ray_cast(
                &path,
                &Point2::new(10.0, 0.0),
                30f64.to_radians(),
                10.0,
                200.0,
            )
            .unwrap();
        assert!((d - 12.0).abs() < 1e-9, "{d}");
        // Outside on the right, heading back in at 30 deg: the entry is ignored, the exit counts.
        let d = cor
            .ray_cast(
                &path,
                &Point2::new(10.0, -8.0),
                30f64.to_radians(),
                10.0,
                200.0,
            )
            .unwrap();
        assert!((d - 28.0).abs() < 1e-9, "{d}");
    }
}
