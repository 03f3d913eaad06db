//! The Nurburgring fixture of the core's benches and of `examples/step_count`
//! (included by `#[path]`, so every timing and instruction count runs the
//! same states): the track file of `../shared/tracks`, and states walking
//! along the track.

use blendtrack::{Path, VehicleState};
use std::path::PathBuf;

/// `../shared/tracks/Nuerburgring.csv`, beside the repository.
pub fn track_file() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/tracks/Nuerburgring.csv")
}

/// States `spacing` m apart along `path` (0.3 m: a vehicle at 30 m/s sampled
/// at 100 Hz), 0.5 m off the centreline with a 0.02 rad heading error, at
/// 30 m/s, so the controller's hints behave as in a real run.
#[allow(dead_code)] // not every including target walks the track
pub fn states_along(path: &Path, spacing: f64) -> Vec<VehicleState> {
    let n = (path.length() / spacing) as usize;
    (0..n)
        .map(|i| {
            let s = i as f64 * spacing;
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
        .collect()
}
