//! Helpers shared by the property-based test files.

use blendtrack::VehicleState;

/// The state of a strategy's tuple `(x, y, theta, v, delta)`.
pub fn state_of((x, y, th, v, d): (f64, f64, f64, f64, f64)) -> VehicleState {
    VehicleState {
        x_m: x,
        y_m: y,
        theta_rad: th,
        v_mps: v,
        delta_rad: d,
    }
}
