//! Polyline geometry: arc length, even resampling, Gaussian smoothing, a
//! smoothstep blend from one polyline onto another, and the distance between
//! two polylines; [`chain`] joins pieces of polylines into one track.
//!
//! These are the building blocks of reference tracks made from road lane
//! centrelines (lanes are polylines with long straight pieces and short
//! kinks where they meet). They are plain functions on slices of `[x, y]`
//! points, with no knowledge of where the points come from.
//!
//! Floating point: each function keeps one fixed order of operations,
//! written down at the function, so that its results are reproducible to the
//! bit: segment lengths are `hypot(dx, dy)` (the C library's), arc lengths a
//! sequential running sum of them, linear interpolation is
//! `slope * (x - x0) + y0`. [`crate::Path`] measures its own arc length with
//! `sqrt(dx^2 + dy^2)`, which can differ from these in the last bit.

pub mod chain;
pub mod turns;

use thiserror::Error;

/// A point `[x, y]` (metres).
pub type Xy = [f64; 2];

/// A polyline that the geometry cannot use.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PolylineError {
    /// Fewer points than the operation needs.
    #[error("{what} needs at least {needed} point(s), got {got}")]
    TooFewPoints {
        what: &'static str,
        needed: usize,
        got: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("{what}: point {index} is not finite ({x}, {y})")]
    NonFinite {
        what: &'static str,
        index: usize,
        x: f64,
        y: f64,
    },
    /// Per-point values that are not one per point.
    #[error("{what}: {got} values for {expected} points")]
    Count {
        what: &'static str,
        got: usize,
        expected: usize,
    },
    /// A parameter is out of range.
    #[error("{name} = {value}: {message}")]
    Parameter {
        name: &'static str,
        value: f64,
        message: &'static str,
    },
}

/// Checks that `points` has at least `needed` points, all finite.
pub fn check_points(what: &'static str, points: &[Xy], needed: usize) -> Result<(), PolylineError> {
    if points.len() < needed {
        return Err(PolylineError::TooFewPoints {
            what,
            needed,
            got: points.len(),
        });
    }
    match points
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        Some(index) => Err(PolylineError::NonFinite {
            what,
            index,
            x: points[index][0],
            y: points[index][1],
        }),
        None => Ok(()),
    }
}

fn check_positive(name: &'static str, value: f64) -> Result<(), PolylineError> {
    if value > 0.0 && value.is_finite() {
        Ok(())
    } else {
        Err(PolylineError::Parameter {
            name,
            value,
            message: "must be positive and finite",
        })
    }
}

/// Length of the segment from `a` to `b`: `hypot(b - a)`.
#[inline]
pub fn distance(a: Xy, b: Xy) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

/// Arc length at each point: 0 at the first, then a running sum of the
/// segment lengths (empty for no points).
pub fn arc_lengths(points: &[Xy]) -> Vec<f64> {
    let mut s = Vec::with_capacity(points.len());
    let mut total = 0.0;
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            total += distance(points[i - 1], *p);
        }
        s.push(total);
    }
    s
}

/// Total length: the last of [`arc_lengths`] (0 for fewer than 2 points).
pub fn length(points: &[Xy]) -> f64 {
    let mut total = 0.0;
    for w in points.windows(2) {
        total += distance(w[0], w[1]);
    }
    total
}

/// Linear interpolation of the table (`xp`, `fp`) at `x`, `xp`
/// non-decreasing and not empty: `fp[0]` below `xp[0]`, the last `fp` from
/// the last `xp` on, else on the segment from the last `xp[j] <= x` (so
/// repeated `xp` values take the later one), `fp[j]` where `x == xp[j]`,
/// else `slope * (x - xp[j]) + fp[j]` (NumPy's `interp`, to the bit).
pub fn interp(x: f64, xp: &[f64], fp: &[f64]) -> f64 {
    let n = xp.len();
    if x.is_nan() {
        return x;
    }
    if x > xp[n - 1] {
        return fp[n - 1];
    }
    if x < xp[0] {
        return fp[0];
    }
    // The last j with xp[j] <= x.
    let j = xp.partition_point(|&v| v <= x) - 1;
    if j == n - 1 || xp[j] == x {
        return fp[j];
    }
    let slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
    let y = slope * (x - xp[j]) + fp[j];
    if !y.is_nan() {
        return y;
    }
    let y = slope * (x - xp[j + 1]) + fp[j + 1];
    if y.is_nan() && fp[j] == fp[j + 1] {
        fp[j]
    } else {
        y
    }
}

/// `n + 1` evenly spaced values from 0 to `stop` (the last exactly `stop`):
/// `i * (stop / n)` (NumPy's `linspace(0, stop, n + 1)`).
fn even_stations(stop: f64, n: usize) -> Vec<f64> {
    let step = stop / n as f64;
    let mut t: Vec<f64> = if step == 0.0 {
        (0..=n).map(|i| i as f64 / n as f64 * stop + 0.0).collect()
    } else {
        (0..=n).map(|i| i as f64 * step + 0.0).collect()
    };
    t[n] = stop;
    t
}

