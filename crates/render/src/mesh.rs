//! Triangle meshes of shapes: parry collider shapes and URDF geometries, tessellated once and
//! cached by their owners (see `scene_mesh.rs`).

use fairgrasp_sim::model::Geometry;
use fairgrasp_sim::rapier3d::math::{Pose, Vector};
use fairgrasp_sim::rapier3d::parry::shape::{Ball, Capsule, Cuboid, Cylinder, Shape};

/// Segments around a circle: a 5 cm cylinder's facets are under 1 px at 640×480.
const CIRCLE: u32 = 24;
/// Latitude bands of a sphere (and of a capsule's two caps together).
const BANDS: u32 = 12;

/// Triangles in a shape's own frame (m).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub vertices: Vec<Vector>,
    /// Vertex indices of each triangle, counter-clockwise seen from outside when [`Self::closed`].
    pub triangles: Vec<[u32; 3]>,
    /// A closed surface wound counter-clockwise seen from outside: faces turned away from the
    /// camera are hidden and can be skipped. Open or inconsistent meshes are drawn two-sided.
    pub closed: bool,
}

impl Mesh {
    fn from_parts((vertices, triangles): (Vec<Vector>, Vec<[u32; 3]>)) -> Self {
        Self {
            vertices,
            triangles,
            closed: false,
        }
    }

    /// Whether every edge is shared by exactly two triangles that run it in opposite
    /// directions (a closed, consistently wound surface).
    fn is_closed(&self) -> bool {
        let mut edges = std::collections::HashMap::with_capacity(3 * self.triangles.len());
        for t in &self.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edges.entry((a, b)).or_insert(0u32) += 1;
            }
        }
        !edges.is_empty()
            && edges
                .iter()
                .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
    }

    /// Six times the enclosed volume, positive when the triangles wind outward.
    fn signed_volume(&self) -> f32 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                a.dot(b.cross(c))
            })
            .sum()
    }

    /// Appends `other` moved by `pose`.
    fn append(&mut self, other: &Mesh, pose: &Pose) {
        let base = self.vertices.len() as u32;
        self.vertices
            .extend(other.vertices.iter().map(|&v| pose.transform_point(v)));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
    }

    /// Drops triangles that refer to missing vertices (user meshes), so drawing never indexes
    /// out of bounds; winds closed surfaces outward and marks them [`Self::closed`].
    fn checked(mut self) -> Self {
        let n = self.vertices.len() as u32;
        self.triangles.retain(|t| t.iter().all(|&i| i < n));
        self.closed = self.is_closed();
        if self.closed && self.signed_volume() < 0.0 {
            for t in &mut self.triangles {
                t.swap(1, 2);
            }
        }
        self
    }

    /// Whether the mesh has no triangle to draw.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }
}

/// The boundary of a collider shape. Cuboids, balls, cylinders, capsules, convex polyhedra,
/// triangle meshes and compounds of these; `None` for other shapes (not drawn).
pub fn tessellate_shape(shape: &dyn Shape) -> Option<Mesh> {
    let mesh = if let Some(s) = shape.as_cuboid() {
        Mesh::from_parts(s.to_trimesh())
    } else if let Some(s) = shape.as_ball() {
        Mesh::from_parts(s.to_trimesh(CIRCLE, BANDS))
    } else if let Some(s) = shape.as_cylinder() {
        Mesh::from_parts(s.to_trimesh(CIRCLE))
    } else if let Some(s) = shape.as_capsule() {
        Mesh::from_parts(s.to_trimesh(CIRCLE, BANDS))
    } else if let Some(s) = shape.as_convex_polyhedron() {
        Mesh::from_parts(s.to_trimesh())
    } else if let Some(s) = shape.as_trimesh() {
        Mesh {
            vertices: s.vertices().to_vec(),
            triangles: s.indices().to_vec(),
            closed: false,
        }
    } else if let Some(s) = shape.as_compound() {
        let mut all = Mesh::default();
        for (pose, part) in s.shapes() {
            all.append(&tessellate_shape(part.as_ref())?, pose);
        }
        all
    } else {
        return None;
    };
    Some(mesh.checked())
}

