//! `fairgrasp export`: a saved model as an ONNX graph or a standalone safetensors file, to run
//! outside fairgrasp (docs/export.md).

use anyhow::Result;
use fairgrasp_deploy::export::{Format, export};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ExportArgs {
    /// Model directory (`runs/NAME/best`, `runs/NAME/final`) or a run directory (its best model).
    #[arg(long)]
    pub model: PathBuf,
    /// `onnx` (raw observation in, action out; normalisation inside the graph) or
    /// `safetensors` (the layers and statistics, described in the file's metadata).
    #[arg(long, value_parser = parse_format)]
    pub format: Format,
    /// Where to write (default: `policy.onnx` or `policy.safetensors` in the model directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

fn parse_format(text: &str) -> Result<Format, String> {
    text.parse()
        .map_err(|e: fairgrasp_deploy::DeployError| e.to_string())
}

pub fn run(args: &ExportArgs) -> Result<()> {
    let path = export(&args.model, args.format, args.out.as_deref())?;
    println!("wrote {}", path.display());
    match args.format {
        Format::Onnx => println!(
            "  inputs: observation [batch, obs_dim] float32 (raw); outputs: action (unclipped), \
             env_action (what the environment's step takes)\n  check it: python -c \"import \
             onnxruntime as ort; s = ort.InferenceSession('{}'); print([(i.name, i.shape) for i \
             in s.get_inputs() + s.get_outputs()], s.get_modelmeta().custom_metadata_map)\"",
            path.display()
        ),
        Format::Safetensors => println!(
            "  tensors: obs_norm.*, policy.l*.weight/bias, env_action.low/high; the layout is \
             in its metadata\n  check it: python -c \"from safetensors import safe_open; f = \
             safe_open('{}', 'np'); print(f.metadata(), {{k: f.get_tensor(k).shape for k in \
             f.keys()}})\"",
            path.display()
        ),
    }
    println!("  see docs/export.md for what stays outside the file");
    Ok(())
}
