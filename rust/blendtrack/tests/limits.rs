//! Size limits: input that would make the core allocate without bound is an
//! error naming the value and the limit, checked before allocating.

use blendtrack::limits::{MAX_PATH_POINTS, MAX_SIM_STEPS};
use blendtrack::*;
use std::sync::Arc;

fn sim(opts: SimOptions) -> Result<Trace, Error> {
    let cfg = ControllerConfig::default();
    let track = Arc::new(Track::new(Path::circle(20.0, 0.01).unwrap(), &cfg));
    simulate(
        track,
        &cfg,
        &VehicleParams::default(),
        &AlphaSchedule::Constant { alpha: 0.5 },
        &opts,
    )
}

fn too_large(e: Error) -> (&'static str, String) {
    match e {
        Error::State(StateError::TooLarge { name, .. }) => (name, e.to_string()),
        other => panic!("expected TooLarge, got {other}"),
    }
}

#[test]
fn step_counts_beyond_the_limit_are_errors_naming_the_value() {
    let limit = MAX_SIM_STEPS.to_string();
    for (opts, name) in [
        (
            SimOptions {
                duration_s: 1e8,
                ..Default::default()
            },
            "duration_s",
        ),
        (
            SimOptions {
                dt_s: 1e-300,
                ..Default::default()
            },
            "duration_s",
        ),
        (
            SimOptions {
                delay_s: 1e9,
                ..Default::default()
            },
            "delay_s",
        ),
        (
            SimOptions {
                duration_s: 1e9,
                laps: Some(1e6),
                ..Default::default()
            },
            "laps",
        ),
    ] {
        let (got, text) = too_large(sim(opts).unwrap_err());
        assert_eq!(got, name, "{text}");
        assert!(text.contains(&limit), "{text}");
    }
    // Exactly at the limit is allowed (checked without running it).
    let at_limit = SimOptions {
        duration_s: MAX_SIM_STEPS as f64 * 0.01,
        delay_s: 1.0,
        ..Default::default()
    };
    assert!(at_limit.validate().is_ok());
}

#[test]
fn laps_within_the_limit_run_under_an_unbounded_duration() {
    // The duration allows 1e11 steps; one lap of 125.7 m needs ~4,000 at
    // 3 m/s: it runs, stops at the lap, and allocates for what it ran.
    let t = sim(SimOptions {
        duration_s: 1e9,
        laps: Some(1.0),
        initial_speed_mps: 3.0,
        ..Default::default()
    })
    .unwrap();
    let lap = 2.0 * std::f64::consts::PI * 20.0;
    assert!(
        *t.distance_m.last().unwrap() >= lap * 0.999,
        "{}",
        t.distance_m.last().unwrap()
    );
    assert!(t.len() < 20_000, "{}", t.len());
}

#[test]
fn a_long_delay_line_fills_as_it_runs() {
    // A delay of 2^40 steps allocates nothing up front: the vehicle holds
    // its steering and gets no acceleration, step after step.
    let state = VehicleState {
        v_mps: 2.0,
        delta_rad: 0.1,
        ..Default::default()
    };
    let mut veh = Vehicle::new(state, VehicleParams::default(), Direction::Forward, 1 << 40);
    for _ in 0..100 {
        veh.step(
            Command {
                steering_rad: -0.5,
                accel_mps2: 3.0,
            },
            0.01,
        );
        assert_eq!(veh.state.delta_rad, 0.1);
        assert_eq!(veh.state.v_mps, 2.0);
    }
    // A short delay still hands the commands on in order after the hold.
    let mut veh = Vehicle::new(state, VehicleParams::default(), Direction::Forward, 2);
    let rate = VehicleParams::default().max_steering_rate_rad_s() * 0.01;
    let mut deltas = vec![];
    for k in 0..4 {
        veh.step(
            Command {
                steering_rad: if k == 0 { 1.0 } else { -1.0 },
                accel_mps2: 0.0,
            },
            0.01,
        );
        deltas.push(veh.state.delta_rad);
    }
    assert_eq!(deltas[0], 0.1);
    assert_eq!(deltas[1], 0.1);
    assert!((deltas[2] - (0.1 + rate)).abs() < 1e-15, "{deltas:?}");
    assert!((deltas[3] - 0.1).abs() < 1e-15, "{deltas:?}");
}

#[test]
fn generators_beyond_the_point_limit_are_errors() {
    for r in [
        Path::straight(1e300, 1.0),
        Path::straight(1e7, 1e-3),
        Path::test_track(1e-6),
    ] {
        match r {
            Err(PathError::TooManyPoints { limit, .. }) => assert_eq!(limit, MAX_PATH_POINTS),
            other => panic!("expected TooManyPoints, got {other:?}"),
        }
    }
    assert!(Path::straight(1e6, 1.0).is_ok());
}

#[test]
fn coordinates_too_far_out_to_resolve_metres_are_refused() {
    // At 1e300 a 4 m offset rounds away: such a path or state is an error,
    // not a run reporting 0 error.
    let e = Path::straight(100.0, 1.0)
        .unwrap()
        .scaled(1e300)
        .unwrap_err();
    assert!(matches!(e, PathError::TooFar { .. }), "{e}");
    assert!(Path::new(&[[0.0, 0.0], [1e9, 0.0]], None, false).is_ok());
    assert!(matches!(
        Path::new(&[[0.0, 0.0], [1.0000001e9, 0.0]], None, false),
        Err(PathError::TooFar { .. })
    ));
    let cfg = ControllerConfig::default();
    let track = Arc::new(Track::new(Path::straight(100.0, 1.0).unwrap(), &cfg));
    let mut ctrl = Controller::new(track, cfg, &VehicleParams::default()).unwrap();
    let far = VehicleState {
        x_m: 1e308,
        ..Default::default()
    };
    let e = ctrl.step(&far, &[]).unwrap_err();
    assert!(e.to_string().contains("x_m"), "{e}");
    assert!(ctrl.step(&VehicleState::default(), &[]).is_ok());
}
