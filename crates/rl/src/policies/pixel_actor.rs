//! [`PixelActor`]: a policy that acts from camera images and the arm's own readings (SB3's
//! `MultiInputPolicy` with its `CombinedExtractor`): one CNN encoder per camera, the state
//! vector standardised, both concatenated into an MLP head that outputs the action. Its forward
//! and backward passes run on the written-out kernels; the weights live in a [`VarMap`] so that
//! they save as every model's do.

use crate::algorithm::TensorMap;
use crate::kernels::dense::{linear_backward, linear_forward, relu, relu_backward};
use crate::kernels::mlp::VarValues;
use crate::nn::adam::Adam;
use crate::policies::cnn::{CnnArch, CnnCache, CnnEncoder};
use candle_core::Var;
use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use fairgrasp_env::spaces::ImageSpace;
use rand::{Rng, RngCore};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// The shape of a pixel actor (`[distill.actor]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PixelActorConfig {
    /// The convolution stack of every camera's encoder.
    pub encoder: CnnArch,
    /// Values each encoder gives.
    pub features: usize,
    /// Hidden layers of the head (ReLU), input side first.
    pub net_arch: Vec<usize>,
}

impl Default for PixelActorConfig {
    fn default() -> Self {
        Self {
            encoder: CnnArch::FastCnn,
            features: 64,
            net_arch: vec![256, 256],
        }
    }
}

/// The saved names of the state's standardisation.
const STATE_MEAN: &str = "state.mean";
const STATE_STD: &str = "state.std";

/// Reused buffers of one batch's passes.
#[derive(Default)]
pub struct PixelCache {
    /// Each camera's images of the batch, gathered contiguously.
    views: Vec<Vec<u8>>,
    encoders: Vec<CnnCache>,
    /// The head's input, then each layer's output (after ReLU for hidden layers).
    head: Vec<Vec<f32>>,
    d_head: Vec<f32>,
    d_next: Vec<f32>,
    batch: usize,
    /// Run the cameras' encoders side by side, one thread each (else one after another). The
    /// results are the same either way: each encoder's sums do not depend on it.
    pub parallel_encoders: bool,
    /// Seconds of [`PixelActor::step_on`]'s forward passes and of its backward passes with
    /// Adam's steps, summed over the calls with this cache (the time split of a run).
    pub forward_seconds: f64,
    /// See [`Self::forward_seconds`].
    pub backward_seconds: f64,
}

/// The pixel policy: encoders, standardisation of the state and the head (see the module).
pub struct PixelActor {
    config: PixelActorConfig,
    images: ImageSpace,
    encoders: Vec<CnnEncoder>,
    state_dim: usize,
    act_dim: usize,
    /// `(in, out)` of each head layer.
    head: Vec<(usize, usize)>,
    varmap: VarMap,
    /// Parameter names in pass order: each encoder's, then the head's.
    names: Vec<String>,
    /// The state's standardisation (mean, standard deviation), fixed once set.
    state_mean: Vec<f32>,
    state_std: Vec<f32>,
}

impl PixelActor {
    /// A pixel actor for observations of `state_dim` values and `images`, giving `act_dim`
    /// values, its weights drawn from `rng` (He-uniform; the output layer scaled by 0.01).
    pub fn new(
        config: &PixelActorConfig,
        images: &ImageSpace,
        state_dim: usize,
        act_dim: usize,
        rng: &mut dyn RngCore,
    ) -> Result<Self, String> {
        Self::build(config, images, state_dim, act_dim, |name, shape, last| {
            let n: usize = shape.iter().product();
            Ok(if name.ends_with("bias") {
                vec![0.0; n]
            } else {
                let fan_in: usize = shape[1..].iter().product();
                let scale = if last { 0.01 } else { 1.0 };
                let bound = scale * (6.0 / fan_in as f32).sqrt();
                (0..n).map(|_| rng.random_range(-bound..bound)).collect()
            })
        })
    }

