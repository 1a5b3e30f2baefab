//! The networks SAC and TD3 share: twin Q networks on `[features, action]` and Polyak-averaged
//! target copies of a network.

use crate::error::{Result, RlError};
use crate::nn::{Activation, Mlp};
use crate::policies::features::{FeaturesConfig, FeaturesExtractor};
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use rand::Rng;

/// Output-layer gain of the critics (see [`Mlp::new`]).
const CRITIC_OUTPUT_GAIN: f64 = 1.0;

/// Online twin critics named `critic.…`, their Polyak-averaged target copy named
/// `critic_target.…`, and the pairs the update walks: what SAC and TD3 build alike.
pub struct CriticsWithTarget {
    /// The critics that learn.
    pub online: TwinCritics,
    /// Their Polyak-averaged copy, for the bootstrap targets.
    pub target: TwinCritics,
    pub(crate) pairs: TargetPairs,
}

/// The critics and their target with zero weights (see [`CriticsWithTarget::init_weights`]).
pub fn critics_with_target(
    obs_dim: usize,
    act_dim: usize,
    net_arch: &[usize],
    activation: Activation,
    features: &FeaturesConfig,
) -> Result<CriticsWithTarget> {
    let critics = |prefix: &str| {
        TwinCritics::zeroed(prefix, obs_dim, act_dim, net_arch, activation, features)
    };
    let (online, target) = (critics("critic")?, critics("critic_target")?);
    let pairs = TargetPairs::new(&online.varmap, "critic.", &target.varmap, "critic_target.")?;
    Ok(CriticsWithTarget {
        online,
        target,
        pairs,
    })
}

impl CriticsWithTarget {
    /// The two groups of variables with their name prefixes, online first.
    pub fn groups(&self) -> [(&'static str, &VarMap); 2] {
        [
            ("critic.", &self.online.varmap),
            ("critic_target.", &self.target.varmap),
        ]
    }

    /// Draws the online critics' weights from `rng` and copies them to the target.
    pub fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.online.init_weights(rng)?;
        self.pairs.copy()
    }

    /// Polyak averaging of the target: `target ← (1 − τ) target + τ online`.
    pub fn soft_update(&self, tau: f32) -> Result<()> {
        self.pairs.soft_update(tau)
    }
}

/// Twin Q networks (Fujimoto et al. 2018: the minimum of two critics curbs the overestimation
/// a single one accumulates). The two share one feature extractor.
pub struct TwinCritics {
    /// Both critics' parameters (and the extractor's), by name.
    pub varmap: VarMap,
    features: Box<dyn FeaturesExtractor>,
    qf1: Mlp,
    qf2: Mlp,
}

impl TwinCritics {
    /// Critics with zero weights, their parameters named `{prefix}.qf1.…`, `{prefix}.qf2.…`.
    pub fn zeroed(
        prefix: &str,
        obs_dim: usize,
        act_dim: usize,
        net_arch: &[usize],
        activation: Activation,
        features: &FeaturesConfig,
    ) -> Result<Self> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu).pp(prefix);
        let features = features.build(&vb.pp("features"), obs_dim)?;
        let critic = |name: &str| {
            Mlp::new(
                &vb.pp(name),
                features.features_dim() + act_dim,
                net_arch,
                1,
                activation,
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

    /// Draws the extractor's and both critics' weights from `rng`.
    pub fn init_weights(&self, rng: &mut impl Rng) -> Result<()> {
        self.features.init_weights(&self.varmap, rng)?;
        self.qf1.init_weights(&self.varmap, rng)?;
        self.qf2.init_weights(&self.varmap, rng)?;
        Ok(())
    }

    fn input(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        Ok(Tensor::cat(&[&self.features.forward(obs)?, actions], 1)?)
    }

    /// Both critics' values, each `batch`.
    pub fn q(&self, obs: &Tensor, actions: &Tensor) -> Result<(Tensor, Tensor)> {
        let x = self.input(obs, actions)?;
        Ok((
            self.qf1.forward(&x)?.squeeze(1)?,
            self.qf2.forward(&x)?.squeeze(1)?,
        ))
    }

    /// The first critic's value alone, `batch` (TD3's actor loss).
    pub fn q1(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        Ok(self.qf1.forward(&self.input(obs, actions)?)?.squeeze(1)?)
    }

    /// The smaller of the two values, `batch`.
    pub fn min_q(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        let (q1, q2) = self.q(obs, actions)?;
        Ok(q1.minimum(&q2)?)
    }

    /// The input with the extractor's weights as constants.
    fn input_detached(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        Ok(Tensor::cat(
            &[&self.features.forward(obs)?.detach(), actions],
            1,
        )?)
    }

    /// [`Self::min_q`] with the critics' weights as constants (see [`Mlp::forward_detached`]):
    /// for an actor's loss, whose gradient only the actor's optimiser uses.
    pub fn min_q_detached(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        let x = self.input_detached(obs, actions)?;
        let q1 = self.qf1.forward_detached(&x)?.squeeze(1)?;
        let q2 = self.qf2.forward_detached(&x)?.squeeze(1)?;
        Ok(q1.minimum(&q2)?)
    }

    /// [`Self::q1`] with the critics' weights as constants (TD3's actor loss).
    pub fn q1_detached(&self, obs: &Tensor, actions: &Tensor) -> Result<Tensor> {
        let x = self.input_detached(obs, actions)?;
        Ok(self.qf1.forward_detached(&x)?.squeeze(1)?)
    }
}

/// (online, target) variable pairs of a network and its target copy, matched by name
/// (`{online}.x` with `{target}.x`).
pub struct TargetPairs(pub(crate) Vec<(Var, Var)>);

impl TargetPairs {
    /// Pairs each variable of `online` with the one of `target` of the same name after its
    /// prefix; errors when the target lacks one.
    pub fn new(
        online: &VarMap,
        online_prefix: &str,
        target: &VarMap,
        target_prefix: &str,
    ) -> Result<Self> {
        let online = online.data().lock().expect("varmap lock");
        let target = target.data().lock().expect("varmap lock");
        let mut pairs: Vec<(String, Var, Var)> = online
            .iter()
            .map(|(name, v)| {
                let rest = name.strip_prefix(online_prefix).unwrap_or(name);
                let target_name = format!("{target_prefix}{rest}");
                let t = target.get(&target_name).cloned().ok_or_else(|| {
                    RlError::Other(format!("target network lacks `{target_name}`"))
                })?;
                Ok((name.clone(), v.clone(), t))
            })
            .collect::<Result<_>>()?;
        pairs.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(Self(pairs.into_iter().map(|(_, o, t)| (o, t)).collect()))
    }

    /// `target ← online`.
    pub fn copy(&self) -> Result<()> {
        for (online, target) in &self.0 {
            target.set(online.as_tensor())?;
        }
        Ok(())
    }

    /// Polyak averaging: `target ← (1 − τ) target + τ online`, in place.
    pub fn soft_update(&self, tau: f32) -> Result<()> {
        for (online, target) in &self.0 {
            crate::kernels::candle_ops::polyak_update(target, online.as_tensor(), tau as f64)?;
        }
        Ok(())
    }
}
