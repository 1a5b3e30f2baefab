//! Image encoders (SB3's `NatureCNN` and a smaller, faster one): convolutions with ReLU, then a
//! linear layer with ReLU to `features` values, over one camera's `u8` images (channel-last, as
//! the environment gives them). Forward and backward run on the written-out kernels
//! ([`crate::kernels::conv`]).

use crate::kernels::conv::{self, ConvScratch, ConvShape};
use crate::kernels::dense::{linear_backward, linear_forward, relu, relu_backward};
use crate::kernels::product::ProductKernel;
use fairgrasp_env::spaces::ImageView;
use serde::{Deserialize, Serialize};

/// Which convolution stack an encoder has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CnnArch {
    /// Mnih et al. 2015 (SB3's `NatureCNN`): 32 filters 8×8 stride 4, 64 4×4 stride 2, 64 3×3
    /// stride 1. Needs at least 36×36 pixels.
    NatureCnn,
    /// 16 filters 5×5 stride 2, 32 3×3 stride 2, 32 3×3 stride 2: about half NatureCNN's work on
    /// 84×84 images and a third of its backward pass on 64×64 (docs/benchmarks.md). Needs at
    /// least 19×19 pixels.
    #[default]
    FastCnn,
}

impl CnnArch {
    /// `(filters, kernel, stride)` of each convolution, input side first.
    pub fn layers(self) -> &'static [(usize, usize, usize)] {
        match self {
            CnnArch::NatureCnn => &[(32, 8, 4), (64, 4, 2), (64, 3, 1)],
            CnnArch::FastCnn => &[(16, 5, 2), (32, 3, 2), (32, 3, 2)],
        }
    }

    /// The name configs use.
    pub fn name(self) -> &'static str {
        match self {
            CnnArch::NatureCnn => "nature_cnn",
            CnnArch::FastCnn => "fast_cnn",
        }
    }
}

/// One camera's encoder: its layer shapes (the parameters live with the network that owns it,
/// in [`CnnEncoder::param_shapes`] order).
#[derive(Clone, Debug, PartialEq)]
pub struct CnnEncoder {
    convs: Vec<ConvShape>,
    features: usize,
}

/// The activations of one batch, kept for the backward pass.
#[derive(Default)]
pub struct CnnCache {
    /// The images as values in [0, 1].
    pixels: Vec<f32>,
    scratch: Vec<ConvScratch>,
    outs: Vec<Vec<f32>>,
    features: Vec<f32>,
    d_in: Vec<f32>,
    d_flat: Vec<f32>,
    batch: usize,
}

impl CnnCache {
    /// The features of the last forward pass (`batch × features`).
    pub fn features(&self) -> &[f32] {
        &self.features
    }
}

impl CnnEncoder {
    /// The encoder `arch` for `view`'s images, ending in `features` values; an error names
    /// the view when its images are too small for the stack.
    pub fn new(arch: CnnArch, view: &ImageView, features: usize) -> Result<Self, String> {
        let (mut h, mut w, mut c) = (
            view.height as usize,
            view.width as usize,
            view.channels as usize,
        );
        let mut convs = Vec::new();
        for &(filters, kernel, stride) in arch.layers() {
            if h < kernel || w < kernel {
                return Err(format!(
                    "{}'s {}×{} images are too small for {} (a {kernel}×{kernel} kernel meets \
                     {h}×{w})",
                    view.name,
                    view.width,
                    view.height,
                    arch.name()
                ));
            }
            let shape = ConvShape {
                height: h,
                width: w,
                channels: c,
                filters,
                kernel,
                stride,
            };
            (h, w, c) = (shape.out_height(), shape.out_width(), filters);
            convs.push(shape);
        }
        if features == 0 {
            return Err("an encoder needs at least one feature".into());
        }
        Ok(Self { convs, features })
    }

    /// Values the encoder gives per image.
    pub fn features(&self) -> usize {
        self.features
    }

    /// Its convolutions, input side first.
    pub fn convs(&self) -> &[ConvShape] {
        &self.convs
    }

