//! Polyline geometry for Python (`blendtrack::polyline`): numpy arrays in
//! and out, one call per polyline or per track, the interpreter released
//! while the core computes. A polyline that cannot be used (too few points,
//! a coordinate that is not finite) raises `PathError`; a bad parameter or
//! mismatched lengths raise `InputError`.

use crate::errors::{input_error, PathError};
use blendtrack::polyline::{self, chain, PolylineError, Xy};
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn geometry_error(e: PolylineError) -> PyErr {
    match e {
        PolylineError::TooFewPoints { .. } | PolylineError::NonFinite { .. } => {
            PathError::new_err(e.to_string())
        }
        PolylineError::Count { .. } | PolylineError::Parameter { .. } => input_error(e.to_string()),
    }
}

/// The rows of an (N, 2) float array.
fn xy(a: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<Vec<Xy>> {
    let shape = a.shape();
    if shape[1] != 2 {
        return Err(input_error(format!(
            "`{name}` must have shape (N, 2), got ({}, {})",
            shape[0], shape[1]
        )));
    }
    let v = a.as_array();
    Ok((0..shape[0]).map(|i| [v[[i, 0]], v[[i, 1]]]).collect())
}

fn xy_array<'py>(py: Python<'py>, pts: &[Xy]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = pts.iter().flat_map(|p| [p[0], p[1]]).collect();
    PyArray1::from_vec(py, flat).reshape([pts.len(), 2])
}

/// Arc length at each point of an (N, 2) polyline (0 at the first; a
/// running sum of `hypot` segment lengths).
#[pyfunction]
pub fn polyline_arc_lengths<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let pts = xy(&points, "points")?;
    polyline::check_points("polyline", &pts, 0).map_err(geometry_error)?;
    let s = py.detach(|| polyline::arc_lengths(&pts));
    Ok(PyArray1::from_vec(py, s))
}

type Resampled<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>, f64);

/// Points evenly spaced along an (N >= 2, 2) polyline, at most `spacing_m`
/// apart, from its first point to its last: (the (M, 2) points, their arc
/// lengths, the length of the input polyline).
#[pyfunction]
pub fn polyline_resample<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    spacing_m: f64,
) -> PyResult<Resampled<'py>> {
    let pts = xy(&points, "points")?;
    let (out, s, total) = py
        .detach(|| -> Result<_, PolylineError> {
            let out = polyline::resample(&pts, spacing_m)?;
            let s = polyline::arc_lengths(&out);
            Ok((out, s, polyline::length(&pts)))
        })
        .map_err(geometry_error)?;
    Ok((xy_array(py, &out)?, PyArray1::from_vec(py, s), total))
}

/// Gaussian smoothing of an (N, 2) polyline, standard deviation
/// `sigma_pts` points, ends held in place (unchanged below 5 points).
#[pyfunction]
pub fn polyline_smooth<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    sigma_pts: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let pts = xy(&points, "points")?;
    polyline::check_points("polyline", &pts, 0).map_err(geometry_error)?;
    let out = py.detach(|| polyline::smooth(&pts, sigma_pts));
    xy_array(py, &out)
}

type BlendArrays<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    f64,
    f64,
);

/// From polyline `source` (resampled every `spacing_m`) onto `target` by a
/// smoothstep weight between `start_m` and `start_m + length_m` along
/// `source`: (points, weight, arc length along the resampled `source`, arc
/// length along `target` of the point each is blended with, the start and
/// the length of the move after clamping).
#[pyfunction]
#[pyo3(signature = (source, target, spacing_m, start_m = None, length_m = None))]
pub fn polyline_blend<'py>(
    py: Python<'py>,
    source: PyReadonlyArray2<'py, f64>,
    target: PyReadonlyArray2<'py, f64>,
    spacing_m: f64,
    start_m: Option<f64>,
    length_m: Option<f64>,
) -> PyResult<BlendArrays<'py>> {
    let (a, b) = (xy(&source, "source")?, xy(&target, "target")?);
    let bl = py
        .detach(|| polyline::blend(&a, &b, spacing_m, start_m, length_m))
        .map_err(geometry_error)?;
    Ok((
        xy_array(py, &bl.points)?,
        PyArray1::from_vec(py, bl.weight),
        PyArray1::from_vec(py, bl.s_from),
        PyArray1::from_vec(py, bl.s_onto),
        bl.start_m,
        bl.length_m,
    ))
}

