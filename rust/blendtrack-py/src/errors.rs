//! Python exception hierarchy of blendtrack.
//!
//! One base class, `BlendtrackError(Exception)`, so callers can catch
//! everything blendtrack raises at once, and one subclass per kind of
//! failure so they can also catch one kind precisely:
//!
//! - `ConfigError`: a parameter or config file is invalid (unknown key,
//!   out-of-range value); the message names the key.
//! - `PathError`: a reference path cannot be built or read (too few distinct
//!   points, NaN or infinite coordinate, negative width); the message names
//!   the row.
//! - `SimulationError`: a simulation cannot proceed (invalid state, SUMO
//!   refused a command).
//! - `InputError`: a bad argument to a call (an array of the wrong length,
//!   an unknown vehicle slot or track id, a negative time step); the message
//!   names the argument or the slot. It also derives from `ValueError`, so
//!   generic argument checks catch it too.
//!
//! The classes report `blendtrack` as their module, the public package that
//! re-exports them, so tracebacks read `blendtrack.ConfigError` and the
//! exceptions pickle by that name.
//!
//! Conversions from the core's error enums to these classes belong here
//! (`impl From<CoreError> for PyErr` picks the subclass), so binding
//! functions can use `?` on core results.

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

create_exception!(
    blendtrack,
    BlendtrackError,
    PyException,
    "Base class of every error raised by blendtrack."
);
create_exception!(
    blendtrack,
    ConfigError,
    BlendtrackError,
    "An invalid parameter or configuration (the message names the key)."
);
create_exception!(
    blendtrack,
    PathError,
    BlendtrackError,
    "A reference path that cannot be built or read (the message names the row)."
);
create_exception!(
    blendtrack,
    SimulationError,
    BlendtrackError,
    "A simulation that cannot proceed."
);

static INPUT_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();

/// `InputError(BlendtrackError, ValueError)`: two bases, which
/// `create_exception!` cannot express, so it is made with `type(...)`.
fn input_error_type(py: Python<'_>) -> PyResult<&Bound<'_, PyType>> {
    INPUT_ERROR
        .get_or_try_init(py, || -> PyResult<Py<PyType>> {
            let bases = PyTuple::new(py, [py.get_type::<BlendtrackError>(), py.get_type::<PyValueError>()])?;
            let ns = PyDict::new(py);
            ns.set_item("__module__", "blendtrack")?;
            ns.set_item(
                "__doc__",
                "A bad argument to a call: wrong array length, unknown slot or track, bad time step (the message names it).",
            )?;
            let ty = py.get_type::<PyType>().call1(("InputError", bases, ns))?;
            Ok(ty.cast_into::<PyType>()?.unbind())
        })
        .map(|t| t.bind(py))
}

/// An `InputError` with `message`.
pub(crate) fn input_error(message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| match input_error_type(py) {
        Ok(ty) => PyErr::from_type(ty.clone(), message),
        Err(e) => e,
    })
}

/// Maps a core error to the exception class of its kind.
pub(crate) fn core_error(e: blendtrack::Error) -> PyErr {
    match e {
        blendtrack::Error::Path(e) => path_error(e),
        blendtrack::Error::Config(e) => config_error(e),
        blendtrack::Error::State(e) => state_error(e),
    }
}

pub(crate) fn path_error(e: blendtrack::PathError) -> PyErr {
    PathError::new_err(e.to_string())
}

pub(crate) fn config_error(e: blendtrack::ConfigError) -> PyErr {
    ConfigError::new_err(e.to_string())
}

/// A bad simulation parameter is a configuration error; an unusable state
/// (NaN) stops the simulation.
pub(crate) fn state_error(e: blendtrack::StateError) -> PyErr {
    match e {
        blendtrack::StateError::NonFinite { .. } => SimulationError::new_err(e.to_string()),
        _ => ConfigError::new_err(e.to_string()),
    }
}

pub(crate) fn fleet_error(e: blendtrack::FleetError) -> PyErr {
    match e {
        blendtrack::FleetError::Config(e) => config_error(e),
        other => input_error(other.to_string()),
    }
}

/// Adds the exception classes to the native module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("BlendtrackError", py.get_type::<BlendtrackError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("PathError", py.get_type::<PathError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("InputError", input_error_type(py)?)?;
    Ok(())
}
