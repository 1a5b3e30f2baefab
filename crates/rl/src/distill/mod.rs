//! Teacher–student distillation (DAgger, Ross et al. 2011): a policy that sees the simulator's
//! state (the teacher, trained in a minute) teaches a [`PixelActor`] that sees only camera
//! images and the arm's own readings.
//!
//! Each round the envs run for `steps_per_round` steps; at every step the teacher labels the
//! state with its action (from `info.privileged`, the task's observation of the true state),
//! and the action taken is the teacher's with probability β, else the student's. β falls from 1
//! to 0 over `teacher_rounds`, so the student soon meets the states its own mistakes lead to,
//! and learns what the teacher would do there. After each round the student takes `epochs`
//! passes of minibatch regression (mean squared error) over every labelled step so far (up to
//! `max_samples`, the oldest dropped). Images stay `u8` in the dataset.

pub mod stage;

use crate::error::{Result, RlError};
use crate::nn::{Adam, LrSchedule};
use crate::policies::pixel_actor::{PixelActor, PixelActorConfig, PixelCache};
use crate::policy::Policy;
use fairgrasp_env::spaces::ImageView;
use fairgrasp_env::{Env, VecEnv, VectorEnv};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;
use std::time::Instant;

/// The `[distill]` settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DistillConfig {
    /// Collection-and-training rounds.
    pub rounds: usize,
    /// Vector-env steps per round (each labels `n_envs` states).
    pub steps_per_round: usize,
    /// Rounds over which β (the chance that the teacher's action is taken) falls from 1 to 0.
    pub teacher_rounds: usize,
    /// Passes over the dataset after each round.
    pub epochs: usize,
    /// States per gradient step.
    pub batch_size: usize,
    /// Adam's step size (the first round's under a falling schedule).
    pub learning_rate: f64,
    /// How the step size changes over the rounds: `"linear"` takes round `r` of `rounds` at
    /// `learning_rate × (1 − r / rounds)`.
    pub lr_schedule: LrSchedule,
    /// The most labelled states kept (the oldest are dropped first).
    pub max_samples: usize,
    /// Random-shift augmentation (DrQ, Kostrikov et al. 2020): each training image moves by up
    /// to this many pixels in each direction, the edge repeated (0: off).
    pub shift: u32,
    /// The student's networks.
    pub actor: PixelActorConfig,
    /// Envs stepped together while collecting.
    pub n_envs: usize,
    /// Threads stepping them; with more than one the student's cameras are also encoded side by
    /// side while it trains (the same weights either way).
    pub threads: usize,
    /// Held-out episodes the student plays alone at the end.
    pub eval_episodes: u32,
    /// The student's environment: these settings over the teacher's, `camera.mode` being
    /// `"rgb+state"` unless set here (e.g. `[distill.env.camera.randomize] enabled = true`).
    pub env: toml::Table,
}

impl Default for DistillConfig {
    fn default() -> Self {
        Self {
            rounds: 10,
            steps_per_round: 250,
            teacher_rounds: 3,
            epochs: 2,
            batch_size: 128,
            learning_rate: 1e-3,
            lr_schedule: LrSchedule::Constant,
            max_samples: 150_000,
            shift: 4,
            actor: PixelActorConfig::default(),
            n_envs: 16,
            threads: 2,
            eval_episodes: 100,
            env: toml::Table::new(),
        }
    }
}

impl DistillConfig {
    /// Checks ranges; errors name the key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, problem: &str| {
            Err(RlError::Config {
                key: format!("distill.{key}"),
                problem: problem.into(),
            })
        };
        if self.rounds == 0 {
            return bad("rounds", "must be at least 1");
        }
        if self.steps_per_round == 0 {
            return bad("steps_per_round", "must be at least 1");
        }
        if self.batch_size == 0 {
            return bad("batch_size", "must be at least 1");
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return bad("learning_rate", "must be positive");
        }
        if self.max_samples < self.batch_size {
            return bad("max_samples", "must be at least batch_size");
        }
        if self.actor.features == 0 {
            return bad("actor.features", "must be at least 1");
        }
        if self.n_envs == 0 || self.n_envs > 1024 {
            return bad("n_envs", "must be in 1..=1024");
        }
        Ok(())
    }

    /// β of round `round` (0-based): 1 in the first round, 0 from `teacher_rounds` on.
    pub fn beta(&self, round: usize) -> f32 {
        if self.teacher_rounds == 0 {
            return 0.0;
        }
        (1.0 - round as f32 / self.teacher_rounds as f32).max(0.0)
    }
}

