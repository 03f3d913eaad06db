//! One full controller step (hinted projections + blended lateral law + ray
//! cast + longitudinal law) on the Nurburgring (../shared/tracks), per vehicle.
//!
//! Run: `cargo bench -p blendtrack --bench controller_step`. The states walk
//! along the track 0.3 m apart (a vehicle at 30 m/s sampled at 100 Hz), 0.5 m
//! off the centreline with a small heading error, so the hints behave as in
//! a real run. The reported time is for one step.

use blendtrack::*;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use std::sync::Arc;

#[path = "common/nurburgring.rs"]
mod nurburgring;

fn bench(c: &mut Criterion) {
    let path = Path::from_tum_csv(&nurburgring::track_file(), true)
        .expect("../shared/tracks/Nuerburgring.csv beside the repo");
    let vp = VehicleParams::default();
    let states = nurburgring::states_along(&path, 0.3);
    let mut group = c.benchmark_group("controller_step");
    group.throughput(Throughput::Elements(1));
    for (name, kind, horizon) in [
        ("blend_nuerburgring", LateralKind::Blend, 200.0),
        ("stanley_nuerburgring", LateralKind::Stanley, 200.0),
        ("pure_pursuit_nuerburgring", LateralKind::PurePursuit, 200.0),
    ] {
        let cfg = ControllerConfig {
            lateral_controller: kind,
            preferred_speed: 30.0,
            ray_horizon_m: horizon,
            ..Default::default()
        };
        let track = Arc::new(Track::new(path.clone(), &cfg));
        let mut ctrl = Controller::new(track, cfg, &vp).unwrap();
        let mut i = 0usize;
        group.bench_function(name, |b| {
            b.iter(|| {
                let st = &states[i];
                i = (i + 1) % states.len();
                if i == 0 {
                    ctrl.reset();
                }
                black_box(ctrl.step_with_alpha(black_box(st), 0.5, &[]).unwrap())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
