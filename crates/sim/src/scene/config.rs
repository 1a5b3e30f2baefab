//! Scene settings: physics, table, objects, bins, placement, gripper and arm, with validation
//! whose errors name the key (`objects[1].shape.radius`).

use crate::error::{Result, SimError};
use crate::model::MeshCollision;
use serde::{Deserialize, Serialize};
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
    /// Gravitational acceleration (m/s²), pointing down world z.
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
    /// Friction coefficient of the table top, also used by the bins (positive).
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

/// The shape of an object, in its own frame. At rest it stands upright on the table: box and
/// cylinder axes along world z, a mesh as it is modelled (its z up).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ObjectShape {
    /// Edge lengths along x, y, z (m).
    Box {
        /// Edge lengths along x, y, z (m), positive.
        size: [f32; 3],
    },
    /// Upright: the axis along z (m).
    Cylinder {
        /// Radius (m), positive.
        radius: f32,
        /// Height along z (m), positive.
        height: f32,
    },
    /// A ball.
    Sphere {
        /// Radius (m), positive.
        radius: f32,
    },
    /// An STL or OBJ file scaled by `scale` (file units → m). The collider is the convex hull of
    /// the scaled vertices, centred on the middle of their bounding box.
    Mesh {
        /// The mesh file; a relative path is taken from the working directory.
        path: PathBuf,
        /// Factor from file units to metres, positive.
        scale: f32,
    },
}

/// One object on the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectConfig {
    /// Unique among objects and bins; also the name [`super::Scene::in_contact`] knows it by.
    pub name: String,
    /// Shape and size.
    pub shape: ObjectShape,
    /// Mass (kg).
    #[serde(default = "default_object_mass")]
    pub mass: f32,
    /// Friction coefficient (positive).
    #[serde(default = "default_object_friction")]
    pub friction: f32,
    /// Linear RGB in 0..1, for renderers.
    #[serde(default = "default_object_color")]
    pub color: [f32; 3],
    /// Damping of the object's spin (1/s, not negative): stands in for rolling resistance,
    /// which the contact model lacks, so that a cylinder on its side comes to rest instead of
    /// rolling wall to wall in a bin.
    #[serde(default)]
    pub angular_damping: f32,
}

fn default_object_mass() -> f32 {
    0.1
}

fn default_object_friction() -> f32 {
    0.8
}

fn default_object_color() -> [f32; 3] {
    [0.8, 0.1, 0.1]
}

impl Default for ObjectConfig {
    /// The task's 5 cm red cube.
    fn default() -> Self {
        Self {
            name: "cube".into(),
            shape: ObjectShape::Box {
                size: [0.05, 0.05, 0.05],
            },
            mass: default_object_mass(),
            friction: default_object_friction(),
            color: default_object_color(),
            angular_damping: 0.0,
        }
    }
}

/// An open box fixed on the table: a floor and four walls, all `wall_thickness` thick, with the
/// table's friction. Its sides are parallel to the arm base frame axes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BinConfig {
    /// Unique among objects and bins.
    pub name: String,
    /// Centre in the arm base frame x, y (m).
    pub center: [f32; 2],
    /// Inside extent along x and y (m).
    pub inner_size: [f32; 2],
    /// Height of the wall tops above the table top (m).
    pub wall_height: f32,
    /// Thickness of the walls and the floor (m).
    pub wall_thickness: f32,
    /// Linear RGB in 0..1, for renderers.
    pub color: [f32; 3],
}

impl Default for BinConfig {
    fn default() -> Self {
        Self {
            name: "bin".into(),
            center: [0.45, 0.3],
            inner_size: [0.14, 0.14],
            wall_height: 0.05,
            wall_thickness: 0.01,
            color: [0.3, 0.35, 0.45],
        }
    }
}

/// Where [`super::Scene::reset`] places objects: uniform in a rectangle on the table, uniform yaw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlacementConfig {
    /// Centre of the area, in the arm base frame x, y (m).
    pub center: [f32; 2],
    /// Extent of the area along x and y (m).
    pub size: [f32; 2],
    /// Yaw drawn from [-yaw_range, yaw_range] (rad).
    pub yaw_range: f32,
    /// Least gap between an object and the other objects and the bins (m): room for the open
    /// fingers beside a neighbour when several objects share the table.
    pub clearance: f32,
}

