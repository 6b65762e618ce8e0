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
pub fn write(name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = temp_dir().join(name);
    std::fs::write(&path, contents).unwrap();
    path
}
