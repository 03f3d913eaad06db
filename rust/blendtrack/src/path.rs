//! Reference tracks: polylines with arc length, projection and curvature (SPEC §3).
//!
//! A [`Path`] is a polyline in the world frame (x east, y north, metres) with
//! cumulative arc length `s`, an `is_closed` flag and optional per-point
//! right/left widths (TUM format). It answers the questions every controller
//! asks: where is my foot point, how far am I from the path (signed, left
//! positive), which way does the path go there, how curved is it, where is
//! the point `d` metres further on.
//!
//! Choices written down here:
//! - The lateral distance is measured to the polyline itself (chords), the
//!   tangent heading is interpolated linearly along each segment between the
//!   vertex tangents (bisectors of the adjacent segments). The heading is thus
//!   continuous, so the heading error does not jump at every vertex of a
//!   discretised track (the "fast oscillations" the paper notes).
//! - Curvature at `s` is the wrapped heading change over
//!   `tangent_sampling_width_m` (centred), divided by that width.
//! - A hinted projection ([`Path::project_hinted`]) scans the segments within
//!   `[s_hint - window_back, s_hint + window_ahead]` and, if the best foot point
//!   lies on the edge of that window, keeps walking while the distance
//!   decreases. One step is O(1) and the projection cannot jump to another leg
//!   of the track passing close by. The full search ([`Path::project`]) uses
//!   chunk bounding boxes so long paths are not scanned segment by segment.
//! - Open paths are extended along their end tangents when asked for a point
//!   beyond either end.

use crate::error::PathError;
use nalgebra::{Point2, Vector2};
use std::f64::consts::PI;

/// Wraps an angle to (-pi, pi].
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    // Fast path for the common case (a sum or difference of wrapped angles):
    // no fmod, which costs more than the rest of a projection.
    if a > -PI && a <= PI {
        return a;
    }
    if a > -3.0 * PI && a <= 3.0 * PI {
        let r = if a > PI { a - 2.0 * PI } else { a + 2.0 * PI };
        if r > -PI && r <= PI {
            return r;
        }
    }
    let mut r = a % (2.0 * PI);
    if r <= -PI {
        r += 2.0 * PI;
    } else if r > PI {
        r -= 2.0 * PI;
    }
    r
}

#[inline]
fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// The nearest point of a path to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Arc length of the foot point, in [0, length].
    pub s: f64,
    /// Foot point on the polyline.
    pub foot: Point2<f64>,
    /// Tangent heading at the foot point (rad, CCW from +x).
    pub heading_rad: f64,
    /// Signed lateral distance of the query point, > 0 on the left.
    pub lateral_m: f64,
    /// Curvature at the foot point (1/m, > 0 turning left).
    pub curvature_per_m: f64,
    /// Index of the segment holding the foot point.
    pub segment: usize,
}

const CHUNK: usize = 32;
/// Steps [`Path::locate_from`] walks from its guess before it looks up.
const LOCATE_STEPS: usize = 4;

/// The next or the previous segment (a walk's direction along a path).
type Advance = fn(&Path, usize) -> Option<usize>;

/// Widths of a track at one point (metres from the centreline along the normal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Widths {
    pub right_m: f64,
    pub left_m: f64,
}

/// A reference track. See the module docs for the conventions.
#[derive(Debug, Clone)]
pub struct Path {
    points: Vec<Point2<f64>>,
    /// Cumulative arc length at each segment start; `s[n_seg] = length`.
    s: Vec<f64>,
    seg_dir: Vec<Vector2<f64>>,
    seg_len: Vec<f64>,
    widths: Option<Vec<Widths>>,
    closed: bool,
    length: f64,
    chunk_boxes: Vec<(Point2<f64>, Point2<f64>)>,
    /// `bucket[b]` = the segment holding arc length `b * length / n_seg`:
    /// O(1) arc-length look-ups also on unevenly sampled paths.
    bucket: Vec<u32>,
    /// `n_seg / length`: arc length to bucket index.
    bucket_scale: f64,
    tangent_sampling_width_m: f64,
    window_back_m: f64,
    window_ahead_m: f64,
    /// Per segment, what a projection reads of it in one record (copies of
    /// the vectors above, so a projection touches one cache line).
    segs: Vec<Seg>,
}

/// One segment of a [`Path`] as a projection reads it.
#[derive(Debug, Clone, Copy)]
struct Seg {
    /// Start vertex (`points[k]`).
    a: Point2<f64>,
    /// Unit direction and length (`seg_dir[k]`, `seg_len[k]`).
    dir: Vector2<f64>,
    len: f64,
    /// Arc length at the start (`s[k]`).
    s0: f64,
    /// Vertex heading (tangent, bisecting the adjacent segments) at the
    /// start of the segment, and the wrapped turn to the one at its end:
    /// `wrap_angle(h1 - h0)`, which every heading look-up on the segment
    /// needs.
    h0: f64,
    dh: f64,
}

impl Path {
    /// Builds a path from points (and optional widths). Consecutive duplicate
    /// points are dropped (for a closed path, also a last point equal to the
    /// first). Errors name the offending point by its index in the input.
    pub fn new(
        points: &[[f64; 2]],
        widths: Option<&[Widths]>,
        closed: bool,
    ) -> Result<Self, PathError> {
        Self::with_locations(points, widths, closed, |i| format!("point {i}"))
    }

