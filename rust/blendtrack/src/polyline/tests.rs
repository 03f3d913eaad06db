//! Closed-form checks of the polyline geometry.

use super::chain::{self, join, runs, ChainPiece};
use super::*;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn circle_arc(radius: f64, n: usize, dtheta: f64) -> Vec<Xy> {
    (0..n)
        .map(|i| {
            let th = i as f64 * dtheta;
            [radius * th.cos(), radius * th.sin()]
        })
        .collect()
}

#[test]
fn arc_lengths_of_a_straight_and_of_a_3_4_5_corner() {
    let line: Vec<Xy> = (0..5).map(|i| [2.0 * i as f64, 0.0]).collect();
    assert_eq!(arc_lengths(&line), vec![0.0, 2.0, 4.0, 6.0, 8.0]);
    assert_eq!(
        arc_lengths(&[[0.0, 0.0], [3.0, 4.0], [3.0, 10.0]]),
        vec![0.0, 5.0, 11.0]
    );
    assert_eq!(length(&[[0.0, 0.0], [3.0, 4.0], [3.0, 10.0]]), 11.0);
    assert_eq!(arc_lengths(&[]), Vec::<f64>::new());
    assert_eq!(length(&[[1.0, 1.0]]), 0.0);
}

#[test]
fn interp_matches_the_linear_formula_and_its_edge_rules() {
    let xp = [0.0, 1.0, 1.0, 3.0];
    let fp = [0.0, 10.0, 20.0, 40.0];
    assert_eq!(interp(0.5, &xp, &fp), 5.0);
    // A repeated abscissa: the later value, and interpolation from it.
    assert_eq!(interp(1.0, &xp, &fp), 20.0);
    assert_eq!(interp(2.0, &xp, &fp), 30.0);
    assert_eq!(interp(-1.0, &xp, &fp), 0.0);
    assert_eq!(interp(9.0, &xp, &fp), 40.0);
    assert_eq!(interp(3.0, &xp, &fp), 40.0);
    assert!(interp(f64::NAN, &xp, &fp).is_nan());
}

#[test]
fn resample_spaces_points_evenly_along_a_straight() {
    let pts = resample(&[[0.0, 0.0], [10.0, 0.0]], 3.0).unwrap();
    assert_eq!(
        pts,
        vec![[0.0, 0.0], [2.5, 0.0], [5.0, 0.0], [7.5, 0.0], [10.0, 0.0]]
    );
    // Shorter than the spacing: just the two ends.
    assert_eq!(
        resample(&[[0.0, 0.0], [0.0, 0.5]], 1.0).unwrap(),
        vec![[0.0, 0.0], [0.0, 0.5]]
    );
}

#[test]
fn resample_of_an_arc_keeps_points_on_its_chords_at_equal_arc_steps() {
    let r = 30.0;
    let src = circle_arc(r, 31, std::f64::consts::PI / 60.0);
    let total = length(&src);
    let pts = resample(&src, 1.0).unwrap();
    let n = (total / 1.0).ceil() as usize;
    assert_eq!(pts.len(), n + 1);
    assert_eq!(pts[0], src[0]);
    assert_eq!(pts[n], src[30]);
    // Points on a chord of the circle lie between R cos(dtheta/2) and R from the centre.
    let inner = r * (std::f64::consts::PI / 120.0).cos();
    for p in &pts {
        let d = p[0].hypot(p[1]);
        assert!(d <= r + 1e-9 && d >= inner - 1e-9, "{d}");
    }
    // Each step is total/n along the source polyline (equal on a chord).
    let s = arc_lengths(&pts);
    for w in s.windows(2) {
        assert!(w[1] - w[0] <= total / n as f64 + 1e-9);
    }
}

