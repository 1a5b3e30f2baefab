//! The twin's physical world: an arm task's scene (the FR5, its gripper, the table, the
//! objects) and the task's own judge of each episode.
//!
//! The world is what the env registry offers for the task ([`ArmWorld`]): its *nominal* scene,
//! with no domain randomisation (the real world does not change between episodes), the
//! configured object mass and friction; random object shapes are drawn when the environment's
//! `[shapes]` section enables them. Episodes are judged by the task's own evaluation on
//! [`ArmState::from_scene`], once per control period, as in training: success and failure (an
//! object off the table) latch until the next reset.
//!
//! Two things are read or set here for the controller:
//! - **Contact force** (what the controller's collision detection feels): the simulator's
//!   [`CollisionSensor`], the net force that everything outside the robot exerts on it averaged
//!   over [`CONTACT_WINDOW`] physics steps — what training's `collision_force_limit` watches
//!   too. The joint reported with it is the arm joint (1–6) that carries the link pressing
//!   hardest.
//! - **Gripper force**: `MoveGripper`'s force % sets the finger drive's force limit, scaled so
//!   that [`NOMINAL_FORCE_PERCENT`] is the scene's own `gripper.force_limit` (the force training
//!   used).

use super::controller::{Measured, Setpoint};
pub use super::gripper::NOMINAL_FORCE_PERCENT;
use crate::error::{DeployError, Result};
use fairgrasp_env::arm::{ArmState, ArmWorld};
use fairgrasp_env::registry;
use fairgrasp_sim::control::DriveIntegral;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::rapier3d::na::Isometry3;
use fairgrasp_sim::scene::{CollisionSensor, Scene};
use serde::Serialize;

/// How one episode went, by the task's rule.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EpisodeResult {
    /// 1 for the first episode, counting every reset.
    pub number: u64,
    /// The seed its objects were placed from.
    pub seed: u64,
    /// The task's success rule held at some control step.
    pub success: bool,
    /// The task failed for good (an object left the table).
    pub failed: bool,
    /// Highest lift of object 0 above its resting height (m).
    pub max_lift: f64,
    /// Control steps judged.
    pub steps: u32,
    /// The control step at which success was first found.
    pub success_step: Option<u32>,
    /// Object 0 is held right now (both pads on it, gripper closing).
    pub grasped: bool,
}

/// Physics steps the contact force is averaged over (one step's solver impulse alone can spike).
pub const CONTACT_WINDOW: usize = CollisionSensor::WINDOW;

/// The scene, the task, and the judged episode.
///
/// The joints follow the controller's set points through the drives' integral action
/// ([`DriveIntegral`]), so they come to rest where the controller commands them.
pub struct World {
    env_id: String,
    inner: Box<dyn ArmWorld>,
    chain: SerialChain,
    substeps: u32,
    physics_steps: u64,
    episode: EpisodeResult,
    integral: DriveIntegral<6>,
    /// The arm joint (1–6; 0 for the base) that carries each robot link.
    link_joint: std::collections::HashMap<String, i32>,
    /// The net external force on the robot in the last physics steps (N, world frame), newest
    /// last, with the joint carrying the link pressing hardest.
    contacts: CollisionSensor,
    /// The force % the finger drive squeezes with now.
    gripper_force_percent: f64,
}

