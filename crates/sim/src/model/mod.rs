//! Robot descriptions: a validated, engine-independent model of a URDF tree.
//!
//! [`RobotModel::load`] parses a URDF file, resolves and loads its meshes, and checks everything a
//! simulator needs (a single tree, finite origins, positive masses, known joint types). Building the
//! model into the physics engine lives in [`crate::robot`].

mod mesh;
mod packages;
mod parse;
mod xacro;

pub(crate) use mesh::load_mesh;
pub use mesh::{MeshCollision, TriangleMesh};
pub use packages::PackagePaths;

use crate::error::{Result, SimError};
use std::path::{Path, PathBuf};

/// A rigid transform as written in URDF: translation (m) then fixed-axis roll-pitch-yaw (rad).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Origin {
    /// Translation (m).
    pub xyz: [f64; 3],
    /// Roll, pitch, yaw about the fixed x, y, z axes (rad).
    pub rpy: [f64; 3],
}

/// Mass properties of a link, in the link frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertial {
    /// Frame of the centre of mass and the inertia axes, in the link frame.
    pub origin: Origin,
    /// Mass (kg), positive.
    pub mass: f64,
    /// `[ixx, ixy, ixz, iyy, iyz, izz]` about the centre of mass, in the inertial frame.
    pub inertia: [f64; 6],
}

/// A collision or visual shape. Sizes are in metres, as in URDF.
#[derive(Clone, Debug)]
pub enum Geometry {
    /// A box centred on its frame.
    Box {
        /// Full edge lengths along x, y, z (m).
        size: [f64; 3],
    },
    /// Axis along the shape frame's z, as in URDF.
    Cylinder {
        /// Radius (m).
        radius: f64,
        /// Length along z (m).
        length: f64,
    },
    /// Axis along z; `length` is the distance between the two sphere centres.
    Capsule {
        /// Radius of the cylinder and of the end spheres (m).
        radius: f64,
        /// Distance between the two sphere centres (m).
        length: f64,
    },
    /// A sphere centred on its frame.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// A triangle mesh loaded from a file.
    Mesh {
        /// The filename as written in the URDF (`package://…`, `file://…` or relative).
        uri: String,
        /// Where it was found on disk.
        path: PathBuf,
        /// Scale factors along the mesh's x, y, z (positive); 1 when the URDF gives none.
        scale: [f64; 3],
        /// Triangles in the mesh's own frame, before `scale`.
        mesh: TriangleMesh,
    },
}

/// A geometry placed in its link's frame.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Pose of the geometry in the link frame.
    pub origin: Origin,
    /// The shape itself.
    pub geometry: Geometry,
    /// RGBA colour of a visual, when the URDF gives one.
    pub rgba: Option<[f64; 4]>,
}

/// A link: a rigid body with optional mass, collision and visual shapes.
#[derive(Clone, Debug)]
pub struct Link {
    /// Name, unique in the model.
    pub name: String,
    /// `None` for massless frames such as `tool0` or `world`.
    pub inertial: Option<Inertial>,
    /// Shapes used for contacts.
    pub collisions: Vec<Shape>,
    /// Shapes drawn, with their colours.
    pub visuals: Vec<Shape>,
}

/// The joint types a simulated arm may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Turns about its axis between limits (rad).
    Revolute,
    /// Turns about its axis without position limits.
    Continuous,
    /// Slides along its axis between limits (m).
    Prismatic,
    /// No degree of freedom.
    Fixed,
}

impl JointKind {
    /// Whether the joint has one degree of freedom.
    pub fn is_movable(self) -> bool {
        !matches!(self, JointKind::Fixed)
    }

    /// The URDF `type` attribute of the joint kind, e.g. `revolute`.
    pub fn as_str(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Continuous => "continuous",
            JointKind::Prismatic => "prismatic",
            JointKind::Fixed => "fixed",
        }
    }
}

/// Position, effort and velocity limits of a joint (rad or m; N·m or N; rad/s or m/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    /// Lowest position (rad or m); −∞ for a continuous joint.
    pub lower: f64,
    /// Highest position (rad or m), not below `lower`; +∞ for a continuous joint.
    pub upper: f64,
    /// Largest torque or force (N·m or N), positive.
    pub effort: f64,
    /// Largest speed (rad/s or m/s), positive.
    pub velocity: f64,
}

/// `q_self = multiplier · q_joint + offset`, as URDF's `<mimic>`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mimic {
    /// Index into [`RobotModel::joints`].
    pub joint: usize,
    /// Factor on the followed joint's position.
    pub multiplier: f64,
    /// Offset added (rad or m).
    pub offset: f64,
}

