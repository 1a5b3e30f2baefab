//! [`FrameStack`]: each camera's last `k` images as one image of `k` times the channels
//! (SB3's `VecFrameStack` on image observations, channel-last; Gymnasium's `FrameStackObservation`
//! stacks on a new first axis instead). The state vector passes through: it already holds
//! speeds and the previous action.

use crate::core::{Env, Frame, Info, Metadata, RenderMode, Step};
use crate::error::{EnvError, Result};
use crate::spaces::{BoxSpace, ImageSpace, ImageView};

/// Stacks the inner environment's camera images over the last `k` steps (see the module).
///
/// Each stacked view is `height × width × (k · channels)`: per pixel the oldest image's
/// channels first, the newest last. At a reset every slot holds the first image (SB3 fills with
/// zeros; repeating the first image keeps the stack a picture the policy could meet later).
pub struct FrameStack<E> {
    env: E,
    k: usize,
    inner_space: ImageSpace,
    space: ImageSpace,
    /// The last `k` images of the inner environment, oldest first (a ring: `next` is the
    /// oldest's slot).
    slots: Vec<Vec<u8>>,
    next: usize,
    stacked: Vec<u8>,
}

impl<E: Env> FrameStack<E> {
    /// Stacks `k` (2–16) images; an environment without cameras is an error.
    pub fn new(env: E, k: usize) -> Result<Self> {
        if !(2..=16).contains(&k) {
            return Err(EnvError::config(
                "frame_stack",
                format!("must be 2 to 16 images, got {k}"),
            ));
        }
        let inner_space = (env.image_space().cloned()).ok_or_else(|| {
            EnvError::config(
                "frame_stack",
                "the environment observes no camera images (camera.mode = \"rgb+state\", …)",
            )
        })?;
        let space = ImageSpace {
            views: (inner_space.views.iter())
                .map(|v| ImageView {
                    channels: v.channels * k as u32,
                    ..v.clone()
                })
                .collect(),
        };
        Ok(Self {
            k,
            slots: vec![vec![0; inner_space.len()]; k],
            next: 0,
            stacked: vec![0; space.len()],
            inner_space,
            space,
            env,
        })
    }

    /// The inner environment.
    pub fn inner(&self) -> &E {
        &self.env
    }

    /// The inner environment, mutably.
    pub fn inner_mut(&mut self) -> &mut E {
        &mut self.env
    }

    /// Unwraps the inner environment.
    pub fn into_inner(self) -> E {
        self.env
    }

    /// Takes the inner environment's newest images into the ring, then rebuilds the stack.
    fn push(&mut self, fill: bool) -> Result<()> {
        let image = self.env.image().ok_or_else(|| {
            EnvError::Usage("the wrapped environment stopped giving camera images".into())
        })?;
        if fill {
            for slot in &mut self.slots {
                slot.copy_from_slice(image);
            }
            self.next = 0;
        } else {
            self.slots[self.next].copy_from_slice(image);
            self.next = (self.next + 1) % self.k;
        }
        for (v, (view, stacked)) in self
            .inner_space
            .views
            .iter()
            .zip(&self.space.views)
            .enumerate()
        {
            let (from, to) = (self.inner_space.range(v), self.space.range(v));
            let c = view.channels as usize;
            let out = &mut self.stacked[to];
            for age in 0..self.k {
                let slot = &self.slots[(self.next + age) % self.k][from.clone()];
                for (p, pixel) in slot.chunks_exact(c).enumerate() {
                    let at = p * stacked.channels as usize + age * c;
                    out[at..at + c].copy_from_slice(pixel);
                }
            }
        }
        Ok(())
    }
}

impl<E: Env> Env for FrameStack<E> {
    fn metadata(&self) -> Metadata {
        self.env.metadata()
    }

    fn observation_space(&self) -> &BoxSpace {
        self.env.observation_space()
    }

    fn action_space(&self) -> &BoxSpace {
        self.env.action_space()
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.env.render_mode()
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)> {
        let out = self.env.reset(seed)?;
        self.push(true)?;
        Ok(out)
    }

    fn step(&mut self, action: &[f32]) -> Result<Step> {
        let step = self.env.step(action)?;
        self.push(false)?;
        Ok(step)
    }

    fn render(&mut self) -> Result<Option<Frame>> {
        self.env.render()
    }

    fn privileged_dim(&self) -> usize {
        self.env.privileged_dim()
    }

    fn image_space(&self) -> Option<&ImageSpace> {
        Some(&self.space)
    }

    fn image(&self) -> Option<&[u8]> {
        Some(&self.stacked)
    }

    fn close(&mut self) {
        self.env.close()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arm::camera::ObsMode;
    use crate::{GraspConfig, GraspEnv};

    fn env() -> GraspEnv {
        let mut config = GraspConfig::default();
        config.camera.mode = ObsMode::RgbState;
        (config.camera.width, config.camera.height) = (16, 16);
        config.camera.wrist.enabled = true;
        GraspEnv::new(config).unwrap()
    }

    #[test]
    fn each_pixel_holds_the_last_k_images_oldest_first() {
        let k = 3;
        let mut plain = env();
        let mut stacked = FrameStack::new(env(), k).unwrap();
        let space = stacked.image_space().unwrap().clone();
        assert_eq!(space.describe(), "scene_rgb 16×16×9, wrist_rgb 16×16×9");
        plain.reset(Some(3)).unwrap();
        stacked.reset(Some(3)).unwrap();
        let mut history = vec![plain.image().unwrap().to_vec(); k];
        let action = [0.5, -0.4, -0.5, 0.3, 0.2, -0.3, 1.0];
        for step in 0..5 {
            let inner = plain.image_space().unwrap().clone();
            let image = stacked.image().unwrap();
            for (v, view) in inner.views.iter().enumerate() {
                let c = view.channels as usize;
                let (from, to) = (inner.range(v), space.range(v));
                for p in 0..(view.height * view.width) as usize {
                    for (age, old) in history.iter().enumerate() {
                        let want = &old[from.clone()][p * c..p * c + c];
                        let got = &image[to.clone()][p * k * c + age * c..p * k * c + age * c + c];
                        assert_eq!(got, want, "step {step} view {v} pixel {p} age {age}");
                    }
                }
            }
            assert_eq!(
                plain.step(&action).unwrap().obs,
                stacked.step(&action).unwrap().obs
            );
            history.remove(0);
            history.push(plain.image().unwrap().to_vec());
        }
        assert!(
            history[0] != history[k - 1],
            "the images changed over the steps"
        );
    }

    #[test]
    fn an_env_without_cameras_or_a_bad_k_is_refused_by_name() {
        let err = FrameStack::new(GraspEnv::new(GraspConfig::default()).unwrap(), 4)
            .err()
            .unwrap();
        assert!(err.to_string().contains("camera.mode"), "{err}");
        let err = FrameStack::new(env(), 1).err().unwrap();
        assert!(err.to_string().contains("frame_stack"), "{err}");
    }
}
