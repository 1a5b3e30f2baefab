//! A [`RobotModel`] built into rapier as one multibody (reduced coordinates), and its control.
//!
//! Links joined by fixed joints are merged into one rigid body (their colliders and mass added
//! up), so `tool0`, a gripper base and a TCP frame cost nothing at run time. Every movable joint
//! becomes a multibody joint with a force-based PD motor capped at the URDF effort limit; URDF
//! `<mimic>` becomes a rapier DOF coupling (this is how the two gripper fingers move as one).
//!
//! With [`JointDrive::Kinematic`] the arm's links are kinematic bodies that follow their joint
//! targets through a ramp instead (see `robot/kinematic.rs`), and only the gripper stays dynamic.

mod kinematic;

use crate::error::{Result, SimError};
use crate::kinematics::origin_to_isometry;
use crate::math::{iso_to_pose, pose_to_iso};
use crate::model::{Geometry, JointKind, MeshCollision, RobotModel, Shape};
use kinematic::KinematicArm;
use rapier3d::na::{Isometry3, Unit, Vector3};
use rapier3d::prelude::*;
use std::collections::HashMap;

/// Collision groups of the scene. Robot links meet the table and objects; robot self-contacts
/// are governed by the multibody's own switch, not by groups.
pub mod groups {
    use rapier3d::prelude::Group;
    /// The robot's links; they meet the table and objects.
    pub const ROBOT: Group = Group::GROUP_1;
    /// The table and the bins; they meet the robot and objects.
    pub const TABLE: Group = Group::GROUP_2;
    /// The objects to grasp; they meet everything.
    pub const OBJECT: Group = Group::GROUP_3;
}

/// How a model becomes bodies, colliders and joints.
#[derive(Clone, Debug)]
pub struct RobotBuildOptions {
    /// Pose of the root link in the world.
    pub base_pose: Isometry3<f64>,
    /// Contacts between non-adjacent links of the robot (adjacent links never collide).
    pub self_collision: bool,
    /// How mesh collision shapes become convex shapes.
    pub mesh_collision: MeshCollision,
    /// Friction of robot colliders unless overridden per link.
    pub friction: f32,
    /// Friction per link name (e.g. high-friction finger pads).
    pub link_friction: HashMap<String, f32>,
    /// Rotor inertia added to every joint (kg·m² or kg): real geared joints have a large one,
    /// and it keeps stiff PD motors on light links stable.
    pub armature: f32,
    /// How the joints are simulated.
    pub drive: JointDrive,
}

/// The joint sets of the world a robot is built into.
pub struct JointSets<'a> {
    /// The world's multibody joints, where the PD drive's joints live.
    pub multibody_joints: &'a mut MultibodyJointSet,
    /// The world's impulse joints, where the kinematic drive's dynamic joints (the gripper's) live.
    pub impulse_joints: &'a mut ImpulseJointSet,
}

/// How the joints are simulated.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum JointDrive {
    /// Every movable joint a multibody joint with a force-based PD motor: a torque-level arm.
    #[default]
    Pd,
    /// Joints follow their targets through a [`crate::control::JointRamp`] with these caps
    /// (rad/s, rad/s²; m/s and m/s² for prismatic joints) every physics step of `dt` seconds,
    /// their links kinematic bodies. The joints in `dynamic_joints` (the gripper's) stay
    /// dynamic: impulse joints with PD motors; no kinematic joint may follow one of them.
    /// `lag` (s): the joints follow the ramp's set point through a first-order lag (0: on it).
    Kinematic {
        /// Speed cap (rad/s or m/s).
        speed: f32,
        /// Acceleration cap (rad/s² or m/s²).
        acc: f32,
        /// Time constant of the lag behind the ramp's set point (s); 0 for none.
        lag: f32,
        /// Physics step (s).
        dt: f32,
        /// Names of the joints that stay dynamic.
        dynamic_joints: Vec<String>,
    },
}

impl Default for RobotBuildOptions {
    fn default() -> Self {
        Self {
            base_pose: Isometry3::identity(),
            self_collision: false,
            mesh_collision: MeshCollision::ConvexHull,
            friction: 0.8,
            link_friction: HashMap::new(),
            armature: 0.05,
            drive: JointDrive::Pd,
        }
    }
}

/// PD gains of a joint's position motor: torque = kp·(q* − q) + kd·(q̇* − q̇), capped at the effort
/// limit (N·m/rad and N·m·s/rad, or N/m and N·s/m for prismatic joints).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PdGains {
    /// Stiffness (N·m/rad or N/m).
    pub kp: f32,
    /// Damping (N·m·s/rad or N·s/m).
    pub kd: f32,
}

/// A movable joint of the built robot.
#[derive(Clone, Debug)]
pub struct RobotJoint {
    /// The URDF joint name.
    pub name: String,
    /// Revolute, continuous or prismatic.
    pub kind: JointKind,
    /// Index into the model's joints.
    pub model_index: usize,
    /// The multibody link this joint moves.
    link_id: usize,
    /// `(lower, upper)` position limits; infinite for continuous joints.
    pub limits: (f32, f32),
    /// Largest motor torque or force (N·m or N): the URDF effort limit, unless changed by
    /// [`Robot::set_effort_limit`]; `f32::MAX` without one.
    pub effort: f32,
    /// URDF velocity limit (rad/s or m/s); `f32::MAX` without one.
    pub velocity: f32,
    /// Mimicked joint (index into [`Robot::joints`]) with multiplier and offset.
    pub mimic: Option<(usize, f32, f32)>,
}

