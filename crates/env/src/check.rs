//! An environment checker in the spirit of Gymnasium's `check_env`: the contract (spaces, reset
//! and step signatures, info), seeding determinism, rejection of bad actions, and a random-action
//! rollout that must produce no NaN and end every episode for a known reason.

use crate::arm::ActionMode;
use crate::core::{Env, EpisodeEvent};
use crate::tasks::grasp::all_variants;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// One configuration a check runs: `key=value` overrides (the CLI's `--set` form) laid over the
/// user's settings, and a label that lists them.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckVariant {
    /// The overrides joined by spaces, or `defaults` when there are none.
    pub label: String,
    /// `key=value` settings, values as a config file spells them
    /// (e.g. `control.action_mode="joint"`).
    pub overrides: Vec<String>,
}

/// The configurations `fairgrasp env check` runs for `env_id`, each with and without domain
/// randomisation: for the grasp every observation × action × reward variant
/// ([`all_variants`]: 24 in all), for the other arm tasks each action mode, for any other env
/// its defaults.
pub fn variants(env_id: &str) -> Vec<CheckVariant> {
    let mut out = Vec::new();
    for randomize in [false, true] {
        let with = |mut settings: Vec<String>| {
            settings.insert(0, format!("randomization.enabled={randomize}"));
            CheckVariant {
                label: settings.join(" "),
                overrides: settings,
            }
        };
        if env_id == crate::ENV_ID {
            for (obs, mode, reward) in all_variants() {
                out.push(with(vec![
                    format!("control.action_mode={}", spelled(&mode)),
                    format!("task.observation={}", spelled(&obs)),
                    format!("reward.kind={}", spelled(&reward)),
                ]));
            }
        } else if env_id.starts_with("FaArm") {
            for mode in [ActionMode::Joint, ActionMode::Cartesian] {
                out.push(with(vec![format!(
                    "control.action_mode={}",
                    spelled(&mode)
                )]));
            }
        }
    }
    if out.is_empty() {
        out.push(CheckVariant {
            label: "defaults".into(),
            overrides: Vec::new(),
        });
    }
    out
}

/// A setting's value as a config file spells it (its serde name, quoted for a string).
fn spelled<T: Serialize>(value: &T) -> String {
    toml::Value::try_from(value).map_or_else(|e| e.to_string(), |v| v.to_string())
}

/// How the episodes of the random rollout ended, counted by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EndReasons {
    /// Episodes that ended in success.
    pub success: u32,
    /// Episodes truncated at the step limit.
    pub time_limit: u32,
    /// Episodes that ended with the object off the table.
    pub object_off_table: u32,
    /// Anything else (non-finite physics, or a terminal step with no known reason): a failure.
    pub other: u32,
}

/// The result of [`check_env`].
#[derive(Clone, Debug, Default)]
pub struct CheckReport {
    /// Each check by name, with the problem when it failed.
    pub checks: Vec<(String, Result<(), String>)>,
    /// Steps the random rollout took (fewer than asked when it failed).
    pub rollout_steps: u64,
    /// How the rollout's episodes ended.
    pub episodes: EndReasons,
    /// Rollout steps whose observation held a non-finite value.
    pub nan_observations: u64,
    /// Rollout steps whose reward was not finite.
    pub non_finite_rewards: u64,
}

impl CheckReport {
    /// Whether every check passed.
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|(_, r)| r.is_ok())
    }

    fn record(&mut self, name: &str, result: Result<(), String>) {
        self.checks.push((name.to_string(), result));
    }
}

fn ensure(condition: bool, problem: impl FnOnce() -> String) -> Result<(), String> {
    if condition { Ok(()) } else { Err(problem()) }
}