/// The polyline at arc lengths `t` (interpolated, clamped to its ends);
/// `s` are its [`arc_lengths`].
pub fn points_at(points: &[Xy], s: &[f64], t: &[f64]) -> Vec<Xy> {
    let xs: Vec<f64> = points.iter().map(|p| p[0]).collect();
    let ys: Vec<f64> = points.iter().map(|p| p[1]).collect();
    t.iter()
        .map(|&x| [interp(x, s, &xs), interp(x, s, &ys)])
        .collect()
}

/// Points evenly spaced along `points` from its first to its last, at most
/// `spacing_m` apart: `max(1, ceil(length / spacing_m))` segments. Needs at
/// least 2 finite points and a positive spacing.
pub fn resample(points: &[Xy], spacing_m: f64) -> Result<Vec<Xy>, PolylineError> {
    check_points("resampled polyline", points, 2)?;
    check_positive("spacing_m", spacing_m)?;
    let s = arc_lengths(points);
    let total = s[s.len() - 1];
    let n = ((total / spacing_m).ceil() as usize).max(1);
    Ok(points_at(points, &s, &even_stations(total, n)))
}

/// `3u^2 - 2u^3` of `u` clamped to [0, 1], as `u * u * (3 - 2u)`.
#[inline]
pub fn smoothstep(u: f64) -> f64 {
    // NaN stays NaN (as NumPy's clip leaves it).
    let u = u.clamp(0.0, 1.0);
    u * u * (3.0 - 2.0 * u)
}

