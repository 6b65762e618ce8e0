//! Output paths checked before any work: none may be an input or another output, so that a
//! mistyped flag never replaces the scene, the reference or a field, nor one output another,
//! and each must be writable, so that a long render never ends in an error about its output.

use anyhow::{Result, bail};
use std::path::{Path, PathBuf};

/// `path` made absolute, its directory resolved through links (the file need not exist).
fn resolved(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match (dir.canonicalize(), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// Refuses an output that is one of the inputs, that another output also writes, or that
/// cannot be written (a missing or read-only directory). Each path comes with what names it
/// (a flag, or what it is).
pub(super) fn check_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    let inputs: Vec<(&str, &Path, PathBuf)> =
        inputs.iter().map(|&(what, p)| (what, p, resolved(p))).collect();
    let mut written: Vec<(&str, PathBuf)> = Vec::with_capacity(outputs.len());
    for &(flag, out) in outputs {
        let o = resolved(out);
        if let Some((what, input, _)) = inputs.iter().find(|(_, _, p)| *p == o) {
            bail!(
                "{flag} {}: that is {what} ({}), which writing would replace; give another path",
                out.display(),
                input.display()
            );
        }
        if let Some((other, _)) = written.iter().find(|(_, p)| *p == o) {
            bail!(
                "{flag} {}: {other} is written there too; give them different paths",
                out.display()
            );
        }
        if let Err(e) = zerovar::files::check_writable(out) {
            bail!(
                "{flag} {}: cannot write there ({e}); give a path in a writable directory",
                out.display()
            );
        }
        written.push((flag, o));
    }
    Ok(())
}
