//! A route's tables along its track: lane [`Piece`]s, junction
//! [`StopLine`]s and the [`LaneChangeDue`] on the way, checked once in
//! [`Route::new`].

use crate::error::TrafficError;

/// One lane along a route's track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// Arc length where the piece starts on the track (m).
    pub start_m: f64,
    /// The simulator's lane position at `start_m` (m; 0 when the piece
    /// starts where its lane starts).
    pub lane_pos_start_m: f64,
    /// Simulator lane length per metre of track.
    pub scale: f64,
    /// The simulator's length of the lane (m).
    pub lane_length_m: f64,
    /// Largest distance between the track and the lane's centreline over the
    /// piece (m); +inf where the track leaves the lane (a lane change). A
    /// vehicle is handed to the simulator as (lane, position) only while its
    /// lateral error plus this stays under the settings' bound.
    pub offset_m: f64,
    /// Speed limit (m/s).
    pub speed_mps: f64,
    /// The caller's ids of the lane and its edge, and the lane's index on the edge.
    pub lane: u32,
    pub edge: u32,
    pub lane_index: u32,
    /// Which of the track's edges, in order, the piece is on (a junction
    /// lane: the edge before it): SUMO's route index counted from the
    /// track's first edge. A route that drives an edge more than once (a
    /// loop, laps, a bus line that comes back) has pieces of one lane with
    /// different occurrences; a position on that lane means one of them.
    pub occurrence: u32,
}

impl Piece {
    /// The simulator's lane position of arc length `s`, at the piece's scale
    /// (not clamped to the piece or the lane).
    #[inline]
    pub fn lane_pos_at(&self, s: f64) -> f64 {
        self.lane_pos_start_m + (s - self.start_m) * self.scale
    }
}

/// A junction entry along a route's track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopLine {
    /// Arc length of the stop line (m).
    pub s_m: f64,
    /// (light, link index) when signalised.
    pub signal: Option<(usize, usize)>,
    /// Right of way by the network, for an unsignalised link.
    pub major: bool,
    /// The caller's id of the first junction lane (to ask about foes).
    pub via: u32,
    /// Arc length where the junction is left (m; +inf when unknown).
    pub exit_m: f64,
    /// Ask the caller before entering even with the right of way: the
    /// junction has other vehicles' lanes crossing or touching this one, and
    /// a vehicle standing inside it (a left turner at its waiting point, a
    /// vehicle left over from a jam) may be in the way.
    pub check_inside: bool,
}

/// A lane change the route needs on one edge, made when the simulator says
/// there is room: until then the track ends early on the current lane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LaneChangeDue {
    pub edge: u32,
    pub target_index: u32,
    /// The occurrence of the edge (see [`Piece::occurrence`]) where the
    /// change is due; None: wherever the track is on the edge.
    pub occurrence: Option<u32>,
}

/// The simulator's station along a route at each point of its track: what
/// the simulator's lane positions, counted on from lane to lane, make of the
/// track where it maps a vehicle by its (x, y) onto the nearest lane
/// (`blendtrack::polyline::Chain::station`). Where the track cuts inside a
/// sharp turn the station jumps ahead of the arc length, so the simulator's
/// gap between two vehicles shrinks by more than the arc length between them
/// (Bologna's 58[0] -> 58[1]: 3.5 m at a 75 deg bend, 5.4 m at the 87 deg
/// junction after it; 9 of 36 collisions with a controlled vehicle over
/// seeds 0-35 at 30 % were there, every one the follower's station jumping
/// onto its leader's back).
#[derive(Debug, Clone, PartialEq)]
pub struct Stations {
    s: Vec<f64>,
    c: Vec<f64>,
}

