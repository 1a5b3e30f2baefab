//! Objects and bins: collider shapes from [`ObjectShape`], building them into the world, their
//! queries, and the placement checks tasks use to lay out an episode.

use super::config::{BinConfig, ObjectConfig, ObjectShape, check_grasp_width, subkey};
use super::{ObjectState, Scene, WorldState};
use crate::error::{Result, SimError};
use crate::math::{iso_to_pose, pose_to_iso, yaw_of};
use crate::model::load_mesh;
use crate::robot::groups;
use rand::Rng;
use rapier3d::na::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rapier3d::parry::query;
use rapier3d::prelude::*;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

/// Largest gap at which two shapes count as touching (m).
const TOUCH_DISTANCE: f32 = 0.001;

/// Height above its resting height at which an object is placed, so it starts clear of the table.
const DROP_GAP: f64 = 0.001;

/// Draws per object before a random placement gives up.
const PLACEMENT_DRAWS: usize = 100;

/// Whole layouts drawn before a placement gives up: with five objects 2 cm apart in sorting's
/// 20 × 20 cm area, a first layout without room for the last ended a training run (seed 42)
/// within its first 50k steps.
const PLACEMENT_LAYOUTS: usize = 20;

/// An object's collider shape and its pose in the object's frame.
#[derive(Clone)]
pub(super) struct ObjectGeometry {
    pub shape: SharedShape,
    pub local: Pose,
}

/// Convex hulls of mesh objects, by file and scale bits: per-episode shape changes reuse them.
pub(super) type MeshCache = HashMap<(PathBuf, u32), ObjectGeometry>;

/// What a shape of [`Scene::environment_shapes`] belongs to; indices as in `config.objects`
/// and `config.bins`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ShapeOwner {
    /// The table top.
    Table,
    /// An object, by its index in `config.objects`.
    Object(usize),
    /// A bin's floor or wall, by the bin's index in `config.bins`.
    Bin(usize),
}

/// One robot body's contact with something outside the robot in the last physics step
/// ([`Scene::robot_contacts`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotContact {
    /// The robot link the touching body carries (its root-most link).
    pub link: String,
    /// The body is a finger (its pads are what grasps).
    pub finger: bool,
    /// What the body touched.
    pub other: ShapeOwner,
    /// The force the other body exerted on the robot (N, world frame): the contact's normal
    /// impulses over the step.
    pub force: Vector3<f32>,
}

/// A collider shape at its world pose.
#[derive(Clone)]
pub struct PlacedShape {
    /// What the shape belongs to.
    pub owner: ShapeOwner,
    /// The collider's shape.
    pub shape: SharedShape,
    /// The collider's pose in the world frame.
    pub pose: Pose,
}

/// The handles of one object in the world.
#[derive(Clone, Copy, Debug)]
pub(super) struct ObjectHandles {
    pub body: RigidBodyHandle,
    pub collider: ColliderHandle,
}

/// The collider of `shape`, checked: positive sizes and a narrowest horizontal width the gripper
/// can close on. The error is `(field, problem)` with the field relative to the shape.
pub(super) fn object_geometry(
    shape: &ObjectShape,
    meshes: &mut MeshCache,
) -> std::result::Result<ObjectGeometry, (String, String)> {
    shape.check()?;
    let geometry = match shape {
        ObjectShape::Box { size } => ObjectGeometry {
            shape: SharedShape::cuboid(size[0] / 2.0, size[1] / 2.0, size[2] / 2.0),
            local: Pose::IDENTITY,
        },
        ObjectShape::Cylinder { radius, height } => ObjectGeometry {
            // rapier's cylinder axis is y; stand it upright along z.
            shape: SharedShape::cylinder(height / 2.0, *radius),
            local: Pose::rotation(Vector::X * std::f32::consts::FRAC_PI_2),
        },
        ObjectShape::Sphere { radius } => ObjectGeometry {
            shape: SharedShape::ball(*radius),
            local: Pose::IDENTITY,
        },
        ObjectShape::Mesh { path, scale } => {
            let key = (path.clone(), scale.to_bits());
            match meshes.get(&key) {
                Some(geometry) => geometry.clone(),
                None => {
                    let geometry = mesh_hull(path, *scale).map_err(|p| ("path".to_string(), p))?;
                    meshes.insert(key, geometry.clone());
                    geometry
                }
            }
        }
    };
    if let ObjectShape::Mesh { .. } = shape {
        check_grasp_width(narrowest_width(&geometry)).map_err(|p| (String::new(), p))?;
    }
    Ok(geometry)
}

