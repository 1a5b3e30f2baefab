//! [`RunDir`]: a training run's directory and its layout, in one place.
//!
//! ```text
//! <run>/config.toml            the effective configuration
//! <run>/tb/                    TensorBoard event files
//! <run>/progress.csv           the same scalars as CSV
//! <run>/best/                  the best model by evaluation (success rate, then return)
//! <run>/final/                 the model when the run ended
//! <run>/checkpoints/step_<N>/  a model, training_state.safetensors and trainer_state.json
//! <run>/videos/eval_<N>.gif    an evaluation episode, when `eval.record` is on
//! <run>/summary.json           the run's summary
//! ```

use crate::algorithm::TensorMap;
use crate::configs::short_env_name;
use crate::error::{Result, RlError};
use crate::evaluation::EvalResult;
use crate::model::{ModelMeta, load_tensors, replace_dir, save_tensors, write_model_files};
use fairgrasp_env::atomic;
use fairgrasp_env::wrappers::EpisodeStats;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const TRAINER_STATE: &str = "trainer_state.json";
const TRAINING_STATE: &str = "training_state.safetensors";

/// A training run's directory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// The run at `path` (nothing is created).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { root: path.into() }
    }

    /// `runs/<algo>_<env>` (e.g. `runs/ppo_grasp`), or the first free `runs/<algo>_<env>_<n>`:
    /// where a run goes when no directory is named.
    pub fn default_for(algo: &str, env_id: &str) -> Self {
        Self::next_free(
            Path::new("runs"),
            &format!("{algo}_{}", short_env_name(env_id)),
        )
    }

    /// `root/<name>`, or `root/<name>_<n>` with the first free n (like SB3's `PPO_1`, `PPO_2`,
    /// … TensorBoard runs).
    pub fn next_free(root: &Path, name: &str) -> Self {
        let first = Self::new(root.join(name));
        if !first.holds_a_run() {
            return first;
        }
        (2..)
            .map(|n| Self::new(root.join(format!("{name}_{n}"))))
            .find(|dir| !dir.holds_a_run())
            .expect("an unused run directory")
    }

    /// The directory itself.
    pub fn path(&self) -> &Path {
        &self.root
    }

    /// Whether it already holds a training run (its config or checkpoints).
    pub fn holds_a_run(&self) -> bool {
        self.config().exists() || self.checkpoints_dir().exists()
    }

    /// `config.toml`: the effective configuration.
    pub fn config(&self) -> PathBuf {
        self.root.join("config.toml")
    }

    /// `tb/`: TensorBoard event files.
    pub fn tensorboard(&self) -> PathBuf {
        self.root.join("tb")
    }

    /// `best/`: the best model by evaluation.
    pub fn best_model(&self) -> PathBuf {
        self.root.join("best")
    }

    /// `final/`: the model when the run ended.
    pub fn final_model(&self) -> PathBuf {
        self.root.join("final")
    }

    /// `summary.json`.
    pub fn summary(&self) -> PathBuf {
        self.root.join("summary.json")
    }

    /// `videos/eval_<steps>.gif`.
    pub fn eval_video(&self, steps: u64) -> PathBuf {
        self.root.join("videos").join(format!("eval_{steps}.gif"))
    }

    /// `checkpoints/`.
    pub fn checkpoints_dir(&self) -> PathBuf {
        self.root.join("checkpoints")
    }

    /// The complete checkpoints, oldest first (a partly written one is skipped).
    pub fn checkpoints(&self) -> Vec<(u64, PathBuf)> {
        let mut found: Vec<(u64, PathBuf)> = std::fs::read_dir(self.checkpoints_dir())
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|entry| {
                let name = entry.file_name().into_string().ok()?;
                let step = name.strip_prefix("step_")?.parse().ok()?;
                let path = entry.path();
                path.join(TRAINER_STATE).is_file().then_some((step, path))
            })
            .collect();
        found.sort();
        found
    }

    /// Writes `checkpoints/step_<N>/` through a staging directory, so an interrupted write
    /// never leaves a checkpoint that [`crate::train::resume`] would pick.
    pub(crate) fn write_checkpoint(
        &self,
        weights: &TensorMap,
        training: &TensorMap,
        meta: &ModelMeta,
        state: &TrainerState,
    ) -> Result<()> {
        let checkpoints = self.checkpoints_dir();
        let dir = checkpoints.join(format!("step_{}", state.num_timesteps));
        let staging = checkpoints.join(format!(".step_{}.partial", state.num_timesteps));
        let _ = std::fs::remove_dir_all(&staging);
        write_model_files(&staging, weights, meta)?;
        save_tensors(&staging.join(TRAINING_STATE), training)?;
        let json = serde_json::to_string(state).map_err(|e| RlError::Other(e.to_string()))?;
        atomic::write(&staging.join(TRAINER_STATE), json.as_bytes())
            .map_err(|e| RlError::Other(format!("{}: {e}", staging.display())))?;
        replace_dir(&staging, &dir)
    }
}

/// What a checkpoint holds for the driver (`trainer_state.json`) and for the learner.
pub(crate) struct Checkpoint {
    pub(crate) trainer: TrainerState,
    pub(crate) meta: ModelMeta,
    pub(crate) weights: TensorMap,
    pub(crate) training: TensorMap,
}

impl Checkpoint {
    /// Reads the checkpoint directory `dir`; errors name the file at fault.
    pub(crate) fn read(dir: &Path) -> Result<Self> {
        Ok(Self {
            trainer: read_trainer_state(dir)?,
            meta: ModelMeta::load(dir)?,
            weights: load_tensors(&dir.join("model.safetensors"))?,
            training: load_tensors(&dir.join(TRAINING_STATE))?,
        })
    }
}

/// The driver's own state, saved with each checkpoint (`trainer_state.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct TrainerState {
    pub(crate) format_version: u32,
    pub(crate) num_timesteps: u64,
    pub(crate) next_eval: u64,
    pub(crate) next_checkpoint: u64,
    pub(crate) best: Option<EvalResult>,
    /// Wall time spent before this checkpoint (s).
    pub(crate) elapsed_seconds: f64,
    pub(crate) recent_episodes: Vec<EpisodeStats>,
    /// The full normalisation state (JSON of
    /// [`fairgrasp_env::wrappers::VecNormalizeState`]).
    pub(crate) normalization: String,
}

fn read_trainer_state(dir: &Path) -> Result<TrainerState> {
    let path = dir.join(TRAINER_STATE);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| RlError::Model(format!("{}: {e}", path.display())))?;
    let state: TrainerState = serde_json::from_str(&text).map_err(|e| {
        RlError::Model(format!(
            "{}: not a fairgrasp trainer state: {e}",
            path.display()
        ))
    })?;
    if state.format_version != 1 {
        return Err(RlError::Model(format!(
            "{}: format version {} is not supported (this build reads 1)",
            path.display(),
            state.format_version
        )));
    }
    Ok(state)
}