/// Sum of `a` in NumPy's pairwise order (blocks of 8 partial sums up to 128
/// values, halves above), so a normalised kernel matches NumPy's to the bit.
fn pairwise_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        return a.iter().fold(-0.0, |acc, &v| acc + v);
    }
    if n <= 128 {
        let mut r = [a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]];
        let full = n - n % 8;
        let mut i = 8;
        while i < full {
            for (j, rj) in r.iter_mut().enumerate() {
                *rj += a[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for v in &a[full..] {
            res += v;
        }
        return res;
    }
    let mut half = n / 2;
    half -= half % 8;
    pairwise_sum(&a[..half]) + pairwise_sum(&a[half..])
}

/// A normalised Gaussian of standard deviation `sigma_pts` (in points)
/// over `2 * ceil(3 sigma) + 1` taps.
pub fn gaussian_kernel(sigma_pts: f64) -> Vec<f64> {
    let half = (3.0 * sigma_pts).ceil() as i64;
    let mut k: Vec<f64> = (-half..=half)
        .map(|i| {
            let x = i as f64 / sigma_pts;
            (-0.5 * (x * x)).exp()
        })
        .collect();
    let total = pairwise_sum(&k);
    for v in &mut k {
        *v /= total;
    }
    k
}

/// Gaussian smoothing along the polyline with standard deviation
/// `sigma_pts` points, the ends padded with copies of the end points and
/// kept in place; unchanged for `sigma_pts <= 0` or fewer than 5 points.
/// Each output is the sequential sum of products, first tap first.
pub fn smooth(points: &[Xy], sigma_pts: f64) -> Vec<Xy> {
    let n = points.len();
    if !(sigma_pts > 0.0) || n < 5 {
        return points.to_vec();
    }
    let k = gaussian_kernel(sigma_pts);
    let half = k.len() / 2;
    let at = |i: usize| points[i.saturating_sub(half).min(n - 1)];
    let mut out: Vec<Xy> = (0..n)
        .map(|i| {
            let mut acc = [0.0, 0.0];
            for (j, kj) in k.iter().enumerate() {
                let p = at(i + j);
                acc[0] += p[0] * kj;
                acc[1] += p[1] * kj;
            }
            acc
        })
        .collect();
    out[0] = points[0];
    out[n - 1] = points[n - 1];
    out
}

/// Finite-difference tangent at each point with unit spacing: the central
/// difference `(p[i+1] - p[i-1]) / 2` inside, one-sided at the ends
/// (NumPy's `gradient`); `[1, 0]` for a single point, nothing for none.
pub fn gradient(points: &[Xy]) -> Vec<Xy> {
    let n = points.len();
    if n < 2 {
        return vec![[1.0, 0.0]; n];
    }
    let diff = |a: Xy, b: Xy, div: f64| [(b[0] - a[0]) / div, (b[1] - a[1]) / div];
    let mut out = Vec::with_capacity(n);
    out.push(diff(points[0], points[1], 1.0));
    for i in 1..n - 1 {
        out.push(diff(points[i - 1], points[i + 1], 2.0));
    }
    out.push(diff(points[n - 2], points[n - 1], 1.0));
    out
}

/// A polyline moved smoothly from one line onto another: see [`blend`].
#[derive(Debug, Clone, PartialEq)]
pub struct Blend {
    /// The blended points, one per resampled point of the first line.
    pub points: Vec<Xy>,
    /// The smoothstep weight at each point: 0 on the first line, 1 on the second.
    pub weight: Vec<f64>,
    /// Arc length along the (resampled) first line at each point.
    pub s_from: Vec<f64>,
    /// Arc length along the second line of the point each is blended with.
    pub s_onto: Vec<f64>,
    /// Where the move starts and how long it is (after clamping).
    pub start_m: f64,
    pub length_m: f64,
}

/// Moves from polyline `from` (resampled every `spacing_m`) onto `onto`
/// with a smoothstep weight between arc lengths `start_m` and `start_m +
/// length_m` along `from` (defaults: 0 and the rest of the line; `start_m`
/// is clamped to the line, `length_m` to at least 1 micrometre). Each point
/// of `from` is blended with the point of `onto` at the same fraction of its
/// length: `(1 - w) * a + w * b`.
pub fn blend(
    from: &[Xy],
    onto: &[Xy],
    spacing_m: f64,
    start_m: Option<f64>,
    length_m: Option<f64>,
) -> Result<Blend, PolylineError> {
    check_points("blended-onto polyline", onto, 2)?;
    let sa = resample(from, spacing_m)?;
    let da = arc_lengths(&sa);
    let db = arc_lengths(onto);
    let last = da[da.len() - 1];
    let total = if 1e-9 > last { 1e-9 } else { last };
    let onto_len = db[db.len() - 1];
    let tb: Vec<f64> = da.iter().map(|&d| d / total * onto_len).collect();
    let pb = points_at(onto, &db, &tb);
    let start = match start_m {
        None => 0.0,
        Some(x) => {
            let x = if 0.0 > x { 0.0 } else { x };
            if total < x {
                total
            } else {
                x
            }
        }
    };
    let length = match length_m {
        None => total - start,
        Some(l) => {
            if 1e-6 > l {
                1e-6
            } else {
                l
            }
        }
    };
    let weight: Vec<f64> = da
        .iter()
        .map(|&d| smoothstep((d - start) / length))
        .collect();
    let points = sa
        .iter()
        .zip(&pb)
        .zip(&weight)
        .map(|((a, b), &w)| [(1.0 - w) * a[0] + w * b[0], (1.0 - w) * a[1] + w * b[1]])
        .collect();
    Ok(Blend {
        points,
        weight,
        s_from: da,
        s_onto: tb,
        start_m: start,
        length_m: length,
    })
}

#[inline]
fn cross(u: Xy, v: Xy) -> f64 {
    u[0] * v[1] - u[1] * v[0]
}

#[inline]
fn sub(a: Xy, b: Xy) -> Xy {
    [a[0] - b[0], a[1] - b[1]]
}

/// Distance from `p` to the segment `s0`-`s1` (a segment shorter than
/// 1 micrometre counts as a point).
pub fn point_segment_distance(p: Xy, s0: Xy, s1: Xy) -> f64 {
    let e = sub(s1, s0);
    let len2 = e[0] * e[0] + e[1] * e[1];
    let den = if len2 > 1e-12 || len2.is_nan() {
        len2
    } else {
        1e-12
    };
    let w = sub(p, s0);
    let t = (w[0] * e[0] + w[1] * e[1]) / den;
    let t = t.clamp(0.0, 1.0);
    let dx = s0[0] + t * e[0] - p[0];
    let dy = s0[1] + t * e[1] - p[1];
    dx.hypot(dy)
}

/// Do the segments `a`-`b` and `c`-`d` cross (each one's ends strictly on
/// both sides of the other's line)?
pub fn segments_cross(a: Xy, b: Xy, c: Xy, d: Xy) -> bool {
    let (ab, dc) = (sub(b, a), sub(d, c));
    let (d1, d2) = (cross(ab, sub(c, a)), cross(ab, sub(d, a)));
    let (d3, d4) = (cross(dc, sub(a, c)), cross(dc, sub(b, c)));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Smallest distance between polylines `p` and `q`: 0 where two of their
/// segments cross, else the smallest distance from an end point of a
/// segment of one to a segment of the other. A single point counts as a
/// segment of length 0; infinite when either is empty. Errors on a
/// coordinate that is not finite.
pub fn segments_distance(p: &[Xy], q: &[Xy]) -> Result<f64, PolylineError> {
    check_points("first polyline", p, 0)?;
    check_points("second polyline", q, 0)?;
    if p.is_empty() || q.is_empty() {
        return Ok(f64::INFINITY);
    }
    let segs = |v: &[Xy]| -> Vec<(Xy, Xy)> {
        if v.len() == 1 {
            vec![(v[0], v[0])]
        } else {
            v.windows(2).map(|w| (w[0], w[1])).collect()
        }
    };
    let (ps, qs) = (segs(p), segs(q));
    let mut best = f64::INFINITY;
    for &(a, b) in &ps {
        for &(c, d) in &qs {
            if segments_cross(a, b, c, d) {
                return Ok(0.0);
            }
            for dist in [
                point_segment_distance(a, c, d),
                point_segment_distance(b, c, d),
                point_segment_distance(c, a, b),
                point_segment_distance(d, a, b),
            ] {
                if dist < best {
                    best = dist;
                }
            }
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests;
