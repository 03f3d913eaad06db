//! `ControllerConfig` and `VehicleParams` for Python: plain attribute holders
//! under the paper's names, converted to the core types (and validated there)
//! when they are used.
//!
//! Attributes can be set freely; the core validates them on use and on
//! `validate()`, with an error naming the key. `direction` is "forward" or
//! "backward", `lateral_controller` is "blend", "stanley" or "pure_pursuit".
//! Keyword constructors, `from_toml` and `to_toml` go through the core's serde
//! types, so unknown keys are `ConfigError`s that name them.

use crate::errors::{config_error, ConfigError as PyConfigError};
use blendtrack::config::{AlphaMode, Config as CoreConfig, ControllerConfig as Core, LateralKind};
use blendtrack::vehicle::{Direction, VehicleParams as CoreVehicle};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyString};

/// Python dict -> TOML table (bool, int, float, str values).
pub(crate) fn dict_to_toml(d: Option<&Bound<'_, PyDict>>) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    if let Some(d) = d {
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            let val = if v.is_instance_of::<PyBool>() {
                toml::Value::Boolean(v.extract()?)
            } else if v.is_instance_of::<PyInt>() {
                match v.extract::<i64>() {
                    Ok(i) => toml::Value::Integer(i),
                    Err(_) => toml::Value::Float(v.extract()?),
                }
            } else if v.is_instance_of::<PyFloat>() {
                toml::Value::Float(v.extract()?)
            } else if v.is_instance_of::<PyString>() {
                toml::Value::String(v.extract()?)
            } else if let Ok(f) = v.extract::<f64>() {
                // numpy scalars and other numbers.
                toml::Value::Float(f)
            } else {
                return Err(PyTypeError::new_err(format!(
                    "`{key}`: unsupported value type {}",
                    v.get_type().name()?
                )));
            };
            t.insert(key, val);
        }
    }
    Ok(t)
}

/// Deserializes a core type from a TOML table; errors name the key.
pub(crate) fn from_table<T: serde::de::DeserializeOwned>(
    t: toml::Table,
    what: &str,
) -> PyResult<T> {
    T::deserialize(toml::Value::Table(t)).map_err(|e| {
        PyConfigError::new_err(format!(
            "{what}: {}",
            e.to_string().trim_end().replace('\n', " | ")
        ))
    })
}

/// TOML value -> Python object.
fn toml_to_py<'py>(py: Python<'py>, v: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        toml::Value::Boolean(b) => PyBool::new(py, *b).to_owned().into_any(),
        toml::Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        toml::Value::Float(f) => f.into_pyobject(py)?.into_any(),
        toml::Value::String(s) => s.into_pyobject(py)?.into_any(),
        other => other.to_string().into_pyobject(py)?.into_any(),
    })
}

fn to_dict<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyDict>> {
    let t = toml::Table::try_from(v).map_err(|e| PyConfigError::new_err(e.to_string()))?;
    let d = PyDict::new(py);
    for (k, v) in &t {
        d.set_item(k, toml_to_py(py, v)?)?;
    }
    Ok(d)
}

/// Parses TOML text: the `[table]` if the document has one, else its top-level keys.
fn parse_section(text: &str, source: &str, table: &str) -> PyResult<toml::Table> {
    let mut doc: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        PyConfigError::new_err(format!(
            "{source}: {}",
            e.to_string().trim_end().replace('\n', " | ")
        ))
    })?;
    match doc.remove(table) {
        Some(toml::Value::Table(t)) => Ok(t),
        Some(_) => Err(PyConfigError::new_err(format!(
            "{source}: `{table}` must be a table"
        ))),
        None => Ok(doc),
    }
}

fn read_file(file: &str) -> PyResult<String> {
    std::fs::read_to_string(file)
        .map_err(|e| PyConfigError::new_err(format!("cannot read config file {file}: {e}")))
}

/// Parameters of the lateral and longitudinal controllers (the paper's
/// Table 1 names plus the tuning the paper leaves open).
#[pyclass(module = "blendtrack", get_all, set_all, eq, from_py_object)]
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    pub lat_blend_factor: f64,
    pub acceleration_exp: f64,
    pub deceleration_factor: f64,
    pub max_deceleration: f64,
    pub max_obs_deceleration: f64,
    pub path_width_m: f64,
    pub preferred_acceleration: f64,
    pub preferred_deceleration: f64,
    pub preferred_speed: f64,
    pub preferred_stop_dist: f64,
    pub reaction_time: f64,
    pub direction: String,
    pub lateral_controller: String,
    pub stanley_gain: f64,
    pub stanley_gain_reverse: f64,
    pub stanley_softening_mps: f64,
    pub target_distance_min_m: f64,
    pub target_distance_gain_s: f64,
    pub curvature_lookahead_gain_s: f64,
    pub pure_pursuit_gain_s: f64,
    pub pure_pursuit_min_lookahead_m: f64,
    pub use_path_widths: bool,
    pub border_margin_m: f64,
    pub ray_horizon_m: f64,
    pub alpha_mode: String,
    pub auto_alpha_forward: f64,
    pub auto_alpha_backward: f64,
    pub auto_alpha_curve_gain: f64,
    pub auto_alpha_curvature_change_gain: f64,
    pub auto_alpha_preview_s: f64,
    pub auto_alpha_large_error_m: f64,
    pub auto_alpha_error_gain: f64,
}

