//! Closed-loop behaviour checked against closed forms: circle steady state,
//! convergence from a 4 m offset forward and backward, moving control point.

use blendtrack::*;
use std::sync::Arc;

/// `simulate` with the default vehicle, the one every test here drives.
fn sim(
    track: &Arc<Track>,
    cfg: &ControllerConfig,
    sched: &AlphaSchedule,
    opts: &SimOptions,
) -> Result<Trace, Error> {
    simulate(track.clone(), cfg, &VehicleParams::default(), sched, opts)
}

fn run(path: Path, cfg: ControllerConfig, opts: SimOptions) -> Trace {
    let track = Arc::new(Track::new(path, &cfg));
    let sched = AlphaSchedule::Constant {
        alpha: cfg.lat_blend_factor,
    };
    sim(&track, &cfg, &sched, &opts).unwrap()
}

fn tail_mean_abs(v: &[f64], n: usize) -> f64 {
    let tail = &v[v.len() - n.min(v.len())..];
    tail.iter().map(|x| x.abs()).sum::<f64>() / tail.len() as f64
}

fn tail_mean(v: &[f64], n: usize) -> f64 {
    let tail = &v[v.len() - n.min(v.len())..];
    tail.iter().sum::<f64>() / tail.len() as f64
}

#[test]
fn circle_steady_state_steering() {
    let e: f64 = 2.6;
    for r in [10.0, 50.0, 200.0] {
        let ackermann = (e / r).atan();
        // The front axle on a circle of radius R: sin(delta) = E / R.
        let front_on_circle = (e / r).asin();
        for (kind, alpha) in [
            (LateralKind::Blend, 0.0),
            (LateralKind::Blend, 0.5),
            (LateralKind::Stanley, 1.0),
            (LateralKind::Blend, 1.0),
        ] {
            let cfg = ControllerConfig {
                lateral_controller: kind,
                lat_blend_factor: alpha,
                path_width_m: 4.0,
                ..Default::default()
            };
            let speed = 3.0;
            let opts = SimOptions {
                duration_s: 3.0 * r.max(20.0) / speed,
                fixed_speed_mps: Some(speed),
                ..Default::default()
            };
            let tr = run(Path::circle(r, 1e-4).unwrap(), cfg, opts);
            let delta = tail_mean(&tr.delta_rad, 500);
            if alpha == 0.0 {
                assert!(
                    (delta - ackermann).abs() < 1e-3,
                    "R={r} rear: {delta} vs atan(E/R) {ackermann}"
                );
            } else if alpha == 1.0 {
                assert!(
                    (delta - front_on_circle).abs() < 1e-3,
                    "R={r} stanley: {delta} vs asin(E/R) {front_on_circle}"
                );
            } else {
                assert!(
                    delta > ackermann - 1e-3 && delta < front_on_circle + 1e-3,
                    "R={r} blend: {delta} not in [{ackermann}, {front_on_circle}]"
                );
            }
            // All of them are the Ackermann angle up to the axle geometry.
            assert!(
                (delta - ackermann).abs() < 0.01,
                "R={r} alpha={alpha}: {delta}"
            );
            // Each single law puts its own axle on the circle; the control point
            // P(alpha) then sits off the path by at most (alpha E)^2 / 2R (rear law
            // equilibrium) or (1 - alpha^2) E^2 / 2R (Stanley equilibrium).
            let bound = (alpha * alpha).max(1.0 - alpha * alpha) * e * e / (2.0 * r) + 1e-3;
            let bound = if alpha == 0.0 || alpha == 1.0 {
                2e-3
            } else {
                bound
            };
            let cp_err = tail_mean_abs(&tr.lateral_error_m, 500);
            assert!(
                cp_err < bound,
                "R={r} alpha={alpha}: control point error {cp_err} > {bound}"
            );
        }
    }
}

fn assert_converges(path: &Path, direction: Direction, alpha: f64, duration_s: f64) {
    let speed = match direction {
        Direction::Forward => 3.0,
        Direction::Backward => 1.0,
    };
    let cfg = ControllerConfig {
        direction,
        lat_blend_factor: alpha,
        preferred_speed: speed,
        ..Default::default()
    };
    let opts = SimOptions {
        duration_s,
        initial_offset_m: 4.0,
        ..Default::default()
    };
    let tr = run(path.clone(), cfg, opts);
    let final_err = tail_mean_abs(&tr.lateral_error_m, 500);
    assert!(
        final_err < 0.05,
        "{direction:?} alpha={alpha}: |e| = {final_err} after {duration_s} s"
    );
    let max_err = tr
        .lateral_error_m
        .iter()
        .fold(0.0f64, |m, e| m.max(e.abs()));
    assert!(
        max_err < 4.0 + 2.6 + 0.5,
        "{direction:?} alpha={alpha}: bounded excursion, max |e| = {max_err}"
    );
    let mean_v = tail_mean(&tr.v_mps, 500);
    assert!(
        (mean_v - direction.sign() * speed).abs() < 0.3,
        "{direction:?}: travels at its preferred speed, got {mean_v}"
    );
}

