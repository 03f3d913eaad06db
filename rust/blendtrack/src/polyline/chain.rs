//! A track joined from pieces of polylines, each piece lying along a
//! reference line of its own (a lane's centreline, say) with a station (arc
//! length along that line) at each point.
//!
//! [`join`] puts the pieces end to end (a piece whose first point is within
//! 1 micrometre of the previous piece's last point shares it), smooths the
//! whole with a Gaussian ([`super::smooth`]) to round the kinks where pieces
//! meet, and measures everything on the smoothed track: where each piece
//! starts, and the stretches ("runs") of each piece where the smoothed track
//! stays within `near_m` of the unsmoothed points, with the station at their
//! start and the station gained per metre of track. A caller can then map a
//! position on the track to (piece, station) and back on a run that is near.

use super::turns::round_sharp_turns;
use super::{
    arc_lengths, check_points, distance, gradient, interp, length, smooth, PolylineError, Xy,
};

/// One piece of a chain.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainPiece {
    /// Points (at least 1).
    pub points: Vec<Xy>,
    /// Station along the piece's reference line at each point.
    pub station: Vec<f64>,
    /// False where the points leave the reference line (no run is near).
    pub on_reference: bool,
    /// Station units per metre of the points (the fallback rate of a run).
    pub station_scale: f64,
}

/// A stretch of one piece, near its reference line or away from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    /// Index of the piece in the input.
    pub piece: usize,
    /// Arc length along the smoothed track where the run starts.
    pub start_s: f64,
    /// Station at the run's start.
    pub station: f64,
    /// Station gained per metre of smoothed track over the run.
    pub scale: f64,
    /// Largest distance between the smoothed track and the piece's points
    /// over the run (infinite for a piece off its reference line).
    pub offset: f64,
}

/// The joined, smoothed track. Per kept piece (a piece that adds at least
/// one point; `kept` lists their input indices) the arc lengths are on the
/// smoothed track.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    /// The smoothed points.
    pub points: Vec<Xy>,
    /// Total arc length of the smoothed track.
    pub length: f64,
    /// Input index of each kept piece.
    pub kept: Vec<usize>,
    /// How many points each kept piece adds (its first is dropped when shared).
    pub kept_points: Vec<usize>,
    /// Where each kept piece starts (at its shared point, if any).
    pub start_s: Vec<f64>,
    /// Where the track before each kept piece ends (before any gap).
    pub before_s: Vec<f64>,
    /// Where each kept piece's first own point is (after any gap).
    pub entry_s: Vec<f64>,
    /// The runs, in order along the track.
    pub runs: Vec<Run>,
    /// Each smoothed point's route station: the station a simulator that
    /// maps a point onto the nearest reference line gives it, counted on
    /// from piece to piece, non-decreasing (see [`route_stations`]).
    pub station: Vec<f64>,
    /// The turns rounded off ([`super::turns`]): where each sharp stretch
    /// starts and ends on the smoothed track, and the peak |curvature| (1/m)
    /// left in it.
    pub rounded: Vec<(f64, f64, f64)>,
}

/// Unsmoothed concatenation: points, and per kept piece (input index, range
/// of its points from the shared one, points added, raw start, before, entry).
struct Joined {
    raw: Vec<Xy>,
    kept: Vec<(usize, usize, usize, usize)>,
    start: Vec<f64>,
    before: Vec<f64>,
    entry: Vec<f64>,
}

fn concatenate(pieces: &[ChainPiece]) -> Joined {
    let mut j = Joined {
        raw: Vec::new(),
        kept: Vec::new(),
        start: Vec::new(),
        before: Vec::new(),
        entry: Vec::new(),
    };
    let mut s = 0.0;
    for (index, pc) in pieces.iter().enumerate() {
        let last = j.raw.last().copied();
        let shared = last.is_some_and(|l| distance(l, pc.points[0]) < 1e-6);
        let own = if shared {
            &pc.points[1..]
        } else {
            &pc.points[..]
        };
        if own.is_empty() {
            continue;
        }
        j.before.push(s);
        let n = j.raw.len();
        if shared {
            j.start.push(s);
        }
        if let Some(l) = last {
            s += distance(l, own[0]);
        }
        if !shared {
            j.start.push(s);
        }
        j.entry.push(s);
        s += length(own);
        j.kept.push((
            index,
            if shared { n - 1 } else { n },
            n + own.len(),
            own.len(),
        ));
        j.raw.extend_from_slice(own);
    }
    j
}

/// How many unsmoothed points either side of a smoothed point's own are
/// searched for its nearest (the rounding of sharp turns moves points a few
/// metres at the track's 1 m spacing).
pub const STATION_WINDOW_PTS: usize = 40;

