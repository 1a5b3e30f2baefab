//! Vectorised environments: N copies of an [`Env`] stepped together, with automatic resets.
//!
//! [`VecEnv`] mirrors Stable-Baselines3's `VecEnv` (`DummyVecEnv` with one thread,
//! `SubprocVecEnv`-like parallelism on a pool of worker threads otherwise) and Gymnasium's vector
//! environments in their `SAME_STEP` autoreset mode:
//!
//! - observations, rewards and flags come back as contiguous row-major batches
//!   (`num_envs × obs_dim` f32 observations, `num_envs` rewards, …) owned by the vector env;
//! - an environment whose episode ends is reset at once: its row of the returned observations is
//!   the new episode's first observation, and the finished episode's last observation, its
//!   statistics and the reset info are kept in [`VecStep::episode_ends`] (SB3's
//!   `info["terminal_observation"]`, `info["episode"]` and `reset_infos`);
//! - camera images (an env's [`Env::image`]) come back beside the observations as one `u8`
//!   batch (`num_envs × image_len` bytes, [`VecStep::images`]), never converted to floats;
//! - `reset(Some(seed))` resets environment `i` with `seed + i`, like SB3's `VecEnv.seed(seed)`
//!   and Gymnasium's `reset(seed=seed)` on a vector env;
//! - results do not depend on the number of threads: each environment owns its random stream
//!   and is stepped by exactly one thread per call.
//!
//! [`VectorEnv`] is the interface shared with vector wrappers such as
//! [`crate::wrappers::VecNormalize`] (SB3's `VecEnvWrapper`).

use crate::core::{Env, Info};
use crate::error::{EnvError, Result};
use crate::spaces::{BoxSpace, ImageSpace};
use crate::wrappers::{EpisodeAccumulator, EpisodeStats};

mod pool;
pub use pool::LockstepPool;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What is kept when an environment's episode ends inside [`VectorEnv::step`].
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodeEnd {
    /// The last observation of the finished episode (SB3's `info["terminal_observation"]`,
    /// Gymnasium's `final_obs`): bootstrap truncated episodes from it, not from the returned
    /// observation row, which already belongs to the next episode. Vector wrappers that
    /// transform observations transform this one too.
    pub terminal_observation: Vec<f32>,
    /// The camera images of the last observation (empty without an image space).
    pub terminal_image: Vec<u8>,
    /// Return, length and success of the finished episode (SB3 `Monitor`'s `info["episode"]`).
    /// Always in the environment's own reward units, also under reward normalisation.
    pub episode: EpisodeStats,
    /// The info of the reset that started the next episode (SB3's `reset_infos[i]`). The final
    /// step's info is the environment's entry of [`VecStep::infos`].
    pub reset_info: Info,
}

/// The result of [`VectorEnv::step`]: contiguous batches borrowed from the vector environment,
/// valid until its next call.
#[derive(Clone, Copy, Debug)]
pub struct VecStep<'a> {
    /// `num_envs × obs_dim` values, row-major. For an environment whose episode ended at this
    /// step, its row is the first observation of the next episode (see
    /// [`Self::episode_ends`]).
    pub observations: &'a [f32],
    /// One reward per environment.
    pub rewards: &'a [f32],
    /// The episode reached a terminal state of the task.
    pub terminated: &'a [bool],
    /// The episode was cut for a reason outside the task (time limit, non-finite physics).
    pub truncated: &'a [bool],
    /// The info of each environment's step; for a finished episode, its final info.
    pub infos: &'a [Info],
    /// `Some` exactly for the environments whose episode ended at this step.
    pub episode_ends: &'a [Option<EpisodeEnd>],
    /// Values per observation row.
    pub obs_dim: usize,
    /// `num_envs × image_len` bytes: each environment's camera images (empty without an image
    /// space); rows as [`Self::observations`]'.
    pub images: &'a [u8],
    /// Bytes per environment in [`Self::images`].
    pub image_len: usize,
}