/// Where a movable joint sits between the robot's bodies.
#[derive(Clone, Debug)]
pub(crate) struct JointGeometry {
    /// Indices into [`Robot::bodies`].
    pub(crate) parent_body: usize,
    pub(crate) child_body: usize,
    /// The joint's frame at zero position, in the parent body's frame.
    pub(crate) origin: Isometry3<f64>,
    /// Unit axis in that frame.
    pub(crate) axis: Unit<Vector3<f64>>,
    pub(crate) kind: JointKind,
}

impl RobotJoint {
    fn axis(&self) -> JointAxis {
        match self.kind {
            JointKind::Prismatic => JointAxis::LinX,
            _ => JointAxis::AngX,
        }
    }
    fn coord_index(&self) -> usize {
        match self.kind {
            JointKind::Prismatic => 0,
            _ => 3,
        }
    }
}

/// Commands applied at every physics step until replaced.
#[derive(Clone, Debug, PartialEq)]
enum DriveMode {
    Position,
    /// Joint torques (N·m or N), one per joint of [`Robot::joints`].
    Torque(Vec<f32>),
}

/// The robot inside a physics world: handles, joint table and motor settings.
#[derive(Clone, Debug)]
pub struct Robot {
    /// The model the robot was built from.
    pub model: RobotModel,
    /// The multibody of the PD drive; `None` under the kinematic drive.
    multibody: Option<MultibodyIndex>,
    /// The kinematic drive's state; `None` under the PD drive.
    kinematic: Option<KinematicArm>,
    /// Per movable joint, in [`Self::joints`] order.
    geometry: Vec<JointGeometry>,
    /// Rigid bodies after merging fixed links; `bodies[0]` is the root.
    pub bodies: Vec<RigidBodyHandle>,
    /// For each model link: its body (index into `bodies`) and pose in that body.
    link_frames: Vec<(usize, Pose)>,
    /// Movable joints, in model (root-to-leaf) order.
    pub joints: Vec<RobotJoint>,
    targets: Vec<f32>,
    gains: Vec<PdGains>,
    mode: DriveMode,
    /// Body pairs whose contacts are ignored when self-collision is on (see
    /// [`Self::exclude_touching_pairs`]).
    self_collision_filter: SelfCollisionFilter,
}

/// Skips contacts between robot bodies that touch by design (overlapping housings of links two
/// joints apart), like MoveIt's "always in collision" pairs. Only active with self-collision.
#[derive(Clone, Debug, Default)]
pub struct SelfCollisionFilter {
    pairs: Vec<(RigidBodyHandle, RigidBodyHandle)>,
}

impl SelfCollisionFilter {
    fn contains(&self, a: RigidBodyHandle, b: RigidBodyHandle) -> bool {
        self.pairs
            .iter()
            .any(|&(x, y)| (x, y) == (a, b) || (x, y) == (b, a))
    }
}

impl PhysicsHooks for SelfCollisionFilter {
    fn filter_contact_pair(&self, context: &PairFilterContext) -> Option<SolverFlags> {
        match (context.rigid_body1, context.rigid_body2) {
            (Some(a), Some(b)) if self.contains(a, b) => None,
            _ => Some(SolverFlags::default()),
        }
    }
}

fn shape_of(geometry: &Geometry, mode: MeshCollision) -> Option<(SharedShape, Pose)> {
    let shape = match geometry {
        Geometry::Box { size } => SharedShape::cuboid(
            size[0] as f32 / 2.0,
            size[1] as f32 / 2.0,
            size[2] as f32 / 2.0,
        ),
        Geometry::Cylinder { radius, length } => {
            // rapier's cylinder axis is y, URDF's is z.
            return Some((
                SharedShape::cylinder(*length as f32 / 2.0, *radius as f32),
                Pose::rotation(Vector::X * std::f32::consts::FRAC_PI_2),
            ));
        }
        Geometry::Capsule { radius, length } => {
            SharedShape::capsule_z(*length as f32 / 2.0, *radius as f32)
        }
        Geometry::Sphere { radius } => SharedShape::ball(*radius as f32),
        Geometry::Mesh { scale, mesh, .. } => {
            let points: Vec<Vector> = mesh
                .vertices
                .iter()
                .map(|v| {
                    Vector::new(
                        v[0] * scale[0] as f32,
                        v[1] * scale[1] as f32,
                        v[2] * scale[2] as f32,
                    )
                })
                .collect();
            // The hull and V-HACD routines index into user geometry: contain any panic.
            let built = std::panic::catch_unwind(|| match mode {
                MeshCollision::ConvexHull => SharedShape::convex_hull(&points),
                MeshCollision::ConvexDecomposition => {
                    Some(SharedShape::convex_decomposition(&points, &mesh.triangles))
                }
            });
            built.ok().flatten()?
        }
    };
    Some((shape, Pose::IDENTITY))
}