impl Default for PlacementConfig {
    fn default() -> Self {
        Self {
            center: [0.5, 0.0],
            size: [0.4, 0.4],
            yaw_range: std::f32::consts::PI,
            clearance: 0.002,
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
    /// Stiffness of the finger drive (N/m), positive.
    pub kp: f32,
    /// Damping of the finger drive (N·s/m), not negative.
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
    /// Translation (m).
    pub xyz: [f32; 3],
    /// Roll, pitch, yaw about the fixed x, y, z axes (rad).
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
    /// Damping gain of the arm joints (N·m·s/rad), not negative.
    pub kd: f32,
    /// Rotor inertia added to every joint (kg·m²).
    pub armature: f32,
    /// Contacts between non-adjacent links of the arm and gripper.
    pub self_collision: bool,
    /// How mesh collision shapes of the URDF become convex shapes.
    pub mesh_collision: MeshCollision,
    /// How the arm's joints are simulated: `"pd"`, torque-level PD motors (`kp`, `kd`,
    /// `armature`), or `"kinematic"`, joints that follow their targets within the speed and
    /// acceleration caps below as the real arm's position controller makes them (faster to
    /// step; the gripper stays dynamic either way). Torque control needs `"pd"`. With
    /// `"kinematic"` set `physics.pgs_iterations = 12`: the fingers then hang on impulse joints,
    /// which need more sweeps than the multibody to hold a cube while the arm moves.
    pub drive: ArmDrive,
    /// Joint speed cap of the kinematic drive (deg/s); the FR5's joints reach 180 deg/s.
    pub kinematic_speed_deg_s: f32,
    /// Joint acceleration cap of the kinematic drive (deg/s²): the deployment's safety default.
    pub kinematic_acc_deg_s2: f32,
    /// Tracking lag of the kinematic drive (s): each joint follows the ramp's set point through
    /// a first-order lag with this time constant, so at a steady speed v it trails by
    /// `lag · v`, as a PD arm trails by `kd / kp · v` (0.05 s with the default gains) and a real
    /// drive by its servo delay. 0 (the default): the joints sit on the set point.
    pub kinematic_lag_s: f32,
}

/// See [`ArmConfig::drive`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ArmDrive {
    /// Torque-level PD motors.
    #[default]
    Pd,
    /// Joints follow their targets through the speed and acceleration caps.
    Kinematic,
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
            drive: ArmDrive::Pd,
            kinematic_speed_deg_s: 180.0,
            kinematic_acc_deg_s2: 720.0,
            kinematic_lag_s: 0.0,
        }
    }
}

/// Everything that defines a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// Time step, solver and gravity.
    pub physics: PhysicsConfig,
    /// The table the arm stands on.
    pub table: TableConfig,
    /// 1 to [`MAX_OBJECTS`] objects; tasks decide which are placed in an episode.
    pub objects: Vec<ObjectConfig>,
    /// Open boxes on the table (none by default).
    pub bins: Vec<BinConfig>,
    /// Where objects are placed at reset.
    pub placement: PlacementConfig,
    /// The gripper's drive and pads.
    pub gripper: GripperConfig,
    /// The arm, its mount and its drives.
    pub arm: ArmConfig,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            physics: PhysicsConfig::default(),
            table: TableConfig::default(),
            objects: vec![ObjectConfig::default()],
            bins: Vec::new(),
            placement: PlacementConfig::default(),
            gripper: GripperConfig::default(),
            arm: ArmConfig::default(),
        }
    }
}

/// The most objects a scene holds.
pub const MAX_OBJECTS: usize = 16;

/// The widest an object may be, across its narrowest horizontal direction, for the 90 mm gripper
/// to close on it with some margin (m).
pub const MAX_GRASP_WIDTH: f32 = 0.085;

fn positive(key: &str, v: f32) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(SimError::config(
            key,
            format!("must be a positive number, got {v}"),
        ))
    }
}