impl Stations {
    /// Arc lengths `s_m` of the track's points (increasing) and the
    /// station at each (non-decreasing), at least one point, all finite.
    pub fn new(s_m: Vec<f64>, station_m: Vec<f64>) -> Result<Stations, TrafficError> {
        let bad = |m: String| Err(TrafficError::Route(m));
        if s_m.len() != station_m.len() || s_m.is_empty() {
            return bad(format!(
                "{} stations for {} track points: one per point, at least one",
                station_m.len(),
                s_m.len()
            ));
        }
        for i in 0..s_m.len() {
            if !(s_m[i].is_finite() && station_m[i].is_finite()) {
                return bad(format!(
                    "point {i} has arc length {} m and station {} m: both must be finite",
                    s_m[i], station_m[i]
                ));
            }
            if i > 0 && (s_m[i] <= s_m[i - 1] || station_m[i] < station_m[i - 1]) {
                return bad(format!(
                    "point {i}: arc lengths must increase and stations not decrease ({} -> {} m, station {} -> {} m)",
                    s_m[i - 1], s_m[i], station_m[i - 1], station_m[i]
                ));
            }
        }
        let (s, c) = thin(&s_m, &station_m, STATION_TOLERANCE_M);
        Ok(Stations { s, c })
    }

    /// How many points the table keeps (see [`STATION_TOLERANCE_M`]).
    pub fn len(&self) -> usize {
        self.s.len()
    }

    /// Never true: a table keeps at least one point.
    pub fn is_empty(&self) -> bool {
        self.s.is_empty()
    }

    /// The station of arc length `s`: linear between points, gaining 1 m
    /// per metre beyond either end.
    pub fn at(&self, s: f64) -> f64 {
        lookup(&self.s, &self.c, s)
    }

    /// The largest arc length whose station is at most `c` (the inverse of
    /// [`Stations::at`]; the far end of a stretch the station stands still
    /// over).
    pub fn arc_at(&self, c: f64) -> f64 {
        lookup(&self.c, &self.s, c)
    }
}

/// `ys` at `x` along non-decreasing `xs`: linear between the last point at
/// or before `x` and the next, 1 per 1 beyond either end (on a stretch of
/// equal `xs`, its last point).
fn lookup(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let k = xs.partition_point(|&v| v <= x);
    if k == 0 {
        return ys[0] + (x - xs[0]);
    }
    if k == xs.len() {
        return ys[k - 1] + (x - xs[k - 1]);
    }
    // xs[k - 1] <= x < xs[k]
    let u = (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
    ys[k - 1] + u * (ys[k] - ys[k - 1])
}

/// A station table keeps only the points it needs for its stations
/// between them to be within this (m) of the given ones: along most of a
/// track the station gains a metre per metre, and a table of a few points
/// is searched in a few steps (a 1 km track has a thousand points).
pub const STATION_TOLERANCE_M: f64 = 0.005;

/// The points of (`s`, `c`) to keep so that linear interpolation between
/// them stays within about `tol` of every point left out (a swinging door:
/// from each kept point, the narrowing range of slopes that passes within
/// `tol` of every point since; the point before the one that closes it is
/// kept). The first and last points are kept.
fn thin(s: &[f64], c: &[f64], tol: f64) -> (Vec<f64>, Vec<f64>) {
    let n = s.len();
    let (mut ks, mut kc) = (vec![s[0]], vec![c[0]]);
    let mut anchor = 0;
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut i = 1;
    while i < n {
        let dx = s[i] - s[anchor];
        let (a, b) = ((c[i] - tol - c[anchor]) / dx, (c[i] + tol - c[anchor]) / dx);
        let (nlo, nhi) = (lo.max(a), hi.min(b));
        if nlo > nhi && i - 1 > anchor {
            // Point i cannot join: keep the one before and start from it.
            anchor = i - 1;
            ks.push(s[anchor]);
            kc.push(c[anchor]);
            (lo, hi) = (f64::NEG_INFINITY, f64::INFINITY);
            continue;
        }
        (lo, hi) = (nlo, nhi);
        i += 1;
    }
    if anchor != n - 1 {
        ks.push(s[n - 1]);
        kc.push(c[n - 1]);
    }
    (ks, kc)
}

/// Lanes and stop lines along a track (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    pub(crate) stations: Option<Stations>,
    pub(crate) pieces: Vec<Piece>,
    pub(crate) stops: Vec<StopLine>,
    pub(crate) length_m: f64,
    pub(crate) lane_change: Option<LaneChangeDue>,
    /// Some edge has pieces of two occurrences (see [`Piece::occurrence`]).
    pub(crate) revisits: bool,
}