impl World {
    /// Builds `env_id` (one of the registry's arm tasks) from its configuration table and
    /// starts episode 1 from `seed`.
    pub fn new(env_id: &str, table: &toml::Table, seed: u64) -> Result<Self> {
        let offer = registry::arm_offer(env_id).ok_or_else(|| {
            DeployError::config(
                "--env",
                format!(
                    "the twin stages the arm tasks ({}), not `{env_id}`",
                    registry::arm_ids().join(", ")
                ),
            )
        })?;
        let inner = (offer.world)(table)?;
        let scene = inner.scene();
        let chain = SerialChain::new(&scene.robot().model, "tcp")
            .map_err(|e| DeployError::Env(e.into()))?;
        let substeps = scene.config().physics.substeps;
        let model = &scene.robot().model;
        let arm = scene.arm_joint_names();
        let link_joint = (0..model.links.len())
            .map(|l| {
                let mut link = l;
                let mut joint = 0;
                while let Some(j) = model.parent_joint(link) {
                    if let Some(k) = arm.iter().position(|&n| n == model.joints[j].name) {
                        joint = k as i32 + 1;
                        break;
                    }
                    link = model.joints[j].parent;
                }
                (model.links[l].name.clone(), joint)
            })
            .collect();
        let mut world = Self {
            env_id: env_id.to_string(),
            inner,
            chain,
            substeps,
            physics_steps: 0,
            episode: EpisodeResult::default(),
            integral: DriveIntegral::new(),
            link_joint,
            contacts: CollisionSensor::new(),
            gripper_force_percent: NOMINAL_FORCE_PERCENT,
        };
        world.start_episode(seed)?;
        Ok(world)
    }

    /// The arm task staged.
    pub fn env_id(&self) -> &str {
        &self.env_id
    }

    /// The simulated scene (arm, gripper, table, objects).
    pub fn scene(&self) -> &Scene {
        self.inner.scene()
    }

    /// The kinematic chain from the arm base to the TCP (the gripper's centre point).
    pub fn chain(&self) -> &SerialChain {
        &self.chain
    }

    /// The physics timestep (s).
    pub fn dt(&self) -> f64 {
        self.scene().dt() as f64
    }

    /// The arm's home joint angles (deg).
    pub fn home_deg(&self) -> [f64; 6] {
        let home = &self.scene().config().arm.home;
        std::array::from_fn(|j| home.get(j).copied().unwrap_or(0.0) as f64).map(f64::to_degrees)
    }

    /// Joint limits (rad).
    pub fn limits(&self) -> Vec<(f64, f64)> {
        self.chain.limits.clone()
    }

    /// Resets the scene (arm home, gripper open, objects placed from `seed`) and starts the next
    /// judged episode.
    pub fn start_episode(&mut self, seed: u64) -> Result<()> {
        self.inner.start_episode(seed)?;
        self.integral = DriveIntegral::new();
        self.contacts.clear();
        self.episode = EpisodeResult {
            number: self.episode.number + 1,
            seed,
            ..EpisodeResult::default()
        };
        Ok(())
    }

    /// Puts the arm at rest at `joints_deg` with its targets there (the drives' integral
    /// action forgotten), the gripper untouched: a replay's start.
    pub fn place_arm(&mut self, joints_deg: &[f64; 6]) -> Result<()> {
        let q: Vec<f32> = joints_deg.iter().map(|v| v.to_radians() as f32).collect();
        let scene = self.inner.scene_mut();
        let sim = |e| DeployError::Env(fairgrasp_env::EnvError::from(e));
        scene.set_arm_positions(&q).map_err(sim)?;
        scene.set_arm_targets(&q).map_err(sim)?;
        self.integral = DriveIntegral::new();
        Ok(())
    }

    /// The episode so far.
    pub fn episode(&self) -> &EpisodeResult {
        &self.episode
    }

    /// Applies the set points and advances one physics step; every `substeps` steps the task
    /// judges the state.
    pub fn step(&mut self, setpoint: &Setpoint) -> Result<()> {
        let dt = self.dt();
        let sp = setpoint.joints_deg.map(f64::to_radians);
        let scene = self.inner.scene_mut();
        let sim = |e| DeployError::Env(fairgrasp_env::EnvError::from(e));
        let q = self.integral.drive(sp).map(|v| v as f32);
        scene.set_arm_targets(&q).map_err(sim)?;
        if setpoint.gripper_force_percent != self.gripper_force_percent {
            let nominal = scene.config().gripper.force_limit as f64;
            // A drive with no force at all would not move; 1 % is the least it is given.
            let share = setpoint.gripper_force_percent.max(1.0) / NOMINAL_FORCE_PERCENT;
            scene
                .set_gripper_force_limit((nominal * share) as f32)
                .map_err(sim)?;
            self.gripper_force_percent = setpoint.gripper_force_percent;
        }
        let opening = (setpoint.gripper_percent / 100.0) as f32 * scene.max_opening();
        scene.set_gripper_target(opening).map_err(sim)?;
        scene.step_physics().map_err(sim)?;
        self.physics_steps += 1;
        self.read_contacts();
        (self.integral).learn(&self.inner.scene().arm_positions(), dt);
        if self.physics_steps.is_multiple_of(self.substeps as u64) {
            self.inner.scene().check_finite().map_err(sim)?;
            self.judge();
        }
        Ok(())
    }

