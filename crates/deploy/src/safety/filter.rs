//! [`SafetyFilter`]: every servo set point passes through here.
//!
//! The joint motion is the environment's [`JointRamp`] — the same code a policy trained with
//! `[control.servo]` moved through in simulation: speed and acceleration caps per period, soft
//! limits with room to brake, every joint in step along a straight joint-space line, stopping
//! at the target. The caps and limits hold by construction (see [`JointRamp`]).
//!
//! On top, the TCP workspace box is checked on each set point with forward kinematics, and so
//! is the path braking from it would take (so braking starts before the wall: in the property
//! test checking where braking stops cut the stops at the box from 154 to 0 per million
//! outputs; checking the path on the way, which bends as each joint brakes on its own, keeps a
//! policy's targets near the floor from ending in a stop). If any of it leaves the box, the
//! filter brakes every joint as hard as allowed instead, and if even that leaves the box it
//! refuses with [`Fault::WorkspaceExit`] (the caller stops the arm) rather than send it.

use super::{Fault, SafetyConfig};
use crate::error::{DeployError, Result};
use fairgrasp_env::arm::JointRamp;

/// The TCP position (mm, robot base frame) for joint angles in degrees, or `None` when it
/// cannot be computed (treated as outside the box).
pub type ForwardKinematics = Box<dyn Fn(&[f64; 6]) -> Option<[f64; 3]> + Send>;

/// Floating-point slack in the checks (deg, mm).
const EPS: f64 = 1e-9;
/// Points of the braking path checked per set point besides its first and last. Braking from
/// full speed takes 0.25 s over the speed scale (128 periods at 0.25): every point up to
/// scale 0.03. Each set point the filter sends then has its whole braking path in the box, so
/// braking from it can never leave; with 16 points, 4 of 200 deployment-matched episodes at
/// scale 0.25 still met a workspace stop. About 2 ms of kinematics per control step there.
const BRAKING_SAMPLES: usize = 1024;

/// The safety layer's motion filter (see the [module](self) documentation).
pub struct SafetyFilter {
    ramp: JointRamp,
    lower: [f64; 6],
    upper: [f64; 6],
    box_min: [f64; 3],
    box_max: [f64; 3],
    fk: ForwardKinematics,
}

fn six(v: &[f64]) -> [f64; 6] {
    std::array::from_fn(|i| v[i])
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
        let limits: Vec<(f64, f64)> = (0..6).map(|i| (lower[i], upper[i])).collect();
        Ok(Self {
            ramp: JointRamp::new(
                &limits,
                config.speed_cap(),
                config.acc_cap(),
                config.servo_period_ms / 1000.0,
            ),
            lower,
            upper,
            box_min,
            box_max: config.workspace_max_mm,
            fk,
        })
    }

    /// The joint limits the filter enforces (deg).
    pub fn joint_limits(&self) -> ([f64; 6], [f64; 6]) {
        (self.lower, self.upper)
    }

    /// Speed cap (deg/s), acceleration cap (deg/s²) and period (s).
    pub fn caps(&self) -> (f64, f64, f64) {
        self.ramp.caps()
    }

    /// The TCP box enforced (mm), with the table's height folded into its floor.
    pub fn workspace(&self) -> ([f64; 3], [f64; 3]) {
        (self.box_min, self.box_max)
    }

    /// The last set point sent (deg), and its velocity (deg/s).
    pub fn last(&self) -> Option<([f64; 6], [f64; 6])> {
        self.ramp.last().map(|(p, v)| (six(p), six(v)))
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
        self.ramp.start(measured);
        Ok(())
    }

    /// The next set point towards `target` (deg), or the fault that stops the arm. After a
    /// fault the filter must be started again.
    pub fn next(&mut self, target: &[f64; 6]) -> std::result::Result<[f64; 6], Fault> {
        if self.ramp.last().is_none() {
            return Err(Fault::UnsafeStart(
                "the safety filter was not started".into(),
            ));
        }
        if let Some(index) = target.iter().position(|v| !v.is_finite()) {
            self.ramp.stop();
            return Err(Fault::NonFiniteOutput {
                index,
                value: target[index] as f32,
            });
        }
        let mut step = six(&self.ramp.propose(target).expect("started"));
        // Look ahead: where braking from the new set point would stop must be in the box too,
        // so braking starts before the wall instead of at it.
        let stop_point = six(&self.ramp.stopping_point(&step).expect("started"));
        let braking = self
            .ramp
            .braking_path(&step, BRAKING_SAMPLES)
            .expect("started");
        if self.tcp_in_box(&step).is_none()
            || self.tcp_in_box(&stop_point).is_none()
            || braking.iter().any(|q| self.tcp_in_box(&six(q)).is_none())
        {
            step = six(&self.ramp.propose_brake().expect("started"));
            if self.tcp_in_box(&step).is_none() {
                let tcp_mm = (self.fk)(&step).unwrap_or([f64::NAN; 3]);
                self.ramp.stop();
                return Err(Fault::WorkspaceExit { tcp_mm });
            }
        }
        self.ramp.commit(step.to_vec());
        Ok(step)
    }
}
