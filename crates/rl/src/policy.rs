//! [`Policy`]: a saved model acting on raw observations, without its learner (no optimiser,
//! no replay buffer, no critics). It sits above the algorithms: the model's [`AlgoConfig`] says
//! how its actor loads ([`AlgoConfig::load_actor`]), and the actor is then any
//! [`ActorNet`].

#[cfg(doc)]
use crate::algo::AlgoConfig;
use crate::algorithm::TensorMap;
use crate::error::{Result, RlError};
use crate::model::{ModelMeta, load_tensors, resolve_model_dir};
use crate::policies::pixel_actor::{PixelActor, PixelCache};
use crate::policies::{ActorDescription, ActorNet};
use fairgrasp_env::spaces::ImageSpace;
use fairgrasp_env::wrappers::VecNormalizeState;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

/// A trained policy: the model's networks and observation statistics. It gives exactly the
/// actions of the learner it was saved from (the algorithms predict through the same
/// functions), and the trainer's evaluation acts through it.
pub struct Policy {
    meta: ModelMeta,
    /// The model directory it was read from (none when built from parts).
    dir: Option<PathBuf>,
    actor: Actor,
    normalization: Option<VecNormalizeState>,
    /// The stream of stochastic actions' noise.
    rng: ChaCha8Rng,
}

/// The network that acts.
enum Actor {
    /// The actor of the model's algorithm, on the observation vector.
    Vector(Box<dyn ActorNet>),
    /// A camera policy, on the state vector and the cameras' images.
    Pixel(Box<PixelActor>, PixelCache),
}

impl Policy {
    /// Loads a model directory, or a run directory's best model (see
    /// [`crate::model::resolve_model_dir`]). A corrupt file, a missing, extra or mis-shaped
    /// tensor, an unknown algorithm or bad statistics is an error that names the file or
    /// directory and the problem. Stochastic actions draw from a stream seeded 0.
    pub fn load(path: &Path) -> Result<Self> {
        let dir = resolve_model_dir(path)?;
        let meta = ModelMeta::load(&dir)?;
        let weights = load_tensors(&dir.join("model.safetensors"))?;
        let mut policy = Self::from_parts(meta, &weights)
            .map_err(|e| RlError::Model(format!("{}: {e}", dir.display())))?;
        policy.dir = Some(dir);
        Ok(policy)
    }

    /// A policy from a model's description and weights (what [`Self::load`] reads from
    /// `model.json` and `model.safetensors`; what the trainer has in memory).
    pub fn from_parts(meta: ModelMeta, weights: &TensorMap) -> Result<Self> {
        if meta.obs_dim == 0 || meta.act_dim == 0 {
            return Err(RlError::Model(format!(
                "model.json: a policy needs observations and actions, it names {} and {} values",
                meta.obs_dim, meta.act_dim
            )));
        }
        let actor = match &meta.pixel_actor {
            None => Actor::Vector(
                (meta.algo)
                    .load_actor(weights, meta.obs_dim, meta.act_dim, meta.privileged_dim)
                    .map_err(|e| RlError::Model(format!("model.safetensors: {e}")))?,
            ),
            Some(pixel) => {
                let actor = PixelActor::from_weights(
                    &pixel.actor,
                    &pixel.images,
                    meta.obs_dim,
                    meta.act_dim,
                    weights,
                )
                .map_err(|e| RlError::Model(format!("model.safetensors: {e}")))?;
                Actor::Pixel(Box::new(actor), PixelCache::default())
            }
        };
        let normalization = match &meta.normalization {
            Some(json) => Some(VecNormalizeState::from_json(json).map_err(|p| {
                RlError::Model(format!("model.json: normalisation statistics: {p}"))
            })?),
            None => None,
        };
        if let Some(n) = &normalization
            && n.obs_dim() != meta.obs_dim
        {
            return Err(RlError::Model(format!(
                "model.json: normalisation statistics for {} values, the model takes {}",
                n.obs_dim(),
                meta.obs_dim
            )));
        }
        Ok(Self {
            meta,
            dir: None,
            actor,
            normalization,
            rng: ChaCha8Rng::seed_from_u64(0),
        })
    }

    /// The action for one raw observation (normalised here when the model was trained on
    /// normalised observations): the distribution's mode when `deterministic`, else a sample.
    /// Unclipped: the caller clips to its action space.
    pub fn act(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        if obs.len() != self.meta.obs_dim {
            return Err(self.error(format!(
                "observation has {} values, the model takes {}",
                obs.len(),
                self.meta.obs_dim
            )));
        }
        self.act_rows(obs, deterministic)
    }

    /// Actions for several raw observations stored row-major (`n × obs_dim` values give
    /// `n × act_dim`). A row's action can differ from [`Self::act`]'s for it in the last bits
    /// (batched matrix products round differently).
    pub fn act_batch(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        if obs.is_empty() || !obs.len().is_multiple_of(self.meta.obs_dim) {
            return Err(self.error(format!(
                "{} observation values are not whole observations of {} values",
                obs.len(),
                self.meta.obs_dim
            )));
        }
        self.act_rows(obs, deterministic)
    }

    /// Actions for whole observations of an environment: their vectors (row-major) and, for a
    /// camera policy, their images (each observation's bytes of every view in
    /// [`Self::image_space`] order, as [`fairgrasp_env::Env::image`] gives them). A policy
    /// without cameras ignores `images`. A camera policy's action is deterministic.
    pub fn act_with_images(
        &mut self,
        obs: &[f32],
        images: Option<&[u8]>,
        deterministic: bool,
    ) -> Result<Vec<f32>> {
        let dim = self.meta.obs_dim;
        let result = match &mut self.actor {
            Actor::Vector(_) => return self.act_batch(obs, deterministic),
            Actor::Pixel(actor, cache) => pixel_actions(actor, cache, obs, dim, images),
        };
        result.map_err(|e| self.error(e))
    }