impl<'a> VecStep<'a> {
    /// Number of environments stepped.
    pub fn num_envs(&self) -> usize {
        self.rewards.len()
    }

    /// Environment `i`'s observation row.
    ///
    /// # Panics
    /// When `i >= num_envs()`.
    pub fn obs(&self, i: usize) -> &'a [f32] {
        &self.observations[i * self.obs_dim..(i + 1) * self.obs_dim]
    }

    /// Environment `i`'s camera images (empty without an image space).
    ///
    /// # Panics
    /// When `i >= num_envs()`.
    pub fn image(&self, i: usize) -> &'a [u8] {
        &self.images[i * self.image_len..(i + 1) * self.image_len]
    }

    /// Whether environment `i`'s episode ended (terminated or truncated) at this step.
    pub fn done(&self, i: usize) -> bool {
        self.terminated[i] || self.truncated[i]
    }

    /// The last observation of the episode environment `i` finished at this step.
    pub fn terminal_observation(&self, i: usize) -> Option<&'a [f32]> {
        self.episode_ends[i]
            .as_ref()
            .map(|e| e.terminal_observation.as_slice())
    }

    /// The statistics of the episode environment `i` finished at this step.
    pub fn episode(&self, i: usize) -> Option<&'a EpisodeStats> {
        self.episode_ends[i].as_ref().map(|e| &e.episode)
    }
}

/// A batch of environments stepped together (SB3's `VecEnv` interface), implemented by
/// [`VecEnv`] and by vector wrappers such as [`crate::wrappers::VecNormalize`].
pub trait VectorEnv {
    /// Number of environments.
    fn num_envs(&self) -> usize;

    /// The observation space of one environment.
    fn observation_space(&self) -> &BoxSpace;

    /// The action space of one environment.
    fn action_space(&self) -> &BoxSpace;

    /// Values per observation row.
    fn obs_dim(&self) -> usize {
        self.observation_space().dim()
    }

    /// Values per action row.
    fn act_dim(&self) -> usize {
        self.action_space().dim()
    }

    /// Values of each environment's [`Info::privileged`] (0: none offered).
    fn privileged_dim(&self) -> usize {
        0
    }

    /// The camera images of one environment's observation; `None` when it observes none.
    fn image_space(&self) -> Option<&ImageSpace> {
        None
    }

    /// The current `num_envs × image_len` bytes of images (those of [`Self::observations`]);
    /// empty without an image space.
    fn images(&self) -> &[u8] {
        &[]
    }

    /// Resets every environment: `Some(seed)` resets environment `i` with `seed + i`
    /// (wrapping), `None` continues each environment's random stream. Returns the
    /// `num_envs × obs_dim` first observations.
    ///
    /// Pass a seed on the first reset: environments that draw their initial stream from a fixed
    /// default (like [`crate::GraspEnv`]) would otherwise all play the same episodes.
    fn reset(&mut self, seed: Option<u64>) -> Result<&[f32]>;

    /// Resets environment `index` alone (e.g. to recover after its step failed) and returns its
    /// first observation.
    fn reset_env(&mut self, index: usize, seed: Option<u64>) -> Result<&[f32]>;

    /// The infos of the most recent reset of each environment, including automatic ones.
    fn reset_infos(&self) -> &[Info];

    /// The current `num_envs × obs_dim` observations (those last returned).
    fn observations(&self) -> &[f32];

    /// Steps every environment with its row of `actions` (`num_envs × act_dim` values,
    /// row-major) and resets those whose episode ends.
    ///
    /// Errors name the environment. A wrong number of values, or a NaN or infinite value in any
    /// row, is rejected before any environment is stepped. When an environment's own step (or
    /// automatic reset) fails or panics, the others are stepped as usual, the error names the
    /// failed environment, and that environment must be reset (with [`Self::reset_env`] or
    /// [`Self::reset`]) before the next step.
    fn step(&mut self, actions: &[f32]) -> Result<VecStep<'_>>;

