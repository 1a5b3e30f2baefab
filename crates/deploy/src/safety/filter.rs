//! [`SafetyFilter`]: every servo set point passes through here.
//!
//! The joint motion is the environment's [`JointRamp`] — the same code a policy trained with
//! `[control.servo]` moved through in simulation: speed and acceleration caps per period, soft
//! limits with room to brake, every joint in step along a straight joint-space line, stopping
//! at the target. The caps and limits hold by construction (see [`JointRamp`]).
//!
//! On top, each set point is checked with forward kinematics: the TCP inside the workspace
//! box, and every part of the arm and gripper (the spheres of its envelope: links, flange,
//! fingers) at least `arm_clearance_mm` above the table and inside the cell's box. So is the
//! path braking from it would take (so braking starts before the wall: in the property
//! test checking where braking stops cut the stops at the box from 154 to 0 per million
//! outputs; checking the path on the way, which bends as each joint brakes on its own, keeps a
//! policy's targets near the floor from ending in a stop). If any of it fails, the filter
//! brakes every joint as hard as allowed instead, and if even that fails it refuses with
//! [`Fault::WorkspaceExit`], naming the part (the caller stops the arm) rather than send it.

use super::{Fault, SafetyConfig};
use crate::error::{DeployError, Result};
use crate::kinematics::{ArmKinematics, PartOutside};
use fairgrasp_env::arm::JointRamp;

/// Floating-point slack in the checks (deg, mm).
const EPS: f64 = 1e-9;
/// Points of the braking path checked per set point besides its first and last. Braking from
/// full speed takes 0.25 s over the speed scale (128 periods at 0.25): every point up to
/// scale 0.03. Each set point the filter sends then has its whole braking path in the box, so
/// braking from it can never leave; with 16 points, 4 of 200 deployment-matched episodes at
/// scale 0.25 still met a workspace stop. About 2 ms of kinematics per control step there.
const BRAKING_SAMPLES: usize = 1024;

/// No part of the arm lies farther than this from any joint axis (mm): the FR5's links from
/// base to flange and the gripper to its fingertips add up to 1.45 m. A joint turn of θ rad
/// moves no point more than θ × this.
const ARM_REACH_MM: f64 = 1500.0;
/// How far any part of the arm moves between two points of a move checked by
/// [`SafetyFilter::check_path`] (mm), at most.
pub const PATH_STEP_MM: f64 = 1.0;

/// The safety layer's motion filter (see [`crate::safety`]; its design is described at the top
/// of `src/safety/filter.rs`).
pub struct SafetyFilter {
    ramp: JointRamp,
    lower: [f64; 6],
    upper: [f64; 6],
    box_min: [f64; 3],
    box_max: [f64; 3],
    /// The table's height and the lowest any part of the arm may reach: table +
    /// `arm_clearance_mm` (mm).
    table_z: f64,
    floor_z: f64,
    cell_min: [f64; 3],
    cell_max: [f64; 3],
    arm: ArmKinematics,
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
        arm: ArmKinematics,
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
            table_z,
            floor_z: table_z + config.arm_clearance_mm,
            cell_min: config.cell_min_mm,
            cell_max: config.cell_max_mm,
            arm,
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

    /// The controller's global speed override (`SetSpeed`, %) that caps the arm at this
    /// filter's speed: the speed cap's share of the FR5's top joint speed, rounded up.
    pub fn speed_override_percent(&self) -> u8 {
        let (speed, _, _) = self.caps();
        (100.0 * speed / crate::fairino::fr5::MOVE_J_FULL_SPEED_DEG_S)
            .ceil()
            .clamp(1.0, 100.0) as u8
    }

    /// The TCP box enforced (mm), with the table's height folded into its floor.
    pub fn workspace(&self) -> ([f64; 3], [f64; 3]) {
        (self.box_min, self.box_max)
    }