/// The convex hull of a mesh file's vertices, scaled and centred on their bounding box.
fn mesh_hull(path: &std::path::Path, scale: f32) -> std::result::Result<ObjectGeometry, String> {
    let mesh = load_mesh(path)?;
    let (min, max) = mesh.bounds();
    let centre = Vector::new(min[0] + max[0], min[1] + max[1], min[2] + max[2]) / 2.0;
    let points: Vec<Vector> = mesh
        .vertices
        .iter()
        .map(|v| (Vector::from(*v) - centre) * scale)
        .collect();
    // The hull routine indexes into user geometry: contain any panic.
    let hull = std::panic::catch_unwind(|| SharedShape::convex_hull(&points))
        .ok()
        .flatten()
        .ok_or_else(|| {
            format!(
                "{}: could not build a convex hull from its vertices (flat or degenerate mesh)",
                path.display()
            )
        })?;
    Ok(ObjectGeometry {
        shape: hull,
        local: Pose::IDENTITY,
    })
}

/// Width of a convex shape (in its object frame) along the horizontal unit direction `dir`.
fn width_along(geometry: &ObjectGeometry, dir: Vector) -> f32 {
    let support = geometry
        .shape
        .as_support_map()
        .expect("object shapes are convex");
    let ahead = support.support_point(&geometry.local, dir).dot(dir);
    let behind = support.support_point(&geometry.local, -dir).dot(dir);
    ahead - behind
}

/// The narrowest horizontal width of an upright object, over yaws in 0.5° steps (m).
fn narrowest_width(geometry: &ObjectGeometry) -> f32 {
    (0..360)
        .map(|k| {
            let angle = k as f32 * std::f32::consts::PI / 360.0;
            width_along(geometry, Vector::new(angle.cos(), angle.sin(), 0.0))
        })
        .fold(f32::INFINITY, f32::min)
}

/// Half the vertical extent of an upright object (m).
fn half_height(geometry: &ObjectGeometry) -> f32 {
    let aabb = geometry.shape.compute_aabb(&geometry.local);
    (aabb.maxs.z - aabb.mins.z) / 2.0
}

/// Adds a dynamic object, disabled until a placement enables it.
pub(super) fn insert_object(
    world: &mut WorldState,
    object: &ObjectConfig,
    geometry: &ObjectGeometry,
) -> ObjectHandles {
    let body = world.bodies.insert(
        RigidBodyBuilder::dynamic()
            .can_sleep(false)
            .enabled(false)
            .angular_damping(object.angular_damping)
            .build(),
    );
    let collider = world.colliders.insert_with_parent(
        ColliderBuilder::new(geometry.shape.clone())
            .position(geometry.local)
            .mass(object.mass)
            .friction(object.friction)
            .collision_groups(InteractionGroups::new(
                groups::OBJECT,
                Group::ALL,
                InteractionTestMode::And,
            ))
            .build(),
        body,
        &mut world.bodies,
    );
    ObjectHandles { body, collider }
}

