//! Distillation as a stage of a run: a saved teacher model in, a camera policy saved and
//! evaluated out (what `fairgrasp train` runs after training when its config has `[distill]`,
//! and `fairgrasp distill` runs on its own).

use crate::distill::{DistillConfig, RoundReport, distill, evaluate_student};
use crate::error::{Result, RlError};
use crate::model::{FORMAT_VERSION, ModelMeta, PixelActorMeta, save_model};
use crate::policies::pixel_actor::PixelActor;
use crate::policy::Policy;
use crate::train::HELD_OUT_SEED_BASE;
use fairgrasp_env::atomic;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, VecEnv, VectorEnv, registry};
use serde::Serialize;
use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

/// What a distillation stage did (written as `student/summary.json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StudentSummary {
    /// Held-out episodes the student played alone, and how many succeeded.
    pub episodes: u32,
    /// See [`Self::episodes`].
    pub successes: u32,
    /// Seconds of distillation (collection and training), and of the evaluation.
    pub distill_seconds: f64,
    /// See [`Self::distill_seconds`].
    pub eval_seconds: f64,
    /// The student's trained values.
    pub parameters: usize,
    /// Labelled states the student learnt from.
    pub samples: usize,
    /// The distillation's time split (s, summed over rounds; [`RoundReport`]'s parts).
    pub env_seconds: f64,
    /// See [`Self::env_seconds`].
    pub act_seconds: f64,
    /// See [`Self::env_seconds`].
    pub forward_seconds: f64,
    /// See [`Self::env_seconds`].
    pub backward_seconds: f64,
    /// Peak resident memory of the process (MiB), where the system reports it.
    pub peak_memory_mib: Option<f64>,
}

/// The student's environment: the teacher's settings with `camera.mode = "rgb+state"`, then
/// `config.env` over them.
pub fn student_env(teacher: &Policy, config: &DistillConfig) -> Result<toml::Table> {
    let mut table = teacher.env_settings(&["camera.mode=\"rgb+state\"".to_string()])?;
    fairgrasp_env::config::overlay(&mut table, &config.env);
    registry::validate(teacher.env_id(), &table).map_err(|e| match e {
        fairgrasp_env::EnvError::Config { key, problem } => RlError::Config {
            key: format!("distill.env.{key}"),
            problem,
        },
        other => other.into(),
    })?;
    Ok(table)
}

/// Distils the model at `teacher_dir` into a camera policy saved as a model in `student_dir`
/// (`model.safetensors`, `model.json`, which [`Policy::load`] reads), then evaluates the saved
/// student alone on `config.eval_episodes` held-out episodes (`summary.json`). `on_round` sees
/// each round. Returns the summary and the student as loaded.
pub fn run_stage(
    teacher_dir: &Path,
    student_dir: &Path,
    config: &DistillConfig,
    seed: u64,
    on_round: &mut dyn FnMut(&RoundReport, &PixelActor) -> ControlFlow<()>,
) -> Result<(StudentSummary, Policy)> {
    config.validate()?;
    let started = Instant::now();
    let mut teacher = Policy::load(teacher_dir)?;
    let table = student_env(&teacher, config)?;
    let env_id = teacher.env_id().to_string();
    let envs = (0..config.n_envs)
        .map(|_| Ok(RescaleAction::new(registry::make(&env_id, &table)?)?))
        .collect::<Result<Vec<_>>>()?;
    let mut envs = VecEnv::new(envs, config.threads)?;
    let teacher_dim = teacher.obs_dim();
    let mut label = |rows: &[f32]| teacher.act_batch(rows, true);
    let mut samples = 0;
    let mut split = [0.0f64; 4];
    let mut watch = |r: &RoundReport, s: &PixelActor| {
        samples = r.samples;
        let parts = [
            r.env_seconds,
            r.act_seconds,
            r.forward_seconds,
            r.backward_seconds,
        ];
        for (total, part) in split.iter_mut().zip(parts) {
            *total += part;
        }
        on_round(r, s)
    };
    let student = distill(&mut label, teacher_dim, &mut envs, config, seed, &mut watch)?;
    envs.close();
    let distill_seconds = started.elapsed().as_secs_f64();
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo: teacher.meta().algo.clone(),
        obs_dim: student.state_dim(),
        act_dim: student.act_dim(),
        env_id: env_id.clone(),
        env: serde_json::to_value(&table).map_err(|e| RlError::Other(e.to_string()))?,
        normalization: None,
        num_timesteps: teacher.meta().num_timesteps,
        train_seed: seed,
        n_envs: config.n_envs,
        privileged_dim: 0,
        pixel_actor: Some(PixelActorMeta {
            actor: config.actor.clone(),
            images: student.images().clone(),
        }),
    };
    save_model(student_dir, &student.weights(), &meta)?;
    let mut student = Policy::load(student_dir)?;
    let started = Instant::now();
    let mut env = RescaleAction::new(registry::make(&env_id, &table)?)?;
    let successes = evaluate_student(
        &mut student,
        &mut env,
        config.eval_episodes,
        HELD_OUT_SEED_BASE,
    )?;
    env.close();
    let summary = StudentSummary {
        episodes: config.eval_episodes,
        successes,
        distill_seconds,
        eval_seconds: started.elapsed().as_secs_f64(),
        parameters: student.pixel_actor().map_or(0, PixelActor::parameter_count),
        samples,
        env_seconds: split[0],
        act_seconds: split[1],
        forward_seconds: split[2],
        backward_seconds: split[3],
        peak_memory_mib: crate::train::peak_memory_mib(),
    };
    let json = serde_json::to_string_pretty(&summary).map_err(|e| RlError::Other(e.to_string()))?;
    let path = student_dir.join("summary.json");
    atomic::write(&path, json.as_bytes())
        .map_err(|e| RlError::Other(format!("{}: {e}", path.display())))?;
    Ok((summary, student))
}
