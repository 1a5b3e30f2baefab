//! The grasp scene: an arm with a gripper on a table, objects to pick and bins to put them in.
//!
//! [`Scene`] owns the rapier world and offers what PyBullet users reach for: stepping at a fixed
//! physics rate, a control period of k physics steps, joint position and torque control, joint and
//! link state, object state, finger opening, pad contacts and inverse kinematics. Resets restore a
//! snapshot of the world taken at construction, so they cost microseconds, not a reload.
//!
//! - `config.rs`: the settings and their validation;
//! - `objects.rs`: object shapes, objects and bins in the world, their queries, placement checks;
//! - this file: the world, stepping, snapshots, arm, gripper, kinematics and reset.
//!
//! Objects are addressed by their index in `config.objects`, bins by theirs in `config.bins`.
//! Tasks own placement: [`Scene::restore_home`], then [`Scene::set_object_params`] and
//! [`Scene::set_object_pose`] (checked with [`Scene::pose_is_free`] and
//! [`Scene::reachable_from_above`]), then [`Scene::settle`]. [`Scene::reset`] does all of it with
//! a random layout.

mod collision_sensor;
mod config;
mod objects;

pub use config::{
    ArmConfig, ArmDrive, BinConfig, GripperConfig, MAX_GRASP_WIDTH, MAX_OBJECTS, MountConfig,
    ObjectConfig, ObjectShape, PhysicsConfig, PlacementConfig, SceneConfig, TableConfig,
};

use crate::error::{Result, SimError};
use crate::kinematics::SerialChain;
use crate::math::yaw_of;
use crate::model::{Origin, RobotModel};
use crate::robot::{JointDrive, JointSets, PdGains, Robot, RobotBuildOptions, groups};
use crate::{assets, model::LoadOptions};
pub use collision_sensor::CollisionSensor;
use objects::{MeshCache, ObjectHandles};
pub use objects::{PlacedShape, RobotContact, ShapeOwner};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rapier3d::na::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;
use std::collections::HashMap;
use std::sync::Arc;

/// The parts of the rapier world that change while stepping; cloned for snapshots.
#[derive(Clone)]
struct WorldState {
    islands: IslandManager,
    broad_phase: DefaultBroadPhase,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    ccd: CCDSolver,
}

impl WorldState {
    fn joint_sets(&mut self) -> JointSets<'_> {
        JointSets {
            multibody_joints: &mut self.multibody_joints,
            impulse_joints: &mut self.impulse_joints,
        }
    }
}

/// A saved state of the scene, restored by [`Scene::restore`].
#[derive(Clone)]
pub struct Snapshot {
    world: WorldState,
    robot: Robot,
    layout: Arc<Layout>,
    time: f64,
}

/// What tasks change per episode outside the physics world: the object settings in force
/// (shape, mass, friction) and the bin centres. Shared between the scene and its snapshots
/// (copied on write), so restores stay a pointer copy.
#[derive(Clone)]
struct Layout {
    objects: Vec<ObjectConfig>,
    bins: Vec<BinConfig>,
}

/// Arm parameters that domain randomisation varies per episode (see [`Scene::reset_with`]);
/// objects change through [`Scene::set_object_params`].
#[derive(Clone, Debug, PartialEq)]
pub struct PhysicalParams {
    /// Viscous damping of each arm joint (N·m·s/rad); `None` keeps the URDF values.
    pub arm_damping: Option<Vec<f32>>,
    /// Factor on the arm's PD gains (actuator strength).
    pub gain_scale: f32,
}

impl Default for PhysicalParams {
    /// The configured arm: URDF damping, gains unscaled.
    fn default() -> Self {
        Self {
            arm_damping: None,
            gain_scale: 1.0,
        }
    }
}

/// The pose and velocity of a rigid object.
#[derive(Clone, Copy, Debug)]
pub struct ObjectState {
    /// Pose of the object's body in the world frame (m, unit quaternion).
    pub pose: Isometry3<f64>,
    /// Linear velocity of its centre of mass in the world frame (m/s).
    pub linvel: [f64; 3],
    /// Angular velocity in the world frame (rad/s).
    pub angvel: [f64; 3],
}