/// Adds a bin as one fixed body at `pose` (the middle of its underside, on the table top): a
/// floor and four walls in the table's collision group.
pub(super) fn insert_bin(
    world: &mut WorldState,
    bin: &BinConfig,
    pose: Pose,
    friction: f32,
) -> RigidBodyHandle {
    let body = world
        .bodies
        .insert(RigidBodyBuilder::fixed().pose(pose).build());
    let t = bin.wall_thickness;
    let [ix, iy] = bin.inner_size.map(|v| v / 2.0);
    let h = bin.wall_height;
    // (half extents, centre) of the floor and the walls at −x, +x, −y, +y.
    let parts = [
        ([ix + t, iy + t, t / 2.0], [0.0, 0.0, t / 2.0]),
        ([t / 2.0, iy + t, h / 2.0], [-(ix + t / 2.0), 0.0, h / 2.0]),
        ([t / 2.0, iy + t, h / 2.0], [ix + t / 2.0, 0.0, h / 2.0]),
        ([ix, t / 2.0, h / 2.0], [0.0, -(iy + t / 2.0), h / 2.0]),
        ([ix, t / 2.0, h / 2.0], [0.0, iy + t / 2.0, h / 2.0]),
    ];
    for (half, centre) in parts {
        world.colliders.insert_with_parent(
            ColliderBuilder::cuboid(half[0], half[1], half[2])
                .translation(Vector::from(centre))
                .friction(friction)
                .collision_groups(InteractionGroups::new(
                    groups::TABLE,
                    groups::ROBOT | groups::OBJECT,
                    InteractionTestMode::And,
                ))
                .build(),
            body,
            &mut world.bodies,
        );
    }
    body
}

/// The world pose of a collider from its body's pose (valid right after a teleport, before the
/// next step moves the collider).
fn collider_pose(world: &WorldState, handle: ColliderHandle) -> Pose {
    let collider = &world.colliders[handle];
    let local = collider.position_wrt_parent().copied().unwrap_or_default();
    match collider.parent() {
        Some(body) => world.bodies[body].position() * local,
        None => *collider.position(),
    }
}

impl Scene {
    fn handles(&self, i: usize) -> ObjectHandles {
        *self.objects.get(i).unwrap_or_else(|| {
            panic!(
                "object index {i} out of range: the scene has {} objects",
                self.objects.len()
            )
        })
    }

    fn bin_body(&self, j: usize) -> RigidBodyHandle {
        *self.bin_bodies.get(j).unwrap_or_else(|| {
            panic!(
                "bin index {j} out of range: the scene has {} bins",
                self.bin_bodies.len()
            )
        })
    }

    /// The geometry object `i` has this episode.
    fn geometry(&self, i: usize) -> ObjectGeometry {
        let collider = &self.world.colliders[self.handles(i).collider];
        ObjectGeometry {
            shape: collider.shared_shape().clone(),
            local: collider.position_wrt_parent().copied().unwrap_or_default(),
        }
    }

    // ── Objects ────────────────────────────────────────────────────────────
    //
    // `i` is an object's index in `config.objects`; an index out of range panics, like slice
    // indexing.

    /// Number of objects (parked or not).
    pub fn num_objects(&self) -> usize {
        self.objects.len()
    }

    /// The name object `i` is known by (its `name` setting).
    pub fn object_name(&self, i: usize) -> &str {
        &self.object_config(i).name
    }

    /// Index of the object called `name`.
    pub fn object_index(&self, name: &str) -> Option<usize> {
        self.layout.objects.iter().position(|o| o.name == name)
    }

    /// The object's settings in force this episode: the configured ones unless
    /// [`Self::set_object_params`] changed its shape, mass or friction since the last reset.
    pub fn object_config(&self, i: usize) -> &ObjectConfig {
        self.handles(i);
        &self.layout.objects[i]
    }

    /// Pose and velocity of object `i`.
    pub fn object_state(&self, i: usize) -> ObjectState {
        let body = &self.world.bodies[self.handles(i).body];
        let v = body.linvel();
        let w = body.angvel();
        ObjectState {
            pose: pose_to_iso(body.position()),
            linvel: [v.x as f64, v.y as f64, v.z as f64],
            angvel: [w.x as f64, w.y as f64, w.z as f64],
        }
    }

    /// Whether object `i` is parked: out of the simulation, beside the table (see
    /// [`Self::park_objects`]).
    pub fn object_parked(&self, i: usize) -> bool {
        !self.world.bodies[self.handles(i).body].is_enabled()
    }