/// Each smoothed point's route station (`Chain::station`): the point is
/// mapped onto the nearest segment of the unsmoothed points within
/// [`STATION_WINDOW_PTS`] of its own index (the pieces' reference lines as
/// the route strings them together), and takes that foot's station, the
/// pieces' stations (times their `station_scale`) counted on from piece to
/// piece (see the code), so that the route station runs on across pieces
/// as a simulator's lane positions do along a route. A running maximum
/// makes it non-decreasing.
///
/// This is what a simulator that places a vehicle by its (x, y) sees of a
/// track that cuts a corner: where the track rounds a sharp turn inside the
/// corner, the nearest point of the lanes jumps ahead (a 75 deg bend of
/// Bologna's 58[0] by 3.5 m, the 87 deg junction after it by 5.4 m), so the
/// simulator's gap between two vehicles shrinks by more than the track's
/// arc length between them.
fn route_stations(pieces: &[ChainPiece], j: &Joined, points: &[Xy]) -> Vec<f64> {
    // A piece whose stations start at 0 starts a new reference line: its
    // stations are counted on from where the piece before it ended (a piece
    // that adds no point of its own, a junction lane shorter than the
    // spacing, included). One whose stations start further on goes on along
    // the line of the piece before (the stretches of a lane change: the
    // lanes of one edge side by side share their positions), from the same
    // origin.
    let mut offsets: Vec<f64> = Vec::with_capacity(pieces.len());
    let mut end = 0.0;
    for pc in pieces {
        let st = |k: usize| pc.station[k] * pc.station_scale;
        let offset = match offsets.last() {
            None => 0.0,
            Some(&before) if pc.station[0] > 0.0 => before,
            Some(_) => end,
        };
        offsets.push(offset);
        end = offset + st(pc.points.len() - 1);
    }
    // The route station of every unsmoothed point.
    let mut raw_c: Vec<f64> = Vec::with_capacity(j.raw.len());
    for &(index, _, stop, own) in &j.kept {
        let pc = &pieces[index];
        let first_own = pc.points.len() - own;
        raw_c.extend(
            (first_own..pc.points.len()).map(|k| offsets[index] + pc.station[k] * pc.station_scale),
        );
        debug_assert_eq!(raw_c.len(), stop);
    }
    let n = j.raw.len();
    let mut out = Vec::with_capacity(points.len());
    let mut floor = f64::NEG_INFINITY;
    let mut near = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let (a, b) = (
            i.saturating_sub(STATION_WINDOW_PTS),
            (i + STATION_WINDOW_PTS).min(n - 1),
        );
        let best = nearest_station(*p, &j.raw[a..=b], &raw_c[a..=b], &mut near)
            .unwrap_or(raw_c[i.min(n - 1)]);
        floor = floor.max(best);
        out.push(floor);
    }
    out
}

/// The station of `p`'s foot on the nearest segment of `line` (`station`
/// per point, interpolated along the segment); of segments equally near
/// (a point on the bisector of a corner is as near to both sides) the
/// first. None for fewer than two points or a NaN point. `scratch` is
/// reused from call to call.
///
/// Nearest by `hypot` distance, but `hypot` (glibc's is slow: most of the
/// join's time when every segment of the window took one) only where the
/// squared distance is within rounding of the smallest: squares can
/// differ in the last bit where the distances do not, and the other way,
/// so the choice is the same as with `hypot` on every segment.
pub fn nearest_station(
    p: Xy,
    line: &[Xy],
    station: &[f64],
    scratch: &mut Vec<(f64, f64, f64, f64)>,
) -> Option<f64> {
    scratch.clear();
    let mut min_sq = f64::INFINITY;
    for w in line.windows(2) {
        let (t, ex, ey) = foot(p, w[0], w[1]);
        let sq = ex * ex + ey * ey;
        min_sq = min_sq.min(sq);
        scratch.push((sq, ex, ey, t));
    }
    let mut best = (f64::INFINITY, None);
    for (r, &(sq, ex, ey, t)) in scratch.iter().enumerate() {
        if sq <= min_sq * (1.0 + 1e-9) {
            let d = ex.hypot(ey);
            if d < best.0 {
                best = (d, Some(station[r] + t * (station[r + 1] - station[r])));
            }
        }
    }
    best.1
}