    /// Values of the last convolution's output (the linear layer's input).
    pub fn flat(&self) -> usize {
        self.convs.last().map_or(0, ConvShape::out_len)
    }

    /// Bytes of one input image.
    pub fn image_len(&self) -> usize {
        self.convs[0].in_len()
    }

    /// Number of parameter tensors (a weight and a bias per layer).
    pub fn param_count(&self) -> usize {
        2 * (self.convs.len() + 1)
    }

    /// `(name, shape)` of each parameter: per convolution `conv<i>.weight` (`filters × kernel ×
    /// kernel × channels`) and `conv<i>.bias`, then `fc.weight` (`features × flat`), `fc.bias`.
    pub fn param_shapes(&self) -> Vec<(String, Vec<usize>)> {
        let mut out = Vec::new();
        for (i, s) in self.convs.iter().enumerate() {
            out.push((
                format!("conv{i}.weight"),
                vec![s.filters, s.kernel, s.kernel, s.channels],
            ));
            out.push((format!("conv{i}.bias"), vec![s.filters]));
        }
        out.push(("fc.weight".into(), vec![self.features, self.flat()]));
        out.push(("fc.bias".into(), vec![self.features]));
        out
    }

    /// The features of `batch` images (`batch × image_len` bytes) into `cache`; `params` in
    /// [`Self::param_shapes`] order.
    pub fn forward(&self, params: &[&[f32]], images: &[u8], batch: usize, cache: &mut CnnCache) {
        let n = self.convs.len();
        cache.scratch.resize_with(n, ConvScratch::default);
        cache.outs.resize_with(n, Vec::new);
        cache.batch = batch;
        cache.pixels.clear();
        let images = &images[..batch * self.image_len()];
        cache
            .pixels
            .extend(images.iter().map(|&v| v as f32 / 255.0));
        let kernel = ProductKernel::current();
        for (l, shape) in self.convs.iter().enumerate() {
            let (before, rest) = cache.outs.split_at_mut(l);
            let input = before.last().unwrap_or(&cache.pixels);
            let out = &mut rest[0];
            out.resize(batch * shape.out_len(), 0.0);
            let (w, b) = (params[2 * l], params[2 * l + 1]);
            let scratch = &mut cache.scratch[l];
            conv::layer_forward(kernel, shape, input, batch, w, b, out, scratch);
            relu(out);
        }
        cache.features.resize(batch * self.features, 0.0);
        let dims = (self.flat(), self.features);
        let (w, b) = (params[2 * n], params[2 * n + 1]);
        linear_forward(dims, &cache.outs[n - 1], w, b, &mut cache.features);
        relu(&mut cache.features);
    }

    /// Accumulates the parameters' gradients (`grads`, in [`Self::param_shapes`] order,
    /// overwritten) from the features' (`d_features`, changed in place) of the batch `cache`
    /// holds.
    pub fn backward(
        &self,
        params: &[&[f32]],
        cache: &mut CnnCache,
        d_features: &mut [f32],
        grads: &mut [Vec<f32>],
    ) {
        let n = self.convs.len();
        let batch = cache.batch;
        relu_backward(&cache.features, d_features);
        cache.d_flat.resize(batch * self.flat(), 0.0);
        let (dw, db) = two(grads, 2 * n);
        linear_backward(
            (self.flat(), self.features),
            &cache.outs[n - 1],
            params[2 * n],
            d_features,
            dw,
            db,
            Some(&mut cache.d_flat),
        );
        let mut d_out = std::mem::take(&mut cache.d_flat);
        let kernel = ProductKernel::current();
        for (l, shape) in self.convs.iter().enumerate().rev() {
            relu_backward(&cache.outs[l], &mut d_out);
            let (dw, db) = two(grads, 2 * l);
            let input = if l == 0 {
                &cache.pixels
            } else {
                &cache.outs[l - 1]
            };
            let d_input = (l > 0).then(|| {
                cache.d_in.resize(batch * shape.in_len(), 0.0);
                &mut cache.d_in[..]
            });
            let (w, scratch) = (params[2 * l], &mut cache.scratch[l]);
            conv::layer_backward(
                kernel, shape, input, batch, w, &d_out, dw, db, d_input, scratch,
            );
            if l > 0 {
                std::mem::swap(&mut d_out, &mut cache.d_in);
            }
        }
        cache.d_flat = d_out;
    }
}