    /// Places object `i` at `pose` (world) with zero velocity, taking it out of the parking.
    pub fn set_object_pose(&mut self, i: usize, pose: &Isometry3<f64>) -> Result<()> {
        let handles = self.handles(i);
        let p = iso_to_pose(pose);
        if !p.is_finite() {
            return Err(SimError::Command(format!(
                "pose of object '{}' is not finite: {pose}",
                self.object_name(i)
            )));
        }
        let body = &mut self.world.bodies[handles.body];
        body.set_enabled(true);
        body.set_position(p, true);
        body.set_linvel(Vector::ZERO, true);
        body.set_angvel(Vector::ZERO, true);
        Ok(())
    }

    /// Changes object `i`'s shape, mass and friction for this episode (domain randomisation);
    /// the next reset restores the configured ones. Call it while the object is parked, before
    /// placing it: a larger shape would otherwise overlap what it rests on.
    pub fn set_object_params(
        &mut self,
        i: usize,
        shape: &ObjectShape,
        mass: f32,
        friction: f32,
    ) -> Result<()> {
        let handles = self.handles(i);
        let name = &self.layout.objects[i].name;
        if !(mass.is_finite() && mass > 0.0) {
            return Err(SimError::Command(format!(
                "object '{name}': mass {mass} must be a positive number"
            )));
        }
        if !(friction.is_finite() && friction >= 0.0) {
            return Err(SimError::Command(format!(
                "object '{name}': friction {friction} must be a non-negative number"
            )));
        }
        let changed_shape = self.layout.objects[i].shape != *shape;
        let geometry = if changed_shape {
            let geometry =
                object_geometry(shape, &mut self.meshes).map_err(|(field, problem)| {
                    SimError::Command(format!(
                        "object '{name}': {} {problem}",
                        subkey("shape", &field)
                    ))
                })?;
            Some(geometry)
        } else {
            None
        };
        let collider = &mut self.world.colliders[handles.collider];
        if let Some(geometry) = geometry {
            collider.set_shape(geometry.shape);
            collider.set_position_wrt_parent(geometry.local);
        }
        collider.set_mass(mass);
        collider.set_friction(friction);
        let in_force = &mut Arc::make_mut(&mut self.layout).objects[i];
        if changed_shape {
            in_force.shape = shape.clone();
        }
        in_force.mass = mass;
        in_force.friction = friction;
        Ok(())
    }

    /// Half the height of object `i` standing upright (m).
    pub fn object_half_height(&self, i: usize) -> f64 {
        half_height(&self.geometry(i)) as f64
    }

    /// Half extents of object `i`'s bounding box in its own frame (m): what a policy needs to
    /// know of an object's size.
    pub fn object_half_extents(&self, i: usize) -> [f32; 3] {
        let g = self.geometry(i);
        let aabb = g.shape.compute_aabb(&g.local);
        let half = (aabb.maxs - aabb.mins) / 2.0;
        [half.x, half.y, half.z]
    }

    /// World z of object `i`'s centre when it rests upright on the table (m).
    pub fn object_rest_height(&self, i: usize) -> f64 {
        self.table_top as f64 + self.object_half_height(i)
    }

    /// Whether object `i` is off the table: dropped below its top, beyond its edges, or parked.
    pub fn object_off_table(&self, i: usize) -> bool {
        let p = self.object_state(i).pose.translation.vector;
        let t = &self.config.table;
        p.z < self.table_top as f64 - 2.0 * self.object_half_height(i)
            || (p.x - t.center[0] as f64).abs() > t.size[0] as f64 / 2.0
            || (p.y - t.center[1] as f64).abs() > t.size[1] as f64 / 2.0
    }

