//! What a cobot's collision detection feels, for the twin's controller and for training alike:
//! the net force that everything outside the robot (the table, objects, bin parts) exerts on
//! the arm and the gripper, averaged over [`CollisionSensor::WINDOW`] physics steps. A
//! gripper's squeeze on what it holds is internal to the gripper: the pads' forces cancel, as
//! they do for the arm's joint torques, and only the held object's weight remains. A link or a
//! fingertip pressing on the table, or on an object resting there, counts in full.

use super::Scene;
use rapier3d::na::Vector3;
use std::collections::VecDeque;

/// The sensor: the last few physics steps' net external force on the robot.
#[derive(Clone, Debug, Default)]
pub struct CollisionSensor {
    /// Each step's net force (N) and the link that pressed hardest in it, if any.
    window: VecDeque<(Vector3<f32>, Option<String>)>,
}

impl CollisionSensor {
    /// Physics steps the force is averaged over (one step's solver impulse alone can spike).
    pub const WINDOW: usize = 4;

    /// A sensor that has read no step yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets every step read (a new episode).
    pub fn clear(&mut self) {
        self.window.clear();
    }

    /// Adds the last physics step of `scene`.
    pub fn read(&mut self, scene: &Scene) {
        let mut net = Vector3::zeros();
        let mut hardest: (f32, Option<String>) = (0.0, None);
        for c in scene.robot_contacts() {
            net += c.force;
            let n = c.force.norm();
            if n > hardest.0 {
                hardest = (n, Some(c.link));
            }
        }
        if self.window.len() == Self::WINDOW {
            self.window.pop_front();
        }
        self.window.push_back((net, hardest.1));
    }

    /// The net external force on the robot (N), averaged over the steps read (at most
    /// [`Self::WINDOW`]).
    pub fn force(&self) -> f32 {
        if self.window.is_empty() {
            return 0.0;
        }
        let sum: Vector3<f32> = self.window.iter().map(|(f, _)| f).sum();
        sum.norm() / self.window.len() as f32
    }

    /// The link that pressed hardest most recently within the window.
    pub fn hardest_link(&self) -> Option<&str> {
        self.window.iter().rev().find_map(|(_, l)| l.as_deref())
    }
}