/// `grads[i]` and `grads[i + 1]`, both mutable.
fn two(grads: &mut [Vec<f32>], i: usize) -> (&mut [f32], &mut [f32]) {
    let (a, b) = grads[i..].split_at_mut(1);
    (&mut a[0], &mut b[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_images_are_refused_with_the_views_name() {
        let view = |side| ImageView {
            name: "scene_rgb".into(),
            height: side,
            width: side,
            channels: 3,
        };
        assert!(CnnEncoder::new(CnnArch::NatureCnn, &view(36), 64).is_ok());
        let err = CnnEncoder::new(CnnArch::NatureCnn, &view(32), 64).unwrap_err();
        assert!(
            err.contains("scene_rgb") && err.contains("nature_cnn"),
            "{err}"
        );
        let fast = CnnEncoder::new(CnnArch::FastCnn, &view(64), 50).unwrap();
        // 64 → 30 → 14 → 6: 6 × 6 × 32 values into the linear layer.
        assert_eq!(
            (fast.flat(), fast.features(), fast.image_len()),
            (1152, 50, 64 * 64 * 3)
        );
    }

    #[test]
    fn the_gradients_match_finite_differences() {
        let view = ImageView {
            name: "v".into(),
            height: 20,
            width: 20,
            channels: 2,
        };
        let enc = CnnEncoder::new(CnnArch::FastCnn, &view, 3).unwrap();
        let shapes = enc.param_shapes();
        let mut params: Vec<Vec<f32>> = shapes
            .iter()
            .enumerate()
            .map(|(p, (_, s))| {
                let n: usize = s.iter().product();
                (0..n)
                    .map(|i| (((i * 7 + p * 13) % 23) as f32 / 23.0 - 0.4) * 0.6)
                    .collect()
            })
            .collect();
        let batch = 2;
        let images: Vec<u8> = (0..batch * enc.image_len())
            .map(|i| (i * 37 % 256) as u8)
            .collect();
        let g = [1.0f32, -0.5, 2.0, 0.3, -1.0, 0.7];
        let loss = |params: &[Vec<f32>]| {
            let refs: Vec<&[f32]> = params.iter().map(Vec::as_slice).collect();
            let mut cache = CnnCache::default();
            enc.forward(&refs, &images, batch, &mut cache);
            cache
                .features()
                .iter()
                .zip(&g)
                .map(|(a, b)| a * b)
                .sum::<f32>()
        };
        let refs: Vec<&[f32]> = params.iter().map(Vec::as_slice).collect();
        let mut cache = CnnCache::default();
        enc.forward(&refs, &images, batch, &mut cache);
        assert!(
            cache.features().iter().any(|&f| f > 0.0),
            "all features dead"
        );
        let mut grads: Vec<Vec<f32>> = params.iter().map(|p| vec![0.0; p.len()]).collect();
        let mut d = g.to_vec();
        enc.backward(&refs, &mut cache, &mut d, &mut grads);
        let eps = 1e-2;
        let mut checked = 0;
        for p in 0..params.len() {
            for i in (0..params[p].len()).step_by(params[p].len() / 5 + 1) {
                let orig = params[p][i];
                params[p][i] = orig + eps;
                let up = loss(&params);
                params[p][i] = orig - eps;
                let down = loss(&params);
                params[p][i] = orig;
                let numeric = (up - down) / (2.0 * eps);
                let analytic = grads[p][i];
                assert!(
                    (numeric - analytic).abs() <= 2e-2 * (1.0 + numeric.abs()),
                    "{}[{i}]: numeric {numeric}, analytic {analytic}",
                    shapes[p].0
                );
                checked += 1;
            }
        }
        assert!(checked > 20);
    }
}