/// What one round did.
#[derive(Clone, Debug, PartialEq)]
pub struct RoundReport {
    /// The round (0-based).
    pub round: usize,
    /// The chance that the teacher's action was taken.
    pub beta: f32,
    /// Labelled states in the dataset after the round.
    pub samples: usize,
    /// Mean training loss of the round's last pass.
    pub loss: f32,
    /// Episodes that ended in the round, and how many succeeded (whoever acted).
    pub episodes: u32,
    /// See [`Self::episodes`].
    pub successes: u32,
    /// Seconds spent stepping the envs (rendering included) and labelling.
    pub collect_seconds: f64,
    /// Seconds spent training.
    pub train_seconds: f64,
    /// The parts: stepping the environments (physics and rendering, on their threads) and
    /// the teacher's and student's actions while collecting; the student's forward passes,
    /// and its backward passes with Adam's steps, while training.
    pub env_seconds: f64,
    /// See [`Self::env_seconds`].
    pub act_seconds: f64,
    /// See [`Self::env_seconds`].
    pub forward_seconds: f64,
    /// See [`Self::env_seconds`].
    pub backward_seconds: f64,
}

/// The labelled states: the student's inputs and the teacher's actions.
struct Dataset {
    state_dim: usize,
    image_len: usize,
    act_dim: usize,
    states: Vec<f32>,
    images: Vec<u8>,
    targets: Vec<f32>,
}

impl Dataset {
    fn len(&self) -> usize {
        self.targets.len() / self.act_dim
    }

    fn push(&mut self, state: &[f32], image: &[u8], target: &[f32]) {
        self.states.extend_from_slice(state);
        self.images.extend_from_slice(image);
        self.targets.extend_from_slice(target);
    }

    /// Drops the oldest states beyond `max`.
    fn keep_last(&mut self, max: usize) {
        let n = self.len();
        if n > max {
            let drop = n - max;
            self.states.drain(..drop * self.state_dim);
            self.images.drain(..drop * self.image_len);
            self.targets.drain(..drop * self.act_dim);
        }
    }

    /// Copies the rows `rows` into the batch buffers.
    fn gather(
        &self,
        rows: &[usize],
        states: &mut Vec<f32>,
        images: &mut Vec<u8>,
        targets: &mut Vec<f32>,
    ) {
        states.clear();
        images.clear();
        targets.clear();
        for &r in rows {
            states.extend_from_slice(&self.states[r * self.state_dim..(r + 1) * self.state_dim]);
            images.extend_from_slice(&self.images[r * self.image_len..(r + 1) * self.image_len]);
            targets.extend_from_slice(&self.targets[r * self.act_dim..(r + 1) * self.act_dim]);
        }
    }
}

/// Moves `image` (one view's `height × width × channels` bytes) by `dx` columns and `dy` rows,
/// repeating the edge pixels into the uncovered border; `scratch` is reused.
pub fn shift_image(image: &mut [u8], view: &ImageView, dx: i32, dy: i32, scratch: &mut Vec<u8>) {
    let (h, w, c) = (
        view.height as i32,
        view.width as i32,
        view.channels as usize,
    );
    scratch.clear();
    scratch.extend_from_slice(image);
    for y in 0..h {
        let sy = (y - dy).clamp(0, h - 1);
        for x in 0..w {
            let sx = (x - dx).clamp(0, w - 1);
            let (to, from) = (((y * w + x) as usize) * c, ((sy * w + sx) as usize) * c);
            image[to..to + c].copy_from_slice(&scratch[from..from + c]);
        }
    }
}

/// A teacher: the actions (`rows × act_dim`, in the envs' action space) for `rows` privileged
/// states, given row-major.
pub type Teacher<'a> = dyn FnMut(&[f32]) -> Result<Vec<f32>> + 'a;