    /// The last set point sent (deg), and its velocity (deg/s).
    pub fn last(&self) -> Option<([f64; 6], [f64; 6])> {
        self.ramp.last().map(|(p, v)| (six(p), six(v)))
    }

    /// The lowest any part of the arm may reach (mm), and the cell's box (mm).
    pub fn arm_bounds(&self) -> (f64, [f64; 3], [f64; 3]) {
        (self.floor_z, self.cell_min, self.cell_max)
    }

    /// The TCP (mm) for joint angles (deg), when it lies inside the box.
    pub fn tcp_in_box(&self, joints: &[f64; 6]) -> Option<[f64; 3]> {
        let tcp = self.arm.tcp_mm(joints)?;
        (0..3)
            .all(|k| tcp[k] >= self.box_min[k] - EPS && tcp[k] <= self.box_max[k] + EPS)
            .then_some(tcp)
    }

    /// The first part of the arm below the table's clearance or outside the cell's box at
    /// joint angles (deg), or `None` when the whole arm is clear.
    pub fn part_outside(&self, joints: &[f64; 6]) -> Option<PartOutside> {
        self.part_below(joints, self.floor_z)
    }

    /// [`Self::part_outside`] with the floor at `floor` (mm).
    fn part_below(&self, joints: &[f64; 6], floor: f64) -> Option<PartOutside> {
        let (lo, hi) = (self.cell_min, self.cell_max);
        self.arm.first_part_outside(joints, |c, r| {
            c[2] - r >= floor - EPS
                && (0..3).all(|k| c[k] - r >= lo[k] - EPS && c[k] + r <= hi[k] + EPS)
        })
    }

    /// The lowest point of the arm's parts at `joints` (deg), mm.
    fn lowest_part(&self, joints: &[f64; 6]) -> f64 {
        let mut low = f64::INFINITY;
        self.arm.first_part_outside(joints, |c, r| {
            low = low.min(c[2] - r);
            true
        });
        low
    }

    /// Why the arm may not be at `joints` (deg): the TCP outside the workspace box or a part
    /// outside the table's clearance or the cell, or `None` when it may.
    pub fn where_outside(&self, joints: &[f64; 6]) -> Option<PartOutside> {
        if self.tcp_in_box(joints).is_none() {
            let at_mm = self.arm.tcp_mm(joints).unwrap_or([f64::NAN; 3]);
            return Some(PartOutside {
                part: "TCP".into(),
                at_mm,
            });
        }
        self.part_outside(joints)
    }

