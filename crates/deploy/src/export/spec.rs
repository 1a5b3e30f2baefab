//! What an exported policy holds, read once from a [`Policy`]: the observation normalisation,
//! the actor's dense layers up to the deterministic action, and the affine map from that action
//! to what the environment receives. Both file formats are written from this.

use crate::error::{DeployError, Result};
use candle_core::Tensor;
use fairgrasp_env::Env;
use fairgrasp_env::spaces::ImageView;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_rl::Policy;
use fairgrasp_rl::nn::Activation;
use fairgrasp_rl::policies::FeaturesConfig;
pub use fairgrasp_rl::policies::Head;
use fairgrasp_rl::policies::pixel_actor::PixelActor;

/// `clip((obs − mean) / sqrt(var + epsilon), ±clip)`, computed in f64 as
/// [`fairgrasp_env::wrappers::VecNormalizeState::normalize_obs`] does.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsNormalization {
    /// Running mean of each observation value.
    pub mean: Vec<f64>,
    /// Running variance of each observation value.
    pub var: Vec<f64>,
    /// Added to the variance before the square root.
    pub epsilon: f64,
    /// Bound on each normalised value (±).
    pub clip: f64,
}

impl ObsNormalization {
    /// `sqrt(var + epsilon)` per observation value: what the centred observation is divided by.
    pub fn scale(&self) -> Vec<f64> {
        self.var.iter().map(|v| (v + self.epsilon).sqrt()).collect()
    }
}

/// One fully connected layer: `y = x Wᵀ + b`.
#[derive(Clone, Debug, PartialEq)]
pub struct Dense {
    /// The layer's name in `model.safetensors` (`pi.l0`, `actor.l2`).
    pub name: String,
    /// Width of the input.
    pub inputs: usize,
    /// Width of the output.
    pub outputs: usize,
    /// `outputs × inputs`, row-major (PyTorch's and candle's layout).
    pub weight: Vec<f32>,
    /// `outputs` values.
    pub bias: Vec<f32>,
}

/// One convolution of a camera's encoder: `filters` kernels of `kernel × kernel` over
/// `channels`, stride `stride`, no padding, ReLU after.
#[derive(Clone, Debug, PartialEq)]
pub struct Conv {
    /// The layer's name in `model.safetensors` (`enc0.conv1`).
    pub name: String,
    /// Input channels.
    pub channels: usize,
    /// Output channels.
    pub filters: usize,
    /// Kernel side.
    pub kernel: usize,
    /// Stride.
    pub stride: usize,
    /// `filters × kernel × kernel × channels`, row-major: channel-last patches, as fairgrasp's
    /// kernels read them (ONNX's `Conv` takes `filters × channels × kernel × kernel`).
    pub weight: Vec<f32>,
    /// `filters` values.
    pub bias: Vec<f32>,
}

/// One camera's encoder: its `u8` image (channel-last) scaled to [0, 1], the convolutions,
/// then a dense layer with ReLU over the last one's output flattened channel-last.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoder {
    /// The camera's image: its name is the input's.
    pub view: ImageView,
    /// Input side first.
    pub convs: Vec<Conv>,
    /// The dense layer to the encoder's features.
    pub fc: Dense,
}

/// What a camera policy reads besides the state vector, and how: the head's input is every
/// encoder's features in order, then the state standardised (`(state − mean) / std`).
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInputs {
    /// One per camera, in the order of the head's input.
    pub encoders: Vec<Encoder>,
    /// Subtracted from each state value.
    pub state_mean: Vec<f32>,
    /// What the centred state values are divided by.
    pub state_std: Vec<f32>,
}

/// The environment's own action box, onto which `[-1, 1]` is mapped (the trainer's
/// [`RescaleAction`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ActionBox {
    /// Lower bound of each action value.
    pub low: Vec<f32>,
    /// Upper bound of each action value.
    pub high: Vec<f32>,
}