#[test]
fn resample_rejects_empty_single_nan_and_bad_spacing() {
    assert!(matches!(
        resample(&[], 1.0),
        Err(PolylineError::TooFewPoints { got: 0, .. })
    ));
    assert!(matches!(
        resample(&[[1.0, 2.0]], 1.0),
        Err(PolylineError::TooFewPoints { got: 1, .. })
    ));
    let e = resample(&[[0.0, 0.0], [f64::NAN, 1.0]], 1.0).unwrap_err();
    assert!(
        matches!(e, PolylineError::NonFinite { index: 1, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("point 1"));
    assert!(resample(&[[0.0, 0.0], [1.0, 1.0]], 0.0).is_err());
    assert!(resample(&[[0.0, 0.0], [1.0, 1.0]], f64::NAN).is_err());
}

#[test]
fn smoothstep_closed_form() {
    assert_eq!(smoothstep(-1.0), 0.0);
    assert_eq!(smoothstep(0.0), 0.0);
    assert_eq!(smoothstep(0.5), 0.5);
    assert_eq!(smoothstep(1.0), 1.0);
    assert_eq!(smoothstep(2.0), 1.0);
    assert!(close(smoothstep(0.25), 3.0 / 16.0 - 2.0 / 64.0, 1e-15));
}

#[test]
fn gaussian_kernel_is_normalised_symmetric_and_gaussian() {
    let sigma = 1.5;
    let k = gaussian_kernel(sigma);
    assert_eq!(k.len(), 11);
    assert!(close(k.iter().sum::<f64>(), 1.0, 1e-15));
    for i in 0..k.len() {
        assert_eq!(k[i], k[k.len() - 1 - i]);
        let x = i as f64 - 5.0;
        assert!(close(
            k[i] / k[5],
            (-0.5 * x * x / (sigma * sigma)).exp(),
            1e-14
        ));
    }
}

#[test]
fn smoothing_keeps_a_straight_and_shrinks_a_circle_by_the_kernel_s_cosine_sum() {
    let line: Vec<Xy> = (0..30).map(|i| [i as f64, 0.5 * i as f64]).collect();
    let sm = smooth(&line, 1.5);
    for i in 6..24 {
        assert!(close(sm[i][0], line[i][0], 1e-12) && close(sm[i][1], line[i][1], 1e-12));
    }
    assert_eq!(sm[0], line[0]);
    assert_eq!(sm[29], line[29]);
    // An evenly sampled circle: interior points stay on a circle of radius
    // R * sum_j k_j cos(j * dtheta).
    let (r, dth) = (30.0, 1.0 / 30.0);
    let circle = circle_arc(r, 60, dth);
    let sm = smooth(&circle, 1.5);
    let k = gaussian_kernel(1.5);
    let factor: f64 = k
        .iter()
        .enumerate()
        .map(|(j, kj)| kj * ((j as f64 - 5.0) * dth).cos())
        .sum();
    for p in &sm[6..54] {
        assert!(close(p[0].hypot(p[1]), r * factor, 1e-9));
    }
    // About sigma^2 / (2 R) inward (1.5 m spacing^2 ... here spacing 1 m).
    assert!(close(r - r * factor, 1.5 * 1.5 / (2.0 * r), 2e-3));
    // Too short or no smoothing: unchanged.
    assert_eq!(smooth(&circle[..4], 1.5), circle[..4].to_vec());
    assert_eq!(smooth(&circle, 0.0), circle);
}

#[test]
fn gradient_is_the_central_difference_inside_and_one_sided_at_the_ends() {
    let parabola: Vec<Xy> = (0..6).map(|i| [i as f64, (i * i) as f64]).collect();
    let g = gradient(&parabola);
    assert_eq!(g[0], [1.0, 1.0]);
    for (i, gi) in g.iter().enumerate().take(5).skip(1) {
        assert_eq!(*gi, [1.0, 2.0 * i as f64]);
    }
    assert_eq!(g[5], [1.0, 9.0]);
    assert_eq!(gradient(&[[3.0, 4.0]]), vec![[1.0, 0.0]]);
}

#[test]
fn blend_moves_between_parallel_lines_by_smoothstep() {
    let a = [[0.0, 0.0], [100.0, 0.0]];
    let b = [[0.0, 3.5], [100.0, 3.5]];
    let bl = blend(&a, &b, 1.0, Some(20.0), Some(50.0)).unwrap();
    assert_eq!(bl.points.len(), 101);
    for (i, p) in bl.points.iter().enumerate() {
        let w = smoothstep((i as f64 - 20.0) / 50.0);
        assert!(close(p[0], i as f64, 1e-12));
        assert!(close(p[1], 3.5 * w, 1e-12), "{i}: {p:?}");
        assert_eq!(bl.weight[i], w);
    }
    assert_eq!(bl.points[45][1], 1.75);
    // Over the whole line by default; the second line may be longer (same fraction).
    let c = [[0.0, 3.5], [200.0, 3.5]];
    let bl = blend(&a, &c, 10.0, None, None).unwrap();
    assert_eq!(bl.weight[0], 0.0);
    assert_eq!(bl.weight[10], 1.0);
    assert_eq!(bl.points[10], [200.0, 3.5]);
    assert_eq!(bl.s_onto[5], 100.0);
    assert!(blend(&a, &[[0.0, 0.0]], 1.0, None, None).is_err());
}

#[test]
fn segment_distances_closed_forms() {
    let d = segments_distance(&[[0.0, 0.0], [1.0, 0.0]], &[[2.0, 1.0], [3.0, 1.0]]).unwrap();
    assert_eq!(d, 2f64.sqrt());
    let d = segments_distance(&[[0.0, 0.0], [10.0, 0.0]], &[[3.0, 2.0], [7.0, 2.0]]).unwrap();
    assert_eq!(d, 2.0);
    // Crossing: zero; touching ends are not a crossing but at distance zero.
    assert_eq!(
        segments_distance(&[[0.0, -1.0], [0.0, 1.0]], &[[-1.0, 0.0], [1.0, 0.0]]).unwrap(),
        0.0
    );
    assert_eq!(
        segments_distance(&[[0.0, 0.0], [1.0, 0.0]], &[[1.0, 0.0], [1.0, 5.0]]).unwrap(),
        0.0
    );
    // A single point to a polyline: distance to its nearest segment.
    let d = segments_distance(&[[5.0, 4.0]], &[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]).unwrap();
    assert_eq!(d, 4.0);
    assert_eq!(
        point_segment_distance([3.0, 4.0], [0.0, 0.0], [0.0, 0.0]),
        5.0
    );
    assert_eq!(
        segments_distance(&[], &[[0.0, 0.0]]).unwrap(),
        f64::INFINITY
    );
    assert!(segments_distance(&[[0.0, f64::NAN]], &[[0.0, 0.0]]).is_err());
}

#[test]
fn runs_merge_short_near_stretches_into_far() {
    let f = [true, false, false, true, true, false, false, false, false];
    assert_eq!(runs(&f, 4), vec![(0, 5), (5, 9)]);
    assert_eq!(runs(&f, 2), vec![(0, 1), (1, 3), (3, 5), (5, 9)]);
    assert_eq!(runs(&[false; 3], 4), vec![(0, 3)]);
}

fn piece(points: Vec<Xy>, scale: f64) -> ChainPiece {
    let station = arc_lengths(&points);
    ChainPiece {
        points,
        station,
        on_reference: true,
        station_scale: scale,
    }
}

#[test]
fn chain_of_straight_pieces_shares_points_and_keeps_stations() {
    let a: Vec<Xy> = (0..=10).map(|i| [i as f64, 0.0]).collect();
    let b: Vec<Xy> = (10..=20).map(|i| [i as f64, 0.0]).collect();
    // A piece after a 1 m gap (evenly spaced, so the smoothing moves nothing).
    let c: Vec<Xy> = (21..=30).map(|i| [i as f64, 0.0]).collect();
    let ch = join(
        &[piece(a, 1.0), piece(b, 2.0), piece(c, 1.0)],
        1.5,
        0.0,
        0.06,
        4,
    )
    .unwrap();
    assert_eq!(ch.points.len(), 11 + 10 + 10);
    assert_eq!(ch.length, 30.0);
    assert_eq!(ch.kept, vec![0, 1, 2]);
    assert_eq!(ch.kept_points, vec![11, 10, 10]);
    assert_eq!(ch.start_s, vec![0.0, 10.0, 21.0]);
    assert_eq!(ch.before_s, vec![0.0, 10.0, 20.0]);
    assert_eq!(ch.entry_s, vec![0.0, 11.0, 21.0]);
    assert_eq!(ch.runs.len(), 3);
    for (run, (start, scale)) in ch.runs.iter().zip([(0.0, 1.0), (10.0, 2.0), (21.0, 1.0)]) {
        assert!(
            close(run.start_s, start, 1e-12) && close(run.scale, scale, 1e-12),
            "{run:?}"
        );
        assert_eq!(run.station, 0.0);
        assert!(run.offset < 1e-12);
    }
    // The route stations:
    // a: its own stations; b: on from a's end at twice the rate; c: on from
    // b's end (30), the 1 m gap before it not counted. The line is straight,
    // so each point's station is a function of its x.
    let station_of = |x: f64| {
        if x <= 10.0 {
            x
        } else if x <= 20.0 {
            10.0 + 2.0 * (x - 10.0)
        } else {
            30.0 + (x - 21.0).max(0.0)
        }
    };
    assert_eq!(ch.station.len(), ch.points.len());
    for (k, (&got, p)) in ch.station.iter().zip(&ch.points).enumerate() {
        let w = station_of(p[0]);
        assert!(close(got, w, 1e-9), "point {k} at x {}: {got} vs {w}", p[0]);
    }
    assert!(close(ch.station[ch.station.len() - 1], 39.0, 1e-9));
}

#[test]
fn chain_splits_a_piece_where_smoothing_rounds_a_corner() {
    let a: Vec<Xy> = (0..=20).map(|i| [i as f64, 0.0]).collect();
    let b: Vec<Xy> = (0..=20).map(|i| [20.0, i as f64]).collect();
    let ch = join(&[piece(a, 1.0), piece(b, 1.0)], 1.5, 0.0, 0.06, 4).unwrap();
    assert_eq!(ch.kept_points, vec![21, 20]);
    // Near, away (the corner), near again on each side: the corner's run is far.
    let of_a: Vec<_> = ch.runs.iter().filter(|r| r.piece == 0).collect();
    assert_eq!(of_a.len(), 2, "{:?}", ch.runs);
    assert!(of_a[0].offset <= 0.06 && of_a[1].offset > 0.06);
    assert!(ch.length < 40.0 && ch.length > 39.0);
    // An off-reference piece is one far run.
    let mut off = piece((0..5).map(|i| [i as f64, 0.0]).collect(), 1.0);
    off.on_reference = false;
    let ch = join(&[off], 1.5, 0.0, 0.06, 4).unwrap();
    assert_eq!(ch.runs.len(), 1);
    assert_eq!(ch.runs[0].offset, f64::INFINITY);
}

#[test]
fn chain_rejects_empty_pieces_and_mismatched_stations() {
    assert!(join(&[], 1.5, 0.0, 0.06, 4).is_err());
    let mut p = piece(vec![[0.0, 0.0], [1.0, 0.0]], 1.0);
    p.station.pop();
    assert!(matches!(
        join(&[p], 1.5, 0.0, 0.06, 4),
        Err(PolylineError::Count {
            got: 1,
            expected: 2,
            ..
        })
    ));
    let p = piece(vec![], 1.0);
    assert!(join(&[p], 1.5, 0.0, 0.06, 4).is_err());
}

/// An L: along x from the origin to (20, 0), then up to (20, 20), 1 m apart.
fn right_angle() -> Vec<Xy> {
    let mut p: Vec<Xy> = (0..=20).map(|i| [i as f64, 0.0]).collect();
    p.extend((1..=20).map(|i| [20.0, i as f64]));
    p
}

fn peak_curvature(p: &[Xy]) -> f64 {
    turns::curvatures(p)
        .iter()
        .fold(0.0, |m: f64, k| m.max(k.abs()))
}

#[test]
fn curvature_of_a_circle_is_its_chord_angle_over_its_chord() {
    // Chords of 2 R sin(dtheta / 2) turning by dtheta: k = dtheta / chord.
    let (r, dth) = (10.0, 0.1_f64);
    let k = turns::curvatures(&circle_arc(r, 20, dth));
    let want = dth / (2.0 * r * (0.5 * dth).sin());
    assert_eq!((k[0], k[19]), (0.0, 0.0));
    assert!(k[1..19].iter().all(|&v| close(v, want, 1e-12)), "{k:?}");
    // Clockwise: negative. Repeated points: 0.
    let cw: Vec<Xy> = circle_arc(r, 5, -dth);
    assert!(close(turns::curvatures(&cw)[2], -want, 1e-12));
    assert_eq!(
        turns::curvatures(&[[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])[1],
        0.0
    );
}

#[test]
fn a_right_angle_is_rounded_to_the_radius_and_stays_symmetric() {
    let sm = smooth(&right_angle(), 1.5);
    let kmax = 0.25;
    assert!(peak_curvature(&sm) > 2.0 * kmax, "{}", peak_curvature(&sm));
    let (out, r) = turns::round_sharp_turns(&sm, 1.5, kmax);
    assert_eq!(r.stretches.len(), 1, "{r:?}");
    assert!(
        r.peak_after[0] <= kmax && peak_curvature(&out) <= kmax,
        "{r:?}"
    );
    assert_eq!(out.len(), sm.len());
    // Far from the corner the track is where it was.
    assert_eq!((out[0], out[40]), (sm[0], sm[40]));
    // The L is its own mirror image across the line through (0, 20) and
    // (20, 0) (x, y) -> (20 - y, 20 - x), point i onto point 40 - i; so is the rounding.
    for i in 0..=40 {
        let (p, q) = (out[i], out[40 - i]);
        assert!(
            close(p[0], 20.0 - q[1], 1e-9) && close(p[1], 20.0 - q[0], 1e-9),
            "{i}: {p:?} {q:?}"
        );
    }
    // The corner is cut: a circle of radius 1 / kmax tangent to both legs
    // passes R (sqrt 2 - 1) from the corner, and a rounding no sharper
    // cannot pass nearer.
    let nearest = out
        .iter()
        .map(|p| distance(*p, [20.0, 0.0]))
        .fold(f64::INFINITY, f64::min);
    assert!(nearest >= (2.0_f64.sqrt() - 1.0) / kmax * 0.9, "{nearest}");
}

#[test]
fn a_u_turn_too_tight_for_any_width_is_left_as_it_was() {
    // Out along y = 0 and back along y = 1: no smoothing makes that R = 4
    // (wider ones pull the legs together into a cusp, sharper still).
    let mut p: Vec<Xy> = (0..=30).map(|i| [i as f64, 0.0]).collect();
    p.extend((0..=30).rev().map(|i| [i as f64, 1.0]));
    let sm = smooth(&p, 1.5);
    let before = peak_curvature(&sm);
    let (out, r) = turns::round_sharp_turns(&sm, 1.5, 0.25);
    assert_eq!(r.stretches.len(), 1, "{r:?}");
    assert_eq!(r.peak_after[0], before);
    assert_eq!(out, sm);
}

#[test]
fn rounding_is_off_without_a_positive_finite_limit_and_leaves_gentle_curves() {
    let sm = smooth(&right_angle(), 1.5);
    for k in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let (out, r) = turns::round_sharp_turns(&sm, 1.5, k);
        assert_eq!(out, sm);
        assert!(r.stretches.is_empty());
    }
    // An R = 10 m circle is within R = 4 m: untouched.
    let arc = circle_arc(10.0, 60, 0.1);
    let (out, r) = turns::round_sharp_turns(&arc, 1.5, 0.25);
    assert_eq!(out, arc);
    assert!(r.stretches.is_empty());
    // Too few points: as given.
    let few = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    assert_eq!(turns::round_sharp_turns(&few, 1.5, 0.25).0, few.to_vec());
}

#[test]
fn join_reports_the_turns_it_rounded_and_the_runs_there_leave_the_lane() {
    let l = right_angle();
    let plain = join(&[piece(l.clone(), 1.0)], 1.5, 0.0, 0.06, 4).unwrap();
    let ch = join(&[piece(l, 1.0)], 1.5, 0.25, 0.06, 4).unwrap();
    assert!(plain.rounded.is_empty());
    assert_eq!(ch.rounded.len(), 1);
    let (a, b, k) = ch.rounded[0];
    assert!(
        a < b && a > 10.0 && b < ch.length - 10.0 && k <= 0.25,
        "{:?} {}",
        ch.rounded,
        ch.length
    );
    // Cutting the corner shortens the track, and its runs off the lane are
    // further off than the plain smoothing's.
    assert!(ch.length < plain.length);
    let far = |c: &chain::Chain| c.runs.iter().map(|r| r.offset).fold(0.0, f64::max);
    assert!(far(&ch) > far(&plain) + 0.5, "{} {}", far(&ch), far(&plain));
}

#[test]
fn route_stations_of_a_piece_that_goes_on_along_its_line_keep_its_origin() {
    // A lane change's stretches: on lane a to 10 m, then on the lane beside
    // (y = 1) from its position 11 m on, not sharing a point: its stations
    // are lane positions of the same edge, so the route station is them.
    let a: Vec<Xy> = (0..=10).map(|i| [i as f64, 0.0]).collect();
    let b: Vec<Xy> = (11..=30).map(|i| [i as f64, 1.0]).collect();
    let mut pb = piece(b, 1.0);
    pb.station.iter_mut().for_each(|x| *x += 11.0);
    let ch = join(&[piece(a, 1.0), pb], 1.5, 0.0, 0.06, 4).unwrap();
    // Away from the step between the lanes (which the smoothing rounds
    // over a few metres) each point's station is its x.
    for (k, (&got, p)) in ch.station.iter().zip(&ch.points).enumerate() {
        if (p[0] - 10.5).abs() > 4.0 {
            assert!(close(got, p[0], 1e-6), "point {k} at x {}: {got}", p[0]);
        }
    }
    assert!(ch.station.windows(2).all(|w| w[1] - w[0] < 1.5));
}

#[test]
fn route_stations_jump_ahead_where_the_track_cuts_a_corner() {
    // A right-angle corner rounded to a 4 m radius: the track cuts inside
    // it, and the nearest point of the reference lines jumps past the corner.
    let a: Vec<Xy> = (0..=30).map(|i| [i as f64, 0.0]).collect();
    let b: Vec<Xy> = (0..=30).map(|i| [30.0, i as f64]).collect();
    let ch = join(&[piece(a, 1.0), piece(b, 1.0)], 1.5, 0.25, 0.06, 4).unwrap();
    let s = arc_lengths(&ch.points);
    assert!(
        ch.station.windows(2).all(|w| w[1] >= w[0]),
        "non-decreasing"
    );
    assert!(close(ch.station[0], 0.0, 1e-9));
    assert!(close(ch.station[ch.station.len() - 1], 60.0, 1e-9));
    let shortcut = 60.0 - ch.length;
    assert!(
        shortcut > 0.5,
        "the track is {shortcut} m shorter than the lanes"
    );
    // Away from the corner the station is the arc length (before it) or the
    // arc length plus the shortcut (after it).
    assert!(close(ch.station[10], s[10], 1e-6));
    let last = s.len() - 10;
    assert!(close(ch.station[last] - s[last], shortcut, 1e-6));
    // Somewhere in the corner, one point to the next gains more station than
    // arc length by a good part of the shortcut: a jump, not a smooth stretch.
    let biggest = (1..s.len())
        .map(|k| (ch.station[k] - ch.station[k - 1]) - (s[k] - s[k - 1]))
        .fold(0.0, f64::max);
    assert!(
        biggest > 0.3 * shortcut,
        "largest jump {biggest} of {shortcut}"
    );
}

/// `nearest_station` as written first: `hypot` on every segment, the
/// first of the smallest kept.
fn nearest_station_reference(p: Xy, line: &[Xy], station: &[f64]) -> Option<f64> {
    let mut best = (f64::INFINITY, None);
    for r in 0..line.len().saturating_sub(1) {
        let (t, ex, ey) = chain::foot(p, line[r], line[r + 1]);
        let d = ex.hypot(ey);
        if d < best.0 {
            best = (d, Some(station[r] + t * (station[r + 1] - station[r])));
        }
    }
    best.1
}

#[test]
fn nearest_station_takes_the_first_of_two_equally_near_sides_of_a_corner() {
    // A right angle at (0, 0); (-0.1, 0.1) is 0.1 m from both sides: the
    // first side's foot (-0.1, 0) is at station 0.9, the second's (0, 0.1)
    // at 1.1.
    let line = [[-1.0, 0.0], [0.0, 0.0], [0.0, 1.0]];
    let st = [0.0, 1.0, 2.0];
    let mut scratch = Vec::new();
    assert_eq!(
        chain::nearest_station([-0.1, 0.1], &line, &st, &mut scratch),
        Some(0.9)
    );
    // Nearer the second side: its foot.
    let s = chain::nearest_station([-0.1, 0.2], &line, &st, &mut scratch).unwrap();
    assert!(close(s, 1.2, 1e-12), "{s}");
    // A corner of the 7 x 7 grid's tracks (a junction lane's points): the
    // point is as near to both sides by `hypot`, but its squared distance
    // to the second side is smaller in the last bit.
    let line = [
        [407.74887468762716, 255.2706751874237],
        [406.9744373438136, 255.73533759371185],
        [406.2, 256.2],
        [405.73533759371185, 256.9744373438136],
        [405.2706751874237, 257.74887468762716],
    ];
    let p = [406.39769536244256, 256.39769536244256];
    let st = [0.0, 1.0, 2.0, 3.0, 4.0];
    let s = chain::nearest_station(p, &line, &st, &mut scratch).unwrap();
    assert!(close(s, 1.925, 1e-3), "{s}");
    assert_eq!(Some(s), nearest_station_reference(p, &line, &st));
    // Nothing to map onto: no segment, or a NaN point.
    assert_eq!(
        chain::nearest_station([0.0, 0.0], &line[..1], &st[..1], &mut scratch),
        None
    );
    assert_eq!(
        chain::nearest_station([f64::NAN, 0.0], &line, &st, &mut scratch),
        None
    );
}

proptest::proptest! {
    /// The pruned search gives the bits of `hypot` on every segment,
    /// ties at corners included (points on a 1 m grid near a zigzag whose
    /// stations jump at a corner).
    #[test]
    fn nearest_station_is_the_full_hypot_search(
        seed in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0), 6..30),
        px in -40i32..40, py in -40i32..40, on_grid in proptest::bool::ANY,
    ) {
        let line: Vec<Xy> = seed.iter().scan([0.0, 0.0], |at, &(dx, dy)| {
            *at = [at[0] + dx.round() * 0.5, at[1] + dy.round() * 0.5];
            Some(*at)
        }).collect();
        let mut st = arc_lengths(&line);
        let k = st.len() / 2;
        st[k..].iter_mut().for_each(|s| *s += 0.25);
        let p = if on_grid {
            [f64::from(px) * 0.25, f64::from(py) * 0.25]
        } else {
            [f64::from(px) * 0.1 + 0.013, f64::from(py) * 0.1 - 0.007]
        };
        let mut scratch = Vec::new();
        let got = chain::nearest_station(p, &line, &st, &mut scratch);
        let want = nearest_station_reference(p, &line, &st);
        proptest::prop_assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits));
    }
}