    /// The TCP yaw for a top-down grasp of object `i` as it is now: the fingers close across its
    /// narrowest horizontal width (a box's faces, any side of a cylinder or sphere), choosing
    /// among the equally narrow yaws the nearest to the home TCP yaw (least wrist travel).
    pub fn object_grasp_yaw(&self, i: usize) -> f64 {
        use std::f64::consts::{FRAC_PI_2, PI};
        let pose = self.object_state(i).pose;
        let geometry = self.geometry(i);
        let object_yaw = yaw_of(&pose.rotation);
        let reference = yaw_of(&self.home_tcp.rotation);
        // Fingers close along the tool y axis: world direction (sin yaw, −cos yaw).
        let width_at = |yaw: f64| {
            let relative = (yaw - object_yaw) as f32;
            width_along(&geometry, Vector::new(relative.sin(), -relative.cos(), 0.0))
        };
        // A box's faces are at quarter turns of its yaw; round shapes fit at the reference itself.
        let steps = 18;
        let candidates = std::iter::once(reference).chain((-4..=4).flat_map(|k| {
            (0..steps).map(move |m| {
                object_yaw + k as f64 * FRAC_PI_2 + m as f64 * FRAC_PI_2 / steps as f64
            })
        }));
        let widths: Vec<(f64, f32)> = candidates.map(|yaw| (yaw, width_at(yaw))).collect();
        let narrowest = widths.iter().map(|w| w.1).fold(f32::INFINITY, f32::min);
        let mut best = reference;
        let mut best_gap = f64::INFINITY;
        for &(candidate, width) in &widths {
            if width > narrowest + 1e-4 {
                continue;
            }
            let gap = (candidate - reference + PI).rem_euclid(2.0 * PI) - PI;
            if gap.abs() < best_gap {
                best_gap = gap.abs();
                best = reference + gap;
            }
        }
        best
    }

    /// Whether two colliders touch: a contact point of the last step is at most
    /// [`TOUCH_DISTANCE`] apart. (rapier also keeps speculative contacts up to 2 cm apart.)
    fn touching(&self, a: ColliderHandle, b: ColliderHandle) -> bool {
        self.world
            .narrow_phase
            .contact_pair(a, b)
            .is_some_and(|pair| {
                pair.solver_manifolds().iter().any(|m| {
                    m.data
                        .solver_contacts
                        .iter()
                        .any(|c| c.dist <= TOUCH_DISTANCE)
                })
            })
    }

    /// Whether each finger pad (left, right) touches object `i`.
    pub fn finger_contacts(&self, i: usize) -> [bool; 2] {
        let object = self.handles(i).collider;
        self.finger_bodies.map(|b| {
            self.world.bodies[b]
                .colliders()
                .iter()
                .any(|&c| self.touching(c, object))
        })
    }

    /// Whether two named things touch: robot link names, object names, bin names or `"table"`.
    /// `None` if a name is unknown.
    pub fn in_contact(&self, a: &str, b: &str) -> Option<bool> {
        let a = self.colliders_of(a)?;
        let b = self.colliders_of(b)?;
        Some(
            a.iter()
                .any(|&ca| b.iter().any(|&cb| self.touching(ca, cb))),
        )
    }

    /// Every contact between a robot body and an object, the table or a bin part in the last
    /// physics step, with its force on the robot; pairs between robot links are left out.
    pub fn robot_contacts(&self) -> Vec<RobotContact> {
        let owner_of = |c: ColliderHandle| -> Option<ShapeOwner> {
            if c == self.table_collider {
                return Some(ShapeOwner::Table);
            }
            if let Some(i) = self.objects.iter().position(|o| o.collider == c) {
                return Some(ShapeOwner::Object(i));
            }
            let body = self.world.colliders[c].parent()?;
            let j = self.bin_bodies.iter().position(|&b| b == body)?;
            Some(ShapeOwner::Bin(j))
        };
        let mut out = Vec::new();
        for &body in &self.robot.bodies {
            let link = self.robot.body_link(body).unwrap_or_default();
            let finger = self.finger_bodies.contains(&body);
            for &c in self.world.bodies[body].colliders() {
                for pair in self.world.narrow_phase.contact_pairs_with(c) {
                    // The manifolds' normals point from collider 1 to collider 2, and the
                    // impulses push the two apart.
                    let (other, sign) = if pair.collider1 == c {
                        (pair.collider2, -1.0)
                    } else {
                        (pair.collider1, 1.0)
                    };
                    let Some(owner) = owner_of(other) else {
                        continue;
                    };
                    let impulse: Vector3<f32> = pair.total_impulse().into();
                    if impulse == Vector3::zeros() {
                        continue;
                    }
                    out.push(RobotContact {
                        link: link.to_string(),
                        finger,
                        other: owner,
                        force: impulse * (sign / self.params.dt),
                    });
                }
            }
        }
        out
    }

