//! Saved models. A model directory is self-contained: `model.safetensors` (the weights of every
//! network) and `model.json` ([`ModelMeta`]: algorithm and its settings, network sizes, the
//! environment it was trained on, observation normalisation statistics).
//! [`crate::Policy`] loads one to act.
//!
//! Directories are replaced whole (written beside the target, then renamed over it), so a crash
//! while saving leaves the previous model readable.

use crate::algo::{Algo, AlgoConfig};
use crate::algorithm::TensorMap;
use crate::error::{Result, RlError};
use crate::policies::pixel_actor::PixelActorConfig;
use candle_core::Device;
use fairgrasp_env::atomic;
use fairgrasp_env::spaces::ImageSpace;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Version of the `model.json` layout this build writes.
pub const FORMAT_VERSION: u32 = 2;
/// Versions of the `model.json` layout this build reads: 1 (before environments were named by
/// id: always the grasp task) and 2.
pub const READABLE_FORMAT_VERSIONS: [u32; 2] = [1, 2];
/// The environment of every format-1 model.
const V1_ENV_ID: &str = "FaArmGrasp-v0";

/// What a saved model needs besides its weights (`model.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelMeta {
    /// Layout version of this file (see [`FORMAT_VERSION`]).
    pub format_version: u32,
    /// The algorithm and its settings: `"algo": "sac"` beside a `"sac"` object.
    #[serde(flatten)]
    pub algo: AlgoConfig,
    /// Observation width.
    pub obs_dim: usize,
    /// Action width.
    pub act_dim: usize,
    /// Id of the environment the model was trained on (`"FaArmGrasp-v0"`).
    pub env_id: String,
    /// Its configuration, as the environment registry writes and parses it (opaque here).
    pub env: serde_json::Value,
    /// Observation normalisation statistics (JSON of [`fairgrasp_env::wrappers::VecNormalizeState`]), if used.
    pub normalization: Option<String>,
    /// Environment steps the model was trained for.
    pub num_timesteps: u64,
    /// Seed of the training environments (to keep evaluation seeds apart).
    #[serde(default)]
    pub train_seed: u64,
    /// Number of training environments (likewise).
    #[serde(default)]
    pub n_envs: usize,
    /// Privileged values the value network reads after the observation (`ppo.privileged_critic`;
    /// 0: none). The policy never reads them.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub privileged_dim: usize,
    /// A camera policy (distilled from a teacher; `algo` is then the teacher's): its network and
    /// the images it reads beside the `obs_dim` state values. `None`: the actor of `algo`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_actor: Option<PixelActorMeta>,
}

/// What a camera policy's network is, besides its weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PixelActorMeta {
    /// Its encoders' and head's shape.
    pub actor: PixelActorConfig,
    /// The cameras' images it reads, in the order their bytes follow one another.
    pub images: ImageSpace,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl ModelMeta {
    /// Reads `dir/model.json`; errors name the file and the problem.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join("model.json");
        let text = std::fs::read_to_string(&path)
            .map_err(|e| RlError::Model(format!("{}: {e}", path.display())))?;
        Self::from_json(&text).map_err(|e| RlError::Model(format!("{}: {e}", path.display())))
    }

    /// Parses the text of a `model.json` of any version this build reads (see
    /// [`READABLE_FORMAT_VERSIONS`]); older layouts are upgraded, so the result is always of
    /// the current [`FORMAT_VERSION`].
    pub fn from_json(text: &str) -> std::result::Result<Self, String> {
        let not_a_model = |e: &dyn std::fmt::Display| format!("not a fairgrasp model: {e}");
        let mut value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| not_a_model(&e))?;
        let object = value
            .as_object_mut()
            .ok_or_else(|| not_a_model(&"expected a JSON object"))?;
        let version = object
            .get("format_version")
            .ok_or_else(|| not_a_model(&"no `format_version`"))?;
        match version.as_u64() {
            Some(2) => {}
            Some(1) => {
                if let Some(env) = object.remove("env") {
                    let env = upgrade_v1_env_config(env).map_err(|e| e.to_string())?;
                    object.insert("env".into(), env);
                }
                object.insert("env_id".into(), V1_ENV_ID.into());
                object.insert("format_version".into(), FORMAT_VERSION.into());
            }
            _ => {
                let readable: Vec<String> = READABLE_FORMAT_VERSIONS
                    .iter()
                    .map(|v| v.to_string())
                    .collect();
                return Err(format!(
                    "model format version {version} is not supported (this build reads {})",
                    readable.join(" and ")
                ));
            }
        }
        // A training config may leave its algorithm's table to the defaults; a model may not: its
        // weights were shaped by those settings.
        if let Some(algo) = value.get("algo").and_then(serde_json::Value::as_str)
            && algo.parse::<Algo>().is_ok()
            && value.get(algo).is_none_or(serde_json::Value::is_null)
        {
            return Err(format!(
                "it names algorithm {algo} but has no `{algo}` settings"
            ));
        }
        serde_json::from_value(value).map_err(|e| not_a_model(&e))
    }

    /// How the model learnt, in words: `ppo`, or `distilled from a ppo teacher` for a camera
    /// policy.
    pub fn trained_by(&self) -> String {
        match &self.pixel_actor {
            None => self.algo.algo().to_string(),
            Some(_) => format!("distilled from a {} teacher", self.algo.algo()),
        }
    }

    /// Errors unless the model was made by `algo` for these observation and action sizes.
    pub fn check_compatible(&self, algo: Algo, obs_dim: usize, act_dim: usize) -> Result<()> {
        if self.algo.algo() != algo {
            return Err(RlError::Model(format!(
                "the model was trained with {}, not {algo}",
                self.algo.algo()
            )));
        }
        if (self.obs_dim, self.act_dim) != (obs_dim, act_dim) {
            return Err(RlError::Model(format!(
                "the model maps {} observation values to {} actions; this environment has {obs_dim} and {act_dim}",
                self.obs_dim, self.act_dim
            )));
        }
        Ok(())
    }
}

