//! Random object shapes (the `[shapes]` section) and scaling (domain randomisation).

use crate::arm::config::{ShapeKind, ShapesConfig};
use crate::arm::uniform;
use fairgrasp_sim::scene::ObjectShape;
use rand::Rng;

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
