//! Resolving mesh URIs: `package://NAME/…`, `file://…` and paths relative to the URDF.

use std::path::{Path, PathBuf};

/// Directories searched for ROS packages, like `ROS_PACKAGE_PATH`.
///
/// `package://NAME/rest` resolves to `ROOT/NAME/rest` for the first root where that exists, or to
/// `ROOT/rest` when the root itself is the package directory `NAME`. When no root matches, the
/// directories above the URDF file are tried, since vendor packages usually keep `urdf/` and
/// `meshes/` side by side inside the package.
#[derive(Clone, Debug, Default)]
pub struct PackagePaths {
    /// The directories, searched in order.
    pub roots: Vec<PathBuf>,
}

impl PackagePaths {
    /// Roots from the environment: `FAIRGRASP_PACKAGE_PATH` then `ROS_PACKAGE_PATH`
    /// (both separated like `PATH`).
    pub fn from_env() -> Self {
        let mut roots = Vec::new();
        for var in ["FAIRGRASP_PACKAGE_PATH", "ROS_PACKAGE_PATH"] {
            if let Some(value) = std::env::var_os(var) {
                roots.extend(std::env::split_paths(&value).filter(|p| !p.as_os_str().is_empty()));
            }
        }
        Self { roots }
    }

    /// Adds roots searched before the existing ones (e.g. from a command-line flag).
    pub fn with_first(mut self, first: impl IntoIterator<Item = PathBuf>) -> Self {
        let mut roots: Vec<PathBuf> = first.into_iter().collect();
        roots.append(&mut self.roots);
        self.roots = roots;
        self
    }
}

/// Finds the file a URDF mesh `filename` names; the error says where it looked.
pub(crate) fn resolve_uri(
    uri: &str,
    base_dir: &Path,
    packages: &PackagePaths,
) -> Result<PathBuf, String> {
    if let Some(rest) = uri.strip_prefix("package://") {
        let (package, relative) = rest
            .split_once('/')
            .ok_or_else(|| format!("'{uri}' has no path after the package name"))?;
        let mut tried = Vec::new();
        for root in &packages.roots {
            let candidates = [
                Some(root.join(package).join(relative)),
                (root.file_name().is_some_and(|n| n == package)).then(|| root.join(relative)),
            ];
            for candidate in candidates.into_iter().flatten() {
                if candidate.is_file() {
                    return Ok(candidate);
                }
                tried.push(candidate);
            }
        }
        for dir in base_dir.ancestors() {
            let candidate = if dir.file_name().is_some_and(|n| n == package) {
                dir.join(relative)
            } else {
                dir.join(package).join(relative)
            };
            if candidate.is_file() {
                return Ok(candidate);
            }
        }
        return Err(format!(
            "package '{package}' not found: add its parent directory with --package-path or \
             ROS_PACKAGE_PATH (searched {} package root(s){})",
            packages.roots.len(),
            if tried.is_empty() {
                String::new()
            } else {
                format!(
                    ": {}",
                    tried
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        ));
    }
    let path = match uri.strip_prefix("file://") {
        Some(absolute) => PathBuf::from(absolute),
        None if uri.contains("://") => {
            return Err(format!(
                "unsupported URI scheme in '{uri}'; use package://, file:// or a path"
            ));
        }
        None => base_dir.join(uri),
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(format!("file not found: {}", path.display()))
    }
}
