//! The excitation: one joint at a time, about the pose the arm is in, the others held.
//!
//! Each joint rests, makes four smooth steps (+A, back, −A, back: minimum-jerk moves, each
//! held), then a chirp from 0.5 to 4 Hz whose amplitude shrinks with frequency so that its
//! speed and acceleration stay under the plan's peaks, and rests again. The steps show the
//! settling, the chirp the phase and gain that tell a delay from a lag.

use crate::error::{DeployError, Result};

/// The largest amplitude accepted (deg).
pub const MAX_AMPLITUDE_DEG: f64 = 5.0;
/// The plan's peak joint speed (deg/s), at most: a ninth of the FR5's top speed.
pub const PEAK_SPEED_DEG_S: f64 = 20.0;
/// The plan's peak joint acceleration (deg/s²), at most.
pub const PEAK_ACC_DEG_S2: f64 = 250.0;

const REST_S: f64 = 0.3;
const STEP_HOLD_S: f64 = 0.4;
const CHIRP_S: f64 = 4.0;
const CHIRP_FROM_HZ: f64 = 0.5;
const CHIRP_TO_HZ: f64 = 4.0;
/// The chirp fades in and out over this long (s).
const CHIRP_FADE_S: f64 = 0.3;
const FINAL_REST_S: f64 = 0.5;

/// Peak speed and acceleration of the minimum-jerk law over its distance and duration.
const MJ_SPEED: f64 = 1.875;
const MJ_ACC: f64 = 5.773_502_691_896_258;

/// One joint's share of the plan (s from the plan's start).
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// 1…6.
    pub joint: usize,
    /// When the joint's share begins (s).
    pub start: f64,
    /// When it ends (s).
    pub end: f64,
}

/// The whole excitation.
#[derive(Clone, Debug, PartialEq)]
pub struct ExcitationPlan {
    joints: Vec<usize>,
    amplitude: f64,
    speed: f64,
    acc: f64,
    /// One minimum-jerk step's duration (s).
    step_s: f64,
}

impl ExcitationPlan {
    /// `joints` 1…6, each once; `amplitude_deg` in (0, [`MAX_AMPLITUDE_DEG`]]; the peaks are
    /// at most half the caps in force (`speed_cap` deg/s, `acc_cap` deg/s²) and never above
    /// [`PEAK_SPEED_DEG_S`] and [`PEAK_ACC_DEG_S2`].
    pub fn new(joints: &[usize], amplitude_deg: f64, speed_cap: f64, acc_cap: f64) -> Result<Self> {
        if joints.is_empty() {
            return Err(DeployError::config("--joints", "no joint to identify"));
        }
        for (i, j) in joints.iter().enumerate() {
            if !(1..=6).contains(j) {
                return Err(DeployError::config(
                    "--joints",
                    format!("joint {j} does not exist (1–6)"),
                ));
            }
            if joints[..i].contains(j) {
                return Err(DeployError::config(
                    "--joints",
                    format!("joint {j} given twice"),
                ));
            }
        }
        if !(amplitude_deg > 0.0 && amplitude_deg <= MAX_AMPLITUDE_DEG) {
            return Err(DeployError::config(
                "--amplitude-deg",
                format!("{amplitude_deg} is outside (0, {MAX_AMPLITUDE_DEG}]"),
            ));
        }
        if !(speed_cap > 0.0 && acc_cap > 0.0 && speed_cap.is_finite() && acc_cap.is_finite()) {
            return Err(DeployError::config("safety caps", "must be positive"));
        }
        let speed = PEAK_SPEED_DEG_S.min(0.5 * speed_cap);
        let acc = PEAK_ACC_DEG_S2.min(0.5 * acc_cap);
        let step_s = (MJ_SPEED * amplitude_deg / speed).max((MJ_ACC * amplitude_deg / acc).sqrt());
        Ok(Self {
            joints: joints.to_vec(),
            amplitude: amplitude_deg,
            speed,
            acc,
            step_s,
        })
    }

    /// The joints excited, in order (1…6).
    pub fn joints(&self) -> &[usize] {
        &self.joints
    }

    /// Step and chirp amplitude (deg).
    pub fn amplitude_deg(&self) -> f64 {
        self.amplitude
    }

    /// The plan's peak speed (deg/s) and acceleration (deg/s²).
    pub fn peaks(&self) -> (f64, f64) {
        (self.speed, self.acc)
    }

    /// One joint's share (s).
    pub fn per_joint(&self) -> f64 {
        REST_S + 4.0 * (self.step_s + STEP_HOLD_S) + CHIRP_S + FINAL_REST_S
    }

    /// The whole plan (s).
    pub fn duration(&self) -> f64 {
        self.per_joint() * self.joints.len() as f64
    }

    /// Each joint's share, in order.
    pub fn segments(&self) -> Vec<Segment> {
        let d = self.per_joint();
        (self.joints.iter().enumerate())
            .map(|(i, &joint)| Segment {
                joint,
                start: i as f64 * d,
                end: (i + 1) as f64 * d,
            })
            .collect()
    }

