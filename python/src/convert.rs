//! Values across the boundary: Python settings into TOML tables (the configuration format of
//! every env and of the trainer), infos and frames into Python objects, arrays into `f32` rows.

use crate::errors::{ActionError, ConfigError};
use fairgrasp_env::core::Frame;
use fairgrasp_env::spaces::ImageSpace;
use fairgrasp_env::{EpisodeEvent, Info};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

/// A Python value as a TOML value; `key` names it in errors.
pub fn to_toml(key: &str, value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    if value.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(value.extract()?));
    }
    if value.is_instance_of::<PyInt>() {
        return value
            .extract::<i64>()
            .map(toml::Value::Integer)
            .map_err(|_| {
                ConfigError::new_err(format!("invalid setting `{key}`: {value} is too large"))
            });
    }
    if value.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(value.extract()?));
    }
    if value.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(value.extract()?));
    }
    if let Ok(dict) = value.cast::<PyDict>() {
        let mut table = toml::Table::new();
        apply_settings(&mut table, key, dict)?;
        return Ok(toml::Value::Table(table));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items = value
            .try_iter()?
            .enumerate()
            .map(|(i, item)| to_toml(&format!("{key}[{i}]"), &item?))
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(toml::Value::Array(items));
    }
    // numpy scalars and arrays: through their Python equivalents.
    if value.hasattr("tolist")? {
        return to_toml(key, &value.call_method0("tolist")?);
    }
    Err(ConfigError::new_err(format!(
        "invalid setting `{key}`: a {} cannot be a setting (use bool, int, float, str, list or dict)",
        value.get_type().name()?
    )))
}

/// Applies a dict of settings to `table`: nested dicts are sections (`{"control":
/// {"action_mode": "cartesian"}}`), a key with dots sets that key (`{"control.action_mode":
/// "cartesian"}`), and None unsets a key (its default applies). `prefix` names the dict's
/// section in errors.
pub fn apply_settings(
    table: &mut toml::Table,
    prefix: &str,
    dict: &Bound<'_, PyDict>,
) -> PyResult<()> {
    for (key, value) in dict.iter() {
        let key: String = key.extract().map_err(|_| {
            ConfigError::new_err(format!(
                "invalid setting under `{prefix}`: keys must be strings, got {key}"
            ))
        })?;
        let path = if prefix.is_empty() {
            key.clone()
        } else {
            format!("{prefix}.{key}")
        };
        if value.is_none() {
            remove_path(table, &key);
        } else if let Ok(inner) = value.cast::<PyDict>() {
            let section = section_at(table, &key, &path)?;
            apply_settings(section, &path, inner)?;
        } else {
            insert_path(table, &key, to_toml(&path, &value)?, &path)?;
        }
    }
    Ok(())
}

/// A dict of settings as a TOML table (see [`apply_settings`]).
pub fn table_from_dict(dict: &Bound<'_, PyDict>) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    apply_settings(&mut table, "", dict)?;
    Ok(table)
}

/// The section at `dotted`, created if missing.
fn section_at<'t>(
    table: &'t mut toml::Table,
    dotted: &str,
    full: &str,
) -> PyResult<&'t mut toml::Table> {
    let mut current = table;
    for part in dotted.split('.') {
        if part.is_empty() {
            return Err(ConfigError::new_err(format!(
                "invalid setting `{full}`: empty key segment"
            )));
        }
        let entry = current
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        current = entry.as_table_mut().ok_or_else(|| {
            ConfigError::new_err(format!(
                "invalid setting `{full}`: `{part}` is a value, not a section"
            ))
        })?;
    }
    Ok(current)
}

/// Removes `dotted` from `table` if it is there.
fn remove_path(table: &mut toml::Table, dotted: &str) {
    match dotted.split_once('.') {
        None => {
            table.remove(dotted);
        }
        Some((head, rest)) => {
            if let Some(toml::Value::Table(inner)) = table.get_mut(head) {
                remove_path(inner, rest);
            }
        }
    }
}

