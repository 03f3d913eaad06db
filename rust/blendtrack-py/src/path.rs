//! `Path` for Python: a reference track built from a numpy array, a TUM csv
//! file or a built-in generator. Immutable; `scaled` returns a new one.

use crate::errors::path_error;
use blendtrack::path::{Path as CorePath, Widths};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A reference path: polyline with arc length, optional per-point widths.
#[pyclass(module = "blendtrack", frozen, from_py_object)]
#[derive(Debug, Clone)]
pub struct Path {
    pub(crate) inner: CorePath,
}

fn rows(a: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<Vec<[f64; 2]>> {
    let shape = a.shape();
    if shape[1] != 2 {
        return Err(crate::errors::input_error(format!(
            "`{name}` must have shape (N, 2), got ({}, {})",
            shape[0], shape[1]
        )));
    }
    let v = a.as_array();
    Ok((0..shape[0]).map(|i| [v[[i, 0]], v[[i, 1]]]).collect())
}

#[pymethods]
impl Path {
    /// From an (N, 2) array of x, y (m); `widths` (N, 2) = right, left (m).
    #[new]
    #[pyo3(signature = (points, widths = None, closed = false))]
    fn new(
        points: PyReadonlyArray2<'_, f64>,
        widths: Option<PyReadonlyArray2<'_, f64>>,
        closed: bool,
    ) -> PyResult<Self> {
        let pts = rows(&points, "points")?;
        let ws: Option<Vec<Widths>> = match widths {
            Some(w) => Some(
                rows(&w, "widths")?
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
    fn point_at(&self, s_m: f64) -> (f64, f64) {
        let p = self.inner.point_at(s_m);
        (p.x, p.y)
    }
    /// Tangent heading (rad) at `s_m`.
    fn heading_at(&self, s_m: f64) -> f64 {
        self.inner.heading_at(s_m)
    }
    /// Curvature (1/m, > 0 turning left) at `s_m`.
    fn curvature_at(&self, s_m: f64) -> f64 {
        self.inner.curvature_at(s_m)
    }

    /// Nearest point of the path to (x, y): dict with s_m, foot_x_m,
    /// foot_y_m, heading_rad, lateral_m (> 0 left), curvature_per_m.
    fn project<'py>(&self, py: Python<'py>, x_m: f64, y_m: f64) -> PyResult<Bound<'py, PyDict>> {
        let p = self.inner.project(&nalgebra::Point2::new(x_m, y_m));
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