fn direction_name(d: Direction) -> &'static str {
    match d {
        Direction::Forward => "forward",
        Direction::Backward => "backward",
    }
}

fn lateral_name(k: LateralKind) -> &'static str {
    match k {
        LateralKind::Blend => "blend",
        LateralKind::Stanley => "stanley",
        LateralKind::PurePursuit => "pure_pursuit",
    }
}

impl From<&Core> for ControllerConfig {
    fn from(c: &Core) -> Self {
        ControllerConfig {
            lat_blend_factor: c.lat_blend_factor,
            acceleration_exp: c.acceleration_exp,
            deceleration_factor: c.deceleration_factor,
            max_deceleration: c.max_deceleration,
            max_obs_deceleration: c.max_obs_deceleration,
            path_width_m: c.path_width_m,
            preferred_acceleration: c.preferred_acceleration,
            preferred_deceleration: c.preferred_deceleration,
            preferred_speed: c.preferred_speed,
            preferred_stop_dist: c.preferred_stop_dist,
            reaction_time: c.reaction_time,
            direction: direction_name(c.direction).to_string(),
            lateral_controller: lateral_name(c.lateral_controller).to_string(),
            stanley_gain: c.stanley_gain,
            stanley_gain_reverse: c.stanley_gain_reverse,
            stanley_softening_mps: c.stanley_softening_mps,
            target_distance_min_m: c.target_distance_min_m,
            target_distance_gain_s: c.target_distance_gain_s,
            curvature_lookahead_gain_s: c.curvature_lookahead_gain_s,
            pure_pursuit_gain_s: c.pure_pursuit_gain_s,
            pure_pursuit_min_lookahead_m: c.pure_pursuit_min_lookahead_m,
            use_path_widths: c.use_path_widths,
            border_margin_m: c.border_margin_m,
            ray_horizon_m: c.ray_horizon_m,
            alpha_mode: match c.alpha_mode {
                AlphaMode::Fixed => "fixed",
                AlphaMode::Auto => "auto",
            }
            .to_string(),
            auto_alpha_forward: c.auto_alpha_forward,
            auto_alpha_backward: c.auto_alpha_backward,
            auto_alpha_curve_gain: c.auto_alpha_curve_gain,
            auto_alpha_curvature_change_gain: c.auto_alpha_curvature_change_gain,
            auto_alpha_preview_s: c.auto_alpha_preview_s,
            auto_alpha_large_error_m: c.auto_alpha_large_error_m,
            auto_alpha_error_gain: c.auto_alpha_error_gain,
        }
    }
}

