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
//! - `a_r` is the reaction-time stopping law ([`stopping_accel`]). For the
//!   virtual obstacle it is bounded below by `max_deceleration` (b_f): the
//!   border ahead in a curve is a comfort limit, not a wall, so it never
//!   triggers the emergency braking at b_l that the law falls back to when
//!   `U < 0`. Followers that expect a leader to brake at most at its normal
//!   deceleration (traffic simulators' car-following models) stay
//!   collision-free behind it.
//!   A soft obstacle ([`Obstacle::soft`]) is bounded the same way.
//!
//! Note that the law is not monotone in the gap: just above the boundary of
//! admissible plans (`U` = 0) it asks for `b_f / 2 - v / tau` (-18 m/s^2 at
//! 16 m/s with the defaults, cut by the actuator), while just below it falls
//! back to `b_l`. For a real obstacle that is the paper's law; for a soft one
//! the bound at `b_f` makes it moot.

use crate::config::ControllerConfig;
use crate::path::Path;
use nalgebra::{Point2, Vector2};

#[inline]
fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// An obstacle ahead on the path: a leader vehicle, a stop line, or (soft)
/// a vehicle to line up behind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    /// Bumper-to-bumper gap along the path (m).
    pub gap_m: f64,
    /// Its speed along the direction of travel (m/s, >= 0; 0 for a stop line).
    pub speed_mps: f64,
    /// A comfort target rather than something in the way (a vehicle on the
    /// lane beside, to line up behind before changing onto it): braking for
    /// it is bounded below by `max_deceleration`, as for the virtual
    /// obstacle, and never reaches the emergency `max_obs_deceleration`.
    pub soft: bool,
    /// A vehicle (or anything a collision is with), as opposed to a line to
    /// stop at: only for a vehicle does braking without a plan go past b_l
    /// toward `emergency_deceleration` (overshooting a line is not a collision).
    pub vehicle: bool,
    /// The reaction time the stopping law takes for this obstacle (s; NaN:
    /// the configured `reaction_time`). A leader seen some time ago and
    /// held where it stops at the worst since ([`Obstacle::with_reaction`])
    /// leaves less of the reaction time to come.
    pub reaction_s: f64,
}

impl Obstacle {
    /// A real obstacle: the stopping law may brake at up to `max_obs_deceleration` for it.
    pub fn new(gap_m: f64, speed_mps: f64) -> Self {
        Obstacle {
            gap_m,
            speed_mps,
            soft: false,
            vehicle: true,
            reaction_s: f64::NAN,
        }
    }

    /// A line to stop at (a stop line, a lane's end): standing, and braked
    /// for at `max_obs_deceleration` at most when there is no plan.
    pub fn line(gap_m: f64) -> Self {
        Obstacle {
            gap_m,
            speed_mps: 0.0,
            soft: false,
            vehicle: false,
            reaction_s: f64::NAN,
        }
    }

    /// A soft obstacle (see the `soft` field): braking for it stops at `max_deceleration`.
    pub fn soft(gap_m: f64, speed_mps: f64) -> Self {
        Obstacle {
            gap_m,
            speed_mps,
            soft: true,
            vehicle: true,
            reaction_s: f64::NAN,
        }
    }

    /// The same obstacle with the stopping law's reaction time `reaction_s`
    /// (s, > 0) in place of the configured one.
    pub fn with_reaction(self, reaction_s: f64) -> Self {
        Obstacle { reaction_s, ..self }
    }
}

/// IDM free-flow acceleration with the comfort bound of [`ControllerConfig::deceleration_factor`].
#[inline]
pub fn free_flow_accel(speed_abs: f64, cfg: &ControllerConfig) -> f64 {
    let a = cfg.preferred_acceleration
        * (1.0 - ratio_pow(speed_abs / cfg.preferred_speed, cfg.acceleration_exp));
    a.max(cfg.deceleration_factor * cfg.preferred_deceleration)
}

/// `x.powf(y)`, without the call where its value is exact and known: 1 at
/// `x = 1` (for every `y`, NaN too: C's `pow`), +0 at `x = +0` for `y > 0`.
/// A vehicle cruising at its preferred speed (the free-flow law's fixed
/// point) or standing still hits these.
#[inline]
fn ratio_pow(x: f64, y: f64) -> f64 {
    if x == 1.0 {
        1.0
    } else if x == 0.0 && x.is_sign_positive() && y > 0.0 {
        0.0
    } else {
        x.powf(y)
    }
}

/// The reaction-time stopping law (the larger root): the acceleration that,
/// held for `tau` and followed by braking at `b_f`, stops exactly where an
/// obstacle at `gap_m` moving at `v_l` and braking at `b_l` stops, keeping
/// `s0`. Falls back to `b_l` when no such acceleration exists (`U < 0`).
///
/// `v` is the speed along the direction of travel (>= 0), `b_f`, `b_l` < 0.
#[inline]
pub fn stopping_accel(v: f64, gap_m: f64, v_l: f64, s0: f64, tau: f64, b_f: f64, b_l: f64) -> f64 {
    stopping_plan(v, gap_m, v_l, s0, tau, b_f, b_l).unwrap_or(b_l)
}

/// The stopping law's acceleration, or `None` where it has no plan (`U < 0`).
#[inline]
pub fn stopping_plan(
    v: f64,
    gap_m: f64,
    v_l: f64,
    s0: f64,
    tau: f64,
    b_f: f64,
    b_l: f64,
) -> Option<f64> {
    let u = (b_f * b_l * tau * tau + 4.0 * b_l * v * tau + 4.0 * v_l * v_l
        - 8.0 * b_l * (gap_m - s0))
        / (4.0 * b_f * b_l);
    if !(u >= 0.0) {
        return None;
    }
    Some((b_f * tau - 2.0 * v - 2.0 * b_f * u.sqrt()) / (2.0 * tau))
}

/// Braking without a plan (`U < 0`) for a real obstacle: `b_l` while
/// braking at `b_l` from now still stops the vehicle before the obstacle's
/// own stopping point (`gap + v_l^2 / (-2 b_l)`, the standstill gap given up);
/// otherwise the constant deceleration that stops it there, down to
/// `b_emergency` (a collision is then certain at `b_l`). Never gentler than `b_l`.
#[inline]
pub fn emergency_accel(v: f64, gap_m: f64, v_l: f64, b_l: f64, b_emergency: f64) -> f64 {
    let room = gap_m + v_l * v_l / (-2.0 * b_l);
    if v * v / (-2.0 * b_l) <= room {
        return b_l;
    }
    let needed = if room > 0.0 {
        -v * v / (2.0 * room)
    } else {
        f64::NEG_INFINITY
    };
    needed.max(b_emergency.min(b_l))
}

