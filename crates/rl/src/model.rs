//! Saved models. A model directory is self-contained: `model.safetensors` (the weights of every
//! network) and `model.json` ([`ModelMeta`]: algorithm and its settings, network sizes, the
//! environment configuration it was trained on, observation normalisation statistics).
//!
//! Directories are replaced whole (written beside the target, then renamed over it), so a crash
//! while saving leaves the previous model readable.

use crate::algorithm::{Algorithm, TensorMap, load_varmap};
use crate::ppo::{ActorCritic, PpoConfig, Result, RlError};
use crate::sac::{Sac, SacConfig};
use crate::save_util::write_atomic;
use candle_core::Device;
use fairgrasp_env::EnvConfig;
use fairgrasp_env::wrappers::VecNormalizeState;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Version of the `model.json` layout this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// What a saved model needs besides its weights (`model.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelMeta {
    pub format_version: u32,
    /// `"ppo"` or `"sac"`.
    pub algo: String,
    pub obs_dim: usize,
    pub act_dim: usize,
    #[serde(default)]
    pub ppo: Option<PpoConfig>,
    #[serde(default)]
    pub sac: Option<SacConfig>,
    /// The environment the model was trained on.
    pub env: EnvConfig,
    /// Observation normalisation statistics (JSON of [`VecNormalizeState`]), if used.
    pub normalization: Option<String>,
    pub num_timesteps: u64,
    /// Seed and number of the training environments (to keep evaluation seeds apart).
    #[serde(default)]
    pub train_seed: u64,
    #[serde(default)]
    pub n_envs: usize,
}

impl ModelMeta {
    /// Reads `dir/model.json`; errors name the file and the problem.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join("model.json");
        let text = std::fs::read_to_string(&path)
            .map_err(|e| RlError::Model(format!("{}: {e}", path.display())))?;
        let meta: ModelMeta = serde_json::from_str(&text).map_err(|e| {
            RlError::Model(format!("{}: not a fairgrasp model: {e}", path.display()))
        })?;
        if meta.format_version != FORMAT_VERSION {
            return Err(RlError::Model(format!(
                "{}: model format version {} is not supported (this build reads {FORMAT_VERSION})",
                path.display(),
                meta.format_version
            )));
        }
        Ok(meta)
    }

    /// Errors unless the model was made by `algo` for these observation and action sizes.
    pub fn check_compatible(&self, algo: &str, obs_dim: usize, act_dim: usize) -> Result<()> {
        if self.algo != algo {
            return Err(RlError::Model(format!(
                "the model was trained with {}, not {algo}",
                self.algo
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

/// Writes `model.safetensors` and `model.json` into `dir` (created if needed).
pub fn write_model_files(dir: &Path, weights: &TensorMap, meta: &ModelMeta) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| RlError::Other(format!("{}: {e}", dir.display())))?;
    save_tensors(&dir.join("model.safetensors"), weights)?;
    let json = serde_json::to_string_pretty(meta).map_err(|e| RlError::Other(e.to_string()))?;
    write_atomic(&dir.join("model.json"), json.as_bytes())
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

/// The networks of a loaded model.
pub enum Agent {
    Ppo(ActorCritic),
    Sac(Box<Sac>),
}

/// A saved model, ready to act deterministically on raw observations.
pub struct LoadedModel {
    pub meta: ModelMeta,
    /// The directory it was read from.
    pub dir: PathBuf,
    pub agent: Agent,
    pub normalization: Option<VecNormalizeState>,
}

impl LoadedModel {
    /// Loads `path` (see [`resolve_model_dir`]). A corrupt file, missing tensor, wrong shape or
    /// unknown algorithm is an error that names it.
    pub fn load(path: &Path) -> Result<Self> {
        let dir = resolve_model_dir(path)?;
        let meta = ModelMeta::load(&dir)?;
        let weights = load_tensors(&dir.join("model.safetensors"))?;
        let context = |e: RlError| RlError::Model(format!("{}: {e}", dir.display()));
        let missing = |algo: &str| {
            RlError::Model(format!(
                "{}: model.json names algorithm {algo} but has no `{algo}` settings",
                dir.display()
            ))
        };
        let agent = match meta.algo.as_str() {
            "ppo" => {
                let config = meta.ppo.clone().ok_or_else(|| missing("ppo"))?;
                // The weights come from the file; the generator only fills them first.
                let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
                let policy = ActorCritic::new(meta.obs_dim, meta.act_dim, &config, &mut rng)?;
                load_varmap(&policy.varmap, &weights).map_err(context)?;
                Agent::Ppo(policy)
            }
            "sac" => {
                let mut config = meta.sac.clone().ok_or_else(|| missing("sac"))?;
                // Acting needs no experience: keep the replay buffer minimal.
                config.buffer_size = config.batch_size.max(1);
                let mut sac =
                    Sac::new(config, meta.obs_dim, meta.act_dim, 1, 0).map_err(context)?;
                sac.load_weights(&weights).map_err(context)?;
                Agent::Sac(Box::new(sac))
            }
            other => {
                return Err(RlError::Model(format!(
                    "{}: unknown algorithm `{other}` (expected ppo or sac)",
                    dir.display()
                )));
            }
        };
        let normalization = match &meta.normalization {
            Some(json) => Some(VecNormalizeState::from_json(json).map_err(|p| {
                RlError::Model(format!("{}: normalisation statistics: {p}", dir.display()))
            })?),
            None => None,
        };
        if let Some(n) = &normalization
            && n.obs_dim() != meta.obs_dim
        {
            return Err(RlError::Model(format!(
                "{}: normalisation statistics for {} values, the model takes {}",
                dir.display(),
                n.obs_dim(),
                meta.obs_dim
            )));
        }
        Ok(Self {
            meta,
            dir,
            agent,
            normalization,
        })
    }

    /// The deterministic action for one raw observation (normalised here if the model was
    /// trained on normalised observations).
    pub fn act(&mut self, obs: &[f32]) -> Result<Vec<f32>> {
        if obs.len() != self.meta.obs_dim {
            return Err(RlError::Model(format!(
                "observation has {} values, the model takes {}",
                obs.len(),
                self.meta.obs_dim
            )));
        }
        let input = match &self.normalization {
            Some(n) => n.normalize_obs(obs)?,
            None => obs.to_vec(),
        };
        match &mut self.agent {
            Agent::Ppo(policy) => policy.mean_actions(&input),
            Agent::Sac(sac) => sac.predict(&input, true),
        }
    }
}