/// Sets `dotted` (`a.b.c`) in `table`, creating sections as needed; `full` names it in errors.
pub fn insert_path(
    table: &mut toml::Table,
    dotted: &str,
    value: toml::Value,
    full: &str,
) -> PyResult<()> {
    let (sections, last) = match dotted.rsplit_once('.') {
        Some((sections, last)) => (section_at(table, sections, full)?, last),
        None => (table, dotted),
    };
    if last.is_empty() {
        return Err(ConfigError::new_err(format!(
            "invalid setting `{full}`: empty key segment"
        )));
    }
    sections.insert(last.to_string(), value);
    Ok(())
}

/// `(low, high)` of a space as float32 arrays.
pub type Bounds<'py> = (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>);

pub fn bounds<'py>(py: Python<'py>, space: &fairgrasp_env::spaces::BoxSpace) -> Bounds<'py> {
    (
        PyArray1::from_slice(py, &space.low),
        PyArray1::from_slice(py, &space.high),
    )
}

/// An observation as Gymnasium sees it: the float32 state vector, or with camera images a dict
/// of it (`state`) and one `H×W×C` uint8 array per view (`scene_rgb`, …), `images` holding
/// the views one after another.
pub fn observation<'py>(
    py: Python<'py>,
    obs: Vec<f32>,
    images: Option<(&ImageSpace, &[u8])>,
) -> PyResult<Bound<'py, PyAny>> {
    let state = PyArray1::from_vec(py, obs).into_any();
    let Some((space, bytes)) = images else {
        return Ok(state);
    };
    let dict = PyDict::new(py);
    dict.set_item("state", state)?;
    for (i, view) in space.views.iter().enumerate() {
        let shape = [
            view.height as usize,
            view.width as usize,
            view.channels as usize,
        ];
        let pixels = PyArray1::from_slice(py, &bytes[space.range(i)]).reshape(shape)?;
        dict.set_item(&view.name, pixels)?;
    }
    Ok(dict.into_any())
}

/// A batch of `n` observations: an `(n, obs_dim)` float32 array, or with camera images a dict
/// of it (`state`) and one `(n, H, W, C)` uint8 array per view. `images` holds each env's
/// views one after another, env after env.
pub fn batch_observation<'py>(
    py: Python<'py>,
    n: usize,
    obs: Vec<f32>,
    space: Option<&ImageSpace>,
    images: &[u8],
) -> PyResult<Bound<'py, PyAny>> {
    let obs_dim = obs.len() / n.max(1);
    let state = PyArray1::from_vec(py, obs)
        .reshape([n, obs_dim])?
        .into_any();
    let Some(space) = space else {
        return Ok(state);
    };
    let dict = PyDict::new(py);
    dict.set_item("state", state)?;
    let per_env = space.len();
    for (i, view) in space.views.iter().enumerate() {
        let range = space.range(i);
        let mut pixels = Vec::with_capacity(n * view.len());
        for env in images.chunks_exact(per_env.max(1)).take(n) {
            pixels.extend_from_slice(&env[range.clone()]);
        }
        let shape = [
            n,
            view.height as usize,
            view.width as usize,
            view.channels as usize,
        ];
        dict.set_item(&view.name, PyArray1::from_vec(py, pixels).reshape(shape)?)?;
    }
    Ok(dict.into_any())
}

/// `(observation, info)`, what `reset` returns.
pub fn obs_info<'py>(
    py: Python<'py>,
    obs: Bound<'py, PyAny>,
    info: &Info,
) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(py, [obs, info_dict(py, info)?.into_any()])
}

/// Gymnasium's `metadata` dict: `render_modes` and `render_fps`.
pub fn metadata_dict<'py>(
    py: Python<'py>,
    meta: &fairgrasp_env::core::Metadata,
) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    let modes: Vec<&str> = meta
        .render_modes
        .iter()
        .map(|m| render_mode_name(*m))
        .collect();
    dict.set_item("render_modes", modes)?;
    dict.set_item("render_fps", meta.render_fps)?;
    Ok(dict)
}

pub fn render_mode_name(mode: fairgrasp_env::core::RenderMode) -> &'static str {
    use fairgrasp_env::core::RenderMode;
    match mode {
        RenderMode::Ansi => "ansi",
        RenderMode::RgbArray => "rgb_array",
        RenderMode::DepthArray => "depth_array",
        RenderMode::SegmentationArray => "segmentation_array",
    }
}

