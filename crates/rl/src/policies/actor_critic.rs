//! PPO's policy (SB3's `ActorCriticPolicy`): a feature extractor shared by a Gaussian policy
//! head `pi` (state-independent log std) and a value head `vf`.
//!
//! With a privileged critic (asymmetric actor-critic, Pinto et al. 2018) the value head reads
//! the observation followed by the environment's privileged state ([`Info::privileged`]), which
//! the policy head never sees: only `pi` and `log_std` act, on the arm as in training.
//!
//! [`Info::privileged`]: fairgrasp_env::Info::privileged

use crate::algorithm::{TensorMap, varmap_tensors};
use crate::distributions::{DiagGaussian, log_prob_term, standard_normal_tensor};
use crate::error::{Result, RlError};
use crate::kernels::mlp;
use crate::nn::{Activation, Mlp};
use crate::policies::actor::{ActorDescription, ActorNet, Head};
use crate::policies::features::{FeaturesConfig, FeaturesExtractor};
use crate::policies::net_config::NetConfig;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use fairgrasp_env::random::standard_normal;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Output-layer gains (see [`Mlp::new`]): small for the policy means, so the first actions are
/// near zero (as CleanRL does), ordinary for the value.
const PI_OUTPUT_GAIN: f64 = 0.01;
const VF_OUTPUT_GAIN: f64 = 1.0;

/// A Gaussian policy with a state-independent standard deviation, and a value network, both
/// reading the same features. Parameters: `pi.*`, `vf.*`, `log_std` (and `features.*` for an
/// extractor with parameters).
pub struct ActorCritic {
    /// Every parameter, by name.
    pub varmap: VarMap,
    features: Box<dyn FeaturesExtractor>,
    pi: Mlp,
    vf: Mlp,
    log_std: Var,
    /// Observation width.
    pub obs_dim: usize,
    /// Action width.
    pub act_dim: usize,
    /// Privileged values the value head reads after the observation (0: it reads the
    /// observation's features only).
    pub privileged_dim: usize,
    device: Device,
    /// Whether acting runs the networks written out ([`crate::kernels::mlp`]: tanh layers on flat
    /// observations) instead of through candle tensors.
    written_out: bool,
    /// The shape it was built with.
    net_config: NetConfig,
}

/// What the policy decided for a batch of observations.
#[derive(Clone, Debug, Default)]
pub struct PolicyOutput {
    /// Sampled (or, deterministically, mean) actions, unclipped.
    pub actions: Vec<f32>,
    /// Log-probability (nats) of each row's action, one per row.
    pub log_probs: Vec<f32>,
    /// The value head's estimate of each row.
    pub values: Vec<f32>,
}

impl ActorCritic {
    /// The networks, with weights drawn from `rng` (see [`Mlp::init_weights`]).
    pub fn new(
        obs_dim: usize,
        act_dim: usize,
        privileged_dim: usize,
        config: &NetConfig,
        log_std_init: f32,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let policy = Self::zeroed(obs_dim, act_dim, privileged_dim, config, log_std_init)?;
        policy.features.init_weights(&policy.varmap, rng)?;
        policy.pi.init_weights(&policy.varmap, rng)?;
        policy.vf.init_weights(&policy.varmap, rng)?;
        Ok(policy)
    }