impl Route {
    /// Checks the tables: at least one piece, finite increasing piece starts,
    /// positive scales, positive speed limits, finite stop lines sorted by arc
    /// length, a finite positive length.
    pub fn new(
        pieces: Vec<Piece>,
        stops: Vec<StopLine>,
        length_m: f64,
        lane_change: Option<LaneChangeDue>,
    ) -> Result<Route, TrafficError> {
        let bad = |m: String| Err(TrafficError::Route(m));
        if pieces.is_empty() {
            return bad("no lane pieces".into());
        }
        if !(length_m.is_finite() && length_m > 0.0) {
            return bad(format!("length {length_m} m is not finite and > 0"));
        }
        for (i, p) in pieces.iter().enumerate() {
            if !p.start_m.is_finite() || (i > 0 && p.start_m < pieces[i - 1].start_m) {
                return bad(format!(
                    "piece {i} starts at {} m: starts must be finite and increasing",
                    p.start_m
                ));
            }
            // (what, value, unit, allowed, rule)
            let checks = [
                (
                    "has lane scale",
                    p.scale,
                    "",
                    p.scale > 0.0,
                    "finite and > 0",
                ),
                (
                    "starts at lane position",
                    p.lane_pos_start_m,
                    " m",
                    p.lane_pos_start_m >= 0.0,
                    "finite and >= 0",
                ),
                (
                    "has lane length",
                    p.lane_length_m,
                    " m",
                    p.lane_length_m > 0.0,
                    "finite and > 0",
                ),
            ];
            for (what, value, unit, ok, rule) in checks {
                if !(value.is_finite() && ok) {
                    return bad(format!("piece {i} {what} {value}{unit}: must be {rule}"));
                }
            }
            if p.offset_m.is_nan() || p.offset_m < 0.0 {
                return bad(format!(
                    "piece {i} has offset {} m: must be >= 0 (+inf: off the lane)",
                    p.offset_m
                ));
            }
            if i > 0 && p.occurrence < pieces[i - 1].occurrence {
                return bad(format!(
                    "piece {i} has occurrence {} after {}: occurrences must not decrease",
                    p.occurrence,
                    pieces[i - 1].occurrence
                ));
            }
            if !(p.speed_mps > 0.0) {
                return bad(format!(
                    "piece {i} has speed limit {} m/s: must be > 0",
                    p.speed_mps
                ));
            }
        }
        for (i, s) in stops.iter().enumerate() {
            if !s.s_m.is_finite() || (i > 0 && s.s_m < stops[i - 1].s_m) {
                return bad(format!(
                    "stop line {i} at {} m: must be finite and sorted",
                    s.s_m
                ));
            }
            if s.exit_m.is_nan() {
                return bad(format!("stop line {i} has a NaN exit"));
            }
        }
        let mut first_seen = std::collections::HashMap::new();
        let revisits = pieces
            .iter()
            .any(|p| *first_seen.entry(p.edge).or_insert(p.occurrence) != p.occurrence);
        Ok(Route {
            stations: None,
            pieces,
            stops,
            length_m,
            lane_change,
            revisits,
        })
    }

    /// The route with the simulator's stations along its track (see
    /// [`Stations`]); without them a station is the arc length.
    pub fn with_stations(mut self, stations: Stations) -> Route {
        self.stations = Some(stations);
        self
    }

