//! A fixed number of controller steps on the Nurburgring, for an
//! instruction count that does not depend on the machine's load:
//!
//! ```text
//! cargo build --release -p blendtrack --example step_count
//! valgrind --tool=callgrind target/release/examples/step_count blend 20000
//! valgrind --tool=callgrind target/release/examples/step_count blend 40000
//! ```
//!
//! The difference of the two totals over 20,000 is the cost of one step
//! (the track's loading cancels). The states are those of the
//! `controller_step` bench: 0.3 m apart, 0.5 m off the centreline.

use blendtrack::*;
use std::hint::black_box;
use std::path::PathBuf;
use std::sync::Arc;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = match args.get(1).map(String::as_str) {
        Some("stanley") => LateralKind::Stanley,
        Some("pure_pursuit") => LateralKind::PurePursuit,
        _ => LateralKind::Blend,
    };
    let steps: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(20_000);
    let file =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/tracks/Nuerburgring.csv");
    let path = match Path::from_tum_csv(&file, true) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("step_count: {e}");
            std::process::exit(2);
        }
    };
    let n = (path.length() / 0.3) as usize;
    let states: Vec<VehicleState> = (0..n)
        .map(|i| {
            let s = i as f64 * 0.3;
            let c = path.point_at(s);
            let h = path.heading_at(s);
            VehicleState {
                x_m: c.x - 0.5 * h.sin(),
                y_m: c.y + 0.5 * h.cos(),
                theta_rad: h + 0.02,
                v_mps: 30.0,
                delta_rad: 0.0,
            }
        })
        .collect();
    let cfg = ControllerConfig {
        lateral_controller: kind,
        preferred_speed: 30.0,
        ray_horizon_m: 200.0,
        ..Default::default()
    };
    let track = Arc::new(Track::new(path, &cfg));
    let mut ctrl = match Controller::new(track, cfg, &VehicleParams::default()) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("step_count: {e}");
            std::process::exit(2);
        }
    };
    let mut hash: u64 = 0;
    for i in 0..steps {
        let j = i % states.len();
        if j == 0 {
            ctrl.reset();
        }
        match ctrl.step_with_alpha(black_box(&states[j]), 0.5, &[]) {
            Ok(out) => {
                for v in [
                    out.steering_rad,
                    out.accel_mps2,
                    out.alpha,
                    out.steering_front_rad,
                    out.steering_rear_rad,
                    out.s_rear_m,
                    out.lateral_error_rear_m,
                    out.lateral_error_front_m,
                    out.s_m,
                    out.lateral_error_m,
                    out.heading_error_rad,
                    out.curvature_per_m,
                    out.virtual_obstacle_m,
                ] {
                    hash = (hash.rotate_left(7) ^ v.to_bits()).wrapping_mul(0x100_0000_01b3);
                }
            }
            Err(e) => {
                eprintln!("step_count: {e}");
                std::process::exit(2);
            }
        }
    }
    // A hash of every output's bits: equal before and after a speed-only change.
    println!("{steps} steps, output hash {hash:016x}");
}
