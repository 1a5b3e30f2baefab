//! How the learning rate changes over training (SB3's schedules as functions of the progress
//! remaining).

use serde::{Deserialize, Serialize};

/// How the learning rate changes over training.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// `learning_rate` throughout.
    #[default]
    Constant,
    /// Linearly from `learning_rate` to 0 at the end of training.
    Linear,
}

impl LrSchedule {
    /// The step size for `learning_rate` when `progress_remaining` of training is left (1 at
    /// the start, 0 at the end).
    pub fn at(self, learning_rate: f64, progress_remaining: f64) -> f64 {
        match self {
            Self::Constant => learning_rate,
            Self::Linear => learning_rate * progress_remaining.clamp(0.0, 1.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_falls_from_the_rate_to_zero_and_constant_stays() {
        assert_eq!(LrSchedule::Linear.at(1e-3, 1.0), 1e-3);
        assert!((LrSchedule::Linear.at(1e-3, 0.25) - 2.5e-4).abs() < 1e-12);
        assert_eq!(LrSchedule::Linear.at(1e-3, -0.1), 0.0);
        assert_eq!(LrSchedule::Constant.at(1e-3, 0.0), 1e-3);
    }
}