    fn with_locations(
        points: &[[f64; 2]],
        widths: Option<&[Widths]>,
        closed: bool,
        location: impl Fn(usize) -> String,
    ) -> Result<Self, PathError> {
        check_points(points, widths, &location)?;
        const EPS: f64 = 1e-9;
        let mut pts: Vec<Point2<f64>> = Vec::with_capacity(points.len());
        let mut ws: Vec<Widths> = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            let q = Point2::new(p[0], p[1]);
            if let Some(last) = pts.last() {
                if (q - last).norm() <= EPS {
                    continue;
                }
            }
            pts.push(q);
            if let Some(w) = widths {
                ws.push(w[i]);
            }
        }
        if closed && pts.len() > 2 && (pts[0] - pts[pts.len() - 1]).norm() <= EPS {
            pts.pop();
            if widths.is_some() {
                ws.pop();
            }
        }
        if pts.len() < 2 {
            return Err(PathError::TooFewPoints(pts.len()));
        }
        // A closed path of two points is a degenerate back-and-forth; treat it as open.
        let closed = closed && pts.len() >= 3;
        let n = pts.len();
        let n_seg = if closed { n } else { n - 1 };
        let mut seg_dir = Vec::with_capacity(n_seg);
        let mut seg_len = Vec::with_capacity(n_seg);
        let mut s = Vec::with_capacity(n_seg + 1);
        s.push(0.0);
        for i in 0..n_seg {
            let d = pts[(i + 1) % n] - pts[i];
            let l = d.norm();
            seg_dir.push(d / l);
            seg_len.push(l);
            s.push(s[i] + l);
        }
        let length = s[n_seg];
        let vertex_heading = vertex_headings(&seg_dir, n, closed);
        let chunk_boxes = chunk_boxes(&pts, n_seg);
        let bucket = buckets(&s, length);
        let segs = (0..n_seg)
            .map(|k| Seg {
                a: pts[k],
                dir: seg_dir[k],
                len: seg_len[k],
                s0: s[k],
                h0: vertex_heading[k],
                dh: wrap_angle(vertex_heading[(k + 1) % n] - vertex_heading[k]),
            })
            .collect();
        Ok(Path {
            segs,
            bucket,
            bucket_scale: n_seg as f64 / length,
            points: pts,
            s,
            seg_dir,
            seg_len,
            widths: widths.map(|_| ws),
            closed,
            length,
            chunk_boxes,
            tangent_sampling_width_m: 2.0,
            window_back_m: 1.0,
            window_ahead_m: 3.0,
        })
    }

    /// Loads a TUM race-track csv (`# x_m,y_m,w_tr_right_m,w_tr_left_m`).
    /// Lines starting with `#` are comments; two columns (no widths) are
    /// accepted too. Errors name the file and line.
    pub fn from_tum_csv(file: &std::path::Path, closed: bool) -> Result<Self, PathError> {
        let name = file.display().to_string();
        let text = std::fs::read_to_string(file).map_err(|e| PathError::Io {
            file: name.clone(),
            message: e.to_string(),
        })?;
        Self::from_tum_str(&text, &name, closed)
    }

    /// Parses TUM csv text; `source_name` is used in error messages.
    pub fn from_tum_str(text: &str, source_name: &str, closed: bool) -> Result<Self, PathError> {
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .comment(Some(b'#'))
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let mut points = Vec::new();
        let mut widths = Vec::new();
        let mut lines = Vec::new();
        let mut ncols = None;
        for rec in reader.records() {
            let rec = rec.map_err(|e| PathError::Parse {
                file: source_name.to_string(),
                line: e.position().map(|p| p.line()).unwrap_or(0),
                message: e.to_string(),
            })?;
            let line = rec.position().map(|p| p.line()).unwrap_or(0);
            if rec.iter().all(|f| f.is_empty()) {
                continue;
            }
            let perr = |message: String| PathError::Parse {
                file: source_name.to_string(),
                line,
                message,
            };
            let vals: Vec<f64> = rec
                .iter()
                .enumerate()
                .map(|(c, f)| {
                    f.parse::<f64>()
                        .map_err(|_| perr(format!("column {} is not a number: {f:?}", c + 1)))
                })
                .collect::<Result<_, _>>()?;
            if vals.len() != 2 && vals.len() != 4 {
                return Err(perr(format!(
                    "expected 2 or 4 columns (x_m,y_m[,w_tr_right_m,w_tr_left_m]), got {}",
                    vals.len()
                )));
            }
            match ncols {
                None => ncols = Some(vals.len()),
                Some(c) if c != vals.len() => {
                    return Err(perr(format!(
                        "expected {c} columns like the first data line, got {}",
                        vals.len()
                    )))
                }
                _ => {}
            }
            points.push([vals[0], vals[1]]);
            if vals.len() == 4 {
                widths.push(Widths {
                    right_m: vals[2],
                    left_m: vals[3],
                });
            }
            lines.push(line);
        }
        let w = if widths.is_empty() {
            None
        } else {
            Some(widths.as_slice())
        };
        Self::with_locations(&points, w, closed, |i| {
            format!("{source_name}: line {}", lines[i])
        })
        .map_err(|e| match e {
            PathError::TooFewPoints(n) => PathError::Parse {
                file: source_name.to_string(),
                line: lines.last().copied().unwrap_or(0),
                message: format!("a track needs at least 2 distinct points, got {n}"),
            },
            other => other,
        })
    }

    /// A straight line from the origin along +x.
    pub fn straight(length_m: f64, spacing_m: f64) -> Result<Self, PathError> {
        check_positive("length_m", length_m)?;
        check_positive("spacing_m", spacing_m)?;
        let n = point_count("length_m", length_m, (length_m / spacing_m).ceil().max(1.0))?;
        let pts: Vec<[f64; 2]> = (0..=n)
            .map(|i| [length_m * i as f64 / n as f64, 0.0])
            .collect();
        Self::new(&pts, None, false)
    }

    /// A closed counter-clockwise circle of radius `radius_m` centred at
    /// (0, radius_m), starting at the origin heading +x. The vertex count is
    /// chosen so that the chord sagitta stays below `max_sagitta_m`.
    pub fn circle(radius_m: f64, max_sagitta_m: f64) -> Result<Self, PathError> {
        check_positive("radius_m", radius_m)?;
        check_positive("max_sagitta_m", max_sagitta_m)?;
        // sagitta = R (1 - cos(dphi / 2)) <= max  =>  dphi <= 2 acos(1 - max/R)
        let dphi = 2.0 * (1.0 - (max_sagitta_m / radius_m).min(1.0)).acos();
        let n = ((2.0 * PI / dphi).ceil() as usize).clamp(8, 1_000_000);
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let phi = 2.0 * PI * i as f64 / n as f64 - PI / 2.0;
                [radius_m * phi.cos(), radius_m + radius_m * phi.sin()]
            })
            .collect();
        Self::new(&pts, None, true)
    }

    /// The built-in closed test track: straights, arcs of radius 25 to 40 m
    /// turning both ways, joined by clothoids (curvature linear in `s`), so
    /// curvature is continuous. The lap is point-symmetric: the second half is
    /// the first rotated by pi, which closes the loop exactly. About 1.2 km,
    /// sampled every `spacing_m`.
    pub fn test_track(spacing_m: f64) -> Result<Self, PathError> {
        check_positive("spacing_m", spacing_m)?;
        // (length, curvature at start, curvature at end) of each piece of half a lap.
        let k1 = 1.0 / 30.0;
        let k2 = -1.0 / 40.0;
        let k3 = 1.0 / 25.0;
        let fixed_turn = (20.0 * k1) + (15.0 * k2) + 40.0 * k2 + (15.0 * k3);
        // The two left arcs share what is left of the half-lap turn of pi.
        let rest = PI - fixed_turn;
        let arc1 = 0.55 * rest / k1;
        let arc3 = 0.45 * rest / k3;
        let half: [(f64, f64, f64); 12] = [
            (80.0, 0.0, 0.0),
            (20.0, 0.0, k1),
            (arc1, k1, k1),
            (20.0, k1, 0.0),
            (40.0, 0.0, 0.0),
            (15.0, 0.0, k2),
            (40.0, k2, k2),
            (15.0, k2, 0.0),
            (30.0, 0.0, 0.0),
            (15.0, 0.0, k3),
            (arc3, k3, k3),
            (15.0, k3, 0.0),
        ];
        let half_len: f64 = half.iter().map(|p| p.0).sum();
        let n_half = point_count("spacing_m", spacing_m, 2.0 * (half_len / spacing_m).ceil())? / 2;
        let ds = half_len / n_half as f64;
        let curvature = |s: f64| -> f64 {
            let mut start = 0.0;
            for &(l, a, b) in &half {
                if s <= start + l {
                    return a + (b - a) * (s - start) / l;
                }
                start += l;
            }
            0.0
        };
        // Integrate heading and position with fine sub-steps (midpoint rule).
        let sub = 20;
        let h = ds / sub as f64;
        let (mut x, mut y, mut th) = (0.0f64, 0.0f64, 0.0f64);
        let mut pts = vec![[x, y]];
        for i in 0..n_half {
            for j in 0..sub {
                let s0 = i as f64 * ds + j as f64 * h;
                let th_mid = th + 0.5 * h * curvature(s0 + 0.25 * h);
                x += h * th_mid.cos();
                y += h * th_mid.sin();
                th += h * curvature(s0 + 0.5 * h);
            }
            pts.push([x, y]);
        }
        // Second half: the first rotated by pi about the half-lap end point.
        let (bx, by) = (x, y);
        for i in 1..n_half {
            let p = pts[i];
            pts.push([bx - p[0], by - p[1]]);
        }
        Self::new(&pts, None, true)
    }

    /// A copy with every coordinate and width multiplied by `factor` (> 0).
    pub fn scaled(&self, factor: f64) -> Result<Self, PathError> {
        check_positive("scale", factor)?;
        let pts: Vec<[f64; 2]> = self
            .points
            .iter()
            .map(|p| [p.x * factor, p.y * factor])
            .collect();
        let ws: Option<Vec<Widths>> = self.widths.as_ref().map(|w| {
            w.iter()
                .map(|w| Widths {
                    right_m: w.right_m * factor,
                    left_m: w.left_m * factor,
                })
                .collect()
        });
        let mut p = Self::new(&pts, ws.as_deref(), self.closed)?;
        p.tangent_sampling_width_m = self.tangent_sampling_width_m;
        p.window_back_m = self.window_back_m;
        p.window_ahead_m = self.window_ahead_m;
        Ok(p)
    }

    /// Sets the width over which curvature is sampled (metres, > 0).
    pub fn with_tangent_sampling_width(mut self, width_m: f64) -> Result<Self, PathError> {
        check_positive("tangent_sampling_width_m", width_m)?;
        self.tangent_sampling_width_m = width_m;
        Ok(self)
    }

    /// Sets the hinted-projection search window (metres behind and ahead of the hint).
    pub fn with_search_window(mut self, back_m: f64, ahead_m: f64) -> Result<Self, PathError> {
        check_positive("window_back_m", back_m)?;
        check_positive("window_ahead_m", ahead_m)?;
        self.window_back_m = back_m;
        self.window_ahead_m = ahead_m;
        Ok(self)
    }

    pub fn len_points(&self) -> usize {
        self.points.len()
    }
    pub fn n_segments(&self) -> usize {
        self.seg_len.len()
    }
    pub fn length(&self) -> f64 {
        self.length
    }
    pub fn is_closed(&self) -> bool {
        self.closed
    }
    pub fn points(&self) -> &[Point2<f64>] {
        &self.points
    }
    pub fn widths(&self) -> Option<&[Widths]> {
        self.widths.as_deref()
    }
    pub fn tangent_sampling_width(&self) -> f64 {
        self.tangent_sampling_width_m
    }
    /// Arc length at each vertex (for a closed path, without the closing vertex).
    pub fn vertex_s(&self) -> &[f64] {
        &self.s[..self.points.len()]
    }

    /// Maps `s` into [0, length) on closed paths; leaves it on open ones.
    #[inline]
    pub fn wrap_s(&self, s: f64) -> f64 {
        if self.closed {
            let l = self.length;
            if (0.0..l).contains(&s) {
                return s;
            }
            let r = if (-l..0.0).contains(&s) {
                s + l
            } else if (l..2.0 * l).contains(&s) {
                s - l
            } else {
                s.rem_euclid(l)
            };
            // Each branch gives r >= 0 (s + l for s in [-l, 0), s - l for
            // s >= l, rem_euclid); rounding can make it l itself.
            if r >= l {
                0.0
            } else {
                r
            }
        } else {
            s
        }
    }

    /// Signed arc distance from `from` to `to` (shortest way round on closed paths).
    #[inline]
    pub fn arc_delta(&self, from: f64, to: f64) -> f64 {
        let d = to - from;
        if self.closed {
            let l = self.length;
            let h = 0.5 * l;
            if d > -h && d <= h {
                return d;
            }
            let r = self.wrap_s(d);
            if r > h {
                r - l
            } else {
                r
            }
        } else {
            d
        }
    }

    /// Segment index and offset into it for arc length `s` (clamped to the
    /// first/last segment on open paths; offset may be negative or exceed the
    /// segment length there, which extrapolates).
    #[inline]
    fn locate(&self, s: f64) -> (usize, f64) {
        let s = self.wrap_s(s);
        let n_seg = self.seg_len.len();
        // The bucket of `s` names the segment holding the bucket's start; a
        // few steps forward find the one holding `s` (one step on evenly
        // sampled paths), else binary search.
        // (Any start gives the same answer: the bucket only saves steps.)
        if s > 0.0 && s < f64::INFINITY {
            let b = ((s * self.bucket_scale) as u32 as usize).min(n_seg - 1);
            let mut k = self.bucket[b] as usize;
            for _ in 0..8 {
                if s < self.s[k] {
                    if k == 0 {
                        break;
                    }
                    k -= 1;
                } else if k + 1 < n_seg && s >= self.s[k + 1] {
                    k += 1;
                } else {
                    return (k, s - self.s[k]);
                }
            }
        }
        let k = self.s[1..n_seg].partition_point(|&b| b <= s);
        (k, s - self.s[k])
    }

    /// [`Self::locate`] from a guess of the segment (`hint`, e.g. the segment
    /// of a projection near `s`): a few steps from the guess to the segment
    /// holding `s`, else (a guess out of range, too far off, or a non-finite
    /// `s`) the bucket look-up. The answer is `locate`'s whatever the guess.
    #[inline(always)]
    fn locate_from(&self, s: f64, hint: usize) -> (usize, f64) {
        let n_seg = self.seg_len.len();
        if hint < n_seg {
            let w = self.wrap_s(s);
            if w.is_finite() {
                // (n_seg + 1 entries: no bounds checks in the walk)
                let starts = &self.s[..=n_seg];
                let mut k = hint;
                for _ in 0..LOCATE_STEPS {
                    if k > 0 && w < starts[k] {
                        k -= 1;
                    } else if k + 1 < n_seg && w >= starts[k + 1] {
                        k += 1;
                    } else {
                        return (k, w - starts[k]);
                    }
                }
            }
        }
        self.locate(s)
    }

    #[inline(always)]
    fn seg_heading(&self, k: usize, offset: f64) -> f64 {
        let g = &self.segs[k];
        let u = (offset / g.len).clamp(0.0, 1.0);
        wrap_angle(g.h0 + u * g.dh)
    }

    /// Index of the segment holding arc length `s`.
    pub fn segment_at(&self, s: f64) -> usize {
        self.locate(s).0
    }

    /// Point at arc length `s`.
    pub fn point_at(&self, s: f64) -> Point2<f64> {
        let (k, off) = self.locate(s);
        self.points[k] + self.seg_dir[k] * off
    }

    /// Tangent heading at arc length `s` (interpolated, continuous).
    pub fn heading_at(&self, s: f64) -> f64 {
        let (k, off) = self.locate(s);
        self.seg_heading(k, off)
    }

    /// [`Self::heading_at`] with a guess of the segment holding `s` (any
    /// value is fine; one near `s` saves the look-up).
    #[inline]
    pub fn heading_at_from(&self, s: f64, segment_hint: usize) -> f64 {
        let (k, off) = self.locate_from(s, segment_hint);
        self.seg_heading(k, off)
    }

    /// [`Self::heading_at_from`] and the segment holding `s` (the guess for
    /// the next look-up near there).
    #[inline]
    pub(crate) fn heading_and_segment_at_from(&self, s: f64, segment_hint: usize) -> (f64, usize) {
        let (k, off) = self.locate_from(s, segment_hint);
        (self.seg_heading(k, off), k)
    }

    /// [`Self::point_at`] with a guess of the segment holding `s` (as
    /// [`Self::heading_at_from`]), and the segment holding `s`.
    #[inline]
    pub(crate) fn point_and_segment_at_from(
        &self,
        s: f64,
        segment_hint: usize,
    ) -> (Point2<f64>, usize) {
        let (k, off) = self.locate_from(s, segment_hint);
        (self.points[k] + self.seg_dir[k] * off, k)
    }

    /// Unit tangent at arc length `s`.
    pub fn tangent_at(&self, s: f64) -> Vector2<f64> {
        let h = self.heading_at(s);
        Vector2::new(h.cos(), h.sin())
    }

    /// Curvature at `s`: centred heading difference over the sampling width
    /// (shifted inside the path at the ends of an open path).
    pub fn curvature_at(&self, s: f64) -> f64 {
        self.curvature_over(s, self.tangent_sampling_width_m)
    }

    /// [`Self::curvature_at`] with a guess of the segment holding `s` (as
    /// [`Self::heading_at_from`]).
    #[inline]
    pub fn curvature_at_from(&self, s: f64, segment_hint: usize) -> f64 {
        self.curvature_over_from(s, self.tangent_sampling_width_m, segment_hint)
    }

    /// Curvature at `s` sampled over `width_m`.
    pub fn curvature_over(&self, s: f64, width_m: f64) -> f64 {
        self.curvature_over_from(s, width_m, usize::MAX)
    }

    #[inline]
    fn curvature_over_from(&self, s: f64, width_m: f64, segment_hint: usize) -> f64 {
        let w = width_m.min(self.length);
        if !(w > 0.0) {
            return 0.0;
        }
        let (mut a, mut b) = (s - 0.5 * w, s + 0.5 * w);
        if !self.closed {
            if a < 0.0 {
                a = 0.0;
                b = w;
            } else if b > self.length {
                b = self.length;
                a = self.length - w;
            }
        }
        wrap_angle(self.heading_at_from(b, segment_hint) - self.heading_at_from(a, segment_hint))
            / w
    }

    /// Widths at `s`, interpolated between vertices; `None` if the path has none.
    pub fn widths_at(&self, s: f64) -> Option<Widths> {
        let w = self.widths.as_ref()?;
        let (k, off) = self.locate(s);
        let u = (off / self.seg_len[k]).clamp(0.0, 1.0);
        let a = w[k];
        let b = w[(k + 1) % w.len()];
        Some(Widths {
            right_m: a.right_m + u * (b.right_m - a.right_m),
            left_m: a.left_m + u * (b.left_m - a.left_m),
        })
    }

    /// Squared distance from `p` to segment `k`, and the offset of the foot along it.
    #[inline(always)]
    fn seg_dist2(&self, k: usize, p: &Point2<f64>) -> (f64, f64) {
        let g = &self.segs[k];
        let a = g.a;
        let d = p - a;
        // d . dir clamped to [0, len] (f64::clamp without its check of the
        // bounds' order: a segment's length is > 0).
        let (x, len) = (d.dot(&g.dir), g.len);
        let t = if x < 0.0 {
            0.0
        } else if x > len {
            len
        } else {
            x
        };
        let foot = a + g.dir * t;
        ((p - foot).norm_squared(), t)
    }

    fn make_projection(&self, p: &Point2<f64>, k: usize, t: f64, dist2: f64) -> Projection {
        let mut pr = self.make_projection_flat(p, k, t, dist2);
        pr.curvature_per_m = self.curvature_at(pr.s);
        pr
    }

    /// A projection without the curvature (left at NaN), for callers that do not need it.
    #[inline(always)]
    fn make_projection_flat(&self, p: &Point2<f64>, k: usize, t: f64, dist2: f64) -> Projection {
        let g = &self.segs[k];
        let foot = g.a + g.dir * t;
        let heading = self.seg_heading(k, t);
        let rel = p - foot;
        // Side from the segment direction in its interior, from the vertex tangent at its ends.
        let side_dir = if t > 0.0 && t < g.len {
            g.dir
        } else {
            Vector2::new(heading.cos(), heading.sin())
        };
        let c = cross(&side_dir, &rel);
        let lateral =
            if !self.closed && ((k == 0 && t <= 0.0) || (k + 1 == self.segs.len() && t >= g.len)) {
                // Before an open path's start or past its end: the distance
                // from the line the end segment extends, not from the end
                // point. A car SUMO inserts with its front at its lane's start
                // has its rear axle 2.5 m behind the track's first point; as the
                // distance to that point it got a 2.5 m "lateral error" of
                // either sign (the cross product of two nearly parallel
                // vectors) and swerved to make it up.
                cross(&g.dir, &rel)
            } else if c >= 0.0 {
                dist2.sqrt()
            } else {
                -dist2.sqrt()
            };
        let s = self.foot_s(k, t);
        Projection {
            s,
            foot,
            heading_rad: heading,
            lateral_m: lateral,
            curvature_per_m: f64::NAN,
            segment: k,
        }
    }

    /// Full projection (no hint): the globally nearest point of the polyline.
    pub fn project(&self, p: &Point2<f64>) -> Projection {
        let (d2, k, t) = self.nearest_full(p);
        self.make_projection(p, k, t, d2)
    }

    fn nearest_full(&self, p: &Point2<f64>) -> (f64, usize, f64) {
        let n_seg = self.seg_len.len();
        let mut order: Vec<(f64, usize)> = self
            .chunk_boxes
            .iter()
            .enumerate()
            .map(|(c, (lo, hi))| {
                let dx = (lo.x - p.x).max(0.0).max(p.x - hi.x);
                let dy = (lo.y - p.y).max(0.0).max(p.y - hi.y);
                (dx * dx + dy * dy, c)
            })
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut best = (f64::INFINITY, 0usize, 0.0f64);
        for (lb, c) in order {
            if lb > best.0 {
                break;
            }
            for k in c * CHUNK..((c + 1) * CHUNK).min(n_seg) {
                let (d2, t) = self.seg_dist2(k, p);
                if d2 < best.0 {
                    best = (d2, k, t);
                }
            }
        }
        best
    }

    /// Brute-force projection over every segment (reference for tests).
    pub fn project_brute_force(&self, p: &Point2<f64>) -> Projection {
        let mut best = (f64::INFINITY, 0usize, 0.0f64);
        for k in 0..self.seg_len.len() {
            let (d2, t) = self.seg_dist2(k, p);
            if d2 < best.0 {
                best = (d2, k, t);
            }
        }
        self.make_projection(p, best.1, best.2, best.0)
    }

    /// The nearest point among the segments that overlap arc lengths
    /// `[s_from, s_to]` (a scan of those segments): the foot point on one
    /// stretch of a track that passes the same place more than once (laps
    /// of a loop), where the full search could answer with another lap.
    pub fn project_between(&self, p: &Point2<f64>, s_from: f64, s_to: f64) -> Projection {
        let n_seg = self.seg_len.len();
        let first = self
            .s
            .partition_point(|&s| s <= s_from)
            .saturating_sub(1)
            .min(n_seg - 1);
        let mut best = (f64::INFINITY, first, 0.0f64);
        for k in first..n_seg {
            if k > first && self.s[k] > s_to {
                break;
            }
            let (d2, t) = self.seg_dist2(k, p);
            if d2 < best.0 {
                best = (d2, k, t);
            }
        }
        self.make_projection(p, best.1, best.2, best.0)
    }

    /// Windowed projection around the hint `hint_s` (see module docs). A
    /// non-finite hint falls back to the full search.
    pub fn project_hinted(&self, p: &Point2<f64>, hint_s: f64) -> Projection {
        let (d2, k, t) = self.nearest_hinted(p, hint_s);
        self.make_projection(p, k, t, d2)
    }

    /// [`Self::project_with`] without the curvature (`curvature_per_m` is NaN):
    /// the controller's fast path for the points whose curvature it does not use.
    pub fn project_with_no_curvature(&self, p: &Point2<f64>, hint_s: Option<f64>) -> Projection {
        let (d2, k, t) = match hint_s {
            Some(h) => self.nearest_hinted(p, h),
            None => self.nearest_full(p),
        };
        self.make_projection_flat(p, k, t, d2)
    }

    /// Projection by local descent from `hint_s` (no curvature): from the
    /// segment holding the hint, on to the next or previous segment while
    /// that one is nearer. For a hint that is already close to the foot
    /// point (a tracker that predicts it, as the controller does from the
    /// vehicle's motion) this is the windowed projection's answer at about a
    /// third of its cost, and like it never jumps to another leg of the
    /// track. A non-finite hint falls back to the full search.
    pub fn project_near(&self, p: &Point2<f64>, hint_s: f64) -> Projection {
        self.project_near_from(p, hint_s, usize::MAX)
    }

    /// [`Self::project_near`] with a guess of the segment holding `hint_s`
    /// (any value is fine; the last step's `segment` saves a look-up).
    #[inline]
    pub fn project_near_from(
        &self,
        p: &Point2<f64>,
        hint_s: f64,
        segment_hint: usize,
    ) -> Projection {
        let (d2, k, t) = self.nearest_near(p, hint_s, segment_hint);
        self.make_projection_flat(p, k, t, d2)
    }

    /// The arc length of [`Self::project_near`]'s foot point alone (no
    /// heading, side or curvature).
    pub fn arc_near(&self, p: &Point2<f64>, hint_s: f64) -> f64 {
        self.arc_near_from(p, hint_s, usize::MAX).0
    }

    /// [`Self::arc_near`] with a guess of the segment holding `hint_s` (as
    /// [`Self::project_near_from`]); also returns the foot point's segment.
    pub fn arc_near_from(&self, p: &Point2<f64>, hint_s: f64, segment_hint: usize) -> (f64, usize) {
        let (_, k, t) = self.nearest_near(p, hint_s, segment_hint);
        (self.foot_s(k, t), k)
    }

    #[inline(always)]
    fn nearest_near(&self, p: &Point2<f64>, hint_s: f64, segment_hint: usize) -> (f64, usize, f64) {
        let Some(bound) = self.hint_bound(hint_s) else {
            return self.nearest_full(p);
        };
        let n_seg = self.seg_len.len();
        let (k0, _) = self.locate_from(bound, segment_hint);
        let (d0, t0) = self.seg_dist2(k0, p);
        let mut best = (d0, k0, t0);
        // Forward first; only if that did not move, backward.
        if self.descend(p, k0, Self::next_seg, &mut best, n_seg) == 0 {
            self.descend(p, k0, Self::prev_seg, &mut best, n_seg);
        }
        best
    }

    /// Arc length of the point `t` metres into segment `k` (the closing
    /// segment's end is 0 on a closed path).
    #[inline]
    fn foot_s(&self, k: usize, t: f64) -> f64 {
        let s = self.segs[k].s0 + t;
        if self.closed && s >= self.length {
            s - self.length
        } else {
            s
        }
    }

    /// Where a projection hint starts its search: the hint itself on a closed
    /// path, clamped to the path on an open one; None for a non-finite hint
    /// (the caller then searches the whole path).
    #[inline]
    fn hint_bound(&self, hint_s: f64) -> Option<f64> {
        if !hint_s.is_finite() {
            None
        } else if self.closed {
            Some(hint_s)
        } else {
            Some(hint_s.clamp(0.0, self.length))
        }
    }

    /// The segment after / before `k`, wrapping on closed paths.
    #[inline]
    fn next_seg(&self, k: usize) -> Option<usize> {
        let n = self.seg_len.len();
        debug_assert!(k < n);
        if self.closed {
            // (k + 1) % n for a segment k < n, without an integer division.
            Some(if k + 1 >= n { 0 } else { k + 1 })
        } else if k + 1 < n {
            Some(k + 1)
        } else {
            None
        }
    }
    #[inline]
    fn prev_seg(&self, k: usize) -> Option<usize> {
        let n = self.seg_len.len();
        debug_assert!(k < n);
        if self.closed {
            // (k + n - 1) % n for a segment k < n, without an integer division.
            Some(if k == 0 { n - 1 } else { k - 1 })
        } else {
            k.checked_sub(1)
        }
    }

    /// Arc length from `from` forward to `to` (wrapping on closed paths).
    #[inline]
    fn forward_distance(&self, from: f64, to: f64) -> f64 {
        let d = self.arc_delta(from, to);
        if self.closed && d < 0.0 {
            d + self.length
        } else {
            d
        }
    }

    /// (squared distance, segment, offset) of the hinted nearest point.
    fn nearest_hinted(&self, p: &Point2<f64>, hint_s: f64) -> (f64, usize, f64) {
        let Some(bound) = self.hint_bound(hint_s) else {
            return self.nearest_full(p);
        };
        let n_seg = self.seg_len.len();
        let (k0, _) = self.locate(bound);
        let hint = self.wrap_s(hint_s);
        let mut best = {
            let (d2, t) = self.seg_dist2(k0, p);
            (d2, k0, t)
        };
        let mut scanned = 1usize;
        let consider = |k: usize, best: &mut (f64, usize, f64)| -> bool {
            let (d2, t) = self.seg_dist2(k, p);
            let better = d2 < best.0;
            if better {
                *best = (d2, k, t);
            }
            better
        };
        // The window: segments starting within window_ahead_m ahead of the
        // hint, and ending within window_back_m behind it.
        let mut last_fwd = k0;
        while scanned < n_seg {
            match self.next_seg(last_fwd) {
                Some(nx) if self.forward_distance(hint, self.s[nx]) <= self.window_ahead_m => {
                    last_fwd = nx;
                    scanned += 1;
                    consider(nx, &mut best);
                }
                _ => break,
            }
        }
        let mut last_bwd = k0;
        while scanned < n_seg {
            match self.prev_seg(last_bwd) {
                Some(pv)
                    if self.forward_distance(self.s[pv] + self.seg_len[pv], hint)
                        <= self.window_back_m =>
                {
                    last_bwd = pv;
                    scanned += 1;
                    consider(pv, &mut best);
                }
                _ => break,
            }
        }
        // Walk on past the window edge while the distance keeps decreasing.
        let step: Option<(usize, Advance)> = if best.1 == last_fwd {
            Some((last_fwd, Self::next_seg))
        } else if best.1 == last_bwd {
            Some((last_bwd, Self::prev_seg))
        } else {
            None
        };
        if let Some((k, advance)) = step {
            self.descend(p, k, advance, &mut best, n_seg - scanned);
        }
        best
    }

    /// From segment `k`, on along `advance` while the next segment is nearer
    /// to `p` than `best` (which it updates), at most `budget` segments.
    /// Returns how many segments it moved.
    #[inline(always)]
    fn descend(
        &self,
        p: &Point2<f64>,
        mut k: usize,
        advance: Advance,
        best: &mut (f64, usize, f64),
        budget: usize,
    ) -> usize {
        let mut moved = 0;
        while moved < budget {
            let Some(nk) = advance(self, k) else { break };
            let (d2, t) = self.seg_dist2(nk, p);
            if d2 >= best.0 {
                break;
            }
            *best = (d2, nk, t);
            k = nk;
            moved += 1;
        }
        moved
    }

    /// Projects with a hint when one is given, with the full search otherwise.
    pub fn project_with(&self, p: &Point2<f64>, hint_s: Option<f64>) -> Projection {
        match hint_s {
            Some(h) => self.project_hinted(p, h),
            None => self.project(p),
        }
    }
}

