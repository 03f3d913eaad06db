//! `simulate` and `metrics` for Python: one call runs a whole closed-loop
//! simulation in Rust (interpreter released) and returns its columns as
//! numpy arrays plus the metrics as a flat dict (keys of `metrics.json`).

use crate::config::{dict_to_toml, from_table, ControllerConfig, VehicleParams};
use crate::errors::{core_error, input_error};
use crate::path::Path;
use blendtrack::metrics::{run_metrics, Series};
use blendtrack::sim::{simulate as core_simulate, SimOptions};
use blendtrack::vehicle::NoiseModel;
use blendtrack::{AlphaSchedule, Track};
use numpy::{PyArray1, PyReadonlyArray1, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// The `metrics.json` metrics, then the extra ones, as a dict (NaN where undefined).
pub(crate) fn metrics_dict<'py>(
    py: Python<'py>,
    m: &blendtrack::RunMetrics,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in m.to_named().into_iter().chain(m.to_named_extra()) {
        d.set_item(k, v)?;
    }
    Ok(d)
}

fn alpha_schedule(
    alpha: Option<f64>,
    alpha_sine_omega: Option<f64>,
    alpha_knots: Option<(PyReadonlyArray1<'_, f64>, PyReadonlyArray1<'_, f64>)>,
    default: f64,
) -> PyResult<AlphaSchedule> {
    let given =
        alpha.is_some() as u8 + alpha_sine_omega.is_some() as u8 + alpha_knots.is_some() as u8;
    if given > 1 {
        return Err(input_error(
            "give at most one of `alpha`, `alpha_sine_omega`, `alpha_knots`",
        ));
    }
    let s = if let Some(a) = alpha {
        AlphaSchedule::Constant { alpha: a }
    } else if let Some(w) = alpha_sine_omega {
        AlphaSchedule::Sine { omega_rad_s: w }
    } else if let Some((t, a)) = alpha_knots {
        let (t, a) = (t.as_array(), a.as_array());
        if t.len() != a.len() {
            return Err(input_error(format!(
                "`alpha_knots`: {} times but {} values",
                t.len(),
                a.len()
            )));
        }
        AlphaSchedule::Piecewise {
            knots: t.iter().copied().zip(a.iter().copied()).collect(),
        }
    } else {
        AlphaSchedule::Constant { alpha: default }
    };
    s.validate()
        .map_err(|m| crate::errors::ConfigError::new_err(format!("alpha schedule: {m}")))?;
    Ok(s)
}

/// Runs one closed-loop simulation; returns (columns, metrics).
#[pyfunction]
#[pyo3(signature = (
    path, config = None, vehicle = None, *, alpha = None, alpha_sine_omega = None, alpha_knots = None,
    dt_s = 0.01, duration_s = 60.0, laps = None, noise = None, delay_s = 0.0, seed = 0,
    start_s_m = 0.0, offset_m = 0.0, heading_error_deg = 0.0, initial_speed_mps = 0.0, fixed_speed_mps = None,
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate<'py>(
    py: Python<'py>,
    path: &Path,
    config: Option<ControllerConfig>,
    vehicle: Option<VehicleParams>,
    alpha: Option<f64>,
    alpha_sine_omega: Option<f64>,
    alpha_knots: Option<(PyReadonlyArray1<'py, f64>, PyReadonlyArray1<'py, f64>)>,
    dt_s: f64,
    duration_s: f64,
    laps: Option<f64>,
    noise: Option<&Bound<'py, PyDict>>,
    delay_s: f64,
    seed: u64,
    start_s_m: f64,
    offset_m: f64,
    heading_error_deg: f64,
    initial_speed_mps: f64,
    fixed_speed_mps: Option<f64>,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
    let cfg = config.map(|c| c.to_core()).transpose()?.unwrap_or_default();
    let params = vehicle
        .map(|v| v.to_core())
        .transpose()?
        .unwrap_or_default();
    let schedule = alpha_schedule(alpha, alpha_sine_omega, alpha_knots, cfg.lat_blend_factor)?;
    let noise: NoiseModel = match noise {
        None => NoiseModel::None,
        Some(d) => from_table(dict_to_toml(Some(d))?, "noise")?,
    };
    let opts = SimOptions {
        dt_s,
        duration_s,
        laps,
        noise,
        delay_s,
        seed,
        start_s_m,
        initial_offset_m: offset_m,
        initial_heading_error_deg: heading_error_deg,
        initial_speed_mps,
        fixed_speed_mps,
    };
    let core_path = path.inner.clone();
    let (trace, metrics) = py
        .detach(move || {
            let track = Arc::new(Track::new(core_path, &cfg));
            let trace = core_simulate(track, &cfg, &params, &schedule, &opts)?;
            let m = run_metrics(&Series::from(&trace), params.wheelbase_m);
            Ok::<_, blendtrack::Error>((trace, m))
        })
        .map_err(core_error)?;
    let cols = PyDict::new(py);
    let t = trace;
    for (k, v) in [
        ("t_s", t.t_s),
        ("x_m", t.x_m),
        ("y_m", t.y_m),
        ("theta_rad", t.theta_rad),
        ("v_mps", t.v_mps),
        ("delta_rad", t.delta_rad),
        ("alpha", t.alpha),
        ("s_m", t.s_m),
        ("lateral_error_m", t.lateral_error_m),
        ("lateral_error_front_m", t.lateral_error_front_m),
        ("lateral_error_rear_m", t.lateral_error_rear_m),
        ("heading_error_rad", t.heading_error_rad),
        ("accel_mps2", t.accel_mps2),
        ("virtual_obstacle_m", t.virtual_obstacle_m),
        ("curvature_per_m", t.curvature_per_m),
        ("distance_m", t.distance_m),
    ] {
        cols.set_item(k, PyArray1::from_vec(py, v))?;
    }
    Ok((cols, metrics_dict(py, &metrics)?))
}