    /// A pixel actor of this shape with saved `weights` (what [`Self::weights`] gave): every
    /// tensor checked, a missing, extra or mis-shaped one is an error naming it.
    pub fn from_weights(
        config: &PixelActorConfig,
        images: &ImageSpace,
        state_dim: usize,
        act_dim: usize,
        weights: &TensorMap,
    ) -> Result<Self, String> {
        let read = |name: &str, shape: &[usize]| -> Result<Vec<f32>, String> {
            let t = weights
                .get(name)
                .ok_or_else(|| format!("the camera policy has no tensor `{name}`"))?;
            if t.dims() != shape {
                return Err(format!(
                    "tensor `{name}` has shape {:?}, the camera policy needs {shape:?}",
                    t.dims()
                ));
            }
            (t.to_dtype(DType::F32)
                .and_then(|t| t.flatten_all()?.to_vec1()))
            .map_err(|e| format!("tensor `{name}`: {e}"))
        };
        let mut actor = Self::build(config, images, state_dim, act_dim, |name, shape, _| {
            read(name, shape)
        })?;
        actor.state_mean = read(STATE_MEAN, &[state_dim])?;
        actor.state_std = read(STATE_STD, &[state_dim])?;
        if let Some(i) = actor
            .state_std
            .iter()
            .position(|s| !(s.is_finite() && *s > 0.0))
        {
            return Err(format!(
                "tensor `{STATE_STD}`: value {i} is {} (standard deviations must be positive)",
                actor.state_std[i]
            ));
        }
        if let Some(extra) = (weights.keys())
            .find(|k| !actor.names.contains(k) && *k != STATE_MEAN && *k != STATE_STD)
        {
            return Err(format!(
                "tensor `{extra}` is not part of a {} camera policy",
                config.encoder.name()
            ));
        }
        Ok(actor)
    }

    /// The layers, their parameters named and shaped, each filled by `value(name, shape,
    /// is_output_weight)`.
    fn build(
        config: &PixelActorConfig,
        images: &ImageSpace,
        state_dim: usize,
        act_dim: usize,
        mut value: impl FnMut(&str, &[usize], bool) -> Result<Vec<f32>, String>,
    ) -> Result<Self, String> {
        if images.views.is_empty() {
            return Err(
                "a pixel actor needs camera images (camera.mode = \"rgb+state\", …)".into(),
            );
        }
        let encoders = (images.views.iter())
            .map(|v| CnnEncoder::new(config.encoder, v, config.features))
            .collect::<Result<Vec<_>, _>>()?;
        let mut widths = vec![encoders.len() * config.features + state_dim];
        widths.extend(&config.net_arch);
        widths.push(act_dim);
        let head: Vec<(usize, usize)> = widths.windows(2).map(|w| (w[0], w[1])).collect();
        let mut shapes = Vec::new();
        for (v, e) in encoders.iter().enumerate() {
            for (name, shape) in e.param_shapes() {
                shapes.push((format!("enc{v}.{name}"), shape));
            }
        }
        for (l, &(inp, out)) in head.iter().enumerate() {
            shapes.push((format!("head.{l}.weight"), vec![out, inp]));
            shapes.push((format!("head.{l}.bias"), vec![out]));
        }
        let varmap = VarMap::new();
        let last = shapes.len() - 2;
        {
            let mut data = varmap.data().lock().expect("varmap lock");
            for (i, (name, shape)) in shapes.iter().enumerate() {
                let values = value(name, shape, i == last)?;
                let tensor = Tensor::from_vec(values, shape.clone(), &Device::Cpu)
                    .and_then(|t| Var::from_tensor(&t))
                    .map_err(|e| format!("tensor `{name}`: {e}"))?;
                data.insert(name.clone(), tensor);
            }
        }
        Ok(Self {
            config: config.clone(),
            images: images.clone(),
            encoders,
            state_dim,
            act_dim,
            head,
            varmap,
            names: shapes.into_iter().map(|(n, _)| n).collect(),
            state_mean: vec![0.0; state_dim],
            state_std: vec![1.0; state_dim],
        })
    }

    /// Every saved value by name: the layers' parameters and the state's standardisation
    /// (`state.mean`, `state.std`), what [`Self::from_weights`] reads back.
    pub fn weights(&self) -> TensorMap {
        let mut map: TensorMap = (self.names.iter().cloned()).zip(self.tensors()).collect();
        for (name, values) in [(STATE_MEAN, &self.state_mean), (STATE_STD, &self.state_std)] {
            let t = Tensor::from_vec(values.clone(), values.len(), &Device::Cpu)
                .expect("a vector of its own length");
            map.insert(name.to_string(), t);
        }
        map
    }

