//! `Fleet` for Python: the core's batch stepper (`blendtrack::fleet`), with
//! numpy arrays in and out and the interpreter released while Rust works.
//!
//! Inputs are converted to contiguous float64 / int64 arrays (any array-like
//! is accepted), checked and stepped by the core; see the core module docs
//! for the error policy (call errors raise `InputError` naming the argument
//! or slot; a vehicle with unusable data gets `ok = False` and NaN outputs).

use crate::config::{ControllerConfig, VehicleParams};
use crate::errors::{fleet_error, input_error};
use crate::path::Path;
use blendtrack::fleet::{Fleet as CoreFleet, FleetInputs};
use numpy::{AllowTypeChange, PyArray1, PyArrayLike1};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::borrow::Cow;

type F64In<'py> = PyArrayLike1<'py, f64, AllowTypeChange>;
type I64In<'py> = PyArrayLike1<'py, i64, AllowTypeChange>;

/// `obj` as a 1-D float column named `name`: any array-like of numbers.
/// Text, or an array that is not 1-D, is a `TypeError` naming the argument.
fn floats<'py>(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<F64In<'py>> {
    if obj.cast::<PyArray1<f64>>().is_err() {
        check_kind(name, obj, "biuf", "numbers")?;
    }
    obj.extract::<F64In<'py>>().map_err(|e| {
        PyTypeError::new_err(format!(
            "argument `{name}` must be a 1-D array of numbers: {}",
            one_line(&e.value(obj.py()).to_string())
        ))
    })
}

fn one_line(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// `obj` as the slot column: integers only (a float slot id is refused, not
/// truncated); an empty list is an empty column.
fn slot_ids<'py>(obj: &Bound<'py, PyAny>) -> PyResult<I64In<'py>> {
    if obj.cast::<PyArray1<i64>>().is_err() {
        check_kind("slots", obj, "iu", "integers")?;
    }
    obj.extract::<I64In<'py>>().map_err(|e| {
        PyTypeError::new_err(format!(
            "argument `slots` must be a 1-D array of integers: {}",
            one_line(&e.value(obj.py()).to_string())
        ))
    })
}

/// A `TypeError` unless `numpy.asarray(obj)` has a dtype kind in `kinds`
/// (an empty array passes: it holds no value of a wrong kind).
fn check_kind(name: &str, obj: &Bound<'_, PyAny>, kinds: &str, what: &str) -> PyResult<()> {
    let arr = obj
        .py()
        .import("numpy")?
        .call_method1("asarray", (obj,))
        .map_err(|e| PyTypeError::new_err(format!("argument `{name}`: {e}")))?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    let size: usize = arr.getattr("size")?.extract()?;
    if size > 0 && !kinds.contains(kind.as_str()) {
        return Err(PyTypeError::new_err(format!(
            "argument `{name}` must be a 1-D array of {what}, got dtype {}",
            arr.getattr("dtype")?.str()?
        )));
    }
    Ok(())
}

fn slice<'a, T: numpy::Element + Copy>(a: &'a numpy::PyReadonlyArray1<'_, T>) -> Cow<'a, [T]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().to_vec()),
    }
}

/// Many vehicles on many tracks, stepped together in one call.
#[pyclass(module = "blendtrack")]
pub struct Fleet {
    inner: CoreFleet,
}

#[pymethods]
impl Fleet {
    #[new]
    fn new() -> Self {
        Fleet {
            inner: CoreFleet::new(),
        }
    }

    /// Registers a track (path + corridor built from `config`, default
    /// `ControllerConfig()`), whose config is also the default of its
    /// vehicles. Returns the track id.
    #[pyo3(signature = (path, config = None))]
    fn add_track(
        &mut self,
        py: Python<'_>,
        path: &Path,
        config: Option<ControllerConfig>,
    ) -> PyResult<usize> {
        let cfg = config.map(|c| c.to_core()).transpose()?.unwrap_or_default();
        let p = path.inner.clone();
        let inner = &mut self.inner;
        py.detach(|| inner.add_track(p, cfg)).map_err(fleet_error)
    }

