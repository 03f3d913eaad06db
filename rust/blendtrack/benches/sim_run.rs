//! Whole closed-loop run (issue #3 target: a 10-minute simulated run at
//! dt = 0.01 s in under 100 ms): 600 s = 60,000 steps on the built-in test
//! track, blended command with alpha = 0.5, longitudinal law on, metrics
//! included. Run: `cargo bench -p blendtrack --bench sim_run`.

use blendtrack::{
    simulate, trace_metrics, AlphaSchedule, ControllerConfig, Path, SimOptions, Track,
    VehicleParams,
};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

fn sim_run(c: &mut Criterion) {
    let cfg = ControllerConfig {
        preferred_speed: 10.0,
        ..Default::default()
    };
    let track = Arc::new(Track::new(
        Path::test_track(1.0).expect("built-in track"),
        &cfg,
    ));
    let params = VehicleParams::default();
    let schedule = AlphaSchedule::Constant { alpha: 0.5 };
    let opts = SimOptions {
        dt_s: 0.01,
        duration_s: 600.0,
        initial_offset_m: 4.0,
        ..Default::default()
    };
    let mut g = c.benchmark_group("sim_run");
    g.sample_size(20).measurement_time(Duration::from_secs(10));
    g.bench_function("test_track_600s_dt0.01", |b| {
        b.iter(|| {
            let trace =
                simulate(track.clone(), &cfg, &params, &schedule, &opts).expect("valid run");
            assert_eq!(trace.len(), 60_000);
            black_box(trace_metrics(&trace, params.wheelbase_m))
        })
    });
    g.finish();
}

criterion_group!(benches, sim_run);
criterion_main!(benches);