    fn act_rows(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        check_finite(obs, self.meta.obs_dim).map_err(|e| self.error(e))?;
        let normalized;
        let input = match &self.normalization {
            Some(n) => {
                normalized = n.normalize_obs(obs)?;
                &normalized
            }
            None => obs,
        };
        match &self.actor {
            Actor::Vector(actor) => actor.act(input, deterministic, &mut self.rng),
            Actor::Pixel(actor, _) => Err(self.error(format!(
                "the model reads camera images ({}) beside its {} state values: act with act_with_images",
                actor.images().describe(),
                self.meta.obs_dim
            ))),
        }
    }

    /// The cameras' images a camera policy reads beside the state vector (`None`: the model
    /// acts on the observation vector alone).
    pub fn image_space(&self) -> Option<&ImageSpace> {
        match &self.actor {
            Actor::Vector(_) => None,
            Actor::Pixel(actor, _) => Some(actor.images()),
        }
    }

    /// The camera policy's network, for exporters.
    pub fn pixel_actor(&self) -> Option<&PixelActor> {
        match &self.actor {
            Actor::Vector(_) => None,
            Actor::Pixel(actor, _) => Some(actor),
        }
    }

    /// Restarts the stream of stochastic actions from `seed`.
    pub fn set_seed(&mut self, seed: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
    }

    /// The observation normalisation statistics [`Self::act`] applies, if the model was trained
    /// on normalised observations.
    pub fn normalization(&self) -> Option<&VecNormalizeState> {
        self.normalization.as_ref()
    }

    /// The parameters of the network that acts, by their names in `model.safetensors`, for
    /// exporters that rebuild the actor elsewhere (see [`Self::actor_description`]).
    pub fn actor_tensors(&self) -> TensorMap {
        match &self.actor {
            Actor::Vector(actor) => actor.tensors(),
            Actor::Pixel(actor, _) => actor.weights(),
        }
    }

    /// Which of [`Self::actor_tensors`] make the actor's layers, and its activation and head
    /// (`None` for a camera policy: see [`Self::pixel_actor`]).
    pub fn actor_description(&self) -> Option<ActorDescription> {
        match &self.actor {
            Actor::Vector(actor) => Some(actor.description()),
            Actor::Pixel(..) => None,
        }
    }

    /// The model's description (`model.json`).
    pub fn meta(&self) -> &ModelMeta {
        &self.meta
    }

    /// The model directory it was loaded from.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    /// Values per observation.
    pub fn obs_dim(&self) -> usize {
        self.meta.obs_dim
    }

    /// Values per action.
    pub fn act_dim(&self) -> usize {
        self.meta.act_dim
    }

    /// Id of the environment the model was trained on.
    pub fn env_id(&self) -> &str {
        &self.meta.env_id
    }

    /// The configuration of that environment, for the environment registry to parse.
    pub fn env_config(&self) -> &serde_json::Value {
        &self.meta.env
    }

    /// The settings table of the environment the model was trained on, with `overrides`
    /// (`section.key=value`) applied and checked by the registry: what evaluation rebuilds.
    pub fn env_settings(&self, overrides: &[String]) -> Result<toml::Table> {
        let path = self
            .dir
            .as_ref()
            .map(|d| d.join("model.json").display().to_string())
            .unwrap_or_else(|| "model.json".into());
        let mut table = crate::model::env_table(self.env_config())
            .map_err(|e| RlError::Model(format!("{path}: the environment settings: {e}")))?;
        for item in overrides {
            fairgrasp_env::config::apply_override(&mut table, item)?;
        }
        fairgrasp_env::registry::validate(self.env_id(), &table).map_err(|e| {
            RlError::Model(format!(
                "invalid settings for {} (overrides or {path}): {e}",
                self.env_id()
            ))
        })?;
        Ok(table)
    }

    /// An error about acting, naming the model's directory when it has one.
    fn error(&self, problem: String) -> RlError {
        match &self.dir {
            Some(dir) => RlError::Model(format!("{}: {problem}", dir.display())),
            None => RlError::Model(problem),
        }
    }
}

/// Errors name the first value that is not finite (and its row when there are several).
fn check_finite(obs: &[f32], dim: usize) -> std::result::Result<(), String> {
    let Some(i) = obs.iter().position(|v| !v.is_finite()) else {
        return Ok(());
    };
    let row = if obs.len() > dim {
        format!("observation {}, ", i / dim)
    } else {
        String::new()
    };
    Err(format!(
        "{row}value {} is {} (observations must be finite)",
        i % dim,
        obs[i]
    ))
}

/// A camera policy's actions for whole observations, their state and images checked first.
fn pixel_actions(
    actor: &PixelActor,
    cache: &mut PixelCache,
    obs: &[f32],
    dim: usize,
    images: Option<&[u8]>,
) -> std::result::Result<Vec<f32>, String> {
    let space = actor.images();
    if obs.is_empty() || !obs.len().is_multiple_of(dim) {
        return Err(format!(
            "{} state values are not whole observations of {dim} values",
            obs.len()
        ));
    }
    let rows = obs.len() / dim;
    let Some(images) = images else {
        return Err(format!(
            "the model reads camera images ({}); none were given",
            space.describe()
        ));
    };
    if images.len() != rows * space.len() {
        return Err(format!(
            "{} image bytes for {rows} observation(s); the model reads {} bytes each ({})",
            images.len(),
            space.len(),
            space.describe()
        ));
    }
    check_finite(obs, dim)?;
    (actor.forward(obs, images, rows, cache)).map_err(|e| e.to_string())
}