    fn colliders_of(&self, name: &str) -> Option<Vec<ColliderHandle>> {
        if name == "table" {
            return Some(vec![self.table_collider]);
        }
        if let Some(i) = self.object_index(name) {
            return Some(vec![self.objects[i].collider]);
        }
        if let Some(j) = self.layout.bins.iter().position(|b| b.name == name) {
            return Some(self.world.bodies[self.bin_bodies[j]].colliders().to_vec());
        }
        let body = self.robot.link_body(name)?;
        Some(self.world.bodies[body].colliders().to_vec())
    }

    // ── Shapes for renderers ───────────────────────────────────────────────

    /// The table, every placed object (parked ones are left out) and every bin part as collider
    /// shapes with their world poses: what a renderer draws besides the robot (whose links it
    /// takes from the robot description's visuals and [`Self::link_pose`]). Poses come from the
    /// bodies, so they are right just after a teleport too.
    pub fn environment_shapes(&self) -> Vec<PlacedShape> {
        let mut out = Vec::with_capacity(1 + self.objects.len() + 5 * self.bin_bodies.len());
        let placed = |owner: ShapeOwner, c: ColliderHandle| PlacedShape {
            owner,
            shape: self.world.colliders[c].shared_shape().clone(),
            pose: collider_pose(&self.world, c),
        };
        out.push(placed(ShapeOwner::Table, self.table_collider));
        for (i, handles) in self.objects.iter().enumerate() {
            if !self.object_parked(i) {
                out.push(placed(ShapeOwner::Object(i), handles.collider));
            }
        }
        for (j, &body) in self.bin_bodies.iter().enumerate() {
            for &c in self.world.bodies[body].colliders() {
                out.push(placed(ShapeOwner::Bin(j), c));
            }
        }
        out
    }

    // ── Bins ───────────────────────────────────────────────────────────────

    /// The bins, with their centres in force this episode (see [`Self::set_bin_xy`]).
    pub fn bins(&self) -> &[BinConfig] {
        &self.layout.bins
    }

    /// World pose of bin `j`'s floor centre: the middle of the floor's top face, where objects
    /// land; axes parallel to the arm base frame's.
    pub fn bin_pose(&self, j: usize) -> Isometry3<f64> {
        let body = pose_to_iso(self.world.bodies[self.bin_body(j)].position());
        let floor = self.layout.bins[j].wall_thickness as f64;
        body * Translation3::new(0.0, 0.0, floor)
    }

    /// The body pose of a bin centred at `xy` in the arm base frame: on the table top, turned
    /// with the base.
    pub(super) fn bin_body_pose(&self, xy: [f32; 2]) -> Pose {
        let world = self.base * Point3::new(xy[0] as f64, xy[1] as f64, 0.0);
        let yaw = yaw_of(&self.base.rotation);
        iso_to_pose(&Isometry3::from_parts(
            Translation3::new(world.x, world.y, self.table_top as f64),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        ))
    }

    /// Moves bin `j` to `xy` (arm base frame, m), e.g. per episode; the next reset restores the
    /// configured centre. Errors if the bin would overhang the table.
    pub fn set_bin_xy(&mut self, j: usize, xy: [f32; 2]) -> Result<()> {
        let body = self.bin_body(j);
        if xy.iter().any(|v| !v.is_finite()) {
            return Err(SimError::Command(format!(
                "bin '{}': centre {xy:?} is not finite",
                self.layout.bins[j].name
            )));
        }
        if self.config.bin_overhangs(xy, &self.layout.bins[j]) {
            return Err(SimError::Command(format!(
                "bin '{}' at {xy:?} (arm base frame) would overhang the table edge",
                self.layout.bins[j].name
            )));
        }
        let pose = self.bin_body_pose(xy);
        self.world.bodies[body].set_position(pose, false);
        // Move the colliders now too, so placement checks see the bin before the next step.
        for c in self.world.bodies[body].colliders().to_vec() {
            let at = collider_pose(&self.world, c);
            self.world.colliders[c].set_position(at);
        }
        Arc::make_mut(&mut self.layout).bins[j].center = xy;
        Ok(())
    }