    /// Parameter names in pass order (each encoder's, then the head's).
    pub fn parameter_names(&self) -> &[String] {
        &self.names
    }

    /// The encoder of each camera, in [`ImageSpace`] order.
    pub fn encoders(&self) -> &[CnnEncoder] {
        &self.encoders
    }

    /// Its shape.
    pub fn config(&self) -> &PixelActorConfig {
        &self.config
    }

    /// The images it reads.
    pub fn images(&self) -> &ImageSpace {
        &self.images
    }

    /// State values it reads.
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// Values of an action.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// The weights.
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }

    /// Number of trained values.
    pub fn parameter_count(&self) -> usize {
        let data = self.varmap.data().lock().expect("varmap lock");
        data.values().map(|v| v.elem_count()).sum()
    }

    /// Sets the state's standardisation from `states` (`rows × state_dim`): per value its mean
    /// and standard deviation, at least `floor` (so that constant values stay finite).
    pub fn fit_state_scale(&mut self, states: &[f32], floor: f32) {
        let rows = states.len() / self.state_dim.max(1);
        if rows == 0 {
            return;
        }
        for j in 0..self.state_dim {
            let column = states.iter().skip(j).step_by(self.state_dim);
            let mean = column.clone().map(|&v| v as f64).sum::<f64>() / rows as f64;
            let var = column.map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / rows as f64;
            self.state_mean[j] = mean as f32;
            self.state_std[j] = (var.sqrt() as f32).max(floor);
        }
    }

    /// The standardisation `(mean, std)` of the state.
    pub fn state_scale(&self) -> (&[f32], &[f32]) {
        (&self.state_mean, &self.state_std)
    }

    /// The tensors in pass order.
    fn tensors(&self) -> Vec<Tensor> {
        let data = self.varmap.data().lock().expect("varmap lock");
        (self.names.iter())
            .map(|n| data[n].as_tensor().clone())
            .collect()
    }

    /// Actions for `batch` observations: `states` (`batch × state_dim`) and `images` (`batch ×
    /// image_len` bytes, each observation's cameras one after another). `batch × act_dim`
    /// values, in `cache`'s last head buffer.
    pub fn forward(
        &self,
        states: &[f32],
        images: &[u8],
        batch: usize,
        cache: &mut PixelCache,
    ) -> candle_core::Result<Vec<f32>> {
        let tensors = self.tensors();
        let values = VarValues::new(tensors.iter());
        let params: Vec<&[f32]> = (0..tensors.len())
            .map(|i| values.get(i))
            .collect::<candle_core::Result<_>>()?;
        self.forward_with(&params, states, images, batch, cache);
        Ok(cache.head.last().cloned().unwrap_or_default())
    }

    fn forward_with(
        &self,
        params: &[&[f32]],
        states: &[f32],
        images: &[u8],
        batch: usize,
        cache: &mut PixelCache,
    ) {
        let per_obs = self.images.len();
        let n_views = self.encoders.len();
        cache.batch = batch;
        cache.views.resize_with(n_views, Vec::new);
        cache.encoders.resize_with(n_views, CnnCache::default);
        for (v, gathered) in cache.views.iter_mut().enumerate() {
            let range = self.images.range(v);
            gathered.clear();
            for obs in images.chunks_exact(per_obs).take(batch) {
                gathered.extend_from_slice(&obs[range.clone()]);
            }
        }
        let passes = (self.encoders.iter().zip(self.per_encoder(params)))
            .zip(cache.views.iter().zip(cache.encoders.iter_mut()))
            .map(|((encoder, own), (view, encoder_cache))| (encoder, own, view, encoder_cache))
            .collect();
        for_each_camera(passes, cache.parallel_encoders, |(e, own, view, c)| {
            e.forward(own, view, batch, c)
        });
        let offset = self.encoder_param_count();
        let layers = self.head.len();
        cache.head.resize_with(layers + 1, Vec::new);
        let input = &mut cache.head[0];
        input.clear();
        let features = self.config.features;
        for b in 0..batch {
            for enc in &cache.encoders {
                input.extend_from_slice(&enc.features()[b * features..(b + 1) * features]);
            }
            let state = &states[b * self.state_dim..(b + 1) * self.state_dim];
            let scale = self.state_mean.iter().zip(&self.state_std);
            input.extend(state.iter().zip(scale).map(|(x, (m, s))| (x - m) / s));
        }
        for (l, &(inp, out)) in self.head.iter().enumerate() {
            let (before, after) = cache.head.split_at_mut(l + 1);
            let y = &mut after[0];
            y.resize(batch * out, 0.0);
            let (w, b) = (params[offset + 2 * l], params[offset + 2 * l + 1]);
            linear_forward((inp, out), &before[l], w, b, y);
            if l + 1 < layers {
                relu(y);
            }
        }
    }

    /// One Adam step on the mean squared error between the actions for the batch and
    /// `targets` (`batch × act_dim`); `adam` must be built on [`Self::varmap`]. Returns the loss
    /// before the step.
    pub fn train_step(
        &self,
        adam: &mut Adam,
        states: &[f32],
        images: &[u8],
        targets: &[f32],
        cache: &mut PixelCache,
    ) -> candle_core::Result<f32> {
        let batch = targets.len() / self.act_dim;
        let n = (batch * self.act_dim) as f32;
        let mut mse = |out: &[f32], d_out: &mut Vec<f32>| {
            let mut loss = 0.0f64;
            d_out.clear();
            for (y, t) in out.iter().zip(targets) {
                let e = y - t;
                loss += (e * e) as f64;
                d_out.push(2.0 * e / n);
            }
            (loss / n as f64) as f32
        };
        self.step_on(adam, states, images, batch, cache, 10.0, &mut mse)
    }

    /// One Adam step on any loss of the batch's actions: `loss` gets the actions (`batch ×
    /// act_dim`), writes the loss's gradient with respect to them into its second argument and
    /// returns the loss, which this returns. The gradients' global norm is clipped to
    /// `max_grad_norm`; `adam` must be built on [`Self::varmap`].
    #[allow(clippy::too_many_arguments)]
    pub fn step_on(
        &self,
        adam: &mut Adam,
        states: &[f32],
        images: &[u8],
        batch: usize,
        cache: &mut PixelCache,
        max_grad_norm: f64,
        loss: &mut dyn FnMut(&[f32], &mut Vec<f32>) -> f32,
    ) -> candle_core::Result<f32> {
        let tensors = self.tensors();
        let mut grads: Vec<Vec<f32>> = tensors.iter().map(|t| vec![0.0; t.elem_count()]).collect();
        let value;
        let mut started;
        {
            let values = VarValues::new(tensors.iter());
            let params: Vec<&[f32]> = (0..tensors.len())
                .map(|i| values.get(i))
                .collect::<candle_core::Result<_>>()?;
            started = Instant::now();
            self.forward_with(&params, states, images, batch, cache);
            let out = cache.head.last().expect("forward ran");
            value = loss(out, &mut cache.d_head);
            cache.forward_seconds += started.elapsed().as_secs_f64();
            if cache.d_head.len() != batch * self.act_dim {
                candle_core::bail!(
                    "the loss gave {} gradient values for {batch} × {} actions",
                    cache.d_head.len(),
                    self.act_dim
                );
            }
            started = Instant::now();
            self.backward(&params, cache, &mut grads);
        }
        // Adam takes the gradients in its own (name-sorted) order.
        let order: Vec<usize> = adam
            .vars()
            .map(|(name, _)| self.names.iter().position(|n| n == name))
            .collect::<Option<_>>()
            .ok_or_else(|| candle_core::Error::Msg("adam is not over this actor".into()))?;
        let sorted: Vec<Option<&[f32]>> =
            order.iter().map(|&i| Some(grads[i].as_slice())).collect();
        adam.step_with(&sorted, max_grad_norm)?;
        cache.backward_seconds += started.elapsed().as_secs_f64();
        Ok(value)
    }

    /// How many parameter tensors the encoders hold (theirs come first in pass order).
    fn encoder_param_count(&self) -> usize {
        self.encoders.iter().map(CnnEncoder::param_count).sum()
    }

    /// `params` cut into each encoder's own, in camera order.
    fn per_encoder<'a, T>(&self, mut params: &'a [T]) -> Vec<&'a [T]> {
        (self.encoders.iter())
            .map(|encoder| {
                let (own, rest) = params.split_at(encoder.param_count());
                params = rest;
                own
            })
            .collect()
    }

    /// The gradients into `grads` (pass order) from the actions' gradient in `cache.d_head`.
    fn backward(&self, params: &[&[f32]], cache: &mut PixelCache, grads: &mut [Vec<f32>]) {
        let batch = cache.batch;
        let offset = self.encoder_param_count();
        for (l, &(inp, out)) in self.head.iter().enumerate().rev() {
            if l + 1 < self.head.len() {
                relu_backward(&cache.head[l + 1], &mut cache.d_head);
            }
            cache.d_next.resize(batch * inp, 0.0);
            let (a, b) = grads[offset + 2 * l..].split_at_mut(1);
            linear_backward(
                (inp, out),
                &cache.head[l],
                params[offset + 2 * l],
                &cache.d_head,
                &mut a[0],
                &mut b[0],
                Some(&mut cache.d_next),
            );
            std::mem::swap(&mut cache.d_head, &mut cache.d_next);
        }
        // `d_head` now holds the head input's gradient: each camera's features, then the state.
        let features = self.config.features;
        let width = self.head[0].0;
        let mut rest = grads;
        let mut passes = Vec::with_capacity(self.encoders.len());
        let encoders = self.encoders.iter().zip(self.per_encoder(params));
        for (v, ((encoder, own), encoder_cache)) in
            encoders.zip(cache.encoders.iter_mut()).enumerate()
        {
            let d_features: Vec<f32> = (0..batch)
                .flat_map(|b| {
                    let row = b * width + v * features;
                    cache.d_head[row..row + features].iter().copied()
                })
                .collect();
            let (own_grads, after) = std::mem::take(&mut rest).split_at_mut(encoder.param_count());
            rest = after;
            passes.push((encoder, own, encoder_cache, d_features, own_grads));
        }
        for_each_camera(passes, cache.parallel_encoders, |(e, own, c, mut d, g)| {
            e.backward(own, c, &mut d, g)
        });
    }
}

