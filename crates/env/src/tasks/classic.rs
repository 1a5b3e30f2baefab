//! Classic-control tasks with known solutions, used to prove the learning algorithms correct on
//! problems far cheaper than grasping.
//!
//! - [`Pendulum`]: Gymnasium's `Pendulum-v1` dynamics and reward (swing up and balance).
//! - [`PointReach`]: a 2-D point mass pushed to a random goal (dense reward; easy).

use crate::core::{Env, Frame, Info, Metadata, NamedValues, RenderMode, Step};
use crate::error::{EnvError, Result};
use crate::spaces::BoxSpace;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn check_action(action: &[f32], n: usize) -> Result<()> {
    if action.len() != n {
        return Err(EnvError::Action(format!(
            "expected {n} values, got {}",
            action.len()
        )));
    }
    if action.iter().any(|v| !v.is_finite()) {
        return Err(EnvError::Action(format!("non-finite action {action:?}")));
    }
    Ok(())
}

fn angle_normalize(x: f32) -> f32 {
    (x + std::f32::consts::PI).rem_euclid(2.0 * std::f32::consts::PI) - std::f32::consts::PI
}

/// Swing a pendulum up and keep it upright with limited torque (Gymnasium `Pendulum-v1`:
/// g = 10, m = l = 1, dt = 0.05, |torque| ≤ 2, |speed| ≤ 8, 200-step episodes).
/// Reward `−(θ² + 0.1 θ̇² + 0.001 u²)`; a good policy averages about −150 per episode.
pub struct Pendulum {
    theta: f32,
    theta_dot: f32,
    steps: u32,
    rng: ChaCha8Rng,
    observation_space: BoxSpace,
    action_space: BoxSpace,
    started: bool,
}

impl Pendulum {
    /// Control steps per episode; the episode is truncated after them.
    pub const MAX_STEPS: u32 = 200;
    const MAX_SPEED: f32 = 8.0;
    const MAX_TORQUE: f32 = 2.0;
    const DT: f32 = 0.05;
    const G: f32 = 10.0;

    /// A pendulum seeded with 0; call `reset` before stepping.
    pub fn new() -> Self {
        Self {
            theta: 0.0,
            theta_dot: 0.0,
            steps: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
            observation_space: BoxSpace::new(
                vec![-1.0, -1.0, -Self::MAX_SPEED],
                vec![1.0, 1.0, Self::MAX_SPEED],
            ),
            action_space: BoxSpace::new(vec![-Self::MAX_TORQUE], vec![Self::MAX_TORQUE]),
            started: false,
        }
    }

    fn obs(&self) -> Vec<f32> {
        vec![self.theta.cos(), self.theta.sin(), self.theta_dot]
    }
}

impl Default for Pendulum {
    fn default() -> Self {
        Self::new()
    }
}

impl Env for Pendulum {
    fn metadata(&self) -> Metadata {
        Metadata {
            id: "Pendulum-v1",
            render_modes: vec![],
            render_fps: 1.0 / Self::DT,
        }
    }
    fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }
    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }
    fn render_mode(&self) -> Option<RenderMode> {
        None
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)> {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        self.theta = self
            .rng
            .random_range(-std::f32::consts::PI..std::f32::consts::PI);
        self.theta_dot = self.rng.random_range(-1.0..1.0);
        self.steps = 0;
        self.started = true;
        Ok((self.obs(), Info::default()))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step> {
        if !self.started {
            return Err(EnvError::Usage("call reset() before step()".into()));
        }
        check_action(action, 1)?;
        let u = action[0].clamp(-Self::MAX_TORQUE, Self::MAX_TORQUE);
        let th = self.theta;
        let cost = angle_normalize(th).powi(2) + 0.1 * self.theta_dot.powi(2) + 0.001 * u * u;
        let new_dot = (self.theta_dot + (3.0 * Self::G / 2.0 * th.sin() + 3.0 * u) * Self::DT)
            .clamp(-Self::MAX_SPEED, Self::MAX_SPEED);
        self.theta = th + new_dot * Self::DT;
        self.theta_dot = new_dot;
        self.steps += 1;
        let truncated = self.steps >= Self::MAX_STEPS;
        if truncated {
            self.started = false;
        }
        Ok(Step {
            obs: self.obs(),
            reward: -cost,
            terminated: false,
            truncated,
            info: Info {
                elapsed_steps: self.steps,
                ..Info::default()
            },
        })
    }

    fn render(&mut self) -> Result<Option<Frame>> {
        Ok(None)
    }
}

/// A point mass in the plane pushed by a bounded force towards a random goal.
///
/// Observation: position (2), velocity (2), goal (2). Action: force in [-1, 1]². Reward: minus
/// the distance to the goal each step; the episode succeeds (and terminates) when the mass stays
/// within 5 cm of the goal with speed below 0.1 m/s. 50-step episodes. Doing nothing averages
/// below −35 per episode, a proportional-derivative controller above −15.
pub struct PointReach {
    pos: [f32; 2],
    vel: [f32; 2],
    goal: [f32; 2],
    steps: u32,
    rng: ChaCha8Rng,
    observation_space: BoxSpace,
    action_space: BoxSpace,
    started: bool,
}

impl PointReach {
    /// Control steps per episode; the episode is truncated after them.
    pub const MAX_STEPS: u32 = 50;
    const DT: f32 = 0.1;