    /// The simulator's station of arc length `s` (see [`Stations`]).
    #[inline]
    pub fn station_at(&self, s: f64) -> f64 {
        self.stations.as_ref().map_or(s, |t| t.at(s))
    }

    /// How far along the track (m) a front at arc length `s` can go before
    /// the simulator's gap ahead of it, `gap_m` now, is used up: `gap_m`
    /// less any jump of the station within it, never more than `gap_m`
    /// (where the station gains less than the arc length, the gap is kept
    /// as it is). `gap_m` itself without stations, for a gap that is not
    /// finite (none, NaN) or not positive.
    #[inline]
    pub fn arc_gap(&self, s: f64, gap_m: f64) -> f64 {
        match &self.stations {
            Some(t) if gap_m.is_finite() && gap_m > 0.0 && s.is_finite() => {
                (t.arc_at(t.at(s) + gap_m) - s).min(gap_m)
            }
            _ => gap_m,
        }
    }

    /// The gap along the track (m) to hand the stopping law for a leader
    /// whose back is `gap_m` ahead in the simulator's stations, moving so
    /// that it stops `stop_m` (>= 0) further on: the law depends on the two
    /// only through the leader's stop point, `gap + stop`, and that point in
    /// stations becomes `arc_gap(s, gap + stop)` along the track. Where a
    /// jump of the station lies between the leader's back and its stop
    /// point, the front must not cross the jump before the leader has made
    /// room behind it: the law, given `arc_gap(s, gap)` and adding `stop`
    /// along the track itself, let a follower cross a 5.4 m jump behind a
    /// leader 3.3 m ahead (Bologna's junction 47, seed 10, 318 s: the
    /// simulator's gap fell to 0.6 m, under the follower's minGap).
    /// `arc_gap(s, gap_m)` where that is shorter or no jump is involved.
    #[inline]
    pub fn arc_gap_moving(&self, s: f64, gap_m: f64, stop_m: f64) -> f64 {
        let plain = self.arc_gap(s, gap_m);
        if self.stations.is_none() || !(stop_m > 0.0) || !stop_m.is_finite() || !plain.is_finite() {
            return plain;
        }
        let to_stop = self.arc_gap(s, gap_m + stop_m) - stop_m;
        // Round-off alone (no jump within reach) leaves the gap as it was.
        if to_stop < plain - 1e-9 {
            to_stop
        } else {
            plain
        }
    }

    /// The arc lengths [from, to) of the pieces of occurrence `k` (its
    /// edge's lanes and the junction lanes after them); None when no piece
    /// has it.
    pub fn occurrence_span(&self, k: u32) -> Option<(f64, f64)> {
        let first = self.pieces.partition_point(|p| p.occurrence < k);
        if self.pieces.get(first)?.occurrence != k {
            return None;
        }
        let end = self.pieces.partition_point(|p| p.occurrence <= k);
        let to = self.pieces.get(end).map_or(self.length_m, |p| p.start_m);
        Some((self.pieces[first].start_m, to))
    }

    /// Does the track drive some edge more than once?
    pub fn revisits_an_edge(&self) -> bool {
        self.revisits
    }

    /// The occurrence of the piece holding arc length `s`.
    pub fn occurrence_at(&self, s: f64) -> u32 {
        self.pieces[self.piece_at(s)].occurrence
    }

    /// Index of the piece holding arc length `s` (clamped to the pieces).
    pub fn piece_at(&self, s: f64) -> usize {
        self.pieces
            .partition_point(|p| p.start_m <= s)
            .saturating_sub(1)
    }

    /// The simulator's lane and lane position of arc length `s`: on the
    /// piece holding `s`, the position clamped to the lane.
    pub fn lane_position(&self, s: f64) -> (u32, f64) {
        let p = &self.pieces[self.piece_at(s)];
        (p.lane, p.lane_pos_at(s).max(0.0).min(p.lane_length_m))
    }

