//! Turns sharper than a vehicle can drive, rounded off.
//!
//! Road maps have kinks no car follows: a lane that overshoots its junction
//! and comes back (Bologna's 58[0] -> 58[1] turns about 170 deg within
//! 2.4 m), short lanes that meet at a sharp angle. A driver cuts them. After
//! the Gaussian smoothing of the whole track ([`super::smooth`]), each
//! stretch whose curvature is above `kappa_max` is smoothed again, alone,
//! with wider Gaussians (two, three, four and six times the track's) until
//! its curvature is within `kappa_max`, and the result is blended into the
//! track with a smoothstep ramp on either side. A turn that no width rounds
//! off (a U-turn between lanes closer than twice the radius) keeps the
//! rounding with the smallest peak curvature among those tried, or stays as
//! it was when none is smoother (smoothing the legs of a U-turn together
//! makes a cusp).

use super::{smooth, smoothstep, Xy};

/// The widths tried, in multiples of the track's own smoothing.
const WIDTHS: [f64; 4] = [2.0, 3.0, 4.0, 6.0];

/// Curvature (1/m, left positive) at each point: the turning angle between
/// the segments before and after it over their mean length; 0 at the ends
/// and where a segment has no length.
pub fn curvatures(points: &[Xy]) -> Vec<f64> {
    let n = points.len();
    let mut k = vec![0.0; n];
    refresh_curvatures(points, &mut k, 1, n);
    k
}

/// [`curvatures`] at the inner point `i`.
fn curvature_at(points: &[Xy], i: usize) -> f64 {
    let (a, b, c) = (points[i - 1], points[i], points[i + 1]);
    let (ux, uy) = (b[0] - a[0], b[1] - a[1]);
    let (vx, vy) = (c[0] - b[0], c[1] - b[1]);
    let (lu, lv) = (ux.hypot(uy), vx.hypot(vy));
    if lu > 1e-9 && lv > 1e-9 {
        let turn = (ux * vy - uy * vx).atan2(ux * vx + uy * vy);
        turn / (0.5 * (lu + lv))
    } else {
        0.0
    }
}

/// [`curvatures`] of `points` again at `from..=to` (clamped to the inner
/// points), the rest of `k` left as it is.
fn refresh_curvatures(points: &[Xy], k: &mut [f64], from: usize, to: usize) {
    let last = points.len().saturating_sub(2);
    for (i, ki) in k
        .iter_mut()
        .enumerate()
        .take(to.min(last) + 1)
        .skip(from.max(1))
    {
        *ki = curvature_at(points, i);
    }
}

fn peak(k: &[f64]) -> f64 {
    k.iter().fold(0.0, |m: f64, v| m.max(v.abs()))
}

/// What [`round_sharp_turns`] did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Rounding {
    /// `[first, last]` point of each stretch that was smoothed again.
    pub stretches: Vec<(usize, usize)>,
    /// Peak |curvature| (1/m) left in each stretch (above `kappa_max` when
    /// no width tried rounds it off).
    pub peak_after: Vec<f64>,
}

/// Rounds off every stretch of `points` (a track already smoothed with a
/// Gaussian of `sigma_pts` points) whose curvature is above `kappa_max`
/// (see the module docs). Unchanged when `kappa_max` is not positive and
/// finite, `sigma_pts` is not positive, or there are fewer than 5 points.
pub fn round_sharp_turns(points: &[Xy], sigma_pts: f64, kappa_max: f64) -> (Vec<Xy>, Rounding) {
    round(points, sigma_pts, kappa_max, false)
}

/// [`round_sharp_turns`]; with `plain`, every curvature is computed again
/// for each stretch (the definition the tests hold the kept curvatures to).
pub(crate) fn round(
    points: &[Xy],
    sigma_pts: f64,
    kappa_max: f64,
    plain: bool,
) -> (Vec<Xy>, Rounding) {
    let mut pts = points.to_vec();
    let mut done = Rounding::default();
    let n = pts.len();
    if !(kappa_max > 0.0 && kappa_max.is_finite() && sigma_pts > 0.0) || n < 5 {
        return (pts, done);
    }
    // A stretch: sharp points no further apart than the track's own
    // smoothing window.
    let gap = (3.0 * sigma_pts).ceil() as usize;
    let mut from = 1;
    // Kept up to date as stretches are rounded: a point's curvature depends
    // on it and its two neighbours only, so a rounding of `lo..=hi` changes
    // it at `lo - 1..=hi + 1` alone (recomputing it all for each stretch
    // made a long track's rounding quadratic: a 596,000-point rail route
    // took 89 s).
    let mut k = curvatures(&pts);
    loop {
        if plain {
            k = curvatures(&pts);
        }
        let Some(a) = (from..n - 1).find(|&i| k[i].abs() > kappa_max) else {
            break;
        };
        let mut b = a;
        while let Some(next) = (b + 1..(b + 1 + gap).min(n - 1)).find(|&i| k[i].abs() > kappa_max) {
            b = next;
        }
        // (peak curvature left, first point, the window's new points)
        let mut best: Option<(f64, usize, Vec<Xy>)> = None;
        for w in WIDTHS {
            let sigma = w * sigma_pts;
            let core = (3.0 * sigma).ceil() as usize;
            // The window reaches a full width past the blend, so that its own
            // ends (held in place by the smoothing) get no weight.
            let (lo, hi) = (a.saturating_sub(3 * core), (b + 3 * core).min(n - 1));
            let wide = smooth(&pts[lo..=hi], sigma);
            let cand: Vec<Xy> = (lo..=hi)
                .map(|i| {
                    // 1 within `core` points of the stretch, smoothstep down
                    // to 0 over the next `core` points.
                    let out = if i < a { a - i } else { i.saturating_sub(b) };
                    let wgt = if out <= core {
                        1.0
                    } else if out >= 2 * core {
                        0.0
                    } else {
                        smoothstep(1.0 - (out - core) as f64 / core as f64)
                    };
                    let (p, q) = (pts[i], wide[i - lo]);
                    [p[0] + wgt * (q[0] - p[0]), p[1] + wgt * (q[1] - p[1])]
                })
                .collect();
            let left = peak(&curvatures(&cand));
            if best.as_ref().map_or(true, |(p, _, _)| left < *p) {
                best = Some((left, lo, cand));
            }
            if left <= kappa_max {
                break;
            }
        }
        let (mut left, lo, cand) = best.expect("at least one width is tried");
        let hi = lo + cand.len() - 1;
        // No width helps: the turn stays as it was.
        let before = peak(&k[a.saturating_sub(1)..=(b + 1).min(n - 1)]);
        if left < before {
            pts[lo..=hi].copy_from_slice(&cand);
            refresh_curvatures(&pts, &mut k, lo.saturating_sub(1), hi + 1);
        } else {
            left = before;
        }
        done.stretches.push((a, b));
        done.peak_after.push(left);
        // Past the stretch and its blend: a turn left sharp is not tried again.
        from = if left <= kappa_max {
            b + 1
        } else {
            hi.max(b + 1)
        };
        if from >= n - 1 {
            break;
        }
    }
    (pts, done)
}