/// The environment configuration of a format-1 `model.json` (the grasp task's former
/// `EnvConfig`, as JSON) in today's form, which the environment registry parses:
/// - `task.action_mode`, `task.max_joint_delta`, `task.max_tcp_delta`, `task.max_yaw_delta`
///   move to `control`;
/// - the cube `scene.object {size, mass, friction}` becomes `scene.objects[0]`, a box;
/// - `randomization.object_size [a, b]` (edge lengths) becomes `object_scale [a/size, b/size]`.
pub fn upgrade_v1_env_config(v: serde_json::Value) -> Result<serde_json::Value> {
    use serde_json::{Map, Value, json};
    let bad = |what: &str| {
        RlError::Model(format!(
            "format-1 environment settings: {what}; retrain, or edit model.json to the current layout (configs/env.toml)"
        ))
    };
    let mut root = match v {
        Value::Object(map) => map,
        _ => return Err(bad("expected an object")),
    };
    let section = |root: &mut Map<String, Value>, name: &str| -> Map<String, Value> {
        match root.remove(name) {
            Some(Value::Object(map)) => map,
            _ => Map::new(),
        }
    };
    let mut task = section(&mut root, "task");
    let mut control = section(&mut root, "control");
    for key in [
        "action_mode",
        "max_joint_delta",
        "max_tcp_delta",
        "max_yaw_delta",
    ] {
        if let Some(value) = task.remove(key) {
            control.insert(key.into(), value);
        }
    }
    let mut scene = section(&mut root, "scene");
    let mut size = 0.05;
    if let Some(object) = scene.remove("object") {
        let object = object
            .as_object()
            .ok_or_else(|| bad("scene.object is not a table"))?;
        let number =
            |key: &str, default: f64| object.get(key).and_then(Value::as_f64).unwrap_or(default);
        size = number("size", 0.05);
        scene.insert(
            "objects".into(),
            json!([{
                "name": "cube",
                "shape": {"kind": "box", "size": [size, size, size]},
                "mass": number("mass", 0.1),
                "friction": number("friction", 0.8),
            }]),
        );
    }
    let mut randomization = section(&mut root, "randomization");
    if let Some(range) = randomization.remove("object_size") {
        let r: Vec<f64> = range
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default();
        if r.len() != 2 {
            return Err(bad("randomization.object_size is not [low, high]"));
        }
        randomization.insert("object_scale".into(), json!([r[0] / size, r[1] / size]));
    }
    for (name, map) in [
        ("scene", scene),
        ("control", control),
        ("task", task),
        ("randomization", randomization),
    ] {
        if !map.is_empty() {
            root.insert(name.into(), Value::Object(map));
        }
    }
    Ok(Value::Object(root))
}

