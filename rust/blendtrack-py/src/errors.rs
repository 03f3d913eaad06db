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
//!
//! The classes report `blendtrack` as their module, the public package that
//! re-exports them, so tracebacks read `blendtrack.ConfigError` and the
//! exceptions pickle by that name.
//!
//! Conversions from the core's error enums to these classes belong here
//! (`impl From<CoreError> for PyErr` picks the subclass), so binding
//! functions can use `?` on core results.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

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

/// Adds the exception classes to the native module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("BlendtrackError", py.get_type::<BlendtrackError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("PathError", py.get_type::<PathError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    Ok(())
}
