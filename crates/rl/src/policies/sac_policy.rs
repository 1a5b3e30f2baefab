//! SAC's networks (SB3's `SACPolicy`): a tanh-squashed Gaussian actor and twin critics with
//! their Polyak-averaged targets. Each has its own feature extractor (SB3's default for
//! off-policy algorithms); the two Q networks of a critic share theirs.
//!
//! Parameters: `actor.*`, `critic.qf1.*`, `critic.qf2.*`, `critic_target.*` (and
//! `actor.features.*`, `critic.features.*` for an extractor with parameters).

use crate::distributions::{SquashedDiagGaussian, standard_normal_tensor};
use crate::error::{Result, RlError};
use crate::nn::Mlp;
use crate::policies::actor_critic::obs_tensor;
use crate::policies::features::FeaturesExtractor;
use crate::sac::SacConfig;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use rand::Rng;

/// The actor's log standard deviation is squashed into this range (CleanRL's bounds).
const LOG_STD_MIN: f64 = -5.0;
const LOG_STD_MAX: f64 = 2.0;
/// Output-layer gains (see [`Mlp::new`]): small for the actor, so the first policy is centred
/// with σ = e^-1.5, as in CleanRL; ordinary for the critics.
const ACTOR_OUTPUT_GAIN: f64 = 0.01;
const CRITIC_OUTPUT_GAIN: f64 = 1.0;

/// `log_std` squashed smoothly into `[LOG_STD_MIN, LOG_STD_MAX]` (a hard clamp would stop its
/// gradient at the bounds).
fn squash_log_std(raw: &Tensor) -> candle_core::Result<Tensor> {
    let half_range = 0.5 * (LOG_STD_MAX - LOG_STD_MIN);
    raw.tanh()?.affine(half_range, LOG_STD_MIN + half_range)
}

/// The squashed Gaussian policy: one MLP on the features gives each action dimension's mean and
/// log std.
pub struct SacActor {
    pub varmap: VarMap,
    features: Box<dyn FeaturesExtractor>,
    net: Mlp,
    obs_dim: usize,
    act_dim: usize,
}

impl SacActor {
    /// The actor with zero weights (see [`Self::init_weights`]).
    fn zeroed(obs_dim: usize, act_dim: usize, config: &SacConfig) -> Result<Self> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu).pp("actor");
        let features = config.features.build(&vb.pp("features"), obs_dim)?;
        let net = Mlp::new(
            &vb,
            features.features_dim(),
            &config.net_arch,
            2 * act_dim,
            config.activation,
            ACTOR_OUTPUT_GAIN,
        )?;
        Ok(Self {
            varmap,
            features,
            net,
            obs_dim,
            act_dim,
        })
    }

    fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.features.init_weights(&self.varmap, rng)?;
        self.net.init_weights(&self.varmap, rng)?;
        Ok(())
    }

    /// The action distribution for a batch of observations (`batch × obs_dim`).
    pub fn distribution(&self, obs: &Tensor) -> Result<SquashedDiagGaussian> {
        let out = self.net.forward(&self.features.forward(obs)?)?;
        let mean = out.narrow(1, 0, self.act_dim)?;
        let log_std = squash_log_std(&out.narrow(1, self.act_dim, self.act_dim)?)?;
        Ok(SquashedDiagGaussian::new(mean, log_std)?)
    }

    /// Actions for a batch of observations (row-major): `tanh(μ)` when `deterministic`, else a
    /// sample with `act_dim` standard normal draws per observation from `rng`. SAC's
    /// `predict`, its evaluation and [`crate::policies::Policy`] all act through this.
    pub fn predict(
        &self,
        obs: &[f32],
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<Vec<f32>> {
        let obs = obs_tensor(obs, self.obs_dim, &Device::Cpu)?;
        let dist = self.distribution(&obs)?;
        let actions = if deterministic {
            dist.mode()?
        } else {
            let eps = standard_normal_tensor(rng, obs.dim(0)?, self.act_dim)?;
            dist.sample(&eps)?.0
        };
        Ok(actions.flatten_all()?.to_vec1()?)
    }
}

/// Twin Q networks on `[features, action]` (Fujimoto et al. 2018: the minimum of two critics
/// curbs the overestimation a single one accumulates).
pub struct SacCritics {
    pub varmap: VarMap,
    features: Box<dyn FeaturesExtractor>,
    qf1: Mlp,
    qf2: Mlp,
}