/// A model's environment settings as the TOML table the environment registry takes (JSON
/// nulls, which TOML cannot hold, are unset options and are left out).
pub fn env_table(env: &serde_json::Value) -> Result<toml::Table> {
    fn strip_nulls(v: &serde_json::Value) -> serde_json::Value {
        use serde_json::Value;
        match v {
            Value::Object(map) => Value::Object(
                map.iter()
                    .filter(|(_, v)| !v.is_null())
                    .map(|(k, v)| (k.clone(), strip_nulls(v)))
                    .collect(),
            ),
            Value::Array(items) => Value::Array(items.iter().map(strip_nulls).collect()),
            other => other.clone(),
        }
    }
    match strip_nulls(env) {
        serde_json::Value::Null => Ok(toml::Table::new()),
        v => serde_json::from_value(v)
            .map_err(|e| RlError::Model(format!("environment settings: {e}"))),
    }
}

/// Writes `model.safetensors` and `model.json` into `dir` (created if needed).
pub fn write_model_files(dir: &Path, weights: &TensorMap, meta: &ModelMeta) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| RlError::Other(format!("{}: {e}", dir.display())))?;
    save_tensors(&dir.join("model.safetensors"), weights)?;
    let json = serde_json::to_string_pretty(meta).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&dir.join("model.json"), json.as_bytes())
        .map_err(|e| RlError::Other(format!("{}: {e}", dir.display())))
}

/// Saves a model directory, replacing any previous one whole.
pub fn save_model(dir: &Path, weights: &TensorMap, meta: &ModelMeta) -> Result<()> {
    let staging = sibling(dir, "partial");
    let _ = std::fs::remove_dir_all(&staging);
    write_model_files(&staging, weights, meta)?;
    replace_dir(&staging, dir)
}

/// `.NAME.suffix` beside `dir`.
fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model".into());
    dir.with_file_name(format!(".{name}.{suffix}"))
}

/// Moves the complete directory `staging` to `target`. The previous `target` is kept as
/// `.NAME.old` until the new one is in place, and [`resolve_model_dir`] falls back to it.
pub fn replace_dir(staging: &Path, target: &Path) -> Result<()> {
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", target.display()));
    let old = sibling(target, "old");
    let _ = std::fs::remove_dir_all(&old);
    if target.exists() {
        std::fs::rename(target, &old).map_err(io)?;
    }
    std::fs::rename(staging, target).map_err(io)?;
    let _ = std::fs::remove_dir_all(&old);
    Ok(())
}

/// Writes tensors as safetensors through a temporary file, so a crash never leaves a torn file.
pub fn save_tensors(path: &Path, tensors: &TensorMap) -> Result<()> {
    let tmp = path.with_extension("safetensors.tmp");
    candle_core::safetensors::save(tensors, &tmp)?;
    std::fs::rename(&tmp, path).map_err(|e| RlError::Other(format!("{}: {e}", path.display())))
}

/// Reads a safetensors file; errors name the file.
pub fn load_tensors(path: &Path) -> Result<TensorMap> {
    if !path.is_file() {
        return Err(RlError::Model(format!("{}: no such file", path.display())));
    }
    candle_core::safetensors::load(path, &Device::Cpu).map_err(|e| {
        RlError::Model(format!(
            "{}: not a readable safetensors file: {e}",
            path.display()
        ))
    })
}

