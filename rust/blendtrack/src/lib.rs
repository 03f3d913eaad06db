//! blendtrack core: path tracking with a dynamic control point.
//!
//! This crate implements the method of "Path Tracking with Dynamic Control
//! Point Blending for Autonomous Vehicles" (Lombard et al.) as fixed by the
//! project's SPEC: a front-axle Stanley command and a rear-axle
//! curvature-based geometric command blended with a barycentric weight
//! `alpha` in [0, 1] ([`lateral`]), a curvature-aware longitudinal law built
//! on virtual borders and a ray cast ([`longitudinal`]), or on curve
//! speeds previewed along the path ([`curve_speed`], for roads), the reference
//! [`path`] they track, a kinematic bicycle [`vehicle`] with actuator limits,
//! delay and sensor noise, a closed-loop [`sim`]ulator with its [`metrics`],
//! one accumulator of a drive's statistics ([`stats`]), and a batch
//! [`fleet`] stepping many vehicles in one call. It knows nothing of Python
//! or of any traffic simulator: the `blendtrack-traffic` crate (road routes
//! among other traffic), the binding crate and the Python package build on
//! it.
//!
//! Conventions (SPEC §1): SI units, world frame x east / y north, heading CCW
//! from +x in (-pi, pi], steering > 0 turns left, lateral error > 0 on the
//! left of the path, `v < 0` drives backwards.

// Checks are written `!(x > 0.0)` on purpose: a NaN fails every comparison,
// so it takes the "bad input" branch; `x <= 0.0` would let it through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod config;
pub mod controller;
pub mod curve_speed;
pub mod error;
pub mod fleet;
pub mod lateral;
pub mod limits;
pub mod longitudinal;
pub mod metrics;
pub mod path;
pub mod polyline;
pub mod sim;
pub mod stats;
pub mod vehicle;

pub use config::{AlphaMode, Config, ControllerConfig, Experiment, ExperimentSet, LateralKind};
pub use controller::{ControlOutput, Controller, Track};
pub use error::{ConfigError, Error, PathError, StateError};
pub use fleet::{Fleet, FleetError, FleetInputs, FleetOutputs, NextStates};
pub use lateral::AlphaSchedule;
pub use longitudinal::{Corridor, Obstacle};
pub use metrics::{run_metrics, trace_metrics, RunMetrics, Series, WindowMetrics};
pub use path::{wrap_angle, Path, Projection, Widths};
pub use sim::{simulate, SimOptions, Trace};
pub use stats::{StatValue, TrackingSample, TrackingStats};
pub use vehicle::{Command, Direction, NoiseModel, Sensor, Vehicle, VehicleParams, VehicleState};