    /// Adds the last physics step's external force on the robot to the sensor.
    fn read_contacts(&mut self) {
        self.contacts.read(self.inner.scene());
    }

    /// The net external force on the robot (N) over the last [`CONTACT_WINDOW`] physics steps,
    /// and the arm joint (1–6) carrying the link that pressed hardest most recently.
    pub fn contact_force(&self) -> (f64, i32) {
        let joint = (self.contacts.hardest_link())
            .and_then(|link| self.link_joint.get(link).copied())
            .unwrap_or(0);
        (self.contacts.force() as f64, joint)
    }

    fn judge(&mut self) {
        let state = ArmState::from_scene(self.inner.scene());
        let evaluation = self.inner.evaluate(&state);
        let e = &mut self.episode;
        e.steps += 1;
        if evaluation.success && !e.success {
            e.success = true;
            e.success_step = Some(e.steps);
        }
        e.failed |= evaluation.failure.is_some();
        if !state.objects.is_empty() {
            e.max_lift = e.max_lift.max(state.lift(0));
            e.grasped = state.grasped(0);
        }
    }

    /// What the controller's encoders and the gripper read now.
    pub fn measure(&self) -> Measured {
        let (contact_force_n, contact_joint) = self.contact_force();
        Measured {
            contact_force_n,
            contact_joint,
            ..measure(self.scene())
        }
    }

    /// Object 0's pose in the robot base frame (m).
    pub fn object_pose(&self) -> Option<Isometry3<f64>> {
        let scene = self.scene();
        (scene.num_objects() > 0).then(|| scene.base_pose().inverse() * scene.object_state(0).pose)
    }
}

