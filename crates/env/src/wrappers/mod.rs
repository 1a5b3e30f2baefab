//! Environment wrappers, as Gymnasium and Stable-Baselines3 define them.
//!
//! - [`RescaleAction`] (Gymnasium's `RescaleAction`): the policy acts in `[-1, 1]^n`;
//! - [`RecordEpisodeStatistics`] (Gymnasium's `RecordEpisodeStatistics`, SB3's `Monitor`):
//!   episode return, length and success;
//! - [`FrameStack`] (SB3's `VecFrameStack` on images): each camera's last `k` images as one
//!   image of `k` times the channels;
//! - [`VecNormalize`] (SB3's `VecNormalize`): running normalisation of observations and
//!   rewards over a [`crate::vector::VectorEnv`], with its statistics saved as JSON.
//!
//! The single-environment wrappers implement [`crate::Env`] and so nest; each gives its inner
//! environment back with `inner`, `inner_mut` and `into_inner`.

mod frame_stack;
mod record_episode_statistics;
mod rescale_action;
mod vec_normalize;

pub use frame_stack::FrameStack;
pub(crate) use record_episode_statistics::EpisodeAccumulator;
pub use record_episode_statistics::{EpisodeStats, RecordEpisodeStatistics};
pub use rescale_action::RescaleAction;
pub use vec_normalize::{VecNormalize, VecNormalizeConfig, VecNormalizeState};