/// `count` points (computed from the parameter `name` = `value`) as a usize,
/// or an error when a generator would make more than the limit.
fn point_count(name: &'static str, value: f64, count: f64) -> Result<usize, PathError> {
    crate::limits::count_within(count, crate::limits::MAX_PATH_POINTS).ok_or(
        PathError::TooManyPoints {
            name,
            value,
            points: count,
            limit: crate::limits::MAX_PATH_POINTS,
        },
    )
}

fn check_positive(name: &'static str, v: f64) -> Result<(), PathError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(PathError::Parameter {
            name,
            value: v,
            message: "must be finite and > 0",
        })
    }
}

/// Every coordinate finite and within range, every width finite and
/// non-negative, one width pair per point; errors name the point.
fn check_points(
    points: &[[f64; 2]],
    widths: Option<&[Widths]>,
    location: &impl Fn(usize) -> String,
) -> Result<(), PathError> {
    if let Some(w) = widths {
        if w.len() != points.len() {
            return Err(PathError::WidthCount {
                widths: w.len(),
                points: points.len(),
            });
        }
    }
    for (i, p) in points.iter().enumerate() {
        for (what, v) in [("x", p[0]), ("y", p[1])] {
            if !v.is_finite() {
                return Err(PathError::NonFinite {
                    location: location(i),
                    what,
                    value: v,
                });
            }
            if v.abs() > crate::limits::MAX_COORDINATE_M {
                return Err(PathError::TooFar {
                    location: location(i),
                    what,
                    value: v,
                });
            }
        }
        if let Some(w) = widths {
            for (what, v) in [("right width", w[i].right_m), ("left width", w[i].left_m)] {
                if !v.is_finite() {
                    return Err(PathError::NonFinite {
                        location: location(i),
                        what,
                        value: v,
                    });
                }
                if v < 0.0 {
                    return Err(PathError::NegativeWidth {
                        location: location(i),
                        what,
                        value: v,
                    });
                }
            }
        }
    }
    Ok(())
}

