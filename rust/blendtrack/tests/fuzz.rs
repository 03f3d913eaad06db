//! Fuzzing with proptest of what reads user input: the TUM csv parser, the
//! TOML config loader and one controller step. Inputs are built from
//! hostile pieces (huge, tiny, NaN and infinite numbers, wrong types, junk
//! text) rather than uniform noise, so most cases get past the first check.
//!
//! Each property: no panic, and an `Ok` is a usable value (a path of finite
//! positive length, a config that validates, a finite bounded command). CI
//! runs 256 cases each; `PROPTEST_CASES=1000000` runs a long campaign.

mod common;

use blendtrack::*;
use proptest::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256)
}

/// Counts the cases of one property and, in a long run (more than 100,000
/// cases), prints the count every 100,000 to stderr (`--nocapture`), so an
/// interrupted campaign still says how far it got.
fn tick(counter: &AtomicU64, name: &str) {
    let n = counter.fetch_add(1, Ordering::Relaxed) + 1;
    if cases() > 100_000 && n % 100_000 == 0 {
        eprintln!("fuzz {name}: {n} cases");
    }
}

static TUM_CASES: AtomicU64 = AtomicU64::new(0);
static TOML_CASES: AtomicU64 = AtomicU64::new(0);
static STEP_CASES: AtomicU64 = AtomicU64::new(0);

/// A number as a user or a broken export might write it.
fn number_text() -> impl Strategy<Value = String> {
    prop_oneof![
        (-1e4f64..1e4).prop_map(|v| format!("{v}")),
        (-1e4f64..1e4).prop_map(|v| format!("{v:e}")),
        any::<f64>().prop_map(|v| format!("{v}")),
        (-1000i64..1000).prop_map(|v| v.to_string()),
        prop::sample::select(vec![
            "nan",
            "NaN",
            "inf",
            "-inf",
            "1e308",
            "-1e308",
            "1e309",
            "1e-320",
            "-0",
            "0",
            "1e9",
            "1.0000001e9",
            "",
            " ",
            "x",
            "1,5",
            "0x10",
            "1e",
            "--1",
            "+3",
            ".5",
            "5.",
        ])
        .prop_map(String::from),
    ]
}

fn tum_text() -> impl Strategy<Value = String> {
    let row = prop::collection::vec(number_text(), 0..6).prop_map(|f| f.join(","));
    let line = prop_oneof![
        6 => row,
        1 => Just("# x_m,y_m,w_tr_right_m,w_tr_left_m".to_string()),
        1 => ".{0,20}".prop_map(|s| s),
        1 => Just(String::new()),
    ];
    prop::collection::vec(line, 0..40).prop_map(|l| l.join("\n"))
}

fn toml_value() -> impl Strategy<Value = String> {
    prop_oneof![
        number_text(),
        any::<i64>().prop_map(|v| v.to_string()),
        Just("99999999999999999999999".to_string()),
        prop::sample::select(vec![
            "true",
            "false",
            "\"blend\"",
            "\"stanley\"",
            "\"pure_pursuit\"",
            "\"backward\"",
            "\"forward\"",
            "\"\"",
            "[]",
            "[1, 2]",
            "{}",
            "nan",
            "+inf",
            "-inf",
            "1e400",
        ])
        .prop_map(String::from),
    ]
}

fn toml_text() -> impl Strategy<Value = String> {
    let controller_keys = ControllerConfig::default();
    let keys: Vec<String> = toml::Table::try_from(&controller_keys)
        .unwrap()
        .keys()
        .cloned()
        .chain(
            toml::Table::try_from(VehicleParams::default())
                .unwrap()
                .keys()
                .cloned(),
        )
        .chain(["x", "alpha", "", "controller"].map(String::from))
        .collect();
    let entry = (prop::sample::select(keys), toml_value()).prop_map(|(k, v)| format!("{k} = {v}"));
    let line = prop_oneof![
        6 => entry,
        1 => prop::sample::select(vec!["[controller]", "[vehicle]", "[other]", "[[test]]", "[controller.x]"])
            .prop_map(String::from),
        1 => ".{0,20}".prop_map(|s| s),
    ];
    prop::collection::vec(line, 0..30).prop_map(|l| l.join("\n"))
}

