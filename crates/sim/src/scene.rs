//! The grasp scene: an arm with a gripper on a table, and a cube placed at random in front of it.
//!
//! [`Scene`] owns the rapier world and offers what PyBullet users reach for: stepping at a fixed
//! physics rate, a control period of k physics steps, joint position and torque control, joint and
//! link state, object state, finger opening, pad contacts and inverse kinematics. Resets restore a
//! snapshot of the world taken at construction, so they cost microseconds, not a reload.

use crate::error::{Result, SimError};
use crate::kinematics::SerialChain;
use crate::math::{iso_to_pose, pose_to_iso, yaw_of};
use crate::model::{MeshCollision, Origin, RobotModel};
use crate::robot::{PdGains, Robot, RobotBuildOptions, groups};
use crate::{assets, model::LoadOptions};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rapier3d::na::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::PathBuf;

/// Physics settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhysicsConfig {
    /// Physics timestep (s). 1/240 like PyBullet; 1/120 also holds grasps.
    pub dt: f32,
    /// Physics steps per control step (the control period is `dt × substeps`).
    pub substeps: u32,
    /// Solver iterations (substeps) per physics step. Each one re-assembles the arm's
    /// joint-space mass matrix, the largest cost of a step.
    pub solver_iterations: usize,
    /// Gauss-Seidel sweeps inside each solver iteration: they tighten contacts and joints
    /// without the mass-matrix cost of another substep.
    pub pgs_iterations: usize,
    /// Contact stiffness as a natural frequency (Hz). rapier's default (30 Hz) lets a hard-squeezed
    /// light cube sink centimetres into the pads; 300 Hz keeps penetration under a millimetre.
    pub contact_frequency: f32,
    pub gravity: f32,
}

impl Default for PhysicsConfig {
    fn default() -> Self {
        Self {
            dt: 1.0 / 240.0,
            substeps: 8,
            // One substep with six Gauss-Seidel sweeps: the arm's mass matrix is assembled once
            // per step (2.5× faster than two substeps) and the sweeps still hold a squeezed cube
            // with < 1 mm of creep over 30 s of motion at 240 Hz and 120 Hz (measured; see
            // docs/simulation.md).
            solver_iterations: 1,
            pgs_iterations: 6,
            contact_frequency: 300.0,
            gravity: 9.81,
        }
    }
}

/// The table the arm stands on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TableConfig {
    /// Height of the table top above the floor (m).
    pub height: f32,
    /// Table top size along x and y (m).
    pub size: [f32; 2],
    /// Centre of the table top in the world x, y (m).
    pub center: [f32; 2],
    pub friction: f32,
}

impl Default for TableConfig {
    fn default() -> Self {
        Self {
            height: 0.75,
            size: [1.4, 1.2],
            center: [0.35, 0.0],
            friction: 0.6,
        }
    }
}

/// The object to grasp: a cube.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectConfig {
    /// Edge length (m).
    pub size: f32,
    pub mass: f32,
    pub friction: f32,
}

impl Default for ObjectConfig {
    fn default() -> Self {
        Self {
            size: 0.05,
            mass: 0.1,
            friction: 0.8,
        }
    }
}

/// Where objects are placed at reset: uniform in a rectangle on the table, uniform yaw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlacementConfig {
    /// Centre of the area, in the arm base frame x, y (m).
    pub center: [f32; 2],
    /// Extent of the area along x and y (m).
    pub size: [f32; 2],
    /// Yaw drawn from [-yaw_range, yaw_range] (rad).
    pub yaw_range: f32,
}

impl Default for PlacementConfig {
    fn default() -> Self {
        Self {
            center: [0.5, 0.0],
            size: [0.4, 0.4],
            yaw_range: std::f32::consts::PI,
        }
    }
}

/// The gripper on the flange.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GripperConfig {
    /// Largest squeezing force of the finger drive (N).
    pub force_limit: f32,
    /// Friction coefficient of the finger pads.
    pub pad_friction: f32,
    pub kp: f32,
    pub kd: f32,
}

impl Default for GripperConfig {
    fn default() -> Self {
        Self {
            force_limit: 40.0,
            pad_friction: 1.5,
            kp: 2_000.0,
            kd: 40.0,
        }
    }
}