    /// The offsets from the start pose at `t` s into the plan (deg).
    pub fn offset(&self, t: f64) -> [f64; 6] {
        let mut out = [0.0; 6];
        let d = self.per_joint();
        if !(t >= 0.0 && t < self.duration()) {
            return out;
        }
        let i = ((t / d) as usize).min(self.joints.len() - 1);
        out[self.joints[i] - 1] = self.one_joint(t - i as f64 * d);
        out
    }

    /// One joint's offset `t` s into its share.
    fn one_joint(&self, t: f64) -> f64 {
        let a = self.amplitude;
        let mut t = t - REST_S;
        if t < 0.0 {
            return 0.0;
        }
        // Four steps between these levels.
        let levels = [0.0, a, 0.0, -a, 0.0];
        for k in 0..4 {
            if t < self.step_s {
                let s = t / self.step_s;
                let blend = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
                return levels[k] + (levels[k + 1] - levels[k]) * blend;
            }
            t -= self.step_s;
            if t < STEP_HOLD_S {
                return levels[k + 1];
            }
            t -= STEP_HOLD_S;
        }
        if t < CHIRP_S {
            let rate = (CHIRP_TO_HZ - CHIRP_FROM_HZ) / CHIRP_S;
            let f = CHIRP_FROM_HZ + rate * t;
            let w = 2.0 * std::f64::consts::PI * f;
            // The fade keeps the start and the end smooth; the amplitude keeps speed and
            // acceleration under the peaks (with room for the fade and the sweep).
            let fade = |x: f64| {
                let s = (x / CHIRP_FADE_S).clamp(0.0, 1.0);
                0.5 - 0.5 * (std::f64::consts::PI * s).cos()
            };
            let envelope = fade(t) * fade(CHIRP_S - t);
            // A smooth minimum (a 4-norm of the inverses): a kink in the amplitude would be
            // a jump in speed.
            let amplitude = [a, 0.7 * self.speed / w, 0.7 * self.acc / (w * w)]
                .iter()
                .map(|b| b.powi(-4))
                .sum::<f64>()
                .powf(-0.25);
            let phase = 2.0 * std::f64::consts::PI * (CHIRP_FROM_HZ * t + 0.5 * rate * t * t);
            return envelope * amplitude * phase.sin();
        }
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_stays_under_its_peaks_and_moves_one_joint_at_a_time() {
        let plan = ExcitationPlan::new(&[2, 5], 3.0, 180.0, 720.0).unwrap();
        let (speed, acc) = plan.peaks();
        assert_eq!((speed, acc), (PEAK_SPEED_DEG_S, PEAK_ACC_DEG_S2));
        let dt = 1e-3;
        let (mut v_max, mut a_max, mut q_max) = (0.0_f64, 0.0_f64, 0.0_f64);
        let mut t = 0.0;
        let mut previous_v = [0.0; 6];
        while t < plan.duration() + 0.1 {
            let (q, q1) = (plan.offset(t), plan.offset(t + dt));
            let moving: Vec<usize> = (0..6).filter(|&j| q[j] != 0.0).collect();
            assert!(moving.len() <= 1, "{t}: {q:?}");
            for j in 0..6 {
                let v = (q1[j] - q[j]) / dt;
                v_max = v_max.max(v.abs());
                a_max = a_max.max(((v - previous_v[j]) / dt).abs());
                q_max = q_max.max(q[j].abs());
                previous_v[j] = v;
            }
            t += dt;
        }
        assert!(v_max <= speed * 1.01, "{v_max} deg/s");
        assert!(a_max <= acc * 1.05, "{a_max} deg/s²");
        assert!((q_max - 3.0).abs() < 1e-6, "{q_max}");
        assert_eq!(plan.offset(plan.duration()), [0.0; 6]);
        let segments = plan.segments();
        assert_eq!(segments.len(), 2);
        assert_eq!(segments[1].joint, 5);
        assert!((segments[1].end - plan.duration()).abs() < 1e-9);
    }

    #[test]
    fn low_caps_slow_the_plan_and_bad_options_are_named() {
        let slow = ExcitationPlan::new(&[1], 3.0, 10.0, 40.0).unwrap();
        assert_eq!(slow.peaks(), (5.0, 20.0));
        let e = |j: &[usize], a: f64| {
            ExcitationPlan::new(j, a, 180.0, 720.0)
                .unwrap_err()
                .to_string()
        };
        assert!(e(&[7], 3.0).contains("joint 7"));
        assert!(e(&[1, 1], 3.0).contains("twice"));
        assert!(e(&[], 3.0).contains("no joint"));
        assert!(e(&[1], 6.0).contains("--amplitude-deg"));
        assert!(e(&[1], f64::NAN).contains("--amplitude-deg"));
    }
}
