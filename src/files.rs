//! Reading input files (scenes, includes, grids, meshes, images): only regular files, and at
//! most [`MAX_INPUT_BYTES`], so that a directory, a device such as `/dev/zero` or a pipe gives
//! an error at once instead of blocking or filling memory. Writing output files atomically:
//! a temporary file beside the target, renamed over it once complete, so that a failed or
//! interrupted write never leaves a partial file nor destroys the one there before.

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

/// Writes `path` through `write`, which is given a temporary path in the same directory: once
/// it succeeds the temporary file replaces `path` (an atomic rename); if it fails the
/// temporary file is removed and `path` is left as it was.
pub fn write_atomically<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
    rename_failed: impl FnOnce(io::Error) -> E,
) -> Result<(), E> {
    let tmp = temporary_beside(path);
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        rename_failed(e)
    })
}

/// A temporary file name beside `path` (hidden, with the process id, keeping the extension,
/// which the image encoders read the format from).
fn temporary_beside(path: &Path) -> std::path::PathBuf {
    let name = path.file_name().map_or_else(|| "output".into(), |n| n.to_string_lossy());
    let ext = path.extension().map(|e| format!(".{}", e.to_string_lossy())).unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.partial{ext}", std::process::id()))
}

/// Checks that a file can be created at `path` (its directory exists and is writable) by
/// creating and removing a temporary file there, before any work that would write it.
pub fn check_writable(path: &Path) -> io::Result<()> {
    if path.is_dir() {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, "a directory; give a file name"));
    }
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        let message = format!("the directory {} does not exist", dir.display());
        return Err(io::Error::new(io::ErrorKind::NotFound, message));
    }
    let tmp = temporary_beside(path);
    std::fs::File::create(&tmp)?;
    std::fs::remove_file(&tmp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_partial_one() {
        let dir = std::env::temp_dir().join(format!("zerovar-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("out.txt");
        std::fs::write(&path, "old").unwrap();
        let failed: Result<(), String> = write_atomically(
            &path,
            |tmp| {
                std::fs::write(tmp, "half").unwrap();
                Err("encoder failed".into())
            },
            |e| e.to_string(),
        );
        assert_eq!(failed.unwrap_err(), "encoder failed");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "a partial file was left");
        write_atomically(&path, |tmp| std::fs::write(tmp, "new"), |e| e).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        assert!(check_writable(&path).is_ok());
        assert!(check_writable(&dir).is_err());
        assert!(check_writable(&dir.join("missing/out.txt")).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