/// Heading of the tangent at each vertex: the mean of its two segments'
/// directions (one at an open path's ends).
fn vertex_headings(seg_dir: &[Vector2<f64>], n: usize, closed: bool) -> Vec<f64> {
    let n_seg = seg_dir.len();
    (0..n)
        .map(|i| {
            let (prev, next) = if closed {
                (Some((i + n_seg - 1) % n_seg), Some(i % n_seg))
            } else {
                (i.checked_sub(1), if i < n_seg { Some(i) } else { None })
            };
            let t = match (prev, next) {
                (Some(a), Some(b)) => {
                    let sum = seg_dir[a] + seg_dir[b];
                    if sum.norm() < 1e-9 {
                        seg_dir[b]
                    } else {
                        sum
                    }
                }
                (Some(a), None) => seg_dir[a],
                (None, Some(b)) => seg_dir[b],
                (None, None) => unreachable!("a path has at least one segment"),
            };
            t.y.atan2(t.x)
        })
        .collect()
}

/// Bounding box of each run of `CHUNK` segments.
fn chunk_boxes(pts: &[Point2<f64>], n_seg: usize) -> Vec<(Point2<f64>, Point2<f64>)> {
    let n = pts.len();
    (0..n_seg)
        .step_by(CHUNK)
        .map(|start| {
            let mut lo = pts[start];
            let mut hi = pts[start];
            for k in start..(start + CHUNK).min(n_seg) {
                for q in [pts[k], pts[(k + 1) % n]] {
                    lo = Point2::new(lo.x.min(q.x), lo.y.min(q.y));
                    hi = Point2::new(hi.x.max(q.x), hi.y.max(q.y));
                }
            }
            (lo, hi)
        })
        .collect()
}

