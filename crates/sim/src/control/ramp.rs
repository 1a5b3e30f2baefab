//! [`JointRamp`]: the joint-space motion a position-controlled industrial arm makes of streamed
//! set points, with speed and acceleration caps. One implementation serves three places: the
//! kinematic arm drive (`arm.drive = "kinematic"`) moves the simulated joints through it every
//! physics step, the environment's `[control.servo]` streams set points through it, and the
//! deployment's safety filter moves the real arm through it, so a policy meets on the robot the
//! motion it learnt on.
//!
//! Each period the ramp moves its last set point towards the target with a velocity chosen
//! inside the intersection of four windows, per joint:
//! - the speed cap `±v`;
//! - the acceleration cap: within `a·dt` of the last velocity;
//! - the joint limits *with room to brake*: from the new position, braking at `a` must stop
//!   before the limit (`p + v·dt + v²/2a ≤ upper`), so a limit is never crossed even when the
//!   target jumps past it;
//! - a profile that can stop at the target, so the arm does not overshoot it.
//!
//! The first three windows always intersect (braking at `a` from a feasible state stays
//! feasible), so the caps and limits hold by construction. Every joint moves along the straight
//! joint-space line to the target at a common rate: per-joint limits alone would let short moves
//! finish first and bend the TCP's path (on the twin at speed scale 0.25 it dipped 7 mm below
//! the table margin). Units are the caller's (degrees or radians, per second).

/// Floating-point slack in the limit checks.
const EPS: f64 = 1e-9;

/// The joint-space set-point ramp (see the module documentation at the top of
/// `control/ramp.rs`).
#[derive(Clone, Debug)]
pub struct JointRamp {
    lower: Vec<f64>,
    upper: Vec<f64>,
    speed: f64,
    acc: f64,
    dt: f64,
    last: Option<Vec<f64>>,
    velocity: Vec<f64>,
}

/// The largest speed from which braking at `acc` stops within `room` after one more period
/// of `dt` at that speed: the positive root of `v·dt + v²/(2·acc) = room`.
fn braking_speed(room: f64, acc: f64, dt: f64) -> f64 {
    if room <= 0.0 {
        return 0.0;
    }
    acc * (-dt + (dt * dt + 2.0 * room / acc).sqrt())
}

impl JointRamp {
    /// `limits`: each joint's (lower, upper); `speed`, `acc`: the caps (positive); `dt`: the
    /// period. The caller validates the numbers.
    pub fn new(limits: &[(f64, f64)], speed: f64, acc: f64, dt: f64) -> Self {
        Self {
            lower: limits.iter().map(|l| l.0).collect(),
            upper: limits.iter().map(|l| l.1).collect(),
            speed,
            acc,
            dt,
            last: None,
            velocity: vec![0.0; limits.len()],
        }
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.lower.len()
    }

    /// The joint limits (lower, upper).
    pub fn limits(&self) -> (&[f64], &[f64]) {
        (&self.lower, &self.upper)
    }

    /// Speed cap, acceleration cap and period.
    pub fn caps(&self) -> (f64, f64, f64) {
        (self.speed, self.acc, self.dt)
    }

    /// Whether `q` lies within the limits.
    pub fn within_limits(&self, q: &[f64]) -> bool {
        q.len() == self.dof()
            && q.iter().enumerate().all(|(i, &v)| {
                v.is_finite() && v >= self.lower[i] - EPS && v <= self.upper[i] + EPS
            })
    }

    /// Starts from rest at `q`.
    pub fn start(&mut self, q: &[f64]) {
        self.last = Some(q.to_vec());
        self.velocity = vec![0.0; q.len()];
    }

    /// Forgets the motion: [`next`](Self::next) needs a new [`start`](Self::start).
    pub fn stop(&mut self) {
        self.last = None;
    }

    /// The last set point and its velocity, once started.
    pub fn last(&self) -> Option<(&[f64], &[f64])> {
        self.last.as_deref().map(|p| (p, self.velocity.as_slice()))
    }