impl Robot {
    /// Builds `model` into the world's sets as one multibody rooted at a fixed base.
    pub fn build(
        model: RobotModel,
        options: &RobotBuildOptions,
        bodies: &mut RigidBodySet,
        colliders: &mut ColliderSet,
        sets: JointSets<'_>,
    ) -> Result<Self> {
        let JointSets {
            multibody_joints,
            impulse_joints,
        } = sets;
        if !model.joints.iter().any(|j| j.kind.is_movable()) {
            return Err(SimError::urdf(
                &model.source_name,
                "robot",
                "has no movable joint; nothing to simulate",
            ));
        }
        // 1. Group links into bodies: a link joined to its parent by a fixed joint rides on the
        //    parent's body. Joints are sorted root to leaves, so parents are placed first.
        let n_links = model.links.len();
        let mut link_frames: Vec<Option<(usize, Isometry3<f64>)>> = vec![None; n_links];
        let mut body_links: Vec<usize> = vec![model.root];
        link_frames[model.root] = Some((0, Isometry3::identity()));
        for joint in &model.joints {
            let (parent_body, parent_offset) =
                link_frames[joint.parent].expect("joints are sorted root to leaves");
            if joint.kind == JointKind::Fixed {
                link_frames[joint.child] = Some((
                    parent_body,
                    parent_offset * origin_to_isometry(&joint.origin),
                ));
            } else {
                link_frames[joint.child] = Some((body_links.len(), Isometry3::identity()));
                body_links.push(joint.child);
            }
        }
        let link_frames: Vec<(usize, Isometry3<f64>)> =
            link_frames.into_iter().map(|f| f.expect("tree")).collect();

        // 2. World poses at q = 0, to place bodies before the multibody takes over.
        let mut world_of_link = vec![options.base_pose; n_links];
        for joint in &model.joints {
            world_of_link[joint.child] =
                world_of_link[joint.parent] * origin_to_isometry(&joint.origin);
        }

        // Under the kinematic drive, which bodies are kinematic: those moved by a joint not
        // listed as dynamic, as long as no dynamic joint lies between them and the root.
        let mut kinematic_body = vec![false; body_links.len()];
        if let JointDrive::Kinematic { dynamic_joints, .. } = &options.drive {
            for name in dynamic_joints {
                if !model
                    .joints
                    .iter()
                    .any(|j| &j.name == name && j.kind.is_movable())
                {
                    return Err(SimError::urdf(
                        &model.source_name,
                        format!("joint '{name}'"),
                        "is listed as a dynamic joint of the kinematic drive but is not a \
                         movable joint of this robot",
                    ));
                }
            }
            let body_of_link = |l: usize| link_frames[l].0;
            for joint in model.joints.iter().filter(|j| j.kind.is_movable()) {
                let parent = body_of_link(joint.parent);
                let child = body_of_link(joint.child);
                let dynamic = dynamic_joints.contains(&joint.name);
                if !dynamic {
                    if parent != 0 && !kinematic_body[parent] {
                        return Err(SimError::urdf(
                            &model.source_name,
                            format!("joint '{}'", joint.name),
                            "follows a dynamic joint, so the kinematic drive cannot move it",
                        ));
                    }
                    kinematic_body[child] = true;
                }
            }
        }

        // 3. Bodies with summed mass properties and colliders.
        let mut handles = Vec::with_capacity(body_links.len());
        for (b, &link) in body_links.iter().enumerate() {
            let mut mass = MassProperties::default();
            for (l, (body, offset)) in link_frames.iter().enumerate() {
                if *body != b {
                    continue;
                }
                if let Some(inertial) = &model.links[l].inertial {
                    let i = inertial.inertia.map(|v| v as f32);
                    let matrix = Matrix::from_cols_array(&[
                        i[0], i[1], i[2], i[1], i[3], i[4], i[2], i[4], i[5],
                    ]);
                    let local = MassProperties::with_inertia_matrix(
                        Vector::ZERO,
                        inertial.mass as f32,
                        matrix,
                    );
                    let frame = offset * origin_to_isometry(&inertial.origin);
                    mass += local.transform_by(&iso_to_pose(&frame));
                }
            }
            let builder = if b == 0 {
                RigidBodyBuilder::fixed()
            } else if kinematic_body[b] {
                RigidBodyBuilder::kinematic_position_based()
            } else {
                if matches!(options.drive, JointDrive::Kinematic { .. }) && mass.mass() > 0.0 {
                    // An impulse joint has no rotor inertia (armature), which the multibody adds
                    // along each joint axis; the body carries it instead (the finger 0.05 →
                    // 0.15 kg). Without it the fingers let a lifted cube slip out: 0 of 50
                    // scripted picks held; with it 50 of 50.
                    let scale = (mass.mass() + options.armature) / mass.mass();
                    mass = MassProperties::with_inertia_matrix(
                        mass.local_com,
                        mass.mass() * scale,
                        mass.reconstruct_inertia_matrix() * scale,
                    );
                }
                RigidBodyBuilder::dynamic()
                    .additional_mass_properties(mass)
                    // A sleeping link ignores new motor targets.
                    .can_sleep(false)
            };
            let handle = bodies.insert(builder.pose(iso_to_pose(&world_of_link[link])).build());
            handles.push(handle);
        }
        let filter = if options.self_collision {
            Group::ALL
        } else {
            groups::TABLE | groups::OBJECT
        };
        let collision_groups =
            InteractionGroups::new(groups::ROBOT, filter, InteractionTestMode::And);
        let hooks = if options.self_collision {
            ActiveHooks::FILTER_CONTACT_PAIRS
        } else {
            ActiveHooks::empty()
        };
        for (l, (body, offset)) in link_frames.iter().enumerate() {
            let link = &model.links[l];
            let friction = options
                .link_friction
                .get(&link.name)
                .copied()
                .unwrap_or(options.friction);
            for (
                k,
                Shape {
                    origin, geometry, ..
                },
            ) in link.collisions.iter().enumerate()
            {
                let (shape, adjust) =
                    shape_of(geometry, options.mesh_collision).ok_or_else(|| {
                        SimError::urdf(
                            &model.source_name,
                            format!("link '{}' <collision> #{}", link.name, k + 1),
                            "could not build a convex collision shape from this mesh \
                             (degenerate or flat)",
                        )
                    })?;
                let pose = iso_to_pose(&(offset * origin_to_isometry(origin))) * adjust;
                let collider = ColliderBuilder::new(shape)
                    .position(pose)
                    .density(0.0)
                    .friction(friction)
                    .collision_groups(collision_groups)
                    .active_hooks(hooks)
                    .build();
                colliders.insert_with_parent(collider, handles[*body], bodies);
            }
        }

        // 4. Joints for movable joints: multibody joints under the PD drive; under the kinematic
        //    drive none for kinematic joints and impulse joints for dynamic ones.
        let mut joints = Vec::new();
        let mut geometry = Vec::new();
        let mut impulse = Vec::new();
        for (model_index, joint) in model.joints.iter().enumerate() {
            if joint.kind == JointKind::Fixed {
                continue;
            }
            let (parent_body, parent_offset) = link_frames[joint.parent];
            let (child_body, _) = link_frames[joint.child];
            let axis = Vector::new(
                joint.axis[0] as f32,
                joint.axis[1] as f32,
                joint.axis[2] as f32,
            );
            // rapier's free axis is the joint frame's x: rotate x onto the URDF axis.
            let basis = Pose::from_rotation(GenericJoint::complete_ang_frame(axis));
            let frame1 = iso_to_pose(&(parent_offset * origin_to_isometry(&joint.origin))) * basis;
            let locked = match joint.kind {
                JointKind::Prismatic => JointAxesMask::LOCKED_PRISMATIC_AXES,
                _ => JointAxesMask::LOCKED_REVOLUTE_AXES,
            };
            let rj = RobotJoint {
                name: joint.name.clone(),
                kind: joint.kind,
                model_index,
                link_id: 0,
                limits: joint
                    .limits
                    .map(|l| (l.lower as f32, l.upper as f32))
                    .unwrap_or((f32::NEG_INFINITY, f32::INFINITY)),
                effort: joint.limits.map(|l| l.effort as f32).unwrap_or(f32::MAX),
                velocity: joint.limits.map(|l| l.velocity as f32).unwrap_or(f32::MAX),
                mimic: None,
            };
            let mut builder = GenericJointBuilder::new(locked)
                .local_frame1(frame1)
                .local_frame2(basis)
                .contacts_enabled(false)
                .motor_model(rj.axis(), MotorModel::ForceBased)
                .motor_max_force(rj.axis(), rj.effort);
            if joint.kind != JointKind::Continuous {
                builder = builder.limits(rj.axis(), [rj.limits.0, rj.limits.1]);
            }
            let axis = Vector3::new(joint.axis[0], joint.axis[1], joint.axis[2]);
            geometry.push(JointGeometry {
                parent_body,
                child_body,
                origin: parent_offset * origin_to_isometry(&joint.origin),
                axis: Unit::try_new(axis, 1e-9).ok_or_else(|| {
                    SimError::urdf(
                        &model.source_name,
                        format!("joint '{}'", joint.name),
                        "has a zero axis",
                    )
                })?,
                kind: joint.kind,
            });
            let refused = || {
                SimError::urdf(
                    &model.source_name,
                    format!("joint '{}'", joint.name),
                    "rapier refused the joint (would close a loop)",
                )
            };
            match &options.drive {
                JointDrive::Pd => {
                    multibody_joints
                        .insert(
                            handles[parent_body],
                            handles[child_body],
                            builder.build(),
                            true,
                        )
                        .ok_or_else(refused)?;
                    impulse.push(None);
                }
                JointDrive::Kinematic { .. } if kinematic_body[child_body] => impulse.push(None),
                JointDrive::Kinematic { .. } => impulse.push(Some(impulse_joints.insert(
                    handles[parent_body],
                    handles[child_body],
                    builder.build(),
                    true,
                ))),
            }
            joints.push(rj);
        }
        // Mimic joints: DOF couplings under the PD drive, mirrored motor targets otherwise.
        let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
        for joint in joints.iter_mut() {
            let model_joint = &model.joints[joint.model_index];
            if let Some(m) = model_joint.mimic {
                let leader_name = &model.joints[m.joint].name;
                let leader = names.iter().position(|n| n == leader_name).ok_or_else(|| {
                    SimError::urdf(
                        &model.source_name,
                        format!("joint '{}'", model_joint.name),
                        format!("mimics '{leader_name}', which is not movable"),
                    )
                })?;
                joint.mimic = Some((leader, m.multiplier as f32, m.offset as f32));
            }
        }
        let (multibody, kinematic) = match &options.drive {
            JointDrive::Pd => {
                let multibody = multibody_joints
                    .rigid_body_link(handles[0])
                    .ok_or_else(|| SimError::Command("robot root is not in a multibody".into()))?
                    .multibody;
                for joint in joints.iter_mut() {
                    let child_body = handles[link_frames[model.joints[joint.model_index].child].0];
                    joint.link_id = multibody_joints
                        .rigid_body_link(child_body)
                        .map(|l| l.id)
                        .ok_or_else(|| {
                            SimError::Command(format!(
                                "joint '{}' lost its multibody link",
                                joint.name
                            ))
                        })?;
                }
                let mb = multibody_joints
                    .get_multibody_mut(multibody)
                    .ok_or_else(|| SimError::Command("robot multibody missing".into()))?;
                mb.set_self_contacts_enabled(options.self_collision);
                for joint in &joints {
                    let link = mb.link(joint.link_id).expect("link id from rapier");
                    let dof = link.assembly_id();
                    mb.armature_mut()[dof] = options.armature;
                    mb.damping_mut()[dof] = model.joints[joint.model_index].damping as f32;
                    if let Some((leader, multiplier, offset)) = joint.mimic {
                        let leader = &joints[leader];
                        mb.add_dof_coupling(MultibodyDofCoupling {
                            link1: leader.link_id,
                            dof1: 0,
                            axis1: leader.coord_index(),
                            link2: joint.link_id,
                            dof2: 0,
                            axis2: joint.coord_index(),
                            coeff: multiplier,
                            offset,
                        });
                    }
                }
                (Some(multibody), None)
            }
            JointDrive::Kinematic {
                speed,
                acc,
                lag,
                dt,
                ..
            } => {
                let limits: Vec<(f32, f32)> = joints.iter().map(|j| j.limits).collect();
                let arm = KinematicArm::new(impulse, &limits, (*speed, *acc, *lag), *dt);
                (None, Some(arm))
            }
        };

        let n = joints.len();
        let mut robot = Robot {
            model,
            multibody,
            kinematic,
            geometry,
            bodies: handles,
            link_frames: link_frames
                .into_iter()
                .map(|(b, offset)| (b, iso_to_pose(&offset)))
                .collect(),
            joints,
            targets: vec![0.0; n],
            gains: vec![PdGains { kp: 0.0, kd: 0.0 }; n],
            mode: DriveMode::Position,
            self_collision_filter: SelfCollisionFilter::default(),
        };
        if options.self_collision {
            robot.exclude_touching_pairs(bodies, colliders);
        }
        robot.set_gains_all(PdGains {
            kp: 2_000.0,
            kd: 100.0,
        });
        robot.apply_motors(JointSets {
            multibody_joints,
            impulse_joints,
        });
        Ok(robot)
    }