    /// Adds a vehicle on track `track_id`; returns its slot (the lowest free one).
    #[pyo3(signature = (track_id, config = None, vehicle = None))]
    fn add_vehicle(
        &mut self,
        track_id: i64,
        config: Option<ControllerConfig>,
        vehicle: Option<VehicleParams>,
    ) -> PyResult<usize> {
        let cfg = config.map(|c| c.to_core()).transpose()?;
        let params = vehicle.map(|v| v.to_core()).transpose()?;
        self.inner
            .add_vehicle(track_id, cfg, params)
            .map_err(fleet_error)
    }

    /// Frees a slot (its number may be handed out again by `add_vehicle`).
    fn remove_vehicle(&mut self, slot: i64) -> PyResult<()> {
        self.inner.remove_vehicle(slot).map_err(fleet_error)
    }

    /// Forgets a vehicle's projection hints (after a teleport).
    fn reset_vehicle(&mut self, slot: i64) -> PyResult<()> {
        self.inner.reset_vehicle(slot).map_err(fleet_error)
    }

    /// Replaces a vehicle's configuration (e.g. its alpha).
    fn set_vehicle_config(&mut self, slot: i64, config: ControllerConfig) -> PyResult<()> {
        let c = config.to_core()?;
        self.inner.set_vehicle_config(slot, c).map_err(fleet_error)
    }

    fn vehicle_config(&self, slot: i64) -> PyResult<ControllerConfig> {
        self.inner
            .vehicle_config(slot)
            .map(ControllerConfig::from)
            .map_err(fleet_error)
    }

    fn vehicle_params(&self, slot: i64) -> PyResult<VehicleParams> {
        self.inner
            .vehicle_params(slot)
            .map(VehicleParams::from)
            .map_err(fleet_error)
    }

    fn vehicle_track(&self, slot: i64) -> PyResult<usize> {
        self.inner.vehicle_track(slot).map_err(fleet_error)
    }

