//! SAC's networks (SB3's `SACPolicy`): a tanh-squashed Gaussian actor and twin critics with
//! their Polyak-averaged targets ([`CriticsWithTarget`]). Each has its own feature extractor
//! (SB3's default for off-policy algorithms); the two Q networks of a critic share theirs.
//!
//! Parameters: `actor.*`, `critic.qf1.*`, `critic.qf2.*`, `critic_target.*` (and
//! `actor.features.*`, `critic.features.*` for an extractor with parameters).

use crate::algorithm::{TensorMap, varmap_tensors};
use crate::distributions::{SquashedDiagGaussian, standard_normal_tensor};
use crate::error::Result;
use crate::nn::Mlp;
use crate::policies::actor::{ActorDescription, ActorNet, Head};
use crate::policies::actor_critic::obs_tensor;
use crate::policies::critics::{CriticsWithTarget, critics_with_target};
use crate::policies::features::FeaturesExtractor;
use crate::policies::net_config::NetConfig;
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// The actor's log standard deviation is squashed into this range (CleanRL's bounds).
const LOG_STD_MIN: f64 = -5.0;
const LOG_STD_MAX: f64 = 2.0;
/// Output-layer gain of the actor (see [`Mlp::new`]): small, so the first policy is centred with
/// σ = e^-1.5, as in CleanRL.
const ACTOR_OUTPUT_GAIN: f64 = 0.01;

/// `log_std` squashed smoothly into `[LOG_STD_MIN, LOG_STD_MAX]` (a hard clamp would stop its
/// gradient at the bounds).
fn squash_log_std(raw: &Tensor) -> candle_core::Result<Tensor> {
    let half_range = 0.5 * (LOG_STD_MAX - LOG_STD_MIN);
    raw.tanh()?.affine(half_range, LOG_STD_MIN + half_range)
}

/// The squashed Gaussian policy: one MLP on the features gives each action dimension's mean and
/// log std.
pub struct SquashedGaussianActor {
    /// Every parameter, by name.
    pub varmap: VarMap,
    features: Box<dyn FeaturesExtractor>,
    net: Mlp,
    obs_dim: usize,
    act_dim: usize,
    /// The shape it was built with.
    net_config: NetConfig,
}

impl SquashedGaussianActor {
    /// The actor with zero weights (see [`Self::init_weights`]).
    fn zeroed(obs_dim: usize, act_dim: usize, config: &NetConfig) -> Result<Self> {
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
            net_config: config.clone(),
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
    /// `predict`, its evaluation and [`crate::Policy`] all act through this.
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

impl ActorNet for SquashedGaussianActor {
    fn act(&self, obs: &[f32], deterministic: bool, rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        self.predict(obs, deterministic, rng)
    }

    fn tensors(&self) -> TensorMap {
        varmap_tensors(&self.varmap, "")
    }

    fn description(&self) -> ActorDescription {
        ActorDescription {
            prefix: "actor",
            net: self.net_config.clone(),
            head: Head::TanhMean,
        }
    }
}

/// The actor, the critics and the target critics.
pub struct SquashedGaussianPolicy {
    /// The policy.
    pub actor: SquashedGaussianActor,
    /// The twin critics and their target.
    pub critics: CriticsWithTarget,
}

impl SquashedGaussianPolicy {
    /// The networks with zero weights (see [`Self::init_weights`]).
    pub fn zeroed(obs_dim: usize, act_dim: usize, config: &NetConfig) -> Result<Self> {
        let actor = SquashedGaussianActor::zeroed(obs_dim, act_dim, config)?;
        let critics = critics_with_target(
            obs_dim,
            act_dim,
            &config.net_arch,
            config.activation,
            &config.features,
        )?;
        Ok(Self { actor, critics })
    }

    /// The groups of variables with their name prefixes, in a fixed order.
    pub fn groups(&self) -> [(&'static str, &VarMap); 3] {
        let [critic, critic_target] = self.critics.groups();
        [("actor.", &self.actor.varmap), critic, critic_target]
    }

    /// Draws the actor's and critics' weights from `rng` and copies the critics to the targets.
    pub fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.actor.init_weights(rng)?;
        self.critics.init_weights(rng)
    }

    /// Polyak averaging of the target critics: `target ← (1 − τ) target + τ online`.
    pub fn soft_update(&self, tau: f32) -> Result<()> {
        self.critics.soft_update(tau)
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
