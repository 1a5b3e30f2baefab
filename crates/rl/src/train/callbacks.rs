//! Callbacks: what the training driver does between iterations (SB3's `BaseCallback`).
//!
//! The driver runs the learner's iterations and, after each, every callback in turn; any of
//! them may stop the run. Logging, evaluation with best-model saving, stopping on success,
//! checkpoints and the time budget are callbacks here, built from the [`TrainConfig`]; users
//! pass their own to [`crate::train::train_with`] (and Python's `fairgrasp.train(callback=…)`
//! arrives as one).

use crate::Policy;
use crate::algorithm::TensorMap;
use crate::error::{Result, RlError};
use crate::evaluation::{Actor, EvalResult, evaluate_parallel, record_episode, wilson_lower_bound};
use crate::logger::{CsvLogger, TensorBoardWriter};
use crate::model::{ModelMeta, save_model};
use crate::train::config::{EVAL_SEED_BASE, TrainConfig, VALIDATION_SEED_BASE};
use crate::train::run_dir::{RunDir, TrainerState};
use fairgrasp_env::NamedValues;
use fairgrasp_env::VecStep;
use fairgrasp_env::atomic;
use fairgrasp_env::wrappers::EpisodeStats;
use std::collections::VecDeque;
use std::ops::ControlFlow;
use std::time::Instant;

/// Why a callback stopped the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// The evaluation reached `eval.success_threshold` (and its confirmation held).
    SuccessThreshold,
    /// The run used up `max_seconds`.
    TimeBudget,
    /// A caller's callback asked to stop (Ctrl-C in Python, a Ray Tune scheduler, …).
    Requested,
}

/// Progress reported to the caller (for a progress bar).
#[derive(Clone, Debug, Default)]
pub struct Progress {
    /// Environment steps taken so far (all environments together).
    pub num_timesteps: u64,
    /// Environment steps the run trains for.
    pub total_timesteps: u64,
    /// Environment steps per second of wall time, updates included.
    pub fps: f64,
    /// Mean return of the last 100 training episodes (SB3's `rollout/ep_rew_mean`);
    /// `None` before one has ended.
    pub ep_rew_mean: Option<f32>,
    /// Share of the last 100 training episodes that succeeded.
    pub rollout_success_rate: Option<f32>,
    /// For each of the task's extras, the mean over recent episodes of its largest value in
    /// the episode (`grasped`: the share of episodes with a grasp; `lift`: the mean peak lift).
    pub rollout_max_extras: NamedValues,
    /// The latest evaluation's result.
    pub last_eval: Option<EvalResult>,
    /// Evaluations run so far (in this session).
    pub eval_count: usize,
    /// Success rate of the best evaluation so far.
    pub best_success_rate: Option<f32>,
}

/// Something that runs between the learner's iterations.
pub trait Callback {
    /// After every vector step of the environments (many per iteration for PPO, one for SAC
    /// and TD3). Keep it cheap: it runs on the training's hot path.
    fn on_step(&mut self, _step: &VecStep<'_>) {}

    /// After each iteration of the learner (PPO: a rollout and its update; SAC, TD3: one vector
    /// step and its gradient steps). `Break` stops the run after every callback of this
    /// iteration has run; the final model, logs and summary are then written as at the end.
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>>;
}

/// A borrowed callback, so that the caller reads what it gathered after the run.
impl<C: Callback + ?Sized> Callback for &mut C {
    fn on_step(&mut self, step: &VecStep<'_>) {
        (**self).on_step(step);
    }

    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        (**self).on_iteration(ctx)
    }
}

/// The state of the run that checkpoints keep, so that a resumed run goes on where it was.
#[derive(Clone, Debug, Default)]
pub struct RunState {
    /// The best evaluation so far, by (confirmed, success rate, return).
    pub best: Option<EvalResult>,
    /// Step count at which the next evaluation is due.
    pub next_eval: u64,
    /// Step count at which the next checkpoint is due.
    pub next_checkpoint: u64,
    /// The last 100 finished training episodes.
    pub recent: VecDeque<EpisodeStats>,
    /// The evaluation of this iteration, if one ran: its result and, when it reached the success
    /// threshold, the confirmation's result and 95 % Wilson lower bound.
    pub latest_eval: Option<(EvalResult, Option<(EvalResult, f64)>)>,
}