fn unit_color(key: &str, color: &[f32; 3]) -> Result<()> {
    if color.iter().all(|c| (0.0..=1.0).contains(c)) {
        Ok(())
    } else {
        Err(SimError::config(
            key,
            format!("must hold three values in 0..=1 (linear RGB), got {color:?}"),
        ))
    }
}

impl ObjectShape {
    /// Checks the dimensions; the error is `(field, problem)`, the field relative to the shape
    /// (`radius`, `size[2]`, …). The width check of meshes needs the file: see
    /// [`super::Scene::new`].
    pub(crate) fn check(&self) -> std::result::Result<(), (String, String)> {
        let positive = |field: &str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err((
                    field.to_string(),
                    format!("must be a positive number, got {v}"),
                ))
            }
        };
        match self {
            ObjectShape::Box { size } => {
                for (k, v) in size.iter().enumerate() {
                    positive(&format!("size[{k}]"), *v)?;
                }
            }
            ObjectShape::Cylinder { radius, height } => {
                positive("radius", *radius)?;
                positive("height", *height)?;
            }
            ObjectShape::Sphere { radius } => positive("radius", *radius)?,
            ObjectShape::Mesh { path, scale } => {
                if path.as_os_str().is_empty() {
                    return Err(("path".into(), "is empty".into()));
                }
                positive("scale", *scale)?;
            }
        }
        if let Some(width) = self.narrowest_width() {
            check_grasp_width(width).map_err(|problem| (String::new(), problem))?;
        }
        Ok(())
    }

    /// The narrowest horizontal width at rest (m), where it follows from the parameters alone.
    fn narrowest_width(&self) -> Option<f32> {
        match self {
            ObjectShape::Box { size } => Some(size[0].min(size[1])),
            ObjectShape::Cylinder { radius, .. } | ObjectShape::Sphere { radius } => {
                Some(2.0 * radius)
            }
            ObjectShape::Mesh { .. } => None,
        }
    }
}

/// The problem, if an object `width` wide (narrowest horizontal width) cannot be grasped.
pub(crate) fn check_grasp_width(width: f32) -> std::result::Result<(), String> {
    if width <= MAX_GRASP_WIDTH {
        Ok(())
    } else {
        Err(format!(
            "its narrowest horizontal width is {width:.4} m; it must be at most {MAX_GRASP_WIDTH} m \
             to fit the 90 mm gripper opening"
        ))
    }
}

/// Joins a key and a field of it (`objects[0].shape` + `radius`).
pub(crate) fn subkey(key: &str, field: &str) -> String {
    if field.is_empty() {
        key.to_string()
    } else {
        format!("{key}.{field}")
    }
}