#[test]
fn rounding_a_staircase_rounds_every_corner_as_it_rounds_one_alone() {
    // A staircase of right-angle corners 100 m apart: a rounding's window
    // (at most 3 x 27 points either side of its stretch, 27 = 3 x 6 x 1.5
    // the widest Gaussian's core) stays clear of the next corner's, so each
    // corner comes out as the corner rounded alone, shifted. Catches a
    // curvature left stale after a rounding (the search would find the
    // rounded corner's old values again) and one refreshed wrongly.
    let (steps, leg) = (20, 100);
    let mut p: Vec<Xy> = vec![];
    for s in 0..steps {
        let o = (leg * s) as f64;
        p.extend((0..leg).map(|i| [o + i as f64, o]));
        p.extend((0..leg).map(|i| [o + leg as f64, o + i as f64]));
    }
    p.push([(leg * steps) as f64; 2]);
    let sm = smooth(&p, 1.5);
    let (out, r) = turns::round_sharp_turns(&sm, 1.5, 0.25);
    assert_eq!(r.stretches.len(), 2 * steps - 1, "{:?}", r.stretches);
    assert!(
        r.peak_after.iter().all(|&k| k <= 0.25),
        "{:?}",
        r.peak_after
    );
    assert!(peak_curvature(&out) <= 0.25);
    // A corner in the middle against the same corner alone (the points
    // within half a leg of it).
    let c = leg * steps; // the corner at (leg s, leg s), s = steps / 2
    let h = leg / 2;
    let (one, r1) = turns::round_sharp_turns(&sm[c - h..=c + h], 1.5, 0.25);
    assert_eq!(r1.stretches.len(), 1, "{:?}", r1.stretches);
    assert_eq!(&out[c - h..=c + h], &one[..]);
}
#[test]
fn rounding_keeps_each_curvature_as_computing_them_all_again_would() {
    // 200 random tracks of 300 m with a kink (up to 86 deg) about every
    // 7 m: roundings reach over the next kinks. The kept curvatures
    // (refreshed only where a rounding moved points) must round every track
    // to the same bits as computing them all again for each stretch; with
    // stale ones 1,252 stretches come out instead of 1,120.
    let mut seed: u64 = 12345;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut stretches = 0;
    for case in 0..200 {
        let mut p: Vec<Xy> = vec![[0.0, 0.0]];
        let mut th: f64 = 0.0;
        for _ in 0..300 {
            if rnd() < 0.15 {
                th += (rnd() - 0.5) * 3.0;
            }
            let q = p[p.len() - 1];
            p.push([q[0] + th.cos(), q[1] + th.sin()]);
        }
        let sm = smooth(&p, 1.5);
        let kept = turns::round(&sm, 1.5, 0.25, false);
        assert_eq!(kept, turns::round(&sm, 1.5, 0.25, true), "track {case}");
        stretches += kept.1.stretches.len();
    }
    assert_eq!(stretches, 1120);
}