/// A few paths, built once: building one per case would dominate the run.
fn paths() -> &'static [Path] {
    static PATHS: OnceLock<Vec<Path>> = OnceLock::new();
    PATHS.get_or_init(|| {
        vec![
            Path::straight(200.0, 1.0).unwrap(),
            Path::circle(20.0, 0.01).unwrap(),
            Path::test_track(2.0).unwrap(),
            Path::new(
                &[
                    [0.0, 0.0],
                    [1e-6, 0.0],
                    [10.0, 0.0],
                    [10.0, 1e-9],
                    [0.0, 0.0],
                ],
                None,
                false,
            )
            .unwrap(),
            Path::new(
                &[[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.0, 5.0]],
                None,
                true,
            )
            .unwrap(),
            Path::new(&[[-1e9, -1e9], [1e9, 1e9]], None, false).unwrap(),
        ]
    })
}

/// A state coordinate: ordinary, far, tiny, or an extreme finite value.
fn coordinate() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -300.0f64..300.0,
        1 => -2e9f64..2e9,
        1 => prop::sample::select(vec![0.0, -0.0, 1e-300, f64::MIN_POSITIVE, 1e9, -1e9, 1e15, 1e308, -1e308, f64::MAX]),
        1 => any::<f64>(),
    ]
}

fn state() -> impl Strategy<Value = VehicleState> {
    (
        coordinate(),
        coordinate(),
        prop_oneof![-10.0f64..10.0, any::<f64>()],
        prop_oneof![-60.0f64..60.0, any::<f64>()],
        prop_oneof![-1.5f64..1.5, any::<f64>()],
    )
        .prop_map(common::state_of)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, .. ProptestConfig::default() })]

    #[test]
    fn tum_csv_parser_never_panics(text in tum_text(), closed in any::<bool>()) {
        tick(&TUM_CASES, "tum_csv");
        match Path::from_tum_str(&text, "fuzz.csv", closed) {
            Ok(p) => {
                prop_assert!(p.len_points() >= 2);
                prop_assert!(p.length().is_finite() && p.length() > 0.0, "length {}", p.length());
                prop_assert!(p.points().iter().all(|q| q.x.abs() <= 1e9 && q.y.abs() <= 1e9));
            }
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    #[test]
    fn toml_config_loader_never_panics(text in toml_text()) {
        tick(&TOML_CASES, "toml_config");
        match Config::from_toml_str(&text, "fuzz.toml") {
            Ok(c) => prop_assert!(c.validate().is_ok()),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    #[test]
    fn controller_step_is_finite_or_an_error(
        which in 0usize..6,
        kind in prop::sample::select(vec![LateralKind::Blend, LateralKind::Stanley, LateralKind::PurePursuit]),
        backward in any::<bool>(),
        states in prop::collection::vec(state(), 1..4),
        alpha in prop_oneof![0.0f64..=1.0, any::<f64>()],
        gap in prop_oneof![-10.0f64..500.0, any::<f64>()],
    ) {
        tick(&STEP_CASES, "controller_step");
        let cfg = ControllerConfig {
            lateral_controller: kind,
            direction: if backward { Direction::Backward } else { Direction::Forward },
            ..Default::default()
        };
        let vp = VehicleParams::default();
        let track = Arc::new(Track::new(paths()[which].clone(), &cfg));
        let mut ctrl = Controller::new(track, cfg, &vp).unwrap();
        let obstacles = [Obstacle::new(gap, 0.0)];
        for st in states {
            if let Ok(out) = ctrl.step_with_alpha(&st, alpha, &obstacles) {
                prop_assert!(st.check_finite().is_ok() && (0.0..=1.0).contains(&alpha));
                prop_assert!(out.steering_rad.is_finite() && out.steering_rad.abs() <= vp.max_steering_rad() + 1e-12, "{:?} -> {:?}", st, out);
                prop_assert!(out.accel_mps2.is_finite(), "{:?} -> {:?}", st, out);
                prop_assert!(out.lateral_error_m.is_finite() && out.s_m.is_finite(), "{:?} -> {:?}", st, out);
            }
        }
    }
}
