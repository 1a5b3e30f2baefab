//! [`TrainConfig`]: everything that defines a training run, as `configs/*.toml` write it.

use crate::algo::AlgoConfig;
use crate::distill::DistillConfig;
use crate::error::{Result, RlError};
use crate::ppo::pixel::PixelPpoConfig;
use fairgrasp_env::registry;
use fairgrasp_env::wrappers::VecNormalizeConfig;
use serde::{Deserialize, Serialize};

/// Evaluation during training (like SB3's `EvalCallback`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Evaluate every this many environment steps (0: never).
    pub freq: u64,
    /// Episodes per evaluation (seeds from [`EVAL_SEED_BASE`]); at least 1 when `freq` > 0.
    pub episodes: u32,
    /// Stop training once the evaluation success rate reaches this (and, with
    /// `confirm_episodes`, the confirmation holds).
    pub success_threshold: Option<f32>,
    /// When an evaluation reaches `success_threshold`, play this many more episodes on
    /// validation seeds of their own ([`VALIDATION_SEED_BASE`]) before stopping (0: stop at
    /// once). The best model is then the one with the best confirmed success, so neither the
    /// stop nor the choice rests on the seeds that triggered it.
    pub confirm_episodes: u32,
    /// Stop only when the 95 % Wilson lower bound of the confirmation's success rate reaches
    /// this (of 200 episodes: 197 successes give 0.957, 196 give 0.9497, 200 give 0.981).
    pub confirm_lower_bound: f32,
    /// After each evaluation, play its first episode again with the `[render]` camera and
    /// write it as `videos/eval_<steps>.gif` in the run directory (arm tasks).
    pub record: bool,
    /// Width and height of those videos.
    pub record_size: [u32; 2],
    /// Settings laid over the training env's for the evaluations and confirmations (SB3's
    /// separate `eval_env`): e.g. the nominal scene, without the training's draws, so that the
    /// stop rule measures the world the model is deployed to. Empty: the training env.
    pub env: toml::Table,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            freq: 50_000,
            episodes: 20,
            success_threshold: None,
            confirm_episodes: 0,
            confirm_lower_bound: 0.95,
            record: false,
            record_size: [320, 240],
            env: toml::Table::new(),
        }
    }
}

/// Seeds of the evaluations during training: `EVAL_SEED_BASE + episode`. Training episodes
/// draw from the streams seeded `seed … seed + n_envs`; `fairgrasp eval` defaults to
/// [`HELD_OUT_SEED_BASE`], so the final figure is measured on episodes that neither trained
/// the policy nor chose the best model.
pub const EVAL_SEED_BASE: u64 = 1_000_000;
/// Default first seed of `fairgrasp eval`.
pub const HELD_OUT_SEED_BASE: u64 = 2_000_000_000;
/// Seeds of the confirmation evaluations (`eval.confirm_episodes`): apart from the training,
/// evaluation and held-out seeds.
pub const VALIDATION_SEED_BASE: u64 = 1_500_000_000;

/// Everything that defines a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The registered environment to learn (`fairgrasp env list`).
    pub env_id: String,
    /// The algorithm and its settings (`algo = "sac"` and the `[sac]` table).
    #[serde(flatten)]
    pub algo: AlgoConfig,
    /// Environment steps to train for (all environments together); at least 1.
    pub total_timesteps: u64,
    /// Seeds the learner (networks, random stream) and the training environments.
    pub seed: u64,
    /// Parallel environments.
    pub n_envs: usize,
    /// Threads stepping them.
    pub threads: usize,
    /// Save a checkpoint every this many environment steps (0: never).
    pub checkpoint_freq: u64,
    /// Stop after this much wall time (s), across resumes (a time budget for benchmarks).
    pub max_seconds: Option<f64>,
    /// Observation and reward normalisation (SB3's `VecNormalize`).
    pub normalize: VecNormalizeConfig,
    /// Evaluation during training (`[eval]`).
    pub eval: EvalConfig,
    /// The environment's own settings (its TOML table; missing keys take their defaults).
    pub env: toml::Table,
    /// `[distill]`: after training, teach a camera policy from the best model
    /// (teacher–student distillation, docs/camera.md); absent: no camera policy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distill: Option<DistillConfig>,
    /// `[pixel_ppo]`: train a camera policy end to end with PPO instead (its critic reads the
    /// privileged state; `[ppo]` holds the PPO settings); absent: a state policy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_ppo: Option<PixelPpoConfig>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            env_id: fairgrasp_env::ENV_ID.into(),
            algo: AlgoConfig::default(),
            total_timesteps: 2_000_000,
            seed: 42,
            n_envs: 4,
            threads: 2,
            checkpoint_freq: 200_000,
            max_seconds: None,
            normalize: VecNormalizeConfig::default(),
            eval: EvalConfig::default(),
            env: toml::Table::new(),
            distill: None,
            pixel_ppo: None,
        }
    }
}

