//! Cost of the geometric building blocks of a controller step on the Nurburgring:
//! hinted projection, curvature, heading lookup, ray cast (`cargo bench --bench geometry`).
use blendtrack::*;
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Point2;
use std::hint::black_box;

#[path = "common/nurburgring.rs"]
mod nurburgring;

fn bench(c: &mut Criterion) {
    let path = Path::from_tum_csv(&nurburgring::track_file(), true).unwrap();
    let cfg = ControllerConfig::default();
    let cor = Corridor::new(&path, &cfg);
    let n = (path.length() / 0.3) as usize;
    let pts: Vec<(Point2<f64>, f64, f64)> = (0..n)
        .map(|i| {
            let s = i as f64 * 0.3;
            let c = path.point_at(s);
            let h = path.heading_at(s);
            (Point2::new(c.x - 0.5 * h.sin(), c.y + 0.5 * h.cos()), h, s)
        })
        .collect();
    let mut i = 0;
    c.bench_function("project_hinted", |b| {
        b.iter(|| {
            let p = &pts[i];
            i = (i + 1) % n;
            black_box(path.project_hinted(&p.0, p.2))
        })
    });
    c.bench_function("curvature_at", |b| {
        b.iter(|| {
            let p = &pts[i];
            i = (i + 1) % n;
            black_box(path.curvature_at(p.2))
        })
    });
    c.bench_function("heading_at", |b| {
        b.iter(|| {
            let p = &pts[i];
            i = (i + 1) % n;
            black_box(path.heading_at(p.2))
        })
    });
    c.bench_function("ray_cast", |b| {
        b.iter(|| {
            let p = &pts[i];
            i = (i + 1) % n;
            black_box(cor.ray_cast(&path, &p.0, p.1, p.2, 200.0))
        })
    });
}
criterion_group!(benches, bench);
criterion_main!(benches);