/// Runs `pass` on each camera's work: the first on this thread and each other on a thread of
/// its own when `parallel`, else one after another. A thread costs tens of microseconds; an
/// encoder's pass on a batch takes milliseconds.
fn for_each_camera<T: Send>(work: Vec<T>, parallel: bool, pass: impl Fn(T) + Sync) {
    if !parallel || work.len() < 2 {
        work.into_iter().for_each(pass);
        return;
    }
    let pass = &pass;
    std::thread::scope(|scope| {
        let mut work = work.into_iter();
        let first = work.next();
        for item in work {
            scope.spawn(move || pass(item));
        }
        if let Some(item) = first {
            pass(item);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use fairgrasp_env::spaces::ImageView;
    use rand::SeedableRng;

    fn space() -> ImageSpace {
        ImageSpace {
            views: vec![
                ImageView {
                    name: "scene_rgb".into(),
                    height: 32,
                    width: 32,
                    channels: 3,
                },
                ImageView {
                    name: "wrist_depth".into(),
                    height: 32,
                    width: 32,
                    channels: 1,
                },
            ],
        }
    }

    /// A bright square at a random place in the scene image; the target is its position: the
    /// actor must read where things are from pixels.
    fn batch(rng: &mut impl Rng, n: usize) -> (Vec<f32>, Vec<u8>, Vec<f32>) {
        let space = space();
        let (mut states, mut images, mut targets) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..n {
            let (x, y) = (rng.random_range(4..24usize), rng.random_range(4..24usize));
            let mut image = vec![20u8; space.len()];
            for r in y..y + 4 {
                for c in x..x + 4 {
                    image[(r * 32 + c) * 3..(r * 32 + c) * 3 + 3].fill(230);
                }
            }
            images.extend(image);
            states.extend([rng.random::<f32>(), 1.0]);
            targets.extend([x as f32 / 10.0 - 1.4, y as f32 / 10.0 - 1.4]);
        }
        (states, images, targets)
    }

    #[test]
    fn it_learns_where_a_square_is_from_pixels() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let config = PixelActorConfig {
            encoder: CnnArch::FastCnn,
            features: 16,
            net_arch: vec![32],
        };
        let mut actor = PixelActor::new(&config, &space(), 2, 2, &mut rng).unwrap();
        assert_eq!(actor.images().views.len(), 2);
        let (states, _, _) = batch(&mut rng, 256);
        actor.fit_state_scale(&states, 1e-3);
        assert!(
            (actor.state_scale().1[1] - 1e-3).abs() < 1e-9,
            "a constant value"
        );
        let mut adam = Adam::new(actor.varmap(), 3e-3).unwrap();
        let mut cache = PixelCache::default();
        let (test_states, test_images, test_targets) = batch(&mut rng, 64);
        let mse = |actor: &PixelActor, cache: &mut PixelCache| {
            let out = actor
                .forward(&test_states, &test_images, 64, cache)
                .unwrap();
            out.iter()
                .zip(&test_targets)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f32>()
                / out.len() as f32
        };
        let before = mse(&actor, &mut cache);
        for _ in 0..800 {
            let (s, i, t) = batch(&mut rng, 32);
            let loss = actor.train_step(&mut adam, &s, &i, &t, &mut cache).unwrap();
            assert!(loss.is_finite());
        }
        let after = mse(&actor, &mut cache);
        assert!(
            after < 0.1 * before && after < 0.02,
            "mse {before} → {after}"
        );
    }

    #[test]
    fn the_gradients_match_finite_differences() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let config = PixelActorConfig {
            encoder: CnnArch::FastCnn,
            features: 4,
            net_arch: vec![6],
        };
        let mut actor = PixelActor::new(&config, &space(), 2, 2, &mut rng).unwrap();
        let (states, _, targets) = batch(&mut rng, 3);
        // Noise, not the flat background of `batch`: on a flat image every patch has the same
        // pre-activation, and a finite difference would step across ReLU's kink for all of them.
        let images: Vec<u8> = (0..3 * space().len()).map(|_| rng.random()).collect();
        actor.fit_state_scale(&states, 1e-3);
        let tensors = actor.tensors();
        let mut params: Vec<Vec<f32>> = (tensors.iter())
            .map(|t| t.flatten_all().unwrap().to_vec1::<f32>().unwrap())
            .collect();
        // Larger output weights than the initial 0.01 scale, so every path carries gradient.
        let last = params.len() - 2;
        for (i, w) in params[last].iter_mut().enumerate() {
            *w = 0.3 * ((i % 5) as f32 - 2.0);
        }
        let mut cache = PixelCache::default();
        let loss = |params: &[Vec<f32>], cache: &mut PixelCache| {
            let refs: Vec<&[f32]> = params.iter().map(Vec::as_slice).collect();
            actor.forward_with(&refs, &states, &images, 3, cache);
            let out = cache.head.last().unwrap();
            out.iter()
                .zip(&targets)
                .map(|(y, t)| (y - t) * (y - t))
                .sum::<f32>()
                / out.len() as f32
        };
        let refs: Vec<&[f32]> = params.iter().map(Vec::as_slice).collect();
        actor.forward_with(&refs, &states, &images, 3, &mut cache);
        let mut grads: Vec<Vec<f32>> = params.iter().map(|p| vec![0.0; p.len()]).collect();
        let n = targets.len() as f32;
        let out = cache.head.last().unwrap();
        cache.d_head = out
            .iter()
            .zip(&targets)
            .map(|(y, t)| 2.0 * (y - t) / n)
            .collect();
        actor.backward(&refs, &mut cache, &mut grads);
        let eps = 2e-3;
        for p in 0..params.len() {
            for i in (0..params[p].len()).step_by(params[p].len() / 4 + 1) {
                let orig = params[p][i];
                params[p][i] = orig + eps;
                let up = loss(&params, &mut cache);
                params[p][i] = orig - eps;
                let down = loss(&params, &mut cache);
                params[p][i] = orig;
                let numeric = (up - down) / (2.0 * eps);
                assert!(
                    (numeric - grads[p][i]).abs() <= 2e-2 * (1.0 + numeric.abs()) + 1e-4,
                    "{}[{i}]: numeric {numeric}, analytic {}",
                    actor.names[p],
                    grads[p][i]
                );
            }
        }
    }

    #[test]
    fn encoding_the_cameras_side_by_side_trains_the_same_weights() {
        let train = |parallel_encoders: bool| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
            let config = PixelActorConfig {
                encoder: CnnArch::FastCnn,
                features: 8,
                net_arch: vec![16],
            };
            let actor = PixelActor::new(&config, &space(), 2, 2, &mut rng).unwrap();
            let weights = |actor: &PixelActor| -> Vec<Vec<f32>> {
                (actor.tensors().iter())
                    .map(|t| t.flatten_all().unwrap().to_vec1::<f32>().unwrap())
                    .collect()
            };
            let initial = weights(&actor);
            let mut adam = Adam::new(actor.varmap(), 1e-2).unwrap();
            let mut cache = PixelCache {
                parallel_encoders,
                ..PixelCache::default()
            };
            let mut losses = Vec::new();
            for _ in 0..4 {
                let (s, i, t) = batch(&mut rng, 16);
                losses.push(actor.train_step(&mut adam, &s, &i, &t, &mut cache).unwrap());
            }
            let (s, i, _) = batch(&mut rng, 8);
            let actions = actor.forward(&s, &i, 8, &mut cache).unwrap();
            assert_ne!(weights(&actor), initial, "the steps moved the weights");
            (losses, actions, weights(&actor))
        };
        let (alone, side_by_side) = (train(false), train(true));
        assert_eq!(alone.0, side_by_side.0, "losses");
        assert_eq!(alone.1, side_by_side.1, "actions");
        assert_eq!(alone.2, side_by_side.2, "weights");
    }

    #[test]
    fn the_same_seed_draws_the_same_weights() {
        let weights = |seed| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let actor =
                PixelActor::new(&PixelActorConfig::default(), &space(), 5, 3, &mut rng).unwrap();
            actor
                .tensors()
                .iter()
                .map(|t| t.flatten_all().unwrap().to_vec1::<f32>().unwrap())
                .collect::<Vec<_>>()
        };
        assert_eq!(weights(1), weights(1));
        assert_ne!(weights(1), weights(2));
    }

    #[test]
    fn saved_weights_load_back_to_the_same_actions_and_bad_ones_are_named() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let config = PixelActorConfig {
            features: 8,
            net_arch: vec![16],
            ..PixelActorConfig::default()
        };
        let mut actor = PixelActor::new(&config, &space(), 2, 3, &mut rng).unwrap();
        let (states, images, _) = batch(&mut rng, 5);
        actor.fit_state_scale(&states, 1e-3);
        let weights = actor.weights();
        let loaded = PixelActor::from_weights(&config, &space(), 2, 3, &weights).unwrap();
        let mut cache = PixelCache::default();
        let want = actor.forward(&states, &images, 5, &mut cache).unwrap();
        let got = loaded.forward(&states, &images, 5, &mut cache).unwrap();
        assert_eq!(want, got, "the state's standardisation saves too");

        let error = |weights: &TensorMap| {
            PixelActor::from_weights(&config, &space(), 2, 3, weights)
                .err()
                .unwrap()
        };
        let mut missing = weights.clone();
        missing.remove("enc1.conv2.bias");
        assert!(error(&missing).contains("enc1.conv2.bias"));
        let mut extra = weights.clone();
        extra.insert(
            "head.9.weight".into(),
            Tensor::zeros(2, DType::F32, &Device::Cpu).unwrap(),
        );
        assert!(error(&extra).contains("head.9.weight"));
        let mut shaped = weights.clone();
        shaped.insert(
            "head.0.bias".into(),
            Tensor::zeros(7, DType::F32, &Device::Cpu).unwrap(),
        );
        assert!(error(&shaped).contains("head.0.bias"));
        let mut zero_std = weights;
        zero_std.insert(
            "state.std".into(),
            Tensor::zeros(2, DType::F32, &Device::Cpu).unwrap(),
        );
        assert!(error(&zero_std).contains("state.std"));
    }
}