/// The grasp scene.
pub struct Scene {
    config: SceneConfig,
    pipeline: PhysicsPipeline,
    params: IntegrationParameters,
    gravity: Vector,
    world: WorldState,
    soft_bodies: SoftBodySet,
    robot: Robot,
    /// Robot joint indices of the six (or n) arm joints, base to flange.
    arm: Vec<usize>,
    /// Robot joint index of the finger drive.
    finger: usize,
    finger_bodies: [RigidBodyHandle; 2],
    chain: SerialChain,
    base: Isometry3<f64>,
    table_collider: ColliderHandle,
    /// In config order.
    objects: Vec<ObjectHandles>,
    bin_bodies: Vec<RigidBodyHandle>,
    layout: Arc<Layout>,
    meshes: MeshCache,
    table_top: f32,
    home: Snapshot,
    /// TCP pose at the home joint vector.
    home_tcp: Isometry3<f64>,
    time: f64,
}

const TCP_LINK: &str = "tcp";

impl Scene {
    /// Builds the scene: arm + gripper + table + bins, arm at home, objects parked (see
    /// [`Self::park_objects`]) until a reset places them.
    pub fn new(config: SceneConfig) -> Result<Self> {
        config.validate()?;
        let mut arm_model = match &config.arm.urdf {
            Some(path) => {
                let options = LoadOptions {
                    packages: crate::model::PackagePaths::from_env()
                        .with_first(config.arm.package_paths.clone()),
                };
                RobotModel::load(path, &options)?
            }
            None => assets::fr5()?,
        };
        let gripper = assets::parallel_gripper()?;
        let mount = &config.arm.gripper_mount;
        arm_model.attach(
            &config.arm.flange_link,
            gripper,
            Origin {
                xyz: mount.xyz.map(f64::from),
                rpy: mount.rpy.map(f64::from),
            },
            "gripper_mount",
        )?;

        let mut world = WorldState {
            islands: IslandManager::new(),
            broad_phase: DefaultBroadPhase::default(),
            narrow_phase: NarrowPhase::new(),
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            ccd: CCDSolver::new(),
        };

        let [bx, by, bz] = config.arm.base_xyz.map(f64::from);
        let base = Isometry3::from_parts(
            Translation3::new(bx, by, bz),
            UnitQuaternion::from_euler_angles(0.0, 0.0, config.arm.base_yaw as f64),
        );
        let link_friction: HashMap<String, f32> = ["left_finger", "right_finger"]
            .into_iter()
            .map(|l| (l.to_string(), config.gripper.pad_friction))
            .collect();
        let build = RobotBuildOptions {
            base_pose: base,
            self_collision: config.arm.self_collision,
            mesh_collision: config.arm.mesh_collision,
            friction: 0.8,
            link_friction,
            armature: config.arm.armature,
            drive: match config.arm.drive {
                ArmDrive::Pd => JointDrive::Pd,
                ArmDrive::Kinematic => JointDrive::Kinematic {
                    speed: config.arm.kinematic_speed_deg_s.to_radians(),
                    acc: config.arm.kinematic_acc_deg_s2.to_radians(),
                    lag: config.arm.kinematic_lag_s,
                    dt: config.physics.dt,
                    dynamic_joints: vec![
                        "left_finger_joint".to_string(),
                        "right_finger_joint".to_string(),
                    ],
                },
            },
        };
        let mut robot = Robot::build(
            arm_model,
            &build,
            &mut world.bodies,
            &mut world.colliders,
            JointSets {
                multibody_joints: &mut world.multibody_joints,
                impulse_joints: &mut world.impulse_joints,
            },
        )?;
        let chain = SerialChain::new(&robot.model, TCP_LINK)?;
        let arm: Vec<usize> = chain
            .joint_names
            .iter()
            .map(|n| robot.joint_index(n).expect("chain joints are robot joints"))
            .collect();
        let finger = robot
            .joint_index("left_finger_joint")
            .ok_or_else(|| SimError::Command("gripper has no left_finger_joint".into()))?;
        if config.arm.home.len() != arm.len() {
            return Err(SimError::config(
                "arm.home",
                format!(
                    "has {} values, the arm has {} joints",
                    config.arm.home.len(),
                    arm.len()
                ),
            ));
        }
        let finger_bodies = [
            robot.link_body("left_finger").expect("gripper link"),
            robot.link_body("right_finger").expect("gripper link"),
        ];
        for &j in &arm {
            robot.set_gains(
                j,
                PdGains {
                    kp: config.arm.kp,
                    kd: config.arm.kd,
                },
            )?;
        }
        robot.set_gains(
            finger,
            PdGains {
                kp: config.gripper.kp,
                kd: config.gripper.kd,
            },
        )?;
        robot.set_effort_limit(finger, config.gripper.force_limit)?;

        // Table: a fixed box whose top is at `table.height`.
        let t = &config.table;
        let thickness = 0.05;
        let table = world.bodies.insert(
            RigidBodyBuilder::fixed()
                .translation(Vector::new(
                    t.center[0],
                    t.center[1],
                    t.height - thickness / 2.0,
                ))
                .build(),
        );
        let table_collider = world.colliders.insert_with_parent(
            ColliderBuilder::cuboid(t.size[0] / 2.0, t.size[1] / 2.0, thickness / 2.0)
                .friction(t.friction)
                .collision_groups(InteractionGroups::new(
                    groups::TABLE,
                    groups::ROBOT | groups::OBJECT,
                    InteractionTestMode::And,
                ))
                .build(),
            table,
            &mut world.bodies,
        );

        let mut params = IntegrationParameters {
            dt: config.physics.dt,
            num_solver_iterations: config.physics.solver_iterations,
            num_internal_pgs_iterations: config.physics.pgs_iterations,
            ..IntegrationParameters::default()
        };
        params.contact_softness.natural_frequency = config.physics.contact_frequency;
        // Recycled contacts keep stale points while the cube sits still between the pads; the
        // stale normals let it yaw out of a grasp held for seconds. Recompute them every step.
        params.contact_recycling = false;
        params.static_contact_softness.natural_frequency = config.physics.contact_frequency * 2.0;

        let table_top = t.height;
        let gravity = Vector::new(0.0, 0.0, -config.physics.gravity);
        let mut scene = Scene {
            pipeline: PhysicsPipeline::new(),
            params,
            gravity,
            soft_bodies: SoftBodySet::new(),
            home: Snapshot {
                world: world.clone(),
                robot: robot.clone(),
                layout: Arc::new(Layout {
                    objects: Vec::new(),
                    bins: Vec::new(),
                }),
                time: 0.0,
            },
            world,
            robot,
            arm,
            finger,
            finger_bodies,
            chain,
            base,
            table_collider,
            objects: Vec::new(),
            bin_bodies: Vec::new(),
            layout: Arc::new(Layout {
                objects: config.objects.clone(),
                bins: config.bins.clone(),
            }),
            meshes: MeshCache::new(),
            table_top,
            home_tcp: Isometry3::identity(),
            time: 0.0,
            config,
        };
        scene.add_objects_and_bins()?;
        let home = scene.config.arm.home.clone();
        scene.set_arm_positions(&home)?;
        scene.set_gripper_opening_now(scene.max_opening())?;
        if scene.config.arm.self_collision {
            // Shapes that overlap at home overlap by design (joint housings): never collide them.
            let w = &scene.world;
            scene.robot.exclude_touching_pairs(&w.bodies, &w.colliders);
        }
        // One zero-length step registers the colliders with the broad and narrow phases.
        scene.step_physics()?;
        scene.park_objects();
        scene.time = 0.0;
        scene.home = scene.snapshot();
        scene.home_tcp = scene.tcp_pose();
        Ok(scene)
    }