impl SceneConfig {
    /// Checks ranges; the error names the key.
    pub fn validate(&self) -> Result<()> {
        let p = &self.physics;
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
        if self.table.center.iter().any(|v| !v.is_finite()) {
            return Err(SimError::config("table.center", "must be finite"));
        }
        positive("table.friction", self.table.friction)?;
        self.validate_objects()?;
        self.validate_bins()?;
        if !(self
            .placement
            .size
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0))
        {
            return Err(SimError::config("placement.size", "must be non-negative"));
        }
        if self.placement.center.iter().any(|v| !v.is_finite()) {
            return Err(SimError::config("placement.center", "must be finite"));
        }
        if !self.placement.yaw_range.is_finite() || self.placement.yaw_range < 0.0 {
            return Err(SimError::config(
                "placement.yaw_range",
                "must be non-negative",
            ));
        }
        let clearance = self.placement.clearance;
        if !(clearance.is_finite() && (0.0..=0.2).contains(&clearance)) {
            return Err(SimError::config(
                "placement.clearance",
                "must be in [0, 0.2] m",
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
        positive("arm.kinematic_speed_deg_s", self.arm.kinematic_speed_deg_s)?;
        positive("arm.kinematic_acc_deg_s2", self.arm.kinematic_acc_deg_s2)?;
        let lag = self.arm.kinematic_lag_s;
        if !(lag.is_finite() && (0.0..=1.0).contains(&lag)) {
            return Err(SimError::config(
                "arm.kinematic_lag_s",
                format!("must be between 0 and 1 s, got {lag}"),
            ));
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

    fn validate_objects(&self) -> Result<()> {
        if self.objects.is_empty() || self.objects.len() > MAX_OBJECTS {
            return Err(SimError::config(
                "objects",
                format!(
                    "has {} entries; a scene holds 1 to {MAX_OBJECTS} objects",
                    self.objects.len()
                ),
            ));
        }
        for (i, o) in self.objects.iter().enumerate() {
            let key = format!("objects[{i}]");
            check_name(&format!("{key}.name"), &o.name)?;
            let earlier = self.objects[..i].iter().map(|e| &e.name);
            if earlier.clone().any(|n| *n == o.name) {
                return Err(SimError::config(
                    format!("{key}.name"),
                    format!("'{}' is already the name of another object", o.name),
                ));
            }
            o.shape.check().map_err(|(field, problem)| {
                SimError::config(subkey(&format!("{key}.shape"), &field), problem)
            })?;
            positive(&format!("{key}.mass"), o.mass)?;
            positive(&format!("{key}.friction"), o.friction)?;
            if !(o.angular_damping.is_finite() && o.angular_damping >= 0.0) {
                return Err(SimError::config(
                    format!("{key}.angular_damping"),
                    "must be non-negative",
                ));
            }
            unit_color(&format!("{key}.color"), &o.color)?;
        }
        Ok(())
    }

    fn validate_bins(&self) -> Result<()> {
        for (j, b) in self.bins.iter().enumerate() {
            let key = format!("bins[{j}]");
            check_name(&format!("{key}.name"), &b.name)?;
            let taken = self.objects.iter().map(|o| &o.name);
            let earlier = self.bins[..j].iter().map(|e| &e.name);
            if taken.chain(earlier).any(|n| *n == b.name) {
                return Err(SimError::config(
                    format!("{key}.name"),
                    format!("'{}' is already the name of an object or bin", b.name),
                ));
            }
            if b.center.iter().any(|v| !v.is_finite()) {
                return Err(SimError::config(format!("{key}.center"), "must be finite"));
            }
            positive(&format!("{key}.inner_size[0]"), b.inner_size[0])?;
            positive(&format!("{key}.inner_size[1]"), b.inner_size[1])?;
            positive(&format!("{key}.wall_thickness"), b.wall_thickness)?;
            positive(&format!("{key}.wall_height"), b.wall_height)?;
            if b.wall_height <= b.wall_thickness {
                return Err(SimError::config(
                    format!("{key}.wall_height"),
                    format!(
                        "{} m must exceed wall_thickness ({} m), the floor's thickness",
                        b.wall_height, b.wall_thickness
                    ),
                ));
            }
            unit_color(&format!("{key}.color"), &b.color)?;
            if self.bin_overhangs(b.center, b) {
                return Err(SimError::config(
                    format!("{key}.center"),
                    format!(
                        "bin '{}' at {:?} (arm base frame) overhangs the table edge",
                        b.name, b.center
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Whether a bin's outer footprint centred at `center` (arm base frame) leaves the table top.
    pub(crate) fn bin_overhangs(&self, center: [f32; 2], bin: &BinConfig) -> bool {
        let (sin, cos) = self.arm.base_yaw.sin_cos();
        let [bx, by, _] = self.arm.base_xyz;
        let t = &self.table;
        let half = [
            bin.inner_size[0] / 2.0 + bin.wall_thickness,
            bin.inner_size[1] / 2.0 + bin.wall_thickness,
        ];
        [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)]
            .iter()
            .any(|(sx, sy)| {
                let local = [center[0] + sx * half[0], center[1] + sy * half[1]];
                let world = [
                    bx + cos * local[0] - sin * local[1],
                    by + sin * local[0] + cos * local[1],
                ];
                (0..2).any(|k| (world[k] - t.center[k]).abs() > t.size[k] / 2.0 + 1e-5)
            })
    }
}

/// The names [`super::Scene::in_contact`] resolves must be non-empty and distinct from "table".
fn check_name(key: &str, name: &str) -> Result<()> {
    if name.trim().is_empty() {
        Err(SimError::config(key, "must not be empty"))
    } else if name == "table" {
        Err(SimError::config(
            key,
            "'table' names the table itself; choose another name",
        ))
    } else {
        Ok(())
    }
}
