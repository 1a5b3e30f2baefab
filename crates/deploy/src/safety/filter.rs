//! [`SafetyFilter`]: every servo set point passes through here.
//!
//! Each period the filter moves its last set point towards the requested target with a
//! velocity chosen inside the intersection of four windows, per joint:
//! - the speed cap `±v` (scaled by the global speed scale);
//! - the acceleration cap: within `a·dt` of the last velocity;
//! - the soft limits *with room to brake*: from the new position, braking at `a` must stop
//!   before the limit (`p + v·dt + v²/2a ≤ upper`), so a limit is never crossed even when the
//!   target jumps past it;
//! - a profile that can stop at the target, so the arm does not overshoot it.
//!
//! The first three windows always intersect (braking at `a` from a feasible state stays
//! feasible), so the caps and limits hold by construction. The TCP workspace box is checked on
//! the result with forward kinematics, and so is the point where braking from it would stop
//! (so braking starts before the wall: in the property test this cut the stops at the box from
//! 154 to 0 per million outputs); if either leaves the box, the filter brakes every
//! joint as hard as allowed instead, and if even that leaves the box it refuses with
//! [`Fault::WorkspaceExit`] (the caller stops the arm) rather than send it.

use super::{Fault, SafetyConfig};
use crate::error::{DeployError, Result};

/// The TCP position (mm, robot base frame) for joint angles in degrees, or `None` when it
/// cannot be computed (treated as outside the box).
pub type ForwardKinematics = Box<dyn Fn(&[f64; 6]) -> Option<[f64; 3]> + Send>;

/// Floating-point slack in the checks (deg, mm).
const EPS: f64 = 1e-9;

/// The safety layer's motion filter (see the [module](self) documentation).
pub struct SafetyFilter {
    lower: [f64; 6],
    upper: [f64; 6],
    speed: f64,
    acc: f64,
    dt: f64,
    box_min: [f64; 3],
    box_max: [f64; 3],
    fk: ForwardKinematics,
    last: Option<[f64; 6]>,
    velocity: [f64; 6],
}

/// The largest speed from which braking at `acc` stops within `room` after one more period
/// of `dt` at that speed: the positive root of `v·dt + v²/(2·acc) = room`.
fn braking_speed(room: f64, acc: f64, dt: f64) -> f64 {
    if room <= 0.0 {
        return 0.0;
    }
    acc * (-dt + (dt * dt + 2.0 * room / acc).sqrt())
}