/// The run's TensorBoard and CSV logs.
pub struct Logs {
    /// `tb/`.
    pub tensorboard: TensorBoardWriter,
    /// `progress.csv`.
    pub csv: CsvLogger,
}

/// What a callback sees after an iteration.
pub struct CallbackContext<'a> {
    /// The run's configuration.
    pub config: &'a TrainConfig,
    /// The run's directory.
    pub run_dir: &'a RunDir,
    /// Environment steps so far (all environments together).
    pub num_timesteps: u64,
    /// What the caller's progress display shows.
    pub progress: &'a mut Progress,
    /// The state checkpoints keep.
    pub state: &'a mut RunState,
    /// The logs.
    pub logs: &'a mut Logs,
    /// The learner's `train/*` scalars of this iteration (empty when it did not learn).
    pub train_scalars: &'a [(&'static str, f32)],
    pub(crate) learner: &'a dyn LearnerSnapshot,
    pub(crate) started: Instant,
    pub(crate) elapsed_before: f64,
}

/// The learner as callbacks read it.
pub(crate) trait LearnerSnapshot {
    /// `model.json` of the model as it is now.
    fn meta(&self) -> ModelMeta;
    /// The networks' weights.
    fn weights(&self) -> Result<TensorMap>;
    /// Optimiser moments, replay buffer… (what resuming needs).
    fn training_state(&self) -> Result<TensorMap>;
    /// The full normalisation state as JSON.
    fn normalization(&self) -> String;
}

impl CallbackContext<'_> {
    /// Wall time of the run so far, across resumes (s).
    pub fn elapsed(&self) -> f64 {
        self.elapsed_before + self.started.elapsed().as_secs_f64()
    }

    /// The model as it is now: its description and weights.
    pub fn model(&self) -> Result<(ModelMeta, TensorMap)> {
        Ok((self.learner.meta(), self.learner.weights()?))
    }

    /// A policy acting as the saved model would.
    pub fn policy(&self) -> Result<Policy> {
        let (meta, weights) = self.model()?;
        Policy::from_parts(meta, &weights)
    }

    /// Saves the model as it is now to `dir` (replaced whole).
    pub fn save_model(&self, dir: &std::path::Path) -> Result<()> {
        let (meta, weights) = self.model()?;
        save_model(dir, &weights, &meta)
    }

    /// Names the run directory in an I/O error.
    fn io(&self) -> impl Fn(std::io::Error) -> RlError + use<> {
        let dir = self.run_dir.path().display().to_string();
        move |e| RlError::Other(format!("{dir}: {e}"))
    }
}

/// Logs the learner's scalars and the rollout statistics to TensorBoard and `progress.csv`
/// (SB3's logger dump), at most once per `interval` steps.
pub struct LogScalars {
    interval: u64,
    last: u64,
}

impl LogScalars {
    /// Logs when at least `interval` steps passed since `start` (0: every iteration).
    pub fn new(interval: u64, start: u64) -> Self {
        Self {
            interval,
            last: start,
        }
    }
}

impl Callback for LogScalars {
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        if ctx.train_scalars.is_empty() || ctx.num_timesteps - self.last < self.interval {
            return Ok(ControlFlow::Continue(()));
        }
        self.last = ctx.num_timesteps;
        let p = &*ctx.progress;
        let mut scalars: Vec<(String, f32)> = ctx
            .train_scalars
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect();
        scalars.push(("time/fps".into(), p.fps as f32));
        scalars.push(("time/time_elapsed".into(), ctx.elapsed() as f32));
        if let Some(r) = p.ep_rew_mean {
            scalars.push(("rollout/ep_rew_mean".into(), r));
        }
        if let Some(r) = p.rollout_success_rate {
            scalars.push(("rollout/success_rate".into(), r));
        }
        for (name, value) in p.rollout_max_extras.iter() {
            scalars.push((format!("rollout/max_{name}"), value));
        }
        let mut row: Vec<(&str, f64)> = scalars
            .iter()
            .map(|(k, v)| (k.as_str(), *v as f64))
            .collect();
        row.push(("time/total_timesteps", p.num_timesteps as f64));
        let io = ctx.io();
        ctx.logs
            .tensorboard
            .add_scalars(p.num_timesteps, &scalars)
            .map_err(&io)?;
        ctx.logs.csv.write_row(&row).map_err(&io)?;
        Ok(ControlFlow::Continue(()))
    }
}