    /// Releases the environments' resources.
    fn close(&mut self) {}
}

/// One environment and its bookkeeping.
struct Slot<E> {
    env: E,
    episode: EpisodeAccumulator,
    /// Why the environment cannot be stepped before a reset (never reset, failed step).
    needs_reset: Option<&'static str>,
}

/// Values per observation row and bytes of images per environment.
#[derive(Clone, Copy)]
struct Dims {
    obs: usize,
    image: usize,
}

/// What one environment's step produced.
struct Outcome {
    obs: Vec<f32>,
    reward: f32,
    terminated: bool,
    truncated: bool,
    info: Info,
    end: Option<EpisodeEnd>,
}

/// Prefixes an environment's error with its index, keeping the error's kind where it carries a
/// message.
fn in_env(index: usize, error: EnvError) -> EnvError {
    match error {
        EnvError::Action(m) => EnvError::Action(format!("env {index}: {m}")),
        EnvError::Usage(m) => EnvError::Usage(format!("env {index}: {m}")),
        EnvError::Config { key, problem } => EnvError::Config {
            key,
            problem: format!("{problem} (env {index})"),
        },
        EnvError::File { path, problem } => EnvError::File {
            path,
            problem: format!("{problem} (env {index})"),
        },
        other => EnvError::Usage(format!("env {index}: {other}")),
    }
}

/// Appends a note to an error's message.
fn with_note(error: EnvError, note: &str) -> EnvError {
    match error {
        EnvError::Action(m) => EnvError::Action(format!("{m} {note}")),
        EnvError::Usage(m) => EnvError::Usage(format!("{m} {note}")),
        EnvError::Config { key, problem } => EnvError::Config {
            key,
            problem: format!("{problem} {note}"),
        },
        EnvError::File { path, problem } => EnvError::File {
            path,
            problem: format!("{problem} {note}"),
        },
        other => EnvError::Usage(format!("{other} {note}")),
    }
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    }
}

/// Runs `f`, turning a panic into an error that names environment `index`.
fn guarded<T>(index: usize, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result.map_err(|e| in_env(index, e)),
        Err(payload) => Err(EnvError::Usage(format!(
            "env {index} panicked during {what}: {}",
            panic_message(payload.as_ref())
        ))),
    }
}

impl<E: Env> Slot<E> {
    fn check_obs(index: usize, obs: &[f32], obs_dim: usize) -> Result<()> {
        if obs.len() == obs_dim {
            Ok(())
        } else {
            Err(EnvError::Usage(format!(
                "env {index} returned an observation of {} values; its space has {obs_dim}",
                obs.len()
            )))
        }
    }

    /// The environment's current images, which must be `image_len` bytes.
    fn image(&self, index: usize, image_len: usize) -> Result<&[u8]> {
        let image = self.env.image().unwrap_or(&[]);
        if image.len() == image_len {
            Ok(image)
        } else {
            Err(EnvError::Usage(format!(
                "env {index} returned {} bytes of images; its image space has {image_len}",
                image.len()
            )))
        }
    }

    fn reset(&mut self, index: usize, seed: Option<u64>, dims: Dims) -> Result<(Vec<f32>, Info)> {
        self.needs_reset = Some("its last reset failed");
        self.episode = EpisodeAccumulator::default();
        let (obs, info) = guarded(index, "reset", || self.env.reset(seed))?;
        Self::check_obs(index, &obs, dims.obs)?;
        self.image(index, dims.image)?;
        self.needs_reset = None;
        Ok((obs, info))
    }

