//! Evaluating a policy: deterministic episodes on fresh environments with known seeds, one after
//! the other ([`evaluate`]) or shared out over threads ([`evaluate_parallel`], which gives the
//! same result: every episode is played exactly as alone, and the sums are taken in episode
//! order); and recording an episode as a GIF ([`record_episode`]).

use crate::error::{Result, RlError};
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, NamedValues, registry};
use serde::{Deserialize, Serialize};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// Result of an evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalResult {
    /// Share of the episodes that succeeded, in [0, 1].
    pub success_rate: f32,
    /// Mean undiscounted return of the environment's own rewards.
    pub mean_return: f32,
    /// Mean episode length (steps).
    pub mean_length: f32,
    /// Episodes played.
    pub episodes: u32,
    /// The mean over episodes of each of the task's extras at the final step
    /// (`fraction_sorted`, `lift`, …).
    #[serde(default)]
    pub final_extras: NamedValues,
    /// Measured on the validation seeds of a confirmation (`eval.confirm_episodes`).
    #[serde(default)]
    pub confirmed: bool,
}

/// What acts: one raw observation in (the vector, and the cameras' images in a camera mode),
/// one action out (it normalises, if the model does).
pub type Act<'a> = dyn FnMut(&[f32], Option<&[u8]>) -> Result<Vec<f32>> + 'a;

/// An owned [`Act`] that can go to another thread.
pub type Actor<'a> = Box<dyn FnMut(&[f32], Option<&[u8]>) -> Result<Vec<f32>> + Send + 'a>;

/// One finished episode.
struct EpisodeOutcome {
    success: bool,
    episode_return: f32,
    length: u32,
    final_extras: NamedValues,
}

fn make_env(env_id: &str, env_config: &toml::Table) -> Result<RescaleAction<Box<dyn Env>>> {
    Ok(RescaleAction::new(registry::make(env_id, env_config)?)?)
}

/// Plays the episode seeded `seed` to its end.
fn play_episode(
    policy: &mut Act,
    env: &mut RescaleAction<Box<dyn Env>>,
    seed: u64,
) -> Result<EpisodeOutcome> {
    let (mut obs, _) = env.reset(Some(seed))?;
    let mut episode_return = 0.0f32;
    loop {
        let mut action = policy(&obs, env.image())?;
        env.action_space().clip(&mut action);
        let step = env.step(&action)?;
        episode_return += step.reward;
        obs = step.obs;
        if step.terminated || step.truncated {
            return Ok(EpisodeOutcome {
                success: step.info.success,
                episode_return,
                length: step.info.elapsed_steps,
                final_extras: step.info.extras,
            });
        }
    }
}

/// Means over the episodes, summed in episode order.
fn summarize(outcomes: &[EpisodeOutcome], episodes: u32) -> EvalResult {
    let (mut successes, mut total_return, mut total_length) = (0u32, 0.0f32, 0u64);
    let mut extras_sum = NamedValues::new();
    for o in outcomes {
        successes += o.success as u32;
        total_return += o.episode_return;
        total_length += o.length as u64;
        for (name, value) in o.final_extras.iter() {
            let sum = extras_sum.get(name).unwrap_or(0.0) + value;
            extras_sum.set(name.to_string(), sum);
        }
    }
    let n = episodes.max(1) as f32;
    let mut final_extras = NamedValues::new();
    for (name, sum) in extras_sum.iter() {
        final_extras.set(name.to_string(), sum / n);
    }
    EvalResult {
        success_rate: successes as f32 / n,
        mean_return: total_return / n,
        mean_length: total_length as f32 / n,
        episodes,
        final_extras,
        confirmed: false,
    }
}

/// Runs a deterministic policy on a fresh environment `env_id` (built through the registry from
/// `env_config`) for episodes seeded `seed, seed+1, …`.
pub fn evaluate(
    policy: &mut Act,
    env_id: &str,
    env_config: &toml::Table,
    episodes: u32,
    seed: u64,
) -> Result<EvalResult> {
    let mut env = make_env(env_id, env_config)?;
    let outcomes = (0..episodes as u64)
        .map(|e| play_episode(policy, &mut env, seed + e))
        .collect::<Result<Vec<_>>>()?;
    Ok(summarize(&outcomes, episodes))
}

