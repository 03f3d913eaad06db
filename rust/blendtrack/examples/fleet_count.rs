//! A fixed number of `Fleet::step`s of the `fleet_step` bench's fleet, on
//! the calling thread, for an instruction count that does not depend on
//! the machine's load:
//!
//! ```text
//! cargo build --profile bench -p blendtrack --example fleet_count
//! valgrind --tool=callgrind target/release/examples/fleet_count 10000 5
//! valgrind --tool=callgrind target/release/examples/fleet_count 10000 10
//! ```
//!
//! The difference of the two totals over 5 x 10,000 is one vehicle-step
//! (the set-up cancels). The vehicles are the bench's
//! (`benches/fleet_step.rs`): the test track, 0.3 m left of it, 3 m/s,
//! dt 0.1 s, each step's next state fed back. It prints a hash of every
//! output's bits (equal before and after a change meant only for speed).

use blendtrack::FleetInputs;

#[path = "../benches/common/fleet_setup.rs"]
mod fleet_setup;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let steps: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(5);
    let (mut fleet, slots, (mut x, mut y, mut theta, mut v, mut delta)) =
        fleet_setup::test_track_fleet(n, 1);
    let mut hash: u64 = 0;
    let mut mix = |col: &[f64]| {
        for v in col {
            hash = (hash.rotate_left(7) ^ v.to_bits()).wrapping_mul(0x100_0000_01b3);
        }
    };
    for _ in 0..steps {
        let mut inp = FleetInputs::new(&slots, &x, &y, &theta, &v, &delta);
        inp.dt_s = Some(0.1);
        let out = match fleet.step(&inp) {
            Ok(o) => o,
            Err(e) => {
                eprintln!("fleet_count: {e}");
                std::process::exit(2);
            }
        };
        for col in [
            &out.steering_rad,
            &out.accel_mps2,
            &out.alpha,
            &out.lateral_error_m,
            &out.heading_error_rad,
            &out.s_m,
            &out.s_rear_m,
            &out.lateral_error_rear_m,
            &out.lateral_error_front_m,
            &out.curvature_per_m,
            &out.virtual_obstacle_m,
        ] {
            mix(col);
        }
        let next = out.next.expect("dt given");
        for col in [
            &next.x_m,
            &next.y_m,
            &next.theta_rad,
            &next.v_mps,
            &next.delta_rad,
        ] {
            mix(col);
        }
        if !out.ok.iter().all(|&ok| ok) {
            eprintln!("fleet_count: a vehicle's step failed");
            std::process::exit(2);
        }
        (x, y, theta, v, delta) = fleet_setup::columns(next);
    }
    println!("{n} vehicles, {steps} steps, output hash {hash:016x}");
}