    /// Whether object `i`'s centre is inside bin `j`: within its inner footprint and below the
    /// top of its walls.
    pub fn object_in_bin(&self, i: usize, j: usize) -> bool {
        if self.object_parked(i) {
            return false;
        }
        let bin = &self.layout.bins[j];
        let floor = self.bin_pose(j);
        let centre = self.object_state(i).pose.translation.vector;
        let local = floor.inverse_transform_point(&Point3::from(centre));
        let wall_top = (bin.wall_height - bin.wall_thickness) as f64;
        local.x.abs() <= bin.inner_size[0] as f64 / 2.0
            && local.y.abs() <= bin.inner_size[1] as f64 / 2.0
            && local.z < wall_top
    }

    // ── Placement ──────────────────────────────────────────────────────────

    /// Whether object `i`, with its current shape, could stand at `pose` (world): it would
    /// intersect no robot link, and keep 2 mm from every other placed object and every bin.
    /// The table is not checked (objects rest on it).
    pub fn pose_is_free(&self, i: usize, pose: &Isometry3<f64>) -> bool {
        let geometry = self.geometry(i);
        let at = iso_to_pose(pose) * geometry.local;
        let shape = geometry.shape.as_ref();
        let intersects = |c: ColliderHandle| {
            let other = &self.world.colliders[c];
            query::intersection_test(&at, shape, &collider_pose(&self.world, c), other.shape())
                .map(|hit| hit.intersecting)
                .unwrap_or(true)
        };
        let too_close = |c: ColliderHandle| {
            let other = &self.world.colliders[c];
            query::distance(&at, shape, &collider_pose(&self.world, c), other.shape())
                .map(|d| d.distance < self.config.placement.clearance)
                .unwrap_or(true)
        };
        let robot_hit = self.robot.bodies.iter().any(|&b| {
            self.world.bodies[b]
                .colliders()
                .iter()
                .any(|&c| intersects(c))
        });
        if robot_hit {
            return false;
        }
        let object_near = (0..self.objects.len())
            .filter(|&k| k != i && !self.object_parked(k))
            .any(|k| too_close(self.objects[k].collider));
        if object_near {
            return false;
        }
        !self.bin_bodies.iter().any(|&b| {
            self.world.bodies[b]
                .colliders()
                .iter()
                .any(|&c| too_close(c))
        })
    }

    /// Whether a top-down grasp of an object at `pose` can be reached: the grasp pose and the
    /// pre-grasp 15 cm above it solve by IK from the current arm joints.
    pub fn reachable_from_above(&self, pose: &Isometry3<f64>) -> bool {
        self.reachable_from_above_with(pose, &self.arm_positions())
    }

    fn reachable_from_above_with(&self, pose: &Isometry3<f64>, seed: &[f32]) -> bool {
        let centre = pose.translation.vector;
        let yaw = self.grasp_yaw(&pose.rotation);
        [0.0, 0.15].iter().all(|lift| {
            let target = self.top_down_pose(centre + Vector3::new(0.0, 0.0, *lift), yaw);
            self.solve_ik(&target, seed).is_ok()
        })
    }

    /// The pose object `i` waits at while parked: in a row beside the table's −y edge, at table
    /// height.
    fn parking_pose(&self, i: usize) -> Pose {
        let t = &self.config.table;
        Pose::translation(
            t.center[0] - t.size[0] / 2.0 + 0.1 * (i as f32 + 0.5),
            t.center[1] - t.size[1] / 2.0 - 0.25,
            self.table_top + half_height(&self.geometry(i)),
        )
    }