#[test]
fn converges_from_4m_offset_on_a_straight_line() {
    let path = Path::straight(400.0, 1.0).unwrap();
    for dir in [Direction::Forward, Direction::Backward] {
        for alpha in [0.0, 0.5, 1.0] {
            assert_converges(&path, dir, alpha, 100.0);
        }
    }
}

#[test]
fn converges_from_4m_offset_on_a_circle() {
    let path = Path::circle(50.0, 1e-3).unwrap();
    for dir in [Direction::Forward, Direction::Backward] {
        for alpha in [0.0, 0.5, 1.0] {
            assert_converges(&path, dir, alpha, 120.0);
        }
    }
}

#[test]
fn starts_on_the_left_converge_too() {
    // Mirror image: offset to the right of the path.
    let path = Path::straight(300.0, 1.0).unwrap();
    let cfg = ControllerConfig::default();
    let opts = SimOptions {
        duration_s: 60.0,
        initial_offset_m: -4.0,
        ..Default::default()
    };
    let tr = run(path, cfg, opts);
    assert!(tail_mean_abs(&tr.lateral_error_m, 500) < 0.05);
    assert!(tr.lateral_error_m[0] < -3.9);
}

#[test]
fn moving_control_point_stays_on_the_path() {
    let cfg = ControllerConfig::default();
    let track = Arc::new(Track::new(Path::test_track(1.0).unwrap(), &cfg));
    let sched = AlphaSchedule::Sine { omega_rad_s: 0.2 };
    let opts = SimOptions {
        duration_s: 200.0,
        ..Default::default()
    };
    let tr = sim(&track, &cfg, &sched, &opts).unwrap();
    let amin = tr.alpha.iter().cloned().fold(1.0, f64::min);
    let amax = tr.alpha.iter().cloned().fold(0.0, f64::max);
    assert!(
        amin < 0.01 && amax > 0.99,
        "alpha sweeps [0, 1]: [{amin}, {amax}]"
    );
    let max_err = tr
        .lateral_error_m
        .iter()
        .skip(500)
        .fold(0.0f64, |m, e| m.max(e.abs()));
    assert!(max_err < 0.2, "moving control point: max |e| = {max_err}");
}

#[test]
fn curvature_slows_the_vehicle_down() {
    // On the test track at a high preferred speed, the ray cast makes the
    // vehicle slower in the R = 25 m arc than on the straights.
    let cfg = ControllerConfig {
        preferred_speed: 15.0,
        path_width_m: 6.0,
        ..Default::default()
    };
    let track = Arc::new(Track::new(Path::test_track(1.0).unwrap(), &cfg));
    let sched = AlphaSchedule::Constant { alpha: 0.5 };
    let opts = SimOptions {
        duration_s: 300.0,
        initial_speed_mps: 0.0,
        ..Default::default()
    };
    let tr = sim(&track, &cfg, &sched, &opts).unwrap();
    let mut v_curve = Vec::new();
    let mut v_straight = Vec::new();
    for i in 3000..tr.len() {
        let k = tr.curvature_per_m[i].abs();
        if k > 0.035 {
            v_curve.push(tr.v_mps[i]);
        } else if k < 1e-4 {
            v_straight.push(tr.v_mps[i]);
        }
    }
    let vc = v_curve.iter().sum::<f64>() / v_curve.len() as f64;
    let vmax_straight = v_straight.iter().cloned().fold(0.0, f64::max);
    assert!(!v_curve.is_empty() && !v_straight.is_empty());
    assert!(
        vc < 0.8 * vmax_straight,
        "curve {vc} m/s vs straight max {vmax_straight} m/s"
    );
    // And lateral acceleration in the tight arc stays bounded.
    let lat_acc = (0..tr.len())
        .map(|i| tr.v_mps[i].powi(2) * tr.delta_rad[i].tan() / 2.6)
        .fold(0.0f64, |m, a| m.max(a.abs()));
    assert!(lat_acc < 4.0, "max lateral acceleration {lat_acc}");
}

#[test]
fn noise_and_delay_runs_are_reproducible_and_stay_close() {
    let cfg = ControllerConfig::default();
    let track = Arc::new(Track::new(Path::test_track(1.0).unwrap(), &cfg));
    let sched = AlphaSchedule::Constant { alpha: 0.5 };
    let opts = SimOptions {
        duration_s: 120.0,
        noise: NoiseModel::Uniform {
            position_m: 0.05,
            heading_deg: 0.5,
        },
        delay_s: 0.1,
        seed: 42,
        ..Default::default()
    };
    let a = sim(&track, &cfg, &sched, &opts).unwrap();
    let b = sim(&track, &cfg, &sched, &opts).unwrap();
    assert_eq!(a, b, "same seed, same run");
    let c = sim(&track, &cfg, &sched, &SimOptions { seed: 43, ..opts }).unwrap();
    assert_ne!(a.x_m, c.x_m);
    assert!(tail_mean_abs(&a.lateral_error_m, 5000) < 0.15);
}

