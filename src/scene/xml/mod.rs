//! Mitsuba 3 XML scenes: a subset of the format read into the same `desc::SceneDesc` the TOML
//! loader produces, so both go through one `build` and render alike. `tree` reads the XML
//! (defaults, includes, refs, transforms, typed properties), `props` reads one plugin's
//! properties with Mitsuba's type rules, and `scene`, `shapes` and `media` map each plugin onto
//! the description. Anything outside the subset is an error at its line and column that says
//! what is supported; nothing is skipped silently.

mod cie;
mod media;
mod props;
mod scene;
mod shapes;
mod spectrum;
mod tree;

use super::desc::{MediumDesc, SceneDesc, TransformStep};
use super::{SceneError, Sources};
use crate::transform::Transform;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use toml::Spanned;
use tree::{Object, Pos, Prop};

type Result<T> = std::result::Result<T, SceneError>;

/// Reads the Mitsuba scene `path` (text `source`); `defines` set or override `<default>`s.
pub(super) fn parse(
    path: &Path,
    source: &str,
    defines: &[(String, String)],
) -> Result<(SceneDesc, Sources)> {
    let mut sources = Sources::default();
    let (root, search) = tree::read(path, source, defines, &mut sources)?;
    let mut conv = Conv {
        root_dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
        search,
        media: BTreeMap::new(),
        medium_names: HashMap::new(),
        sampling_weight: Default::default(),
    };
    let desc = scene::scene(&mut conv, &root)?;
    Ok((desc, sources))
}

/// What the conversion collects across plugins.
struct Conv {
    /// The scene file's directory, which `build` resolves file names against.
    root_dir: PathBuf,
    /// Directories added by `<path>`, the last first.
    search: Vec<PathBuf>,
    media: BTreeMap<String, Spanned<MediumDesc>>,
    /// The name each medium object got, so a medium referenced twice is one medium.
    medium_names: HashMap<*const Object, String>,
    /// The first emitter's `sampling_weight` (1 where it gives none) and where it was given:
    /// every other emitter's must equal it (see `shapes::sampling_weight`).
    sampling_weight: std::cell::RefCell<Option<(f32, Option<tree::Pos>)>>,
}

impl Conv {
    /// A file named by property `p` (see `tree::resolve`), as a path relative to the scene
    /// file's directory or absolute; a missing file is an error at the property.
    fn file(&self, name: &str, p: &Prop) -> Result<String> {
        let dir = p.pos.path.parent().unwrap_or(Path::new(""));
        let Some(file) = tree::resolve(name, dir, &self.search, &self.root_dir) else {
            return Err(p.pos.err(format!(
                "`{}`: {} not found; file names are relative to the file that gives them, a \
                 <path> directory or the scene file",
                p.name,
                dir.join(name).display()
            )));
        };
        let rel = match file.strip_prefix(&self.root_dir) {
            Ok(rel) => rel.to_path_buf(),
            Err(_) => file.canonicalize().unwrap_or(file),
        };
        Ok(rel.to_string_lossy().into_owned())
    }
}

/// A value carrying the element's place, for `build`'s errors.
fn spanned<T>(pos: &Pos, value: T) -> Spanned<T> {
    Spanned::new(pos.offset..pos.offset + 1, value)
}

/// A transform list composed, or an error naming the degenerate step.
fn compose(steps: &[TransformStep], pos: &Pos, what: &str) -> Result<Transform> {
    super::build::compose(steps).map_err(|i| {
        pos.err(format!(
            "{what}: step {} is degenerate (zero axis or scale, origin = target, up parallel to \
             the view, or a singular or non-affine matrix)",
            i + 1
        ))
    })
}
