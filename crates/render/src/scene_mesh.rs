//! What to draw of a scene: the robot's visual shapes, tessellated once per renderer, and the
//! table, objects and bins, tessellated once per collider shape and cached.

use crate::error::Result;
use crate::mesh::{Mesh, tessellate_geometry, tessellate_shape};
use crate::raster::decode_srgb;
use crate::segment::Segment;
use fairgrasp_sim::kinematics::origin_to_isometry;
use fairgrasp_sim::math::iso_to_pose;
use fairgrasp_sim::rapier3d::math::Pose;
use fairgrasp_sim::rapier3d::prelude::SharedShape;
use fairgrasp_sim::scene::{Scene, ShapeOwner};
use std::collections::HashMap;
use std::sync::Arc;

/// Linear RGB of robot shapes without a URDF colour.
const ROBOT_DEFAULT: [f32; 3] = [0.6, 0.6, 0.6];
/// Linear RGB of the table top (light wood).
pub const TABLE_COLOUR: [f32; 3] = [0.55, 0.40, 0.25];

/// Cached meshes kept at most; past it the cache starts over (shapes randomised every episode
/// would otherwise pile up).
const CACHE_LIMIT: usize = 256;

/// One visual shape of a robot link.
struct RobotPart {
    /// Index into the robot model's links.
    link: usize,
    /// Shape frame in the link frame.
    local: Pose,
    mesh: Arc<Mesh>,
    colour: [f32; 3],
    id: u16,
}

/// A mesh placed in the world, ready to draw.
pub struct Placed<'a> {
    /// The triangles, in the mesh's own frame.
    pub mesh: &'a Mesh,
    /// Pose of the mesh's frame in the world.
    pub pose: Pose,
    /// Linear RGB in 0..1.
    pub colour: [f32; 3],
    /// Segmentation id (see [`crate::segment`]).
    pub id: u16,
}

/// Meshes of a scene's robot (fixed at construction) and of its other shapes (cached).
pub struct SceneMeshes {
    robot: Vec<RobotPart>,
    /// Names of the links that carry parts, in model order, with their indices.
    links: Vec<(usize, String)>,
    /// By the address of the shared shape, which the entry keeps alive so the address cannot
    /// be reused by another shape. `None`: a shape we cannot tessellate.
    shapes: HashMap<usize, (SharedShape, Option<Arc<Mesh>>)>,
}

fn address(shape: &SharedShape) -> usize {
    Arc::as_ptr(&shape.0) as *const () as usize
}

impl SceneMeshes {
    /// Tessellates the robot's visuals (a link's collision shapes when it has no visual).
    pub fn new(scene: &Scene) -> Result<Self> {
        let model = &scene.robot().model;
        let mut robot = Vec::new();
        let mut links = Vec::new();
        for (l, link) in model.links.iter().enumerate() {
            let shapes = if link.visuals.is_empty() {
                &link.collisions
            } else {
                &link.visuals
            };
            if shapes.is_empty() {
                continue;
            }
            let id = Segment::Link(l).id()?;
            links.push((l, link.name.clone()));
            for shape in shapes {
                let mesh = tessellate_geometry(&shape.geometry);
                if mesh.is_empty() {
                    continue;
                }
                let colour = shape
                    .rgba
                    .map(|c| [c[0], c[1], c[2]].map(|v| decode_srgb(v as f32)))
                    .unwrap_or(ROBOT_DEFAULT);
                robot.push(RobotPart {
                    link: l,
                    local: iso_to_pose(&origin_to_isometry(&shape.origin)),
                    mesh: Arc::new(mesh),
                    colour,
                    id,
                });
            }
        }
        // Room for every object and bin the scene may show.
        Segment::Object(scene.num_objects().saturating_sub(1)).id()?;
        Segment::Bin(scene.bins().len().saturating_sub(1)).id()?;
        Ok(Self {
            robot,
            links,
            shapes: HashMap::new(),
        })
    }

    /// Everything to draw in the scene's current state.
    pub fn placed(&mut self, scene: &Scene) -> Result<Vec<Placed<'_>>> {
        let environment = scene.environment_shapes();
        // Fill the cache first; drawing below only borrows it.
        if self.shapes.len() + environment.len() > CACHE_LIMIT {
            self.shapes.clear();
        }
        for placed in &environment {
            self.shapes
                .entry(address(&placed.shape))
                .or_insert_with(|| {
                    let mesh = tessellate_shape(placed.shape.as_ref()).map(Arc::new);
                    (placed.shape.clone(), mesh)
                });
        }

        let mut out = Vec::with_capacity(self.robot.len() + environment.len());
        let mut link_poses: HashMap<usize, Pose> = HashMap::with_capacity(self.links.len());
        for (l, name) in &self.links {
            if let Some(pose) = scene.link_pose(name) {
                link_poses.insert(*l, iso_to_pose(&pose));
            }
        }
        for part in &self.robot {
            let Some(link) = link_poses.get(&part.link) else {
                continue;
            };
            out.push(Placed {
                mesh: &part.mesh,
                pose: *link * part.local,
                colour: part.colour,
                id: part.id,
            });
        }
        for placed in &environment {
            let Some((_, Some(mesh))) = self.shapes.get(&address(&placed.shape)) else {
                continue;
            };
            let (colour, segment) = match placed.owner {
                ShapeOwner::Table => (TABLE_COLOUR, Segment::Table),
                ShapeOwner::Object(i) => (scene.object_config(i).color, Segment::Object(i)),
                ShapeOwner::Bin(j) => (scene.bins()[j].color, Segment::Bin(j)),
            };
            out.push(Placed {
                mesh,
                pose: placed.pose,
                colour,
                id: segment.id()?,
            });
        }
        Ok(out)
    }

    /// Number of cached environment meshes (for tests of the cache).
    pub fn cached_shapes(&self) -> usize {
        self.shapes.len()
    }
}