    /// The arc length of lane position `pos` on lane `lane`: on the first
    /// piece of that lane covering the position (within a micrometre) whose
    /// arc length is at or after `s_from`; None where none does (the lane
    /// is not on the track, or only behind `s_from`).
    pub fn arc_at_lane_position(&self, lane: u32, pos: f64, s_from: f64) -> Option<f64> {
        const TOL_M: f64 = 1e-6;
        self.pieces.iter().enumerate().find_map(|(k, p)| {
            if p.lane != lane {
                return None;
            }
            let end = self.pieces.get(k + 1).map_or(self.length_m, |q| q.start_m);
            let last = p.lane_pos_at(end);
            let on = p.lane_pos_start_m - TOL_M <= pos && pos <= last + TOL_M;
            let s = p.start_m + (pos - p.lane_pos_start_m) / p.scale;
            (on && s >= s_from).then_some(s)
        })
    }

    /// The occurrences of the pieces within `slack_m` of arc length `s`
    /// (the piece holding `s - slack_m` to the one holding `s + slack_m`),
    /// in track order, repeats kept.
    pub fn occurrences_near(&self, s: f64, slack_m: f64) -> impl Iterator<Item = u32> + '_ {
        let lo = self.pieces.partition_point(|p| p.start_m <= s - slack_m);
        let hi = self.pieces.partition_point(|p| p.start_m <= s + slack_m);
        self.pieces[lo.saturating_sub(1)..hi.max(1)]
            .iter()
            .map(|p| p.occurrence)
    }

    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }
    pub fn stops(&self) -> &[StopLine] {
        &self.stops
    }
    pub fn length_m(&self) -> f64 {
        self.length_m
    }
}

#[cfg(test)]
mod tests {
    use crate::testkit::*;
    use crate::*;

    #[test]
    fn route_tables_are_checked() {
        let p = |start_m| Piece {
            start_m,
            lane_pos_start_m: 0.0,
            scale: 1.0,
            lane_length_m: 100.0,
            offset_m: 0.0,
            speed_mps: 10.0,
            lane: 0,
            edge: 0,
            lane_index: 0,
            occurrence: 0,
        };
        assert!(matches!(
            Route::new(vec![], vec![], 10.0, None),
            Err(TrafficError::Route(_))
        ));
        let e = Route::new(vec![p(0.0), p(5.0), p(3.0)], vec![], 10.0, None).unwrap_err();
        assert!(e.to_string().contains("piece 2"), "{e}");
        assert!(Route::new(vec![p(0.0)], vec![], f64::NAN, None).is_err());
        let r = Route::new(vec![p(0.0), p(5.0), p(5.0), p(9.0)], vec![], 10.0, None).unwrap();
        assert_eq!(
            [
                r.piece_at(-1.0),
                r.piece_at(4.99),
                r.piece_at(5.0),
                r.piece_at(9.5),
                r.piece_at(99.0)
            ],
            [0, 0, 2, 3, 3]
        );
    }

    /// A 100 m track whose station jumps 4 m over the metre from 50 to 51 m
    /// (a corner cut inside), with a flat metre before the jump.
    fn jumping_stations() -> Stations {
        let s: Vec<f64> = (0..=100).map(f64::from).collect();
        let c = s
            .iter()
            .map(|&x| match x {
                x if x <= 49.0 => x,
                x if x <= 50.0 => 49.0,
                x => x + 3.0,
            })
            .collect();
        Stations::new(s, c).unwrap()
    }

