//! `Path` for Python: a reference track built from a numpy array, a TUM csv
//! file or a built-in generator. Immutable; `scaled` returns a new one.

use crate::errors::path_error;
use blendtrack::path::{Path as CorePath, Widths};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyString};

/// A reference path: polyline with arc length, optional per-point widths.
#[pyclass(module = "blendtrack", frozen, from_py_object)]
#[derive(Debug, Clone)]
pub struct Path {
    pub(crate) inner: CorePath,
}

/// `obj` as N rows of 2 numbers: any array-like of ints or floats of shape
/// (N, 2). None, text or another shape is refused with the expected shape.
fn rows(obj: &Bound<'_, PyAny>, name: &str, columns: &str) -> PyResult<Vec<[f64; 2]>> {
    let expected = format!("`{name}` must be an (N, 2) array of numbers ({columns} per row)");
    if obj.is_none() || obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyBytes>() {
        return Err(PyTypeError::new_err(format!(
            "{expected}, got {}",
            obj.get_type().name()?
        )));
    }
    let np = obj.py().import("numpy")?;
    let kind: String = np
        .call_method1("asarray", (obj,))
        .and_then(|a| a.getattr("dtype")?.getattr("kind")?.extract())
        .map_err(|e| PyTypeError::new_err(format!("{expected}: {e}")))?;
    if !"biuf".contains(kind.as_str()) {
        return Err(PyTypeError::new_err(format!(
            "{expected}, got an array of dtype kind '{kind}'"
        )));
    }
    let arr = np
        .call_method1("asarray", (obj, "float64"))
        .map_err(|e| PyTypeError::new_err(format!("{expected}: {e}")))?;
    let a: PyReadonlyArray2<'_, f64> = arr.extract().map_err(|_| {
        let shape = arr
            .getattr("shape")
            .and_then(|s| s.str().map(|s| s.to_string()))
            .unwrap_or_default();
        crate::errors::input_error(format!("{expected}, got shape {shape}"))
    })?;
    let shape = a.shape();
    if shape[1] != 2 {
        return Err(crate::errors::input_error(format!(
            "{expected}, got shape ({}, {})",
            shape[0], shape[1]
        )));
    }
    let v = a.as_array();
    Ok((0..shape[0]).map(|i| [v[[i, 0]], v[[i, 1]]]).collect())
}

/// An arc length argument: NaN or infinite is an `InputError`.
fn finite(name: &str, value: f64) -> PyResult<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(crate::errors::input_error(format!(
            "argument `{name}` = {value}: must be finite"
        )))
    }
}

/// A coordinate argument: finite and within the core's coordinate range.
fn coordinate(name: &str, value: f64) -> PyResult<f64> {
    if finite(name, value)?.abs() <= blendtrack::limits::MAX_COORDINATE_M {
        Ok(value)
    } else {
        Err(crate::errors::input_error(format!(
            "argument `{name}` = {}: beyond +-1e9 m, where f64 cannot resolve the path",
            blendtrack::limits::fmt_number(value)
        )))
    }
}

#[pymethods]
impl Path {
    /// From an (N, 2) array of x, y (m); `widths` (N, 2) = right, left (m).
    #[new]
    #[pyo3(signature = (points, widths = None, closed = false))]
    fn new(
        points: &Bound<'_, PyAny>,
        widths: Option<&Bound<'_, PyAny>>,
        closed: bool,
    ) -> PyResult<Self> {
        let pts = rows(points, "points", "x, y")?;
        let ws: Option<Vec<Widths>> = match widths {
            Some(w) => Some(
                rows(w, "widths", "right, left")?
                    .into_iter()
                    .map(|[r, l]| Widths {
                        right_m: r,
                        left_m: l,
                    })
                    .collect(),
            ),
            None => None,
        };
        Ok(Path {
            inner: CorePath::new(&pts, ws.as_deref(), closed).map_err(path_error)?,
        })
    }

    /// Reads a TUM race-track csv (`x_m,y_m,w_tr_right_m,w_tr_left_m`).
    #[staticmethod]
    #[pyo3(signature = (file, closed = true))]
    fn from_tum_csv(py: Python<'_>, file: std::path::PathBuf, closed: bool) -> PyResult<Self> {
        let p = py
            .detach(|| CorePath::from_tum_csv(&file, closed))
            .map_err(path_error)?;
        Ok(Path { inner: p })
    }