/// Everything an exported policy file holds.
#[derive(Clone, Debug)]
pub struct PolicySpec {
    /// Id of the environment it was trained on (`"FaArmGrasp-v0"`).
    pub env_id: String,
    /// The environment's configuration, as the model saved it.
    pub env_config: serde_json::Value,
    /// How it learnt: the algorithm's name (`ppo`), or `distilled from a ppo teacher`.
    pub algo: String,
    /// Observation width.
    pub obs_dim: usize,
    /// Action width.
    pub act_dim: usize,
    /// Environment steps it was trained for.
    pub num_timesteps: u64,
    /// `None` when the model acts on raw observations.
    pub normalization: Option<ObsNormalization>,
    /// A camera policy's images and encoders (`None`: the policy reads the observation vector
    /// alone).
    pub camera: Option<CameraInputs>,
    /// In order from the observation (a camera policy: from the encoders' features and the
    /// standardised state); an activation follows every layer but the last.
    pub layers: Vec<Dense>,
    /// The activation after each hidden layer.
    pub activation: Activation,
    /// How the last layer's outputs become the action.
    pub head: Head,
    /// The environment's action box; the policy's `[-1, 1]` actions are mapped onto it.
    pub env_action: ActionBox,
    /// What each action value means, in words.
    pub action_layout: String,
}

impl PolicySpec {
    /// Reads `policy`'s networks, statistics and environment. The environment is built once
    /// through the registry for its action box; an unknown environment or settings the
    /// registry refuses are errors.
    pub fn from_policy(policy: &Policy) -> Result<Self> {
        let meta = policy.meta();
        let fail = |message: String| DeployError::config(model_name(policy), message);
        let (env_action, action_layout) = environment_actions(policy).map_err(fail)?;
        let mut spec = Self {
            env_id: meta.env_id.clone(),
            env_config: meta.env.clone(),
            algo: meta.algo.algo().to_string(),
            obs_dim: meta.obs_dim,
            act_dim: meta.act_dim,
            num_timesteps: meta.num_timesteps,
            normalization: None,
            camera: None,
            layers: Vec::new(),
            activation: Activation::Relu,
            head: Head::Mean,
            env_action,
            action_layout,
        };
        if let Some(actor) = policy.pixel_actor() {
            let (camera, layers) = camera_policy(actor).map_err(fail)?;
            check_chain(&layers, layers[0].inputs, meta.act_dim).map_err(fail)?;
            (spec.camera, spec.layers) = (Some(camera), layers);
            spec.algo = meta.trained_by();
            return Ok(spec);
        }
        let actor = policy
            .actor_description()
            .ok_or_else(|| fail("the model's actor cannot be exported".into()))?;
        let (prefix, net_arch, activation, head) = (
            actor.prefix,
            &actor.net.net_arch,
            actor.net.activation,
            actor.head,
        );
        // The flatten extractor is the identity on flat observations. A new extractor must be
        // added to the exported graph before this match compiles again.
        match actor.net.features {
            FeaturesConfig::Flatten {} => {}
        }
        let tensors = policy.actor_tensors();
        let mut layers = Vec::with_capacity(net_arch.len() + 1);
        for i in 0..=net_arch.len() {
            let name = format!("{prefix}.l{i}");
            let get = |part: &str| {
                tensors
                    .get(&format!("{name}.{part}"))
                    .ok_or_else(|| fail(format!("the actor has no tensor `{name}.{part}`")))
            };
            let (outputs, inputs) = get("weight")?
                .dims2()
                .map_err(|e| fail(format!("`{name}.weight`: {e}")))?;
            let mut layer = Dense {
                weight: values(get("weight")?).map_err(|e| fail(format!("{name}: {e}")))?,
                bias: values(get("bias")?).map_err(|e| fail(format!("{name}: {e}")))?,
                name,
                inputs,
                outputs,
            };
            if i == net_arch.len() && head == Head::TanhMean {
                // SAC's last layer gives the means, then the log standard deviations, which a
                // deterministic action does not use (TD3's gives the actions alone: a no-op).
                layer.outputs = meta.act_dim;
                layer.weight.truncate(meta.act_dim * inputs);
                layer.bias.truncate(meta.act_dim);
            }
            layers.push(layer);
        }
        check_chain(&layers, meta.obs_dim, meta.act_dim).map_err(fail)?;
        let normalization = policy
            .normalization()
            .filter(|n| n.config.norm_obs)
            .map(|n| ObsNormalization {
                mean: n.obs_rms.mean().to_vec(),
                var: n.obs_rms.var().to_vec(),
                epsilon: n.config.epsilon,
                clip: n.config.clip_obs as f64,
            });
        spec.normalization = normalization;
        (spec.layers, spec.activation, spec.head) = (layers, activation, head);
        Ok(spec)
    }
}