impl TrainConfig {
    /// Parses TOML, applies `section.key=value` overrides, validates; errors name the key.
    pub fn from_toml_str(text: &str, overrides: &[String]) -> Result<Self> {
        let mut table: toml::Table =
            text.parse().map_err(|e: toml::de::Error| RlError::Config {
                key: "(file)".into(),
                problem: e.to_string(),
            })?;
        for item in overrides {
            fairgrasp_env::config::apply_override(&mut table, item)?;
        }
        let text = toml::to_string(&table).map_err(|e| RlError::Other(e.to_string()))?;
        let config: TrainConfig = toml::from_str(&text).map_err(|e| RlError::Config {
            key: "config".into(),
            problem: e.to_string(),
        })?;
        config.validate()?;
        Ok(config)
    }

    /// Checks every setting, the environment's included; errors name the key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, problem: &str| {
            Err(RlError::Config {
                key: key.into(),
                problem: problem.into(),
            })
        };
        if self.total_timesteps == 0 {
            return bad("total_timesteps", "must be at least 1");
        }
        if self
            .max_seconds
            .is_some_and(|s| !(s.is_finite() && s > 0.0))
        {
            return bad("max_seconds", "must be a positive number of seconds");
        }
        if self.n_envs == 0 || self.n_envs > 1024 {
            return bad("n_envs", "must be in 1..=1024");
        }
        self.algo.validate(self.n_envs)?;
        if self.eval.freq > 0 && self.eval.episodes == 0 {
            return bad("eval.episodes", "must be at least 1 when evaluating");
        }
        let bound = self.eval.confirm_lower_bound;
        if !(bound.is_finite() && (0.0..=1.0).contains(&bound)) {
            return bad("eval.confirm_lower_bound", "must be in [0, 1]");
        }
        let [w, h] = self.eval.record_size;
        if !((16..=1920).contains(&w) && (16..=1080).contains(&h)) {
            return bad(
                "eval.record_size",
                "must be [width, height] within 16×16 and 1920×1080",
            );
        }
        self.normalize
            .validate()
            .map_err(|problem| RlError::Config {
                key: "normalize".into(),
                problem,
            })?;
        let check = |section: &str, env: &toml::Table| {
            registry::validate(&self.env_id, env).map_err(|e| match e {
                fairgrasp_env::EnvError::Config { key, problem } => RlError::Config {
                    key: format!("{section}.{key}"),
                    problem: format!("{problem} ({})", self.env_id),
                },
                other => other.into(),
            })
        };
        check("env", &self.env)?;
        if let Some(distill) = &self.distill {
            distill.validate()?;
            let mut student = self.env.clone();
            let camera = toml::Table::from_iter([(
                "camera".to_string(),
                toml::Value::Table(toml::Table::from_iter([(
                    "mode".to_string(),
                    toml::Value::String("rgb+state".into()),
                )])),
            )]);
            fairgrasp_env::config::overlay(&mut student, &camera);
            fairgrasp_env::config::overlay(&mut student, &distill.env);
            check("distill.env", &student)?;
        }
        if self.pixel_ppo.is_some() {
            if !matches!(self.algo, AlgoConfig::Ppo(_)) {
                return bad(
                    "pixel_ppo",
                    "end-to-end camera training runs PPO: algo = \"ppo\"",
                );
            }
            if self.distill.is_some() {
                return bad(
                    "pixel_ppo",
                    "a run trains its camera policy one way: [pixel_ppo] or [distill], not both",
                );
            }
        }
        if !self.eval.env.is_empty() {
            let eval_env = self.eval_env();
            check("eval.env", &eval_env)?;
            // The policy trained on one env must be able to act in the other.
            let sizes = |env: &toml::Table| -> Result<(usize, usize)> {
                let e = registry::make(&self.env_id, env)?;
                Ok((e.observation_space().dim(), e.action_space().dim()))
            };
            let (train, eval) = (sizes(&self.env)?, sizes(&eval_env)?);
            if train != eval {
                return bad(
                    "eval.env",
                    &format!(
                        "changes the (observation, action) sizes from {train:?} to {eval:?}: \
                         the policy could not act in it"
                    ),
                );
            }
        }
        Ok(())
    }

    /// The env the evaluations play: the training env with `eval.env` laid over it.
    pub fn eval_env(&self) -> toml::Table {
        let mut env = self.env.clone();
        fairgrasp_env::config::overlay(&mut env, &self.eval.env);
        env
    }
}