    /// Whether the arm may be at `joints` (deg): see [`Self::where_outside`].
    fn clear(&self, joints: &[f64; 6]) -> bool {
        self.tcp_in_box(joints).is_some() && self.part_outside(joints).is_none()
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
        if let Some(outside) = self.where_outside(measured) {
            return Err(Fault::UnsafeStart(format!(
                "{}; move the arm clear with the teach pendant",
                self.describe(&outside)
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
        if !self.clear(&step)
            || !self.clear(&stop_point)
            || braking.iter().any(|q| !self.clear(&six(q)))
        {
            step = six(&self.ramp.propose_brake().expect("started"));
            if let Some(outside) = self.where_outside(&step) {
                self.ramp.stop();
                return Err(Fault::WorkspaceExit {
                    part: outside.part.clone(),
                    at_mm: outside.at_mm,
                    limit: self.describe(&outside),
                });
            }
        }
        self.ramp.commit(step.to_vec());
        Ok(step)
    }

    /// The next set point braking every joint as hard as allowed, or `None` once the ramp is at
    /// rest (or was never started). Every set point sent had its braking path checked, so
    /// braking from it stays inside everything the filter keeps.
    pub fn brake(&mut self) -> Option<[f64; 6]> {
        let (_, velocity) = self.ramp.last()?;
        if velocity.iter().all(|v| *v == 0.0) {
            return None;
        }
        let step = self.ramp.propose_brake()?;
        self.ramp.commit(step.clone());
        Some(six(&step))
    }

    /// Checks a point-to-point move (MoveJ: every joint in step along the straight joint-space
    /// line) from `from` to `to` (deg): every point of it inside the soft limits, the TCP in
    /// the box and the whole arm clear of the table and inside the cell. Points are checked so
    /// densely that nothing of the arm moves more than `PATH_STEP_MM` (1 mm) between two of them.
    ///
    /// `from` is a measured pose: the drives lag their set points, so an arm stopped just past
    /// a soft limit, the box or the table's clearance may move home through limits grown to
    /// include where it is (never the cell, never past what it already reaches).
    pub fn check_path(&self, from: &[f64; 6], to: &[f64; 6]) -> std::result::Result<(), Fault> {
        let turn: f64 = (0..6).map(|i| (to[i] - from[i]).abs()).sum();
        if !turn.is_finite() {
            return Err(Fault::UnsafeStart(format!(
                "a move from {from:.1?} to {to:.1?} deg is not finite"
            )));
        }
        let (lower, upper): ([f64; 6], [f64; 6]) = (
            std::array::from_fn(|i| self.lower[i].min(from[i])),
            std::array::from_fn(|i| self.upper[i].max(from[i])),
        );
        let tcp_from = self.arm.tcp_mm(from).unwrap_or(self.box_min);
        let (box_min, box_max): ([f64; 3], [f64; 3]) = (
            std::array::from_fn(|k| self.box_min[k].min(tcp_from[k])),
            std::array::from_fn(|k| self.box_max[k].max(tcp_from[k])),
        );
        let floor = self.floor_z.min(self.lowest_part(from));
        let n = (turn.to_radians() * ARM_REACH_MM / PATH_STEP_MM)
            .ceil()
            .max(1.0) as usize;
        for k in 0..=n {
            let s = k as f64 / n as f64;
            let q: [f64; 6] = std::array::from_fn(|i| from[i] + (to[i] - from[i]) * s);
            if let Some(i) = (0..6).find(|&i| q[i] < lower[i] - EPS || q[i] > upper[i] + EPS) {
                return Err(Fault::UnsafeStart(format!(
                    "the move to {to:.1?} deg takes joint {} to {:.2} deg, outside its soft \
                     limits [{:.2}, {:.2}] deg (with the margin)",
                    i + 1,
                    q[i],
                    self.lower[i],
                    self.upper[i]
                )));
            }
            let tcp = self.arm.tcp_mm(&q);
            let tcp_outside = !tcp.is_some_and(|p| {
                (0..3).all(|k| p[k] >= box_min[k] - EPS && p[k] <= box_max[k] + EPS)
            });
            let outside = if tcp_outside {
                Some(PartOutside {
                    part: "TCP".into(),
                    at_mm: tcp.unwrap_or([f64::NAN; 3]),
                })
            } else {
                self.part_below(&q, floor)
            };
            if let Some(outside) = outside {
                return Err(Fault::UnsafeStart(format!(
                    "the move to {to:.1?} deg would pass where {} ({:.0} % of the way); move \
                     the arm with the teach pendant or change the home pose",
                    self.describe(&outside),
                    100.0 * s
                )));
            }
        }
        Ok(())
    }

    /// What a part outside breaks, in words.
    fn describe(&self, outside: &PartOutside) -> String {
        let [x, y, z] = outside.at_mm;
        if outside.part == "TCP" {
            format!(
                "the TCP at ({x:.0}, {y:.0}, {z:.0}) mm is outside the workspace box \
                 {:?}–{:?} mm",
                self.box_min, self.box_max
            )
        } else {
            format!(
                "the {} (around ({x:.0}, {y:.0}, {z:.0}) mm) comes within {:.0} mm of the table \
                 (at {:.0} mm) or leaves the cell {:?}–{:?} mm",
                outside.part,
                self.floor_z - self.table_z,
                self.table_z,
                self.cell_min,
                self.cell_max
            )
        }
    }
}
