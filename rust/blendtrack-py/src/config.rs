//! `ControllerConfig` and `VehicleParams` for Python: the core types held as
//! their serde image ([`Fields`]: a TOML table with every key of the core
//! type), converted to the core types (and validated there) when they are
//! used. No field is listed here: the core's structs are the one definition,
//! and attributes are read and set by name through the table.
//!
//! Attributes can be set freely (to a value of the key's type: number,
//! bool or string); the core validates them on use and on `validate()`,
//! with an error naming the key. `direction` is "forward" or "backward",
//! `lateral_controller` is "blend", "stanley" or "pure_pursuit". Keyword
//! constructors, `from_toml` and `to_toml` go through the core's serde
//! types, so unknown keys are `ConfigError`s that name them.

use crate::errors::{config_error, ConfigError as PyConfigError};
use blendtrack::config::{Config as CoreConfig, ControllerConfig as Core};
use blendtrack::vehicle::VehicleParams as CoreVehicle;
use pyo3::exceptions::{PyAttributeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PySet, PyString};
use serde::{de::DeserializeOwned, Serialize};

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
                    Err(_) => toml::Value::Float(v.extract().map_err(|_| {
                        PyConfigError::new_err(format!("`{key}`: integer too large for a float"))
                    })?),
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

/// A core config type's values by key: its TOML image, every key present
/// (the core serializes all of its fields). Read and written by name; turned
/// back into the core type, and validated there, on use.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Fields(toml::Table);

impl Fields {
    fn of<T: Serialize>(v: &T) -> PyResult<Fields> {
        toml::Table::try_from(v)
            .map(Fields)
            .map_err(|e| PyConfigError::new_err(e.to_string()))
    }

    /// The core value (deserialized, then checked by `validate`). A value
    /// the core type cannot hold (a name that is not one of its choices) is a
    /// ConfigError naming its key.
    fn to_core<T: DeserializeOwned + Serialize + Default>(
        &self,
        what: &str,
        validate: impl Fn(&T) -> Result<(), blendtrack::ConfigError>,
    ) -> PyResult<T> {
        let v: T = from_table(self.0.clone(), what).map_err(|e| self.name_bad_key::<T>(what, e))?;
        validate(&v).map_err(config_error)?;
        Ok(v)
    }

    /// `e`, or better the error of the first key that alone fails to
    /// deserialize (over the defaults), with the key and its value.
    fn name_bad_key<T: DeserializeOwned + Serialize + Default>(
        &self,
        what: &str,
        e: PyErr,
    ) -> PyErr {
        let Ok(Fields(defaults)) = Fields::of(&T::default()) else {
            return e;
        };
        for (key, value) in &self.0 {
            let mut one = defaults.clone();
            one.insert(key.clone(), value.clone());
            if let Err(err) = T::deserialize(toml::Value::Table(one)) {
                return PyConfigError::new_err(format!(
                    "{what}: config key `{key}` = {value}: {}",
                    err.to_string().trim_end().replace('\n', " | ")
                ));
            }
        }
        e
    }

    fn no_attribute(class: &str, name: &str) -> PyErr {
        PyAttributeError::new_err(format!("'{class}' object has no attribute '{name}'"))
    }

    fn get<'py>(&self, py: Python<'py>, class: &str, name: &str) -> PyResult<Bound<'py, PyAny>> {
        match self.0.get(name) {
            Some(v) => toml_to_py(py, v),
            None => Err(Self::no_attribute(class, name)),
        }
    }

    /// Sets a key to a value of its type (a number for a number, ...): the
    /// value itself is checked on use, as the core checks it.
    fn set(&mut self, class: &str, name: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let slot = self
            .0
            .get_mut(name)
            .ok_or_else(|| Self::no_attribute(class, name))?;
        *slot = match slot {
            toml::Value::Float(_) => toml::Value::Float(value.extract()?),
            toml::Value::Integer(_) => toml::Value::Integer(value.extract()?),
            toml::Value::Boolean(_) => toml::Value::Boolean(value.extract()?),
            toml::Value::String(_) => toml::Value::String(value.extract()?),
            other => {
                return Err(PyTypeError::new_err(format!(
                    "`{name}` holds a {} and cannot be set",
                    other.type_str()
                )))
            }
        };
        Ok(())
    }

    /// `Class(key=value, ...)` over `keys` (`...` closes the partial list),
    /// or over every key in the order the core declares its fields.
    fn repr<T: Serialize + Default>(&self, class: &str, keys: Option<&[&str]>) -> String {
        // The core's own serialization lists its fields in declaration order.
        let order = toml::to_string(&T::default()).unwrap_or_default();
        let all: Vec<&str> = order
            .lines()
            .filter_map(|l| l.split_once(" = ").map(|(k, _)| k))
            .collect();
        let shown = keys
            .unwrap_or(&all)
            .iter()
            .filter_map(|&k| {
                let v = match self.0.get(k)? {
                    toml::Value::Float(x) => x.to_string(),
                    toml::Value::String(s) => format!("{s:?}"),
                    other => other.to_string(),
                };
                Some(format!("{k}={v}"))
            })
            .collect::<Vec<_>>()
            .join(", ");
        let more = if keys.is_some() { ", ..." } else { "" };
        format!("{class}({shown}{more})")
    }

    fn dir(slf: &Bound<'_, PyAny>, fields: &Fields) -> PyResult<Vec<String>> {
        let mut names: Vec<String> = slf.get_type().dir()?.extract()?;
        names.extend(fields.0.keys().cloned());
        names.sort_unstable();
        Ok(names)
    }
}

