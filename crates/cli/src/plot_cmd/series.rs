//! A run's learning curves from its `progress.csv`: success rate and return, each point placed
//! at its environment step and wall time.

use fairgrasp_rl::logger::ProgressLog;

pub const STEPS: &str = "time/total_timesteps";
pub const SECONDS: &str = "time/time_elapsed";

/// What a panel shows, with the columns that hold it, best first: the evaluation (deterministic,
/// fixed seeds) where the run logged one, else the training episodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    Success,
    Return,
}

impl Metric {
    pub const ALL: [Metric; 2] = [Metric::Success, Metric::Return];

    pub fn columns(self) -> [&'static str; 2] {
        match self {
            Metric::Success => ["eval/success_rate", "rollout/success_rate"],
            Metric::Return => ["eval/mean_reward", "rollout/ep_rew_mean"],
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    pub steps: f64,
    pub seconds: f64,
    pub value: f64,
}

/// One metric of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// The `progress.csv` column the values come from.
    pub column: &'static str,
    pub points: Vec<Point>,
}

/// The rows of `column` that have a value, a step count and a wall time (all finite).
pub fn points(log: &ProgressLog, column: &str) -> Vec<Point> {
    log.values(STEPS)
        .zip(log.values(SECONDS))
        .zip(log.values(column))
        .filter_map(|((steps, seconds), value)| {
            let point = Point {
                steps: steps?,
                seconds: seconds?,
                value: value?,
            };
            [point.steps, point.seconds, point.value]
                .iter()
                .all(|v| v.is_finite())
                .then_some(point)
        })
        .collect()
}

/// The curve of `metric` from the first of its columns that has points.
pub fn curve(log: &ProgressLog, metric: Metric) -> Option<Curve> {
    metric.columns().into_iter().find_map(|column| {
        let points = points(log, column);
        (!points.is_empty()).then_some(Curve { column, points })
    })
}

/// Each value replaced by the mean of it and up to `window - 1` points before it (trailing, so a
/// point never uses the future; the first points average over fewer).
pub fn smooth(points: &[Point], window: usize) -> Vec<Point> {
    let window = window.max(1);
    let mut sum = 0.0;
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            sum += p.value;
            if i >= window {
                sum -= points[i - window].value;
            }
            Point {
                value: sum / (i + 1).min(window) as f64,
                ..*p
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// A PPO-like log: rollout rows every 1000 steps, an evaluation row every 2000 (cells empty
    /// where a row does not log a tag), and a row without a time (skipped).
    const FIXTURE: &str = "\
time/time_elapsed,rollout/ep_rew_mean,rollout/success_rate,time/total_timesteps,eval/success_rate,eval/mean_reward
1.5,-90,0,1000,,
3,-80,0.25,2000,,
3.5,,,2000,0.5,-70
,-60,0.5,3000,,
6,-50,0.75,4000,,
6.5,,,4000,1,-40
";

    fn log() -> ProgressLog {
        ProgressLog::parse(FIXTURE, Path::new("fixture/progress.csv")).unwrap()
    }

    fn p(steps: f64, seconds: f64, value: f64) -> Point {
        Point {
            steps,
            seconds,
            value,
        }
    }

    #[test]
    fn evaluation_rows_give_the_success_and_return_curves() {
        let log = log();
        let success = curve(&log, Metric::Success).unwrap();
        assert_eq!(success.column, "eval/success_rate");
        assert_eq!(success.points, [p(2000.0, 3.5, 0.5), p(4000.0, 6.5, 1.0)]);
        let ret = curve(&log, Metric::Return).unwrap();
        assert_eq!(ret.column, "eval/mean_reward");
        assert_eq!(ret.points, [p(2000.0, 3.5, -70.0), p(4000.0, 6.5, -40.0)]);
    }

    #[test]
    fn a_run_without_evaluations_falls_back_to_its_rollouts() {
        // Drop the two evaluation rows.
        let text: String = FIXTURE
            .lines()
            .filter(|l| !l.ends_with(",1,-40") && !l.ends_with(",0.5,-70"))
            .map(|l| format!("{l}\n"))
            .collect();
        let log = ProgressLog::parse(&text, Path::new("p.csv")).unwrap();
        let success = curve(&log, Metric::Success).unwrap();
        assert_eq!(success.column, "rollout/success_rate");
        // The row without a wall time is left out.
        assert_eq!(
            success.points,
            [
                p(1000.0, 1.5, 0.0),
                p(2000.0, 3.0, 0.25),
                p(4000.0, 6.0, 0.75)
            ]
        );
        assert_eq!(
            curve(&log, Metric::Return).unwrap().column,
            "rollout/ep_rew_mean"
        );
        let empty = ProgressLog::parse("time/total_timesteps\n1\n", Path::new("p.csv")).unwrap();
        assert_eq!(curve(&empty, Metric::Success), None);
    }

    #[test]
    fn smoothing_is_a_trailing_moving_average() {
        let points: Vec<Point> = [0.0, 1.0, 2.0, 6.0]
            .iter()
            .enumerate()
            .map(|(i, v)| p(i as f64, i as f64, *v))
            .collect();
        let values = |w| -> Vec<f64> { smooth(&points, w).iter().map(|p| p.value).collect() };
        assert_eq!(values(1), [0.0, 1.0, 2.0, 6.0]);
        assert_eq!(values(2), [0.0, 0.5, 1.5, 4.0]);
        assert_eq!(values(3), [0.0, 0.5, 1.0, 3.0]);
        assert_eq!(smooth(&points, 2)[3].steps, 3.0);
    }
}