    /// The next set point towards `target` (finite, one value per joint), without taking it:
    /// see [`commit`](Self::commit). `None` before [`start`](Self::start).
    pub fn propose(&self, target: &[f64]) -> Option<Vec<f64>> {
        let last = self.last.as_ref()?;
        let (dt, acc, n) = (self.dt, self.acc, self.dof());
        let (mut low, mut high, mut error) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        // The common rate `k` that moves every joint along the straight line to the target
        // (v = k · error), each joint slow enough to stop at its goal and under the speed cap.
        let mut k = f64::INFINITY;
        for i in 0..n {
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
        for i in 0..n {
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
        Some(
            (0..n)
                .map(|i| {
                    let chosen = if s_lo <= s_hi {
                        s_hi * k * error[i]
                    } else {
                        // Out of step (a joint still braking from an earlier motion): each
                        // joint on its own, inside its window.
                        (k * error[i]).clamp(low[i], high[i])
                    };
                    let v = chosen.clamp(low[i], high[i]);
                    (last[i] + v * dt).clamp(self.lower[i], self.upper[i])
                })
                .collect(),
        )
    }

    /// The set point that brakes every joint as hard as allowed along its present motion.
    pub fn propose_brake(&self) -> Option<Vec<f64>> {
        let last = self.last.as_ref()?;
        Some(self.brake_once(last, &self.velocity).0)
    }

    /// One period of braking every joint as hard as allowed from `position` moving at
    /// `velocity`: the next position and velocity.
    fn brake_once(&self, position: &[f64], velocity: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (dt, acc) = (self.dt, self.acc);
        (0..self.dof())
            .map(|i| {
                let v = velocity[i];
                let braked = v - v.signum() * (acc * dt).min(v.abs());
                let p = (position[i] + braked * dt).clamp(self.lower[i], self.upper[i]);
                (p, braked)
            })
            .unzip()
    }

    /// The set points braking would send after `step` (reached from the last set point) until
    /// every joint stops: the first, the last, and at most `samples` evenly spaced between.
    /// Joints brake independently, so the path bends away from the straight line to
    /// [`stopping_point`](Self::stopping_point): checking only where braking ends let the TCP
    /// dip below the workspace floor on the way.
    pub fn braking_path(&self, step: &[f64], samples: usize) -> Option<Vec<Vec<f64>>> {
        let last = self.last.as_ref()?;
        let mut velocity: Vec<f64> = (step.iter().zip(last))
            .map(|(s, l)| (s - l) / self.dt)
            .collect();
        let periods = (velocity.iter())
            .map(|v| (v.abs() / (self.acc * self.dt)).ceil())
            .fold(0.0, f64::max) as usize;
        let stride = periods.div_ceil(samples.max(1)).max(1);
        let mut position = step.to_vec();
        let mut path = Vec::new();
        for k in 1..=periods {
            (position, velocity) = self.brake_once(&position, &velocity);
            if k == 1 || k % stride == 0 || k == periods {
                path.push(position.clone());
            }
        }
        Some(path)
    }

    /// Where braking at the cap from `step`, reached from the last set point, would stop.
    pub fn stopping_point(&self, step: &[f64]) -> Option<Vec<f64>> {
        let last = self.last.as_ref()?;
        Some(
            (0..self.dof())
                .map(|i| {
                    let v = (step[i] - last[i]) / self.dt;
                    (step[i] + v * v.abs() / (2.0 * self.acc)).clamp(self.lower[i], self.upper[i])
                })
                .collect(),
        )
    }

    /// Takes `step` (from [`propose`](Self::propose) or [`propose_brake`](Self::propose_brake))
    /// as the new set point.
    pub fn commit(&mut self, step: Vec<f64>) {
        if let Some(last) = &self.last {
            self.velocity = step
                .iter()
                .zip(last)
                .map(|(s, l)| (s - l) / self.dt)
                .collect();
        }
        self.last = Some(step);
    }

    /// [`propose`](Self::propose) and [`commit`](Self::commit) in one: the next set point.
    pub fn next(&mut self, target: &[f64]) -> Option<Vec<f64>> {
        let step = self.propose(target)?;
        self.commit(step.clone());
        Some(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> JointRamp {
        JointRamp::new(&[(-90.0, 90.0); 3], 100.0, 500.0, 0.01)
    }

    #[test]
    fn reaches_the_target_within_the_caps_without_overshoot() {
        let mut r = ramp();
        r.start(&[0.0, 0.0, 0.0]);
        let target = [40.0, -20.0, 10.0];
        let (mut previous, mut previous_v) = (vec![0.0; 3], vec![0.0; 3]);
        for _ in 0..200 {
            let p = r.next(&target).unwrap();
            for i in 0..3 {
                let v = (p[i] - previous[i]) / 0.01;
                assert!(v.abs() <= 100.0 + 1e-6, "speed {v}");
                assert!(
                    (v - previous_v[i]).abs() / 0.01 <= 500.0 + 1e-6,
                    "acceleration"
                );
                assert!(
                    p[i].abs() <= target[i].abs() + 1e-9,
                    "overshoot on joint {i}"
                );
                previous_v[i] = v;
            }
            previous = p;
        }
        assert!(
            (0..3).all(|i| (previous[i] - target[i]).abs() < 1e-6),
            "{previous:?}"
        );
    }

    #[test]
    fn joints_move_in_step_along_a_straight_line() {
        let mut r = ramp();
        r.start(&[0.0, 0.0, 0.0]);
        for _ in 0..20 {
            let p = r.next(&[40.0, -20.0, 10.0]).unwrap();
            assert!((p[1] + p[0] / 2.0).abs() < 1e-9 && (p[2] - p[0] / 4.0).abs() < 1e-9);
        }
    }

    #[test]
    fn never_crosses_a_limit_when_the_target_lies_beyond_it() {
        let mut r = ramp();
        r.start(&[80.0, 0.0, 0.0]);
        for _ in 0..100 {
            let p = r.next(&[500.0, 0.0, 0.0]).unwrap();
            assert!(p[0] <= 90.0 + 1e-9);
        }
        assert!(
            r.propose(&[0.0; 3]).is_some() && JointRamp::new(&[], 1.0, 1.0, 1.0).last().is_none()
        );
    }
}