    fn step(&mut self, index: usize, action: &[f32], dims: Dims) -> Result<Outcome> {
        let step = match guarded(index, "step", || self.env.step(action)) {
            Ok(step) => step,
            Err(e) => {
                self.needs_reset = Some("its last step failed");
                return Err(e);
            }
        };
        let checked = Self::check_obs(index, &step.obs, dims.obs);
        if let Err(e) = checked.and_then(|()| self.image(index, dims.image).map(|_| ())) {
            self.needs_reset = Some("its last step failed");
            return Err(e);
        }
        self.episode.add(step.reward, &step.info);
        if !(step.terminated || step.truncated) {
            return Ok(Outcome {
                obs: step.obs,
                reward: step.reward,
                terminated: false,
                truncated: false,
                info: step.info,
                end: None,
            });
        }
        let episode = self.episode.finish(&step.info);
        let terminal_image = self.env.image().unwrap_or(&[]).to_vec();
        let (obs, reset_info) = self
            .reset(index, None, dims)
            .map_err(|e| with_note(e, "(in the automatic reset after its episode ended)"))?;
        Ok(Outcome {
            obs,
            reward: step.reward,
            terminated: step.terminated,
            truncated: step.truncated,
            info: step.info,
            end: Some(EpisodeEnd {
                terminal_observation: step.obs,
                terminal_image,
                episode,
                reset_info,
            }),
        })
    }
}

/// Environment `i`'s entries in the batches a call fills: each part of a pool call writes its
/// own environments' rows, so nothing is gathered (or freed) on the caller's thread afterwards.
struct Row<'a> {
    obs: &'a mut [f32],
    image: &'a mut [u8],
    reward: &'a mut f32,
    terminated: &'a mut bool,
    truncated: &'a mut bool,
    info: &'a mut Info,
    reset_info: &'a mut Info,
    episode_end: &'a mut Option<EpisodeEnd>,
    error: &'a mut Option<EnvError>,
}

/// The vector env's per-environment storage, handed to the pool's parts as raw pointers.
struct RowPtrs<E> {
    slots: *mut Slot<E>,
    obs: *mut f32,
    obs_dim: usize,
    images: *mut u8,
    image_len: usize,
    rewards: *mut f32,
    terminated: *mut bool,
    truncated: *mut bool,
    infos: *mut Info,
    reset_infos: *mut Info,
    episode_ends: *mut Option<EpisodeEnd>,
    errors: *mut Option<EnvError>,
}

impl<E> RowPtrs<E> {
    /// # Safety
    /// `i` must be in bounds of every vector, which must outlive the returned references, and
    /// no other thread may use index `i` meanwhile.
    unsafe fn at<'a>(&self, i: usize) -> (&'a mut Slot<E>, Row<'a>) {
        unsafe {
            let obs = self.obs.add(i * self.obs_dim);
            let image = self.images.add(i * self.image_len);
            (
                &mut *self.slots.add(i),
                Row {
                    obs: std::slice::from_raw_parts_mut(obs, self.obs_dim),
                    image: std::slice::from_raw_parts_mut(image, self.image_len),
                    reward: &mut *self.rewards.add(i),
                    terminated: &mut *self.terminated.add(i),
                    truncated: &mut *self.truncated.add(i),
                    info: &mut *self.infos.add(i),
                    reset_info: &mut *self.reset_infos.add(i),
                    episode_end: &mut *self.episode_ends.add(i),
                    error: &mut *self.errors.add(i),
                },
            )
        }
    }
}

// SAFETY: only used inside `VecEnv::for_each_env`, whose parts take disjoint indices; `E: Send`
// because an environment is stepped on another thread.
unsafe impl<E: Send> Sync for RowPtrs<E> {}