/// Distils `teacher` into a new [`PixelActor`] on `envs`, whose observations must carry
/// images and whose infos the privileged state the teacher reads (its first `teacher_dim`
/// values). `on_round` sees each round's report and may stop early. The same seed gives the
/// same student.
pub fn distill<E: Env>(
    teacher: &mut Teacher<'_>,
    teacher_dim: usize,
    envs: &mut VecEnv<E>,
    config: &DistillConfig,
    seed: u64,
    on_round: &mut dyn FnMut(&RoundReport, &PixelActor) -> ControlFlow<()>,
) -> Result<PixelActor> {
    config.validate()?;
    let images = envs.image_space().cloned().ok_or_else(|| RlError::Config {
        key: "env.camera.mode".into(),
        problem: "distillation needs camera images: set it to \"rgb+state\" (or depth, rgbd)"
            .into(),
    })?;
    if envs.privileged_dim() < teacher_dim {
        return Err(RlError::Config {
            key: "env".into(),
            problem: format!(
                "the teacher reads {teacher_dim} privileged values, the env reports {}",
                envs.privileged_dim()
            ),
        });
    }
    let (n, state_dim, act_dim) = (envs.num_envs(), envs.obs_dim(), envs.act_dim());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut student = PixelActor::new(&config.actor, &images, state_dim, act_dim, &mut rng)
        .map_err(|p| RlError::Config {
            key: "distill.actor".into(),
            problem: p,
        })?;
    let mut adam = Adam::new(student.varmap(), config.learning_rate)?;
    let mut data = Dataset {
        state_dim,
        image_len: images.len(),
        act_dim,
        states: Vec::new(),
        images: Vec::new(),
        targets: Vec::new(),
    };
    let mut cache = PixelCache::default();
    cache.parallel_encoders = config.threads > 1;
    envs.reset(Some(seed))?;
    let mut privileged: Vec<f32> = (envs.reset_infos().iter())
        .flat_map(|info| info.privileged[..teacher_dim].iter().copied())
        .collect();
    let (mut batch_states, mut batch_images, mut batch_targets) =
        (Vec::new(), Vec::new(), Vec::new());
    let mut shifted = Vec::new();
    let mut actions = vec![0.0f32; n * act_dim];
    for round in 0..config.rounds {
        let beta = config.beta(round);
        let started = Instant::now();
        let (mut episodes, mut successes) = (0, 0);
        let (mut env_seconds, mut act_seconds) = (0.0, 0.0);
        for _ in 0..config.steps_per_round {
            let acting = Instant::now();
            let labels = teacher(&privileged)?;
            let states = envs.observations().to_vec();
            let frames = envs.images().to_vec();
            let own = if beta < 1.0 {
                student.forward(&states, &frames, n, &mut cache)?
            } else {
                Vec::new()
            };
            for i in 0..n {
                let label = &labels[i * act_dim..(i + 1) * act_dim];
                let target: Vec<f32> = label.iter().map(|a| a.clamp(-1.0, 1.0)).collect();
                let image = &frames[i * data.image_len..(i + 1) * data.image_len];
                data.push(&states[i * state_dim..(i + 1) * state_dim], image, &target);
                let row = &mut actions[i * act_dim..(i + 1) * act_dim];
                if beta >= 1.0 || rng.random::<f32>() < beta {
                    row.copy_from_slice(&target);
                } else {
                    row.copy_from_slice(&own[i * act_dim..(i + 1) * act_dim]);
                }
            }
            act_seconds += acting.elapsed().as_secs_f64();
            let stepping = Instant::now();
            let step = envs.step(&actions)?;
            env_seconds += stepping.elapsed().as_secs_f64();
            for i in 0..n {
                let info = match &step.episode_ends[i] {
                    Some(end) => {
                        episodes += 1;
                        successes += u32::from(step.infos[i].success);
                        &end.reset_info
                    }
                    None => &step.infos[i],
                };
                privileged[i * teacher_dim..(i + 1) * teacher_dim]
                    .copy_from_slice(&info.privileged[..teacher_dim]);
            }
        }
        if round == 0 {
            student.fit_state_scale(&data.states, 1e-3);
        }
        data.keep_last(config.max_samples);
        let collect_seconds = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let (forward_before, backward_before) = (cache.forward_seconds, cache.backward_seconds);
        let progress_remaining = 1.0 - round as f64 / config.rounds as f64;
        adam.lr = config
            .lr_schedule
            .at(config.learning_rate, progress_remaining);
        let mut order: Vec<usize> = (0..data.len()).collect();
        let mut loss = 0.0;
        for _ in 0..config.epochs.max(1) {
            order.shuffle(&mut rng);
            let (mut sum, mut count) = (0.0f64, 0usize);
            for rows in order.chunks(config.batch_size) {
                data.gather(
                    rows,
                    &mut batch_states,
                    &mut batch_images,
                    &mut batch_targets,
                );
                if config.shift > 0 {
                    let s = config.shift as i32;
                    for frame in batch_images.chunks_exact_mut(data.image_len) {
                        for (v, view) in images.views.iter().enumerate() {
                            let (dx, dy) = (rng.random_range(-s..=s), rng.random_range(-s..=s));
                            let image = &mut frame[images.range(v)];
                            shift_image(image, view, dx, dy, &mut shifted);
                        }
                    }
                }
                let l = student.train_step(
                    &mut adam,
                    &batch_states,
                    &batch_images,
                    &batch_targets,
                    &mut cache,
                )?;
                sum += l as f64;
                count += 1;
            }
            loss = (sum / count.max(1) as f64) as f32;
        }
        let report = RoundReport {
            round,
            beta,
            samples: data.len(),
            loss,
            episodes,
            successes,
            collect_seconds,
            train_seconds: started.elapsed().as_secs_f64(),
            env_seconds,
            act_seconds,
            forward_seconds: cache.forward_seconds - forward_before,
            backward_seconds: cache.backward_seconds - backward_before,
        };
        if on_round(&report, &student).is_break() {
            break;
        }
    }
    Ok(student)
}