/// The boundary of a URDF geometry in its shape frame (cylinders and capsules along z).
pub fn tessellate_geometry(geometry: &Geometry) -> Mesh {
    let mesh = match geometry {
        Geometry::Box { size } => Mesh::from_parts(
            Cuboid::new(Vector::new(
                size[0] as f32 / 2.0,
                size[1] as f32 / 2.0,
                size[2] as f32 / 2.0,
            ))
            .to_trimesh(),
        ),
        Geometry::Cylinder { radius, length } => {
            // parry's cylinder axis is y: turn it onto z.
            let y_cylinder = Mesh::from_parts(
                Cylinder::new(*length as f32 / 2.0, *radius as f32).to_trimesh(CIRCLE),
            );
            let mut z = Mesh::default();
            z.append(
                &y_cylinder,
                &Pose::rotation(Vector::X * std::f32::consts::FRAC_PI_2),
            );
            z
        }
        Geometry::Capsule { radius, length } => Mesh::from_parts(
            Capsule::new_z(*length as f32 / 2.0, *radius as f32).to_trimesh(CIRCLE, BANDS),
        ),
        Geometry::Sphere { radius } => {
            Mesh::from_parts(Ball::new(*radius as f32).to_trimesh(CIRCLE, BANDS))
        }
        Geometry::Mesh { scale, mesh, .. } => Mesh {
            vertices: mesh
                .vertices
                .iter()
                .map(|v| {
                    Vector::new(
                        v[0] * scale[0] as f32,
                        v[1] * scale[1] as f32,
                        v[2] * scale[2] as f32,
                    )
                })
                .collect(),
            triangles: mesh.triangles.clone(),
            closed: false,
        },
    };
    mesh.checked()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fairgrasp_sim::rapier3d::prelude::SharedShape;

    fn bounds(m: &Mesh) -> (Vector, Vector) {
        let min = m
            .vertices
            .iter()
            .fold(Vector::splat(f32::MAX), |a, &v| a.min(v));
        let max = m
            .vertices
            .iter()
            .fold(Vector::splat(f32::MIN), |a, &v| a.max(v));
        (min, max)
    }

    #[test]
    fn shapes_tessellate_to_their_extents() {
        let cube = tessellate_shape(SharedShape::cuboid(0.1, 0.2, 0.3).as_ref()).unwrap();
        assert_eq!(cube.triangles.len(), 12);
        let (min, max) = bounds(&cube);
        assert!((max - Vector::new(0.1, 0.2, 0.3)).length() < 1e-6);
        assert!((min + Vector::new(0.1, 0.2, 0.3)).length() < 1e-6);

        let cylinder = tessellate_geometry(&Geometry::Cylinder {
            radius: 0.05,
            length: 0.4,
        });
        let (min, max) = bounds(&cylinder);
        assert!(
            (max.z - 0.2).abs() < 1e-5 && (min.z + 0.2).abs() < 1e-5,
            "{min} {max}"
        );
        assert!((max.x - 0.05).abs() < 1e-3);

        let ball = tessellate_shape(SharedShape::ball(0.03).as_ref()).unwrap();
        assert!(
            ball.vertices
                .iter()
                .all(|v| (v.length() - 0.03).abs() < 1e-5)
        );
    }

    #[test]
    fn closed_meshes_are_found_and_wound_outward() {
        let cube = tessellate_shape(SharedShape::cuboid(0.1, 0.1, 0.1).as_ref()).unwrap();
        assert!(cube.closed && cube.signed_volume() > 0.0);
        // Turned inside out, it is wound back outward.
        let inverted = Mesh {
            triangles: cube.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect(),
            ..cube.clone()
        }
        .checked();
        assert!(inverted.closed);
        assert!((inverted.signed_volume() - cube.signed_volume()).abs() < 1e-9);
        // One face alone is open: drawn two-sided.
        let face = Mesh {
            triangles: cube.triangles[..2].to_vec(),
            ..cube.clone()
        }
        .checked();
        assert!(!face.closed);
    }
}