/// N environments stepped in parallel, with automatic resets (see the [module](self)
/// documentation).
///
/// ```no_run
/// use fairgrasp_env::{GraspConfig, GraspEnv, VecEnv, VectorEnv};
/// # fn main() -> fairgrasp_env::Result<()> {
/// let envs = (0..8)
///     .map(|_| GraspEnv::new(GraspConfig::default()))
///     .collect::<Result<Vec<_>, _>>()?;
/// let mut venv = VecEnv::new(envs, 2)?;
/// venv.reset(Some(42))?;
/// let actions = vec![0.0; venv.num_envs() * venv.act_dim()];
/// let step = venv.step(&actions)?;
/// for i in 0..step.num_envs() {
///     if let Some(end) = &step.episode_ends[i] {
///         println!("env {i}: return {}", end.episode.episode_return);
///     }
/// }
/// # Ok(())
/// # }
/// ```
pub struct VecEnv<E: Env> {
    slots: Vec<Slot<E>>,
    /// `None`: step on the caller's thread.
    pool: Option<LockstepPool>,
    threads: usize,
    observation_space: BoxSpace,
    action_space: BoxSpace,
    image_space: Option<ImageSpace>,
    observations: Vec<f32>,
    images: Vec<u8>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    infos: Vec<Info>,
    reset_infos: Vec<Info>,
    episode_ends: Vec<Option<EpisodeEnd>>,
    /// Each environment's failure in the current call, taken before it returns.
    errors: Vec<Option<EnvError>>,
}

impl<E: Env> VecEnv<E> {
    /// Wraps `envs`, which must be at least one and share their observation and action spaces.
    ///
    /// `num_threads` is the number of worker threads: `1` steps the environments one after the
    /// other on the caller's thread (no pool); `0` uses one thread per available CPU; more
    /// threads than environments are not started. The environments must be reset (with
    /// [`VectorEnv::reset`]) before the first step.
    pub fn new(envs: Vec<E>, num_threads: usize) -> Result<Self> {
        let Some(first) = envs.first() else {
            return Err(EnvError::Usage(
                "a vector environment needs at least one environment".into(),
            ));
        };
        let observation_space = first.observation_space().clone();
        let action_space = first.action_space().clone();
        let image_space = first.image_space().cloned();
        for (i, env) in envs.iter().enumerate().skip(1) {
            if env.image_space() != image_space.as_ref() {
                return Err(EnvError::Usage(format!(
                    "env {i}'s camera images differ from env 0's: {:?} vs {:?}",
                    env.image_space(),
                    image_space
                )));
            }
            if *env.observation_space() != observation_space {
                return Err(EnvError::Usage(format!(
                    "env {i}'s observation space differs from env 0's: {:?} vs {:?}",
                    env.observation_space().shape,
                    observation_space.shape
                )));
            }
            if *env.action_space() != action_space {
                return Err(EnvError::Usage(format!(
                    "env {i}'s action space differs from env 0's: [{:?}, {:?}] vs [{:?}, {:?}]",
                    env.action_space().low,
                    env.action_space().high,
                    action_space.low,
                    action_space.high
                )));
            }
        }
        let n = envs.len();
        let wanted = if num_threads == 0 {
            std::thread::available_parallelism().map_or(1, |p| p.get())
        } else {
            num_threads
        };
        let threads = wanted.min(n).max(1);
        let pool = if threads > 1 {
            Some(LockstepPool::new(threads).map_err(|e| {
                EnvError::Usage(format!("cannot start {threads} worker threads: {e}"))
            })?)
        } else {
            None
        };
        let obs_dim = observation_space.dim();
        let image_len = image_space.as_ref().map_or(0, ImageSpace::len);
        Ok(Self {
            slots: envs
                .into_iter()
                .map(|env| Slot {
                    env,
                    episode: EpisodeAccumulator::default(),
                    needs_reset: Some("it has not been reset yet"),
                })
                .collect(),
            pool,
            threads,
            observation_space,
            action_space,
            image_space,
            observations: vec![0.0; n * obs_dim],
            images: vec![0; n * image_len],
            rewards: vec![0.0; n],
            terminated: vec![false; n],
            truncated: vec![false; n],
            infos: vec![Info::default(); n],
            reset_infos: vec![Info::default(); n],
            episode_ends: vec![None; n],
            errors: (0..n).map(|_| None).collect(),
        })
    }

    /// The number of threads stepping the environments (1: the caller's thread).
    pub fn num_threads(&self) -> usize {
        self.threads
    }

