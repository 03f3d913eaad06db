//! Property tests: for any finite state and valid path every controller
//! returns a finite, bounded command and never panics; invalid paths,
//! configurations and states are errors, not panics.

mod common;

use blendtrack::*;
use proptest::prelude::*;
use std::sync::Arc;

fn any_path() -> impl Strategy<Value = Path> {
    prop_oneof![
        (1.0f64..500.0).prop_map(|l| Path::straight(l, 1.0).unwrap()),
        (3.0f64..300.0).prop_map(|r| Path::circle(r, 0.01).unwrap()),
        Just(Path::test_track(2.0).unwrap()),
        // Random polylines, possibly with sharp corners and reversals.
        (
            prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0), 2..40),
            any::<bool>()
        )
            .prop_filter_map("degenerate", |(pts, closed)| {
                let pts: Vec<[f64; 2]> = pts.into_iter().map(|(x, y)| [x, y]).collect();
                Path::new(&pts, None, closed).ok()
            }),
    ]
}

fn any_state() -> impl Strategy<Value = VehicleState> {
    (
        -1e3f64..1e3,
        -1e3f64..1e3,
        -10.0f64..10.0,
        -40.0f64..40.0,
        -1.0f64..1.0,
    )
        .prop_map(common::state_of)
}

fn any_config() -> impl Strategy<Value = ControllerConfig> {
    (
        0.0f64..=1.0,
        prop_oneof![Just(Direction::Forward), Just(Direction::Backward)],
        prop_oneof![
            Just(LateralKind::Blend),
            Just(LateralKind::Stanley),
            Just(LateralKind::PurePursuit)
        ],
        0.1f64..40.0,
        0.5f64..30.0,
    )
        .prop_map(|(alpha, direction, kind, v0, width)| ControllerConfig {
            lat_blend_factor: alpha,
            direction,
            lateral_controller: kind,
            preferred_speed: v0,
            path_width_m: width,
            ..Default::default()
        })
}