impl ControllerConfig {
    /// The validated core configuration.
    pub(crate) fn to_core(&self) -> PyResult<Core> {
        let direction = match self.direction.as_str() {
            "forward" => Direction::Forward,
            "backward" => Direction::Backward,
            other => {
                return Err(PyConfigError::new_err(format!(
                    "config key `direction` = {other:?}: must be \"forward\" or \"backward\""
                )))
            }
        };
        let lateral_controller = match self.lateral_controller.as_str() {
            "blend" => LateralKind::Blend,
            "stanley" => LateralKind::Stanley,
            "pure_pursuit" => LateralKind::PurePursuit,
            other => {
                return Err(PyConfigError::new_err(format!(
                    "config key `lateral_controller` = {other:?}: must be \"blend\", \"stanley\" or \"pure_pursuit\""
                )))
            }
        };
        let alpha_mode = match self.alpha_mode.as_str() {
            "fixed" => AlphaMode::Fixed,
            "auto" => AlphaMode::Auto,
            other => {
                return Err(PyConfigError::new_err(format!(
                    "config key `alpha_mode` = {other:?}: must be \"fixed\" or \"auto\""
                )))
            }
        };
        let c = Core {
            lat_blend_factor: self.lat_blend_factor,
            acceleration_exp: self.acceleration_exp,
            deceleration_factor: self.deceleration_factor,
            max_deceleration: self.max_deceleration,
            max_obs_deceleration: self.max_obs_deceleration,
            path_width_m: self.path_width_m,
            preferred_acceleration: self.preferred_acceleration,
            preferred_deceleration: self.preferred_deceleration,
            preferred_speed: self.preferred_speed,
            preferred_stop_dist: self.preferred_stop_dist,
            reaction_time: self.reaction_time,
            direction,
            lateral_controller,
            stanley_gain: self.stanley_gain,
            stanley_gain_reverse: self.stanley_gain_reverse,
            stanley_softening_mps: self.stanley_softening_mps,
            target_distance_min_m: self.target_distance_min_m,
            target_distance_gain_s: self.target_distance_gain_s,
            curvature_lookahead_gain_s: self.curvature_lookahead_gain_s,
            pure_pursuit_gain_s: self.pure_pursuit_gain_s,
            pure_pursuit_min_lookahead_m: self.pure_pursuit_min_lookahead_m,
            use_path_widths: self.use_path_widths,
            border_margin_m: self.border_margin_m,
            ray_horizon_m: self.ray_horizon_m,
            alpha_mode,
            auto_alpha_forward: self.auto_alpha_forward,
            auto_alpha_backward: self.auto_alpha_backward,
            auto_alpha_curve_gain: self.auto_alpha_curve_gain,
            auto_alpha_curvature_change_gain: self.auto_alpha_curvature_change_gain,
            auto_alpha_preview_s: self.auto_alpha_preview_s,
            auto_alpha_large_error_m: self.auto_alpha_large_error_m,
            auto_alpha_error_gain: self.auto_alpha_error_gain,
        };
        c.validate().map_err(config_error)?;
        Ok(c)
    }

    fn with_kwargs(base: &Core, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut t =
            toml::Table::try_from(base).map_err(|e| PyConfigError::new_err(e.to_string()))?;
        t.extend(dict_to_toml(kwargs)?);
        let c: Core = from_table(t, "ControllerConfig")?;
        c.validate().map_err(config_error)?;
        Ok(Self::from(&c))
    }
}

#[pymethods]
impl ControllerConfig {
    /// Defaults of the paper's tests #1-#3, overridden by keyword arguments
    /// (validated; unknown or out-of-range keys raise ConfigError).
    #[new]
    #[pyo3(signature = (**kwargs))]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        Self::with_kwargs(&Core::default(), kwargs)
    }

    /// A validated copy with some keys changed.
    #[pyo3(signature = (**kwargs))]
    fn replace(&self, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        Self::with_kwargs(&self.to_core()?, kwargs)
    }

    /// Raises ConfigError naming the first invalid key.
    fn validate(&self) -> PyResult<()> {
        self.to_core().map(|_| ())
    }

    /// Parses TOML: the `[controller]` table if there is one (a whole config
    /// file), else the top-level keys.
    #[staticmethod]
    #[pyo3(signature = (text, source = "<string>"))]
    fn from_toml(text: &str, source: &str) -> PyResult<Self> {
        let t = parse_section(text, source, "controller")?;
        let c: Core = from_table(t, source)?;
        c.validate().map_err(config_error)?;
        Ok(Self::from(&c))
    }

    /// Reads a TOML file (see `from_toml`).
    #[staticmethod]
    fn load(file: std::path::PathBuf) -> PyResult<Self> {
        let name = file.display().to_string();
        Self::from_toml(&read_file(&name)?, &name)
    }

    /// The keys as TOML (a `[controller]` table when `table` is true).
    #[pyo3(signature = (table = false))]
    fn to_toml(&self, table: bool) -> PyResult<String> {
        let c = self.to_core()?;
        if table {
            toml::to_string(&c)
                .map(|s| format!("[controller]\n{s}"))
                .map_err(|e| PyConfigError::new_err(e.to_string()))
        } else {
            toml::to_string(&c).map_err(|e| PyConfigError::new_err(e.to_string()))
        }
    }

    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        to_dict(py, &self.to_core()?)
    }

    fn __repr__(&self) -> String {
        format!(
            "ControllerConfig(lat_blend_factor={}, direction={:?}, lateral_controller={:?}, preferred_speed={}, ...)",
            self.lat_blend_factor, self.direction, self.lateral_controller, self.preferred_speed
        )
    }

    fn __copy__(&self) -> Self {
        self.clone()
    }
    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> Self {
        self.clone()
    }

    /// Pickling (worker processes of `blendtrack batch`, `run_scenario`'s
    /// child process): rebuilt from its TOML, validated again.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (String, &'static str))> {
        let text = slf.borrow().to_toml(false)?;
        Ok((slf.get_type().getattr("from_toml")?, (text, "<pickle>")))
    }
}

