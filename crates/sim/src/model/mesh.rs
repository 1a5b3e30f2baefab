//! Mesh files (STL binary/ASCII, OBJ, COLLADA/DAE) → triangles, through the mesh-loader crate.

use std::path::Path;

/// Triangles of a mesh, in the mesh file's own frame and units.
#[derive(Clone, Debug, Default)]
pub struct TriangleMesh {
    /// Vertex positions.
    pub vertices: Vec<[f32; 3]>,
    /// Vertex indices of each triangle.
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
    // Choose the parser by extension ourselves: mesh-loader only knows lower- or upper-case
    // extensions and words its error for other formats poorly.
    let format = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    if !matches!(format.as_str(), "stl" | "obj" | "dae") {
        let found = if format.is_empty() {
            "no file extension".to_string()
        } else {
            format!("'.{format}'")
        };
        return Err(format!(
            "{} has an unsupported mesh format ({found}); use STL (.stl), OBJ (.obj) or COLLADA (.dae)",
            path.display()
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    if bytes.starts_with(b"version https://git-lfs.github.com/spec/") {
        return Err(format!(
            "{} is a Git LFS pointer, not the mesh itself; fetch the real file with `git lfs pull`",
            path.display()
        ));
    }
    let loader = mesh_loader::Loader::default().merge_meshes(true);
    // The parsers index into untrusted bytes; a panic there must become an error, not a crash.
    let parsed = std::panic::catch_unwind(|| match format.as_str() {
        "stl" => loader.load_stl_from_slice(&bytes, path),
        "obj" => loader.load_obj_from_slice(&bytes, path),
        _ => loader.load_collada_from_slice(&bytes, path),
    })
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
    if format == "stl" {
        check_binary_stl_count(&bytes, mesh.triangles.len())
            .map_err(|problem| format!("{} is truncated: {problem}", path.display()))?;
    }
    if mesh.vertices.iter().flatten().any(|v| !v.is_finite()) {
        return Err(format!(
            "{} has non-finite vertex coordinates",
            path.display()
        ));
    }
    Ok(mesh)
}

/// mesh-loader sizes a binary STL by its length and ignores the triangle count in its header, so a
/// file cut off at a triangle boundary would load with triangles silently missing. Like assimp,
/// refuse a binary STL whose header declares more triangles than the file holds (a smaller
/// count, e.g. the 0 some exporters write, is tolerated).
fn check_binary_stl_count(bytes: &[u8], loaded: usize) -> Result<(), String> {
    const HEADER: usize = 84;
    const TRIANGLE: usize = 50;
    let Some(count) = bytes.get(80..HEADER) else {
        return Ok(());
    };
    let held = (bytes.len() - HEADER) / TRIANGLE;
    if loaded != held {
        // Read as ASCII STL: there is no binary count to trust.
        return Ok(());
    }
    let declared = u32::from_le_bytes([count[0], count[1], count[2], count[3]]) as usize;
    if declared > held {
        Err(format!(
            "its binary STL header declares {declared} triangles but the file holds only {held}"
        ))
    } else {
        Ok(())
    }
}