/// A joint between two links, with indices into [`RobotModel::links`].
#[derive(Clone, Debug)]
pub struct Joint {
    /// Name, unique in the model.
    pub name: String,
    /// Joint type.
    pub kind: JointKind,
    /// Index of the parent link.
    pub parent: usize,
    /// Index of the child link.
    pub child: usize,
    /// Pose of the joint frame in the parent link's frame.
    pub origin: Origin,
    /// Unit axis in the joint frame.
    pub axis: [f64; 3],
    /// `None` for fixed joints, and for continuous joints whose URDF gives no positive effort
    /// and velocity limits.
    pub limits: Option<JointLimits>,
    /// Viscous damping (N·m·s/rad) and Coulomb friction (N·m) from `<dynamics>`.
    pub damping: f64,
    /// Coulomb friction (N·m, or N for a prismatic joint), not negative.
    pub friction: f64,
    /// The joint this one follows, if it mimics one.
    pub mimic: Option<Mimic>,
}

/// How to load a robot description.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Where `package://NAME/…` URIs are looked up.
    pub packages: PackagePaths,
}

/// A validated robot: links and joints forming one tree.
#[derive(Clone, Debug)]
pub struct RobotModel {
    /// The URDF `<robot name>`.
    pub name: String,
    /// Where the description came from, used in messages.
    pub source_name: String,
    /// Every link; joints refer to them by index.
    pub links: Vec<Link>,
    /// Sorted so that every joint comes after the joint of its parent link.
    pub joints: Vec<Joint>,
    /// The link with no parent joint.
    pub root: usize,
}

impl RobotModel {
    /// Loads and validates a URDF file, resolving its meshes through `options.packages`.
    pub fn load(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        parse::parse_urdf(&text, &path.display().to_string(), &base_dir, options)
    }

    /// Parses URDF text. Relative mesh paths resolve against `base_dir`.
    pub fn from_urdf_str(
        text: &str,
        source_name: &str,
        base_dir: &Path,
        options: &LoadOptions,
    ) -> Result<Self> {
        parse::parse_urdf(text, source_name, base_dir, options)
    }

    /// The index of the link called `name`.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// The index of the joint called `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The joint whose child is `link`, if any (none for the root).
    pub fn parent_joint(&self, link: usize) -> Option<usize> {
        self.joints.iter().position(|j| j.child == link)
    }

    /// The joints from the root to `link`, root first.
    pub fn chain_to(&self, link: usize) -> Vec<usize> {
        let mut chain = Vec::new();
        let mut current = link;
        while let Some(j) = self.parent_joint(current) {
            chain.push(j);
            current = self.joints[j].parent;
        }
        chain.reverse();
        chain
    }

    /// The leaf link reached from the root by always following the first movable branch:
    /// for a serial arm, its end link.
    pub fn end_link(&self) -> usize {
        let mut current = self.root;
        loop {
            let children: Vec<usize> = (0..self.joints.len())
                .filter(|&j| self.joints[j].parent == current)
                .collect();
            let next = children
                .iter()
                .copied()
                .find(|&j| self.joints[j].kind.is_movable())
                .or_else(|| children.first().copied());
            match next {
                Some(j) => current = self.joints[j].child,
                None => return current,
            }
        }
    }

    /// Joints with a degree of freedom of their own (movable and not mimicking another joint).
    pub fn actuated_joints(&self) -> Vec<usize> {
        (0..self.joints.len())
            .filter(|&j| self.joints[j].kind.is_movable() && self.joints[j].mimic.is_none())
            .collect()
    }

    /// Joins `child` under `parent_link` of `self` with a fixed joint at `origin`, as when a
    /// gripper is bolted on a flange. Link and joint names must not clash.
    pub fn attach(
        &mut self,
        parent_link: &str,
        child: RobotModel,
        origin: Origin,
        joint_name: &str,
    ) -> Result<()> {
        let parent = self.link_index(parent_link).ok_or_else(|| {
            SimError::urdf(
                &self.source_name,
                format!("link '{parent_link}'"),
                format!("cannot attach '{}': no such link", child.name),
            )
        })?;
        for link in &child.links {
            if self.link_index(&link.name).is_some() {
                return Err(SimError::urdf(
                    &child.source_name,
                    format!("link '{}'", link.name),
                    format!("name already used by '{}'", self.name),
                ));
            }
        }
        for joint in child
            .joints
            .iter()
            .map(|j| j.name.as_str())
            .chain([joint_name])
        {
            if self.joint_index(joint).is_some() {
                return Err(SimError::urdf(
                    &child.source_name,
                    format!("joint '{joint}'"),
                    format!("name already used by '{}'", self.name),
                ));
            }
        }
        let link_offset = self.links.len();
        let joint_offset = self.joints.len() + 1;
        self.joints.push(Joint {
            name: joint_name.to_string(),
            kind: JointKind::Fixed,
            parent,
            child: child.root + link_offset,
            origin,
            axis: [1.0, 0.0, 0.0],
            limits: None,
            damping: 0.0,
            friction: 0.0,
            mimic: None,
        });
        self.links.extend(child.links);
        self.joints.extend(child.joints.into_iter().map(|mut j| {
            j.parent += link_offset;
            j.child += link_offset;
            if let Some(m) = &mut j.mimic {
                m.joint += joint_offset;
            }
            j
        }));
        Ok(())
    }
}