impl SafetyFilter {
    /// `soft_limits_deg`: each robot joint's (min, max) from the calibration; the filter keeps
    /// `joint_margin_deg` inside them. `table_z_mm`: the table height to use when the config
    /// does not set one.
    pub fn new(
        config: &SafetyConfig,
        soft_limits_deg: &[(f64, f64)],
        table_z_mm: f64,
        fk: ForwardKinematics,
    ) -> Result<Self> {
        config.validate()?;
        if soft_limits_deg.len() != 6 {
            return Err(DeployError::config(
                "soft limits",
                format!("6 joints expected, {} given", soft_limits_deg.len()),
            ));
        }
        let (mut lower, mut upper) = ([0.0; 6], [0.0; 6]);
        for (i, &(lo, hi)) in soft_limits_deg.iter().enumerate() {
            let (lo, hi) = (lo + config.joint_margin_deg, hi - config.joint_margin_deg);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(DeployError::config(
                    format!("joint {} soft limits", i + 1),
                    format!("[{lo}, {hi}] deg after the margin is empty or not finite"),
                ));
            }
            (lower[i], upper[i]) = (lo, hi);
        }
        let table_z = config.table_z_mm.unwrap_or(table_z_mm);
        let mut box_min = config.workspace_min_mm;
        box_min[2] = box_min[2].max(table_z + config.table_margin_mm);
        if box_min[2] >= config.workspace_max_mm[2] {
            return Err(DeployError::config(
                "safety.workspace_max_mm",
                format!(
                    "the box's top ({} mm) is below the table plus margin ({} mm)",
                    config.workspace_max_mm[2], box_min[2]
                ),
            ));
        }
        Ok(Self {
            lower,
            upper,
            speed: config.speed_cap(),
            acc: config.max_joint_acc_deg_s2,
            dt: config.servo_period_ms / 1000.0,
            box_min,
            box_max: config.workspace_max_mm,
            fk,
            last: None,
            velocity: [0.0; 6],
        })
    }

    /// The joint limits the filter enforces (deg).
    pub fn joint_limits(&self) -> ([f64; 6], [f64; 6]) {
        (self.lower, self.upper)
    }

    /// Speed cap (deg/s), acceleration cap (deg/s²) and period (s).
    pub fn caps(&self) -> (f64, f64, f64) {
        (self.speed, self.acc, self.dt)
    }

    /// The TCP box enforced (mm), with the table's height folded into its floor.
    pub fn workspace(&self) -> ([f64; 3], [f64; 3]) {
        (self.box_min, self.box_max)
    }

    /// The last set point sent (deg), and its velocity (deg/s).
    pub fn last(&self) -> Option<([f64; 6], [f64; 6])> {
        self.last.map(|p| (p, self.velocity))
    }

    /// The TCP (mm) for joint angles (deg), when it lies inside the box.
    pub fn tcp_in_box(&self, joints: &[f64; 6]) -> Option<[f64; 3]> {
        let tcp = (self.fk)(joints)?;
        (0..3)
            .all(|k| tcp[k] >= self.box_min[k] - EPS && tcp[k] <= self.box_max[k] + EPS)
            .then_some(tcp)
    }

    /// Starts a motion from the measured joints (deg) at rest: they must be inside the soft
    /// limits and the TCP inside the box.
    pub fn start(&mut self, measured: &[f64; 6]) -> std::result::Result<(), Fault> {
        for (i, &q) in measured.iter().enumerate() {
            if !(q.is_finite() && q >= self.lower[i] - EPS && q <= self.upper[i] + EPS) {
                return Err(Fault::UnsafeStart(format!(
                    "joint {} is at {q:.2} deg, outside its soft limits [{:.2}, {:.2}] deg \
                     (with the margin); move it inside with the teach pendant",
                    i + 1,
                    self.lower[i],
                    self.upper[i]
                )));
            }
        }
        if self.tcp_in_box(measured).is_none() {
            let tcp = (self.fk)(measured).unwrap_or([f64::NAN; 3]);
            return Err(Fault::UnsafeStart(format!(
                "the TCP is at ({:.0}, {:.0}, {:.0}) mm, outside the workspace box \
                 {:?}–{:?} mm",
                tcp[0], tcp[1], tcp[2], self.box_min, self.box_max
            )));
        }
        self.last = Some(*measured);
        self.velocity = [0.0; 6];
        Ok(())
    }

    /// The next set point towards `target` (deg), or the fault that stops the arm. After a
    /// fault the filter must be started again.
    pub fn next(&mut self, target: &[f64; 6]) -> std::result::Result<[f64; 6], Fault> {
        let Some(last) = self.last else {
            return Err(Fault::UnsafeStart(
                "the safety filter was not started".into(),
            ));
        };
        if let Some(index) = target.iter().position(|v| !v.is_finite()) {
            self.last = None;
            return Err(Fault::NonFiniteOutput {
                index,
                value: target[index] as f32,
            });
        }
        let (dt, acc) = (self.dt, self.acc);
        let (mut low, mut high, mut error) = ([0.0; 6], [0.0; 6], [0.0; 6]);
        // The common rate `k` that moves every joint along the straight joint-space line to the
        // target (v = k · error), each joint slow enough to stop at its goal and under the speed
        // cap. Per-joint limits alone would let short moves finish first and bend the TCP's path
        // (on the twin at speed scale 0.25 it dipped 7 mm below the table margin).
        let mut k = f64::INFINITY;
        for i in 0..6 {
            let (p, v) = (last[i], self.velocity[i]);
            error[i] = target[i].clamp(self.lower[i], self.upper[i]) - p;
            let e = error[i].abs();
            if e > 1e-12 {
                let allowed = (e / dt).min(braking_speed(e, acc, dt)).min(self.speed);
                k = k.min(allowed / e);
            }
            low[i] =
                (-self.speed)
                    .max(v - acc * dt)
                    .max(-braking_speed(p - self.lower[i], acc, dt));
            high[i] = self
                .speed
                .min(v + acc * dt)
                .min(braking_speed(self.upper[i] - p, acc, dt));
            if low[i] > high[i] {
                // The windows intersect by construction; guard rounding anyway.
                let braked = v - v.signum() * (acc * dt).min(v.abs());
                (low[i], high[i]) = (braked, braked);
            }
        }
        if !k.is_finite() {
            k = 0.0;
        }
        // The largest share s ≤ 1 of that motion every joint's window allows.
        let (mut s_lo, mut s_hi) = (0.0f64, 1.0f64);
        for i in 0..6 {
            let w = k * error[i];
            if w > 0.0 {
                s_lo = s_lo.max(low[i] / w);
                s_hi = s_hi.min(high[i] / w);
            } else if w < 0.0 {
                s_lo = s_lo.max(high[i] / w);
                s_hi = s_hi.min(low[i] / w);
            } else if low[i] > 0.0 || high[i] < 0.0 {
                s_hi = -1.0;
            }
        }
        let mut step = [0.0; 6];
        let mut velocity = [0.0; 6];
        for i in 0..6 {
            let chosen = if s_lo <= s_hi {
                s_hi * k * error[i]
            } else {
                // Out of step (a joint still braking from an earlier motion): each joint on
                // its own, inside its window.
                (k * error[i]).clamp(low[i], high[i])
            };
            velocity[i] = chosen.clamp(low[i], high[i]);
            step[i] = (last[i] + velocity[i] * dt).clamp(self.lower[i], self.upper[i]);
        }
        // Look ahead: where braking from the new set point would stop must be in the box too,
        // so braking starts before the wall instead of at it.
        let stop_point: [f64; 6] = std::array::from_fn(|i| {
            let v = velocity[i];
            (step[i] + v * v.abs() / (2.0 * acc)).clamp(self.lower[i], self.upper[i])
        });
        if self.tcp_in_box(&step).is_none() || self.tcp_in_box(&stop_point).is_none() {
            // Brake every joint as hard as allowed along its present motion.
            for i in 0..6 {
                let v = self.velocity[i];
                velocity[i] = v - v.signum() * (acc * dt).min(v.abs());
                step[i] = (last[i] + velocity[i] * dt).clamp(self.lower[i], self.upper[i]);
            }
            if self.tcp_in_box(&step).is_none() {
                let tcp_mm = (self.fk)(&step).unwrap_or([f64::NAN; 3]);
                self.last = None;
                return Err(Fault::WorkspaceExit { tcp_mm });
            }
        }
        for i in 0..6 {
            velocity[i] = (step[i] - last[i]) / dt;
        }
        self.last = Some(step);
        self.velocity = velocity;
        Ok(step)
    }
}