/// A rigid offset as in a URDF `<origin>`: translation (m), then fixed-axis roll-pitch-yaw (rad).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MountConfig {
    pub xyz: [f32; 3],
    pub rpy: [f32; 3],
}

/// The arm and its drives.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmConfig {
    /// URDF of the arm; the bundled FR5 when `None`.
    pub urdf: Option<PathBuf>,
    /// Extra `package://` search roots.
    pub package_paths: Vec<PathBuf>,
    /// Link the gripper is mounted on.
    pub flange_link: String,
    /// Pose of the gripper's base relative to `flange_link` (at most 0.5 m away). Zero when the
    /// flange link is the flange face, as the bundled FR5's `tool0`. Arms whose last link is not
    /// the flange face set it: the vendor's FR5 description ends at `wrist3_link`, 0.1 m behind
    /// the face, with no `tool0`, so it takes `flange_link = "wrist3_link"` and
    /// `gripper_mount.xyz = [0, 0, 0.1]`.
    pub gripper_mount: MountConfig,
    /// Base position in the world (m): on the table top by default.
    pub base_xyz: [f32; 3],
    /// Base yaw (rad).
    pub base_yaw: f32,
    /// Joint vector at reset (rad).
    pub home: Vec<f32>,
    /// PD gains of the arm joints (N·m/rad, N·m·s/rad).
    pub kp: f32,
    pub kd: f32,
    /// Rotor inertia added to every joint (kg·m²).
    pub armature: f32,
    pub self_collision: bool,
    pub mesh_collision: MeshCollision,
}

impl Default for ArmConfig {
    fn default() -> Self {
        Self {
            urdf: None,
            package_paths: Vec::new(),
            flange_link: "tool0".into(),
            gripper_mount: MountConfig::default(),
            base_xyz: [0.0, 0.0, 0.75],
            base_yaw: 0.0,
            // Flange pointing down, about 30 cm above the middle of the placement area.
            home: vec![
                0.2056,
                -1.5709,
                -1.7669,
                -1.3746,
                std::f32::consts::FRAC_PI_2,
                -1.3651,
            ],
            kp: 8_000.0,
            kd: 400.0,
            armature: 0.1,
            self_collision: false,
            mesh_collision: MeshCollision::ConvexHull,
        }
    }
}

/// Everything that defines a scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    pub physics: PhysicsConfig,
    pub table: TableConfig,
    pub object: ObjectConfig,
    pub placement: PlacementConfig,
    pub gripper: GripperConfig,
    pub arm: ArmConfig,
}