/// For each of `n_seg` equal arc-length buckets, the first segment in it.
fn buckets(s: &[f64], length: f64) -> Vec<u32> {
    let n_seg = s.len() - 1;
    (0..n_seg)
        .map(|b| {
            let at = b as f64 * length / n_seg as f64;
            s[1..n_seg].partition_point(|&x| x <= at) as u32
        })
        .collect()
}

#[cfg(test)]
mod tests {

    #[test]
    fn an_open_path_at_and_past_its_end_stays_on_its_last_segment() {
        // 100 m in 1 m segments: s = 100 is the end of segment 99, and
        // beyond it the last segment extrapolates.
        let p = Path::straight(100.0, 1.0).unwrap();
        let last = p.n_segments() - 1;
        for s in [99.5, 100.0, 103.0] {
            assert_eq!(p.segment_at(s), last, "s = {s}");
            let q = p.point_at(s);
            assert!((q.x - s).abs() < 1e-9 && q.y.abs() < 1e-9, "s = {s}: {q}");
        }
    }

    #[test]
    fn a_foot_at_the_closing_vertex_is_at_arc_length_zero() {
        // A closed square, 40 m a side: the closing segment ends where the
        // path starts. A point outside that corner, searched from the
        // closing segment, has its foot at the corner: arc length 0 (the
        // closing segment's end), not the lap's length or anything past it.
        let sq = Path::new(
            &[[0.0, 0.0], [40.0, 0.0], [40.0, 40.0], [0.0, 40.0]],
            None,
            true,
        )
        .unwrap();
        let pr = sq.project_hinted(&Point2::new(-3.0, -4.0), sq.length() - 1.0);
        assert!(
            (pr.foot - Point2::new(0.0, 0.0)).norm() < 1e-9,
            "{:?}",
            pr.foot
        );
        assert!(pr.s.abs() < 1e-9, "s = {}", pr.s);
    }

