//! Random object shapes (the `[shapes]` section): their settings, the draw, and the scaling
//! domain randomisation applies.

use crate::config::check_range;
use crate::error::{EnvError, Result};
use crate::random::uniform;
use fairgrasp_sim::scene::ObjectShape;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A kind of object shape drawn by [`ShapesConfig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// A box, each side drawn from `box_side`.
    Box,
    /// An upright cylinder, radius and height drawn from their ranges.
    Cylinder,
    /// A ball, radius drawn from `sphere_radius`.
    Sphere,
    /// A file from `meshes`, scaled by a factor drawn from `mesh_scale`.
    Mesh,
}

/// Random object shapes (the design's "random object shapes"): when enabled, every object gets
/// a new shape at each reset, its kind uniform among `kinds`. Part of the task's distribution,
/// independent of the domain-randomisation switch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShapesConfig {
    /// Master switch; off, objects keep the scene's shapes.
    pub enabled: bool,
    /// The kinds drawn from, uniformly (at least one).
    pub kinds: Vec<ShapeKind>,
    /// Each side of a box (m).
    pub box_side: [f32; 2],
    /// Cylinder radius range (m), within [0.005, 0.0425].
    pub cylinder_radius: [f32; 2],
    /// Cylinder height range (m), within [0.01, 0.2].
    pub cylinder_height: [f32; 2],
    /// Sphere radius range (m), within [0.005, 0.0425].
    pub sphere_radius: [f32; 2],
    /// STL or OBJ files drawn from for the `mesh` kind.
    pub meshes: Vec<PathBuf>,
    /// Factor on a mesh's own units.
    pub mesh_scale: [f32; 2],
}

impl Default for ShapesConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            kinds: vec![ShapeKind::Box, ShapeKind::Cylinder],
            box_side: [0.03, 0.07],
            cylinder_radius: [0.015, 0.03],
            cylinder_height: [0.04, 0.08],
            sphere_radius: [0.02, 0.03],
            meshes: Vec::new(),
            mesh_scale: [1.0, 1.0],
        }
    }
}

impl ShapesConfig {
    /// Checks the ranges when enabled; errors name the key (`shapes.…`).
    pub fn validate(&self) -> Result<()> {
        if !self.enabled {
            return Ok(());
        }
        if self.kinds.is_empty() {
            return Err(EnvError::config("shapes.kinds", "name at least one kind"));
        }
        // The gripper opens 90 mm: keep every graspable width below 85 mm.
        check_range("shapes.box_side", self.box_side, 0.01, 0.085)?;
        check_range(
            "shapes.cylinder_radius",
            self.cylinder_radius,
            0.005,
            0.0425,
        )?;
        check_range("shapes.cylinder_height", self.cylinder_height, 0.01, 0.2)?;
        check_range("shapes.sphere_radius", self.sphere_radius, 0.005, 0.0425)?;
        check_range("shapes.mesh_scale", self.mesh_scale, 0.001, 1000.0)?;
        if self.kinds.contains(&ShapeKind::Mesh) && self.meshes.is_empty() {
            return Err(EnvError::config(
                "shapes.meshes",
                "the `mesh` kind needs at least one STL or OBJ file",
            ));
        }
        Ok(())
    }
}

/// A shape drawn from `config`: the kind uniform among `config.kinds`, dimensions uniform in
/// their ranges (each side of a box on its own).
pub fn draw(config: &ShapesConfig, rng: &mut impl Rng) -> ObjectShape {
    let kind = config.kinds[rng.random_range(0..config.kinds.len())];
    match kind {
        ShapeKind::Box => ObjectShape::Box {
            size: [0; 3].map(|_| uniform(rng, config.box_side)),
        },
        ShapeKind::Cylinder => ObjectShape::Cylinder {
            radius: uniform(rng, config.cylinder_radius),
            height: uniform(rng, config.cylinder_height),
        },
        ShapeKind::Sphere => ObjectShape::Sphere {
            radius: uniform(rng, config.sphere_radius),
        },
        ShapeKind::Mesh => ObjectShape::Mesh {
            path: config.meshes[rng.random_range(0..config.meshes.len())].clone(),
            scale: uniform(rng, config.mesh_scale),
        },
    }
}

/// `shape` with every dimension multiplied by `factor`.
pub fn scaled(shape: &ObjectShape, factor: f32) -> ObjectShape {
    match shape {
        ObjectShape::Box { size } => ObjectShape::Box {
            size: size.map(|s| s * factor),
        },
        ObjectShape::Cylinder { radius, height } => ObjectShape::Cylinder {
            radius: radius * factor,
            height: height * factor,
        },
        ObjectShape::Sphere { radius } => ObjectShape::Sphere {
            radius: radius * factor,
        },
        ObjectShape::Mesh { path, scale } => ObjectShape::Mesh {
            path: path.clone(),
            scale: scale * factor,
        },
    }
}