/// Checks `env` (and `twin`, a second instance built from the same configuration, used to
/// compare seeded runs) and rolls out `rollout_steps` random actions.
pub fn check_env<E: Env>(env: &mut E, twin: &mut E, rollout_steps: u64, seed: u64) -> CheckReport {
    let mut report = CheckReport::default();
    let obs_space = env.observation_space().clone();
    let act_space = env.action_space().clone();

    report.record(
        "spaces",
        ensure(obs_space.dim() > 0 && act_space.dim() > 0, || {
            "empty space".into()
        })
        .and_then(|_| {
            ensure(act_space.is_bounded(), || {
                "the action space must be bounded for continuous-control agents".into()
            })
        })
        .and_then(|_| {
            ensure(
                act_space
                    .low
                    .iter()
                    .zip(&act_space.high)
                    .all(|(l, h)| l < h),
                || format!("action low must be below high: {act_space:?}"),
            )
        })
        .and_then(|_| {
            ensure(
                obs_space
                    .low
                    .iter()
                    .zip(&obs_space.high)
                    .all(|(l, h)| l <= h),
                || "observation low above high".into(),
            )
        })
        .and_then(|_| {
            ensure(obs_space.is_bounded(), || {
                "the observation space must be bounded (Gymnasium's checker warns about infinite bounds)"
                    .into()
            })
        }),
    );

    // reset(seed) → (obs in space, info); same seed → same obs.
    let reset = env.reset(Some(seed)).map_err(|e| e.to_string());
    let twin_reset = twin.reset(Some(seed)).map_err(|e| e.to_string());
    report.record(
        "reset",
        match (&reset, &twin_reset) {
            (Ok((obs, _)), Ok((twin_obs, _))) => ensure(obs_space.contains(obs), || {
                format!("reset observation not in the observation space: {obs:?}")
            })
            .and_then(|_| {
                ensure(obs == twin_obs, || {
                    "reset with the same seed gave different observations".into()
                })
            }),
            (Err(e), _) | (_, Err(e)) => Err(format!("reset failed: {e}")),
        },
    );
    if reset.is_err() || twin_reset.is_err() {
        return report;
    }

    // Bad actions are refused and leave no trace.
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut bad = act_space.sample(&mut rng);
    bad[0] = f32::NAN;
    let short = vec![0.0; act_space.dim() - 1];
    let refused = env.step(&bad).is_err()
        && env.step(&short).is_err()
        && env.step(&vec![f32::INFINITY; act_space.dim()]).is_err();
    report.record(
        "bad actions refused",
        ensure(refused, || {
            "NaN, infinite or wrong-length actions were accepted".into()
        }),
    );

    // step → (obs, reward, terminated, truncated, info); seeded runs agree step by step.
    let mut step_check = Ok(());
    let mut determinism = Ok(());
    for i in 0..50 {
        let action = act_space.sample(&mut rng);
        match (env.step(&action), twin.step(&action)) {
            (Ok(a), Ok(b)) => {
                if !obs_space.contains(&a.obs) {
                    step_check = Err(format!(
                        "step {i}: observation not in the space: {:?}",
                        a.obs
                    ));
                    break;
                }
                if !a.reward.is_finite() {
                    step_check = Err(format!("step {i}: reward {}", a.reward));
                    break;
                }
                // Terms are optional; when an env reports them they must add up.
                let terms = &a.info.reward_terms;
                if !terms.is_empty() && (terms.total() - a.reward).abs() > 1e-4 {
                    step_check = Err(format!("step {i}: reward terms do not sum to the reward"));
                    break;
                }
                if a != b {
                    determinism = Err(format!("step {i}: the same seed and actions diverged"));
                    break;
                }
                if a.terminated || a.truncated {
                    let _ = env.reset(Some(seed + 1));
                    let _ = twin.reset(Some(seed + 1));
                }
            }
            (Err(e), _) | (_, Err(e)) => {
                step_check = Err(format!("step {i} failed: {e}"));
                break;
            }
        }
    }
    report.record("step", step_check);
    report.record("seeding determinism", determinism);
    report.record(
        "render",
        env.render()
            .map(|_| ())
            .map_err(|e| format!("render failed: {e}")),
    );

    // Random rollout.
    let mut rollout = Ok(());
    if let Err(e) = env.reset(Some(seed + 2)) {
        rollout = Err(format!("reset failed: {e}"));
    }
    let mut steps = 0;
    while rollout.is_ok() && steps < rollout_steps {
        let action = act_space.sample(&mut rng);
        match env.step(&action) {
            Ok(step) => {
                steps += 1;
                if step.obs.iter().any(|v| !v.is_finite()) {
                    report.nan_observations += 1;
                }
                if !step.reward.is_finite() {
                    report.non_finite_rewards += 1;
                }
                if step.terminated || step.truncated {
                    let e = &mut report.episodes;
                    if step.info.success {
                        e.success += 1;
                    } else if step.info.events.contains(&EpisodeEvent::ObjectOffTable) {
                        e.object_off_table += 1;
                    } else if step.truncated
                        && !step.info.events.contains(&EpisodeEvent::NonFiniteState)
                    {
                        e.time_limit += 1;
                    } else {
                        e.other += 1;
                    }
                    if let Err(err) = env.reset(None) {
                        rollout = Err(format!("reset failed after {steps} steps: {err}"));
                    }
                }
            }
            Err(e) => rollout = Err(format!("step failed after {steps} steps: {e}")),
        }
    }
    report.rollout_steps = steps;
    if rollout.is_ok() && (report.nan_observations > 0 || report.non_finite_rewards > 0) {
        rollout = Err(format!(
            "{} NaN observations and {} non-finite rewards",
            report.nan_observations, report.non_finite_rewards
        ));
    }
    if rollout.is_ok() && report.episodes.other > 0 {
        rollout = Err(format!(
            "{} episodes ended for no known reason (non-finite physics?)",
            report.episodes.other
        ));
    }
    report.record(&format!("random rollout ({rollout_steps} steps)"), rollout);
    report
}
