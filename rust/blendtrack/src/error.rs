//! Error types of the core crate.
//!
//! Every error says what was wrong and where: the row of a path, the key of a
//! configuration, the field of a vehicle state. User input never panics; it
//! becomes one of these values.

use thiserror::Error;

/// A path (reference track) could not be built or loaded.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PathError {
    /// Fewer than two distinct points remain after dropping duplicates.
    #[error("a path needs at least 2 distinct points, got {0}")]
    TooFewPoints(usize),
    /// A coordinate or width is NaN or infinite.
    #[error("{location}: {what} is not finite ({value})")]
    NonFinite {
        location: String,
        what: &'static str,
        value: f64,
    },
    /// A coordinate is beyond [`crate::limits::MAX_COORDINATE_M`].
    #[error("{location}: {what} = {} is beyond +-1e9 m, where f64 cannot resolve offsets of metres", crate::limits::fmt_number(*value))]
    TooFar {
        location: String,
        what: &'static str,
        value: f64,
    },
    /// A width is negative.
    #[error("{location}: {what} must be >= 0, got {value}")]
    NegativeWidth {
        location: String,
        what: &'static str,
        value: f64,
    },
    /// Widths were given but not one pair per point.
    #[error("got {widths} width pairs for {points} points")]
    WidthCount { widths: usize, points: usize },
    /// A track file line could not be parsed.
    #[error("{file}: line {line}: {message}")]
    Parse {
        file: String,
        line: u64,
        message: String,
    },
    /// A track file could not be read.
    #[error("cannot read track file {file}: {message}")]
    Io { file: String, message: String },
    /// A generator would produce more points than [`crate::limits::MAX_PATH_POINTS`].
    #[error("{name} = {}: {} points, more than the limit of {limit} (raise the spacing or shorten the path)", crate::limits::fmt_number(*value), crate::limits::fmt_number(*points))]
    TooManyPoints {
        name: &'static str,
        value: f64,
        points: f64,
        limit: usize,
    },
    /// A generator parameter is out of range.
    #[error("invalid path parameter {name} = {}: {message}", crate::limits::fmt_number(*value))]
    Parameter {
        name: &'static str,
        value: f64,
        message: &'static str,
    },
}

/// A configuration value is missing, unknown, out of range or unreadable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    /// A value is out of its admissible range; `key` is the TOML key.
    #[error("config key `{key}` = {value}: {message}")]
    Invalid {
        key: String,
        value: String,
        message: String,
    },
    /// The TOML text is malformed or has an unknown key (the message names it).
    #[error("{source_name}: {message}")]
    Parse {
        source_name: String,
        message: String,
    },
    /// The file could not be read or written.
    #[error("cannot access config file {file}: {message}")]
    Io { file: String, message: String },
}

impl ConfigError {
    pub(crate) fn invalid(
        key: impl Into<String>,
        value: impl ToString,
        message: impl Into<String>,
    ) -> Self {
        ConfigError::Invalid {
            key: key.into(),
            value: value.to_string(),
            message: message.into(),
        }
    }
}

/// A vehicle state or observation handed to a controller is unusable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum StateError {
    #[error("vehicle state field `{field}` is not finite ({value})")]
    NonFinite { field: &'static str, value: f64 },
    #[error("simulation parameter `{name}` = {}: {message}", crate::limits::fmt_number(*value))]
    Parameter {
        name: &'static str,
        value: f64,
        message: &'static str,
    },
    /// A run would need more memory than a limit of [`crate::limits`] allows.
    #[error("simulation parameter `{name}` = {}: {message}", crate::limits::fmt_number(*value))]
    TooLarge {
        name: &'static str,
        value: f64,
        message: String,
    },
}

/// Any error of the core crate.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Error {
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    State(#[from] StateError),
}