/// The gap beyond which a standing obstacle no longer matters: at that gap
/// the stopping law asks for `preferred_acceleration`, more than free flow
/// ever does, so `min(a_free, a_r)` ignores it. Solves the stopping-law
/// identity for `a = preferred_acceleration`, `v_l = 0`:
/// `s0 + v tau + a tau^2 / 2 + (v + a tau)^2 / (-2 b_f)`.
/// The controller casts its ray no further than this (plus the corridor
/// width), which keeps a step cheap at low speed without changing the command.
pub fn relevance_distance(speed_abs: f64, cfg: &ControllerConfig) -> f64 {
    let a = cfg.preferred_acceleration;
    let tau = cfg.reaction_time;
    let v1 = speed_abs + a * tau;
    cfg.preferred_stop_dist
        + speed_abs * tau
        + 0.5 * a * tau * tau
        + v1 * v1 / (-2.0 * cfg.max_deceleration)
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
    // Without a plan: b_l, or harder when b_l can no longer stop the
    // vehicle before a vehicle ahead (the virtual and soft ones cap it below;
    // a line to stop at keeps b_l).
    let law = |gap: f64, vl: f64, vehicle: bool, tau: f64| {
        let vl = vl.max(0.0);
        stopping_plan(
            speed_abs,
            gap,
            vl,
            cfg.preferred_stop_dist,
            tau,
            cfg.max_deceleration,
            cfg.max_obs_deceleration,
        )
        .unwrap_or_else(|| {
            if !vehicle {
                return cfg.max_obs_deceleration;
            }
            emergency_accel(
                speed_abs,
                gap,
                vl,
                cfg.max_obs_deceleration,
                cfg.emergency_deceleration,
            )
        })
    };
    // A curve is not an emergency: braking for the virtual obstacle stops at
    // the planning deceleration b_f; only real obstacles may demand b_l.
    let virt = d_obs
        .map(|d| law(d, 0.0, false, cfg.reaction_time).max(cfg.max_deceleration))
        .unwrap_or(f64::INFINITY);
    let mut a = free.min(virt);
    for o in obstacles {
        let r = if o.gap_m.is_finite() && o.speed_mps.is_finite() {
            let tau = if o.reaction_s > 0.0 {
                o.reaction_s
            } else {
                cfg.reaction_time
            };
            law(o.gap_m, o.speed_mps, o.vehicle, tau)
        } else if o.gap_m.is_nan() || o.speed_mps.is_nan() {
            // An obstacle we cannot read is treated as a wall right here.
            cfg.max_obs_deceleration
        } else {
            continue;
        };
        a = a.min(if o.soft {
            r.max(cfg.max_deceleration)
        } else {
            r
        });
    }
    LongitudinalOutput {
        accel_mps2: a,
        free_flow_mps2: free,
        virtual_obstacle_mps2: virt,
    }
}

/// The virtual borders of a path.
///
/// Each border is kept twice: at full resolution (one vertex per path
/// vertex, [`Corridor::left`], [`Corridor::right`]) and simplified for the
/// ray cast (Douglas-Peucker, 1 cm tolerance), so that a straight stretch of
/// a densely sampled road lane costs one segment test instead of hundreds.
#[derive(Debug, Clone)]
pub struct Corridor {
    left: Vec<Point2<f64>>,
    right: Vec<Point2<f64>>,
    left_simple: Border,
    right_simple: Border,
    max_width_m: f64,
}

/// A simplified border polyline with the path arc length of each vertex.
#[derive(Debug, Clone)]
struct Border {
    pts: Vec<Point2<f64>>,
    s: Vec<f64>,
    closed: bool,
    path_length: f64,
    /// +1 for the left border (leaving = crossing it right to left), -1 for the right.
    leaving_sign: f64,
    /// Per run of `RUN_SEGMENTS` segments, the strip around its chord that
    /// holds all its vertices ([`Strip`]): a ray whose line passes a strip
    /// on one side cannot leave through the run.
    strips: Vec<Strip>,
    /// Per segment, together so a scan reads one record per segment: its
    /// start, its vector and the path arc length at its end.
    segs: Vec<Seg>,
    /// `bucket[b]`: the vertex [`Border::vertex_holding`] gives for arc
    /// length `b / bucket_scale`, where a look-up starts its walk.
    bucket: Vec<u32>,
    bucket_scale: f64,
}

/// One border segment as the ray cast reads it.
#[derive(Debug, Clone, Copy)]
struct Seg {
    /// Start vertex.
    a: Point2<f64>,
    /// End minus start, times `-leaving_sign`: the ray leaves the corridor
    /// through the segment only if `cross(u, e_out) > 0`. A sign change is
    /// exact, so every quantity of [`segment_exit`] is this one's up to an
    /// exact sign change (see [`Border::exit_below`]).
    e_out: Vector2<f64>,
    /// Path arc length at its end (`path_length` for a closed border's
    /// closing segment), so the scan needs no index wrap-around.
    end_s: f64,
}

/// The vertices of a run of border segments, as a strip: every vertex lies
/// within `half_width` of the chord from the run's first vertex to its last
/// (`p1`). `half_width` includes the margin [`Ray::misses_strip`]
/// relies on.
#[derive(Debug, Clone, Copy)]
struct Strip {
    /// The chord's end, the run's last vertex (its start, the run's first
    /// vertex, is the first segment's `a`, and the last run's `p1`).
    p1: Point2<f64>,
    half_width: f64,
    /// The end arc length of the run's last segment (its `end_s`).
    end_s: f64,
}

/// The margin (m) added to a strip's half-width for [`Ray::misses_strip`]:
/// it covers the rounding of the strip test and of the segment test
/// (coordinates up to [`STRIP_MAX_COORDINATE_M`]: errors of a few 1e-6 m)
/// and the segment test's `1 + 1e-6` factor (`STRIP_LENGTH_MARGIN` times
/// the run's longest segment).
const STRIP_MARGIN_M: f64 = 1e-3;
const STRIP_LENGTH_MARGIN: f64 = 4e-6;
/// Beyond this coordinate magnitude (m) of a border vertex or a ray origin
/// the strip test is not used (the margin above would not cover the
/// rounding there).
const STRIP_MAX_COORDINATE_M: f64 = 1e10;

/// Segments per run (strip) of a border.
const RUN_SEGMENTS: usize = 8;

/// Steps [`Border::vertex_holding_from`] walks from its guess before it looks up.
const VERTEX_WALK_STEPS: usize = 4;

/// The last vertex of the sorted arc lengths `s` at or before `at` (with
/// `s[0] <= at`), by at most `steps` steps from vertex `k` (`k < s.len()`);
/// None when that is not enough.
#[inline(always)]
fn walk_to_vertex(s: &[f64], at: f64, mut k: usize, steps: usize) -> Option<usize> {
    for _ in 0..steps {
        if s[k] > at {
            // s[0] <= at: k > 0 here.
            k -= 1;
        } else if k + 1 < s.len() && s[k + 1] <= at {
            k += 1;
        } else {
            // s[k] <= at < s[k + 1] (or k is the last vertex).
            return Some(k);
        }
    }
    None
}

/// A ray `o + t u` with what its strip tests need, computed once per ray cast.
struct Ray<'a> {
    o: &'a Point2<f64>,
    u: &'a Vector2<f64>,
    /// The strip test applies: `o` within [`crate::limits::MAX_COORDINATE_M`]
    /// of the origin on each axis (as the controller's states are) and `u`
    /// a unit vector within 1 %. Otherwise every segment is tested.
    strips: bool,
}

impl<'a> Ray<'a> {
    fn new(o: &'a Point2<f64>, u: &'a Vector2<f64>) -> Self {
        Ray {
            o,
            u,
            strips: o.x.abs() <= crate::limits::MAX_COORDINATE_M
                && o.y.abs() <= crate::limits::MAX_COORDINATE_M
                && (0.98..=1.02).contains(&u.norm_squared()),
        }
    }

    /// `cross(u, p - o)`: the side of the ray's line that `p` is on (> 0
    /// left), times `|u|` its distance from it.
    #[inline(always)]
    fn side(&self, p: &Point2<f64>) -> f64 {
        cross(self.u, &(p - self.o))
    }

