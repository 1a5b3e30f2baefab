//! The learning algorithms, listed once: [`Algo`] names one and [`AlgoConfig`] is one with its
//! settings, shared by the training configuration and the saved model. Everything else about an
//! algorithm lives in its own file (settings, learner, how its saved actor loads), so adding one
//! touches that file and the variants here.
//!
//! In TOML and JSON an [`AlgoConfig`] is the `algo` name beside a table of that name
//! (`algo = "sac"` and `[sac]`); tables of the other algorithms may be present (a config file
//! shared across `--algo` choices) and are checked but unused.

use crate::algorithm::{Algorithm, TensorMap};
use crate::error::{Result, RlError};
use crate::policies::{ActorNet, NetConfig};
use crate::ppo::{self, Ppo, PpoConfig};
use crate::sac::{self, Sac, SacConfig};
use crate::td3::{self, Td3, Td3Config};
use serde::{Deserialize, Serialize};

/// Which algorithm learns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Algo {
    /// Proximal Policy Optimization.
    #[default]
    Ppo,
    /// Soft Actor-Critic.
    Sac,
    /// Twin Delayed DDPG.
    Td3,
}

impl Algo {
    /// Every algorithm, in the order help texts list them.
    pub const ALL: [Algo; 3] = [Algo::Ppo, Algo::Sac, Algo::Td3];

    /// The name configs, saved models and the command line use.
    pub fn as_str(self) -> &'static str {
        match self {
            Algo::Ppo => "ppo",
            Algo::Sac => "sac",
            Algo::Td3 => "td3",
        }
    }
}

impl std::fmt::Display for Algo {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Algo {
    type Err = RlError;

    fn from_str(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|a| a.as_str() == name)
            .ok_or_else(|| RlError::Config {
                key: "algo".into(),
                problem: format!(
                    "unknown algorithm `{name}` (one of {})",
                    Self::ALL.map(Algo::as_str).join(", ")
                ),
            })
    }
}

/// The files of `configs/` a run starts from, by name: `<algo>_<env>` (see
/// [`crate::configs::short_env_name`]), compiled in. Every algorithm has a `<algo>_grasp`.
pub const BUILTIN_CONFIGS: [(&str, &str); 5] = [
    ("ppo_grasp", include_str!("../../../configs/ppo_grasp.toml")),
    ("sac_grasp", include_str!("../../../configs/sac_grasp.toml")),
    ("td3_grasp", include_str!("../../../configs/td3_grasp.toml")),
    (
        "ppo_pick_place",
        include_str!("../../../configs/ppo_pick_place.toml"),
    ),
    ("ppo_sort", include_str!("../../../configs/ppo_sort.toml")),
];

/// An algorithm with its settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "AlgoTables", into = "AlgoTables")]
pub enum AlgoConfig {
    /// PPO and its settings (`[ppo]`).
    Ppo(PpoConfig),
    /// SAC and its settings (`[sac]`).
    Sac(SacConfig),
    /// TD3 and its settings (`[td3]`).
    Td3(Td3Config),
}

impl Default for AlgoConfig {
    fn default() -> Self {
        Self::default_for(Algo::default())
    }
}

/// What a learner is built for, besides its settings.
#[derive(Clone, Copy, Debug)]
pub struct LearnerShape {
    /// Values per observation.
    pub obs_dim: usize,
    /// Values per action.
    pub act_dim: usize,
    /// Privileged values per observation the environments offer (a critic may read them).
    pub privileged_dim: usize,
    /// Parallel environments.
    pub n_envs: usize,
    /// Seed of the learner's weights and random stream.
    pub seed: u64,
    /// Threads the environments step on (idle while the learner updates).
    pub threads: usize,
}

/// Receives a freshly built learner, whatever its type: what runs a training loop generic over
/// [`Algorithm`] on an algorithm chosen at run time.
pub trait LearnerVisitor {
    /// What the visit returns.
    type Output;
    /// Runs with `learner`.
    fn visit<A: Algorithm>(self, learner: A) -> Result<Self::Output>;
}

impl AlgoConfig {
    /// `algo` with its default settings.
    pub fn default_for(algo: Algo) -> Self {
        match algo {
            Algo::Ppo => Self::Ppo(PpoConfig::default()),
            Algo::Sac => Self::Sac(SacConfig::default()),
            Algo::Td3 => Self::Td3(Td3Config::default()),
        }
    }

