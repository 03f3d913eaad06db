//! The fleet of `benches/fleet_step.rs` and `examples/fleet_count.rs`:
//! `n` vehicles spread evenly over the built-in test track, 0.3 m left of
//! it, at 3 m/s, default configuration.

use blendtrack::{ControllerConfig, Fleet, NextStates, Path};

/// The fleet's vehicles' state columns (x, y, theta, v, delta).
pub type Columns = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

/// The fleet on `threads` threads (0: rayon's pool), its slots and the
/// vehicles' first states.
pub fn test_track_fleet(n: usize, threads: usize) -> (Fleet, Vec<i64>, Columns) {
    let path = Path::test_track(1.0).expect("built-in track");
    let mut fleet = Fleet::new();
    fleet.set_threads(threads);
    let track = fleet
        .add_track(path.clone(), ControllerConfig::default())
        .expect("track") as i64;
    let slots: Vec<i64> = (0..n)
        .map(|_| fleet.add_vehicle(track, None, None).expect("vehicle") as i64)
        .collect();
    let (mut x, mut y, mut theta) = (vec![], vec![], vec![]);
    for i in 0..n {
        let s = path.length() * i as f64 / n as f64;
        let (p, h) = (path.point_at(s), path.heading_at(s));
        x.push(p.x - 0.3 * h.sin());
        y.push(p.y + 0.3 * h.cos());
        theta.push(h);
    }
    (fleet, slots, (x, y, theta, vec![3.0; n], vec![0.0; n]))
}

/// A step's next states as the next step's input columns.
pub fn columns(next: NextStates) -> Columns {
    (
        next.x_m,
        next.y_m,
        next.theta_rad,
        next.v_mps,
        next.delta_rad,
    )
}