/// What a controller's encoders and gripper read of a simulated scene: joint angles and speeds
/// in degrees, the opening in percent of the stroke (the controller rounds it when reporting).
pub fn measure(scene: &Scene) -> Measured {
    let q = scene.arm_positions();
    let qd = scene.arm_velocities();
    let deg = |v: &[f32]| -> [f64; 6] {
        std::array::from_fn(|j| (v.get(j).copied().unwrap_or(0.0) as f64).to_degrees())
    };
    Measured {
        joints_deg: deg(&q),
        joint_speeds_deg: deg(&qd),
        gripper_percent: (scene.gripper_opening() / scene.max_opening()) as f64 * 100.0,
        ..Measured::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fairino::error_codes::codes;
    use crate::twin::controller::{
        Controller, ControllerConfig, StartState, pose_to_wire, wire_to_pose,
    };
    use crate::twin::motion::max_gap;

    /// The controller and the world in lockstep, in simulated time (no threads, no clock).
    struct Rig {
        world: World,
        c: Controller,
        t: f64,
    }

    impl Rig {
        fn new(seed: u64) -> Self {
            let world = World::new("FaArmGrasp-v0", &toml::Table::new(), seed).unwrap();
            let config = ControllerConfig::fr5(
                &world.limits(),
                StartState {
                    gripper_active: true,
                    ..StartState::default()
                },
            );
            let mut c = Controller::new(config, world.chain().clone(), world.home_deg(), 0.0);
            c.observe(0.0, world.measure());
            Self { world, c, t: 0.0 }
        }

        fn step(&mut self) {
            self.t += self.world.dt();
            let sp = self.c.setpoint(self.t);
            self.world.step(&sp).unwrap();
            self.c.observe(self.t, self.world.measure());
        }

        fn run(&mut self, seconds: f64) {
            let n = (seconds / self.world.dt()).round() as usize;
            for _ in 0..n {
                self.step();
            }
        }

        fn move_j(&mut self, target: [f64; 6], vel: f64) {
            let ticket = self.c.move_j(self.t, target, vel, 0.0, 100.0).unwrap();
            for _ in 0..5000 {
                if let Some(code) = self.c.outcome(ticket) {
                    assert_eq!(code, codes::OK);
                    return;
                }
                self.step();
            }
            panic!("MoveJ never ended");
        }
    }

    #[test]
    fn the_arm_holds_home_and_tracks_a_move() {
        let mut rig = Rig::new(3);
        let home = rig.world.home_deg();
        rig.run(0.5);
        let sagging = max_gap(&rig.world.measure().joints_deg, &home);
        rig.run(1.5);
        let m = rig.world.measure();
        assert!(
            max_gap(&m.joints_deg, &home) < 0.02,
            "{m:?} (sagged {sagging}°)"
        );
        assert!(
            (m.gripper_percent - 100.0).abs() < 2.0,
            "gripper open at start"
        );
        let mut target = home;
        target[0] += 20.0;
        target[2] -= 10.0;
        rig.move_j(target, 50.0);
        let m = rig.world.measure();
        assert!(max_gap(&m.joints_deg, &target) < 2.0, "arrived: {m:?}");
        let object = rig.world.object_pose().unwrap();
        assert!(object.translation.z > -0.05 && object.translation.z < 0.1);
        assert!(!rig.world.episode().success);
        assert!(
            rig.world.episode().steps > 20,
            "judged every control period"
        );
    }

    /// MoveJ above the cube, down, close the gripper, up: the task's own rule says success.
    #[test]
    fn a_scripted_grasp_through_the_controller_succeeds() {
        let mut rig = Rig::new(11);
        let object = rig.world.object_pose().unwrap();
        let tcp = pose_to_wire(
            &rig.world
                .chain()
                .forward(&rig.world.home_deg().map(f64::to_radians)),
        );
        let yaw = grasp_yaw(object.rotation.euler_angles().2.to_degrees(), tcp[5]);
        let p = object.translation.vector * 1000.0;
        let pose = |dz: f64| [p.x, p.y, p.z + dz, 180.0, 0.0, yaw];
        let above = rig.c.inverse_kin(&pose(100.0)).unwrap();
        rig.move_j(above, 60.0);
        let down = rig.c.inverse_kin(&pose(0.0)).unwrap();
        rig.move_j(down, 20.0);
        let g = rig.c.move_gripper(rig.t, 1, [0, 100, 50], 3000).unwrap();
        let mut peak = 0.0f64;
        while rig.c.gripper_moving(g) {
            rig.step();
            peak = peak.max(rig.world.contact_force().0);
        }
        let up = rig.c.inverse_kin(&pose(120.0)).unwrap();
        let (code, lift_peak) = rig.move_j_outcome(up, 30.0);
        assert_eq!(code, codes::OK);
        rig.run(0.6);
        eprintln!("contact force: closing {peak:.1} N, lifting {lift_peak:.1} N");
        assert!(
            peak.max(lift_peak) < crate::twin::faults::STRICT_COLLISION_LEVEL_N / 3.0,
            "a grasp is far from a collision: {peak} N, {lift_peak} N"
        );
        assert!(!rig.c.state().collision);
        let e = rig.world.episode();
        assert!(e.success, "{e:?}");
        assert!(e.grasped && e.max_lift > 0.05, "{e:?}");
        assert!(!e.failed);
        // The pose feed's frame: the held cube hangs at the TCP.
        let held = rig.world.object_pose().unwrap();
        let tcp_now = wire_to_pose(&rig.c.state().tcp);
        assert!((held.translation.vector - tcp_now.translation.vector).norm() < 0.03);
    }

    impl Rig {
        /// The TCP pose (wire form) above object 0, grasping it across two faces, `dz` mm
        /// above its centre, shifted `dy` mm.
        fn grasp_pose(&self, dz: f64, dy: f64) -> [f64; 6] {
            let object = self.world.object_pose().unwrap();
            let tcp = pose_to_wire(
                &self
                    .world
                    .chain()
                    .forward(&self.world.home_deg().map(f64::to_radians)),
            );
            let yaw = grasp_yaw(object.rotation.euler_angles().2.to_degrees(), tcp[5]);
            let p = object.translation.vector * 1000.0;
            [p.x, p.y + dy, p.z + dz, 180.0, 0.0, yaw]
        }

        /// Sends a MoveJ to `target` and steps until it ends; returns its outcome and the
        /// largest contact force met (N).
        fn move_j_outcome(&mut self, target: [f64; 6], vel: f64) -> (i32, f64) {
            let ticket = self.c.move_j(self.t, target, vel, 0.0, 100.0).unwrap();
            let mut peak = 0.0f64;
            for _ in 0..5000 {
                if let Some(code) = self.c.outcome(ticket) {
                    return (code, peak);
                }
                self.step();
                peak = peak.max(self.world.contact_force().0);
            }
            panic!("MoveJ never ended");
        }

        /// Steps until the arm is at rest (every joint under 1 deg/s and the controller's
        /// motion done); returns the twin time it took.
        fn until_rest(&mut self) -> f64 {
            let start = self.t;
            for _ in 0..2000 {
                let m = self.world.measure();
                let top = m
                    .joint_speeds_deg
                    .iter()
                    .fold(0.0f64, |a, v| a.max(v.abs()));
                if top < 1.0 && self.c.motion_done() {
                    return self.t - start;
                }
                self.step();
            }
            panic!("the arm never came to rest");
        }

        /// The pads' mean normal force on object 0 now (N).
        fn squeeze(&self) -> f64 {
            let pads: Vec<f64> = (self.world.scene().robot_contacts().iter())
                .filter(|c| c.finger && c.other == fairgrasp_sim::scene::ShapeOwner::Object(0))
                .map(|c| c.force.norm() as f64)
                .collect();
            pads.iter().sum::<f64>() / 2.0
        }
    }

    /// Above a free spot of the table, then down through it: the fingertips press on the table
    /// and the controller stops the arm with a collision. Returns the rig, the MoveJ's outcome
    /// and the largest contact force met.
    fn press_into_table(level: Option<f64>) -> (Rig, i32, f64) {
        let mut rig = Rig::new(11);
        rig.c.set_collision_level(level);
        // 120 mm beside the cube, so only the table is in the way.
        let above = rig.c.inverse_kin(&rig.grasp_pose(100.0, 120.0)).unwrap();
        rig.move_j(above, 60.0);
        let into = rig.c.inverse_kin(&rig.grasp_pose(-60.0, 120.0)).unwrap();
        let (code, peak) = rig.move_j_outcome(into, 20.0);
        (rig, code, peak)
    }

    #[test]
    fn pressing_the_fingers_into_the_table_is_a_collision_and_the_arm_brakes() {
        let (mut rig, code, peak) = press_into_table(Some(150.0));
        assert_eq!(code, codes::EXECUTION_FAILED, "the move is stopped");
        let s = rig.c.state();
        assert!(s.collision, "collision_state set (peak {peak:.0} N)");
        assert_eq!(s.main_code, crate::twin::controller::MAIN_CODE_COLLISION);
        assert!((1..=6).contains(&s.sub_code), "the joint: {}", s.sub_code);
        let settled = rig.until_rest();
        assert!(settled < 0.5, "at rest {settled:.2} s after the stop");
        // Gated until reset; the reset clears the state, and the arm still pressing does not
        // trip it again until the force has fallen below the level.
        assert_eq!(rig.c.servo_start(), codes::EXECUTION_FAILED);
        assert_eq!(rig.c.reset_errors(), codes::OK);
        rig.run(0.1);
        let s = rig.c.state();
        assert!(!s.collision && s.main_code == 0, "{s:?}");
    }

    #[test]
    fn below_the_level_or_off_nothing_is_detected() {
        let (rig, code, peak) = press_into_table(None);
        eprintln!("pressing into the table undetected: {peak:.0} N");
        let s = rig.c.state();
        assert!(!s.collision && s.main_code == 0, "off: {s:?}");
        assert_eq!(code, codes::OK, "off: the move ends");
        assert!(peak > 150.0, "the press is a real one: {peak} N");
        let (rig, code, peak_here) = press_into_table(Some(peak * 1.2));
        let s = rig.c.state();
        assert!(!s.collision && s.main_code == 0, "below the level: {s:?}");
        assert_eq!(
            code,
            codes::OK,
            "below the level: the move ends ({peak_here:.0} N)"
        );
    }

    /// Closing on the cube with `force` %: the squeeze it holds with, and the controller's
    /// report once stalled.
    fn hold_cube(force: i64) -> (f64, crate::robot::RobotState, (i32, i32)) {
        let mut rig = Rig::new(11);
        let down = rig.c.inverse_kin(&rig.grasp_pose(0.0, 0.0)).unwrap();
        let above = rig.c.inverse_kin(&rig.grasp_pose(100.0, 0.0)).unwrap();
        rig.move_j(above, 60.0);
        rig.move_j(down, 20.0);
        let g = rig.c.move_gripper(rig.t, 1, [0, 100, force], 3000).unwrap();
        while rig.c.gripper_moving(g) {
            rig.step();
        }
        rig.run(0.3);
        let n = 24;
        let mut squeeze = 0.0;
        for _ in 0..n {
            rig.step();
            squeeze += rig.squeeze() / n as f64;
        }
        (squeeze, rig.c.state(), rig.c.gripper_motion_done())
    }

    #[test]
    fn the_gripper_squeezes_with_its_force_and_reports_holding() {
        let (weak, s20, done20) = hold_cube(20);
        let (strong, s100, done100) = hold_cube(100);
        eprintln!("squeeze at 20 %: {weak:.1} N, at 100 %: {strong:.1} N");
        assert!(strong > 2.0 * weak && weak > 2.0, "{weak} N vs {strong} N");
        for (s, done, force) in [(&s20, done20, 20), (&s100, done100, 100)] {
            assert_eq!(done, (0, 1), "motion done while stalled on the cube");
            assert!(s.gripper_motion_done);
            assert!(
                s.gripper_position > 5,
                "short of closed: {}",
                s.gripper_position
            );
            assert_eq!(
                s.gripper_current, force,
                "holding draws the force's current"
            );
            assert!(!s.collision, "a grasp is not a collision");
        }
    }

    #[test]
    fn closing_on_nothing_ends_closed_and_holds_nothing() {
        let mut rig = Rig::new(11);
        let g = rig.c.move_gripper(rig.t, 1, [0, 100, 100], 3000).unwrap();
        while rig.c.gripper_moving(g) {
            rig.step();
        }
        rig.run(0.2);
        let s = rig.c.state();
        assert_eq!(rig.c.gripper_motion_done(), (0, 1));
        assert!(s.gripper_position <= 1, "closed: {}", s.gripper_position);
        assert_eq!(s.gripper_current, 0, "nothing held");
    }

    /// The top-down TCP yaw (deg) that grasps a cube of yaw `object` across two faces,
    /// nearest to `current`.
    fn grasp_yaw(object: f64, current: f64) -> f64 {
        (-4..=4)
            .map(|k| object + 90.0 * k as f64)
            .min_by(|a, b| (a - current).abs().total_cmp(&(b - current).abs()))
            .unwrap()
    }

    #[test]
    fn only_arm_tasks_are_staged() {
        let e = World::new("Pendulum-v1", &toml::Table::new(), 0)
            .err()
            .unwrap();
        assert!(e.to_string().contains("FaArmGrasp-v0"), "{e}");
        let mut bad = toml::Table::new();
        bad.insert("nonsense".into(), toml::Value::Integer(1));
        assert!(World::new("FaArmGrasp-v0", &bad, 0).is_err());
    }
}
