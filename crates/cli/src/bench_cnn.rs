//! `fairgrasp bench cnn`: the image encoders' forward and forward-plus-backward passes per
//! batch, on the written-out kernels and through candle's `conv2d` and autograd, at the shapes
//! of `bench/cnn`'s PyTorch reference (`bench/harness/torch_cnn.py`).

use anyhow::Result;
use candle_core::{Device, Tensor, Var};
use fairgrasp_env::spaces::ImageView;
use fairgrasp_rl::kernels::product::ProductKernel;
use fairgrasp_rl::policies::cnn::{CnnArch, CnnCache, CnnEncoder};
use rand::{Rng, SeedableRng};
use std::time::Instant;

#[derive(clap::Args)]
pub struct CnnBenchArgs {
    /// Images per batch.
    #[arg(long, default_value_t = 64)]
    pub batch: usize,
    /// Seconds of wall time per measurement.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Print one JSON object per line instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The shapes measured: (name, encoder, image side, features), as the PyTorch reference has them.
pub const SHAPES: [(&str, CnnArch, u32, usize); 2] = [
    ("nature_cnn_84", CnnArch::NatureCnn, 84, 512),
    ("fast_cnn_64", CnnArch::FastCnn, 64, 64),
];

/// Mean seconds per call of `f` over about `seconds` (after one warm-up call).
fn time(seconds: f64, mut f: impl FnMut()) -> f64 {
    f();
    let started = Instant::now();
    let mut calls = 0u32;
    while calls == 0 || started.elapsed().as_secs_f64() < seconds {
        f();
        calls += 1;
    }
    started.elapsed().as_secs_f64() / calls as f64
}

pub fn run(args: &CnnBenchArgs) -> Result<()> {
    anyhow::ensure!(args.batch > 0, "--batch must be at least 1");
    let b = args.batch;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    if !args.json {
        println!(
            "CPU: {}; batch {b}; ms per batch; product kernel {} (FAIRGRASP_IMAGE_KERNEL)",
            crate::host::cpu_model(),
            ProductKernel::current().name()
        );
    }
    for (name, arch, side, features) in SHAPES {
        let view = ImageView {
            name: name.into(),
            height: side,
            width: side,
            channels: 3,
        };
        let encoder = CnnEncoder::new(arch, &view, features).map_err(anyhow::Error::msg)?;
        let params: Vec<Vec<f32>> = (encoder.param_shapes().iter())
            .map(|(_, s)| {
                let n: usize = s.iter().product();
                (0..n).map(|_| rng.random_range(-0.05..0.05)).collect()
            })
            .collect();
        let refs: Vec<&[f32]> = params.iter().map(Vec::as_slice).collect();
        let images: Vec<u8> = (0..b * encoder.image_len()).map(|_| rng.random()).collect();
        let mut cache = CnnCache::default();
        let mut grads: Vec<Vec<f32>> = params.iter().map(|p| vec![0.0; p.len()]).collect();
        let ours_forward = time(args.seconds, || {
            encoder.forward(&refs, &images, b, &mut cache)
        });
        let ours_step = time(args.seconds, || {
            encoder.forward(&refs, &images, b, &mut cache);
            let mut d = vec![1.0f32; b * features];
            encoder.backward(&refs, &mut cache, &mut d, &mut grads);
        });

        // candle: the same stack in NCHW through conv2d and autograd.
        let dev = Device::Cpu;
        let x = Tensor::rand(0f32, 1f32, (b, 3, side as usize, side as usize), &dev)?;
        let mut channels = 3;
        let mut kernels = Vec::new();
        for &(filters, k, stride) in arch.layers() {
            let w = Var::randn(0f32, 0.05, (filters, channels, k, k), &dev)?;
            let bias = Var::zeros((1, filters, 1, 1), candle_core::DType::F32, &dev)?;
            kernels.push((w, bias, stride));
            channels = filters;
        }
        let fc = Var::randn(0f32, 0.05, (features, encoder.flat()), &dev)?;
        let forward = || -> candle_core::Result<Tensor> {
            let mut h = x.clone();
            for (w, bias, stride) in &kernels {
                h = h.conv2d(w, 0, *stride, 1, 1)?.broadcast_add(bias)?.relu()?;
            }
            h.flatten_from(1)?.matmul(&fc.t()?)?.relu()
        };
        let candle_forward = time(args.seconds, || {
            forward().expect("candle forward");
        });
        let candle_step = time(args.seconds, || {
            let y = forward().expect("candle forward");
            y.sum_all()
                .and_then(|s| s.backward())
                .expect("candle backward");
        });
        let ms = |s: f64| s * 1e3;
        if args.json {
            println!(
                "{}",
                serde_json::json!({
                    "shape": name, "batch": b, "cpu": crate::host::cpu_model(),
                    "kernel": ProductKernel::current().name(),
                    "ours_forward_ms": ms(ours_forward), "ours_step_ms": ms(ours_step),
                    "candle_forward_ms": ms(candle_forward), "candle_step_ms": ms(candle_step),
                })
            );
        } else {
            println!(
                "{name}: written-out forward {:.2}, forward+backward {:.2}; candle {:.2}, {:.2} ({:.1}× and {:.1}× ours)",
                ms(ours_forward),
                ms(ours_step),
                ms(candle_forward),
                ms(candle_step),
                candle_forward / ours_forward,
                candle_step / ours_step
            );
        }
    }
    Ok(())
}