    /// Builds the configured objects (disabled until placed) and bins into the world.
    fn add_objects_and_bins(&mut self) -> Result<()> {
        for (i, object) in self.config.objects.iter().enumerate() {
            let key = format!("objects[{i}]");
            if self.robot.link_body(&object.name).is_some() {
                return Err(SimError::config(
                    format!("{key}.name"),
                    format!("'{}' is the name of a robot link", object.name),
                ));
            }
            let geometry = objects::object_geometry(&object.shape, &mut self.meshes).map_err(
                |(field, problem)| {
                    SimError::config(config::subkey(&format!("{key}.shape"), &field), problem)
                },
            )?;
            let handles = objects::insert_object(&mut self.world, object, &geometry);
            self.objects.push(handles);
        }
        for (j, bin) in self.config.bins.iter().enumerate() {
            if self.robot.link_body(&bin.name).is_some() {
                return Err(SimError::config(
                    format!("bins[{j}].name"),
                    format!("'{}' is the name of a robot link", bin.name),
                ));
            }
            let pose = self.bin_body_pose(bin.center);
            let body = objects::insert_bin(&mut self.world, bin, pose, self.config.table.friction);
            self.bin_bodies.push(body);
        }
        Ok(())
    }

    /// The settings the scene was built from; the object settings and bin centres in force this
    /// episode are [`Self::object_config`] and [`Self::bins`].
    pub fn config(&self) -> &SceneConfig {
        &self.config
    }