    /// Which algorithm this is.
    pub fn algo(&self) -> Algo {
        match self {
            Self::Ppo(_) => Algo::Ppo,
            Self::Sac(_) => Algo::Sac,
            Self::Td3(_) => Algo::Td3,
        }
    }

    /// Errors name the key (`ppo.batch_size`) and the problem.
    pub fn validate(&self, n_envs: usize) -> Result<()> {
        match self {
            Self::Ppo(c) => ppo::validate(c, n_envs),
            Self::Sac(c) => sac::validate(c, n_envs),
            Self::Td3(c) => td3::validate(c, n_envs),
        }
    }

    /// The shape of the policy's networks.
    pub fn net(&self) -> NetConfig {
        match self {
            Self::Ppo(c) => c.net(),
            Self::Sac(c) => c.net(),
            Self::Td3(c) => c.net(),
        }
    }

    /// Whether the value network reads the environment's privileged values.
    pub fn privileged_critic(&self) -> bool {
        matches!(self, Self::Ppo(c) if c.privileged_critic)
    }

    /// Builds the learner for `shape` and hands it to `visitor`.
    pub fn build<V: LearnerVisitor>(&self, shape: LearnerShape, visitor: V) -> Result<V::Output> {
        let LearnerShape {
            obs_dim,
            act_dim,
            privileged_dim,
            n_envs,
            seed,
            threads,
        } = shape;
        match self {
            Self::Ppo(c) => {
                let mut learner = Ppo::with_privileged(
                    c.clone(),
                    obs_dim,
                    act_dim,
                    privileged_dim,
                    n_envs,
                    seed,
                )?;
                // The env threads idle during the update; its two heads use them.
                learner.set_update_threads(threads)?;
                visitor.visit(learner)
            }
            Self::Sac(c) => visitor.visit(Sac::new(c.clone(), obs_dim, act_dim, n_envs, seed)?),
            Self::Td3(c) => visitor.visit(Td3::new(c.clone(), obs_dim, act_dim, n_envs, seed)?),
        }
    }

    /// The acting network of a saved model trained with these settings, from its weights
    /// (every tensor checked: a missing, extra or mis-shaped one is an error naming it).
    pub fn load_actor(
        &self,
        weights: &TensorMap,
        obs_dim: usize,
        act_dim: usize,
        privileged_dim: usize,
    ) -> Result<Box<dyn ActorNet>> {
        Ok(match self {
            Self::Ppo(c) => Box::new(ppo::load_actor(
                weights,
                obs_dim,
                act_dim,
                privileged_dim,
                c,
            )?),
            Self::Sac(c) => Box::new(sac::load_actor(weights, obs_dim, act_dim, c)?),
            Self::Td3(c) => Box::new(td3::load_actor(weights, obs_dim, act_dim, c)?),
        })
    }
}

/// The written form: the name, and a table per algorithm (only the named one when written).
#[derive(Clone, Default, Serialize, Deserialize)]
#[serde(default)]
struct AlgoTables {
    algo: Algo,
    #[serde(skip_serializing_if = "Option::is_none")]
    ppo: Option<PpoConfig>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sac: Option<SacConfig>,
    #[serde(skip_serializing_if = "Option::is_none")]
    td3: Option<Td3Config>,
}

impl From<AlgoTables> for AlgoConfig {
    fn from(t: AlgoTables) -> Self {
        match t.algo {
            Algo::Ppo => Self::Ppo(t.ppo.unwrap_or_default()),
            Algo::Sac => Self::Sac(t.sac.unwrap_or_default()),
            Algo::Td3 => Self::Td3(t.td3.unwrap_or_default()),
        }
    }
}

impl From<AlgoConfig> for AlgoTables {
    fn from(c: AlgoConfig) -> Self {
        let algo = c.algo();
        let mut t = AlgoTables {
            algo,
            ..Self::default()
        };
        match c {
            AlgoConfig::Ppo(c) => t.ppo = Some(c),
            AlgoConfig::Sac(c) => t.sac = Some(c),
            AlgoConfig::Td3(c) => t.td3 = Some(c),
        }
        t
    }
}