/// A camera policy's encoders and standardisation, and its head's layers.
fn camera_policy(actor: &PixelActor) -> Result<(CameraInputs, Vec<Dense>), String> {
    let tensors = actor.weights();
    let get = |name: &str| -> Result<(Vec<usize>, Vec<f32>), String> {
        let t = (tensors.get(name)).ok_or_else(|| format!("the camera policy has no `{name}`"))?;
        Ok((
            t.dims().to_vec(),
            values(t).map_err(|e| format!("{name}: {e}"))?,
        ))
    };
    let dense = |name: String| -> Result<Dense, String> {
        let (dims, weight) = get(&format!("{name}.weight"))?;
        let (_, bias) = get(&format!("{name}.bias"))?;
        Ok(Dense {
            name,
            inputs: dims[1],
            outputs: dims[0],
            weight,
            bias,
        })
    };
    let mut encoders = Vec::new();
    for (v, (encoder, view)) in actor
        .encoders()
        .iter()
        .zip(&actor.images().views)
        .enumerate()
    {
        let mut convs = Vec::new();
        for (i, shape) in encoder.convs().iter().enumerate() {
            let name = format!("enc{v}.conv{i}");
            convs.push(Conv {
                weight: get(&format!("{name}.weight"))?.1,
                bias: get(&format!("{name}.bias"))?.1,
                name,
                channels: shape.channels,
                filters: shape.filters,
                kernel: shape.kernel,
                stride: shape.stride,
            });
        }
        let fc = dense(format!("enc{v}.fc"))?;
        encoders.push(Encoder {
            view: view.clone(),
            convs,
            fc,
        });
    }
    let head = (0..=actor.config().net_arch.len())
        .map(|l| dense(format!("head.{l}")))
        .collect::<Result<Vec<_>, _>>()?;
    let (mean, std) = actor.state_scale();
    let camera = CameraInputs {
        encoders,
        state_mean: mean.to_vec(),
        state_std: std.to_vec(),
    };
    Ok((camera, head))
}

/// How errors name the policy: its directory, or `policy` for one built in memory.
pub(crate) fn model_name(policy: &Policy) -> String {
    policy
        .dir()
        .map(|d| d.display().to_string())
        .unwrap_or_else(|| "policy".into())
}

/// A tensor's values as f32, row-major.
fn values(t: &Tensor) -> candle_core::Result<Vec<f32>> {
    t.to_dtype(candle_core::DType::F32)?
        .flatten_all()?
        .to_vec1()
}

/// Errors unless each layer feeds the next, from `obs_dim` values to `act_dim`.
fn check_chain(layers: &[Dense], obs_dim: usize, act_dim: usize) -> Result<(), String> {
    let mut width = obs_dim;
    for layer in layers {
        if layer.inputs != width
            || layer.weight.len() != layer.inputs * layer.outputs
            || layer.bias.len() != layer.outputs
        {
            return Err(format!(
                "layer `{}` takes {} values to {} ({} weights, {} biases); expected {width} inputs",
                layer.name,
                layer.inputs,
                layer.outputs,
                layer.weight.len(),
                layer.bias.len()
            ));
        }
        width = layer.outputs;
    }
    if width != act_dim {
        return Err(format!(
            "the actor gives {width} values, the model has {act_dim} actions"
        ));
    }
    Ok(())
}

/// The environment's action box (as the trainer's [`RescaleAction`] sees it) and the action
/// layout in words.
fn environment_actions(policy: &Policy) -> Result<(ActionBox, String), String> {
    let id = policy.env_id();
    let table = fairgrasp_rl::model::env_table(policy.env_config()).map_err(|e| e.to_string())?;
    let built = fairgrasp_env::registry::make(id, &table)
        .and_then(RescaleAction::new)
        .map_err(|e| format!("cannot build its environment {id}: {e}"))?;
    let space = built.inner().action_space();
    if space.dim() != policy.act_dim() {
        return Err(format!(
            "environment {id} takes {} action values, the model gives {}",
            space.dim(),
            policy.act_dim()
        ));
    }
    let mode = fairgrasp_env::registry::effective_config(id, &table)
        .ok()
        .and_then(|c| {
            c.get("control")?
                .get("action_mode")?
                .as_str()
                .map(String::from)
        });
    let n = policy.act_dim();
    let layout = match mode.as_deref() {
        Some("joint") => format!(
            "joint: {} joint-angle deltas (rad), then the gripper command (> 0 opens)",
            n - 1
        ),
        Some("cartesian") => {
            "cartesian: TCP dx, dy, dz (m) and dyaw (rad), then the gripper command (> 0 opens)"
                .into()
        }
        _ if n == 1 => "one value in the environment's action box".into(),
        _ => format!("{n} values in the environment's action box"),
    };
    let action_box = ActionBox {
        low: space.low.clone(),
        high: space.high.clone(),
    };
    Ok((action_box, layout))
}