/// Runs a camera policy alone (its actions, no teacher) for `episodes` episodes on `env`,
/// episode `e` seeded `seed + e`: the successes.
pub fn evaluate_student<E: Env>(
    student: &mut Policy,
    env: &mut E,
    episodes: u32,
    seed: u64,
) -> Result<u32> {
    let mut successes = 0;
    for e in 0..episodes as u64 {
        let (mut obs, _) = env.reset(Some(seed + e))?;
        loop {
            let image = env.image().ok_or_else(|| {
                RlError::Other("the evaluation env gives no camera images".into())
            })?;
            let action = student.act_with_images(&obs, Some(image), true)?;
            let step = env.step(&action)?;
            if step.terminated || step.truncated {
                successes += u32::from(step.info.success);
                break;
            }
            obs = step.obs;
        }
    }
    Ok(successes)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use fairgrasp_env::{GraspConfig, GraspEnv, ObsMode};

    /// Two grasp envs with 24×24 camera images in `mode`, on one thread (the camera learners'
    /// tests share them).
    pub(crate) fn envs(mode: ObsMode) -> VecEnv<GraspEnv> {
        let make = || {
            let mut config = GraspConfig::default();
            config.camera.mode = mode;
            (config.camera.width, config.camera.height) = (24, 24);
            GraspEnv::new(config).unwrap()
        };
        VecEnv::new(vec![make(), make()], 1).unwrap()
    }

    fn small() -> DistillConfig {
        DistillConfig {
            rounds: 3,
            steps_per_round: 5,
            teacher_rounds: 2,
            epochs: 1,
            batch_size: 4,
            max_samples: 1000,
            actor: PixelActorConfig {
                features: 8,
                net_arch: vec![16],
                ..PixelActorConfig::default()
            },
            ..DistillConfig::default()
        }
    }

    fn run(seed: u64) -> (Vec<RoundReport>, Vec<Vec<f32>>, usize) {
        run_with(&small(), seed)
    }

    fn run_with(config: &DistillConfig, seed: u64) -> (Vec<RoundReport>, Vec<Vec<f32>>, usize) {
        let mut venv = envs(ObsMode::RgbState);
        let teacher_dim = venv.privileged_dim() - 1;
        let act_dim = venv.act_dim();
        let mut calls = 0;
        let mut teacher = |rows: &[f32]| {
            assert_eq!(rows.len(), 2 * teacher_dim, "one privileged row per env");
            calls += 1;
            Ok(vec![0.5; 2 * act_dim])
        };
        let mut reports = Vec::new();
        let mut on_round = |r: &RoundReport, _: &PixelActor| {
            reports.push(r.clone());
            ControlFlow::Continue(())
        };
        let student = distill(
            &mut teacher,
            teacher_dim,
            &mut venv,
            config,
            seed,
            &mut on_round,
        )
        .unwrap();
        let data = student.varmap().data().lock().unwrap();
        let mut names: Vec<&String> = data.keys().collect();
        names.sort();
        let weights = (names.iter())
            .map(|n| data[*n].flatten_all().unwrap().to_vec1::<f32>().unwrap())
            .collect();
        (reports, weights, calls)
    }

    #[test]
    fn every_state_is_labelled_and_beta_hands_the_actions_to_the_student() {
        let (reports, weights, calls) = run(3);
        assert_eq!(calls, 15, "the teacher labels every step of every round");
        let samples: Vec<usize> = reports.iter().map(|r| r.samples).collect();
        assert_eq!(samples, [10, 20, 30]);
        let betas: Vec<f32> = reports.iter().map(|r| r.beta).collect();
        assert_eq!(betas, [1.0, 0.5, 0.0]);
        assert!(reports.iter().all(|r| r.loss.is_finite()));
        let (again, same, _) = run(3);
        assert_eq!(
            (reports.len(), &weights),
            (again.len(), &same),
            "same seed, same student"
        );
        assert_ne!(run(4).1, weights);
    }

    #[test]
    fn a_linear_schedule_keeps_the_first_rounds_rate_and_lowers_the_later_ones() {
        let linear = |rounds| DistillConfig {
            rounds,
            lr_schedule: LrSchedule::Linear,
            ..small()
        };
        let constant = |rounds| DistillConfig { rounds, ..small() };
        assert_eq!(run_with(&linear(1), 5).1, run_with(&constant(1), 5).1);
        assert_ne!(run_with(&linear(3), 5).1, run_with(&constant(3), 5).1);
    }

    #[test]
    fn a_shift_moves_the_picture_and_repeats_the_edge() {
        let view = ImageView {
            name: "v".into(),
            height: 2,
            width: 3,
            channels: 1,
        };
        let mut image = vec![1, 2, 3, 4, 5, 6];
        let mut scratch = Vec::new();
        shift_image(&mut image, &view, 1, 0, &mut scratch);
        assert_eq!(image, [1, 1, 2, 4, 4, 5]);
        shift_image(&mut image, &view, 0, -1, &mut scratch);
        assert_eq!(image, [4, 4, 5, 4, 4, 5]);
    }

    #[test]
    fn an_env_without_images_or_privileged_state_is_refused() {
        let mut teacher = |_: &[f32]| Ok(Vec::new());
        let mut on_round = |_: &RoundReport, _: &PixelActor| ControlFlow::Continue(());
        let mut venv = envs(ObsMode::State);
        let err = distill(&mut teacher, 3, &mut venv, &small(), 0, &mut on_round)
            .err()
            .unwrap();
        assert!(err.to_string().contains("camera.mode"), "{err}");
        let mut venv = envs(ObsMode::RgbState);
        let too_many = venv.privileged_dim() + 1;
        let err = (distill(
            &mut teacher,
            too_many,
            &mut venv,
            &small(),
            0,
            &mut on_round,
        ))
        .err()
        .unwrap();
        assert!(err.to_string().contains("privileged"), "{err}");
        let bad = DistillConfig {
            batch_size: 0,
            ..small()
        };
        let err = distill(&mut teacher, 3, &mut venv, &bad, 0, &mut on_round)
            .err()
            .unwrap();
        assert!(err.to_string().contains("distill.batch_size"), "{err}");
    }
}
