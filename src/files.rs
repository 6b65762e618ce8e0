//! Reading input files (scenes, includes, grids, meshes, images): only regular files, and at
//! most [`MAX_INPUT_BYTES`], so that a directory, a device such as `/dev/zero` or a pipe gives
//! an error at once instead of blocking or filling memory.

use std::io;
use std::path::Path;

/// The largest input file zerovar reads (4 GiB): far above any scene, grid, mesh or image it
/// renders, and below what would exhaust a workstation's memory.
pub const MAX_INPUT_BYTES: u64 = 1 << 32;

/// Checks that `path` is a regular file of at most [`MAX_INPUT_BYTES`].
pub(crate) fn check(path: &Path) -> io::Result<()> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file (a directory, device or pipe); give a file",
        ));
    }
    if meta.len() > MAX_INPUT_BYTES {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} bytes, more than the {MAX_INPUT_BYTES} zerovar reads", meta.len()),
        ));
    }
    Ok(())
}

/// The bytes of the file at `path`, after [`check`].
pub(crate) fn read(path: &Path) -> io::Result<Vec<u8>> {
    check(path)?;
    std::fs::read(path)
}

/// The text of the file at `path`, after [`check`].
pub(crate) fn read_to_string(path: &Path) -> io::Result<String> {
    check(path)?;
    std::fs::read_to_string(path)
}