    /// True if the ray's line passes a run's [`Strip`] on one side, clear of
    /// it, given the [`Self::side`]s `s0`, `s1` of the strip's chord ends:
    /// then every segment of the run fails the exit test
    /// ([`Border::exit_below`] returns `best` for it, bit for bit).
    ///
    /// Why: write `sigma(v)` for `cross(u, v - o)` computed exactly on the
    /// stored doubles. A vertex within `w` of the chord `[p0, p1]` has a
    /// `sigma` within `|u| w` (`|u| < 1.01`) of a convex combination of
    /// `sigma(p0)` and `sigma(p1)`; each computed side is within 1e-4 m of
    /// its `sigma` (coordinates under [`STRIP_MAX_COORDINATE_M`], `o` under
    /// 1e9 m: each rounding is below 4e-16 of 3e10 m). So if both computed
    /// sides are beyond `half_width` on one side, every vertex of the run
    /// is beyond `STRIP_MARGIN_M + STRIP_LENGTH_MARGIN L - 1e-4` there
    /// (`L` the run's longest segment). For a segment from `a` to `b`, the
    /// exit test's `mm` is `leaving_sign sigma(a)` and its `d` is
    /// `leaving_sign (sigma(a) - sigma(b))`, each within 1e-4 m. With
    /// `leaving_sign sigma` negative at both ends by that much, `mm` is
    /// below `-1e-4`, hence below `-(d 1e-100)`: rejected. With it positive
    /// at both ends, `mm - fl(d (1 + 1e-6))` is at least
    /// `leaving_sign sigma(b) - 1.1e-6 |b - a| - 3e-4`, positive: rejected
    /// too. (A NaN side compares false: the run is tested.)
    #[inline(always)]
    fn misses_strip(&self, s0: f64, s1: f64, half_width: f64) -> bool {
        self.strips
            && ((s0 > half_width && s1 > half_width) || (s0 < -half_width && s1 < -half_width))
    }
}

/// Tolerance of the border simplification (m).
const SIMPLIFY_TOL_M: f64 = 0.01;