/// [`evaluate`] with the episodes shared out over `threads` threads (0: one per CPU), each with
/// its own environment and its own actor from `make_actor`. The result equals [`evaluate`]'s
/// with the same actor: an episode depends only on its seed. The first failed episode's error
/// is returned.
pub fn evaluate_parallel(
    make_actor: &(dyn Fn() -> Result<Actor<'static>> + Sync),
    env_id: &str,
    env_config: &toml::Table,
    episodes: u32,
    seed: u64,
    threads: usize,
) -> Result<EvalResult> {
    let wanted = if threads == 0 {
        std::thread::available_parallelism().map_or(1, |p| p.get())
    } else {
        threads
    };
    let workers = wanted.min(episodes as usize).max(1);
    if workers == 1 {
        return evaluate(&mut make_actor()?, env_id, env_config, episodes, seed);
    }
    let next = AtomicU64::new(0);
    let results: Mutex<Vec<(u64, Result<EpisodeOutcome>)>> = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                let setup =
                    make_actor().and_then(|actor| Ok((actor, make_env(env_id, env_config)?)));
                let (mut actor, mut env) = match setup {
                    Ok(pair) => pair,
                    Err(e) => {
                        next.store(episodes as u64, Ordering::Relaxed); // the others stop
                        if let Ok(mut r) = results.lock() {
                            r.push((0, Err(e)));
                        }
                        return;
                    }
                };
                loop {
                    let e = next.fetch_add(1, Ordering::Relaxed);
                    if e >= episodes as u64 {
                        break;
                    }
                    let outcome = play_episode(&mut actor, &mut env, seed + e);
                    let failed = outcome.is_err();
                    if let Ok(mut r) = results.lock() {
                        r.push((e, outcome));
                    }
                    if failed {
                        next.store(episodes as u64, Ordering::Relaxed);
                        break;
                    }
                }
            });
        }
    });
    let mut results = results
        .into_inner()
        .map_err(|_| RlError::Other("an evaluation thread panicked".into()))?;
    results.sort_by_key(|(e, _)| *e);
    let outcomes = results
        .into_iter()
        .map(|(_, r)| r)
        .collect::<Result<Vec<_>>>()?;
    if outcomes.len() != episodes as usize {
        return Err(RlError::Other(format!(
            "evaluation finished {} of {episodes} episodes",
            outcomes.len()
        )));
    }
    Ok(summarize(&outcomes, episodes))
}

/// Plays one deterministic episode (seed `seed`) of `env_id` rendered by its `[render]`
/// camera at `size`, and returns it as a GIF.
pub fn record_episode(
    policy: &mut Act,
    env_id: &str,
    env_config: &toml::Table,
    seed: u64,
    size: [u32; 2],
) -> Result<Vec<u8>> {
    let mut table = env_config.clone();
    for item in [
        "task.render_mode=\"rgb_array\"".to_string(),
        format!("render.width={}", size[0]),
        format!("render.height={}", size[1]),
    ] {
        fairgrasp_env::config::apply_override(&mut table, &item)?;
    }
    let mut env = RescaleAction::new(registry::make(env_id, &table)?)?;
    let (mut obs, _) = env.reset(Some(seed))?;
    let mut frames = Vec::new();
    let mut frame = |env: &mut RescaleAction<Box<dyn fairgrasp_env::Env>>| -> Result<()> {
        match env.render()? {
            Some(fairgrasp_env::core::Frame::Rgb { data, .. }) => {
                frames.push(data);
                Ok(())
            }
            _ => Err(RlError::Other(format!(
                "eval.record: {env_id} renders no RGB image (only the arm tasks do)"
            ))),
        }
    };
    loop {
        frame(&mut env)?;
        let mut action = policy(&obs, env.image())?;
        env.action_space().clip(&mut action);
        let step = env.step(&action)?;
        obs = step.obs;
        if step.terminated || step.truncated {
            frame(&mut env)?;
            break;
        }
    }
    let fps = env.metadata().render_fps;
    fairgrasp_env::render::video::encode_gif(&frames, size[0], size[1], fps)
        .map_err(|e| RlError::Other(format!("eval.record: {e}")))
}

/// The lower end of the 95 % Wilson score interval for `successes` of `n` (0 when `n` is 0).
pub fn wilson_lower_bound(successes: u32, n: u32) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let (n, z) = (n as f64, 1.959_963_985);
    let p = successes as f64 / n;
    let centre = p + z * z / (2.0 * n);
    let margin = z * ((p * (1.0 - p) + z * z / (4.0 * n)) / n).sqrt();
    (centre - margin) / (1.0 + z * z / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic actor that depends on what it sees.
    fn reactive(act_dim: usize) -> Actor<'static> {
        Box::new(move |obs: &[f32], _: Option<&[u8]>| {
            Ok((0..act_dim)
                .map(|i| (obs[i % obs.len()] * 3.0 + i as f32).sin())
                .collect())
        })
    }

    #[test]
    fn parallel_evaluation_equals_sequential_evaluation() {
        for (env_id, act_dim, episodes) in [("PointReach-v0", 2, 7), ("FaArmGrasp-v0", 7, 5)] {
            let config = toml::Table::new();
            let alone = evaluate(&mut reactive(act_dim), env_id, &config, episodes, 40).unwrap();
            for threads in [2, 3] {
                let shared = evaluate_parallel(
                    &|| Ok(reactive(act_dim)),
                    env_id,
                    &config,
                    episodes,
                    40,
                    threads,
                )
                .unwrap();
                assert_eq!(shared, alone, "{env_id} on {threads} threads");
            }
            assert!(alone.mean_length > 1.0);
        }
    }

    #[test]
    fn a_failing_actor_fails_the_parallel_evaluation_with_its_error() {
        let err = evaluate_parallel(
            &|| -> Result<Actor<'static>> {
                Ok(Box::new(|_obs: &[f32], _: Option<&[u8]>| {
                    Err(RlError::Other("actor broke".into()))
                }))
            },
            "PointReach-v0",
            &toml::Table::new(),
            4,
            0,
            2,
        )
        .unwrap_err();
        assert!(err.to_string().contains("actor broke"), "{err}");
        let err = evaluate_parallel(
            &|| -> Result<Actor<'static>> { Err(RlError::Other("no actor".into())) },
            "PointReach-v0",
            &toml::Table::new(),
            4,
            0,
            2,
        )
        .unwrap_err();
        assert!(err.to_string().contains("no actor"), "{err}");
    }
}
