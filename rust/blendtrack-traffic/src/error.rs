//! The error type of route-fleet calls ([`TrafficError`]) and the
//! argument-length check they share.

use blendtrack::FleetError;
use thiserror::Error;

/// An error of a route-fleet call; nothing was changed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrafficError {
    #[error(transparent)]
    Fleet(#[from] FleetError),
    #[error("route: {0}")]
    Route(String),
    #[error("argument `{argument}` has {got} entries, expected {expected}")]
    Length {
        argument: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("slot {slot} has no route (added through the inner fleet?)")]
    NoRoute { slot: i64 },
    #[error("traffic light number {light} is too large (lights are numbered below 2^20)")]
    UnknownLight { light: usize },
    #[error("step() called without a plan() before it")]
    NoPlan,
    #[error("argument `{name}` = {value}: {message}")]
    Parameter {
        name: &'static str,
        value: f64,
        message: &'static str,
    },
}

pub(crate) fn check_len(
    argument: &'static str,
    expected: usize,
    got: usize,
) -> Result<(), TrafficError> {
    if expected == got {
        Ok(())
    } else {
        Err(TrafficError::Length {
            argument,
            expected,
            got,
        })
    }
}