    #[test]
    fn stations_map_both_ways_and_reject_bad_tables() {
        let t = jumping_stations();
        assert_eq!(t.at(10.0), 10.0);
        assert_eq!(t.at(49.5), 49.0);
        assert_eq!(t.at(50.5), 51.5);
        assert_eq!(t.at(60.0), 63.0);
        // Beyond the ends, a metre of station per metre.
        assert_eq!(t.at(-2.0), -2.0);
        assert_eq!(t.at(110.0), 113.0);
        // The inverse: the far end of the flat metre, and inside the jump
        // (from station 49 at 50 m to 54 at 51 m).
        assert_eq!(t.arc_at(49.0), 50.0);
        assert_eq!(t.arc_at(51.0), 50.4);
        assert_eq!(t.arc_at(63.0), 60.0);
        assert_eq!(t.arc_at(-1.0), -1.0);
        assert_eq!(t.arc_at(113.0), 110.0);
        let s = vec![0.0, 1.0, 2.0];
        for (what, s_m, c) in [
            ("a station short", s.clone(), vec![0.0, 1.0]),
            ("no points", vec![], vec![]),
            ("a NaN station", s.clone(), vec![0.0, f64::NAN, 2.0]),
            ("a station that goes back", s.clone(), vec![0.0, 2.0, 1.0]),
            (
                "arc lengths that repeat",
                vec![0.0, 1.0, 1.0],
                vec![0.0, 1.0, 2.0],
            ),
        ] {
            let e = Stations::new(s_m, c).expect_err(what);
            assert!(matches!(e, TrafficError::Route(_)), "{what}: {e}");
        }
    }

    #[test]
    fn a_station_table_keeps_the_points_it_needs_within_its_tolerance() {
        // A kilometre at a metre a metre: its two ends.
        let s: Vec<f64> = (0..=1000).map(f64::from).collect();
        assert_eq!(Stations::new(s.clone(), s.clone()).unwrap().len(), 2);
        // The jump: the ends and the three corners of the flat metre and jump.
        let t = jumping_stations();
        assert_eq!(t.len(), 5);
        // A curve (a station gaining 1.2 to 0.8 m a metre, smoothly) keeps
        // enough points to stay within the tolerance everywhere, and far
        // fewer than it was given.
        let c: Vec<f64> = s.iter().map(|&x| x + 50.0 * (x / 159.0).sin()).collect();
        let t = Stations::new(s.clone(), c.clone()).unwrap();
        assert!(t.len() < 200, "{} points kept", t.len());
        let worst = s
            .iter()
            .zip(&c)
            .map(|(&x, &y)| (t.at(x) - y).abs())
            .fold(0.0, f64::max);
        assert!(worst <= 2.0 * super::STATION_TOLERANCE_M, "{worst} m off");
    }

    #[test]
    fn the_gap_along_the_track_leaves_out_the_jump_of_the_station_within_it() {
        let (_, route) = road(None, true);
        let jumping = route.clone().with_stations(jumping_stations());
        // Without stations, or with no jump within it, the gap is the gap.
        assert_eq!(route.arc_gap(40.0, 8.0), 8.0);
        assert_eq!(jumping.arc_gap(10.0, 8.0), 8.0);
        assert_eq!(jumping.arc_gap(60.0, 8.0), 8.0);
        // A front at 45 m with 10 m to its leader's back in the simulator
        // (station 55 m) may go to arc length 52 m: 7 m, the jump's 3 m
        // left out (the metre the station stands still over gives nothing
        // back: the gap is never more than the simulator's).
        assert!((jumping.arc_gap(45.0, 10.0) - 7.0).abs() < 1e-12);
        // None, NaN, a gap already used up: as they are.
        assert_eq!(jumping.arc_gap(45.0, f64::INFINITY), f64::INFINITY);
        assert!(jumping.arc_gap(45.0, f64::NAN).is_nan());
        assert_eq!(jumping.arc_gap(45.0, -0.5), -0.5);
        assert_eq!(jumping.arc_gap(f64::NAN, 5.0), 5.0);
    }

