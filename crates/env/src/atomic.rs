//! Writing files so that nothing already saved is lost: the bytes go to a temporary file beside
//! the target, synced to disk, and only a complete file is put in its place (a rename, atomic on
//! POSIX file systems). A reader sees the old file or the new one, never half of one, and a
//! process killed mid-write leaves the old one. Every layer's saves (models, checkpoints,
//! statistics, calibrations, reports) come through here.

use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Writes `bytes` to `path`, replacing what is there; creates the parent directories. On any
/// error the previous file is left as it was.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    via_temporary(path, bytes, |tmp, path| std::fs::rename(tmp, path))
}

/// As [`write()`], but never replaces a file: the complete temporary file is hard-linked to
/// `path`, which fails with [`std::io::ErrorKind::AlreadyExists`] if anything is there by then
/// (no window between a check and the write).
pub fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    via_temporary(path, bytes, |tmp, path| std::fs::hard_link(tmp, path))
}

/// Writes `bytes` to a fresh temporary file beside `path`, syncs it and hands both paths to
/// `place`; the temporary file is gone afterwards whatever happened.
fn via_temporary(
    path: &Path,
    bytes: &[u8],
    place: impl FnOnce(&Path, &Path) -> std::io::Result<()>,
) -> std::io::Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    let tmp = dir.join(format!(
        ".{}.{}.{}.tmp",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        drop(file);
        place(&tmp, path)
    })();
    let _ = std::fs::remove_file(&tmp);
    // Make the new name itself durable where the platform allows it (best effort).
    #[cfg(unix)]
    if result.is_ok()
        && let Ok(d) = std::fs::File::open(dir)
    {
        let _ = d.sync_all();
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<std::ffi::OsString> {
        (std::fs::read_dir(dir).unwrap())
            .map(|e| e.unwrap().file_name())
            .collect()
    }

    #[test]
    fn write_replaces_the_file_and_leaves_no_temporary_behind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.bin");
        write(&path, b"first").unwrap();
        write(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        assert_eq!(names(dir.path()).len(), 1, "{:?}", names(dir.path()));
        // A target under a file fails without touching anything.
        let blocked = path.join("inside-a-file").join("x");
        assert!(write(&blocked, b"x").is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        // Parent directories are made.
        write(&dir.path().join("a/b/c.txt"), b"deep").unwrap();
        assert_eq!(
            std::fs::read(dir.path().join("a/b/c.txt")).unwrap(),
            b"deep"
        );
    }

    #[test]
    fn write_new_never_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.toml");
        write_new(&path, b"one").unwrap();
        let e = write_new(&path, b"two").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::AlreadyExists, "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        assert_eq!(names(dir.path()).len(), 1, "no temporary left");
    }
}
