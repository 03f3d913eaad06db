//! `Fleet::step` with 10,000 vehicles (issue 19 target: 1.5 ms per step),
//! the Rust side of `scripts/bench_fleet.py`: the vehicles spread evenly
//! over the built-in test track (1 m spacing), 0.3 m left of it, at 3 m/s,
//! default configuration, each step integrating the next state over
//! dt = 0.1 s and feeding it back as the next step's input.
//!
//! Run: `cargo bench -p blendtrack --bench fleet_step`. `threads_default`
//! splits the step over rayon's global pool (one thread per core, as the
//! Python module does), `threads_1` stays on the calling thread.

use blendtrack::{ControllerConfig, Fleet, FleetInputs, Path};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::time::Duration;

const VEHICLES: usize = 10_000;

fn bench(c: &mut Criterion) {
    let path = Path::test_track(1.0).expect("built-in track");
    let mut g = c.benchmark_group("fleet_step");
    g.sample_size(30).measurement_time(Duration::from_secs(5));
    for (name, threads) in [("threads_default", 0), ("threads_1", 1)] {
        let mut fleet = Fleet::new();
        fleet.set_threads(threads);
        let track = fleet
            .add_track(path.clone(), ControllerConfig::default())
            .unwrap() as i64;
        let slots: Vec<i64> = (0..VEHICLES)
            .map(|_| fleet.add_vehicle(track, None, None).unwrap() as i64)
            .collect();
        let (mut x, mut y, mut theta) = (vec![], vec![], vec![]);
        for i in 0..VEHICLES {
            let s = path.length() * i as f64 / VEHICLES as f64;
            let (p, h) = (path.point_at(s), path.heading_at(s));
            x.push(p.x - 0.3 * h.sin());
            y.push(p.y + 0.3 * h.cos());
            theta.push(h);
        }
        let (mut v, mut delta) = (vec![3.0; VEHICLES], vec![0.0; VEHICLES]);
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut inp = FleetInputs::new(&slots, &x, &y, &theta, &v, &delta);
                inp.dt_s = Some(0.1);
                let out = fleet.step(black_box(&inp)).unwrap();
                let next = out.next.expect("dt given");
                (x, y, theta, v, delta) = (
                    next.x_m,
                    next.y_m,
                    next.theta_rad,
                    next.v_mps,
                    next.delta_rad,
                );
                black_box(out.steering_rad)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
