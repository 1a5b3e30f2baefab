//! [`RescaleAction`]: the policy acts in `[-1, 1]^n`, the environment gets its own units.

use crate::core::{Env, Frame, Info, Metadata, RenderMode, Step};
use crate::error::{EnvError, Result};
use crate::spaces::{BoxSpace, ImageSpace};

/// Maps actions from `[-1, 1]^n` affinely onto the inner environment's action box, like
/// Gymnasium's `RescaleAction(env, min_action=-1.0, max_action=1.0)` (and what SB3 expects of
/// a squashed SAC/TD3 policy): `-1` gives `low`, `+1` gives `high` (both exactly), `0` the
/// centre of the box. The wrapper's action space is `[-1, 1]^n`.
///
/// Unlike Gymnasium, which asserts the input lies in `[-1, 1]`, values outside it are clipped
/// into it first (so a Gaussian policy's raw sample is safe to pass). NaN or infinite values and
/// a wrong number of values are errors, and the inner environment is not stepped.
pub struct RescaleAction<E> {
    env: E,
    action_space: BoxSpace,
    low: Vec<f64>,
    high: Vec<f64>,
}

impl<E: Env> RescaleAction<E> {
    /// Wraps `env`, whose action space must be bounded (finite `low <= high` in every
    /// dimension).
    pub fn new(env: E) -> Result<Self> {
        let inner = env.action_space();
        if let Some(i) = (0..inner.dim()).find(|&i| {
            !(inner.low[i].is_finite()
                && inner.high[i].is_finite()
                && inner.low[i] <= inner.high[i])
        }) {
            return Err(EnvError::Usage(format!(
                "RescaleAction needs a bounded action space; dimension {i} is [{}, {}]",
                inner.low[i], inner.high[i]
            )));
        }
        let n = inner.dim();
        let mut action_space = BoxSpace::new(vec![-1.0; n], vec![1.0; n]);
        action_space.shape = inner.shape.clone();
        Ok(Self {
            low: inner.low.iter().map(|&v| v as f64).collect(),
            high: inner.high.iter().map(|&v| v as f64).collect(),
            action_space,
            env,
        })
    }

    /// The action the inner environment receives for the policy action `action` (clipped into
    /// `[-1, 1]` first).
    pub fn to_inner_action(&self, action: &[f32]) -> Result<Vec<f32>> {
        let n = self.action_space.dim();
        if action.len() != n {
            return Err(EnvError::Action(format!(
                "expected {n} values in [-1, 1], got {}",
                action.len()
            )));
        }
        if let Some(i) = action.iter().position(|v| !v.is_finite()) {
            return Err(EnvError::Action(format!(
                "value {i} is {}; actions must be finite",
                action[i]
            )));
        }
        Ok(action
            .iter()
            .zip(self.low.iter().zip(&self.high))
            .map(|(&a, (&low, &high))| {
                let a = a.clamp(-1.0, 1.0) as f64;
                // Weighted form: exact at both ends (a = -1 → low, a = +1 → high).
                let x = 0.5 * (1.0 - a) * low + 0.5 * (1.0 + a) * high;
                (x as f32).clamp(low as f32, high as f32)
            })
            .collect())
    }

    /// The policy action in `[-1, 1]` that maps to the inner action `inner` (clipped into the
    /// inner box first): e.g. to express scripted demonstrations in the policy's units. A
    /// dimension with `low == high` maps to 0.
    pub fn to_policy_action(&self, inner: &[f32]) -> Result<Vec<f32>> {
        let n = self.action_space.dim();
        if inner.len() != n {
            return Err(EnvError::Action(format!(
                "expected {n} values, got {}",
                inner.len()
            )));
        }
        if let Some(i) = inner.iter().position(|v| !v.is_finite()) {
            return Err(EnvError::Action(format!(
                "value {i} is {}; actions must be finite",
                inner[i]
            )));
        }
        Ok(inner
            .iter()
            .zip(self.low.iter().zip(&self.high))
            .map(|(&x, (&low, &high))| {
                if high > low {
                    let x = (x as f64).clamp(low, high);
                    ((2.0 * (x - low) / (high - low) - 1.0) as f32).clamp(-1.0, 1.0)
                } else {
                    0.0
                }
            })
            .collect())
    }

    /// The wrapped environment.
    pub fn inner(&self) -> &E {
        &self.env
    }

    /// The wrapped environment, mutably; it takes actions in its own, unscaled space.
    pub fn inner_mut(&mut self) -> &mut E {
        &mut self.env
    }

    /// The wrapped environment, unwrapped.
    pub fn into_inner(self) -> E {
        self.env
    }
}

impl<E: Env> Env for RescaleAction<E> {
    fn metadata(&self) -> Metadata {
        self.env.metadata()
    }

    fn observation_space(&self) -> &BoxSpace {
        self.env.observation_space()
    }

    /// `[-1, 1]` in every dimension.
    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.env.render_mode()
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)> {
        self.env.reset(seed)
    }

    fn step(&mut self, action: &[f32]) -> Result<Step> {
        let inner = self.to_inner_action(action)?;
        self.env.step(&inner)
    }

    fn render(&mut self) -> Result<Option<Frame>> {
        self.env.render()
    }

    fn privileged_dim(&self) -> usize {
        self.env.privileged_dim()
    }

    fn image_space(&self) -> Option<&ImageSpace> {
        self.env.image_space()
    }

    fn image(&self) -> Option<&[u8]> {
        self.env.image()
    }

    fn close(&mut self) {
        self.env.close()
    }
}