    #[test]
    fn a_moving_leaders_stop_point_is_taken_through_the_stations() {
        let (_, route) = road(None, true);
        let jumping = route.clone().with_stations(jumping_stations());
        // A front at 45 m, its leader's back 2 m ahead in stations (47 m),
        // the leader stopping 4 m further on (station 51 m): the front
        // reaches station 51 m at arc length 50.4 m (the station goes 49 ->
        // 54 m over 50 -> 51 m), so the law's gap is 50.4 - 45 - 4 = 1.4 m,
        // not the 2 m up to the back.
        assert!((jumping.arc_gap(45.0, 2.0) - 2.0).abs() < 1e-12);
        assert!((jumping.arc_gap_moving(45.0, 2.0, 4.0) - 1.4).abs() < 1e-12);
        // No jump between the back and the stop point, no stations, a
        // standing leader, unusable values: the gap up to the back, exactly.
        assert_eq!(jumping.arc_gap_moving(10.0, 2.0, 4.0), 2.0);
        assert_eq!(jumping.arc_gap_moving(60.0, 2.0, 4.0), 2.0);
        assert_eq!(route.arc_gap_moving(45.0, 2.0, 4.0), 2.0);
        assert_eq!(jumping.arc_gap_moving(45.0, 2.0, 0.0), 2.0);
        assert_eq!(jumping.arc_gap_moving(45.0, 2.0, f64::NAN), 2.0);
        assert_eq!(
            jumping.arc_gap_moving(45.0, f64::INFINITY, 4.0),
            f64::INFINITY
        );
        assert!(jumping.arc_gap_moving(45.0, f64::NAN, 4.0).is_nan());
        // Never longer than the gap up to the back.
        for k in 0..200 {
            let (s, g) = (40.0 + 0.1 * f64::from(k), 0.5 + 0.03 * f64::from(k));
            assert!(jumping.arc_gap_moving(s, g, 3.0) <= jumping.arc_gap(s, g) + 1e-12);
        }
    }

    #[test]
    fn a_track_that_drives_an_edge_three_times_has_three_spans_of_it() {
        let (path, route) = laps();
        let lap = path.length() / 3.0;
        assert!(route.revisits_an_edge());
        assert!(!road(None, true).1.revisits_an_edge());
        for k in 0..3 {
            let (from, to) = route.occurrence_span(k).unwrap();
            assert!(
                (from - k as f64 * lap).abs() < 1e-9 && (to - (k + 1) as f64 * lap).abs() < 1e-9
            );
            assert_eq!(route.occurrence_at(from + 1.0), k);
        }
        assert_eq!(route.occurrence_span(3), None);
        // On the road, the junction lane belongs to the edge before it.
        assert_eq!(road(None, true).1.occurrence_span(0), Some((0.0, 210.0)));
        let mut pieces = route.pieces.clone();
        pieces[2].occurrence = 0;
        let e = Route::new(pieces, vec![], path.length(), None).unwrap_err();
        assert!(
            e.to_string().contains("piece 2 has occurrence 0 after 1"),
            "{e}"
        );
    }

