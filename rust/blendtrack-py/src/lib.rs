//! Python binding of the blendtrack core, imported as `blendtrack._blendtrack`.
//!
//! This crate is thin on purpose: it converts Python inputs to core types,
//! calls the core with the interpreter released (`py.detach`), and converts
//! the results back (numpy arrays for anything per-vehicle or per-step). All
//! behaviour lives in the `blendtrack` crate; the public Python API is the
//! `blendtrack` package, which re-exports what this module registers.
//!
//! It is built by maturin only (`pip install -e .` or `maturin develop`); it
//! is kept out of the workspace's default members so a bare `cargo test`
//! stays Python-free. Every name registered here must also be declared in
//! `python/blendtrack/_blendtrack.pyi` (checked by `mypy.stubtest`).
//!
//! Modules: `errors` (exception classes and core-error mapping), `path`
//! (`Path`), `config` (`ControllerConfig`, `VehicleParams`, `load_config`),
//! `sim` (`simulate`, `compute_metrics`), `fleet` (`Fleet`), `traffic`
//! (`RouteFleet`, on the `blendtrack-traffic` crate), `geometry` (polyline
//! functions: arc length, resampling, smoothing, blends, joined tracks,
//! segment distances).

// `!(x >= y)` is a NaN guard on purpose (see the core crate).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use pyo3::prelude::*;

mod config;
mod errors;
mod fleet;
mod geometry;
mod path;
mod sim;
mod traffic;

/// The native module. Each submodule of this crate adds its own names
/// through a `register` function, so this stays a list of one-liners.
#[pymodule]
fn _blendtrack(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MAX_SIM_STEPS", blendtrack::limits::MAX_SIM_STEPS)?;
    m.add(
        "HOLD_BRAKING_MIN_STEP_S",
        blendtrack_traffic::HOLD_BRAKING_MIN_STEP_S,
    )?;
    m.add("ADVANCE_MAX_M", blendtrack_traffic::ADVANCE_MAX_M)?;
    errors::register(m)?;
    m.add_class::<path::Path>()?;
    m.add_class::<config::ControllerConfig>()?;
    m.add_class::<config::VehicleParams>()?;
    m.add_function(wrap_pyfunction!(config::load_config, m)?)?;
    m.add_function(wrap_pyfunction!(sim::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sim::compute_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(sim::stopping_accel, m)?)?;
    m.add_class::<fleet::Fleet>()?;
    m.add_class::<traffic::RouteFleet>()?;
    geometry::register(m)?;
    Ok(())
}
