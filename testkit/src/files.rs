//! Files for integration tests: the repository's own (scenes, data) and a scratch directory
//! per test process.

use std::path::{Path, PathBuf};

/// The path of a file in the repository (this crate sits at its top level).
pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// A fresh directory for this test process.
pub fn temp_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("zerovar-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `contents` to a file in the temporary directory and returns its path.
///
/// Tests run in parallel and several write the same input file, so the file is written under a
/// unique name and renamed into place: a reader sees the old or the new file, never a truncated one.
pub fn write(name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let path = temp_dir().join(name);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let partial = temp_dir().join(format!(".{name}.{n}.partial"));
    std::fs::write(&partial, contents).unwrap();
    std::fs::rename(&partial, &path).unwrap();
    path
}
