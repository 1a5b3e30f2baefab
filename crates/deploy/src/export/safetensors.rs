//! The policy as a standalone safetensors file: the deterministic actor's layers, the
//! observation statistics and the environment's action box, described by `__metadata__`, for
//! users who run the network with their own code (PyTorch, NumPy). Tensor names:
//!
//! - `obs_norm.mean`, `obs_norm.var` (f64, `obs_dim`): only when the model normalises
//!   observations (`normalized` = `true`): `clip((obs − mean) / sqrt(var + obs_norm_epsilon),
//!   ±obs_norm_clip)`;
//! - `policy.l{i}.weight` (f32, `outputs × inputs`) and `policy.l{i}.bias` (f32, `outputs`), in
//!   the order of `layers`: `y = x Wᵀ + b`, `activation` after every layer but the last; the
//!   last layer gives the action mean (SAC: its log-std rows are left out);
//! - `env_action.low`, `env_action.high` (f32, `act_dim`): the environment's action box.
//!
//! The deterministic action is the last layer's output (`head` = `identity`, PPO) or its tanh
//! (`head` = `tanh`, SAC); the environment receives `low + (clip(action, ±1) + 1)(high − low)/2`.

use crate::export::spec::{Head, PolicySpec};
use ::safetensors::tensor::{Dtype, TensorView};
use fairgrasp_rl::nn::Activation;
use std::collections::HashMap;

/// `__metadata__`'s `format` value.
pub const FORMAT: &str = "fairgrasp.policy";
/// `__metadata__`'s `version` value: the layout described in the module documentation.
pub const VERSION: u32 = 1;

/// The name of layer `i`'s tensors (`policy.l{i}`).
pub fn layer_name(i: usize) -> String {
    format!("policy.l{i}")
}

/// The serialised safetensors file of `spec`.
pub fn safetensors_bytes(spec: &PolicySpec) -> Result<Vec<u8>, String> {
    if spec.camera.is_some() {
        return Err(
            "a camera policy exports as ONNX only (--format onnx); its weights are \
                    model.safetensors beside model.json"
                .into(),
        );
    }
    let mut tensors: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    let mut add = |name: String, dtype, shape: Vec<usize>, bytes: Vec<u8>| {
        tensors.push((name, dtype, shape, bytes));
    };
    if let Some(n) = &spec.normalization {
        add(
            "obs_norm.mean".into(),
            Dtype::F64,
            vec![n.mean.len()],
            f64_bytes(&n.mean),
        );
        add(
            "obs_norm.var".into(),
            Dtype::F64,
            vec![n.var.len()],
            f64_bytes(&n.var),
        );
    }
    for (i, layer) in spec.layers.iter().enumerate() {
        let shape = vec![layer.outputs, layer.inputs];
        add(
            format!("{}.weight", layer_name(i)),
            Dtype::F32,
            shape,
            f32_bytes(&layer.weight),
        );
        let shape = vec![layer.outputs];
        add(
            format!("{}.bias", layer_name(i)),
            Dtype::F32,
            shape,
            f32_bytes(&layer.bias),
        );
    }
    let box_ = &spec.env_action;
    add(
        "env_action.low".into(),
        Dtype::F32,
        vec![box_.low.len()],
        f32_bytes(&box_.low),
    );
    add(
        "env_action.high".into(),
        Dtype::F32,
        vec![box_.high.len()],
        f32_bytes(&box_.high),
    );

    let views = tensors
        .iter()
        .map(|(name, dtype, shape, bytes)| {
            TensorView::new(*dtype, shape.clone(), bytes)
                .map(|view| (name.clone(), view))
                .map_err(|e| format!("tensor `{name}`: {e}"))
        })
        .collect::<Result<Vec<_>, String>>()?;
    ::safetensors::tensor::serialize(views, Some(metadata(spec)))
        .map_err(|e| format!("cannot encode the safetensors file: {e}"))
}

/// The `__metadata__` map: `format`, `version`, `env_id`, `env_config` (JSON), `algo`,
/// `obs_dim`, `act_dim`, `layers` (comma-separated, in order), `activation`, `head`,
/// `normalized`, `obs_norm_epsilon` and `obs_norm_clip` (when normalised), `action_layout`,
/// `num_timesteps`.
pub fn metadata(spec: &PolicySpec) -> HashMap<String, String> {
    let layers: Vec<String> = (0..spec.layers.len()).map(layer_name).collect();
    let mut out: HashMap<String, String> = [
        ("format", FORMAT.to_string()),
        ("version", VERSION.to_string()),
        ("env_id", spec.env_id.clone()),
        ("env_config", spec.env_config.to_string()),
        ("algo", spec.algo.clone()),
        ("obs_dim", spec.obs_dim.to_string()),
        ("act_dim", spec.act_dim.to_string()),
        ("layers", layers.join(",")),
        (
            "activation",
            match spec.activation {
                Activation::Tanh => "tanh",
                Activation::Relu => "relu",
            }
            .into(),
        ),
        (
            "head",
            match spec.head {
                Head::Mean => "identity",
                Head::TanhMean => "tanh",
            }
            .into(),
        ),
        ("normalized", spec.normalization.is_some().to_string()),
        ("action_layout", spec.action_layout.clone()),
        ("num_timesteps", spec.num_timesteps.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    if let Some(n) = &spec.normalization {
        // `{}` of an f64 prints the shortest text that reads back to the same value.
        out.insert("obs_norm_epsilon".into(), n.epsilon.to_string());
        out.insert("obs_norm_clip".into(), n.clip.to_string());
    }
    out
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}