    /// A point mass seeded with 0; call `reset` before stepping.
    pub fn new() -> Self {
        Self {
            pos: [0.0; 2],
            vel: [0.0; 2],
            goal: [0.0; 2],
            steps: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
            // Position and velocity are clamped to ±2 by the dynamics; goals lie in ±1.
            observation_space: BoxSpace::new(vec![-2.0; 6], vec![2.0; 6]),
            action_space: BoxSpace::new(vec![-1.0; 2], vec![1.0; 2]),
            started: false,
        }
    }

    fn obs(&self) -> Vec<f32> {
        vec![
            self.pos[0],
            self.pos[1],
            self.vel[0],
            self.vel[1],
            self.goal[0],
            self.goal[1],
        ]
    }

    fn distance(&self) -> f32 {
        ((self.pos[0] - self.goal[0]).powi(2) + (self.pos[1] - self.goal[1]).powi(2)).sqrt()
    }
}

impl Default for PointReach {
    fn default() -> Self {
        Self::new()
    }
}

impl Env for PointReach {
    fn metadata(&self) -> Metadata {
        Metadata {
            id: "PointReach-v0",
            render_modes: vec![],
            render_fps: 1.0 / Self::DT,
        }
    }
    fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }
    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }
    fn render_mode(&self) -> Option<RenderMode> {
        None
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)> {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        for k in 0..2 {
            self.pos[k] = self.rng.random_range(-1.0..1.0);
            self.goal[k] = self.rng.random_range(-1.0..1.0);
        }
        self.vel = [0.0; 2];
        self.steps = 0;
        self.started = true;
        let info = Info {
            extras: NamedValues::new().with("distance", self.distance()),
            ..Info::default()
        };
        Ok((self.obs(), info))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step> {
        if !self.started {
            return Err(EnvError::Usage("call reset() before step()".into()));
        }
        check_action(action, 2)?;
        for (k, force) in action.iter().enumerate() {
            let force = force.clamp(-1.0, 1.0);
            // Damped double integrator.
            self.vel[k] =
                (self.vel[k] + (2.0 * force - 0.5 * self.vel[k]) * Self::DT).clamp(-2.0, 2.0);
            self.pos[k] = (self.pos[k] + self.vel[k] * Self::DT).clamp(-2.0, 2.0);
        }
        self.steps += 1;
        let distance = self.distance();
        let speed = (self.vel[0].powi(2) + self.vel[1].powi(2)).sqrt();
        let success = distance < 0.05 && speed < 0.1;
        let truncated = !success && self.steps >= Self::MAX_STEPS;
        if success || truncated {
            self.started = false;
        }
        Ok(Step {
            obs: self.obs(),
            reward: -distance,
            terminated: success,
            truncated,
            info: Info {
                success,
                extras: NamedValues::new().with("distance", distance),
                elapsed_steps: self.steps,
                ..Info::default()
            },
        })
    }

    fn render(&mut self) -> Result<Option<Frame>> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pendulum_follows_gymnasium_dynamics() {
        let mut env = Pendulum::new();
        env.reset(Some(0)).unwrap();
        env.theta = 1.0;
        env.theta_dot = 0.5;
        let step = env.step(&[1.5]).unwrap();
        // Hand-computed from Pendulum-v1's update rule.
        let cost = 1.0f32 + 0.1 * 0.25 + 0.001 * 2.25;
        let new_dot = 0.5 + (15.0 * 1.0f32.sin() + 4.5) * 0.05;
        let new_th = 1.0 + new_dot * 0.05;
        assert!((step.reward + cost).abs() < 1e-6);
        assert!((step.obs[2] - new_dot).abs() < 1e-6);
        assert!((step.obs[0] - new_th.cos()).abs() < 1e-6);
        assert!(env.step(&[f32::NAN]).is_err());
        for _ in 1..Pendulum::MAX_STEPS - 1 {
            assert!(!env.step(&[0.0]).unwrap().truncated);
        }
        assert!(env.step(&[0.0]).unwrap().truncated);
    }

    fn point_reach_return(seed: u64, policy: impl Fn(&PointReach) -> Vec<f32>) -> (f32, bool) {
        let mut env = PointReach::new();
        env.reset(Some(seed)).unwrap();
        let mut total = 0.0;
        loop {
            let step = env.step(&policy(&env)).unwrap();
            total += step.reward;
            if step.terminated || step.truncated {
                return (total, step.info.success);
            }
        }
    }

    #[test]
    fn point_reach_rewards_closing_in_and_succeeds_at_rest_on_the_goal() {
        // A proportional-derivative controller solves it; doing nothing does not.
        let pd = |env: &PointReach| -> Vec<f32> {
            (0..2)
                .map(|k| (2.0 * (env.goal[k] - env.pos[k]) - 1.5 * env.vel[k]).clamp(-1.0, 1.0))
                .collect()
        };
        let (mut pd_total, mut idle_total, mut successes) = (0.0, 0.0, 0);
        for seed in 0..20 {
            let (r, success) = point_reach_return(seed, pd);
            pd_total += r / 20.0;
            successes += success as u32;
            idle_total += point_reach_return(seed, |_| vec![0.0, 0.0]).0 / 20.0;
        }
        assert!(successes >= 19, "PD reached the goal {successes}/20 times");
        assert!(
            pd_total > -15.0 && idle_total < -35.0,
            "PD {pd_total}, idle {idle_total}"
        );
    }
}