    #[test]
    fn arc_delta_of_half_a_lap_is_forward_either_way() {
        // The shortest way round is in (-L/2, L/2]: exactly half a lap is
        // +L/2 whichever end it is measured from.
        let p = Path::circle(20.0, 0.01).unwrap();
        let (l, h) = (p.length(), 0.5 * p.length());
        assert_eq!(p.arc_delta(0.0, h), h);
        assert_eq!(p.arc_delta(h, 0.0), h);
        assert!((p.arc_delta(0.25 * l, 0.75 * l) - h).abs() < 1e-9);
        // Just inside, the sign is the way round.
        assert!(p.arc_delta(h, 1e-6) < 0.0);
        assert!(p.arc_delta(1e-6, h) > 0.0);
    }

    #[test]
    fn arc_length_lookup_is_exact_on_unevenly_sampled_paths() {
        // Segment lengths from 0.01 m to 40 m, as road-network lane shapes have.
        let mut pts = vec![[0.0, 0.0]];
        let mut x = 0.0;
        for i in 0..300 {
            x += [0.01, 0.3, 40.0, 1.0, 2.5, 0.05][i % 6];
            pts.push([x, 0.1 * (i as f64).sin()]);
        }
        for closed in [false, true] {
            let p = Path::new(&pts, None, closed).unwrap();
            let n_seg = p.n_segments();
            // [0, length): a closed path wraps `length` to 0.
            for j in 0..20_000 {
                let s = p.length() * j as f64 / 20_000.0;
                let k = p.s[1..n_seg].partition_point(|&b| b <= s);
                assert_eq!(p.segment_at(s), k, "s = {s}");
            }
        }
    }