impl SceneConfig {
    /// Checks ranges; the error names the key.
    pub fn validate(&self) -> Result<()> {
        let p = &self.physics;
        let positive = |key: &str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SimError::config(
                    key,
                    format!("must be a positive number, got {v}"),
                ))
            }
        };
        positive("physics.dt", p.dt)?;
        if p.dt > 1.0 / 60.0 {
            return Err(SimError::config(
                "physics.dt",
                format!("{} s is too coarse for grasping; use at most 1/60 s", p.dt),
            ));
        }
        if p.substeps == 0 {
            return Err(SimError::config("physics.substeps", "must be at least 1"));
        }
        if p.solver_iterations == 0 || p.solver_iterations > 100 {
            return Err(SimError::config(
                "physics.solver_iterations",
                "must be in 1..=100",
            ));
        }
        if p.pgs_iterations == 0 || p.pgs_iterations > 100 {
            return Err(SimError::config(
                "physics.pgs_iterations",
                "must be in 1..=100",
            ));
        }
        positive("physics.contact_frequency", p.contact_frequency)?;
        if !p.gravity.is_finite() {
            return Err(SimError::config("physics.gravity", "must be finite"));
        }
        positive("table.size[0]", self.table.size[0])?;
        positive("table.size[1]", self.table.size[1])?;
        if !self.table.height.is_finite() || self.table.height < 0.0 {
            return Err(SimError::config(
                "table.height",
                "must be a non-negative number",
            ));
        }
        positive("table.friction", self.table.friction)?;
        positive("object.size", self.object.size)?;
        if self.object.size > 0.085 {
            return Err(SimError::config(
                "object.size",
                format!(
                    "{} m does not fit the 90 mm gripper opening",
                    self.object.size
                ),
            ));
        }
        positive("object.mass", self.object.mass)?;
        positive("object.friction", self.object.friction)?;
        if !(self
            .placement
            .size
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0))
        {
            return Err(SimError::config("placement.size", "must be non-negative"));
        }
        if !self.placement.yaw_range.is_finite() || self.placement.yaw_range < 0.0 {
            return Err(SimError::config(
                "placement.yaw_range",
                "must be non-negative",
            ));
        }
        positive("gripper.force_limit", self.gripper.force_limit)?;
        positive("gripper.pad_friction", self.gripper.pad_friction)?;
        positive("gripper.kp", self.gripper.kp)?;
        if !(self.gripper.kd.is_finite() && self.gripper.kd >= 0.0) {
            return Err(SimError::config("gripper.kd", "must be non-negative"));
        }
        positive("arm.kp", self.arm.kp)?;
        if !(self.arm.kd.is_finite() && self.arm.kd >= 0.0) {
            return Err(SimError::config("arm.kd", "must be non-negative"));
        }
        if !(self.arm.armature.is_finite() && self.arm.armature >= 0.0) {
            return Err(SimError::config("arm.armature", "must be non-negative"));
        }
        if self.arm.base_xyz.iter().any(|v| !v.is_finite()) || !self.arm.base_yaw.is_finite() {
            return Err(SimError::config("arm.base_xyz", "must be finite"));
        }
        if self.arm.home.iter().any(|v| !v.is_finite()) {
            return Err(SimError::config("arm.home", "must be finite"));
        }
        let mount = &self.arm.gripper_mount;
        if mount.rpy.iter().any(|v| !v.is_finite()) {
            return Err(SimError::config("arm.gripper_mount.rpy", "must be finite"));
        }
        let distance = mount.xyz.iter().map(|v| v * v).sum::<f32>().sqrt();
        if !distance.is_finite() || distance > 0.5 {
            return Err(SimError::config(
                "arm.gripper_mount.xyz",
                format!(
                    "must be finite and at most 0.5 m from the flange link, got {:?}",
                    mount.xyz
                ),
            ));
        }
        Ok(())
    }
}

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

/// A saved state of the scene, restored by [`Scene::restore`].
#[derive(Clone)]
pub struct Snapshot {
    world: WorldState,
    robot: Robot,
    time: f64,
}

/// Physical parameters that domain randomisation varies per episode (see [`Scene::reset_with`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PhysicalParams {
    /// Cube edge length (m).
    pub object_size: f32,
    pub object_mass: f32,
    pub object_friction: f32,
    /// Viscous damping of each arm joint (N·m·s/rad); `None` keeps the URDF values.
    pub arm_damping: Option<Vec<f32>>,
    /// Factor on the arm's PD gains (actuator strength).
    pub gain_scale: f32,
}

/// The pose and velocity of a rigid object.
#[derive(Clone, Copy, Debug)]
pub struct ObjectState {
    pub pose: Isometry3<f64>,
    pub linvel: [f64; 3],
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
    object: RigidBodyHandle,
    object_collider: ColliderHandle,
    table_top: f32,
    /// Edge length of the cube in this episode.
    object_size: f32,
    home: Snapshot,
    /// TCP pose at the home joint vector.
    home_tcp: Isometry3<f64>,
    time: f64,
}

const TCP_LINK: &str = "tcp";