/// The model directory to read for `path`: the directory itself, its `best/` model when given a
/// run directory, or the previous version left by an interrupted save.
pub fn resolve_model_dir(path: &Path) -> Result<PathBuf> {
    if path.join("model.json").is_file() {
        return Ok(path.to_path_buf());
    }
    if path.join("best").join("model.json").is_file() {
        return Ok(path.join("best"));
    }
    let old = sibling(path, "old");
    if old.join("model.json").is_file() {
        return Ok(old);
    }
    Err(RlError::Model(format!(
        "{}: no model here (expected model.json and model.safetensors, or a run directory with best/)",
        path.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `model.json` as format 1 wrote it (the grasp task's configuration under `env`).
    const V1_MODEL_JSON: &str = r#"{
  "format_version": 1,
  "algo": "ppo",
  "obs_dim": 40,
  "act_dim": 5,
  "ppo": { "net_arch": [128, 128], "activation": "tanh", "log_std_init": -0.5 },
  "sac": null,
  "env": {
    "task": { "action_mode": "cartesian", "observation": "rich", "max_episode_steps": 100 },
    "reward": { "kind": "staged" }
  },
  "normalization": null,
  "num_timesteps": 204800,
  "train_seed": 42,
  "n_envs": 16
}"#;

    #[test]
    fn a_format_1_model_json_reads_as_the_grasp_task() {
        let meta = ModelMeta::from_json(V1_MODEL_JSON).unwrap();
        assert_eq!(meta.format_version, FORMAT_VERSION);
        assert_eq!(meta.env_id, "FaArmGrasp-v0");
        assert_eq!(meta.env["task"]["max_episode_steps"], 100);
        assert_eq!(meta.env["reward"]["kind"], "staged");
        // The action settings moved to `[control]`.
        assert_eq!(meta.env["control"]["action_mode"], "cartesian");
        assert!(meta.env["task"].get("action_mode").is_none());
        let crate::algo::AlgoConfig::Ppo(ppo) = &meta.algo else {
            panic!("a PPO model read as {:?}", meta.algo.algo());
        };
        assert_eq!(ppo.net_arch, [128, 128]);
        assert_eq!(ppo.log_std_init, -0.5);
        assert_eq!(ppo.features, crate::policies::FeaturesConfig::Flatten {});
        assert_eq!((meta.obs_dim, meta.act_dim, meta.n_envs), (40, 5, 16));

        // Written back, it is format 2 and reads back the same.
        let text = serde_json::to_string(&meta).unwrap();
        assert!(text.contains("\"format_version\":2") && text.contains("\"env_id\""));
        let again = ModelMeta::from_json(&text).unwrap();
        assert_eq!(again.algo, meta.algo);
        assert_eq!((again.env_id, again.env), (meta.env_id, meta.env));
    }

    #[test]
    fn a_format_1_cube_and_size_range_become_an_object_list_and_a_scale() {
        let old = serde_json::json!({
            "scene": {"object": {"size": 0.04, "mass": 0.2, "friction": 0.7}},
            "randomization": {"enabled": true, "object_size": [0.036, 0.044]},
            "task": {"render_mode": null}
        });
        let new = upgrade_v1_env_config(old).unwrap();
        let object = &new["scene"]["objects"][0];
        assert_eq!(object["shape"]["kind"], "box");
        assert_eq!(object["shape"]["size"][2], 0.04);
        assert_eq!(object["mass"], 0.2);
        let scale = new["randomization"]["object_scale"].as_array().unwrap();
        assert!((scale[0].as_f64().unwrap() - 0.9).abs() < 1e-9);
        assert!((scale[1].as_f64().unwrap() - 1.1).abs() < 1e-9);
        // Nulls (unset options) are dropped on the way to TOML.
        let table = env_table(&new).unwrap();
        assert!(table["task"].as_table().unwrap().is_empty());
        assert!(upgrade_v1_env_config(serde_json::json!([1])).is_err());
    }

    #[test]
    fn unknown_versions_and_malformed_files_are_refused() {
        for version in ["0", "3", "\"2\"", "null"] {
            let text = V1_MODEL_JSON.replace(
                "\"format_version\": 1",
                &format!("\"format_version\": {version}"),
            );
            let err = ModelMeta::from_json(&text).unwrap_err();
            assert!(
                err.contains(&format!("version {version} is not supported"))
                    && err.contains("this build reads 1 and 2"),
                "{err}"
            );
        }
        // Format 2 names its environment.
        let v2_without_id = V1_MODEL_JSON.replace("\"format_version\": 1", "\"format_version\": 2");
        let err = ModelMeta::from_json(&v2_without_id).unwrap_err();
        assert!(
            err.contains("not a fairgrasp model") && err.contains("env_id"),
            "{err}"
        );
        for (text, problem) in [
            ("[1, 2]", "expected a JSON object"),
            ("{\"algo\": \"ppo\"}", "no `format_version`"),
            ("{\"format_version\": 1", "EOF"),
        ] {
            let err = ModelMeta::from_json(text).unwrap_err();
            assert!(
                err.contains("not a fairgrasp model") && err.contains(problem),
                "{err}"
            );
        }
    }

    #[test]
    fn load_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let err = ModelMeta::load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("model.json"), "{err}");
        std::fs::write(
            dir.path().join("model.json"),
            V1_MODEL_JSON.replace(": 1,", ": 7,"),
        )
        .unwrap();
        let err = ModelMeta::load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("model.json: model format version 7"), "{err}");
    }
}