    /// Adds to the self-collision filter every pair of robot bodies whose shapes intersect in the
    /// current configuration (bodies joined by a joint never collide anyway).
    pub fn exclude_touching_pairs(&mut self, bodies: &RigidBodySet, colliders: &ColliderSet) {
        for (i, &a) in self.bodies.iter().enumerate() {
            for &b in &self.bodies[i + 1..] {
                if self.self_collision_filter.contains(a, b) {
                    continue;
                }
                let touching = bodies[a].colliders().iter().any(|&ca| {
                    bodies[b].colliders().iter().any(|&cb| {
                        let (ca, cb) = (&colliders[ca], &colliders[cb]);
                        rapier3d::parry::query::intersection_test(
                            ca.position(),
                            ca.shape(),
                            cb.position(),
                            cb.shape(),
                        )
                        .map(|hit| hit.intersecting)
                        .unwrap_or(false)
                    })
                });
                if touching {
                    self.self_collision_filter.pairs.push((a, b));
                }
            }
        }
    }

    /// The contact filter to pass to the physics step.
    pub fn self_collision_filter(&self) -> &SelfCollisionFilter {
        &self.self_collision_filter
    }

    /// Index of the joint called `name` in [`Self::joints`].
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    fn multibody<'a>(&self, set: &'a MultibodyJointSet) -> Option<&'a Multibody> {
        self.multibody.map(|m| {
            set.get_multibody(m)
                .expect("the robot's multibody lives as long as the world")
        })
    }

    fn multibody_mut<'a>(&self, set: &'a mut MultibodyJointSet) -> Option<&'a mut Multibody> {
        self.multibody.map(|m| {
            set.get_multibody_mut(m)
                .expect("the robot's multibody lives as long as the world")
        })
    }

    /// Whether the joints follow their targets kinematically ([`JointDrive::Kinematic`]).
    pub fn is_kinematic(&self) -> bool {
        self.kinematic.is_some()
    }

    /// Positions of all movable joints (rad or m), in [`Self::joints`] order.
    pub fn joint_positions(&self, bodies: &RigidBodySet, set: &MultibodyJointSet) -> Vec<f32> {
        if let Some(mb) = self.multibody(set) {
            return self
                .joints
                .iter()
                .map(|j| mb.link(j.link_id).expect("link").joint.coords()[j.coord_index()])
                .collect();
        }
        let arm = self.kinematic.as_ref().expect("one drive or the other");
        (0..self.joints.len())
            .map(|j| match arm.impulse[j] {
                None => arm.q[j],
                Some(_) => kinematic::measured_position(&self.geometry[j], bodies, &self.bodies),
            })
            .collect()
    }

    /// Velocities of all movable joints (rad/s or m/s).
    pub fn joint_velocities(&self, bodies: &RigidBodySet, set: &MultibodyJointSet) -> Vec<f32> {
        if let Some(mb) = self.multibody(set) {
            return self
                .joints
                .iter()
                .map(|j| mb.joint_velocity(mb.link(j.link_id).expect("link"))[0])
                .collect();
        }
        let arm = self.kinematic.as_ref().expect("one drive or the other");
        (0..self.joints.len())
            .map(|j| match arm.impulse[j] {
                None => arm.qd[j],
                Some(_) => kinematic::measured_velocity(&self.geometry[j], bodies, &self.bodies),
            })
            .collect()
    }

    /// Teleports the joints to `q` with zero velocity (like PyBullet's resetJointState), and sets
    /// the position targets to match so the motors hold it.
    pub fn set_joint_positions(
        &mut self,
        q: &[f32],
        bodies: &mut RigidBodySet,
        sets: JointSets<'_>,
    ) -> Result<()> {
        self.check_len(q, "joint positions")?;
        if let Some(mb) = self.multibody_mut(sets.multibody_joints) {
            let current: Vec<f32> = self
                .joints
                .iter()
                .map(|j| mb.link(j.link_id).expect("link").joint.coords()[j.coord_index()])
                .collect();
            let mut disp = vec![0.0; mb.ndofs()];
            for (j, joint) in self.joints.iter().enumerate() {
                let dof = mb.link(joint.link_id).expect("link").assembly_id();
                disp[dof] = q[j] - current[j];
            }
            mb.apply_displacements(&disp);
            mb.generalized_velocity_mut().fill(0.0);
            mb.forward_kinematics(bodies, true);
            mb.update_rigid_bodies(bodies, true);
        }
        if let Some(arm) = self.kinematic.as_mut() {
            for &j in &arm.ramp_joints {
                arm.q[j] = q[j];
                arm.qd[j] = 0.0;
            }
            let start: Vec<f64> = arm.ramp_joints.iter().map(|&j| q[j] as f64).collect();
            arm.ramp.start(&start);
            let root = pose_to_iso(bodies[self.bodies[0]].position());
            let poses = kinematic::body_poses(root, &self.geometry, self.bodies.len(), q);
            for (b, pose) in poses.iter().enumerate().skip(1) {
                let body = &mut bodies[self.bodies[b]];
                body.set_position(iso_to_pose(pose), true);
                if body.is_kinematic() {
                    body.set_next_kinematic_position(iso_to_pose(pose));
                }
            }
        }
        for &b in &self.bodies {
            if let Some(rb) = bodies.get_mut(b) {
                rb.set_linvel(Vector::ZERO, true);
                rb.set_angvel(Vector::ZERO, true);
            }
        }
        self.targets.copy_from_slice(q);
        self.apply_motors(sets);
        Ok(())
    }

    fn check_len(&self, values: &[f32], what: &str) -> Result<()> {
        if values.len() != self.joints.len() {
            return Err(SimError::Command(format!(
                "{what}: expected {} values (joints {}), got {}",
                self.joints.len(),
                self.joints
                    .iter()
                    .map(|j| j.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                values.len()
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(SimError::Command(format!(
                "{what}: value for joint '{}' is {}",
                self.joints[i].name, values[i]
            )));
        }
        Ok(())
    }

    /// Sets the same PD gains on every joint.
    pub fn set_gains_all(&mut self, gains: PdGains) {
        self.gains.fill(gains);
    }

    /// Sets PD gains of one joint.
    pub fn set_gains(&mut self, joint: usize, gains: PdGains) -> Result<()> {
        if !(gains.kp.is_finite() && gains.kd.is_finite() && gains.kp >= 0.0 && gains.kd >= 0.0) {
            return Err(SimError::Command(format!(
                "gains must be finite and non-negative, got {gains:?}"
            )));
        }
        *self
            .gains
            .get_mut(joint)
            .ok_or_else(|| SimError::Command(format!("no joint {joint}")))? = gains;
        Ok(())
    }

    /// Changes a joint's effort limit (N·m or N), e.g. the gripper's squeezing force.
    pub fn set_effort_limit(&mut self, joint: usize, effort: f32) -> Result<()> {
        if !(effort.is_finite() && effort > 0.0) {
            return Err(SimError::Command(format!(
                "effort limit must be positive, got {effort}"
            )));
        }
        self.joints
            .get_mut(joint)
            .ok_or_else(|| SimError::Command(format!("no joint {joint}")))?
            .effort = effort;
        Ok(())
    }

    /// Sets the viscous damping of a joint (N·m·s/rad or N·s/m).
    pub fn set_joint_damping(
        &mut self,
        joint: usize,
        damping: f32,
        set: &mut MultibodyJointSet,
    ) -> Result<()> {
        if !(damping.is_finite() && damping >= 0.0) {
            return Err(SimError::Command(format!(
                "joint damping must be non-negative, got {damping}"
            )));
        }
        let link_id = self
            .joints
            .get(joint)
            .ok_or_else(|| SimError::Command(format!("no joint {joint}")))?
            .link_id;
        // Kinematic joints follow their targets whatever the damping.
        if let Some(mb) = self.multibody_mut(set) {
            let dof = mb.link(link_id).expect("link").assembly_id();
            mb.damping_mut()[dof] = damping;
        }
        Ok(())
    }

    /// Current PD gains of a joint.
    pub fn gains(&self, joint: usize) -> Option<PdGains> {
        self.gains.get(joint).copied()
    }

    /// Current position targets.
    pub fn position_targets(&self) -> &[f32] {
        &self.targets
    }

    /// Position control: targets clamped to the joint limits, tracked by the PD motors.
    /// Targets of mimic joints are ignored (the coupling drives them).
    pub fn set_position_targets(&mut self, q: &[f32], sets: JointSets<'_>) -> Result<()> {
        self.check_len(q, "position targets")?;
        for (t, (v, j)) in self.targets.iter_mut().zip(q.iter().zip(&self.joints)) {
            *t = v.clamp(j.limits.0, j.limits.1);
        }
        self.mode = DriveMode::Position;
        self.apply_motors(sets);
        Ok(())
    }

    /// Position target of one joint.
    pub fn set_position_target(&mut self, joint: usize, q: f32, sets: JointSets<'_>) -> Result<()> {
        let mut targets = self.targets.clone();
        *targets
            .get_mut(joint)
            .ok_or_else(|| SimError::Command(format!("no joint {joint}")))? = q;
        self.set_position_targets(&targets, sets)
    }

    /// Torque control: motors off, `tau` (clamped to effort limits) applied every physics step.
    pub fn set_torques(&mut self, tau: &[f32], sets: JointSets<'_>) -> Result<()> {
        if self.is_kinematic() {
            return Err(SimError::Command(
                "torque control needs the PD drive (arm.drive = \"pd\"); kinematic joints \
                 follow position targets only"
                    .into(),
            ));
        }
        self.check_len(tau, "torques")?;
        let clamped = tau
            .iter()
            .zip(&self.joints)
            .map(|(t, j)| t.clamp(-j.effort, j.effort))
            .collect();
        self.mode = DriveMode::Torque(clamped);
        self.apply_motors(sets);
        Ok(())
    }

    fn apply_motors(&self, sets: JointSets<'_>) {
        let torque_mode = matches!(self.mode, DriveMode::Torque(_));
        if let Some(mb) = self.multibody_mut(sets.multibody_joints) {
            for (j, joint) in self.joints.iter().enumerate() {
                let link = mb.link_mut(joint.link_id).expect("link");
                let (kp, kd) = if torque_mode || joint.mimic.is_some() {
                    (0.0, 0.0)
                } else {
                    (self.gains[j].kp, self.gains[j].kd)
                };
                if kp == 0.0 && kd == 0.0 {
                    // A motor without gains pushes nothing, but rapier would still build and
                    // solve a constraint for it (with a mass-matrix solve): off instead, with
                    // the same trajectory. The mimic finger's motor is one, and every motor in
                    // torque control (holding 58.7k -> 59.9k steps/s, grasped 38.4k -> 39.6k).
                    link.joint.data.motor_axes &= !JointAxesMask::from(joint.axis());
                    continue;
                }
                link.joint
                    .data
                    .set_motor(joint.axis(), self.targets[j], 0.0, kp, kd);
                link.joint
                    .data
                    .set_motor_max_force(joint.axis(), joint.effort);
            }
        }
        let Some(arm) = &self.kinematic else {
            return;
        };
        // Dynamic joints: PD motors; a mimic joint gets its leader's target (mapped), gains and
        // force, since no coupling ties the two.
        for (j, joint) in self.joints.iter().enumerate() {
            let Some(handle) = arm.impulse[j] else {
                continue;
            };
            let (target, drive) = match joint.mimic {
                Some((leader, multiplier, offset)) => {
                    (multiplier * self.targets[leader] + offset, leader)
                }
                None => (self.targets[j], j),
            };
            if let Some(impulse) = sets.impulse_joints.get_mut(handle, true) {
                let PdGains { kp, kd } = self.gains[drive];
                impulse.data.set_motor(joint.axis(), target, 0.0, kp, kd);
                impulse
                    .data
                    .set_motor_max_force(joint.axis(), self.joints[drive].effort);
            }
        }
    }

    /// Applies this step's joint torques as equal and opposite body torques/forces on the two
    /// links of each joint (called by the scene before every physics step in torque mode).
    pub(crate) fn apply_joint_torques(&self, bodies: &mut RigidBodySet, set: &MultibodyJointSet) {
        let DriveMode::Torque(tau) = &self.mode else {
            return;
        };
        let Some(mb) = self.multibody(set) else {
            return;
        };
        for (joint, &t) in self.joints.iter().zip(tau) {
            if t == 0.0 {
                continue;
            }
            let link = mb.link(joint.link_id).expect("link");
            let parent = mb.link(link.parent_id().unwrap_or(0)).expect("parent");
            let frame1 = link.joint.data.local_frame1;
            let parent_pose = *bodies[parent.rigid_body_handle()].position();
            let axis_world = (parent_pose * frame1).rotation * Vector::X;
            let (child_h, parent_h) = (link.rigid_body_handle(), parent.rigid_body_handle());
            match joint.kind {
                JointKind::Prismatic => {
                    let point = (parent_pose * frame1).translation;
                    bodies[child_h].add_force_at_point(axis_world * t, point, true);
                    bodies[parent_h].add_force_at_point(-axis_world * t, point, true);
                }
                _ => {
                    bodies[child_h].add_torque(axis_world * t, true);
                    bodies[parent_h].add_torque(-axis_world * t, true);
                }
            }
        }
    }

    /// Keeps each multibody joint's limit constraint on only while the joint is past a limit.
    ///
    /// Rapier builds a limit constraint for every limited joint every step, each with a solve of
    /// the arm's mass matrix, though one pushes only once its joint is past a limit (inside, its
    /// impulse bounds are [0, 0] and it changes no velocity). Switching it on by the same test,
    /// on the joint position the step starts from, leaves every trajectory bit for bit the same
    /// (PPO weights after 40k steps identical) and drops 8 of the PD arm's 17 joint constraints:
    /// physics steps/s, holding 54.8k -> 58.7k (+7 %), grasped 37.3k -> 38.4k (+3 %); medians of
    /// 5 alternated runs, quiet AMD EPYC host. Exact only when the step starts from these
    /// positions: one solver iteration per step (the caller checks).
    pub(crate) fn gate_joint_limits(&self, set: &mut MultibodyJointSet) {
        let Some(mb) = self.multibody_mut(set) else {
            return;
        };
        for joint in &self.joints {
            if joint.kind == JointKind::Continuous {
                continue;
            }
            let link = mb.link_mut(joint.link_id).expect("link");
            let q = link.joint.coords()[joint.coord_index()];
            let axis: JointAxesMask = joint.axis().into();
            if q < joint.limits.0 || q > joint.limits.1 {
                link.joint.data.limit_axes |= axis;
            } else {
                link.joint.data.limit_axes &= !axis;
            }
        }
    }

    /// Clears the forces added by [`Self::apply_joint_torques`].
    pub(crate) fn clear_joint_torques(&self, bodies: &mut RigidBodySet) {
        if matches!(self.mode, DriveMode::Torque(_)) {
            for &b in &self.bodies {
                bodies[b].reset_forces(false);
                bodies[b].reset_torques(false);
            }
        }
    }

    /// World pose of a link (merged links included), like PyBullet's getLinkState.
    pub fn link_pose(&self, bodies: &RigidBodySet, link: &str) -> Option<Isometry3<f64>> {
        let l = self.model.link_index(link)?;
        let (b, offset) = self.link_frames[l];
        Some(pose_to_iso(&(bodies[self.bodies[b]].position() * offset)))
    }

    /// Linear and angular velocity of a link frame's origin in the world.
    pub fn link_velocity(&self, bodies: &RigidBodySet, link: &str) -> Option<([f64; 3], [f64; 3])> {
        let l = self.model.link_index(link)?;
        let (b, offset) = self.link_frames[l];
        let body = &bodies[self.bodies[b]];
        let point = (body.position() * offset).translation;
        let v = body.velocity_at_point(point);
        let w = body.angvel();
        Some((
            [v.x as f64, v.y as f64, v.z as f64],
            [w.x as f64, w.y as f64, w.z as f64],
        ))
    }

    /// The body (handle) carrying a link.
    pub fn link_body(&self, link: &str) -> Option<RigidBodyHandle> {
        let l = self.model.link_index(link)?;
        Some(self.bodies[self.link_frames[l].0])
    }

    /// The name of the first link (in model order) that `body` carries: fixed joints merge
    /// links into one body, so a body answers for its root-most link.
    pub fn body_link(&self, body: RigidBodyHandle) -> Option<&str> {
        let b = self.bodies.iter().position(|&h| h == body)?;
        let l = self.link_frames.iter().position(|&(i, _)| i == b)?;
        Some(&self.model.links[l].name)
    }
}
