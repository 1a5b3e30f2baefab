//! Atomic file writes: nothing already saved is lost if the process dies mid-write.

use crate::error::{DeployError, Result};
use std::io::Write;
use std::path::Path;

/// Writes `bytes` to a temporary file beside `path` (named with `tag`), syncs it, and hands
/// both paths to `place`, which puts it in place; the temporary file is removed if left.
fn via_temporary(
    path: &Path,
    bytes: &[u8],
    tag: &str,
    place: impl FnOnce(&Path, &Path) -> std::io::Result<()>,
) -> Result<std::io::Result<()>> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| DeployError::config(path.display().to_string(), "not a file path"))?;
    let tmp = dir.join(format!(
        ".{}.{tag}{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        place(&tmp, path)
    })();
    let _ = std::fs::remove_file(&tmp);
    Ok(result)
}

/// Writes `bytes` to a temporary file beside `path`, syncs it, then renames it over `path`.
pub fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    via_temporary(path, bytes, "tmp", |tmp, path| std::fs::rename(tmp, path))?
        .map_err(|e| DeployError::config(path.display().to_string(), format!("cannot write: {e}")))
}

/// As [`write`], but never replaces a file: the complete temporary file is hard-linked to
/// `path`, which fails if anything is there by then (no window between a check and the write).
pub fn write_new(path: &Path, bytes: &[u8]) -> Result<()> {
    via_temporary(path, bytes, "new", |tmp, path| {
        std::fs::hard_link(tmp, path)
    })?
    .map_err(|e| {
        let message = if e.kind() == std::io::ErrorKind::AlreadyExists {
            "exists already; it is kept (give another path, or move it away)".to_string()
        } else {
            format!("cannot write: {e}")
        };
        DeployError::config(path.display().to_string(), message)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_new_never_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.toml");
        write_new(&path, b"one").unwrap();
        let e = write_new(&path, b"two").unwrap_err().to_string();
        assert!(e.contains("exists already"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "no temporary left"
        );
    }
}
