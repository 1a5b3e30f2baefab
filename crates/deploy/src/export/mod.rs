//! ONNX and safetensors files of a trained policy (`fairgrasp export`), for running it outside
//! fairgrasp. docs/export.md describes both files and what stays outside them.
//!
//! - [`spec`]: what an exported policy holds, read from a [`Policy`];
//! - [`onnx`]: the ONNX graph (raw observation → action and environment action);
//! - [`safetensors`]: the tensors and statistics with a `__metadata__` description.

pub mod onnx;
pub mod safetensors;
pub mod spec;

use crate::error::{DeployError, Result};
use fairgrasp_rl::Policy;
use spec::PolicySpec;
use std::path::{Path, PathBuf};

/// The file formats `fairgrasp export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// `policy.onnx`: the ONNX graph.
    Onnx,
    /// `policy.safetensors`: the tensors, with a `__metadata__` description.
    Safetensors,
}

impl Format {
    /// The default file name in the model directory.
    pub fn default_file_name(self) -> &'static str {
        match self {
            Format::Onnx => "policy.onnx",
            Format::Safetensors => "policy.safetensors",
        }
    }
}

impl std::str::FromStr for Format {
    type Err = DeployError;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "onnx" => Ok(Format::Onnx),
            "safetensors" => Ok(Format::Safetensors),
            other => Err(DeployError::config(
                "format",
                format!("unknown export format `{other}` (expected onnx or safetensors)"),
            )),
        }
    }
}

/// Loads the model at `policy_dir` (a model directory or a run directory, as `fairgrasp eval`
/// takes) and writes it as `format` to `out`, by default `policy.onnx` or `policy.safetensors`
/// in the model directory. Returns the path written. A bad model directory is an error naming
/// it.
pub fn export(policy_dir: &Path, format: Format, out: Option<&Path>) -> Result<PathBuf> {
    let policy = Policy::load(policy_dir).map_err(|e| {
        DeployError::config(
            format!("model {}", policy_dir.display()),
            format!("cannot load: {e}"),
        )
    })?;
    let out = match out {
        Some(path) => path.to_path_buf(),
        None => policy
            .dir()
            .unwrap_or(policy_dir)
            .join(format.default_file_name()),
    };
    export_policy(&policy, format, &out)?;
    Ok(out)
}

/// Writes `policy` as `format` to `out`, atomically (a crash leaves any previous file whole).
pub fn export_policy(policy: &Policy, format: Format, out: &Path) -> Result<()> {
    let spec = PolicySpec::from_policy(policy)?;
    let bytes = match format {
        Format::Onnx => onnx::onnx_bytes(&spec),
        Format::Safetensors => safetensors::safetensors_bytes(&spec),
    }
    .map_err(|e| DeployError::config(spec::model_name(policy), e))?;
    fairgrasp_env::atomic::write(out, &bytes)
        .map_err(|e| DeployError::config(out.display().to_string(), format!("cannot write: {e}")))
}
