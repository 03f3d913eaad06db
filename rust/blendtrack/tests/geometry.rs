//! Projection and ray cast on real race tracks (../shared/tracks) and on a
//! hairpin: the fast windowed searches agree with brute force where they must
//! and refuse to jump legs where they must not.

use blendtrack::*;
use nalgebra::Point2;
use std::path::PathBuf;

/// A race track of ../shared/tracks (or of `$BLENDTRACK_SHARED_DIR/tracks`),
/// or `None` (with a message saying the test is skipped) when that folder
/// is not there. A track that is there but does not load is a failure, not
/// a skip.
fn shared_track(name: &str) -> Option<Path> {
    let shared = std::env::var_os("BLENDTRACK_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    let dir = shared.join("tracks");
    if !dir.is_dir() {
        eprintln!(
            "skipped: {} is missing (keep ../shared beside the repo)",
            dir.display()
        );
        return None;
    }
    Some(Path::from_tum_csv(&dir.join(name), true).unwrap_or_else(|e| panic!("{name}: {e}")))
}

/// Deterministic pseudo-random numbers in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

#[test]
fn nuerburgring_loads_with_widths() {
    let Some(p) = shared_track("Nuerburgring.csv") else {
        return;
    };
    assert_eq!(p.len_points(), 1029);
    assert!(p.is_closed());
    assert!((p.length() - 5144.0).abs() < 30.0, "lap {}", p.length());
    let w = p.widths_at(0.0).unwrap();
    assert!((w.right_m - 7.288).abs() < 1e-9 && (w.left_m - 7.487).abs() < 1e-9);
}

#[test]
fn windowed_projection_equals_brute_force_near_the_track() {
    for name in [
        "Nuerburgring.csv",
        "Monza.csv",
        "Hockenheim.csv",
        "Zandvoort.csv",
    ] {
        let Some(p) = shared_track(name) else {
            return;
        };
        let mut rng = Lcg(7);
        let mut hint = 0.0;
        let mut checked = 0;
        let mut s = 0.0;
        while s < p.length() {
            // A point within 3 m of the centreline, hint from the previous step.
            let c = p.point_at(s);
            let h = p.heading_at(s);
            let off = 3.0 * rng.next();
            let q = Point2::new(
                c.x - off * h.sin() + 0.5 * rng.next(),
                c.y + off * h.cos() + 0.5 * rng.next(),
            );
            let fast = p.project_hinted(&q, hint);
            let full = p.project(&q);
            let brute = p.project_brute_force(&q);
            // The descent from a predicted hint (the controller moves its
            // hints on by the distance travelled: here, the 2.7 m step).
            let near = p.project_near(&q, hint + 2.7);
            assert_eq!(p.arc_near(&q, hint + 2.7), near.s);
            assert!(
                (near.lateral_m.abs() - brute.lateral_m.abs()).abs() < 1e-9,
                "{name} s={s}: near {near:?} vs brute {brute:?}"
            );
            assert!(
                (fast.lateral_m.abs() - brute.lateral_m.abs()).abs() < 1e-9,
                "{name} s={s}: hinted {fast:?} vs brute {brute:?}"
            );
            assert!(
                (full.lateral_m.abs() - brute.lateral_m.abs()).abs() < 1e-9,
                "{name} s={s}: full {full:?} vs brute {brute:?}"
            );
            assert!(
                p.arc_delta(fast.s, brute.s).abs() < 1.0,
                "{name} s={s}: same place on the track"
            );
            hint = fast.s;
            s += 2.7;
            checked += 1;
        }
        assert!(checked > 1000, "{name}: {checked}");
    }
}

#[test]
fn hinted_projection_does_not_jump_to_the_other_leg_of_a_hairpin() {
    // Two parallel 100 m legs 6 m apart joined by a half circle of radius 3 m.
    let mut pts = Vec::new();
    for i in 0..=100 {
        pts.push([i as f64, 0.0]);
    }
    for k in 1..30 {
        let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * k as f64 / 30.0;
        pts.push([100.0 + 3.0 * a.cos(), 3.0 + 3.0 * a.sin()]);
    }
    for i in (0..=100).rev() {
        pts.push([i as f64, 6.0]);
    }
    let p = Path::new(&pts, None, false).unwrap();
    // A vehicle on the first leg, drifted 4 m toward the other leg: the
    // nearest point overall is on the other leg, the tracked one is not.
    let q = Point2::new(50.0, 4.0);
    let brute = p.project_brute_force(&q);
    assert!(
        brute.s > 150.0,
        "brute force picks the other leg: {brute:?}"
    );
    let hinted = p.project_hinted(&q, 49.0);
    assert!(
        (hinted.s - 50.0).abs() < 1e-9 && (hinted.lateral_m - 4.0).abs() < 1e-9,
        "{hinted:?}"
    );
    let near = p.project_near(&q, 49.0);
    assert!(
        (near.s - 50.0).abs() < 1e-9 && (near.lateral_m - 4.0).abs() < 1e-9,
        "{near:?}"
    );
    // Driving along the first leg step by step keeps the first leg.
    let (mut hint, mut hint_near) = (0.0, 0.0);
    for i in 0..90 {
        let q = Point2::new(i as f64 + 0.3, 3.9);
        let pr = p.project_hinted(&q, hint);
        assert!(pr.s < 100.0, "step {i}: jumped to {}", pr.s);
        hint = pr.s;
        let pn = p.project_near(&q, hint_near + 1.0);
        assert!(pn.s < 100.0, "step {i}: the descent jumped to {}", pn.s);
        hint_near = pn.s;
    }
}

#[test]
fn hinted_projection_catches_up_after_a_long_jump() {
    // A hint far behind (a vehicle that was teleported) still finds the right place by walking.
    let p = Path::straight(1000.0, 2.0).unwrap();
    let pr = p.project_hinted(&Point2::new(600.0, 1.0), 10.0);
    assert!((pr.s - 600.0).abs() < 1e-9, "{pr:?}");
    let pr = p.project_near(&Point2::new(600.0, 1.0), 10.0);
    assert!((pr.s - 600.0).abs() < 1e-9, "the descent too: {pr:?}");
    // On a closed path it goes round the seam, both ways.
    let c = Path::circle(20.0, 1e-3).unwrap();
    for (q, hint) in [
        (Point2::new(20.5, -0.3), 1.0),
        (Point2::new(20.5, 0.3), c.length() - 1.0),
    ] {
        let a = c.project_near(&q, hint);
        let b = c.project_brute_force(&q);
        assert!(c.arc_delta(a.s, b.s).abs() < 1e-9, "{a:?} vs {b:?}");
    }
    // A NaN hint is the full search.
    let pr = p.project_near(&Point2::new(321.0, -2.0), f64::NAN);
    assert!((pr.s - 321.0).abs() < 1e-9 && (pr.lateral_m + 2.0).abs() < 1e-9);
}

#[test]
fn ray_cast_window_equals_full_scan_on_real_tracks() {
    let cfg = ControllerConfig::default();
    for name in ["Nuerburgring.csv", "Monza.csv"] {
        let Some(p) = shared_track(name) else {
            return;
        };
        let cor = Corridor::new(&p, &cfg);
        let mut rng = Lcg(11);
        let mut s = 0.0;
        let mut hits = 0;
        while s < p.length() {
            let c = p.point_at(s);
            let h = p.heading_at(s);
            let off = 2.0 * rng.next();
            let q = Point2::new(c.x - off * h.sin(), c.y + off * h.cos());
            let heading = h + 0.2 * rng.next();
            let pr = p.project_hinted(&q, s);
            let fast = cor.ray_cast(&p, &q, heading, pr.s, 1e6);
            let all = cor.ray_cast_all(&p, &q, heading);
            match (fast, all) {
                (Some(a), Some(b)) => {
                    assert!((a - b).abs() < 1e-9, "{name} s={s}: {a} vs {b}");
                    hits += 1;
                }
                (a, b) => assert_eq!(a, b, "{name} s={s}"),
            }
            s += 5.3;
        }
        assert!(hits > 500, "{name}: {hits}");
    }
}

#[test]
fn track_widths_drive_the_borders() {
    // The TUM widths (about 7.4 m a side) are used unless disabled.
    let Some(p) = shared_track("Nuerburgring.csv") else {
        return;
    };
    let with = Corridor::new(&p, &ControllerConfig::default());
    let without = Corridor::new(
        &p,
        &ControllerConfig {
            use_path_widths: false,
            path_width_m: 4.0,
            ..Default::default()
        },
    );
    let c = p.points()[0];
    let dl = (with.left()[0] - c).norm();
    let dr = (with.right()[0] - c).norm();
    assert!((dl - 7.487).abs() < 1e-9 && (dr - 7.288).abs() < 1e-9);
    assert!(((without.left()[0] - c).norm() - 2.0).abs() < 1e-9);
    let margin = Corridor::new(
        &p,
        &ControllerConfig {
            border_margin_m: -1.0,
            ..Default::default()
        },
    );
    assert!(((margin.left()[0] - c).norm() - 6.487).abs() < 1e-9);
}

#[test]
fn a_projection_between_two_arc_lengths_keeps_to_that_stretch() {
    // The same straight 100 m driven out and, 3 m to the left, back: a
    // point 1 m left of the way out is nearer to it (1 m) than to the way
    // back (2 m), and on the way back when only that stretch is searched.
    let mut pts: Vec<[f64; 2]> = (0..=100).map(|i| [i as f64, 0.0]).collect();
    pts.extend((0..=100).rev().map(|i| [i as f64, 3.0]));
    let p = Path::new(&pts, None, false).unwrap();
    let q = Point2::new(40.0, 1.0);
    let whole = p.project_between(&q, 0.0, p.length());
    assert!((whole.s - 40.0).abs() < 1e-9, "{whole:?}");
    assert_eq!(whole.s, p.project_brute_force(&q).s);
    let back = p.project_between(&q, 150.0, p.length());
    // The way back starts at 103 m (100 m out, 3 m across); x = 40 is 60 m
    // on, the point 2 m to its left (heading west, left is south).
    assert!(
        (back.s - 163.0).abs() < 1e-9 && (back.lateral_m - 2.0).abs() < 1e-9,
        "{back:?}"
    );
    // A stretch inside one segment still finds that segment's foot point.
    let short = p.project_between(&q, 40.2, 40.4);
    assert!((short.s - 40.0).abs() < 1e-9, "{short:?}");
}