/// The keys the `[table]` of a TOML file sets (none when it has no such table).
fn keys_in_file(file: &str, table: &str) -> PyResult<Vec<String>> {
    let doc: toml::Table = read_file(file)?.parse().map_err(|e: toml::de::Error| {
        PyConfigError::new_err(format!(
            "{file}: {}",
            e.to_string().trim_end().replace('\n', " | ")
        ))
    })?;
    Ok(match doc.get(table) {
        Some(toml::Value::Table(t)) => t.keys().cloned().collect(),
        _ => Vec::new(),
    })
}

/// Parameters of the lateral and longitudinal controllers (the paper's
/// Table 1 names plus the tuning the paper leaves open): the core's
/// `ControllerConfig`, attribute by attribute.
#[pyclass(module = "blendtrack", eq, from_py_object)]
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    fields: Fields,
}

const CONTROLLER: &str = "ControllerConfig";

impl From<&Core> for ControllerConfig {
    fn from(c: &Core) -> Self {
        // A core config always serializes (numbers, bools and names).
        ControllerConfig {
            fields: Fields::of(c).unwrap_or(Fields(toml::Table::new())),
        }
    }
}

/// The methods `ControllerConfig` and `VehicleParams` share: the same code
/// for both but for the core type, the class name, the validation and the
/// TOML table, so it is written once. The docs of `new` and `from_toml` and
/// the class's own methods come with each use.
macro_rules! config_class {
    (
        $class:ident, $core:ty, $name:expr, $validate:expr, $table:literal,
        new: { $(#[$new_doc:meta])* },
        from_toml: { $(#[$from_toml_doc:meta])* },
        { $($extra:tt)* }
    ) => {
        impl $class {
            /// The validated core configuration.
            pub(crate) fn to_core(&self) -> PyResult<$core> {
                self.fields.to_core($name, $validate)
            }

            fn with_kwargs(base: &$core, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
                let mut t = Fields::of(base)?.0;
                t.extend(dict_to_toml(kwargs)?);
                let c: $core = Fields(t).to_core($name, $validate)?;
                Ok(Self::from(&c))
            }

            /// The keys as TOML, without a table header.
            fn toml_text(&self) -> PyResult<String> {
                toml::to_string(&self.to_core()?).map_err(|e| PyConfigError::new_err(e.to_string()))
            }
        }

        #[pymethods]
        impl $class {
            $(#[$new_doc])*
            #[new]
            #[pyo3(signature = (**kwargs))]
            fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
                Self::with_kwargs(&<$core>::default(), kwargs)
            }

            fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
                self.fields.get(py, $name, name)
            }

            fn __setattr__(&mut self, name: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
                self.fields.set($name, name, value)
            }

            fn __delattr__(&mut self, name: &str) -> PyResult<()> {
                Err(PyAttributeError::new_err(format!(
                    "cannot delete attribute '{name}' of '{}'",
                    $name
                )))
            }

            fn __dir__(slf: &Bound<'_, Self>) -> PyResult<Vec<String>> {
                Fields::dir(slf.as_any(), &slf.borrow().fields)
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

            $(#[$from_toml_doc])*
            #[staticmethod]
            #[pyo3(signature = (text, source = "<string>"))]
            fn from_toml(text: &str, source: &str) -> PyResult<Self> {
                let t = parse_section(text, source, $table)?;
                let c: $core = Fields(t).to_core(source, $validate)?;
                Ok(Self::from(&c))
            }

            /// Reads a TOML file (see `from_toml`).
            #[staticmethod]
            fn load(file: std::path::PathBuf) -> PyResult<Self> {
                let name = file.display().to_string();
                Self::from_toml(&read_file(&name)?, &name)
            }

            fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
                to_dict(py, &self.to_core()?)
            }

            /// Pickling (worker processes of `blendtrack batch`, `run_scenario`'s
            /// child process): rebuilt from its TOML, validated again.
            fn __reduce__<'py>(
                slf: &Bound<'py, Self>,
            ) -> PyResult<(Bound<'py, PyAny>, (String, &'static str))> {
                let text = slf.borrow().toml_text()?;
                Ok((slf.get_type().getattr("from_toml")?, (text, "<pickle>")))
            }

            $($extra)*
        }
    };
}

config_class!(
    ControllerConfig, Core, CONTROLLER, Core::validate, "controller",
    new: {
        /// Defaults of the paper's tests #1-#3, overridden by keyword arguments
        /// (validated; unknown or out-of-range keys raise ConfigError).
    },
    from_toml: {
        /// Parses TOML: the `[controller]` table if there is one (a whole config
        /// file), else the top-level keys.
    },
    {
        /// The keys a config file sets in its `[controller]` table (to tell a
        /// user's explicit values from the defaults); empty without the table.
        #[staticmethod]
        fn keys_in_file<'py>(py: Python<'py>, file: std::path::PathBuf) -> PyResult<Bound<'py, PySet>> {
            PySet::new(py, keys_in_file(&file.display().to_string(), "controller")?)
        }

        /// A copy that drives with this control point: a blend factor in
        /// [0, 1] (`lat_blend_factor`, `alpha_mode = "fixed"`) or `"auto"`
        /// (`alpha_mode = "auto"`); `None` leaves the config as it is. The one
        /// place where `--alpha`, a vType's alpha and a sweep's `alpha` become
        /// config keys.
        fn with_alpha(&self, alpha: &Bound<'_, PyAny>) -> PyResult<Self> {
            let bad = || {
                let shown = alpha.repr().map(|r| r.to_string()).unwrap_or_default();
                PyConfigError::new_err(format!("alpha must be a number in [0, 1] or \"auto\", got {shown}"))
            };
            let kwargs = PyDict::new(alpha.py());
            if alpha.is_none() {
                return Ok(self.clone());
            } else if alpha.is_instance_of::<PyString>() {
                if alpha.extract::<String>()? != "auto" {
                    return Err(bad());
                }
                kwargs.set_item("alpha_mode", "auto")?;
            } else if alpha.is_instance_of::<PyBool>() {
                return Err(bad());
            } else {
                let a: f64 = alpha.extract().map_err(|_| bad())?;
                kwargs.set_item("lat_blend_factor", a)?;
                kwargs.set_item("alpha_mode", "fixed")?;
            }
            Self::with_kwargs(&self.to_core()?, Some(&kwargs))
        }

        /// The keys as TOML (a `[controller]` table when `table` is true).
        #[pyo3(signature = (table = false))]
        fn to_toml(&self, table: bool) -> PyResult<String> {
            let s = self.toml_text()?;
            Ok(if table { format!("[controller]\n{s}") } else { s })
        }

        fn __repr__(&self) -> String {
            let keys = [
                "lat_blend_factor",
                "direction",
                "lateral_controller",
                "preferred_speed",
            ];
            self.fields.repr::<Core>(CONTROLLER, Some(&keys))
        }

        fn __copy__(&self) -> Self {
            self.clone()
        }
        fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> Self {
            self.clone()
        }
    }
);

