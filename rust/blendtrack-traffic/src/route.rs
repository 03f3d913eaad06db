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

/// Lanes and stop lines along a track (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
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
            pieces,
            stops,
            length_m,
            lane_change,
            revisits,
        })
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