/// Evaluates every `eval.freq` steps on the evaluation env (SB3's `EvalCallback`), acting
/// exactly as the saved model will, one policy per thread; logs the result, records a video
/// when asked, confirms a result that reaches the success threshold on validation seeds, and
/// saves the best model to `best/`.
pub struct Evaluate;

impl Callback for Evaluate {
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        let config = ctx.config;
        let steps = ctx.num_timesteps;
        ctx.state.latest_eval = None;
        if config.eval.freq == 0 || steps < ctx.state.next_eval {
            return Ok(ControlFlow::Continue(()));
        }
        ctx.state.next_eval += config.eval.freq;
        let eval_env = config.eval_env();
        // The episodes run on the env threads, idle during evaluation.
        let (meta, weights) = ctx.model()?;
        let make_actor = || -> Result<Actor<'static>> {
            let mut policy = Policy::from_parts(meta.clone(), &weights)?;
            Ok(Box::new(move |obs: &[f32], images: Option<&[u8]>| {
                policy.act_with_images(obs, images, true)
            }))
        };
        let result = evaluate_parallel(
            &make_actor,
            &config.env_id,
            &eval_env,
            config.eval.episodes,
            EVAL_SEED_BASE,
            config.threads,
        )?;
        let mut scalars: Vec<(String, f32)> = vec![
            ("eval/success_rate".into(), result.success_rate),
            ("eval/mean_reward".into(), result.mean_return),
            ("eval/mean_ep_length".into(), result.mean_length),
        ];
        scalars.extend(
            result
                .final_extras
                .iter()
                .map(|(name, v)| (format!("eval/{name}"), v)),
        );
        let io = ctx.io();
        if config.eval.record {
            let mut actor = make_actor()?;
            let gif = record_episode(
                &mut actor,
                &config.env_id,
                &eval_env,
                EVAL_SEED_BASE,
                config.eval.record_size,
            )?;
            atomic::write(&ctx.run_dir.eval_video(steps), &gif).map_err(&io)?;
        }
        ctx.logs
            .tensorboard
            .add_scalars(steps, &scalars)
            .map_err(&io)?;
        let mut row: Vec<(&str, f64)> = scalars
            .iter()
            .map(|(k, v)| (k.as_str(), *v as f64))
            .collect();
        row.push(("time/total_timesteps", steps as f64));
        row.push(("time/time_elapsed", ctx.elapsed()));
        ctx.logs.csv.write_row(&row).map_err(&io)?;
        let reached = (config.eval.success_threshold).is_some_and(|t| result.success_rate >= t);
        // The confirmation: more episodes on validation seeds, the stop on their lower bound.
        let confirmation = if reached && config.eval.confirm_episodes > 0 {
            let confirmation = evaluate_parallel(
                &make_actor,
                &config.env_id,
                &eval_env,
                config.eval.confirm_episodes,
                VALIDATION_SEED_BASE,
                config.threads,
            )?;
            let successes = (confirmation.success_rate * confirmation.episodes as f32).round();
            let bound = wilson_lower_bound(successes as u32, confirmation.episodes);
            ctx.logs
                .tensorboard
                .add_scalars(
                    steps,
                    &[
                        ("eval/confirmed_success_rate", confirmation.success_rate),
                        ("eval/confirmed_lower_bound", bound as f32),
                    ],
                )
                .map_err(&io)?;
            Some((confirmation, bound))
        } else {
            None
        };
        // A confirmed result outranks an unconfirmed one; among equals, success then return.
        let rank = |r: &EvalResult| (r.confirmed, r.success_rate, r.mean_return);
        let candidate = match &confirmation {
            Some((c, _)) => EvalResult {
                confirmed: true,
                ..c.clone()
            },
            None => result.clone(),
        };
        if ctx
            .state
            .best
            .as_ref()
            .is_none_or(|b| rank(&candidate) > rank(b))
        {
            save_model(&ctx.run_dir.best_model(), &weights, &meta)?;
            ctx.state.best = Some(candidate);
        }
        ctx.progress.best_success_rate = ctx.state.best.as_ref().map(|b| b.success_rate);
        ctx.progress.last_eval = Some(result.clone());
        ctx.progress.eval_count += 1;
        ctx.state.latest_eval = Some((result, confirmation));
        Ok(ControlFlow::Continue(()))
    }
}

