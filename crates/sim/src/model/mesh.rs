//! Mesh files (STL binary/ASCII, OBJ, COLLADA/DAE) → triangles, through the mesh-loader crate.

use std::path::Path;

/// Triangles of a mesh, in the mesh file's own frame and units.
#[derive(Clone, Debug, Default)]
pub struct TriangleMesh {
    pub vertices: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// Axis-aligned bounds `(min, max)` of the vertices.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for v in &self.vertices {
            for k in 0..3 {
                min[k] = min[k].min(v[k]);
                max[k] = max[k].max(v[k]);
            }
        }
        (min, max)
    }
}

/// How a mesh becomes a collision shape on a moving body.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeshCollision {
    /// One convex hull around all vertices: fast and robust, the usual choice for arm links.
    #[default]
    ConvexHull,
    /// An approximate convex decomposition (V-HACD): follows concave shapes such as fingers.
    ConvexDecomposition,
}

impl std::str::FromStr for MeshCollision {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "convex-hull" | "convex_hull" => Ok(Self::ConvexHull),
            "convex-decomposition" | "convex_decomposition" => Ok(Self::ConvexDecomposition),
            other => Err(format!(
                "unknown mesh collision mode '{other}'; expected convex-hull or convex-decomposition"
            )),
        }
    }
}

/// Reads a mesh file; the error text says what is wrong with it.
pub(crate) fn load_mesh(path: &Path) -> Result<TriangleMesh, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let loader = mesh_loader::Loader::default().merge_meshes(true);
    // The parsers index into untrusted bytes; a panic there must become an error, not a crash.
    let parsed = std::panic::catch_unwind(|| loader.load_from_slice(&bytes, path))
        .map_err(|_| format!("{} is corrupt (the mesh parser failed)", path.display()))?
        .map_err(|e| format!("{} is not a readable mesh: {e}", path.display()))?;
    let mut mesh = TriangleMesh::default();
    for part in parsed.meshes {
        let base = mesh.vertices.len() as u32;
        let n = part.vertices.len() as u32;
        for face in &part.faces {
            if face.iter().any(|&i| i >= n) {
                return Err(format!(
                    "{} is corrupt: a face refers to vertex {} of {n}",
                    path.display(),
                    face.iter().max().copied().unwrap_or(0)
                ));
            }
            mesh.triangles.push(face.map(|i| i + base));
        }
        mesh.vertices.extend(part.vertices);
    }
    if mesh.triangles.is_empty() {
        return Err(format!("{} contains no triangles", path.display()));
    }
    if mesh.vertices.iter().flatten().any(|v| !v.is_finite()) {
        return Err(format!("{} has non-finite vertex coordinates", path.display()));
    }
    Ok(mesh)
}