    /// Takes every object out of the simulation: disabled (no contacts, no cost per step, no
    /// effect on [`Self::settle`]) and moved beside the table. [`Self::set_object_pose`] brings
    /// one back.
    pub fn park_objects(&mut self) {
        for i in 0..self.objects.len() {
            let pose = self.parking_pose(i);
            let body = &mut self.world.bodies[self.objects[i].body];
            body.set_enabled(false);
            body.set_position(pose, false);
            body.set_linvel(Vector::ZERO, false);
            body.set_angvel(Vector::ZERO, false);
        }
    }

    /// Steps until every placed object rests (speed below 1 mm/s), at most one simulated second.
    /// Settling belongs to setting an episode up, so [`Self::time`] does not advance.
    pub fn settle(&mut self) -> Result<()> {
        let time = self.time;
        let max_steps = (1.0 / self.params.dt).ceil() as usize;
        for step in 0..max_steps {
            self.step_physics()?;
            let resting = (0..self.objects.len())
                .filter(|&i| !self.object_parked(i))
                .all(|i| {
                    let s = self.object_state(i);
                    let speed =
                        Vector3::from(s.linvel).norm() + Vector3::from(s.angvel).norm() * 0.05;
                    speed < 1e-3
                });
            if step >= 4 && resting {
                break;
            }
        }
        self.time = time;
        self.check_finite()
    }

    /// Parks every object, then places each, in config order, uniform in the placement area
    /// with uniform yaw, redrawing until it is reachable from above and free (see
    /// [`Self::pose_is_free`]); a layout that leaves no room for an object is drawn again
    /// whole, up to [`PLACEMENT_LAYOUTS`] times. Then settles. Returns the object poses.
    pub fn place_objects_at_random(&mut self, rng: &mut impl Rng) -> Result<Vec<Isometry3<f64>>> {
        let mut layout = 0;
        let mut i = 0;
        self.park_objects();
        while i < self.objects.len() {
            match self.draw_free_pose(i, rng) {
                Some(pose) => {
                    self.set_object_pose(i, &pose)?;
                    i += 1;
                }
                None if layout + 1 < PLACEMENT_LAYOUTS => {
                    layout += 1;
                    i = 0;
                    self.park_objects();
                }
                None => {
                    return Err(SimError::config(
                        "placement",
                        format!(
                            "no reachable, collision-free placement for object '{}' found in \
                             {PLACEMENT_DRAWS} draws, in each of {PLACEMENT_LAYOUTS} layouts; \
                             check the area, the bins, the number of objects and the clearance \
                             ({} m)",
                            self.object_name(i),
                            self.config.placement.clearance
                        ),
                    ));
                }
            }
        }
        self.settle()?;
        Ok((0..self.objects.len())
            .map(|i| self.object_state(i).pose)
            .collect())
    }

    /// Up to [`PLACEMENT_DRAWS`] uniform draws of object `i`'s pose in the placement area (at
    /// its rest height, a little above); the first free and reachable from above.
    fn draw_free_pose(&self, i: usize, rng: &mut impl Rng) -> Option<Isometry3<f64>> {
        let p = &self.config.placement;
        let seed = self.arm_positions();
        let base_yaw = yaw_of(&self.base.rotation);
        let rest = self.object_rest_height(i) + DROP_GAP;
        (0..PLACEMENT_DRAWS).find_map(|_| {
            let local_x = p.center[0] + (rng.random::<f32>() - 0.5) * p.size[0];
            let local_y = p.center[1] + (rng.random::<f32>() - 0.5) * p.size[1];
            let yaw = (rng.random::<f32>() * 2.0 - 1.0) * p.yaw_range;
            let world_xy = self.base * Point3::new(local_x as f64, local_y as f64, 0.0);
            let pose = Isometry3::from_parts(
                Translation3::new(world_xy.x, world_xy.y, rest),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw as f64 + base_yaw),
            );
            (self.pose_is_free(i, &pose) && self.reachable_from_above_with(&pose, &seed))
                .then_some(pose)
        })
    }
}