    /// The environments, in order.
    pub fn envs(&self) -> impl ExactSizeIterator<Item = &E> {
        self.slots.iter().map(|s| &s.env)
    }

    /// Environment `i`, if there is one.
    pub fn env(&self, i: usize) -> Option<&E> {
        self.slots.get(i).map(|s| &s.env)
    }

    /// Environment `i`, mutably (e.g. to render it). Resetting or stepping it directly puts it
    /// out of step with the vector environment's buffers and episode statistics.
    pub fn env_mut(&mut self, i: usize) -> Option<&mut E> {
        self.slots.get_mut(i).map(|s| &mut s.env)
    }

    /// The environments, giving up the vector environment.
    pub fn into_envs(self) -> Vec<E> {
        self.slots.into_iter().map(|s| s.env).collect()
    }

    /// Runs `f` on every environment with its rows, on the pool when there is one, then returns
    /// the failures `f` recorded. With a pool, part `p` of `t` threads takes environments
    /// `p, p + t, …`: always the same ones, so each environment's state (and the memory its
    /// steps allocate and free) stays with one core.
    fn for_each_env(&mut self, f: impl Fn(usize, &mut Slot<E>, Row<'_>) + Sync) -> Result<()> {
        let n = self.slots.len();
        let ptrs = RowPtrs {
            slots: self.slots.as_mut_ptr(),
            obs: self.observations.as_mut_ptr(),
            obs_dim: self.observation_space.dim(),
            images: self.images.as_mut_ptr(),
            image_len: self.dims().image,
            rewards: self.rewards.as_mut_ptr(),
            terminated: self.terminated.as_mut_ptr(),
            truncated: self.truncated.as_mut_ptr(),
            infos: self.infos.as_mut_ptr(),
            reset_infos: self.reset_infos.as_mut_ptr(),
            episode_ends: self.episode_ends.as_mut_ptr(),
            errors: self.errors.as_mut_ptr(),
        };
        let visit = |i: usize| {
            // SAFETY: every vector holds `n` entries (`obs_dim` values each for the
            // observations) and outlives this call; each index is visited by exactly one part.
            let (slot, row) = unsafe { ptrs.at(i) };
            f(i, slot, row);
        };
        match &self.pool {
            None => (0..n).for_each(visit),
            Some(pool) => {
                let threads = pool.threads();
                pool.run(&|part| (part..n).step_by(threads).for_each(visit));
            }
        }
        let errors: Vec<(usize, EnvError)> = self
            .errors
            .iter_mut()
            .enumerate()
            .filter_map(|(i, e)| e.take().map(|e| (i, e)))
            .collect();
        Self::first_error(errors)
    }

    /// Turns per-environment failures into one error naming the first failed environment and
    /// listing the others.
    fn first_error(errors: Vec<(usize, EnvError)>) -> Result<()> {
        let mut errors = errors.into_iter();
        let Some((_, first)) = errors.next() else {
            return Ok(());
        };
        let others: Vec<String> = errors.map(|(i, _)| i.to_string()).collect();
        Err(if others.is_empty() {
            first
        } else {
            with_note(first, &format!("(envs {} failed too)", others.join(", ")))
        })
    }

    fn dims(&self) -> Dims {
        Dims {
            obs: self.observation_space.dim(),
            image: self.image_space.as_ref().map_or(0, ImageSpace::len),
        }
    }

    fn check_actions(&self, actions: &[f32]) -> Result<()> {
        let (n, act_dim) = (self.slots.len(), self.action_space.dim());
        if actions.len() != n * act_dim {
            return Err(EnvError::Action(format!(
                "expected {n} envs × {act_dim} values = {} action values, got {}",
                n * act_dim,
                actions.len()
            )));
        }
        let bad: Vec<(usize, EnvError)> = actions
            .chunks_exact(act_dim.max(1))
            .enumerate()
            .filter_map(|(i, row)| {
                row.iter().position(|v| !v.is_finite()).map(|j| {
                    (
                        i,
                        EnvError::Action(format!(
                            "env {i}: value {j} is {}; actions must be finite",
                            row[j]
                        )),
                    )
                })
            })
            .collect();
        Self::first_error(bad)
    }
}

impl<E: Env> VectorEnv for VecEnv<E> {
    fn num_envs(&self) -> usize {
        self.slots.len()
    }

    fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }

    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<&[f32]> {
        let dims = self.dims();
        self.for_each_env(|i, slot, row| {
            *row.episode_end = None;
            *row.reward = 0.0;
            *row.terminated = false;
            *row.truncated = false;
            match slot.reset(i, seed.map(|s| s.wrapping_add(i as u64)), dims) {
                Ok((obs, info)) => {
                    row.obs.copy_from_slice(&obs);
                    row.image.copy_from_slice(slot.env.image().unwrap_or(&[]));
                    *row.reset_info = info;
                }
                Err(e) => *row.error = Some(e),
            }
        })?;
        Ok(&self.observations)
    }

    fn reset_env(&mut self, index: usize, seed: Option<u64>) -> Result<&[f32]> {
        let n = self.slots.len();
        let dims = self.dims();
        let obs_dim = dims.obs;
        let slot = self
            .slots
            .get_mut(index)
            .ok_or_else(|| EnvError::Usage(format!("env {index} does not exist; there are {n}")))?;
        let (obs, info) = slot.reset(index, seed, dims)?;
        let image = &mut self.images[index * dims.image..(index + 1) * dims.image];
        image.copy_from_slice(slot.env.image().unwrap_or(&[]));
        let row = &mut self.observations[index * obs_dim..(index + 1) * obs_dim];
        row.copy_from_slice(&obs);
        self.reset_infos[index] = info;
        self.episode_ends[index] = None;
        Ok(row)
    }

    fn privileged_dim(&self) -> usize {
        self.slots
            .first()
            .map_or(0, |slot| slot.env.privileged_dim())
    }

    fn image_space(&self) -> Option<&ImageSpace> {
        self.image_space.as_ref()
    }

    fn images(&self) -> &[u8] {
        &self.images
    }

    fn reset_infos(&self) -> &[Info] {
        &self.reset_infos
    }

    fn observations(&self) -> &[f32] {
        &self.observations
    }

    fn step(&mut self, actions: &[f32]) -> Result<VecStep<'_>> {
        if let Some((i, why)) = self
            .slots
            .iter()
            .enumerate()
            .find_map(|(i, s)| s.needs_reset.map(|why| (i, why)))
        {
            return Err(EnvError::Usage(format!(
                "env {i} must be reset before stepping ({why}): call reset() or reset_env({i}, seed)"
            )));
        }
        self.check_actions(actions)?;
        let (dims, act_dim) = (self.dims(), self.action_space.dim());
        self.for_each_env(|i, slot, row| {
            match slot.step(i, &actions[i * act_dim..(i + 1) * act_dim], dims) {
                Ok(o) => {
                    row.obs.copy_from_slice(&o.obs);
                    row.image.copy_from_slice(slot.env.image().unwrap_or(&[]));
                    *row.reward = o.reward;
                    *row.terminated = o.terminated;
                    *row.truncated = o.truncated;
                    *row.info = o.info;
                    if let Some(end) = &o.end {
                        *row.reset_info = end.reset_info.clone();
                    }
                    *row.episode_end = o.end;
                }
                Err(e) => {
                    *row.episode_end = None;
                    *row.error = Some(e);
                }
            }
        })?;
        Ok(VecStep {
            observations: &self.observations,
            rewards: &self.rewards,
            terminated: &self.terminated,
            truncated: &self.truncated,
            infos: &self.infos,
            episode_ends: &self.episode_ends,
            obs_dim: dims.obs,
            images: &self.images,
            image_len: dims.image,
        })
    }

    fn close(&mut self) {
        for slot in &mut self.slots {
            slot.env.close();
            slot.needs_reset = Some("it was closed");
        }
    }
}
