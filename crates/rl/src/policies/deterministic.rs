//! TD3's networks (SB3's `TD3Policy`): a deterministic tanh actor, twin critics
//! ([`CriticsWithTarget`]), and Polyak-averaged targets of both.
//!
//! Parameters: `actor.*`, `actor_target.*`, `critic.qf1.*`, `critic.qf2.*`, `critic_target.*`.

use crate::algorithm::{TensorMap, varmap_tensors};
use crate::error::Result;
use crate::nn::Mlp;
use crate::policies::actor::{ActorDescription, ActorNet, Head};
use crate::policies::actor_critic::obs_tensor;
use crate::policies::critics::{CriticsWithTarget, TargetPairs, critics_with_target};
use crate::policies::features::FeaturesExtractor;
use crate::policies::net_config::NetConfig;
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Output-layer gain of the actor (see [`Mlp::new`]): small, so the first actions are near zero
/// and the exploration noise decides them, as with SAC's actor.
const ACTOR_OUTPUT_GAIN: f64 = 0.01;

/// The deterministic policy `a = tanh(MLP(features(s)))`.
pub struct DeterministicActor {
    /// Every parameter, by name.
    pub varmap: VarMap,
    features: Box<dyn FeaturesExtractor>,
    net: Mlp,
    obs_dim: usize,
    act_dim: usize,
    /// σ of the Gaussian exploration noise of stochastic actions.
    action_noise: f32,
    /// The shape it was built with.
    net_config: NetConfig,
    /// Name prefix of its parameters (`actor`, `actor_target`).
    prefix: &'static str,
}

impl DeterministicActor {
    /// The actor with zero weights, parameters named `{prefix}.…`.
    fn zeroed(
        prefix: &'static str,
        obs_dim: usize,
        act_dim: usize,
        config: &NetConfig,
        action_noise: f32,
    ) -> Result<Self> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu).pp(prefix);
        let features = config.features.build(&vb.pp("features"), obs_dim)?;
        let net = Mlp::new(
            &vb,
            features.features_dim(),
            &config.net_arch,
            act_dim,
            config.activation,
            ACTOR_OUTPUT_GAIN,
        )?;
        Ok(Self {
            varmap,
            features,
            net,
            obs_dim,
            act_dim,
            action_noise,
            net_config: config.clone(),
            prefix,
        })
    }

    fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.features.init_weights(&self.varmap, rng)?;
        self.net.init_weights(&self.varmap, rng)?;
        Ok(())
    }

    /// Actions in `[-1, 1]` for a batch of observations (`batch × obs_dim`).
    pub fn forward(&self, obs: &Tensor) -> Result<Tensor> {
        Ok(self.net.forward(&self.features.forward(obs)?)?.tanh()?)
    }

    /// Actions for a batch of observations (row-major): the policy's when `deterministic`,
    /// else with N(0, `action_noise`²) noise from `rng` added and clipped to `[-1, 1]` (TD3's
    /// exploration). TD3's `predict`, its evaluation and [`crate::Policy`] act
    /// through this.
    pub fn predict(
        &self,
        obs: &[f32],
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<Vec<f32>> {
        let obs = obs_tensor(obs, self.obs_dim, &Device::Cpu)?;
        let mut actions: Vec<f32> = self.forward(&obs)?.flatten_all()?.to_vec1()?;
        if !deterministic {
            for a in &mut actions {
                let noise = self.action_noise * fairgrasp_env::random::standard_normal(rng);
                *a = (*a + noise).clamp(-1.0, 1.0);
            }
        }
        Ok(actions)
    }

    /// Action width.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }
}

impl ActorNet for DeterministicActor {
    fn act(&self, obs: &[f32], deterministic: bool, rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        self.predict(obs, deterministic, rng)
    }

    fn tensors(&self) -> TensorMap {
        varmap_tensors(&self.varmap, "")
    }

    fn description(&self) -> ActorDescription {
        ActorDescription {
            prefix: self.prefix,
            net: self.net_config.clone(),
            head: Head::TanhMean,
        }
    }
}

/// The actor, the critics and the targets of both.
pub struct DeterministicPolicy {
    /// The policy μ.
    pub actor: DeterministicActor,
    /// Its Polyak-averaged copy μ', for the critics' targets.
    pub actor_target: DeterministicActor,
    /// The twin critics and their target.
    pub critics: CriticsWithTarget,
    pub(crate) actor_pairs: TargetPairs,
}

impl DeterministicPolicy {
    /// The networks with zero weights (see [`Self::init_weights`]); stochastic actions add
    /// Gaussian noise of σ `action_noise`.
    pub fn zeroed(
        obs_dim: usize,
        act_dim: usize,
        config: &NetConfig,
        action_noise: f32,
    ) -> Result<Self> {
        let actor = DeterministicActor::zeroed("actor", obs_dim, act_dim, config, action_noise)?;
        let actor_target =
            DeterministicActor::zeroed("actor_target", obs_dim, act_dim, config, action_noise)?;
        let critics = critics_with_target(
            obs_dim,
            act_dim,
            &config.net_arch,
            config.activation,
            &config.features,
        )?;
        Ok(Self {
            actor_pairs: TargetPairs::new(
                &actor.varmap,
                "actor.",
                &actor_target.varmap,
                "actor_target.",
            )?,
            actor,
            actor_target,
            critics,
        })
    }

    /// The groups of variables with their name prefixes, in a fixed order.
    pub fn groups(&self) -> [(&'static str, &VarMap); 4] {
        let [critic, critic_target] = self.critics.groups();
        [
            ("actor.", &self.actor.varmap),
            ("actor_target.", &self.actor_target.varmap),
            critic,
            critic_target,
        ]
    }

    /// Draws the actor's and critics' weights from `rng` and copies them to the targets.
    pub fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        // The actor draws first, as it always has, so a seed keeps its networks.
        self.actor.init_weights(rng)?;
        self.critics.init_weights(rng)?;
        self.actor_pairs.copy()
    }

    /// Polyak averaging of both targets: `target ← (1 − τ) target + τ online`.
    pub fn soft_update(&self, tau: f32) -> Result<()> {
        self.actor_pairs.soft_update(tau)?;
        self.critics.soft_update(tau)
    }
}