    use super::*;

    /// A deterministic stream of numbers in [0, 1) (no rand dependency).
    fn uniform(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn a_segment_guess_never_changes_a_look_up() {
        // Unevenly sampled (as road-network lane shapes are), open and closed.
        let mut pts = vec![[0.0, 0.0]];
        let mut x = 0.0f64;
        for i in 0..200 {
            x += [0.01, 0.3, 40.0, 1.0, 2.5, 0.05, 7.0][i % 7];
            pts.push([x, 3.0 * (0.05 * x).sin()]);
        }
        let mut rng = 7u64;
        for closed in [false, true] {
            let p = Path::new(&pts, None, closed).unwrap();
            let (n, len) = (p.n_segments(), p.length());
            let mut specials = vec![
                0.0,
                -0.0,
                len,
                -len,
                2.0 * len,
                -1e-300,
                len - 1e-12,
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ];
            specials.extend(p.vertex_s().iter().copied());
            let mut queries: Vec<f64> = (0..4000)
                .map(|_| (3.0 * uniform(&mut rng) - 1.0) * len)
                .collect();
            queries.extend(specials);
            for (j, &s) in queries.iter().enumerate() {
                let exact = p.locate(s);
                let k_true = exact.0;
                let hints = [
                    0,
                    n - 1,
                    n,
                    usize::MAX,
                    k_true,
                    k_true.saturating_sub(3),
                    (k_true + 5) % n,
                    (uniform(&mut rng) * 1.2 * n as f64) as usize,
                ];
                for &h in &hints {
                    let got = p.locate_from(s, h);
                    assert_eq!(got.0, exact.0, "s = {s}, hint {h}, closed {closed}");
                    assert!(
                        got.1.to_bits() == exact.1.to_bits(),
                        "s = {s}, hint {h}: offset {} vs {}",
                        got.1,
                        exact.1
                    );
                    let (a, b) = (p.heading_at_from(s, h), p.heading_at(s));
                    assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
                    let (a, b) = (p.curvature_at_from(s, h), p.curvature_at(s));
                    assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
                }
                // Projections from a hint near the query point, with any guess.
                if s.is_finite() && j % 4 == 0 {
                    let q = p.point_at(s) + Vector2::new(0.3, -0.7 * uniform(&mut rng));
                    let hint_s = s + 2.0 * uniform(&mut rng) - 1.0;
                    let plain = p.project_near(&q, hint_s);
                    let arc = p.arc_near(&q, hint_s);
                    for &h in &hints {
                        // (curvature is NaN in both: compared without it)
                        let got = Projection {
                            curvature_per_m: 0.0,
                            ..p.project_near_from(&q, hint_s, h)
                        };
                        let want = Projection {
                            curvature_per_m: 0.0,
                            ..plain
                        };
                        assert_eq!(got, want, "s = {s}, hint {h}");
                        let (a, k) = p.arc_near_from(&q, hint_s, h);
                        assert_eq!((a.to_bits(), k), (arc.to_bits(), plain.segment));
                    }
                }
            }
        }
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-10.0, -PI, -3.0, 0.0, 3.0, PI, 10.0, 7.0 * PI] {
            let w = wrap_angle(a);
            assert!(w > -PI - 1e-12 && w <= PI + 1e-12, "{a} -> {w}");
            assert!(
                ((a - w) / (2.0 * PI)).fract().abs() < 1e-9
                    || ((a - w) / (2.0 * PI)).fract().abs() > 1.0 - 1e-9
            );
        }
        assert_eq!(wrap_angle(-PI), PI);
    }