/// Metrics of hand-made or recorded columns (same definitions as `simulate`);
/// the axle metrics need both `lateral_error_front_m` and `lateral_error_rear_m` (NaN otherwise).
#[pyfunction]
#[pyo3(signature = (t_s, lateral_error_m, heading_error_rad, delta_rad, v_mps, distance_m, wheelbase_m = 2.6, lateral_error_front_m = None, lateral_error_rear_m = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn compute_metrics<'py>(
    py: Python<'py>,
    t_s: PyReadonlyArray1<'py, f64>,
    lateral_error_m: PyReadonlyArray1<'py, f64>,
    heading_error_rad: PyReadonlyArray1<'py, f64>,
    delta_rad: PyReadonlyArray1<'py, f64>,
    v_mps: PyReadonlyArray1<'py, f64>,
    distance_m: PyReadonlyArray1<'py, f64>,
    wheelbase_m: f64,
    lateral_error_front_m: Option<PyReadonlyArray1<'py, f64>>,
    lateral_error_rear_m: Option<PyReadonlyArray1<'py, f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let n = t_s.len();
    if n == 0 {
        return Err(input_error(
            "argument `t_s` is empty: metrics of no samples are undefined",
        ));
    }
    for (name, c) in [
        ("lateral_error_front_m", &lateral_error_front_m),
        ("lateral_error_rear_m", &lateral_error_rear_m),
    ] {
        if let Some(c) = c {
            if c.len() != n {
                return Err(input_error(format!(
                    "argument `{name}` has {} entries, expected {n} (as `t_s`)",
                    c.len()
                )));
            }
        }
    }
    let cols = [
        ("lateral_error_m", &lateral_error_m),
        ("heading_error_rad", &heading_error_rad),
        ("delta_rad", &delta_rad),
        ("v_mps", &v_mps),
        ("distance_m", &distance_m),
    ];
    for (name, c) in cols {
        if c.len() != n {
            return Err(input_error(format!(
                "argument `{name}` has {} entries, expected {n} (as `t_s`)",
                c.len()
            )));
        }
    }
    if !(wheelbase_m.is_finite() && wheelbase_m > 0.0) {
        return Err(input_error(format!(
            "argument `wheelbase_m` = {wheelbase_m}: must be > 0"
        )));
    }
    let v = |a: &PyReadonlyArray1<'py, f64>| a.as_array().to_vec();
    let (t, e, h, d, s, dist) = (
        v(&t_s),
        v(&lateral_error_m),
        v(&heading_error_rad),
        v(&delta_rad),
        v(&v_mps),
        v(&distance_m),
    );
    let opt = |a: &Option<PyReadonlyArray1<'py, f64>>| a.as_ref().map(v).unwrap_or_default();
    let (front, rear) = (opt(&lateral_error_front_m), opt(&lateral_error_rear_m));
    let series = Series {
        t_s: &t,
        lateral_error_m: &e,
        lateral_error_front_m: &front,
        lateral_error_rear_m: &rear,
        heading_error_rad: &h,
        delta_rad: &d,
        v_mps: &s,
        distance_m: &dist,
    };
    metrics_dict(py, &run_metrics(&series, wheelbase_m))
}

/// The reaction-time stopping law (paper eq. 7, the larger root; `b_l` when
/// no admissible acceleration exists): the acceleration that, held for `tau`
/// and followed by braking at `b_f`, stops `s0` behind an obstacle `gap_m`
/// ahead moving at `v_l` and braking at `b_l`. Decelerations are negative.
#[pyfunction]
#[pyo3(signature = (v_mps, gap_m, v_l_mps, s0_m, tau_s, b_f_mps2, b_l_mps2))]
pub(crate) fn stopping_accel(
    v_mps: f64,
    gap_m: f64,
    v_l_mps: f64,
    s0_m: f64,
    tau_s: f64,
    b_f_mps2: f64,
    b_l_mps2: f64,
) -> f64 {
    blendtrack::longitudinal::stopping_accel(v_mps, gap_m, v_l_mps, s0_m, tau_s, b_f_mps2, b_l_mps2)
}
