//! `fairgrasp robustness`: a policy's success over a grid of held-out conditions — object mass
//! and friction, action latency, observation noise, joint calibration errors — each varied
//! alone around the nominal environment.
//!
//! A cell is exactly the trainer's evaluation ([`fairgrasp_rl::train::evaluate`]) of the
//! model in its own environment with randomisation switched on and every range pinned
//! ([`condition::condition_table`]); every cell runs the same episode seeds, and pinned ranges
//! draw as many random numbers as free ones, so all cells see the same object placements.
//!
//! - [`grid`]: the axes, the conditions and the central region;
//! - [`condition`]: a condition as environment settings;
//! - [`report`]: the results, the table and the JSON file.

pub mod condition;
pub mod grid;
pub mod report;

pub use condition::{condition_table, nominal_of, pinned_randomization};
pub use grid::{Axis, AxisSpec, Cell, Condition, Grid, Nominal};
pub use report::{CellResult, CentralSummary, RobustnessReport};

use crate::error::{DeployError, Result};
use fairgrasp_rl::Policy;
use fairgrasp_rl::model::{env_table, load_tensors};
use fairgrasp_rl::train::{EvalResult, evaluate};
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// How a grid is run.
#[derive(Clone, Debug, PartialEq)]
pub struct RobustnessOptions {
    /// Episodes per condition.
    pub episodes: u32,
    /// Episode k of every condition uses seed `seed + k`.
    pub seed: u64,
    /// Conditions evaluated at once.
    pub threads: usize,
}

/// Evaluates every distinct condition of `grid` (each once, in parallel) with an actor made
/// by `make_actor` per condition, and returns the rows in the grid's order. `on_done` is
/// called as each condition finishes (for progress).
pub fn run_grid<F, A>(
    make_actor: F,
    env_id: &str,
    base: &toml::Table,
    grid: &Grid,
    options: &RobustnessOptions,
    on_done: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<CellResult>>
where
    F: Fn() -> Result<A> + Sync,
    A: FnMut(&[f32], Option<&[u8]>) -> fairgrasp_rl::error::Result<Vec<f32>>,
{
    grid.validate()
        .map_err(|e| DeployError::config("the robustness grid", e))?;
    if options.episodes == 0 {
        return Err(DeployError::config(
            "episodes",
            "at least one episode per condition",
        ));
    }
    let nominal = nominal_of(env_id, base)?;
    let cells = grid.cells(&nominal);
    let mut distinct: Vec<Condition> = Vec::new();
    for cell in &cells {
        if !distinct.contains(&cell.condition) {
            distinct.push(cell.condition);
        }
    }
    let tables = distinct
        .iter()
        .map(|c| condition_table(env_id, base, &nominal, c))
        .collect::<Result<Vec<_>>>()?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.threads.max(1))
        .build()
        .map_err(|e| DeployError::Other(format!("thread pool: {e}")))?;
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<EvalResult> = pool.install(|| {
        tables
            .par_iter()
            .map(|table| {
                let mut actor = make_actor()?;
                let result = evaluate(&mut actor, env_id, table, options.episodes, options.seed)?;
                let done = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                on_done(done, tables.len());
                Ok(result)
            })
            .collect::<Result<Vec<_>>>()
    })?;
    Ok(cells
        .iter()
        .map(|cell| {
            let i = distinct
                .iter()
                .position(|c| *c == cell.condition)
                .expect("every cell's condition is listed");
            CellResult::new(cell, grid.is_central(&cell.condition), &results[i])
        })
        .collect())
}

/// Runs `grid` on the saved model at `model` (a model directory or a run directory), acting
/// deterministically. Errors name the model directory.
pub fn evaluate_model(
    model: &Path,
    grid: &Grid,
    options: &RobustnessOptions,
    on_done: &(dyn Fn(usize, usize) + Sync),
) -> Result<RobustnessReport> {
    let started = Instant::now();
    let named = |e: &dyn std::fmt::Display| {
        DeployError::config(format!("model {}", model.display()), e.to_string())
    };
    let policy = Policy::load(model).map_err(|e| named(&e))?;
    let dir = policy.dir().unwrap_or(model).to_path_buf();
    let weights = load_tensors(&dir.join("model.safetensors")).map_err(|e| named(&e))?;
    let meta = policy.meta().clone();
    let base = env_table(policy.env_config()).map_err(|e| named(&e))?;
    let make_actor = || -> Result<_> {
        let mut policy = Policy::from_parts(meta.clone(), &weights).map_err(|e| named(&e))?;
        Ok(move |obs: &[f32], images: Option<&[u8]>| policy.act_with_images(obs, images, true))
    };
    let cells =
        run_grid(make_actor, &meta.env_id, &base, grid, options, on_done).map_err(|e| named(&e))?;
    let trained_randomized = base
        .get("randomization")
        .and_then(|r| r.get("enabled"))
        .and_then(toml::Value::as_bool)
        .unwrap_or(false);
    Ok(RobustnessReport {
        model: dir.display().to_string(),
        env_id: meta.env_id.clone(),
        algo: meta.algo.algo().to_string(),
        trained_steps: meta.num_timesteps,
        trained_randomized,
        episodes_per_cell: options.episodes,
        first_seed: options.seed,
        nominal: nominal_of(&meta.env_id, &base)?,
        central: CentralSummary::of(grid, &cells),
        cells,
        seconds: started.elapsed().as_secs_f64(),
    })
}