/// 400 cases (what CI runs), or `PROPTEST_CASES` when it is set: a long run
/// outside CI raises the count with the environment variable.
fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(400)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), .. ProptestConfig::default() })]

    #[test]
    fn commands_are_finite_and_bounded(
        path in any_path(),
        cfg in any_config(),
        states in prop::collection::vec(any_state(), 1..6),
        alpha in 0.0f64..=1.0,
        gaps in prop::collection::vec((-5.0f64..200.0, -5.0f64..40.0), 0..3),
    ) {
        let vp = VehicleParams::default();
        let track = Arc::new(Track::new(path, &cfg));
        let mut ctrl = Controller::new(track, cfg, &vp).unwrap();
        let obstacles: Vec<Obstacle> = gaps.into_iter().map(|(g, v)| Obstacle::new(g, v)).collect();
        for st in states {
            let out = ctrl.step_with_alpha(&st, alpha, &obstacles).unwrap();
            prop_assert!(out.steering_rad.is_finite() && out.steering_rad.abs() <= vp.max_steering_rad() + 1e-12);
            prop_assert!(out.accel_mps2.is_finite(), "accel {:?}", out);
            prop_assert!(out.lateral_error_m.is_finite() && out.heading_error_rad.is_finite() && out.s_m.is_finite());
            prop_assert!(out.virtual_obstacle_m >= 0.0, "virtual obstacle {}", out.virtual_obstacle_m);
            let mut veh = Vehicle::new(st, vp, ctrl.config().direction, 2);
            veh.step(Command { steering_rad: out.steering_rad, accel_mps2: out.accel_mps2 }, 0.05);
            prop_assert!(veh.state.check_finite().is_ok());
        }
    }

    #[test]
    fn bad_states_are_errors(field in 0usize..5, bad in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)]) {
        let cfg = ControllerConfig::default();
        let track = Arc::new(Track::new(Path::straight(100.0, 1.0).unwrap(), &cfg));
        let mut ctrl = Controller::new(track, cfg, &VehicleParams::default()).unwrap();
        let mut v = [1.0, 0.5, 0.1, 2.0, 0.0];
        v[field] = bad;
        let st = VehicleState { x_m: v[0], y_m: v[1], theta_rad: v[2], v_mps: v[3], delta_rad: v[4] };
        let e = ctrl.step(&st, &[]).unwrap_err();
        let is_non_finite = matches!(e, StateError::NonFinite { .. });
        prop_assert!(is_non_finite, "{}", e);
        // The controller still works afterwards.
        let recovered = VehicleState { x_m: 1.0, ..Default::default() };
        prop_assert!(ctrl.step(&recovered, &[]).is_ok());
    }

    #[test]
    fn bad_alpha_is_an_error(alpha in prop_oneof![Just(f64::NAN), -10.0f64..-1e-9, 1.0 + 1e-9..10.0]) {
        let cfg = ControllerConfig::default();
        let track = Arc::new(Track::new(Path::straight(100.0, 1.0).unwrap(), &cfg));
        let mut ctrl = Controller::new(track, cfg, &VehicleParams::default()).unwrap();
        prop_assert!(ctrl.step_with_alpha(&VehicleState::default(), alpha, &[]).is_err());
    }

    #[test]
    fn invalid_paths_are_errors(
        pts in prop::collection::vec((prop_oneof![Just(f64::NAN), Just(f64::INFINITY), -10.0f64..10.0], -10.0f64..10.0), 0..8),
        closed in any::<bool>(),
    ) {
        let pts: Vec<[f64; 2]> = pts.into_iter().map(|(x, y)| [x, y]).collect();
        match Path::new(&pts, None, closed) {
            Ok(p) => {
                prop_assert!(pts.iter().all(|q| q[0].is_finite()));
                prop_assert!(p.length() > 0.0 && p.len_points() >= 2);
            }
            Err(e) => {
                let has_bad = pts.iter().any(|q| !q[0].is_finite());
                match e {
                    PathError::NonFinite { .. } => prop_assert!(has_bad),
                    PathError::TooFewPoints(_) => prop_assert!(!has_bad),
                    other => prop_assert!(false, "unexpected error {other}"),
                }
            }
        }
    }

    #[test]
    fn out_of_range_configs_are_errors_naming_the_key(
        which in 0usize..6,
        value in prop_oneof![Just(f64::NAN), Just(-1.0), Just(0.0), Just(2.0), Just(1e300)],
    ) {
        let keys = ["lat_blend_factor", "max_deceleration", "max_obs_deceleration", "reaction_time", "preferred_speed", "path_width_m"];
        let mut c = ControllerConfig::default();
        match which {
            0 => c.lat_blend_factor = value,
            1 => c.max_deceleration = value,
            2 => c.max_obs_deceleration = value,
            3 => c.reaction_time = value,
            4 => c.preferred_speed = value,
            _ => c.path_width_m = value,
        }
        let valid = match which {
            0 => (0.0..=1.0).contains(&value),
            1 | 2 => value < 0.0,
            _ => value > 0.0 && value.is_finite(),
        };
        match c.validate() {
            Ok(()) => prop_assert!(valid),
            Err(e) => {
                prop_assert!(!valid);
                prop_assert!(e.to_string().contains(keys[which]), "{e}");
            }
        }
    }

    #[test]
    fn garbage_toml_is_an_error_naming_the_file_or_a_valid_config(text in ".{0,200}") {
        // Whatever the text, no panic; an accepted config is a valid one (it
        // round-trips through TOML), a refused one says which file it was.
        match Config::from_toml_str(&text, "fuzz.toml") {
            Ok(c) => {
                prop_assert!(c.controller.validate().is_ok());
                let again = Config::from_toml_str(&c.to_toml_string(), "again.toml");
                prop_assert!(again.is_ok(), "{again:?}");
            }
            Err(e) => prop_assert!(e.to_string().contains("fuzz.toml"), "{e}"),
        }
        if let Err(e) = ExperimentSet::from_toml_str(&text, "fuzz.toml") {
            prop_assert!(e.to_string().contains("fuzz.toml") || e.to_string().contains("test["), "{e}");
        }
        match Path::from_tum_str(&text, "fuzz.csv", true) {
            Ok(p) => prop_assert!(p.length().is_finite() && p.length() > 0.0),
            Err(e) => prop_assert!(e.to_string().contains("fuzz.csv"), "{e}"),
        }
    }
}