/// Physical limits of the vehicle (wheelbase, steering, acceleration,
/// speed): the core's `VehicleParams`, attribute by attribute.
#[pyclass(module = "blendtrack", eq, from_py_object)]
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleParams {
    fields: Fields,
}

const VEHICLE: &str = "VehicleParams";

impl From<&CoreVehicle> for VehicleParams {
    fn from(v: &CoreVehicle) -> Self {
        // Vehicle parameters always serialize (numbers).
        VehicleParams {
            fields: Fields::of(v).unwrap_or(Fields(toml::Table::new())),
        }
    }
}

config_class!(
    VehicleParams, CoreVehicle, VEHICLE, blendtrack::config::validate_vehicle, "vehicle",
    new: {
        /// Defaults (wheelbase 2.6 m, 40 deg, 30 deg/s, ...) overridden by keywords.
    },
    from_toml: {
        /// Parses TOML: the `[vehicle]` table if there is one, else the top-level keys.
    },
    {
        fn to_toml(&self) -> PyResult<String> {
            self.toml_text()
        }

        fn __repr__(&self) -> String {
            self.fields.repr::<CoreVehicle>(VEHICLE, None)
        }
    }
);

/// Loads a whole config file (`[controller]` and `[vehicle]` tables).
#[pyfunction]
pub(crate) fn load_config(file: std::path::PathBuf) -> PyResult<(ControllerConfig, VehicleParams)> {
    let c = CoreConfig::load(&file).map_err(config_error)?;
    Ok((
        ControllerConfig::from(&c.controller),
        VehicleParams::from(&c.vehicle),
    ))
}