impl SacCritics {
    /// Critics with zero weights, their parameters named `{prefix}.…`.
    fn zeroed(prefix: &str, obs_dim: usize, act_dim: usize, config: &SacConfig) -> Result<Self> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu).pp(prefix);
        let features = config.features.build(&vb.pp("features"), obs_dim)?;
        let critic = |name: &str| {
            Mlp::new(
                &vb.pp(name),
                features.features_dim() + act_dim,
                &config.net_arch,
                1,
                config.activation,
                CRITIC_OUTPUT_GAIN,
            )
        };
        Ok(Self {
            qf1: critic("qf1")?,
            qf2: critic("qf2")?,
            features,
            varmap,
        })
    }

    fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.features.init_weights(&self.varmap, rng)?;
        self.qf1.init_weights(&self.varmap, rng)?;
        self.qf2.init_weights(&self.varmap, rng)?;
        Ok(())
    }

    /// Both critics' values, each `batch`.
    pub fn q(&self, obs: &Tensor, actions: &Tensor) -> Result<(Tensor, Tensor)> {
        let x = Tensor::cat(&[&self.features.forward(obs)?, actions], 1)?;
        Ok((
            self.qf1.forward(&x)?.squeeze(1)?,
            self.qf2.forward(&x)?.squeeze(1)?,
        ))
    }

    /// The smaller of the two values, `batch`.
    pub fn min_q(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        let (q1, q2) = self.q(obs, actions)?;
        Ok(q1.minimum(&q2)?)
    }
}

/// The actor, the critics and the target critics.
pub struct SacPolicy {
    pub actor: SacActor,
    pub critic: SacCritics,
    pub critic_target: SacCritics,
    /// (online, target) critic variables, for the Polyak update.
    pub(crate) target_pairs: Vec<(Var, Var)>,
}

impl SacPolicy {
    /// The networks with zero weights (see [`Self::init_weights`]).
    pub fn zeroed(obs_dim: usize, act_dim: usize, config: &SacConfig) -> Result<Self> {
        let actor = SacActor::zeroed(obs_dim, act_dim, config)?;
        let critic = SacCritics::zeroed("critic", obs_dim, act_dim, config)?;
        let critic_target = SacCritics::zeroed("critic_target", obs_dim, act_dim, config)?;
        let target_pairs = {
            let online = critic.varmap.data().lock().expect("varmap lock");
            let target = critic_target.varmap.data().lock().expect("varmap lock");
            online
                .iter()
                .map(|(name, v)| {
                    let target_name = format!("critic_target.{}", &name["critic.".len()..]);
                    let t = target.get(&target_name).cloned().ok_or_else(|| {
                        RlError::Other(format!("target critic lacks `{target_name}`"))
                    })?;
                    Ok((v.clone(), t))
                })
                .collect::<Result<_>>()?
        };
        Ok(Self {
            actor,
            critic,
            critic_target,
            target_pairs,
        })
    }

    /// The groups of variables with their name prefixes, in a fixed order.
    pub fn groups(&self) -> [(&'static str, &VarMap); 3] {
        [
            ("actor.", &self.actor.varmap),
            ("critic.", &self.critic.varmap),
            ("critic_target.", &self.critic_target.varmap),
        ]
    }

    /// Draws the actor's and critics' weights from `rng` and copies the critics to the targets.
    pub fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.actor.init_weights(rng)?;
        self.critic.init_weights(rng)?;
        self.copy_critic_to_target()
    }

    pub fn copy_critic_to_target(&self) -> Result<()> {
        for (online, target) in &self.target_pairs {
            target.set(online.as_tensor())?;
        }
        Ok(())
    }

    /// Polyak averaging: `target ← (1 − τ) target + τ online`.
    pub fn soft_update(&self, tau: f32) -> Result<()> {
        let tau = tau as f64;
        for (online, target) in &self.target_pairs {
            let mixed = ((target.as_tensor() * (1.0 - tau))? + (online.as_tensor() * tau)?)?;
            target.set(&mixed)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn actor_log_std_stays_within_its_bounds() {
        // Reaching them only asymptotically.
        let raw = Tensor::new(&[-100.0f32, 0.0, 100.0], &Device::Cpu).unwrap();
        let squashed: Vec<f32> = squash_log_std(&raw).unwrap().to_vec1().unwrap();
        assert_eq!(squashed, [-5.0, -1.5, 2.0]);
    }
}