    /// Slots in use, ascending.
    fn slots<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        PyArray1::from_vec(
            py,
            self.inner.slots().into_iter().map(|s| s as i64).collect(),
        )
    }

    #[getter]
    fn n_tracks(&self) -> usize {
        self.inner.n_tracks()
    }

    /// Threads a step of many vehicles is split over: 0 (the default) for
    /// one per core, 1 to stay on the calling thread.
    #[getter]
    fn threads(&self) -> usize {
        self.inner.threads()
    }
    #[setter]
    fn set_threads(&mut self, threads: usize) {
        self.inner.set_threads(threads);
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// One control step for the listed slots (see the class docs). Returns a
    /// dict of arrays in the order of `slots`: ok, steering_rad, accel_mps2,
    /// alpha, lateral_error_m, heading_error_rad, s_m, s_rear_m,
    /// lateral_error_rear_m, lateral_error_front_m (the axles' errors),
    /// curvature_per_m, virtual_obstacle_m, and with `dt` the next state x_m, y_m, theta_rad,
    /// v_mps, delta_rad. `soft_gap`/`soft_speed`: a vehicle to line up
    /// behind, braked for at `max_deceleration` at most (a soft obstacle).
    #[pyo3(signature = (slots, x, y, theta, v, delta, alpha = None, leader_gap = None, leader_speed = None, stop_gap = None, speed_limit = None, dt = None, soft_gap = None, soft_speed = None))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        slots: &Bound<'py, PyAny>,
        x: &Bound<'py, PyAny>,
        y: &Bound<'py, PyAny>,
        theta: &Bound<'py, PyAny>,
        v: &Bound<'py, PyAny>,
        delta: &Bound<'py, PyAny>,
        alpha: Option<&Bound<'py, PyAny>>,
        leader_gap: Option<&Bound<'py, PyAny>>,
        leader_speed: Option<&Bound<'py, PyAny>>,
        stop_gap: Option<&Bound<'py, PyAny>>,
        speed_limit: Option<&Bound<'py, PyAny>>,
        dt: Option<f64>,
        soft_gap: Option<&Bound<'py, PyAny>>,
        soft_speed: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if dt.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
            return Err(input_error(format!(
                "argument `dt` = {}: must be finite and > 0",
                dt.unwrap_or_default()
            )));
        }
        let opt =
            |name: &str, o: Option<&Bound<'py, PyAny>>| o.map(|o| floats(name, o)).transpose();
        let (slots, x, y, theta, v, delta) = (
            slot_ids(slots)?,
            floats("x", x)?,
            floats("y", y)?,
            floats("theta", theta)?,
            floats("v", v)?,
            floats("delta", delta)?,
        );
        let (alpha, leader_gap, leader_speed) = (
            opt("alpha", alpha)?,
            opt("leader_gap", leader_gap)?,
            opt("leader_speed", leader_speed)?,
        );
        let (stop_gap, speed_limit, soft_gap, soft_speed) = (
            opt("stop_gap", stop_gap)?,
            opt("speed_limit", speed_limit)?,
            opt("soft_gap", soft_gap)?,
            opt("soft_speed", soft_speed)?,
        );
        let (sl, xs, ys, ths, vs, ds) = (
            slice(&slots),
            slice(&x),
            slice(&y),
            slice(&theta),
            slice(&v),
            slice(&delta),
        );
        let al = alpha.as_ref().map(|a| slice(a));
        let lg = leader_gap.as_ref().map(|a| slice(a));
        let ls = leader_speed.as_ref().map(|a| slice(a));
        let sg = stop_gap.as_ref().map(|a| slice(a));
        let sp = speed_limit.as_ref().map(|a| slice(a));
        let fg = soft_gap.as_ref().map(|a| slice(a));
        let fs = soft_speed.as_ref().map(|a| slice(a));
        let inputs = FleetInputs {
            slots: &sl,
            x_m: &xs,
            y_m: &ys,
            theta_rad: &ths,
            v_mps: &vs,
            delta_rad: &ds,
            alpha: al.as_deref(),
            leader_gap_m: lg.as_deref(),
            leader_speed_mps: ls.as_deref(),
            leader_reaction_s: None,
            stop_gap_m: sg.as_deref(),
            soft_gap_m: fg.as_deref(),
            soft_speed_mps: fs.as_deref(),
            speed_limit_mps: sp.as_deref(),
            dt_s: dt,
        };
        let inner = &mut self.inner;
        let out = py.detach(|| inner.step(&inputs)).map_err(fleet_error)?;
        let d = PyDict::new(py);
        d.set_item("ok", PyArray1::from_vec(py, out.ok))?;
        for (k, col) in [
            ("steering_rad", out.steering_rad),
            ("accel_mps2", out.accel_mps2),
            ("alpha", out.alpha),
            ("lateral_error_m", out.lateral_error_m),
            ("heading_error_rad", out.heading_error_rad),
            ("s_m", out.s_m),
            ("s_rear_m", out.s_rear_m),
            ("lateral_error_rear_m", out.lateral_error_rear_m),
            ("lateral_error_front_m", out.lateral_error_front_m),
            ("curvature_per_m", out.curvature_per_m),
            ("virtual_obstacle_m", out.virtual_obstacle_m),
        ] {
            d.set_item(k, PyArray1::from_vec(py, col))?;
        }
        if let Some(n) = out.next {
            for (k, col) in [
                ("x_m", n.x_m),
                ("y_m", n.y_m),
                ("theta_rad", n.theta_rad),
                ("v_mps", n.v_mps),
                ("delta_rad", n.delta_rad),
            ] {
                d.set_item(k, PyArray1::from_vec(py, col))?;
            }
        }
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "Fleet(tracks={}, vehicles={})",
            self.inner.n_tracks(),
            self.inner.len()
        )
    }
}