    #[test]
    fn lane_positions_and_arc_lengths_map_both_ways_on_each_lap() {
        // Three laps of one lane (id 20), each lap from lane position 2 m
        // at 0.5 m of lane a metre of track: lane position x on lap k is arc
        // length k * lap + (x - 2) / 0.5, and back.
        let (path, laps) = laps();
        let lap = path.length() / 3.0;
        let pieces = laps
            .pieces
            .iter()
            .map(|p| Piece {
                lane_pos_start_m: 2.0,
                scale: 0.5,
                ..*p
            })
            .collect();
        let route = Route::new(pieces, vec![], path.length(), None).unwrap();
        assert_eq!(route.lane_position(lap + 4.0), (20, 2.0 + 4.0 * 0.5));
        // Clamped to the lane: before the track's start, past its end.
        assert_eq!(route.lane_position(-5.0), (20, 0.0));
        assert_eq!(route.lane_position(1e9), (20, lap));
        let x = 7.5;
        for k in 0..3 {
            let want = k as f64 * lap + (x - 2.0) / 0.5;
            let s = route.arc_at_lane_position(20, x, want - 1.0).unwrap();
            assert!((s - want).abs() < 1e-9, "lap {k}: {s} against {want}");
            let (lane, at) = route.lane_position(s);
            assert!(lane == 20 && (at - x).abs() < 1e-9);
        }
        let first = route.arc_at_lane_position(20, x, f64::NEG_INFINITY);
        assert_eq!(first, Some((x - 2.0) / 0.5));
        // Only behind s_from, another lane, or a position no lap covers.
        assert_eq!(route.arc_at_lane_position(20, x, 2.0 * lap + 12.0), None);
        assert_eq!(route.arc_at_lane_position(21, x, f64::NEG_INFINITY), None);
        assert_eq!(route.arc_at_lane_position(20, 1.0, f64::NEG_INFINITY), None);
        // The pieces within 1 m of a lap's start: the end of the lap before
        // and the start of this one; mid-lap, that lap's alone.
        assert_eq!(route.occurrences_near(lap, 1.0).collect::<Vec<_>>(), [0, 1]);
        assert_eq!(
            route.occurrences_near(1.5 * lap, 1.0).collect::<Vec<_>>(),
            [1]
        );
        assert_eq!(route.occurrences_near(-9.0, 1.0).collect::<Vec<_>>(), [0]);
    }

    #[test]
    fn a_vehicle_placed_on_a_lap_stays_on_that_lap() {
        let (mut f, t) = fleet_on(laps());
        let lap = f.route_of_track(t).unwrap().length_m / 3.0;
        for k in 0..3u32 {
            let a = f
                .add_vehicle(t, None, None, body(), on_circle(0.5, 10.0), Some(k))
                .unwrap() as i64;
            for _ in 0..100 {
                let out = step(&mut f, &[a], false).1;
                // On the lap it was put on (10 s at 10-15 m/s is 100-150 m:
                // less than the 314 m lap), and on its track, not a lap away.
                assert_eq!(f.occurrence(a).unwrap(), k);
                assert!(
                    out.lateral_error_m[0].abs() < 0.2,
                    "{}",
                    out.lateral_error_m[0]
                );
                assert!(out.s_rear_m[0] > k as f64 * lap && out.s_rear_m[0] < (k + 1) as f64 * lap);
            }
            // Retracked onto the same track, on the next lap: there it goes on.
            if k < 2 {
                f.retrack_at(a, t, Some(k + 1)).unwrap();
                let s = f.s_front(a).unwrap();
                assert!(s > (k + 1) as f64 * lap && s < (k + 2) as f64 * lap, "{s}");
                let out = step(&mut f, &[a], false).1;
                assert_eq!(f.occurrence(a).unwrap(), k + 1);
                assert!(
                    out.s_rear_m[0] > (k + 1) as f64 * lap,
                    "{}",
                    out.s_rear_m[0]
                );
            }
            f.remove_vehicle(a).unwrap();
        }
    }

    #[test]
    fn piece_tables_with_bad_lane_positions_lengths_or_offsets_are_rejected() {
        let (_, route) = road(None, true);
        for (k, bad) in [
            (
                0,
                Piece {
                    lane_pos_start_m: -1.0,
                    ..route.pieces[0]
                },
            ),
            (
                1,
                Piece {
                    lane_length_m: 0.0,
                    ..route.pieces[1]
                },
            ),
            (
                2,
                Piece {
                    offset_m: f64::NAN,
                    ..route.pieces[2]
                },
            ),
        ] {
            let mut pieces = route.pieces.clone();
            pieces[k] = bad;
            let e = Route::new(pieces, route.stops.clone(), 600.0, None).unwrap_err();
            assert!(e.to_string().contains(&format!("piece {k}")), "{e}");
        }
    }
}