/// Physical limits of the vehicle (wheelbase, steering, acceleration, speed).
#[pyclass(module = "blendtrack", get_all, set_all, eq, from_py_object)]
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleParams {
    pub wheelbase_m: f64,
    pub max_steering_deg: f64,
    pub max_steering_rate_deg_s: f64,
    pub max_acceleration_mps2: f64,
    pub max_braking_mps2: f64,
    pub max_speed_mps: f64,
}

impl From<&CoreVehicle> for VehicleParams {
    fn from(v: &CoreVehicle) -> Self {
        VehicleParams {
            wheelbase_m: v.wheelbase_m,
            max_steering_deg: v.max_steering_deg,
            max_steering_rate_deg_s: v.max_steering_rate_deg_s,
            max_acceleration_mps2: v.max_acceleration_mps2,
            max_braking_mps2: v.max_braking_mps2,
            max_speed_mps: v.max_speed_mps,
        }
    }
}

impl VehicleParams {
    pub(crate) fn to_core(&self) -> PyResult<CoreVehicle> {
        let v = CoreVehicle {
            wheelbase_m: self.wheelbase_m,
            max_steering_deg: self.max_steering_deg,
            max_steering_rate_deg_s: self.max_steering_rate_deg_s,
            max_acceleration_mps2: self.max_acceleration_mps2,
            max_braking_mps2: self.max_braking_mps2,
            max_speed_mps: self.max_speed_mps,
        };
        blendtrack::config::validate_vehicle(&v).map_err(config_error)?;
        Ok(v)
    }

    fn with_kwargs(base: &CoreVehicle, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut t =
            toml::Table::try_from(base).map_err(|e| PyConfigError::new_err(e.to_string()))?;
        t.extend(dict_to_toml(kwargs)?);
        let v: CoreVehicle = from_table(t, "VehicleParams")?;
        blendtrack::config::validate_vehicle(&v).map_err(config_error)?;
        Ok(Self::from(&v))
    }
}

#[pymethods]
impl VehicleParams {
    /// Defaults (wheelbase 2.6 m, 40 deg, 30 deg/s, ...) overridden by keywords.
    #[new]
    #[pyo3(signature = (**kwargs))]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        Self::with_kwargs(&CoreVehicle::default(), kwargs)
    }

    #[pyo3(signature = (**kwargs))]
    fn replace(&self, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        Self::with_kwargs(&self.to_core()?, kwargs)
    }

    fn validate(&self) -> PyResult<()> {
        self.to_core().map(|_| ())
    }

    /// Parses TOML: the `[vehicle]` table if there is one, else the top-level keys.
    #[staticmethod]
    #[pyo3(signature = (text, source = "<string>"))]
    fn from_toml(text: &str, source: &str) -> PyResult<Self> {
        let t = parse_section(text, source, "vehicle")?;
        let v: CoreVehicle = from_table(t, source)?;
        blendtrack::config::validate_vehicle(&v).map_err(config_error)?;
        Ok(Self::from(&v))
    }

    #[staticmethod]
    fn load(file: std::path::PathBuf) -> PyResult<Self> {
        let name = file.display().to_string();
        Self::from_toml(&read_file(&name)?, &name)
    }

    fn to_toml(&self) -> PyResult<String> {
        toml::to_string(&self.to_core()?).map_err(|e| PyConfigError::new_err(e.to_string()))
    }

    /// Pickling: rebuilt from its TOML, validated again.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (String, &'static str))> {
        let text = slf.borrow().to_toml()?;
        Ok((slf.get_type().getattr("from_toml")?, (text, "<pickle>")))
    }

    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        to_dict(py, &self.to_core()?)
    }

    fn __repr__(&self) -> String {
        format!(
            "VehicleParams(wheelbase_m={}, max_steering_deg={}, max_steering_rate_deg_s={}, max_acceleration_mps2={}, max_braking_mps2={}, max_speed_mps={})",
            self.wheelbase_m, self.max_steering_deg, self.max_steering_rate_deg_s, self.max_acceleration_mps2, self.max_braking_mps2, self.max_speed_mps
        )
    }
}

/// Loads a whole config file (`[controller]` and `[vehicle]` tables).
#[pyfunction]
pub(crate) fn load_config(file: std::path::PathBuf) -> PyResult<(ControllerConfig, VehicleParams)> {
    let c = CoreConfig::load(&file).map_err(config_error)?;
    Ok((
        ControllerConfig::from(&c.controller),
        VehicleParams::from(&c.vehicle),
    ))
}
