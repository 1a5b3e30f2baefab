//! Joint-space motion of the twin's controller: the point-to-point profile of `MoveJ`, the
//! set-point interpolation of a `ServoJ` stream, the braking of a stopped motion and the
//! drives' tracking of their set points. Degrees and seconds throughout.

/// Six joint values (deg, deg/s or deg/s²).
pub type Joints = [f64; 6];

/// A synchronised point-to-point move: every joint follows the same minimum-jerk (quintic)
/// time law, so the joints start and stop together with zero velocity and acceleration, and
/// the slowest joint sets the duration.
#[derive(Clone, Debug, PartialEq)]
pub struct Profile {
    /// Start joints (deg).
    pub from: Joints,
    /// Target joints (deg).
    pub to: Joints,
    /// When the move starts (s).
    pub start: f64,
    /// How long it takes (s); 0 when `from` is `to`.
    pub duration: f64,
}

/// Peak speed of the quintic law `10s³ − 15s⁴ + 6s⁵` is 1.875 × distance / duration.
const PEAK_SPEED: f64 = 1.875;
/// Peak acceleration of the same law is 10/√3 ≈ 5.7735 × distance / duration².
const PEAK_ACC: f64 = 5.773_502_691_896_258;

impl Profile {
    /// The move from `from` to `to` starting at `start`, as fast as `max_speed` and `max_acc`
    /// (per joint, positive) allow.
    pub fn new(from: Joints, to: Joints, start: f64, max_speed: &Joints, max_acc: &Joints) -> Self {
        let mut duration: f64 = 0.0;
        for j in 0..6 {
            let d = (to[j] - from[j]).abs();
            duration = duration
                .max(PEAK_SPEED * d / max_speed[j])
                .max((PEAK_ACC * d / max_acc[j]).sqrt());
        }
        Self {
            from,
            to,
            start,
            duration,
        }
    }

    /// When the move ends (s).
    pub fn end(&self) -> f64 {
        self.start + self.duration
    }

    /// The set point at time `t` (held at the ends outside the move).
    pub fn at(&self, t: f64) -> Joints {
        if self.duration <= 0.0 {
            return self.to;
        }
        let s = ((t - self.start) / self.duration).clamp(0.0, 1.0);
        let blend = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
        std::array::from_fn(|j| self.from[j] + (self.to[j] - self.from[j]) * blend)
    }
}

/// One `ServoJ` set point being reached: a straight line from where the set point was when
/// the command arrived to the new target, over `cmdT`.
#[derive(Clone, Debug, PartialEq)]
pub struct ServoStep {
    /// The set point when the command arrived (deg).
    pub from: Joints,
    /// The command's target (deg).
    pub to: Joints,
    /// When the command arrived (s).
    pub start: f64,
    /// Its cmdT (s).
    pub duration: f64,
}

impl ServoStep {
    /// The set point at time `t` (held at the ends outside the step).
    pub fn at(&self, t: f64) -> Joints {
        let s = if self.duration > 0.0 {
            ((t - self.start) / self.duration).clamp(0.0, 1.0)
        } else {
            1.0
        };
        std::array::from_fn(|j| self.from[j] + (self.to[j] - self.from[j]) * s)
    }

    /// Whether the target is reached at time `t`.
    pub fn finished(&self, t: f64) -> bool {
        t >= self.start + self.duration
    }
}

/// A stopped motion's set point braking to rest: every joint decelerates uniformly from its
/// speed, all reaching zero together (so the set point stays on the line it was moving along).
#[derive(Clone, Debug, PartialEq)]
pub struct Brake {
    /// The set point when braking began (deg).
    pub from: Joints,
    /// Each joint's speed then (deg/s).
    pub speed: Joints,
    /// When braking began (s).
    pub start: f64,
    /// Time to rest (s): the fastest joint's speed over the deceleration.
    pub duration: f64,
}

impl Brake {
    /// Braking from `from` at speed `speed`, the fastest joint at `decel`; `None` when
    /// already at rest.
    pub fn new(from: Joints, speed: Joints, start: f64, decel: f64) -> Option<Self> {
        let fastest = speed.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let duration = fastest / decel;
        (duration > 1e-9 && duration.is_finite()).then_some(Self {
            from,
            speed,
            start,
            duration,
        })
    }

    /// The set point at time `t` (at rest after the brake ends).
    pub fn at(&self, t: f64) -> Joints {
        let s = (t - self.start).clamp(0.0, self.duration);
        let k = s - s * s / (2.0 * self.duration);
        std::array::from_fn(|j| self.from[j] + self.speed[j] * k)
    }

    /// Where the set point comes to rest.
    pub fn end_point(&self) -> Joints {
        self.at(self.start + self.duration)
    }

    /// Whether the set point is at rest at time `t`.
    pub fn finished(&self, t: f64) -> bool {
        t >= self.start + self.duration
    }
}

/// The drives between the controller's set point and the joints.
pub type Drives = fairgrasp_sim::control::DriveFilter<6>;

/// `next` moved towards no further from `previous` than `max_speed × dt` on each joint: the
/// controller's own joint speed limit on streamed set points.
pub fn rate_limited(previous: &Joints, next: &Joints, max_speed: &Joints, dt: f64) -> Joints {
    std::array::from_fn(|j| {
        let step = max_speed[j] * dt.max(0.0);
        next[j].clamp(previous[j] - step, previous[j] + step)
    })
}

/// The largest absolute difference between two joint vectors.
pub fn max_gap(a: &Joints, b: &Joints) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_respects_speed_and_acceleration_and_ends_on_target() {
        let (speed, acc) = ([90.0; 6], [300.0; 6]);
        let from = [0.0; 6];
        let to = [45.0, -30.0, 10.0, 0.0, 5.0, -2.0];
        let p = Profile::new(from, to, 1.0, &speed, &acc);
        assert!(
            p.duration > 0.9,
            "45° at ≤90°/s takes ≥0.94 s: {}",
            p.duration
        );
        assert_eq!(p.at(0.0), from);
        assert_eq!(p.at(p.end() + 1.0), to);
        let dt = 1e-3;
        let mut t = p.start;
        let mut previous_speed = [0.0; 6];
        while t < p.end() {
            let (a, b) = (p.at(t), p.at(t + dt));
            for j in 0..6 {
                let v = (b[j] - a[j]) / dt;
                assert!(v.abs() <= speed[j] * 1.01, "joint {j} at {v} deg/s");
                let accel = (v - previous_speed[j]) / dt;
                assert!(accel.abs() <= acc[j] * 1.05, "joint {j} at {accel} deg/s²");
                previous_speed[j] = v;
            }
            t += dt;
        }
    }

    #[test]
    fn servo_step_interpolates_and_rate_limit_caps() {
        let step = ServoStep {
            from: [0.0; 6],
            to: [1.0; 6],
            start: 0.0,
            duration: 0.008,
        };
        assert_eq!(step.at(0.004)[0], 0.5);
        assert!(step.finished(0.008) && !step.finished(0.007));
        let capped = rate_limited(&[0.0; 6], &[10.0; 6], &[100.0; 6], 0.01);
        assert_eq!(capped, [1.0; 6]);
        assert_eq!(max_gap(&capped, &[0.0, 0.0, 0.0, 0.0, 0.0, 3.0]), 2.0);
    }
}