#[test]
fn laps_and_open_path_end_stop_the_run() {
    let cfg = ControllerConfig::default();
    let path = Path::circle(20.0, 1e-3).unwrap();
    let len = path.length();
    let tr = run(
        path,
        cfg.clone(),
        SimOptions {
            duration_s: 1e4,
            laps: Some(1.0),
            fixed_speed_mps: Some(3.0),
            ..Default::default()
        },
    );
    let d = *tr.distance_m.last().unwrap();
    assert!(d >= len && d < len + 0.1, "one lap: {d} vs {len}");
    let tr = run(
        Path::straight(50.0, 1.0).unwrap(),
        cfg,
        SimOptions {
            duration_s: 1e4,
            fixed_speed_mps: Some(3.0),
            ..Default::default()
        },
    );
    assert!(
        *tr.t_s.last().unwrap() < 20.0,
        "stops at the end of an open path"
    );
}

#[test]
fn bad_sim_options_are_errors() {
    let cfg = ControllerConfig::default();
    let track = Arc::new(Track::new(Path::straight(10.0, 1.0).unwrap(), &cfg));
    let sched = AlphaSchedule::Constant { alpha: 0.5 };
    for opts in [
        SimOptions {
            dt_s: -0.01,
            ..Default::default()
        },
        SimOptions {
            dt_s: f64::NAN,
            ..Default::default()
        },
        SimOptions {
            duration_s: 0.0,
            ..Default::default()
        },
        SimOptions {
            delay_s: -1.0,
            ..Default::default()
        },
        SimOptions {
            initial_offset_m: f64::INFINITY,
            ..Default::default()
        },
        SimOptions {
            noise: NoiseModel::Uniform {
                position_m: -1.0,
                heading_deg: 0.0,
            },
            ..Default::default()
        },
    ] {
        let e = sim(&track, &cfg, &sched, &opts).unwrap_err();
        assert!(
            matches!(e, Error::State(StateError::Parameter { .. })),
            "{e}"
        );
    }
    let e = sim(
        &track,
        &cfg,
        &AlphaSchedule::Constant { alpha: 2.0 },
        &SimOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("alpha"), "{e}");
    let bad = ControllerConfig {
        lat_blend_factor: -0.1,
        ..Default::default()
    };
    let e = sim(&track, &bad, &sched, &SimOptions::default()).unwrap_err();
    assert!(e.to_string().contains("lat_blend_factor"), "{e}");
}

#[test]
fn curve_with_ray_takes_the_faster_of_the_ray_and_the_curve_speed_on_a_circle() {
    // On a circle of radius R in a corridor of half width w the ray from the
    // rear axle along the heading leaves the corridor sqrt(2 R w + w^2)
    // ahead, and the stopping law for it settles where
    // v tau + v^2 / (-2 b_f) = d (tau = 1 s, b_f = -4: v^2 / 8 + v = d);
    // the curve speed is sqrt(a_y R). With `curve_with_ray` the steady speed
    // is the larger of the two, from either side of the crossover.
    let (r, w) = (200.0_f64, 1.75_f64);
    let d = (2.0 * r * w + w * w).sqrt();
    let v_ray = -4.0 + (16.0 + 8.0 * d).sqrt(); // 11.2 m/s
    let steady = |a_y: f64, with_ray: bool| {
        let cfg = ControllerConfig {
            preferred_speed: 30.0,
            path_width_m: 2.0 * w,
            curve_lateral_accel: a_y,
            curve_with_ray: with_ray,
            ..Default::default()
        };
        let opts = SimOptions {
            duration_s: 120.0,
            initial_speed_mps: 5.0,
            ..Default::default()
        };
        let tr = run(Path::circle(r, 1e-4).unwrap(), cfg, opts);
        tail_mean(&tr.v_mps, 1000)
    };
    // The paper's law alone, and the curve speeds alone, are the closed forms.
    let lane = steady(0.0, false);
    assert!(
        (lane - v_ray).abs() < 0.02 * v_ray,
        "ray only: {lane} vs {v_ray}"
    );
    for (a_y, expected) in [(2.0, (2.0 * r).sqrt()), (0.3, v_ray)] {
        let both = steady(a_y, true);
        assert!(
            (both - expected).abs() < 0.02 * expected,
            "a_y = {a_y}: {both} vs {expected}"
        );
    }
    // Below the crossover the ray's speed is the one kept: the curve speed
    // alone would be slower.
    let arc_only = steady(0.3, false);
    assert!(
        (arc_only - (0.3 * r).sqrt()).abs() < 0.02 * (0.3 * r).sqrt(),
        "{arc_only}"
    );
}
