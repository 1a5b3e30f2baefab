//! [`RecordEpisodeStatistics`]: episode return, length and success.

use crate::core::{Env, Frame, Info, Metadata, NamedValues, RenderMode, Step};
use crate::error::Result;
use crate::spaces::{BoxSpace, ImageSpace};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// The statistics of one finished episode: Gymnasium's `info["episode"]` (`r`, `l`) and SB3
/// `Monitor`'s, with SB3's `is_success`. Wall-clock time (`t`) is left out so that results stay
/// reproducible.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeStats {
    /// Sum of the episode's rewards (accumulated in f64).
    #[serde(rename = "r")]
    pub episode_return: f64,
    /// Number of steps.
    #[serde(rename = "l")]
    pub length: u32,
    /// [`Info::success`] of the episode's final step (SB3's `info["is_success"]`).
    #[serde(rename = "is_success")]
    pub success: bool,
    /// Each of the task's [`Info::extras`] at its largest over the episode: a flag that was
    /// ever raised reads 1 (`grasped`), a height its peak (`lift`).
    #[serde(default)]
    pub max_extras: NamedValues,
    /// The task's extras at the episode's final step (`objects_sorted` at the end).
    #[serde(default)]
    pub final_extras: NamedValues,
}

/// Accumulates the current episode (shared with [`crate::vector::VecEnv`]).
#[derive(Clone, Debug, Default)]
pub(crate) struct EpisodeAccumulator {
    episode_return: f64,
    length: u32,
    max_extras: NamedValues,
}

impl EpisodeAccumulator {
    pub(crate) fn add(&mut self, reward: f32, info: &Info) {
        self.episode_return += reward as f64;
        self.length += 1;
        self.max_extras.merge_max(&info.extras);
    }

    /// The finished episode's statistics, given its final step's info; starts a new episode.
    pub(crate) fn finish(&mut self, last: &Info) -> EpisodeStats {
        let stats = EpisodeStats {
            episode_return: self.episode_return,
            length: self.length,
            success: last.success,
            max_extras: std::mem::take(&mut self.max_extras),
            final_extras: last.extras.clone(),
        };
        *self = Self::default();
        stats
    }
}

/// Records each episode's return, length and success, like Gymnasium's
/// `RecordEpisodeStatistics` (and SB3's `Monitor` without the CSV file).
///
/// Gymnasium adds `info["episode"]` on the step that ends an episode; here [`Self::episode`]
/// returns the statistics right after that step (and `None` after any other step or a reset),
/// and [`Self::recent_episodes`] keeps the last `buffer_length` episodes (Gymnasium's
/// `return_queue` / `length_queue`, 100 by default). An episode cut short by `reset` is not
/// recorded. Steps that fail change nothing.
pub struct RecordEpisodeStatistics<E> {
    env: E,
    current: EpisodeAccumulator,
    last: Option<EpisodeStats>,
    recent: VecDeque<EpisodeStats>,
    buffer_length: usize,
    episode_count: u64,
}

impl<E: Env> RecordEpisodeStatistics<E> {
    /// Keeps the last 100 episodes, like Gymnasium.
    pub fn new(env: E) -> Self {
        Self::with_buffer_length(env, 100)
    }

    /// Keeps the last `buffer_length` episodes.
    pub fn with_buffer_length(env: E, buffer_length: usize) -> Self {
        Self {
            env,
            current: EpisodeAccumulator::default(),
            last: None,
            recent: VecDeque::with_capacity(buffer_length),
            buffer_length,
            episode_count: 0,
        }
    }

    /// The statistics of the episode the last step ended; `None` if it did not end one.
    pub fn episode(&self) -> Option<&EpisodeStats> {
        self.last.as_ref()
    }

    /// The last finished episodes, oldest first.
    pub fn recent_episodes(&self) -> &VecDeque<EpisodeStats> {
        &self.recent
    }

    /// Number of episodes finished since the wrapper was built.
    pub fn episode_count(&self) -> u64 {
        self.episode_count
    }

    /// Return of the episode in progress so far.
    pub fn current_return(&self) -> f64 {
        self.current.episode_return
    }

    /// Steps of the episode in progress so far.
    pub fn current_length(&self) -> u32 {
        self.current.length
    }

    /// The wrapped environment.
    pub fn inner(&self) -> &E {
        &self.env
    }

    /// The wrapped environment, mutably; steps taken on it directly are not counted.
    pub fn inner_mut(&mut self) -> &mut E {
        &mut self.env
    }

    /// The wrapped environment, dropping the statistics.
    pub fn into_inner(self) -> E {
        self.env
    }
}

impl<E: Env> Env for RecordEpisodeStatistics<E> {
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
        self.current = EpisodeAccumulator::default();
        self.last = None;
        Ok(out)
    }

    fn step(&mut self, action: &[f32]) -> Result<Step> {
        let step = self.env.step(action)?;
        self.current.add(step.reward, &step.info);
        self.last = None;
        if step.terminated || step.truncated {
            let stats = self.current.finish(&step.info);
            self.last = Some(stats.clone());
            self.episode_count += 1;
            if self.buffer_length > 0 {
                if self.recent.len() == self.buffer_length {
                    self.recent.pop_front();
                }
                self.recent.push_back(stats);
            }
        }
        Ok(step)
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