/// Stops when this iteration's evaluation reached `eval.success_threshold` and, with
/// `eval.confirm_episodes`, its confirmation's lower bound reached `eval.confirm_lower_bound`
/// (SB3's `StopTrainingOnRewardThreshold`, on the success rate). Runs after [`Evaluate`].
pub struct StopOnSuccess;

impl Callback for StopOnSuccess {
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        let (Some(threshold), Some((result, confirmation))) =
            (ctx.config.eval.success_threshold, &ctx.state.latest_eval)
        else {
            return Ok(ControlFlow::Continue(()));
        };
        let stop = match confirmation {
            Some((_, bound)) => *bound >= ctx.config.eval.confirm_lower_bound as f64,
            None => result.success_rate >= threshold && ctx.config.eval.confirm_episodes == 0,
        };
        Ok(match stop {
            true => ControlFlow::Break(StopReason::SuccessThreshold),
            false => ControlFlow::Continue(()),
        })
    }
}

/// Writes `checkpoints/step_<N>/` every `checkpoint_freq` steps (SB3's `CheckpointCallback`,
/// with what resuming needs).
pub struct SaveCheckpoint;

impl Callback for SaveCheckpoint {
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        let freq = ctx.config.checkpoint_freq;
        if freq == 0 || ctx.num_timesteps < ctx.state.next_checkpoint {
            return Ok(ControlFlow::Continue(()));
        }
        ctx.state.next_checkpoint += freq;
        let state = TrainerState {
            format_version: 1,
            num_timesteps: ctx.num_timesteps,
            next_eval: ctx.state.next_eval,
            next_checkpoint: ctx.state.next_checkpoint,
            best: ctx.state.best.clone(),
            elapsed_seconds: ctx.elapsed(),
            recent_episodes: ctx.state.recent.iter().cloned().collect(),
            normalization: ctx.learner.normalization(),
        };
        let (meta, weights) = ctx.model()?;
        let training = ctx.learner.training_state()?;
        ctx.run_dir
            .write_checkpoint(&weights, &training, &meta, &state)?;
        Ok(ControlFlow::Continue(()))
    }
}

/// Stops once the run's wall time, across resumes, reaches `seconds`.
pub struct TimeBudget {
    /// The budget (s).
    pub seconds: f64,
}

impl Callback for TimeBudget {
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        Ok(match ctx.elapsed() >= self.seconds {
            true => ControlFlow::Break(StopReason::TimeBudget),
            false => ControlFlow::Continue(()),
        })
    }
}

/// A progress function as a callback: it sees [`Progress`] after every iteration, and `Break`
/// stops the run ([`StopReason::Requested`]).
pub struct OnProgress<F>(pub F);

impl<F: FnMut(&Progress) -> ControlFlow<()>> Callback for OnProgress<F> {
    fn on_iteration(&mut self, ctx: &mut CallbackContext<'_>) -> Result<ControlFlow<StopReason>> {
        Ok(match (self.0)(&*ctx.progress) {
            ControlFlow::Break(()) => ControlFlow::Break(StopReason::Requested),
            ControlFlow::Continue(()) => ControlFlow::Continue(()),
        })
    }
}
