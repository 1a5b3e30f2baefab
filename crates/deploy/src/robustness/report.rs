//! What a robustness run found: one row per cell, the central-region summary, the printed
//! table and the JSON file.

use super::grid::{Axis, Cell, Condition, Grid, Nominal};
use crate::error::{DeployError, Result};
use fairgrasp_rl::train::EvalResult;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

/// One row of the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    /// The axis varied.
    pub axis: Axis,
    /// Its value in this row.
    pub value: f32,
    /// The value with its unit, as printed.
    pub label: String,
    /// The whole condition.
    pub condition: Condition,
    /// Whether the condition lies in the grid's central region.
    pub central: bool,
    /// Fraction of episodes that succeeded (0–1).
    pub success_rate: f32,
    /// Mean undiscounted episode return.
    pub mean_return: f32,
    /// Mean episode length (control steps).
    pub mean_length: f32,
    /// Episodes run.
    pub episodes: u32,
}

impl CellResult {
    /// The row of `cell` from its evaluation.
    pub fn new(cell: &Cell, central: bool, result: &EvalResult) -> Self {
        Self {
            axis: cell.axis,
            value: cell.value,
            label: cell.axis.format_value(cell.value),
            condition: cell.condition,
            central,
            success_rate: result.success_rate,
            mean_return: result.mean_return,
            mean_length: result.mean_length,
            episodes: result.episodes,
        }
    }
}

/// Success over the central region, each distinct condition counted once (the nominal
/// condition appears on several axes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CentralSummary {
    /// Each axis's central range.
    pub ranges: Vec<(Axis, [f32; 2])>,
    /// Distinct conditions in the region.
    pub conditions: usize,
    /// Mean success rate over those conditions (0–1).
    pub mean_success: f32,
    /// Lowest success rate among them (0–1).
    pub min_success: f32,
    /// The row with the lowest success (`axis value`).
    pub worst: String,
}

impl CentralSummary {
    /// The summary of `cells` (rows of `grid`); `None` when no row is central.
    pub fn of(grid: &Grid, cells: &[CellResult]) -> Option<Self> {
        let mut distinct: Vec<&CellResult> = Vec::new();
        for cell in cells.iter().filter(|c| c.central) {
            if !distinct.iter().any(|d| d.condition == cell.condition) {
                distinct.push(cell);
            }
        }
        let worst = distinct
            .iter()
            .min_by(|a, b| a.success_rate.total_cmp(&b.success_rate))?;
        let mean = distinct.iter().map(|c| c.success_rate).sum::<f32>() / distinct.len() as f32;
        Some(Self {
            ranges: grid.axes.iter().map(|s| (s.axis, s.central)).collect(),
            conditions: distinct.len(),
            mean_success: mean,
            min_success: worst.success_rate,
            worst: format!("{} {}", worst.axis.label(), worst.label),
        })
    }
}

/// A robustness run: the model, the grid's rows and the central summary.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobustnessReport {
    /// The model directory.
    pub model: String,
    /// Id of the environment evaluated.
    pub env_id: String,
    /// The algorithm that trained the model.
    pub algo: String,
    /// Environment steps the model was trained for.
    pub trained_steps: u64,
    /// Whether the model was trained with domain randomisation.
    pub trained_randomized: bool,
    /// Episodes evaluated per cell.
    pub episodes_per_cell: u32,
    /// Episode k of every cell uses seed `first_seed + k`.
    pub first_seed: u64,
    /// The model's nominal object mass and friction.
    pub nominal: Nominal,
    /// One row per cell, axis by axis.
    pub cells: Vec<CellResult>,
    /// The central region's summary; `None` when no row is central.
    pub central: Option<CentralSummary>,
    /// Wall time of the run (s).
    pub seconds: f64,
}

impl RobustnessReport {
    /// The table: axis, value, success, mean return, mean length; central rows marked `*`.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{} ({} on {}, trained {} steps{}), {} episodes per condition from seed {}",
            self.model,
            self.algo,
            self.env_id,
            self.trained_steps,
            if self.trained_randomized {
                ", with domain randomisation"
            } else {
                ""
            },
            self.episodes_per_cell,
            self.first_seed
        );
        let _ = writeln!(
            out,
            "nominal: object mass {} kg, friction {}, no latency, no noise, no joint offset",
            self.nominal.object_mass, self.nominal.object_friction
        );
        let _ = writeln!(
            out,
            "{:<18} {:>10}  {:>9}  {:>11}  {:>11}",
            "axis", "value", "success", "mean return", "mean length"
        );
        let mut last_axis = None;
        for c in &self.cells {
            let axis = if last_axis == Some(c.axis) {
                ""
            } else {
                c.axis.label()
            };
            last_axis = Some(c.axis);
            let mark = if c.central { "*" } else { " " };
            let _ = writeln!(
                out,
                "{axis:<18} {:>9}{mark}  {:>7.1} %  {:>11.2}  {:>11.1}",
                c.label,
                c.success_rate * 100.0,
                c.mean_return,
                c.mean_length
            );
        }
        match &self.central {
            Some(s) => {
                let ranges: Vec<String> = s
                    .ranges
                    .iter()
                    .map(|(axis, [lo, hi])| {
                        format!(
                            "{} {}–{}",
                            axis.label(),
                            axis.format_value(*lo),
                            axis.format_value(*hi)
                        )
                    })
                    .collect();
                let _ = writeln!(
                    out,
                    "central region (* rows: {}): {} conditions, mean success {:.1} %, worst {:.1} % ({})",
                    ranges.join(", "),
                    s.conditions,
                    s.mean_success * 100.0,
                    s.min_success * 100.0,
                    s.worst
                );
            }
            None => {
                let _ = writeln!(out, "central region: no row of the grid lies in it");
            }
        }
        out
    }

    /// Writes the report as JSON (atomically: a temporary file renamed over `path`).
    pub fn save(&self, path: &Path) -> Result<()> {
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| DeployError::Other(format!("robustness report: {e}")))?;
        fairgrasp_env::atomic::write(path, json.as_bytes())
            .map_err(|e| DeployError::config(path.display().to_string(), e.to_string()))
    }

    /// Reads a report written by [`Self::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let where_ = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| DeployError::config(&where_, e.to_string()))?;
        serde_json::from_str(&text).map_err(|e| DeployError::config(where_, e.to_string()))
    }
}