    /// The networks with zero weights (`log_std` at `log_std_init`), to load weights into.
    pub fn zeroed(
        obs_dim: usize,
        act_dim: usize,
        privileged_dim: usize,
        config: &NetConfig,
        log_std_init: f32,
    ) -> Result<Self> {
        if privileged_dim > 0 && config.features != (FeaturesConfig::Flatten {}) {
            return Err(RlError::Other(
                "a privileged critic reads flat observations (features.kind = \"flatten\")".into(),
            ));
        }
        let device = Device::Cpu;
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &device);
        let features = config.features.build(&vb.pp("features"), obs_dim)?;
        let (arch, activation) = (&config.net_arch, config.activation);
        let dim = features.features_dim();
        let pi = Mlp::new(&vb.pp("pi"), dim, arch, act_dim, activation, PI_OUTPUT_GAIN)?;
        let vf_in = dim + privileged_dim;
        let vf = Mlp::new(&vb.pp("vf"), vf_in, arch, 1, activation, VF_OUTPUT_GAIN)?;
        vb.get_with_hints(
            act_dim,
            "log_std",
            candle_nn::Init::Const(log_std_init as f64),
        )?;
        let log_std = varmap
            .data()
            .lock()
            .expect("varmap lock")
            .get("log_std")
            .cloned()
            .ok_or_else(|| RlError::Other("log_std parameter missing".into()))?;
        Ok(Self {
            varmap,
            features,
            pi,
            vf,
            log_std,
            obs_dim,
            act_dim,
            privileged_dim,
            device,
            written_out: config.activation == Activation::Tanh
                && config.features == FeaturesConfig::Flatten {},
            net_config: config.clone(),
        })
    }

    /// `obs` (whole observations, row-major) as a `batch × obs_dim` tensor.
    pub fn obs_tensor(&self, obs: &[f32]) -> Result<Tensor> {
        obs_tensor(obs, self.obs_dim, &self.device)
    }

    /// The policy and value networks (for PPO's loss written out, [`crate::ppo::fused_loss`]).
    pub(crate) fn heads(&self) -> (&Mlp, &Mlp) {
        (&self.pi, &self.vf)
    }

    /// The log standard deviation of every action dimension.
    pub fn log_std(&self) -> &Tensor {
        self.log_std.as_tensor()
    }

    /// The action distribution for a batch of observations.
    pub fn distribution(&self, obs: &Tensor) -> Result<DiagGaussian> {
        let features = self.features.forward(obs)?;
        self.distribution_from_features(&features)
    }

    fn distribution_from_features(&self, features: &Tensor) -> Result<DiagGaussian> {
        Ok(DiagGaussian::new(
            self.pi.forward(features)?,
            self.log_std.as_tensor().clone(),
        )?)
    }

    /// The action distribution and the state values (`batch`), from one feature pass; the
    /// values from `critic_obs` (`batch × critic_dim`) with a privileged critic.
    pub fn forward(
        &self,
        obs: &Tensor,
        critic_obs: Option<&Tensor>,
    ) -> Result<(DiagGaussian, Tensor)> {
        let features = self.features.forward(obs)?;
        let values = match (self.privileged_dim, critic_obs) {
            (0, _) => self.vf.forward(&features)?,
            (_, Some(critic_obs)) => self.vf.forward(critic_obs)?,
            (_, None) => return Err(self.no_critic_obs()),
        };
        Ok((
            self.distribution_from_features(&features)?,
            values.squeeze(1)?,
        ))
    }

    /// Values per row of the value head's input: the observation, followed by the privileged
    /// state with a privileged critic.
    pub fn critic_dim(&self) -> usize {
        self.obs_dim + self.privileged_dim
    }

    fn no_critic_obs(&self) -> RlError {
        RlError::Other(format!(
            "the privileged critic reads {} values per row (observation and privileged state); \
             none were given",
            self.critic_dim()
        ))
    }

    /// State values for a batch of the value head's inputs (rows of [`Self::critic_dim`]:
    /// observations, or observations and privileged states).
    pub fn values(&self, critic_obs: &[f32]) -> Result<Vec<f32>> {
        if self.written_out || self.privileged_dim > 0 {
            let rows = rows_of(critic_obs, self.critic_dim())?;
            return Ok(mlp::forward_mlp(&self.vf, critic_obs, rows)?);
        }
        let features = self.features.forward(&self.obs_tensor(critic_obs)?)?;
        Ok(self.vf.forward(&features)?.flatten_all()?.to_vec1()?)
    }

    /// Samples actions (or takes the means when `deterministic`), with log-probabilities and
    /// values. The noise comes from `rng`, `act_dim` draws per observation in order, so a
    /// seeded run is reproducible.
    pub fn act(
        &self,
        obs: &[f32],
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<PolicyOutput> {
        self.act_with_critic(obs, None, deterministic, rng)
    }

    /// [`Self::act`], the values read from `critic_obs` (rows of [`Self::critic_dim`]) where
    /// given; a privileged critic needs them.
    pub fn act_with_critic(
        &self,
        obs: &[f32],
        critic_obs: Option<&[f32]>,
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<PolicyOutput> {
        if self.privileged_dim > 0 && critic_obs.is_none() {
            return Err(self.no_critic_obs());
        }
        if self.written_out {
            let rows = self.rows(obs)?;
            let (actions, means, log_std) =
                self.actions_written_out(obs, rows, deterministic, rng)?;
            let mut terms = vec![0.0f32; self.act_dim];
            let inv_std: Vec<f32> = log_std.iter().map(|s| (-s).exp()).collect();
            let log_probs = (0..rows)
                .map(|i| {
                    let row = i * self.act_dim..(i + 1) * self.act_dim;
                    for (j, (t, (a, mu))) in terms
                        .iter_mut()
                        .zip(actions[row.clone()].iter().zip(&means[row]))
                        .enumerate()
                    {
                        *t = log_prob_term((a - mu) * inv_std[j], log_std[j]);
                    }
                    mlp::sum(&terms)
                })
                .collect();
            return Ok(PolicyOutput {
                log_probs,
                actions,
                values: self.values(critic_obs.unwrap_or(obs))?,
            });
        }
        let critic_obs = match critic_obs {
            Some(rows) => Some(obs_tensor(rows, self.critic_dim(), &self.device)?),
            None => None,
        };
        let (dist, values) = self.forward(&self.obs_tensor(obs)?, critic_obs.as_ref())?;
        let actions = self.actions(&dist, deterministic, rng)?;
        Ok(PolicyOutput {
            log_probs: dist.log_prob(&actions)?.to_vec1()?,
            actions: actions.flatten_all()?.to_vec1()?,
            values: values.to_vec1()?,
        })
    }

    /// Actions only (no value pass): what [`Self::act`] would take, drawing the same noise.
    /// The trainer's evaluation and [`crate::Policy`] both act through this.
    pub fn predict(
        &self,
        obs: &[f32],
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<Vec<f32>> {
        if self.written_out {
            let rows = self.rows(obs)?;
            return Ok(self.actions_written_out(obs, rows, deterministic, rng)?.0);
        }
        let dist = self.distribution(&self.obs_tensor(obs)?)?;
        Ok(self
            .actions(&dist, deterministic, rng)?
            .flatten_all()?
            .to_vec1()?)
    }

    /// Rows of whole observations in `obs`.
    fn rows(&self, obs: &[f32]) -> Result<usize> {
        rows_of(obs, self.obs_dim)
    }

    /// [`Self::actions`] with the networks written out: `(actions, means, log σ)`, with
    /// candle's arithmetic (`μ + ε·e^{log σ}`), so the actions are candle's to rounding (the
    /// products sum in their own order, the same on every host). Acting through
    /// candle cost 22–34 µs per call for 4 observations, most of it per-operation overhead.
    fn actions_written_out(
        &self,
        obs: &[f32],
        rows: usize,
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<(Vec<f32>, Vec<f32>, Vec<f32>)> {
        let means = mlp::forward_mlp(&self.pi, obs, rows)?;
        let log_std: Vec<f32> = self.log_std.as_tensor().to_vec1()?;
        if deterministic {
            return Ok((means.clone(), means, log_std));
        }
        let std: Vec<f32> = log_std.iter().map(|s| s.exp()).collect();
        let actions = means
            .iter()
            .enumerate()
            .map(|(k, mu)| mu + standard_normal(rng) * std[k % self.act_dim])
            .collect();
        Ok((actions, means, log_std))
    }

    fn actions(
        &self,
        dist: &DiagGaussian,
        deterministic: bool,
        rng: &mut impl Rng,
    ) -> Result<Tensor> {
        if deterministic {
            return Ok(dist.mode());
        }
        let rows = dist.mean().dim(0)?;
        Ok(dist.sample(&standard_normal_tensor(rng, rows, self.act_dim)?)?)
    }
}

/// Rows of `dim` values in `values`; errors unless it holds whole rows.
fn rows_of(values: &[f32], dim: usize) -> Result<usize> {
    if values.is_empty() || dim == 0 || !values.len().is_multiple_of(dim) {
        return Err(RlError::Other(format!(
            "{} observation values are not rows of {dim}",
            values.len(),
        )));
    }
    Ok(values.len() / dim)
}

impl ActorNet for ActorCritic {
    fn act(&self, obs: &[f32], deterministic: bool, rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        self.predict(obs, deterministic, rng)
    }

    fn tensors(&self) -> TensorMap {
        varmap_tensors(&self.varmap, "")
    }

    fn description(&self) -> ActorDescription {
        ActorDescription {
            prefix: "pi",
            net: self.net_config.clone(),
            head: Head::Mean,
        }
    }
}

/// `obs` as a `batch × obs_dim` tensor; errors unless it holds whole observations.
pub(crate) fn obs_tensor(obs: &[f32], obs_dim: usize, device: &Device) -> Result<Tensor> {
    if obs.is_empty() || obs_dim == 0 || !obs.len().is_multiple_of(obs_dim) {
        return Err(RlError::Other(format!(
            "{} observation values are not rows of {obs_dim}",
            obs.len()
        )));
    }
    Ok(Tensor::from_slice(
        obs,
        (obs.len() / obs_dim, obs_dim),
        device,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithm::varmap_tensors;
    use crate::kernels::assert_close;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn config() -> NetConfig {
        NetConfig {
            net_arch: vec![8, 8],
            activation: Activation::Tanh,
            features: FeaturesConfig::Flatten {},
        }
    }

    #[test]
    fn parameter_names_are_those_of_saved_models() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let policy = ActorCritic::new(4, 2, 0, &config(), -0.5, &mut rng).unwrap();
        let mut names: Vec<String> = varmap_tensors(&policy.varmap, "").into_keys().collect();
        names.sort();
        let mut want: Vec<String> = ["pi", "vf"]
            .iter()
            .flat_map(|head| (0..3).map(move |i| format!("{head}.l{i}")))
            .flat_map(|layer| [format!("{layer}.bias"), format!("{layer}.weight")])
            .collect();
        want.push("log_std".into());
        want.sort();
        assert_eq!(names, want);
        assert_eq!(policy.log_std().to_vec1::<f32>().unwrap(), [-0.5, -0.5]);
    }

    #[test]
    fn act_samples_around_the_mean_and_predict_draws_the_same_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let policy = ActorCritic::new(4, 2, 0, &config(), -0.5, &mut rng).unwrap();
        let obs = [0.5f32, -1.0, 0.25, 2.0, 0.0, 0.1, -0.3, 1.0];
        let mean = policy.predict(&obs, true, &mut rng).unwrap();
        let det = policy.act(&obs, true, &mut rng).unwrap();
        assert_eq!(det.actions, mean);
        assert_eq!((det.values.len(), det.log_probs.len()), (2, 2));

        let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(9), ChaCha8Rng::seed_from_u64(9));
        let sampled = policy.act(&obs, false, &mut a).unwrap();
        assert_eq!(
            policy.predict(&obs, false, &mut b).unwrap(),
            sampled.actions
        );
        assert_ne!(sampled.actions, mean);
        // The log-probability is that of N(mean, e^-1) at the sampled action.
        for (row, lp) in sampled.log_probs.iter().enumerate() {
            let want: f32 = (0..2)
                .map(|k| {
                    let i = row * 2 + k;
                    let z = (sampled.actions[i] - mean[i]) / (-0.5f32).exp();
                    -0.5 * z * z + 0.5 - 0.5 * (2.0 * std::f32::consts::PI).ln()
                })
                .sum();
            assert!((lp - want).abs() < 1e-4, "{lp} vs {want}");
        }
        let err = policy.predict(&obs[..3], true, &mut a).unwrap_err();
        assert!(err.to_string().contains("not rows of 4"), "{err}");
    }

    #[test]
    fn a_privileged_critic_s_values_read_the_privileged_state_and_the_actions_never_do() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut policy = ActorCritic::new(4, 2, 3, &config(), -0.5, &mut rng).unwrap();
        let weights = varmap_tensors(&policy.varmap, "");
        assert_eq!(weights["pi.l0.weight"].dims(), [8, 4]);
        assert_eq!(weights["vf.l0.weight"].dims(), [8, 7]);
        let obs = [0.5f32, -1.0, 0.25, 2.0, 0.0, 0.1, -0.3, 1.0];
        let critic = |privileged: [f32; 3]| -> Vec<f32> {
            obs.chunks(4)
                .flat_map(|o| o.iter().chain(&privileged).copied())
                .collect()
        };
        let err = policy.act(&obs, false, &mut rng).err().unwrap();
        assert!(err.to_string().contains("reads 7 values per row"), "{err}");
        for written_out in [true, false] {
            policy.written_out = written_out;
            let run = |privileged: [f32; 3]| {
                let rows = critic(privileged);
                let mut rng = ChaCha8Rng::seed_from_u64(11);
                let out = policy
                    .act_with_critic(&obs, Some(&rows), false, &mut rng)
                    .unwrap();
                // `values` runs written out; acting through candle sums in candle's order.
                assert_close(&out.values, &policy.values(&rows).unwrap(), "values");
                out
            };
            let (a, b) = (run([0.0, 0.0, 0.0]), run([1.0, -2.0, 0.5]));
            assert_eq!((&a.actions, &a.log_probs), (&b.actions, &b.log_probs));
            assert_ne!(a.values, b.values);
        }
    }

    #[test]
    fn acting_written_out_matches_candle() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut policy = ActorCritic::new(4, 2, 0, &config(), -0.5, &mut rng).unwrap();
        let obs: Vec<f32> = (0..12).map(|i| (i as f32 * 0.37).sin() * 2.0).collect();
        // Actions, log-probabilities, values, predicted actions and values again, in a row.
        let run = |policy: &ActorCritic, deterministic: bool| -> Vec<f32> {
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            let out = policy.act(&obs, deterministic, &mut rng).unwrap();
            let predicted = policy.predict(&obs, deterministic, &mut rng).unwrap();
            [
                out.actions,
                out.log_probs,
                out.values,
                predicted,
                policy.values(&obs).unwrap(),
            ]
            .concat()
        };
        assert!(policy.written_out);
        let x = [run(&policy, false), run(&policy, true)].concat();
        policy.written_out = false;
        let y = [run(&policy, false), run(&policy, true)].concat();
        assert_close(&x, &y, "acting");
    }
}