/// Indices of the vertices kept by Douglas-Peucker on `pts[lo..=hi]`.
fn simplify(pts: &[Point2<f64>], tol: f64) -> Vec<usize> {
    let n = pts.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((lo, hi)) = stack.pop() {
        if hi <= lo + 1 {
            continue;
        }
        let a = pts[lo];
        let e = pts[hi] - a;
        let len = e.norm();
        let mut worst = (0.0f64, lo);
        for (i, p) in pts.iter().enumerate().take(hi).skip(lo + 1) {
            let d = if len < 1e-12 {
                (p - a).norm()
            } else {
                cross(&e, &(p - a)).abs() / len
            };
            // Also keep vertices that fold back beyond the chord's ends.
            let t = if len < 1e-12 {
                0.0
            } else {
                e.dot(&(p - a)) / (len * len)
            };
            let d = if !(0.0..=1.0).contains(&t) {
                d.max(tol * 2.0)
            } else {
                d
            };
            if d > worst.0 {
                worst = (d, i);
            }
        }
        if worst.0 > tol {
            keep[worst.1] = true;
            stack.push((lo, worst.1));
            stack.push((worst.1, hi));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

/// Distance from `q` to the segment `[a, b]` (to `a` if the two coincide).
fn distance_to_segment(q: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>) -> f64 {
    let e = b - a;
    let l2 = e.norm_squared();
    let t = if l2 > 0.0 {
        (e.dot(&(q - a)) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (q - (a + e * t)).norm()
}

impl Border {
    fn new(
        full: &[Point2<f64>],
        vertex_s: &[f64],
        closed: bool,
        path_length: f64,
        leaving_sign: f64,
    ) -> Self {
        let idx = simplify(full, SIMPLIFY_TOL_M);
        let pts: Vec<Point2<f64>> = idx.iter().map(|&i| full[i]).collect();
        let n = pts.len();
        let n_seg = if closed { n } else { n.saturating_sub(1) };
        let s: Vec<f64> = idx.iter().map(|&i| vertex_s[i]).collect();
        let far = pts
            .iter()
            .any(|p| !(p.x.abs() <= STRIP_MAX_COORDINATE_M && p.y.abs() <= STRIP_MAX_COORDINATE_M));
        let strips = (0..n_seg)
            .step_by(RUN_SEGMENTS)
            .map(|start| {
                let end = (start + RUN_SEGMENTS).min(n_seg);
                let (p0, p1) = (pts[start], pts[end % n]);
                let mut w: f64 = 0.0;
                let mut longest: f64 = 0.0;
                for k in start..end {
                    let q = pts[(k + 1) % n];
                    w = w.max(distance_to_segment(&q, &p0, &p1));
                    longest = longest.max((q - pts[k]).norm());
                }
                // Rounded up generously: the proof needs an upper bound.
                let half_width = if far {
                    f64::INFINITY
                } else {
                    1.02 * w + STRIP_LENGTH_MARGIN * longest + STRIP_MARGIN_M
                };
                Strip {
                    p1,
                    half_width,
                    end_s: if end < n { s[end] } else { path_length },
                }
            })
            .collect();
        let segs = (0..n_seg)
            .map(|k| Seg {
                a: pts[k],
                e_out: (pts[(k + 1) % n] - pts[k]) * -leaving_sign,
                end_s: if k + 1 < n { s[k + 1] } else { path_length },
            })
            .collect();
        // About one bucket per vertex over the border's arc lengths.
        let span = s.last().copied().unwrap_or(0.0).max(path_length);
        let n_buckets = s.len().max(1);
        let bucket_scale = if span > 0.0 {
            n_buckets as f64 / span
        } else {
            0.0
        };
        let bucket = (0..n_buckets)
            .map(|b| {
                let at = b as f64 * span / n_buckets as f64;
                s.partition_point(|&v| v <= at).saturating_sub(1) as u32
            })
            .collect();
        Border {
            pts,
            s,
            segs,
            closed,
            path_length,
            leaving_sign,
            strips,
            bucket,
            bucket_scale,
        }
    }

    fn n_segments(&self) -> usize {
        if self.closed {
            self.pts.len()
        } else {
            self.pts.len() - 1
        }
    }

    /// `s.partition_point(|&v| v <= at).saturating_sub(1)`: the last vertex
    /// at or before arc length `at` (0 if none), by a short walk from the
    /// bucket of `at` (a binary search if the walk is long).
    #[inline]
    fn vertex_holding(&self, at: f64) -> usize {
        let s = &self.s[..];
        // Also false for a NaN `at`, which no vertex is at or before.
        if !s.first().is_some_and(|&s0| at >= s0) {
            return 0;
        }
        let b = ((at * self.bucket_scale) as usize).min(self.bucket.len() - 1);
        walk_to_vertex(s, at, self.bucket[b] as usize, 8)
            .unwrap_or_else(|| s.partition_point(|&v| v <= at).saturating_sub(1))
    }

    /// [`Self::vertex_holding`] by a walk of a few steps from `hint` (the
    /// answer near there, e.g. the last ray cast's), else (a hint out of
    /// range or too far off) by the look-up: the same vertex either way.
    #[inline(always)]
    fn vertex_holding_from(&self, at: f64, hint: usize) -> usize {
        let s = &self.s[..];
        // `at >= s[0]` is also false for a NaN `at` (vertex_holding gives 0).
        if hint < s.len() && at >= s[0] {
            if let Some(k) = walk_to_vertex(s, at, hint, VERTEX_WALK_STEPS) {
                return k;
            }
        }
        self.vertex_holding(at)
    }

    /// Ray parameter at which the ray leaves the corridor through segment `k`.
    #[inline]
    fn exit(&self, k: usize, u: &Vector2<f64>, o: &Point2<f64>) -> Option<f64> {
        let g = &self.segs[k];
        // -leaving_sign e_out is the segment's vector (the sign change is exact).
        segment_exit(
            &g.a,
            &(g.e_out * -self.leaving_sign),
            u,
            o,
            self.leaving_sign,
        )
    }

    /// `best.min(self.exit(k, u, o).unwrap_or(inf))`, bit for bit, cheaper.
    ///
    /// With `e` the segment's vector, [`segment_exit`] computes
    /// `denom = cross(u, e)`, `t = cross(a - o, e) / denom` and
    /// `lam = cross(a - o, u) / denom`. Here `e_out = -leaving_sign e`, so
    /// `d = cross(u, e_out) = -leaving_sign denom` and
    /// `cross(a - o, e_out) = -leaving_sign cross(a - o, e)` exactly (a
    /// change of sign commutes with rounding), and `t` is
    /// `cross(a - o, e_out) / d`, `lam` is `mm / d` with
    /// `mm = -leaving_sign cross(a - o, u)`, the same doubles. Then:
    /// - `segment_exit` goes on only if `|denom| >= 1e-15` and
    ///   `-denom leaving_sign > 0`, that is `d >= 1e-15` (a NaN `d`, which
    ///   this rejects at once, gives a NaN `t` there, rejected too);
    /// - a segment parameter certainly outside [0, 1] (most segments the ray
    ///   meets ahead) rejects the segment before any division: if
    ///   `mm > fl(d (1 + 1e-6))` then `mm / d > 1 + 2^-52` exactly (the
    ///   product rounds down by less than a part in 2^53), so the rounded
    ///   quotient is at least the next double above 1; if
    ///   `mm < -fl(d 1e-100)`, the quotient is below -1e-101, negative also
    ///   after rounding (d >= 1e-15: no underflow). Either way `lam` fails;
    /// - the ray parameter is tested before the segment parameter is
    ///   divided out: a segment the ray meets behind its origin or beyond
    ///   `best` costs one division instead of two.
    ///
    /// (The scan, [`Self::scan_run`], runs its two halves inline; the tests
    /// hold this to `exit`.)
    #[cfg(test)]
    fn exit_below(&self, k: usize, u: &Vector2<f64>, o: &Point2<f64>, best: f64) -> f64 {
        let g = &self.segs[k];
        let d = cross(u, &g.e_out);
        if d >= 1e-15 {
            self.exit_ahead(g, d, u, o, best)
        } else {
            best
        }
    }

    /// The rest of [`Self::exit_below`] for a segment with `d >= 1e-15`.
    #[inline]
    fn exit_ahead(&self, g: &Seg, d: f64, u: &Vector2<f64>, o: &Point2<f64>, best: f64) -> f64 {
        let ao = g.a - o;
        let mm = cross(&ao, u) * -self.leaving_sign;
        if mm > d * (1.0 + 1e-6) || mm < -(d * 1e-100) {
            return best;
        }
        let t = cross(&ao, &g.e_out) / d;
        if !(t > BORDER_TOUCH_M && t < best) {
            return best;
        }
        let lam = mm / d;
        if (0.0..=1.0).contains(&lam) {
            t
        } else {
            best
        }
    }

    /// Smallest exit parameter over the segments from path arc length
    /// `start_s` on, scanning at most `scan_m` of path and stopping early
    /// (see [`Corridor::ray_cast`]).
    ///
    /// In effect, from the segment holding `start_s` on (wrapping round on a
    /// closed border, at most every segment once), each segment updates the
    /// best exit with [`Self::exit_below`]; after each, the scan stops once
    /// the arc length from `start_s` to its end exceeds `scan_m` or
    /// `2 best + slack_m`. The loop goes run by run: the segments of a run
    /// whose strip the ray's line passes clear of ([`Ray::misses_strip`])
    /// cannot change the best exit, so only the end of the run's last one is
    /// checked against the stop (within a run the ends grow, so the scan
    /// stops after the run if and only if it would have stopped within
    /// it); in the other runs a segment costs its test and one comparison.
    ///
    /// `start_hint`: a guess of the vertex holding `start_s` (any value),
    /// set to that vertex.
    #[inline(always)]
    fn first_exit(
        &self,
        ray: &Ray,
        start_s: f64,
        scan_m: f64,
        slack_m: f64,
        start_hint: &mut usize,
    ) -> f64 {
        let segs = &self.segs[..];
        let n_seg = segs.len();
        if n_seg == 0 {
            return f64::INFINITY;
        }
        // Segment holding start_s.
        let start = self.vertex_holding_from(start_s, *start_hint);
        *start_hint = start;
        let k = start.min(n_seg - 1);
        let mut scan = Scan {
            best: f64::INFINITY,
            stop: 0.0,
            start_s,
            scan_m,
            slack_m,
            path_length: self.path_length,
        };
        scan.update_stop();
        let strips = &self.strips[..];
        let n_runs = strips.len();
        let r0 = k / RUN_SEGMENTS;
        let (mut r, mut from) = (r0, k);
        // The side of the current run's first vertex (the last run's `p1`).
        let mut s0 = ray.side(&segs[r0 * RUN_SEGMENTS].a);
        // Each segment is visited at most once: run r0 from segment k on,
        // then whole runs, on a closed border round to the run before r0,
        // and last the part of run r0 before k (if any).
        let visits = if self.closed { n_runs } else { n_runs - r0 };
        for _ in 0..visits {
            let strip = &strips[r];
            let end = ((r + 1) * RUN_SEGMENTS).min(n_seg);
            let s1 = ray.side(&strip.p1);
            if self.visit_stops(ray, &mut scan, s0, s1, strip, from..end, strip.end_s) {
                return scan.best;
            }
            s0 = s1;
            r += 1;
            if r == n_runs {
                r = 0;
            }
            from = r * RUN_SEGMENTS;
        }
        if self.closed && k > r0 * RUN_SEGMENTS {
            let strip = &strips[r0];
            let s1 = ray.side(&strip.p1);
            let end_s = segs[k - 1].end_s;
            self.visit_stops(ray, &mut scan, s0, s1, strip, r0 * RUN_SEGMENTS..k, end_s);
        }
        scan.best
    }

    /// One run's part `range` in [`Self::first_exit`]: skipped if the ray
    /// passes its strip clear (given the sides `s0`, `s1` of the strip's
    /// chord ends), the scan then stopping if the arc length to `end_s`
    /// (the part's last segment's end) is beyond the stop, else each
    /// segment tested ([`Self::scan_run`]). True once the scan is to stop.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn visit_stops(
        &self,
        ray: &Ray,
        scan: &mut Scan,
        s0: f64,
        s1: f64,
        strip: &Strip,
        range: std::ops::Range<usize>,
        end_s: f64,
    ) -> bool {
        if ray.misses_strip(s0, s1, strip.half_width) {
            // `scanned > stop` with `scanned` as in scan_run (the path
            // length added on a closed border when negative), testing the
            // common case first: a negative `scanned` above the stop is
            // above it also with the (positive) length added.
            let scanned = end_s - scan.start_s;
            scanned > scan.stop
                || (self.closed && scanned < 0.0 && scanned + self.path_length > scan.stop)
        } else {
            let run = &self.segs[range];
            // Within a run the end arc lengths grow: if the first is not
            // behind start_s, none is and no wrap-around correction applies.
            if self.closed && run[0].end_s - scan.start_s < 0.0 {
                self.scan_run::<true>(run, scan, ray.u, ray.o)
            } else {
                self.scan_run::<false>(run, scan, ray.u, ray.o)
            }
        }
    }

    /// Tests the segments of `run` in turn (see [`Self::first_exit`]);
    /// true once the scan is to stop. `WRAP`: add the path length to an arc
    /// length scanned that is negative (a closed border past its start).
    #[inline(always)]
    fn scan_run<const WRAP: bool>(
        &self,
        run: &[Seg],
        scan: &mut Scan,
        u: &Vector2<f64>,
        o: &Point2<f64>,
    ) -> bool {
        for g in run {
            let d = cross(u, &g.e_out);
            if d >= 1e-15 {
                let b = self.exit_ahead(g, d, u, o, scan.best);
                if b < scan.best {
                    scan.best = b;
                    scan.update_stop();
                }
            }
            // Arc length (along the path) scanned once this segment is done.
            let mut scanned = g.end_s - scan.start_s;
            if WRAP && scanned < 0.0 {
                scanned += scan.path_length;
            }
            if scanned > scan.stop {
                return true;
            }
        }
        false
    }
}

/// The state of one border's scan in [`Border::first_exit`].
struct Scan {
    best: f64,
    /// The scan stops after a segment whose end is more than this arc
    /// length past `start_s`: `scan_m.min(2 best + slack_m)`, which is
    /// `scanned > scan_m || scanned > 2 best + slack_m` in one comparison
    /// (also with a NaN: `f64::min` returns the other operand, and a
    /// comparison with NaN is false).
    stop: f64,
    start_s: f64,
    scan_m: f64,
    slack_m: f64,
    path_length: f64,
}

impl Scan {
    #[inline]
    fn update_stop(&mut self) {
        self.stop = self.scan_m.min(2.0 * self.best + self.slack_m);
    }
}

/// Exits closer than this (m) are the ray's origin touching the border.
const BORDER_TOUCH_M: f64 = 1e-9;

/// Ray parameter at which the ray `o + t u` leaves the corridor through the
/// border segment from `a` along `e` (`leaving_sign` +1 for a left border, -1 for a right one).
#[inline]
fn segment_exit(
    a: &Point2<f64>,
    e: &Vector2<f64>,
    u: &Vector2<f64>,
    o: &Point2<f64>,
    leaving_sign: f64,
) -> Option<f64> {
    let denom = cross(u, e);
    // Leaving a left border: the ray crosses it from its right to its left.
    if denom.abs() < 1e-15 || -denom * leaving_sign <= 0.0 {
        return None;
    }
    let ao = a - o;
    let t = cross(&ao, e) / denom;
    let lam = cross(&ao, u) / denom;
    // A ray starting on the border (t = 0 up to rounding) is not leaving
    // the corridor ahead: counted, it would be an obstacle at distance 0 that
    // holds a standing vehicle on the border forever (steering needs motion).
    // It is treated as a vehicle just outside is: free to drive back.
    if t > BORDER_TOUCH_M && (0.0..=1.0).contains(&lam) {
        Some(t)
    } else {
        None
    }
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
        let (closed, len) = (path.is_closed(), path.length());
        let left_simple = Border::new(&left, vs, closed, len, 1.0);
        let right_simple = Border::new(&right, vs, closed, len, -1.0);
        Corridor {
            left,
            right,
            left_simple,
            right_simple,
            max_width_m: max_w,
        }
    }

    /// Left border, one point per path vertex.
    pub fn left(&self) -> &[Point2<f64>] {
        &self.left
    }
    /// Right border, one point per path vertex.
    pub fn right(&self) -> &[Point2<f64>] {
        &self.right
    }
    /// Largest half-width of the corridor (m).
    pub fn max_width(&self) -> f64 {
        self.max_width_m
    }
    /// Vertices kept by the simplification (left, right): what a ray cast scans.
    pub fn simplified_len(&self) -> (usize, usize) {
        (self.left_simple.pts.len(), self.right_simple.pts.len())
    }

    /// Distance along the ray from `origin` in direction `heading_rad` to the
    /// first border segment it leaves the corridor through, looking at border
    /// segments from a little behind `s_origin` up to `horizon_m` ahead along
    /// the path. `None` = free road (within the horizon).
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
        self.ray_cast_along(path, origin, &u, s_origin, horizon_m)
    }

    /// [`Self::ray_cast`] along the unit vector `u` (`(cos, sin)` of the
    /// heading), for a caller that has it already.
    #[inline]
    pub fn ray_cast_along(
        &self,
        path: &Path,
        origin: &Point2<f64>,
        u: &Vector2<f64>,
        s_origin: f64,
        horizon_m: f64,
    ) -> Option<f64> {
        self.ray_cast_along_from(path, origin, u, s_origin, horizon_m, &mut [usize::MAX; 2])
    }

    /// [`Self::ray_cast_along`] with guesses of the (left, right) border
    /// vertices where the scans start (any values; the last ray cast's
    /// nearby save the look-ups), set to those vertices.
    #[inline]
    pub(crate) fn ray_cast_along_from(
        &self,
        path: &Path,
        origin: &Point2<f64>,
        u: &Vector2<f64>,
        s_origin: f64,
        horizon_m: f64,
        start_hints: &mut [usize; 2],
    ) -> Option<f64> {
        let back = self.max_width_m + 1.0;
        let start_s = if path.is_closed() {
            path.wrap_s(s_origin - back)
        } else {
            (s_origin - back).max(0.0)
        };
        let scan = back + horizon_m;
        let slack = back + 2.0 * self.max_width_m + 5.0;
        let ray = Ray::new(origin, u);
        let [left_hint, right_hint] = start_hints;
        let best = self
            .left_simple
            .first_exit(&ray, start_s, scan, slack, left_hint)
            .min(
                self.right_simple
                    .first_exit(&ray, start_s, scan, slack, right_hint),
            );
        if best.is_finite() {
            Some(best)
        } else {
            None
        }
    }

    /// Ray cast against every segment of the (simplified) borders, with no
    /// window and no early exit: the reference the tests hold [`Self::ray_cast`] to.
    pub fn ray_cast_all(
        &self,
        _path: &Path,
        origin: &Point2<f64>,
        heading_rad: f64,
    ) -> Option<f64> {
        let u = Vector2::new(heading_rad.cos(), heading_rad.sin());
        let best = [&self.left_simple, &self.right_simple]
            .iter()
            .flat_map(|b| (0..b.n_segments()).filter_map(move |k| b.exit(k, &u, origin)))
            .fold(f64::INFINITY, f64::min);
        if best.is_finite() {
            Some(best)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_straight_corridor_simplifies_to_its_two_ends_a_curved_one_keeps_more() {
        let cfg = ControllerConfig::default();
        let straight = Corridor::new(&Path::straight(100.0, 1.0).unwrap(), &cfg);
        assert_eq!(straight.simplified_len(), (2, 2));
        // A circle's borders bend everywhere: many vertices stay.
        let (l, r) = Corridor::new(&Path::circle(20.0, 0.01).unwrap(), &cfg).simplified_len();
        assert!(l > 8 && r > 8, "{l}, {r}");
    }

    #[test]
    fn simplify_keeps_vertices_that_fold_back_beyond_the_chord() {
        // All on the x axis: (12, 0) lies on the line of the chord from
        // (0, 0) to (10, 0), 0 m from it, but beyond its end; (5, 0) is on
        // the chord itself and goes.
        let pts: Vec<Point2<f64>> = [[0.0, 0.0], [5.0, 0.0], [12.0, 0.0], [10.0, 0.0]]
            .iter()
            .map(|p| Point2::new(p[0], p[1]))
            .collect();
        assert_eq!(simplify(&pts, 0.01), vec![0, 2, 3]);
        let back: Vec<Point2<f64>> = [[0.0, 0.0], [-3.0, 0.0], [5.0, 0.0], [10.0, 0.0]]
            .iter()
            .map(|p| Point2::new(p[0], p[1]))
            .collect();
        assert_eq!(simplify(&back, 0.01), vec![0, 1, 3]);
    }

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
                        let a = stopping_accel(v, gap, vl, s0, tau, bf, bl);
                        let rhs = gap - s0 + vl * vl / (-2.0 * bl);
                        // The distance v tau + a tau^2/2 + (v + a tau)^2/(-2 b_f) is a
                        // convex quadratic in a, least (v tau/2 + b_f tau^2/8) where
                        // v + a tau = b_f tau/2: a plan exists iff that least value fits.
                        let least = v * tau / 2.0 + bf * tau * tau / 8.0;
                        if a == bl {
                            assert!(
                                least > rhs - 1e-9,
                                "v={v} gap={gap} vl={vl}: no plan although one fits"
                            );
                            continue;
                        }
                        assert!(
                            least <= rhs + 1e-9,
                            "v={v} gap={gap} vl={vl}: a plan where none fits"
                        );
                        // Of the two roots the law takes the larger (the vertex's right),
                        // the gentler command; the other satisfies the identity too.
                        assert!(
                            v + a * tau >= bf * tau / 2.0 - 1e-9,
                            "v={v} gap={gap} vl={vl}: a = {a} is the harsher root"
                        );
                        let lhs =
                            v * tau + a * tau * tau / 2.0 + (v + a * tau).powi(2) / (-2.0 * bf);
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
    fn without_a_plan_b_l_is_kept_while_it_still_stops_before_the_obstacle() {
        // v = 10, standing obstacle 20 m ahead, b_l = -4: 12.5 m to stop fits.
        assert_eq!(emergency_accel(10.0, 20.0, 0.0, -4.0, -9.0), -4.0);
        // 1 m behind a leader at 10 m/s also braking at b_l: it stops 12.5 m
        // on, so the vehicle has 13.5 m and needs 12.5.
        assert_eq!(emergency_accel(10.0, 1.0, 10.0, -4.0, -9.0), -4.0);
    }

    #[test]
    fn without_a_plan_braking_goes_as_hard_as_stopping_needs_down_to_the_emergency_limit() {
        // v = 20, 30 m to a standing obstacle: b_l = -4 needs 50 m, so brake at
        // v^2 / (2 * 30) = 6.67 m/s^2, which stops exactly at the obstacle.
        let a = emergency_accel(20.0, 30.0, 0.0, -4.0, -9.0);
        assert!((a + 400.0 / 60.0).abs() < 1e-12, "{a}");
        assert!((20.0f64 * 20.0 / (-2.0 * a) - 30.0).abs() < 1e-9);
        // 20 m: 10 m/s^2 would be needed; the emergency limit 9 is the most.
        assert_eq!(emergency_accel(20.0, 20.0, 0.0, -4.0, -9.0), -9.0);
        // Already touching: the limit. A limit gentler than b_l never weakens b_l.
        assert_eq!(emergency_accel(5.0, 0.0, 0.0, -4.0, -9.0), -9.0);
        assert_eq!(emergency_accel(20.0, 30.0, 0.0, -4.0, -2.0), -4.0);
    }

    #[test]
    fn an_obstacle_s_own_reaction_time_replaces_the_configured_one_for_it_alone() {
        let cfg = ControllerConfig {
            max_deceleration: -4.0,
            max_obs_deceleration: -4.0,
            preferred_speed: 30.0,
            ..Default::default()
        };
        let law = |tau: f64| stopping_plan(10.0, 12.0, 6.0, 0.0, tau, -4.0, -4.0).unwrap();
        let at = |o: Obstacle| longitudinal_accel(10.0, None, &[o], &cfg).accel_mps2;
        let o = Obstacle::new(12.0, 6.0);
        assert_eq!(at(o), law(cfg.reaction_time));
        assert_eq!(at(o.with_reaction(0.4)), law(0.4));
        // Less reaction time to come, more room now (both below free flow).
        assert!(law(0.4) > law(cfg.reaction_time));
        assert!(law(0.4) < free_flow_accel(10.0, &cfg));
        // NaN (and nonsense) fall back to the configured one.
        assert_eq!(at(o.with_reaction(f64::NAN)), law(cfg.reaction_time));
        assert_eq!(at(o.with_reaction(-1.0)), law(cfg.reaction_time));
        // The fleet takes it per leader.
        let mut fleet = crate::fleet::Fleet::new();
        let t = fleet
            .add_track(Path::straight(200.0, 1.0).unwrap(), cfg.clone())
            .unwrap() as i64;
        let slots = [fleet.add_vehicle(t, None, None).unwrap() as i64; 1];
        let mut step = |reaction: Option<&[f64]>| {
            fleet
                .step(&crate::fleet::FleetInputs {
                    leader_gap_m: Some(&[12.0]),
                    leader_speed_mps: Some(&[6.0]),
                    leader_reaction_s: reaction,
                    ..crate::fleet::FleetInputs::new(
                        &slots,
                        &[10.0],
                        &[0.0],
                        &[0.0],
                        &[10.0],
                        &[0.0],
                    )
                })
                .unwrap()
                .accel_mps2[0]
        };
        assert_eq!(step(None), law(cfg.reaction_time));
        assert_eq!(step(Some(&[0.4])), law(0.4));
    }

    #[test]
    fn the_controller_brakes_harder_than_b_l_only_for_a_real_obstacle_without_a_plan() {
        let cfg = ControllerConfig {
            max_deceleration: -4.0,
            max_obs_deceleration: -4.0,
            preferred_stop_dist: 2.0,
            preferred_speed: 30.0,
            ..Default::default()
        };
        // 10 m/s, a standing car 6 m ahead: no plan (U < 0 below 6.5 m here),
        // b_l would need 12.5 m: brake at 100 / 12 = 8.33 m/s^2.
        assert!(stopping_plan(10.0, 6.0, 0.0, 2.0, 1.0, -4.0, -4.0).is_none());
        let real = longitudinal_accel(10.0, None, &[Obstacle::new(6.0, 0.0)], &cfg);
        assert!((real.accel_mps2 + 100.0 / 12.0).abs() < 1e-12, "{real:?}");
        // The same distance as the virtual obstacle (a curve) or a soft one: b_f at most.
        let virt = longitudinal_accel(10.0, Some(6.0), &[], &cfg);
        assert_eq!(virt.accel_mps2, -4.0);
        let soft = longitudinal_accel(10.0, None, &[Obstacle::soft(6.0, 0.0)], &cfg);
        assert_eq!(soft.accel_mps2, -4.0);
        // A line to stop at (a stop line, a lane's end) keeps b_l without a plan.
        let line = longitudinal_accel(10.0, None, &[Obstacle::line(6.0)], &cfg);
        assert_eq!(line.accel_mps2, -4.0);
        // With a plan nothing changes: the law's value.
        let far = longitudinal_accel(20.0, None, &[Obstacle::new(120.0, 0.0)], &cfg);
        assert_eq!(
            far.accel_mps2,
            cfg_law(&cfg, 20.0, 120.0).min(free_flow_accel(20.0, &cfg))
        );
    }

    fn cfg_law(cfg: &ControllerConfig, v: f64, gap: f64) -> f64 {
        stopping_accel(
            v,
            gap,
            0.0,
            cfg.preferred_stop_dist,
            cfg.reaction_time,
            cfg.max_deceleration,
            cfg.max_obs_deceleration,
        )
    }

    #[test]
    fn ratio_pow_is_powf_bit_for_bit() {
        let xs = [
            0.0,
            -0.0,
            1.0,
            1.0 - 1e-16,
            1.0 + 2e-16,
            0.5,
            1.5,
            5e-324,
            f64::NAN,
            f64::INFINITY,
        ];
        let ys = [
            3.0,
            4.0,
            2.5,
            1.0,
            0.5,
            1e-300,
            0.0,
            -1.0,
            -3.0,
            f64::NAN,
            f64::INFINITY,
        ];
        for x in xs {
            for y in ys {
                let (got, want) = (ratio_pow(x, y), x.powf(y));
                assert!(got.to_bits() == want.to_bits(), "{x}^{y}: {got} vs {want}");
            }
        }
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
    fn obstacles_beyond_the_relevance_distance_do_not_change_the_command() {
        let cfg = ControllerConfig {
            preferred_stop_dist: 1.5,
            ..Default::default()
        };
        for &v in &[0.0, 1.0, 3.0, 10.0, 30.0] {
            let d = relevance_distance(v, &cfg);
            let at = stopping_accel(
                v,
                d,
                0.0,
                cfg.preferred_stop_dist,
                cfg.reaction_time,
                cfg.max_deceleration,
                cfg.max_obs_deceleration,
            );
            assert!(
                (at - cfg.preferred_acceleration).abs() < 1e-9,
                "v={v}: a_r(D) = {at}"
            );
            for &extra in &[1e-6, 1.0, 100.0] {
                let with = longitudinal_accel(v, Some(d + extra), &[], &cfg).accel_mps2;
                let without = longitudinal_accel(v, None, &[], &cfg).accel_mps2;
                assert_eq!(with, without, "v={v} obstacle at D + {extra}");
            }
            // Any closer obstacle asks for less than a_pref: D is the smallest such gap.
            let closer = stopping_accel(
                v,
                0.99 * d,
                0.0,
                cfg.preferred_stop_dist,
                cfg.reaction_time,
                cfg.max_deceleration,
                cfg.max_obs_deceleration,
            );
            assert!(closer < cfg.preferred_acceleration, "v={v}: {closer}");
        }
    }

    #[test]
    fn min_over_obstacles() {
        let cfg = ControllerConfig::default();
        let far = longitudinal_accel(3.0, None, &[], &cfg);
        assert_eq!(far.accel_mps2, far.free_flow_mps2);
        let near = longitudinal_accel(3.0, Some(4.0), &[], &cfg);
        assert!(near.accel_mps2 < 0.0 && near.accel_mps2 == near.virtual_obstacle_mps2);
        // Too fast for a close curve: the law alone would fall back to b_l; the
        // virtual obstacle asks for b_f at most, a real one at the same gap for b_l.
        assert_eq!(stopping_accel(25.0, 5.0, 0.0, 0.0, 1.0, -4.0, -8.0), -8.0);
        let curve = longitudinal_accel(25.0, Some(5.0), &[], &cfg);
        assert_eq!(curve.accel_mps2, cfg.max_deceleration);
        // A real one without a plan that b_l cannot stop short of: 25^2 / 10
        // would be needed, so the emergency limit.
        let wall = longitudinal_accel(25.0, None, &[Obstacle::new(5.0, 0.0)], &cfg);
        assert_eq!(wall.accel_mps2, cfg.emergency_deceleration);
        let leader = longitudinal_accel(
            3.0,
            None,
            &[Obstacle::new(3.0, 0.0), Obstacle::new(50.0, 0.0)],
            &cfg,
        );
        let expected = stopping_accel(3.0, 3.0, 0.0, 0.0, 1.0, -4.0, -8.0);
        assert_eq!(leader.accel_mps2, expected);
        let nan = longitudinal_accel(3.0, None, &[Obstacle::new(f64::NAN, 0.0)], &cfg);
        assert_eq!(nan.accel_mps2, cfg.max_obs_deceleration);
    }

    #[test]
    fn soft_obstacles_are_braked_for_at_max_deceleration_at_most() {
        // The law's boundary U = 0 in closed form: with tau = 1 s, b_f = b_l = -4,
        // v = 16 m/s and a standing obstacle, gap* = s0 + (b_f b_l tau^2 + 4 b_l v tau)
        // / (8 b_l) = 7.5 m, where the larger root is b_f / 2 - v / tau = -18.
        let cfg = ControllerConfig {
            max_obs_deceleration: -4.0,
            ..Default::default()
        };
        let (v, tau, b) = (16.0, cfg.reaction_time, cfg.max_deceleration);
        let boundary =
            cfg.preferred_stop_dist + (b * b * tau * tau + 4.0 * b * v * tau) / (8.0 * b);
        assert!((boundary - 7.5).abs() < 1e-12);
        let at = |gap: f64, soft: bool| {
            let o = if soft {
                Obstacle::soft(gap, 0.0)
            } else {
                Obstacle::new(gap, 0.0)
            };
            longitudinal_accel(v, None, &[o], &cfg).accel_mps2
        };
        assert!((at(boundary, false) - (b / 2.0 - v / tau)).abs() < 1e-9);
        // Not monotone for a real obstacle: a little closer there is no plan,
        // and b_l cannot stop short of it (256 / 14.8 needed): the emergency limit.
        assert_eq!(at(boundary - 0.1, false), cfg.emergency_deceleration);
        // A soft one never asks for more than b_f, at any gap or unreadable...
        for gap in [-2.0, 0.0, 3.0, boundary, 12.0, 20.0, f64::NAN] {
            assert_eq!(at(gap, true), cfg.max_deceleration, "gap {gap}");
        }
        // ...and where the law asks for less, it is the same as a real one.
        assert!(at(40.0, true) > cfg.max_deceleration);
        assert_eq!(at(40.0, true), at(40.0, false));
        // A real obstacle beside a soft one still gets the full law.
        let both = longitudinal_accel(
            v,
            None,
            &[Obstacle::soft(3.0, 0.0), Obstacle::new(12.0, 0.0)],
            &cfg,
        );
        assert_eq!(both.accel_mps2, at(12.0, false));
        assert!(both.accel_mps2 < cfg.max_deceleration);
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

    #[test]
    fn exit_below_is_the_plain_exit_test_bit_for_bit() {
        // Every segment of both borders of the test track against rays from
        // a grid of origins and headings, with bounds below, at and above the
        // exits: the fast test must give min(best, exit) exactly.
        let path = Path::test_track(1.0).unwrap();
        let cor = Corridor::new(&path, &ControllerConfig::default());
        let (mut hits, mut n) = (0, 0);
        for b in [&cor.left_simple, &cor.right_simple] {
            for s in (0..40).map(|i| i as f64 * path.length() / 40.0) {
                let c = path.point_at(s);
                for off in [-7.0, -2.0, 0.0, 0.5, 6.0] {
                    let o = c + Vector2::new(0.3 * off, off);
                    for deg in (0..24).map(|i| i as f64 * 15.0) {
                        let u = Vector2::new(deg.to_radians().cos(), deg.to_radians().sin());
                        for k in 0..b.n_segments() {
                            let plain = b.exit(k, &u, &o);
                            hits += plain.is_some() as usize;
                            let t = plain.unwrap_or(f64::INFINITY);
                            for best in [f64::INFINITY, 50.0, t, t * 0.999, t * 1.001] {
                                let got = b.exit_below(k, &u, &o, best);
                                assert_eq!(got.to_bits(), best.min(t).to_bits(), "k={k} {best}");
                                n += 1;
                            }
                        }
                    }
                }
            }
        }
        // Both outcomes occur often (the test would be empty otherwise).
        assert!(hits > 1000 && n > 100 * hits, "{hits} hits of {n}");
    }

    /// [`Border::first_exit`] as a plain loop, one segment at a time and
    /// every segment tested: the scan's definition, which the run-by-run
    /// scan with its strip tests must match bit for bit.
    fn plain_first_exit(
        b: &Border,
        u: &Vector2<f64>,
        o: &Point2<f64>,
        start_s: f64,
        scan_m: f64,
        slack_m: f64,
    ) -> f64 {
        let n_seg = b.n_segments();
        if n_seg == 0 {
            return f64::INFINITY;
        }
        let mut k =
            b.s.partition_point(|&v| v <= start_s)
                .saturating_sub(1)
                .min(n_seg - 1);
        let mut best = f64::INFINITY;
        for _ in 0..n_seg {
            best = best.min(b.exit(k, u, o).unwrap_or(f64::INFINITY));
            let mut scanned = b.segs[k].end_s - start_s;
            if b.closed && scanned < 0.0 {
                scanned += b.path_length;
            }
            if scanned > scan_m || scanned > 2.0 * best + slack_m {
                break;
            }
            k += 1;
            if k >= n_seg {
                if !b.closed {
                    break;
                }
                k = 0;
            }
        }
        best
    }

    #[test]
    fn no_segment_of_a_strip_the_ray_passes_clear_of_is_left_through() {
        // Rays along, across and just beside each run's chord, the line at
        // the strip's edge and a little beyond: wherever the strip test
        // says the line passes clear, every segment's exit test fails.
        let track = Path::test_track(1.0).unwrap();
        let wiggly: Vec<[f64; 2]> = (0..400)
            .map(|i| {
                let x = i as f64 * 0.7;
                [x, 3.0 * (0.05 * x).sin() + 0.02 * ((i * 7919) % 13) as f64]
            })
            .collect();
        let paths = [
            track,
            Path::circle(25.0, 1e-3).unwrap(),
            Path::new(&wiggly, None, false).unwrap(),
        ];
        let (mut culled, mut n) = (0, 0);
        for path in &paths {
            let cor = Corridor::new(path, &ControllerConfig::default());
            for b in [&cor.left_simple, &cor.right_simple] {
                for (r, strip) in b.strips.iter().enumerate() {
                    let p0 = b.segs[r * RUN_SEGMENTS].a;
                    let chord = strip.p1 - p0;
                    let along = if chord.norm() > 0.0 {
                        chord / chord.norm()
                    } else {
                        Vector2::new(1.0, 0.0)
                    };
                    let normal = Vector2::new(-along.y, along.x);
                    for off in [0.0, 0.999, 1.0, 1.001, 1.5, 3.0] {
                        for side in [-1.0, 1.0] {
                            for (turn, back) in [(0.0, 5.0), (0.01, -3.0), (-0.2, 40.0), (1.5, 0.0)]
                            {
                                let (c, s) = (f64::cos(turn), f64::sin(turn));
                                let u = Vector2::new(
                                    c * along.x - s * along.y,
                                    s * along.x + c * along.y,
                                );
                                let o =
                                    p0 - along * back + normal * (side * off * strip.half_width);
                                let ray = Ray::new(&o, &u);
                                let (s0, s1) = (ray.side(&p0), ray.side(&strip.p1));
                                if !ray.misses_strip(s0, s1, strip.half_width) {
                                    continue;
                                }
                                culled += 1;
                                let end = ((r + 1) * RUN_SEGMENTS).min(b.n_segments());
                                for k in r * RUN_SEGMENTS..end {
                                    assert_eq!(b.exit(k, &u, &o), None, "run {r} segment {k}");
                                    assert_eq!(b.exit_below(k, &u, &o, 1e300), 1e300);
                                    n += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(culled > 500 && n > 2000, "{culled} strips, {n} segments");
    }

    #[test]
    fn the_run_by_run_scan_is_the_plain_scan_bit_for_bit() {
        // Rays from around the corridor (inside, outside, across) mostly
        // along the path, some any way, some axis-parallel or not finite;
        // bounds of every kind (NaN, out of range, wrapping round).
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let track = Path::test_track(1.0).unwrap();
        let open: Vec<[f64; 2]> = track.points()[..200].iter().map(|p| [p.x, p.y]).collect();
        let paths = [
            track.clone(),
            Path::circle(30.0, 1e-3).unwrap(),
            Path::straight(500.0, 5.0).unwrap(),
            Path::new(&open, None, false).unwrap(),
        ];
        let (mut n, mut hits) = (0, 0);
        for path in &paths {
            for width in [3.0, 12.0] {
                let cfg = ControllerConfig {
                    path_width_m: width,
                    ..Default::default()
                };
                let cor = Corridor::new(path, &cfg);
                for _ in 0..4000 {
                    let s = (1.1 * rnd() - 0.05) * path.length();
                    let (c, h) = (path.point_at(s), path.heading_at(s));
                    let off = (rnd() - 0.5) * 3.0 * width;
                    let mut o = Point2::new(c.x - off * h.sin() + rnd() - 0.5, c.y + off * h.cos());
                    let hd = if rnd() < 0.7 {
                        h + 0.4 * (rnd() - 0.5)
                    } else {
                        7.0 * rnd()
                    };
                    let u = match (40.0 * rnd()) as u32 {
                        0 => Vector2::new(1.0, 0.0),
                        1 => Vector2::new(0.0, -1.0),
                        2 => Vector2::new(f64::NAN, 0.5),
                        3 => Vector2::new(f64::INFINITY, 1e-16),
                        _ => Vector2::new(hd.cos(), hd.sin()),
                    };
                    if rnd() < 0.02 {
                        o.x = f64::NAN;
                    }
                    let start_s = match (30.0 * rnd()) as u32 {
                        0 => f64::NAN,
                        1 => -5.0,
                        2 => path.length() + 3.0,
                        _ if path.is_closed() => path.wrap_s(s - 8.0),
                        _ => (s - 8.0).max(0.0),
                    };
                    let scan_m = match (30.0 * rnd()) as u32 {
                        0 => f64::NAN,
                        1 => f64::INFINITY,
                        _ => 400.0 * rnd(),
                    };
                    let slack_m = if rnd() < 0.03 { f64::NAN } else { 40.0 * rnd() };
                    let ray = Ray::new(&o, &u);
                    for b in [&cor.left_simple, &cor.right_simple] {
                        let want = plain_first_exit(b, &u, &o, start_s, scan_m, slack_m);
                        // Guesses of the start vertex: none, anywhere, near it.
                        let at = b.vertex_holding(start_s);
                        let mut hint = match (3.0 * rnd()) as u32 {
                            0 => usize::MAX,
                            1 => (rnd() * b.s.len() as f64) as usize,
                            _ => (at + (9.0 * rnd()) as usize).saturating_sub(4),
                        };
                        let got = b.first_exit(&ray, start_s, scan_m, slack_m, &mut hint);
                        assert_eq!(hint, at, "start {start_s}");
                        assert_eq!(
                            got.to_bits(),
                            want.to_bits(),
                            "o {o:?} u {u:?} start {start_s} scan {scan_m} slack {slack_m}"
                        );
                        n += 1;
                        hits += want.is_finite() as usize;
                    }
                }
            }
        }
        // Exits are found often (the test would be empty otherwise).
        assert!(hits > n / 10, "{hits} exits of {n} scans");
    }
}