    /// The arm and gripper as built into the world: joint table, bodies, model.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The multibody joint set (for robot state queries).
    pub fn world_multibody_joints(&self) -> &MultibodyJointSet {
        &self.world.multibody_joints
    }

    /// The physics timestep (s).
    pub fn dt(&self) -> f32 {
        self.params.dt
    }

    /// The control period: `dt × substeps` (s).
    pub fn control_period(&self) -> f32 {
        self.params.dt * self.config.physics.substeps as f32
    }

    /// Simulated time since the last reset (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Height of the table top (m).
    pub fn table_top(&self) -> f32 {
        self.table_top
    }

    /// Pose of the arm base in the world.
    pub fn base_pose(&self) -> Isometry3<f64> {
        self.base
    }

    /// Saves the current state.
    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            world: self.world.clone(),
            robot: self.robot.clone(),
            layout: self.layout.clone(),
            time: self.time,
        }
    }

    /// Restores a saved state exactly.
    pub fn restore(&mut self, snapshot: &Snapshot) {
        self.world.clone_from(&snapshot.world);
        self.robot.clone_from(&snapshot.robot);
        self.layout = Arc::clone(&snapshot.layout);
        self.time = snapshot.time;
    }

    /// Advances the physics by one timestep.
    pub fn step_physics(&mut self) -> Result<()> {
        let w = &mut self.world;
        self.robot
            .apply_joint_torques(&mut w.bodies, &w.multibody_joints);
        self.robot.drive_kinematic(&mut w.bodies, self.params.dt);
        if self.params.num_solver_iterations == 1 {
            self.robot.gate_joint_limits(&mut w.multibody_joints);
        }
        self.pipeline.step(
            self.gravity,
            &self.params,
            &mut w.islands,
            &mut w.broad_phase,
            &mut w.narrow_phase,
            &mut w.bodies,
            &mut w.colliders,
            &mut w.impulse_joints,
            &mut w.multibody_joints,
            &mut self.soft_bodies,
            &mut w.ccd,
            self.robot.self_collision_filter(),
            &(),
        );
        self.robot.clear_joint_torques(&mut w.bodies);
        self.time += self.params.dt as f64;
        Ok(())
    }

    /// Advances one control period (`substeps` physics steps) and checks the state is finite.
    pub fn step_control(&mut self) -> Result<()> {
        for _ in 0..self.config.physics.substeps {
            self.step_physics()?;
        }
        self.check_finite()
    }

    /// Errors if any body pose or velocity is NaN or infinite.
    pub fn check_finite(&self) -> Result<()> {
        for (_, body) in self.world.bodies.iter() {
            let p = body.position();
            let ok = p.translation.is_finite()
                && p.rotation.is_finite()
                && body.linvel().is_finite()
                && body.angvel().is_finite();
            if !ok {
                return Err(SimError::NonFinite(format!("at t = {:.4} s", self.time)));
            }
        }
        Ok(())
    }

    // ── Arm ────────────────────────────────────────────────────────────────

    /// Number of arm joints.
    pub fn arm_dof(&self) -> usize {
        self.arm.len()
    }

    /// Names of the arm joints, base to flange.
    pub fn arm_joint_names(&self) -> Vec<&str> {
        self.arm
            .iter()
            .map(|&j| self.robot.joints[j].name.as_str())
            .collect()
    }

    /// `(lower, upper)` limits of the arm joints.
    pub fn arm_limits(&self) -> Vec<(f32, f32)> {
        self.arm
            .iter()
            .map(|&j| self.robot.joints[j].limits)
            .collect()
    }

    /// Arm joint angles (rad).
    pub fn arm_positions(&self) -> Vec<f32> {
        let q = self
            .robot
            .joint_positions(&self.world.bodies, &self.world.multibody_joints);
        self.arm.iter().map(|&j| q[j]).collect()
    }

    /// Arm joint velocities (rad/s).
    pub fn arm_velocities(&self) -> Vec<f32> {
        let v = self
            .robot
            .joint_velocities(&self.world.bodies, &self.world.multibody_joints);
        self.arm.iter().map(|&j| v[j]).collect()
    }

    /// Current arm position targets (rad).
    pub fn arm_targets(&self) -> Vec<f32> {
        self.arm
            .iter()
            .map(|&j| self.robot.position_targets()[j])
            .collect()
    }

    fn full_vector(&self, arm_values: &[f32], finger: f32) -> Result<Vec<f32>> {
        if arm_values.len() != self.arm.len() {
            return Err(SimError::Command(format!(
                "expected {} arm joint values, got {}",
                self.arm.len(),
                arm_values.len()
            )));
        }
        let mut full = self.robot.position_targets().to_vec();
        for (&j, &v) in self.arm.iter().zip(arm_values) {
            full[j] = v;
        }
        full[self.finger] = finger;
        Ok(full)
    }

    /// Teleports the arm to `q` (rad) with zero velocity, holding it there.
    pub fn set_arm_positions(&mut self, q: &[f32]) -> Result<()> {
        let finger = self
            .robot
            .joint_positions(&self.world.bodies, &self.world.multibody_joints)[self.finger];
        let full = self.full_vector(q, finger)?;
        let w = &mut self.world;
        let sets = JointSets {
            multibody_joints: &mut w.multibody_joints,
            impulse_joints: &mut w.impulse_joints,
        };
        self.robot.set_joint_positions(&full, &mut w.bodies, sets)
    }

    /// Position control of the arm: PD targets (rad), clamped to the joint limits.
    pub fn set_arm_targets(&mut self, q: &[f32]) -> Result<()> {
        let finger = self.robot.position_targets()[self.finger];
        let full = self.full_vector(q, finger)?;
        self.robot
            .set_position_targets(&full, self.world.joint_sets())
    }

    /// Torque control of the arm (N·m, clamped to effort limits); the gripper stays position
    /// controlled... by holding its current target through its own motor.
    pub fn set_arm_torques(&mut self, tau: &[f32]) -> Result<()> {
        let mut full = vec![0.0; self.robot.joints.len()];
        if tau.len() != self.arm.len() {
            return Err(SimError::Command(format!(
                "expected {} arm torques, got {}",
                self.arm.len(),
                tau.len()
            )));
        }
        for (&j, &t) in self.arm.iter().zip(tau) {
            full[j] = t;
        }
        self.robot.set_torques(&full, self.world.joint_sets())
    }

    // ── Gripper ────────────────────────────────────────────────────────────

    /// Largest finger opening (m).
    pub fn max_opening(&self) -> f32 {
        2.0 * self.robot.joints[self.finger].limits.1
    }

    /// Distance between the finger pads (m).
    pub fn gripper_opening(&self) -> f32 {
        2.0 * self
            .robot
            .joint_positions(&self.world.bodies, &self.world.multibody_joints)[self.finger]
    }

    /// Sets the contacts' stiffness as a natural frequency (Hz), contacts with fixed bodies (the
    /// table) twice as stiff, as the scene builds them from `physics.contact_frequency`: softer
    /// contacts let the pads sink into a squeezed object. Kept until set again.
    pub fn set_contact_frequency(&mut self, hz: f32) -> Result<()> {
        if !(hz.is_finite() && hz > 0.0) {
            return Err(SimError::Command(format!(
                "contact frequency {hz} Hz must be positive"
            )));
        }
        self.params.contact_softness.natural_frequency = hz;
        self.params.static_contact_softness.natural_frequency = hz * 2.0;
        Ok(())
    }

    /// The contacts' stiffness as a natural frequency (Hz; see [`Self::set_contact_frequency`]).
    pub fn contact_frequency(&self) -> f32 {
        self.params.contact_softness.natural_frequency
    }

    /// Commands the fingers to an opening (m); they squeeze with at most the force limit.
    pub fn set_gripper_target(&mut self, opening: f32) -> Result<()> {
        if !opening.is_finite() {
            return Err(SimError::Command(format!("gripper opening is {opening}")));
        }
        let q = (opening / 2.0).clamp(0.0, self.max_opening() / 2.0);
        self.robot
            .set_position_target(self.finger, q, self.world.joint_sets())
    }

    /// Sets the largest force (N) the finger drive squeezes with, kept until set again
    /// (the scene starts with `gripper.force_limit`).
    pub fn set_gripper_force_limit(&mut self, newtons: f32) -> Result<()> {
        self.robot.set_effort_limit(self.finger, newtons)?;
        let target = self.robot.position_targets()[self.finger];
        self.robot
            .set_position_target(self.finger, target, self.world.joint_sets())
    }

    /// The largest force (N) the finger drive squeezes with.
    pub fn gripper_force_limit(&self) -> f32 {
        self.robot.joints[self.finger].effort
    }

    /// Opens fully (`true`) or closes (`false`).
    pub fn set_gripper_open(&mut self, open: bool) -> Result<()> {
        self.set_gripper_target(if open { self.max_opening() } else { 0.0 })
    }

    /// Target opening (m).
    pub fn gripper_target(&self) -> f32 {
        2.0 * self.robot.position_targets()[self.finger]
    }

    /// Whether the fingers are commanded closed (their target below half the stroke).
    pub fn gripper_commanded_closed(&self) -> bool {
        self.gripper_target() < self.max_opening() * 0.5
    }

    fn set_gripper_opening_now(&mut self, opening: f32) -> Result<()> {
        let mut q = self
            .robot
            .joint_positions(&self.world.bodies, &self.world.multibody_joints);
        let half = (opening / 2.0).clamp(0.0, self.max_opening() / 2.0);
        q[self.finger] = half;
        for (j, joint) in self.robot.joints.iter().enumerate() {
            if let Some((leader, m, o)) = joint.mimic {
                q[j] = m * q[leader] + o;
            }
        }
        let w = &mut self.world;
        let sets = JointSets {
            multibody_joints: &mut w.multibody_joints,
            impulse_joints: &mut w.impulse_joints,
        };
        self.robot.set_joint_positions(&q, &mut w.bodies, sets)
    }

    // ── Poses ──────────────────────────────────────────────────────────────

    /// World pose of any robot link (merged frames such as `tool0` and `tcp` included).
    pub fn link_pose(&self, link: &str) -> Option<Isometry3<f64>> {
        self.robot.link_pose(&self.world.bodies, link)
    }

    /// World linear and angular velocity of a robot link frame.
    pub fn link_velocity(&self, link: &str) -> Option<([f64; 3], [f64; 3])> {
        self.robot.link_velocity(&self.world.bodies, link)
    }

    /// Pose of the gripper's centre point between the pads.
    pub fn tcp_pose(&self) -> Isometry3<f64> {
        self.link_pose(TCP_LINK)
            .expect("the gripper has a tcp frame")
    }

    /// Pose of the arm flange.
    pub fn flange_pose(&self) -> Isometry3<f64> {
        self.link_pose(&self.config.arm.flange_link)
            .expect("flange link checked at build")
    }

    /// The arm parameters of the configuration, unrandomised.
    pub fn nominal_params(&self) -> PhysicalParams {
        PhysicalParams::default()
    }

    fn apply_params(&mut self, params: &PhysicalParams) -> Result<()> {
        if !(params.gain_scale.is_finite() && params.gain_scale > 0.0) {
            return Err(SimError::Command(format!(
                "gain scale {} must be positive",
                params.gain_scale
            )));
        }
        for (i, &j) in self.arm.iter().enumerate() {
            if let Some(damping) = &params.arm_damping {
                let d = *damping.get(i).ok_or_else(|| {
                    SimError::Command(format!(
                        "arm damping has {} values, the arm has {} joints",
                        damping.len(),
                        self.arm.len()
                    ))
                })?;
                self.robot
                    .set_joint_damping(j, d, &mut self.world.multibody_joints)?;
            }
            self.robot.set_gains(
                j,
                PdGains {
                    kp: self.config.arm.kp * params.gain_scale,
                    kd: self.config.arm.kd * params.gain_scale,
                },
            )?;
        }
        // Gains take effect through the motors at the next target update.
        let targets = self.robot.position_targets().to_vec();
        self.robot
            .set_position_targets(&targets, self.world.joint_sets())
    }

    // ── Kinematics ─────────────────────────────────────────────────────────

    /// TCP pose (world) at arm joint vector `q`, without touching the simulation.
    pub fn tcp_forward(&self, q: &[f32]) -> Isometry3<f64> {
        let q: Vec<f64> = q.iter().map(|&v| v as f64).collect();
        self.base * self.chain.forward(&q)
    }

    /// Arm joints that put the TCP at `target` (world), starting the search at `seed`.
    pub fn solve_ik(&self, target: &Isometry3<f64>, seed: &[f32]) -> Result<Vec<f32>> {
        let local = self.base.inverse() * target;
        let seed: Vec<f64> = seed.iter().map(|&v| v as f64).collect();
        let q = self.chain.inverse(&local, &seed, 1e-4)?;
        Ok(q.into_iter().map(|v| v as f32).collect())
    }

    /// A TCP pose pointing straight down at `position` with the fingers closing along `yaw`.
    pub fn top_down_pose(&self, position: Vector3<f64>, yaw: f64) -> Isometry3<f64> {
        // z of the tool points down (world −z); its y (finger motion axis) at angle `yaw`.
        let down = UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0);
        let rotation = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw) * down;
        Isometry3::from_parts(Translation3::from(position), rotation)
    }

    /// The TCP yaw that grasps a cube of orientation `object` across two opposite faces, chosen
    /// among the four symmetric ones as the nearest to the home TCP yaw (least wrist travel).
    /// For an object of the scene, whatever its shape, see [`Self::object_grasp_yaw`].
    pub fn grasp_yaw(&self, object: &UnitQuaternion<f64>) -> f64 {
        use std::f64::consts::{FRAC_PI_2, PI};
        let reference = yaw_of(&self.home_tcp.rotation);
        let object_yaw = yaw_of(object);
        let mut best = object_yaw;
        let mut best_gap = f64::INFINITY;
        for k in -4..=4 {
            let candidate = object_yaw + k as f64 * FRAC_PI_2;
            let gap = (candidate - reference + PI).rem_euclid(2.0 * PI) - PI;
            if gap.abs() < best_gap {
                best_gap = gap.abs();
                best = reference + gap;
            }
        }
        best
    }

    // ── Reset ──────────────────────────────────────────────────────────────

    /// Restores the home state and places every object at random (see
    /// [`Self::place_objects_at_random`]). Returns the object poses, in config order.
    pub fn reset(&mut self, seed: u64) -> Result<Vec<Isometry3<f64>>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        self.reset_with_rng(&mut rng)
    }

    /// [`Self::reset`] drawing from a caller's random stream.
    pub fn reset_with_rng(&mut self, rng: &mut impl Rng) -> Result<Vec<Isometry3<f64>>> {
        let nominal = self.nominal_params();
        self.reset_with(rng, &nominal, &[])
    }

    /// [`Self::restore_home`], then places every object at random as [`Self::reset`] does.
    pub fn reset_with(
        &mut self,
        rng: &mut impl Rng,
        params: &PhysicalParams,
        home_offset: &[f32],
    ) -> Result<Vec<Isometry3<f64>>> {
        self.restore_home(params, home_offset)?;
        self.place_objects_at_random(rng)
    }

    /// Restores the home state (arm at home, objects parked with their configured settings, bins
    /// at their configured centres, time 0), applies the arm parameters and adds `home_offset`
    /// to the home joint vector (initial joint jitter; missing values are 0). Tasks then place
    /// objects and call [`Self::settle`].
    pub fn restore_home(&mut self, params: &PhysicalParams, home_offset: &[f32]) -> Result<()> {
        // Field by field: cloning the whole home snapshot first would copy the world twice.
        self.world.clone_from(&self.home.world);
        self.robot.clone_from(&self.home.robot);
        self.layout = Arc::clone(&self.home.layout);
        self.time = self.home.time;
        self.apply_params(params)?;
        if !home_offset.is_empty() {
            let q: Vec<f32> = self
                .config
                .arm
                .home
                .iter()
                .zip(home_offset.iter().chain(std::iter::repeat(&0.0)))
                .map(|(h, o)| h + o)
                .collect();
            self.set_arm_positions(&q)?;
        }
        Ok(())
    }
}
