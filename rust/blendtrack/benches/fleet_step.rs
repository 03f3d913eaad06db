//! `Fleet::step` with 10,000 vehicles (issue 19 target: 1.5 ms per step),
//! the Rust side of `scripts/bench_fleet.py`: the vehicles spread evenly
//! over the built-in test track (1 m spacing), 0.3 m left of it, at 3 m/s,
//! default configuration, each step integrating the next state over
//! dt = 0.1 s and feeding it back as the next step's input.
//!
//! Run: `cargo bench -p blendtrack --bench fleet_step`. `threads_default`
//! splits the step over rayon's global pool (one thread per core, as the
//! Python module does), `threads_1` stays on the calling thread.

use blendtrack::FleetInputs;
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::time::Duration;

#[path = "common/fleet_setup.rs"]
mod fleet_setup;

const VEHICLES: usize = 10_000;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("fleet_step");
    g.sample_size(30).measurement_time(Duration::from_secs(5));
    for (name, threads) in [("threads_default", 0), ("threads_1", 1)] {
        let (mut fleet, slots, (mut x, mut y, mut theta, mut v, mut delta)) =
            fleet_setup::test_track_fleet(VEHICLES, threads);
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut inp = FleetInputs::new(&slots, &x, &y, &theta, &v, &delta);
                inp.dt_s = Some(0.1);
                let out = fleet.step(black_box(&inp)).unwrap();
                let next = out.next.expect("dt given");
                (x, y, theta, v, delta) = fleet_setup::columns(next);
                black_box(out.steering_rad)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