    /// A straight line from the origin along +x.
    #[staticmethod]
    #[pyo3(signature = (length_m, spacing_m = 1.0))]
    fn straight(length_m: f64, spacing_m: f64) -> PyResult<Self> {
        Ok(Path {
            inner: CorePath::straight(length_m, spacing_m).map_err(path_error)?,
        })
    }

    /// A closed counter-clockwise circle through the origin heading +x.
    #[staticmethod]
    #[pyo3(signature = (radius_m, max_sagitta_m = 0.001))]
    fn circle(radius_m: f64, max_sagitta_m: f64) -> PyResult<Self> {
        Ok(Path {
            inner: CorePath::circle(radius_m, max_sagitta_m).map_err(path_error)?,
        })
    }

    /// The built-in closed test track (about 1.2 km, radii 25 to 40 m, clothoids).
    #[staticmethod]
    #[pyo3(signature = (spacing_m = 1.0))]
    fn test_track(spacing_m: f64) -> PyResult<Self> {
        Ok(Path {
            inner: CorePath::test_track(spacing_m).map_err(path_error)?,
        })
    }

    /// A copy with every coordinate and width multiplied by `factor`.
    fn scaled(&self, factor: f64) -> PyResult<Self> {
        Ok(Path {
            inner: self.inner.scaled(factor).map_err(path_error)?,
        })
    }

    #[getter]
    fn length_m(&self) -> f64 {
        self.inner.length()
    }
    #[getter]
    fn is_closed(&self) -> bool {
        self.inner.is_closed()
    }
    #[getter]
    fn has_widths(&self) -> bool {
        self.inner.widths().is_some()
    }
    fn __len__(&self) -> usize {
        self.inner.len_points()
    }

    /// The vertices as an (N, 2) array.
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let flat: Vec<f64> = self
            .inner
            .points()
            .iter()
            .flat_map(|p| [p.x, p.y])
            .collect();
        PyArray1::from_vec(py, flat)
            .reshape([self.inner.len_points(), 2])
            .expect("N*2 elements")
    }

    /// The (N, 2) widths (right, left), or None.
    fn widths<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.inner.widths().map(|w| {
            let flat: Vec<f64> = w.iter().flat_map(|w| [w.right_m, w.left_m]).collect();
            PyArray1::from_vec(py, flat)
                .reshape([w.len(), 2])
                .expect("N*2 elements")
        })
    }

    /// Arc length of each vertex.
    fn vertex_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.vertex_s())
    }

    /// Point (x, y) at arc length `s_m`.
    fn point_at(&self, s_m: f64) -> PyResult<(f64, f64)> {
        let p = self.inner.point_at(finite("s_m", s_m)?);
        Ok((p.x, p.y))
    }
    /// Tangent heading (rad) at `s_m`.
    fn heading_at(&self, s_m: f64) -> PyResult<f64> {
        Ok(self.inner.heading_at(finite("s_m", s_m)?))
    }
    /// Curvature (1/m, > 0 turning left) at `s_m`.
    fn curvature_at(&self, s_m: f64) -> PyResult<f64> {
        Ok(self.inner.curvature_at(finite("s_m", s_m)?))
    }

    /// Nearest point of the path to (x, y): dict with s_m, foot_x_m,
    /// foot_y_m, heading_rad, lateral_m (> 0 left), curvature_per_m.
    fn project<'py>(&self, py: Python<'py>, x_m: f64, y_m: f64) -> PyResult<Bound<'py, PyDict>> {
        let p = self.inner.project(&nalgebra::Point2::new(
            coordinate("x_m", x_m)?,
            coordinate("y_m", y_m)?,
        ));
        let d = PyDict::new(py);
        d.set_item("s_m", p.s)?;
        d.set_item("foot_x_m", p.foot.x)?;
        d.set_item("foot_y_m", p.foot.y)?;
        d.set_item("heading_rad", p.heading_rad)?;
        d.set_item("lateral_m", p.lateral_m)?;
        d.set_item("curvature_per_m", p.curvature_per_m)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "Path(points={}, length_m={:.3}, closed={}, widths={})",
            self.inner.len_points(),
            self.inner.length(),
            self.inner.is_closed(),
            self.inner.widths().is_some()
        )
    }
}