/// `Info` as Gymnasium's info dict: `is_success` (SB3's key), `elapsed_steps`, the task's extras
/// by name, `reward_terms`, `events` and, where the env reports one, `privileged` (float32: for
/// a critic only).
pub fn info_dict<'py>(py: Python<'py>, info: &Info) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    dict.set_item("is_success", info.success)?;
    dict.set_item("elapsed_steps", info.elapsed_steps)?;
    for (name, value) in info.extras.iter() {
        dict.set_item(name, value)?;
    }
    let terms = PyDict::new(py);
    for (name, value) in info.reward_terms.iter() {
        terms.set_item(name, value)?;
    }
    dict.set_item("reward_terms", terms)?;
    let events: Vec<&str> = info.events.iter().map(|e| event_name(*e)).collect();
    dict.set_item("events", events)?;
    if !info.privileged.is_empty() {
        dict.set_item("privileged", PyArray1::from_slice(py, &info.privileged))?;
    }
    Ok(dict)
}

fn event_name(event: EpisodeEvent) -> &'static str {
    match event {
        EpisodeEvent::ObjectOffTable => "object_off_table",
        EpisodeEvent::NonFiniteState => "non_finite_state",
        EpisodeEvent::IkFailed => "ik_failed",
        EpisodeEvent::ObjectMisplaced => "object_misplaced",
        EpisodeEvent::Collision => "collision",
    }
}

/// A rendered frame as numpy (`H×W×3` uint8 RGB, `H×W` float32 depth, `H×W` uint16 segment
/// ids) or text.
pub fn frame_object<'py>(py: Python<'py>, frame: Frame) -> PyResult<Bound<'py, PyAny>> {
    fn image<'py, T: numpy::Element>(
        py: Python<'py>,
        data: Vec<T>,
        shape: &[usize],
    ) -> PyResult<Bound<'py, PyAny>> {
        Ok(PyArray1::from_vec(py, data).reshape(shape)?.into_any())
    }
    match frame {
        Frame::Text(text) => Ok(PyString::new(py, &text).into_any()),
        Frame::Rgb {
            width,
            height,
            data,
        } => image(py, data, &[height as usize, width as usize, 3]),
        Frame::Depth {
            width,
            height,
            data,
        } => image(py, data, &[height as usize, width as usize]),
        Frame::Segmentation {
            width,
            height,
            data,
        } => image(py, data, &[height as usize, width as usize]),
    }
}

/// `rows × cols` f32 values from a numpy array or a sequence. `shape` is what is expected, for
/// the error; `what` names the value ("action", "observation").
pub fn f32_values(value: &Bound<'_, PyAny>, what: &str, shape: &[usize]) -> PyResult<Vec<f32>> {
    let expected: usize = shape.iter().product();
    let wrong = |got: String| {
        let message =
            format!("invalid {what}: expected shape {shape:?} ({expected} values), got {got}");
        if what.starts_with("action") {
            ActionError::new_err(message)
        } else {
            pyo3::exceptions::PyValueError::new_err(message)
        }
    };
    if let Ok(array) = value.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        let dims = array.shape().to_vec();
        if dims != shape {
            return Err(wrong(format!("shape {dims:?}")));
        }
        return Ok(match array.as_slice() {
            Ok(slice) => slice.to_vec(),
            Err(_) => array.as_array().iter().copied().collect(),
        });
    }
    // Anything else numpy can read as float32 (float64 arrays, lists, scalars).
    let numpy = value.py().import("numpy")?;
    let converted = numpy
        .call_method1("asarray", (value, numpy.getattr("float32")?))
        .map_err(|e| wrong(format!("a value numpy cannot read as float32 ({e})")))?;
    let array: PyReadonlyArrayDyn<'_, f32> = converted.extract()?;
    let dims = array.shape().to_vec();
    if dims != shape {
        return Err(wrong(format!("shape {dims:?}")));
    }
    Ok(array.as_array().iter().copied().collect())
}
