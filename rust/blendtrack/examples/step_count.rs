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
//! (the track's loading cancels). The states are the `controller_step`
//! bench's (`benches/common/nurburgring.rs`).

use blendtrack::*;
use std::hint::black_box;
use std::sync::Arc;

#[path = "../benches/common/nurburgring.rs"]
mod nurburgring;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = match args.get(1).map(String::as_str) {
        Some("stanley") => LateralKind::Stanley,
        Some("pure_pursuit") => LateralKind::PurePursuit,
        _ => LateralKind::Blend,
    };
    let steps: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(20_000);
    let path = match Path::from_tum_csv(&nurburgring::track_file(), true) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("step_count: {e}");
            std::process::exit(2);
        }
    };
    let states = nurburgring::states_along(&path, 0.3);
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