type PieceIn<'py> = (
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray1<'py, f64>,
    bool,
    f64,
);

/// Joins pieces `(points (N, 2), station (N,), on_reference, station_scale)`
/// into one smoothed track (`blendtrack::polyline::chain`). Returns a dict:
/// `points` (M, 2), `length_m`, per kept piece `kept` (input index),
/// `kept_points`, `start_s`, `before_s`, `entry_s`, and per run `run_piece`
/// (input index), `run_start_s`, `run_station`, `run_scale`, `run_offset`,
/// and `rounded`: (start, end, peak |curvature| left) of each stretch
/// sharper than `kappa_max` (1/m; 0: no limit) that was rounded off.
#[pyfunction]
#[pyo3(signature = (pieces, sigma_pts, near_m, min_run, kappa_max = 0.0))]
pub fn polyline_join<'py>(
    py: Python<'py>,
    pieces: Vec<PieceIn<'py>>,
    sigma_pts: f64,
    near_m: f64,
    min_run: usize,
    kappa_max: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let mut input = Vec::with_capacity(pieces.len());
    for (i, (points, station, on_reference, station_scale)) in pieces.iter().enumerate() {
        input.push(chain::ChainPiece {
            points: xy(points, &format!("pieces[{i}] points"))?,
            station: station.as_array().to_vec(),
            on_reference: *on_reference,
            station_scale: *station_scale,
        });
    }
    let ch = py
        .detach(|| chain::join(&input, sigma_pts, kappa_max, near_m, min_run))
        .map_err(geometry_error)?;
    let d = PyDict::new(py);
    d.set_item("points", xy_array(py, &ch.points)?)?;
    d.set_item("length_m", ch.length)?;
    d.set_item("kept", ch.kept)?;
    d.set_item("kept_points", ch.kept_points)?;
    d.set_item("start_s", ch.start_s)?;
    d.set_item("before_s", ch.before_s)?;
    d.set_item("entry_s", ch.entry_s)?;
    d.set_item(
        "run_piece",
        ch.runs.iter().map(|r| r.piece).collect::<Vec<_>>(),
    )?;
    let col = |f: fn(&chain::Run) -> f64| PyArray1::from_vec(py, ch.runs.iter().map(f).collect());
    d.set_item("run_start_s", col(|r| r.start_s))?;
    d.set_item("run_station", col(|r| r.station))?;
    d.set_item("run_scale", col(|r| r.scale))?;
    d.set_item("run_offset", col(|r| r.offset))?;
    d.set_item("station", PyArray1::from_vec(py, ch.station))?;
    d.set_item("rounded", ch.rounded)?;
    Ok(d)
}

/// Smallest distance between two (N, 2) polylines: 0 where segments
/// cross, infinite when either is empty; a single point is a segment of
/// length 0.
#[pyfunction]
pub fn polyline_distance(
    py: Python<'_>,
    p: PyReadonlyArray2<'_, f64>,
    q: PyReadonlyArray2<'_, f64>,
) -> PyResult<f64> {
    let (a, b) = (xy(&p, "p")?, xy(&q, "q")?);
    py.detach(|| polyline::segments_distance(&a, &b))
        .map_err(geometry_error)
}

/// The lateral profile of a lane change's blend (`polyline_blend`):
/// `3u^2 - 2u^3` of `u` clamped to [0, 1]; NaN stays NaN.
#[pyfunction]
pub fn smoothstep(u: f64) -> f64 {
    polyline::smoothstep(u)
}

/// Adds the geometry functions to the native module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(polyline_arc_lengths, m)?)?;
    m.add_function(wrap_pyfunction!(polyline_resample, m)?)?;
    m.add_function(wrap_pyfunction!(polyline_smooth, m)?)?;
    m.add_function(wrap_pyfunction!(polyline_blend, m)?)?;
    m.add_function(wrap_pyfunction!(polyline_join, m)?)?;
    m.add_function(wrap_pyfunction!(polyline_distance, m)?)?;
    m.add_function(wrap_pyfunction!(smoothstep, m)?)?;
    Ok(())
}