/// The foot of `p` on the segment `q0`-`q1`: its parameter `t` in [0, 1]
/// (0 for a segment of no length) and the offset from it to `p`.
#[inline]
pub(crate) fn foot(p: Xy, q0: Xy, q1: Xy) -> (f64, f64, f64) {
    let (dx, dy) = (q1[0] - q0[0], q1[1] - q0[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - q0[0]) * dx + (p[1] - q0[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (t, p[0] - q0[0] - t * dx, p[1] - q0[1] - t * dy)
}

/// `[a, b)` ranges of equal `far`, in order, after any stretch of near
/// points shorter than `min_len` is counted as far.
pub fn runs(far: &[bool], min_len: usize) -> Vec<(usize, usize)> {
    let cuts = |f: &[bool]| -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut a = 0;
        for i in 1..=f.len() {
            if i == f.len() || f[i] != f[i - 1] {
                out.push((a, i));
                a = i;
            }
        }
        out
    };
    let mut f = far.to_vec();
    for (a, b) in cuts(far) {
        if !f[a] && b - a < min_len {
            f[a..b].iter_mut().for_each(|v| *v = true);
        }
    }
    cuts(&f)
}

/// Distance across (signed, left of the tangent positive) and along the
/// tangent from each raw point to its smoothed point.
fn offsets(raw: &[Xy], smoothed: &[Xy]) -> Vec<(f64, f64)> {
    gradient(raw)
        .iter()
        .zip(raw.iter().zip(smoothed))
        .map(|(t, (r, p))| {
            let norm = t[0].hypot(t[1]);
            let norm = if norm > 1e-12 || norm.is_nan() {
                norm
            } else {
                1e-12
            };
            let (tx, ty) = (t[0] / norm, t[1] / norm);
            let (sx, sy) = (p[0] - r[0], p[1] - r[1]);
            (tx * sy - ty * sx, tx * sx + ty * sy)
        })
        .collect()
}

fn check(pieces: &[ChainPiece]) -> Result<(), PolylineError> {
    if pieces.is_empty() {
        return Err(PolylineError::TooFewPoints {
            what: "chain (pieces)",
            needed: 1,
            got: 0,
        });
    }
    for pc in pieces {
        check_points("chain piece", &pc.points, 1)?;
        if pc.station.len() != pc.points.len() {
            return Err(PolylineError::Count {
                what: "chain piece stations",
                got: pc.station.len(),
                expected: pc.points.len(),
            });
        }
    }
    Ok(())
}

/// Joins `pieces` (see the module docs), smoothing with a Gaussian of
/// `sigma_pts` points and rounding off what is still sharper than
/// `kappa_max` (1/m; 0 for no limit, see [`super::turns`]); a run is near
/// where the smoothed track is within `near_m` of the piece's points for at
/// least `min_run` points.
pub fn join(
    pieces: &[ChainPiece],
    sigma_pts: f64,
    kappa_max: f64,
    near_m: f64,
    min_run: usize,
) -> Result<Chain, PolylineError> {
    check(pieces)?;
    let j = concatenate(pieces);
    let (points, rounding) = round_sharp_turns(&smooth(&j.raw, sigma_pts), sigma_pts, kappa_max);
    let (s_raw, s_sm) = (arc_lengths(&j.raw), arc_lengths(&points));
    let on_smoothed = |x: f64| interp(x, &s_raw, &s_sm);
    let start_s: Vec<f64> = j.start.iter().map(|&x| on_smoothed(x)).collect();
    let mut out: Vec<Run> = Vec::new();
    for (k, &(index, i0, i1, _)) in j.kept.iter().enumerate() {
        let pc = &pieces[index];
        let off = offsets(&j.raw[i0..i1], &points[i0..i1]);
        let pos: Vec<f64> = off
            .iter()
            .zip(&pc.station)
            .map(|(o, st)| (st + o.1) * pc.station_scale)
            .collect();
        let dev: Vec<f64> = off
            .iter()
            .map(|o| {
                if pc.on_reference {
                    o.0.abs()
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        let far: Vec<bool> = dev.iter().map(|&d| d > near_m).collect();
        for (a, b) in runs(&far, min_run) {
            let c = (b + 1).min(i1 - i0);
            let ds = s_sm[i0 + c - 1] - s_sm[i0 + a];
            let rise = pos[c - 1] - pos[a];
            let scale = if ds > 1e-9 && rise > 0.0 {
                rise / ds
            } else {
                pc.station_scale
            };
            let (mut start, mut station) = (if a == 0 { start_s[k] } else { s_sm[i0 + a] }, pos[a]);
            if a == 0 && pc.station[0] == 0.0 {
                // Where the reference line starts, along the smoothed track.
                start -= station / scale;
                station = 0.0;
                if let Some(prev) = out.last() {
                    let floor = prev.start_s + 1e-6;
                    start = if floor > start { floor } else { start };
                }
            }
            let offset = dev[a..b]
                .iter()
                .fold(f64::NEG_INFINITY, |m, &d| if d > m { d } else { m });
            out.push(Run {
                piece: index,
                start_s: start,
                station,
                scale,
                offset,
            });
        }
    }
    let station = route_stations(pieces, &j, &points);
    Ok(Chain {
        station,
        rounded: rounding
            .stretches
            .iter()
            .zip(&rounding.peak_after)
            .map(|(&(a, b), &k)| (s_sm[a], s_sm[b], k))
            .collect(),
        length: s_sm[s_sm.len() - 1],
        kept: j.kept.iter().map(|k| k.0).collect(),
        kept_points: j.kept.iter().map(|k| k.3).collect(),
        start_s,
        before_s: j.before.iter().map(|&x| on_smoothed(x)).collect(),
        entry_s: j.entry.iter().map(|&x| on_smoothed(x)).collect(),
        runs: out,
        points,
    })
}