    #[test]
    fn straight_projection_and_sign() {
        let p = Path::straight(100.0, 1.0).unwrap();
        let pr = p.project(&Point2::new(30.2, 2.5));
        assert!((pr.s - 30.2).abs() < 1e-12);
        assert!((pr.lateral_m - 2.5).abs() < 1e-12);
        assert!(pr.heading_rad.abs() < 1e-12);
        let pr = p.project(&Point2::new(30.2, -1.5));
        assert!(
            (pr.lateral_m + 1.5).abs() < 1e-12,
            "right of the path is negative"
        );
    }

    #[test]
    fn beyond_an_open_paths_ends_the_lateral_error_is_from_the_extended_end_segment() {
        // An L: (0,0) -> (10,0) -> (10,10). Behind the start and past the
        // end the foot is the end point (s clamped), and the lateral error
        // is the distance from the end segment's line, not from the point.
        let p = Path::new(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], None, false).unwrap();
        for (q, s, lat) in [
            ((-2.5, 0.0), 0.0, 0.0),
            ((-2.5, 0.4), 0.0, 0.4),
            ((-2.5, -0.4), 0.0, -0.4),
            ((10.0, 13.0), 20.0, 0.0),
            ((9.5, 13.0), 20.0, 0.5),
        ] {
            for pr in [
                p.project(&Point2::new(q.0, q.1)),
                p.project_brute_force(&Point2::new(q.0, q.1)),
                p.project_near(&Point2::new(q.0, q.1), s),
            ] {
                assert!((pr.s - s).abs() < 1e-12, "{q:?}: s {}", pr.s);
                assert!(
                    (pr.lateral_m - lat).abs() < 1e-12,
                    "{q:?}: lateral {}",
                    pr.lateral_m
                );
            }
        }
        // The outer corner of an interior vertex keeps the distance to it.
        let pr = p.project(&Point2::new(11.0, -1.0));
        assert!((pr.lateral_m.abs() - 2f64.sqrt()).abs() < 1e-12);
        // A closed path has no ends.
        let c = Path::new(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], None, true).unwrap();
        assert!(c.project(&Point2::new(-1.0, -1.0)).lateral_m.abs() > 1.0);
    }

    #[test]
    fn circle_heading_and_curvature() {
        let r = 20.0;
        let p = Path::circle(r, 1e-4).unwrap();
        assert!((p.length() - 2.0 * PI * r).abs() < 1e-2);
        for s in [0.0, 10.0, 33.3, 100.0] {
            let expected = wrap_angle(s / r);
            assert!(
                wrap_angle(p.heading_at(s) - expected).abs() < 1e-4,
                "heading at {s}"
            );
            assert!(
                (p.curvature_at(s) - 1.0 / r).abs() < 1e-4,
                "curvature at {s}"
            );
        }
        // Inside the circle is on the left.
        let pr = p.project(&Point2::new(0.0, 1.0));
        assert!((pr.lateral_m - 1.0).abs() < 1e-3);
    }

    #[test]
    fn duplicates_dropped_and_errors_name_point() {
        let p = Path::new(
            &[[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],
            None,
            false,
        )
        .unwrap();
        assert_eq!(p.len_points(), 3);
        let e = Path::new(&[[0.0, 0.0], [f64::NAN, 0.0]], None, false).unwrap_err();
        assert!(e.to_string().contains("point 1"), "{e}");
        let e = Path::new(&[[1.0, 1.0], [1.0, 1.0]], None, false).unwrap_err();
        assert_eq!(e, PathError::TooFewPoints(1));
        let e = Path::new(&[], None, false).unwrap_err();
        assert_eq!(e, PathError::TooFewPoints(0));
        let w = [
            Widths {
                right_m: 1.0,
                left_m: 1.0,
            },
            Widths {
                right_m: -1.0,
                left_m: 1.0,
            },
        ];
        let e = Path::new(&[[0.0, 0.0], [1.0, 0.0]], Some(&w), false).unwrap_err();
        assert!(
            e.to_string().contains("point 1") && e.to_string().contains("right width"),
            "{e}"
        );
    }

    #[test]
    fn tum_parse_errors_name_line() {
        let e = Path::from_tum_str(
            "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,abc,1,1\n",
            "t.csv",
            true,
        )
        .unwrap_err();
        assert!(e.to_string().contains("t.csv: line 3"), "{e}");
        let e = Path::from_tum_str("# h\n0,0,1,1\n1,0,1\n", "t.csv", true).unwrap_err();
        assert!(e.to_string().contains("line 3"), "{e}");
        let e = Path::from_tum_str("# h\n0,0,1,1\n1,0,-1,1\n", "t.csv", true).unwrap_err();
        assert!(
            e.to_string().contains("line 3") && e.to_string().contains(">= 0"),
            "{e}"
        );
        let e = Path::from_tum_str("# h\n", "t.csv", true).unwrap_err();
        assert!(e.to_string().contains("at least 2"), "{e}");
        let p = Path::from_tum_str("# h\n0,0,1,2\n10,0,1,2\n10,10,1,2\n", "t.csv", true).unwrap();
        assert!(p.is_closed());
        assert_eq!(
            p.widths_at(5.0).unwrap(),
            Widths {
                right_m: 1.0,
                left_m: 2.0
            }
        );
    }

    #[test]
    fn test_track_is_closed_smooth_and_turns_both_ways() {
        let p = Path::test_track(1.0).unwrap();
        let pts = p.points();
        // The closing segment is as long as the others (the loop really closes).
        let closing = (pts[0] - pts[pts.len() - 1]).norm();
        assert!((closing - 1.0).abs() < 0.05, "closing segment {closing}");
        let mut kmin = f64::INFINITY;
        let mut kmax = f64::NEG_INFINITY;
        let mut s = 0.0;
        while s < p.length() {
            let k = p.curvature_at(s);
            kmin = kmin.min(k);
            kmax = kmax.max(k);
            s += 0.5;
        }
        assert!(
            kmin < -0.02 && kmax > 0.035 && kmax < 0.045,
            "curvature range [{kmin}, {kmax}]"
        );
    }

    #[test]
    fn open_path_extrapolates() {
        let p = Path::straight(10.0, 1.0).unwrap();
        let q = p.point_at(12.0);
        assert!((q.x - 12.0).abs() < 1e-12 && q.y.abs() < 1e-12);
        let q = p.point_at(-3.0);
        assert!((q.x + 3.0).abs() < 1e-12);
    }
}