impl Scene {
    /// Builds the scene: arm + gripper + table + cube, arm at home.
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
        };
        let mut robot = Robot::build(
            arm_model,
            &build,
            &mut world.bodies,
            &mut world.colliders,
            &mut world.multibody_joints,
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
        world.colliders.insert_with_parent(
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

        // Object: parked out of the way until a reset places it.
        let o = &config.object;
        let object = world.bodies.insert(
            RigidBodyBuilder::dynamic()
                .translation(Vector::new(
                    t.center[0],
                    t.center[1],
                    t.height + o.size / 2.0,
                ))
                .can_sleep(false)
                .build(),
        );
        let half = o.size / 2.0;
        let object_collider = world.colliders.insert_with_parent(
            ColliderBuilder::cuboid(half, half, half)
                .mass(o.mass)
                .friction(o.friction)
                .collision_groups(InteractionGroups::new(
                    groups::OBJECT,
                    Group::ALL,
                    InteractionTestMode::And,
                ))
                .build(),
            object,
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
                time: 0.0,
            },
            world,
            robot,
            arm,
            finger,
            finger_bodies,
            chain,
            base,
            object,
            object_collider,
            table_top,
            object_size: config.object.size,
            home_tcp: Isometry3::identity(),
            time: 0.0,
            config,
        };
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
        scene.time = 0.0;
        scene.home = scene.snapshot();
        scene.home_tcp = scene.tcp_pose();
        Ok(scene)
    }

    pub fn config(&self) -> &SceneConfig {
        &self.config
    }

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
            time: self.time,
        }
    }

    /// Restores a saved state exactly.
    pub fn restore(&mut self, snapshot: &Snapshot) {
        self.world.clone_from(&snapshot.world);
        self.robot.clone_from(&snapshot.robot);
        self.time = snapshot.time;
    }

    /// Advances the physics by one timestep.
    pub fn step_physics(&mut self) -> Result<()> {
        let w = &mut self.world;
        self.robot
            .apply_joint_torques(&mut w.bodies, &w.multibody_joints);
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
        let q = self.robot.joint_positions(&self.world.multibody_joints);
        self.arm.iter().map(|&j| q[j]).collect()
    }

    /// Arm joint velocities (rad/s).
    pub fn arm_velocities(&self) -> Vec<f32> {
        let v = self.robot.joint_velocities(&self.world.multibody_joints);
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
        let finger = self.robot.joint_positions(&self.world.multibody_joints)[self.finger];
        let full = self.full_vector(q, finger)?;
        self.robot.set_joint_positions(
            &full,
            &mut self.world.bodies,
            &mut self.world.multibody_joints,
        )
    }

    /// Position control of the arm: PD targets (rad), clamped to the joint limits.
    pub fn set_arm_targets(&mut self, q: &[f32]) -> Result<()> {
        let finger = self.robot.position_targets()[self.finger];
        let full = self.full_vector(q, finger)?;
        self.robot
            .set_position_targets(&full, &mut self.world.multibody_joints)
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
        self.robot
            .set_torques(&full, &mut self.world.multibody_joints)
    }

    // ── Gripper ────────────────────────────────────────────────────────────

    /// Largest finger opening (m).
    pub fn max_opening(&self) -> f32 {
        2.0 * self.robot.joints[self.finger].limits.1
    }

    /// Distance between the finger pads (m).
    pub fn gripper_opening(&self) -> f32 {
        2.0 * self.robot.joint_positions(&self.world.multibody_joints)[self.finger]
    }

    /// Commands the fingers to an opening (m); they squeeze with at most the force limit.
    pub fn set_gripper_target(&mut self, opening: f32) -> Result<()> {
        if !opening.is_finite() {
            return Err(SimError::Command(format!("gripper opening is {opening}")));
        }
        let q = (opening / 2.0).clamp(0.0, self.max_opening() / 2.0);
        self.robot
            .set_position_target(self.finger, q, &mut self.world.multibody_joints)
    }

    /// Opens fully (`true`) or closes (`false`).
    pub fn set_gripper_open(&mut self, open: bool) -> Result<()> {
        self.set_gripper_target(if open { self.max_opening() } else { 0.0 })
    }

    /// Target opening (m).
    pub fn gripper_target(&self) -> f32 {
        2.0 * self.robot.position_targets()[self.finger]
    }

    fn set_gripper_opening_now(&mut self, opening: f32) -> Result<()> {
        let mut q = self.robot.joint_positions(&self.world.multibody_joints);
        let half = (opening / 2.0).clamp(0.0, self.max_opening() / 2.0);
        q[self.finger] = half;
        for (j, joint) in self.robot.joints.iter().enumerate() {
            if let Some((leader, m, o)) = joint.mimic {
                q[j] = m * q[leader] + o;
            }
        }
        self.robot
            .set_joint_positions(&q, &mut self.world.bodies, &mut self.world.multibody_joints)
    }

    /// Whether each finger pad (left, right) touches the object.
    pub fn finger_contacts(&self) -> [bool; 2] {
        self.finger_bodies.map(|b| {
            self.world.bodies[b].colliders().iter().any(|&c| {
                self.world
                    .narrow_phase
                    .contact_pair(c, self.object_collider)
                    .is_some_and(|p| p.has_any_active_contact())
            })
        })
    }

    /// Whether two named things touch: a robot link name, `"object"` or `"table"`.
    pub fn in_contact(&self, a: &str, b: &str) -> Option<bool> {
        let a = self.colliders_of(a)?;
        let b = self.colliders_of(b)?;
        Some(a.iter().any(|&ca| {
            b.iter().any(|&cb| {
                self.world
                    .narrow_phase
                    .contact_pair(ca, cb)
                    .is_some_and(|p| p.has_any_active_contact())
            })
        }))
    }

    fn colliders_of(&self, name: &str) -> Option<Vec<ColliderHandle>> {
        match name {
            "object" => Some(vec![self.object_collider]),
            "table" => self
                .world
                .colliders
                .iter()
                .find(|(_, c)| c.collision_groups().memberships == groups::TABLE)
                .map(|(h, _)| vec![h]),
            link => {
                let body = self.robot.link_body(link)?;
                Some(self.world.bodies[body].colliders().to_vec())
            }
        }
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

    /// Pose and velocity of the object.
    pub fn object_state(&self) -> ObjectState {
        let body = &self.world.bodies[self.object];
        let v = body.linvel();
        let w = body.angvel();
        ObjectState {
            pose: pose_to_iso(body.position()),
            linvel: [v.x as f64, v.y as f64, v.z as f64],
            angvel: [w.x as f64, w.y as f64, w.z as f64],
        }
    }

    /// Height of the object's centre when resting on the table (m).
    pub fn object_rest_height(&self) -> f64 {
        (self.table_top + self.object_size / 2.0) as f64
    }

    /// Edge length of the cube in this episode (m).
    pub fn object_size(&self) -> f32 {
        self.object_size
    }

    /// Whether the object has left the table: dropped below its top or beyond its edges.
    pub fn object_off_table(&self) -> bool {
        let p = self.object_state().pose.translation.vector;
        let t = &self.config.table;
        p.z < (self.table_top - self.object_size) as f64
            || (p.x - t.center[0] as f64).abs() > t.size[0] as f64 / 2.0
            || (p.y - t.center[1] as f64).abs() > t.size[1] as f64 / 2.0
    }

    /// The physical parameters of the configuration, unrandomised.
    pub fn nominal_params(&self) -> PhysicalParams {
        PhysicalParams {
            object_size: self.config.object.size,
            object_mass: self.config.object.mass,
            object_friction: self.config.object.friction,
            arm_damping: None,
            gain_scale: 1.0,
        }
    }

    fn apply_params(&mut self, params: &PhysicalParams) -> Result<()> {
        let size = params.object_size;
        if !(size.is_finite() && size > 0.0 && size <= 0.085) {
            return Err(SimError::Command(format!(
                "object size {size} m must be in (0, 0.085]"
            )));
        }
        if !(params.gain_scale.is_finite() && params.gain_scale > 0.0) {
            return Err(SimError::Command(format!(
                "gain scale {} must be positive",
                params.gain_scale
            )));
        }
        self.set_object_properties(params.object_mass, params.object_friction)?;
        if size != self.object_size {
            let half = size / 2.0;
            let mass = params.object_mass;
            let collider = &mut self.world.colliders[self.object_collider];
            collider.set_shape(SharedShape::cuboid(half, half, half));
            collider.set_mass(mass);
            self.object_size = size;
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
            .set_position_targets(&targets, &mut self.world.multibody_joints)
    }

    /// Places the object at `pose` (world) with zero velocity.
    pub fn set_object_pose(&mut self, pose: &Isometry3<f64>) {
        let body = &mut self.world.bodies[self.object];
        body.set_position(iso_to_pose(pose), true);
        body.set_linvel(Vector::ZERO, true);
        body.set_angvel(Vector::ZERO, true);
    }

    /// Changes the object's mass and friction (for domain randomisation).
    pub fn set_object_properties(&mut self, mass: f32, friction: f32) -> Result<()> {
        if !(mass.is_finite() && mass > 0.0 && friction.is_finite() && friction >= 0.0) {
            return Err(SimError::Command(format!(
                "object mass {mass} and friction {friction} must be positive"
            )));
        }
        let c = &mut self.world.colliders[self.object_collider];
        c.set_mass(mass);
        c.set_friction(friction);
        Ok(())
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

    /// Restores the home state and places the object at random (uniform in the placement area,
    /// uniform yaw), retrying until the placement is reachable and collision-free; then lets it
    /// settle. Returns the object pose.
    pub fn reset(&mut self, seed: u64) -> Result<Isometry3<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        self.reset_with_rng(&mut rng)
    }

    /// [`Self::reset`] drawing from a caller's random stream.
    pub fn reset_with_rng(&mut self, rng: &mut impl Rng) -> Result<Isometry3<f64>> {
        let nominal = self.nominal_params();
        self.reset_with(rng, &nominal, &[])
    }

    /// Resets with given physical parameters and an offset added to the home joint vector
    /// (initial joint jitter), then places the object as [`Self::reset`] does.
    pub fn reset_with(
        &mut self,
        rng: &mut impl Rng,
        params: &PhysicalParams,
        home_offset: &[f32],
    ) -> Result<Isometry3<f64>> {
        let home = self.home.clone();
        self.restore(&home);
        self.object_size = self.config.object.size;
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
        let p = &self.config.placement;
        let home_q = self.arm_positions();
        for _ in 0..100 {
            let local_x = p.center[0] + (rng.random::<f32>() - 0.5) * p.size[0];
            let local_y = p.center[1] + (rng.random::<f32>() - 0.5) * p.size[1];
            let yaw = (rng.random::<f32>() * 2.0 - 1.0) * p.yaw_range;
            let world_xy =
                self.base * rapier3d::na::Point3::new(local_x as f64, local_y as f64, 0.0);
            let position = Vector3::new(world_xy.x, world_xy.y, self.object_rest_height() + 0.001);
            let pose = Isometry3::from_parts(
                Translation3::from(position),
                UnitQuaternion::from_euler_angles(
                    0.0,
                    0.0,
                    yaw as f64 + yaw_of(&self.base.rotation),
                ),
            );
            if self.placement_is_valid(&pose, &home_q) {
                self.set_object_pose(&pose);
                self.settle()?;
                self.time = 0.0;
                return Ok(self.object_state().pose);
            }
        }
        Err(SimError::config(
            "placement",
            "no reachable, collision-free placement found in 100 draws; check the area",
        ))
    }

    /// Reachable from above (pre-grasp and grasp poses solve) and clear of the robot.
    fn placement_is_valid(&self, pose: &Isometry3<f64>, seed: &[f32]) -> bool {
        let centre = pose.translation.vector;
        let yaw = self.grasp_yaw(&pose.rotation);
        for lift in [0.0, 0.15] {
            let target = self.top_down_pose(centre + Vector3::new(0.0, 0.0, lift), yaw);
            if self.solve_ik(&target, seed).is_err() {
                return false;
            }
        }
        let half = self.config.object.size / 2.0;
        let cube = Cuboid::new(Vector::new(half, half, half));
        let cube_pose = iso_to_pose(pose);
        !self.robot.bodies.iter().any(|&b| {
            self.world.bodies[b].colliders().iter().any(|&c| {
                let collider = &self.world.colliders[c];
                rapier3d::parry::query::intersection_test(
                    &cube_pose,
                    &cube,
                    collider.position(),
                    collider.shape(),
                )
                .map(|hit| hit.intersecting)
                .unwrap_or(true)
            })
        })
    }

    /// Steps until the object rests (speed below 1 mm/s), at most one simulated second.
    fn settle(&mut self) -> Result<()> {
        let max_steps = (1.0 / self.params.dt).ceil() as usize;
        for i in 0..max_steps {
            self.step_physics()?;
            let s = self.object_state();
            let speed = Vector3::from(s.linvel).norm() + Vector3::from(s.angvel).norm() * 0.05;
            if i >= 4 && speed < 1e-3 {
                break;
            }
        }
        self.check_finite()
    }
}
