//! The grid of held-out conditions: five axes, each varied alone around the nominal
//! condition, and the central region the aim is stated over.

use serde::{Deserialize, Serialize};

/// A quantity the grid varies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// Object mass, as a factor on the model's nominal object mass.
    Mass,
    /// Object friction coefficient (absolute).
    Friction,
    /// Action latency (control steps).
    Latency,
    /// Standard deviation of the noise on every observed position, TCP and object (mm).
    Noise,
    /// Joint calibration error, uniform in ± this per joint per episode (degrees).
    JointOffset,
}

impl Axis {
    /// Every axis, in table order.
    pub const ALL: [Axis; 5] = [
        Axis::Mass,
        Axis::Friction,
        Axis::Latency,
        Axis::Noise,
        Axis::JointOffset,
    ];

    /// The name in the table.
    pub fn label(self) -> &'static str {
        match self {
            Axis::Mass => "object mass",
            Axis::Friction => "object friction",
            Axis::Latency => "action latency",
            Axis::Noise => "position noise σ",
            Axis::JointOffset => "joint offset ±",
        }
    }

    /// A value of this axis with its unit (`×0.5`, `2 steps`, `1 mm`, `0.25°`).
    pub fn format_value(self, v: f32) -> String {
        match self {
            Axis::Mass => format!("×{v}"),
            Axis::Friction => format!("{v}"),
            Axis::Latency if v == 1.0 => "1 step".into(),
            Axis::Latency => format!("{v} steps"),
            Axis::Noise => format!("{v} mm"),
            Axis::JointOffset => format!("{v}°"),
        }
    }
}

/// The nominal values a model's environment has (the scene's first object).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Nominal {
    /// kg
    pub object_mass: f32,
    /// Friction coefficient.
    pub object_friction: f32,
}

/// One fixed condition: every axis at one value.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Condition {
    /// Factor on the nominal object mass.
    pub mass_factor: f32,
    /// Object friction coefficient.
    pub friction: f32,
    /// Control steps between choosing an action and its reaching the robot.
    pub latency_steps: u32,
    /// σ of the Gaussian noise on observed positions (mm).
    pub noise_mm: f32,
    /// Joint calibration error bound (degrees).
    pub joint_offset_deg: f32,
}

impl Condition {
    /// The environment the model was trained on, without randomisation.
    pub fn nominal(nominal: &Nominal) -> Self {
        Self {
            mass_factor: 1.0,
            friction: nominal.object_friction,
            latency_steps: 0,
            noise_mm: 0.0,
            joint_offset_deg: 0.0,
        }
    }

    /// This condition's value on `axis`.
    pub fn value(&self, axis: Axis) -> f32 {
        match axis {
            Axis::Mass => self.mass_factor,
            Axis::Friction => self.friction,
            Axis::Latency => self.latency_steps as f32,
            Axis::Noise => self.noise_mm,
            Axis::JointOffset => self.joint_offset_deg,
        }
    }

    /// This condition with `axis` at `value` (latency rounded to whole steps).
    pub fn with(mut self, axis: Axis, value: f32) -> Self {
        match axis {
            Axis::Mass => self.mass_factor = value,
            Axis::Friction => self.friction = value,
            Axis::Latency => self.latency_steps = value.round().max(0.0) as u32,
            Axis::Noise => self.noise_mm = value,
            Axis::JointOffset => self.joint_offset_deg = value,
        }
        self
    }
}

/// The values one axis takes, and its central range (inclusive).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisSpec {
    /// The axis varied.
    pub axis: Axis,
    /// Its values, in the axis's unit ([`Axis::format_value`]).
    pub values: Vec<f32>,
    /// The central range `[low, high]`.
    pub central: [f32; 2],
}

/// One row of the grid: `axis` at `value`, every other axis nominal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cell {
    /// The axis varied.
    pub axis: Axis,
    /// Its value in this row.
    pub value: f32,
    /// The whole condition: `axis` at `value`, the others nominal.
    pub condition: Condition,
}

/// Held-out conditions, one axis at a time around nominal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// One entry per axis varied.
    pub axes: Vec<AxisSpec>,
}

impl Grid {
    /// The grid: mass ×0.5…×3, friction 0.3…2, latency 0…3 steps, position noise
    /// 0…5 mm, joint offsets up to 1°. Its central region (mass ×0.5–×2, friction 0.5–1.5,
    /// latency 0–2, noise 0–2 mm, offset ≤ 0.5°) is the default domain randomisation's
    /// ranges, plus offsets of half a degree.
    pub fn standard() -> Self {
        let spec = |axis, values: &[f32], central| AxisSpec {
            axis,
            values: values.to_vec(),
            central,
        };
        Self {
            axes: vec![
                spec(Axis::Mass, &[0.5, 1.0, 1.5, 2.0, 3.0], [0.5, 2.0]),
                spec(Axis::Friction, &[0.3, 0.5, 1.0, 1.5, 2.0], [0.5, 1.5]),
                spec(Axis::Latency, &[0.0, 1.0, 2.0, 3.0], [0.0, 2.0]),
                spec(Axis::Noise, &[0.0, 1.0, 2.0, 5.0], [0.0, 2.0]),
                spec(Axis::JointOffset, &[0.0, 0.25, 0.5, 1.0], [0.0, 0.5]),
            ],
        }
    }

    /// Every row, axis by axis in ascending value; each axis also gets a row at its nominal
    /// value when its list lacks one (friction 0.8 for the default scene).
    pub fn cells(&self, nominal: &Nominal) -> Vec<Cell> {
        let base = Condition::nominal(nominal);
        let mut out = Vec::new();
        for spec in &self.axes {
            let mut values = spec.values.clone();
            let own = base.value(spec.axis);
            if !values.contains(&own) {
                values.push(own);
            }
            values.sort_by(f32::total_cmp);
            values.dedup();
            out.extend(values.into_iter().map(|value| Cell {
                axis: spec.axis,
                value,
                condition: base.with(spec.axis, value),
            }));
        }
        out
    }

    /// Whether every axis of `condition` lies in its central range.
    pub fn is_central(&self, condition: &Condition) -> bool {
        self.axes.iter().all(|spec| {
            let v = condition.value(spec.axis);
            v >= spec.central[0] && v <= spec.central[1]
        })
    }

    /// Checks that every axis has values and a well-formed central range.
    pub fn validate(&self) -> Result<(), String> {
        for spec in &self.axes {
            let name = spec.axis.label();
            if spec.values.is_empty() {
                return Err(format!("axis {name} has no values"));
            }
            if let Some(v) = spec.values.iter().find(|v| !v.is_finite() || **v < 0.0) {
                return Err(format!(
                    "axis {name}: value {v} must be a non-negative number"
                ));
            }
            let [lo, hi] = spec.central;
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(format!(
                    "axis {name}: central range [{lo}, {hi}] is not a range"
                ));
            }
        }
        Ok(())
    }
}
