//! Reading Mitsuba 3 XML into a tree of plugin objects with typed, named properties, before
//! any plugin is interpreted: `<default>` values and `-D` overrides substituted for `$name` in
//! attribute values, `<include>` files spliced in (cycles rejected), `<ref id>` resolved to
//! the object of that id (defined before or after it, as in Mitsuba), transforms read into `TransformStep` lists, and every element,
//! attribute and value checked against the format, with an error at its line and column.

use crate::scene::desc::{Rgb, TransformStep};
use crate::scene::{SceneError, Sources};
use glam::Vec3;
use roxmltree::Node;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

type Result<T> = std::result::Result<T, SceneError>;

/// Where an element starts: file, 1-based line and column, and its offset in `Sources`.
#[derive(Clone, Debug)]
pub(super) struct Pos {
    pub(super) path: Rc<Path>,
    pub(super) line: usize,
    pub(super) column: usize,
    pub(super) offset: usize,
}

impl Pos {
    /// An error at this place.
    pub(super) fn err(&self, message: impl Into<String>) -> SceneError {
        SceneError::Parse {
            path: self.path.to_path_buf(),
            line: self.line,
            column: self.column,
            message: message.into(),
        }
    }
}

/// A property's value.
#[derive(Clone, Debug)]
pub(super) enum Value {
    Float(f64),
    Integer(i64),
    Boolean(bool),
    String(String),
    Rgb(Rgb),
    /// A `<spectrum>` with one value.
    Spectrum(f32),
    /// A `<spectrum>` of wavelength:value pairs (nm), at least two, wavelengths increasing.
    SpectrumPairs(Vec<[f64; 2]>),
    Point(Vec3),
    Vector(Vec3),
    Transform(Vec<TransformStep>),
    /// A nested plugin, or one named by `<ref id>`.
    Object(Rc<Object>),
}

impl Value {
    /// The element that gives this kind of value, for messages.
    pub(super) fn tag(&self) -> String {
        match self {
            Value::Float(_) => "<float>".into(),
            Value::Integer(_) => "<integer>".into(),
            Value::Boolean(_) => "<boolean>".into(),
            Value::String(_) => "<string>".into(),
            Value::Rgb(_) => "<rgb>".into(),
            Value::Spectrum(_) | Value::SpectrumPairs(_) => "<spectrum>".into(),
            Value::Point(_) => "<point>".into(),
            Value::Vector(_) => "<vector>".into(),
            Value::Transform(_) => "<transform>".into(),
            Value::Object(o) => o.describe(),
        }
    }
}

/// A property of an object; nested objects without a `name` have an empty one.
#[derive(Debug)]
pub(super) struct Prop {
    pub(super) name: String,
    pub(super) value: Value,
    pub(super) pos: Pos,
}

/// A plugin instance (`<shape type="sphere">`), or the `<scene>` itself.
#[derive(Debug)]
pub(super) struct Object {
    pub(super) tag: String,
    pub(super) kind: String,
    pub(super) id: Option<String>,
    pub(super) pos: Pos,
    pub(super) props: Vec<Prop>,
}

impl Object {
    /// The opening tag, for messages: `<shape type="sphere">`.
    pub(super) fn describe(&self) -> String {
        if self.tag == "scene" {
            "<scene>".into()
        } else {
            format!("<{} type=\"{}\">", self.tag, self.kind)
        }
    }
}

const OBJECT_TAGS: &[&str] = &[
    "integrator",
    "sensor",
    "film",
    "rfilter",
    "sampler",
    "shape",
    "bsdf",
    "texture",
    "emitter",
    "medium",
    "phase",
    "volume",
];
const PROPERTY_TAGS: &str = "float, integer, boolean, string, rgb, spectrum, point, vector, \
                             transform, ref";

/// Reads the scene file `path` (text `source`) and the files it includes into the `<scene>`
/// object and the directories `<path>` elements added, the last first; every file read is
/// added to `sources`.
pub(super) fn read(
    path: &Path,
    source: &str,
    defines: &[(String, String)],
    sources: &mut Sources,
) -> Result<(Object, Vec<PathBuf>)> {
    let mut reader = Reader {
        params: defines.iter().cloned().collect(),
        nesting: 0,
        includes: 0,
        ids: HashMap::new(),
        forward_refs: false,
        sources,
        stack: Vec::new(),
        root_dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
        search: Vec::new(),
    };
    let (pos, props) = reader.file(path, source, true)?;
    let props = if reader.forward_refs {
        let mut linker =
            Linker { ids: &reader.ids, done: HashMap::new(), open: Vec::new(), depth: 0 };
        linker.props(&props)?
    } else {
        props
    };
    let scene = Object { tag: "scene".into(), kind: "scene".into(), id: None, pos, props };
    Ok((scene, reader.search))
}

/// The tag of the stand-in a `<ref>` to an object not read yet becomes, its `kind` the id:
/// Mitsuba resolves references once the whole file is read, so a sensor may name a medium
/// defined after it.
const FORWARD_REF: &str = "ref";

/// Replaces forward references by their objects once every object is read. An object with an
/// id is linked once and shared wherever it is referenced (a medium referenced twice stays one
/// medium); a reference cycle is an error.
struct Linker<'a> {
    ids: &'a HashMap<String, Rc<Object>>,
    done: HashMap<String, Rc<Object>>,
    /// Ids being linked, outermost first.
    open: Vec<String>,
    /// Objects being rebuilt, nested in each other and through references.
    depth: usize,
}

impl Linker<'_> {
    fn props(&mut self, props: &[Prop]) -> Result<Vec<Prop>> {
        props
            .iter()
            .map(|p| {
                let value = match &p.value {
                    Value::Object(o) => Value::Object(self.object(o)?),
                    other => other.clone(),
                };
                Ok(Prop { name: p.name.clone(), value, pos: p.pos.clone() })
            })
            .collect()
    }

    fn object(&mut self, o: &Rc<Object>) -> Result<Rc<Object>> {
        if o.tag == FORWARD_REF {
            let id = &o.kind;
            let Some(target) = self.ids.get(id) else {
                return Err(o.pos.err(format!(
                    "<ref id=\"{id}\"> names no object; define an object with id=\"{id}\" \
                     in the scene"
                )));
            };
            return self.object(&target.clone());
        }
        let Some(id) = &o.id else { return self.rebuilt(o) };
        if let Some(done) = self.done.get(id) {
            return Ok(done.clone());
        }
        if self.open.contains(id) {
            return Err(o.pos.err(format!(
                "{} refers to itself through <ref id=\"{id}\">; an object cannot contain itself",
                o.describe()
            )));
        }
        // Each link in a chain of references nests the linker once more: a hostile file's
        // chain must not overflow the stack.
        if self.open.len() >= MAX_NESTING {
            return Err(o.pos.err(format!(
                "references nested more than {MAX_NESTING} deep; no scene needs that"
            )));
        }
        self.open.push(id.clone());
        let linked = self.rebuilt(o);
        self.open.pop();
        let linked = linked?;
        self.done.insert(id.clone(), linked.clone());
        Ok(linked)
    }

    fn rebuilt(&mut self, o: &Object) -> Result<Rc<Object>> {
        // Nesting within the file and chains of references multiply: the whole depth is
        // bounded, so a hostile file cannot overflow the stack.
        if self.depth >= 2 * MAX_NESTING {
            return Err(o.pos.err(format!(
                "objects nested more than {} deep, counting those reached through <ref>; no \
                 scene needs that",
                2 * MAX_NESTING
            )));
        }
        self.depth += 1;
        let props = self.props(&o.props);
        self.depth -= 1;
        Ok(Rc::new(Object {
            tag: o.tag.clone(),
            kind: o.kind.clone(),
            id: o.id.clone(),
            pos: o.pos.clone(),
            props: props?,
        }))
    }
}

/// Deepest nesting of elements read: far beyond any real scene, and shallow enough that a
/// hostile file cannot overflow the stack of the recursive reader.
const MAX_NESTING: usize = 64;
/// Most `<include>` elements read in all: a file including another twice, which includes a
/// third twice, and so on, would otherwise be read an exponential number of times.
const MAX_INCLUDES: usize = 1024;

struct Reader<'s> {
    /// `$name` values: `-D` first, then `<default>` elements in document order.
    params: HashMap<String, String>,
    /// Elements open around the one being read, and includes read so far.
    nesting: usize,
    includes: usize,
    ids: HashMap<String, Rc<Object>>,
    /// Whether some `<ref>` named an object not read yet (see [`FORWARD_REF`]).
    forward_refs: bool,
    sources: &'s mut Sources,
    /// Files being read, outermost first, to detect cyclic includes.
    stack: Vec<PathBuf>,
    /// The scene file's directory.
    root_dir: PathBuf,
    /// Directories added by `<path>`, the last first.
    search: Vec<PathBuf>,
}

impl Reader<'_> {
    /// Reads one file's `<scene>` and returns its position and children; `top` when they are
    /// the scene's own (not included inside an object).
    fn file(&mut self, path: &Path, source: &str, top: bool) -> Result<(Pos, Vec<Prop>)> {
        let base = self.sources.push(path.to_path_buf(), source.to_string());
        let path: Rc<Path> = Rc::from(path);
        let doc = roxmltree::Document::parse(source).map_err(|e| {
            let p = e.pos();
            SceneError::Parse {
                path: path.to_path_buf(),
                line: p.row as usize,
                column: p.col as usize,
                message: format!(
                    "malformed XML: {}",
                    e.to_string().trim_end_matches(&format!(" at {}:{}", p.row, p.col))
                ),
            }
        })?;
        let at = |node: Node<'_, '_>| {
            let p = doc.text_pos_at(node.range().start);
            Pos {
                path: path.clone(),
                line: p.row as usize,
                column: p.col as usize,
                offset: base + node.range().start,
            }
        };
        let root = doc.root_element();
        let pos = at(root);
        if root.tag_name().name() != "scene" {
            return Err(pos.err(format!(
                "the root element is <{}>; a Mitsuba scene file holds one \
                 <scene version=\"3.0.0\">",
                root.tag_name().name()
            )));
        }
        self.attributes(root, &pos, &["version"])?;
        match self.attr(root, &pos, "version")? {
            Some(v) if v.starts_with("2.") || v.starts_with("3.") => {}
            Some(v) => {
                return Err(pos.err(format!(
                    "<scene version=\"{v}\">: only Mitsuba 2 and 3 scenes (version 2.x or 3.x) \
                     are read; upgrade older scenes with Mitsuba first"
                )));
            }
            // Included files may leave the version out, as in Mitsuba.
            None if !self.stack.is_empty() => {}
            None => {
                return Err(pos.err("<scene> needs a version attribute, e.g. version=\"3.0.0\""));
            }
        }
        let props = self.children(root, &at, top)?;
        Ok((pos, props))
    }

    /// The properties and objects nested in `node`.
    fn children(
        &mut self,
        node: Node<'_, '_>,
        at: &dyn Fn(Node<'_, '_>) -> Pos,
        top: bool,
    ) -> Result<Vec<Prop>> {
        let mut props: Vec<Prop> = Vec::new();
        for child in node.children() {
            if child.is_text() {
                if child.text().is_some_and(|t| !t.trim().is_empty()) {
                    return Err(at(child).err(format!(
                        "unexpected text inside <{}>; values go in value=\"...\" attributes",
                        node.tag_name().name()
                    )));
                }
                continue;
            }
            if !child.is_element() {
                continue;
            }
            for p in self.element(node, child, at, top)? {
                if let Some(first) = props.iter().find(|q| !p.name.is_empty() && q.name == p.name) {
                    return Err(p.pos.err(format!(
                        "`{}` is given twice (first at line {}); give it once",
                        p.name, first.pos.line
                    )));
                }
                props.push(p);
            }
        }
        Ok(props)
    }

    /// The properties one child element of `node` gives (none for a `<default>` or `<path>`,
    /// several for an `<include>`).
    fn element(
        &mut self,
        node: Node<'_, '_>,
        child: Node<'_, '_>,
        at: &dyn Fn(Node<'_, '_>) -> Pos,
        top: bool,
    ) -> Result<Vec<Prop>> {
        let pos = at(child);
        let tag = child.tag_name().name();
        Ok(match tag {
            "default" | "path" if !top => {
                return Err(pos.err(format!(
                    "<{tag}> belongs directly inside <scene>, not inside <{}>",
                    node.tag_name().name()
                )));
            }
            "default" => {
                self.declare_default(child, &pos)?;
                vec![]
            }
            "include" => self.include(child, &pos, top)?,
            "path" => {
                self.path(child, &pos)?;
                vec![]
            }
            "ref" if top => {
                return Err(pos.err(
                    "<ref> belongs inside the object that uses the referenced one, not in \
                     <scene>",
                ));
            }
            "ref" => vec![self.reference(child, pos)?],
            t if OBJECT_TAGS.contains(&t) => vec![self.object(child, at, t, pos)?],
            "transform" => {
                self.attributes(child, &pos, &["name"])?;
                let name = self.required(child, &pos, "name")?;
                vec![Prop { name, value: Value::Transform(self.transform(child, at)?), pos }]
            }
            "spectrum" if child.attribute("type").is_some() => {
                let value = self.typed_spectrum(child, &pos, at)?;
                vec![Prop { name: self.required(child, &pos, "name")?, value, pos }]
            }
            "float" | "integer" | "boolean" | "string" | "rgb" | "spectrum" | "point"
            | "vector" => {
                let value = self.value(child, &pos)?;
                vec![Prop { name: self.required(child, &pos, "name")?, value, pos }]
            }
            other => {
                return Err(pos.err(format!(
                    "unknown element <{other}>; use an object ({}), a property \
                     ({PROPERTY_TAGS}), {}",
                    OBJECT_TAGS.join(", "),
                    if top { "<default>, <path> or <include>" } else { "or <include>" }
                )));
            }
        })
    }

    /// `<default name value>`: a value for `$name` unless `-D` gave one.
    fn declare_default(&mut self, child: Node<'_, '_>, pos: &Pos) -> Result<()> {
        self.attributes(child, pos, &["name", "value"])?;
        let name = self.required(child, pos, "name")?;
        let value = self.required(child, pos, "value")?;
        // As in Mitsuba, the first value of a name wins: a -D value (put there first), then
        // the first <default> (an included file may repeat the scene's).
        self.params.entry(name).or_insert(value);
        Ok(())
    }

    /// `<path value>`: a directory searched for file names, before the ones given earlier.
    fn path(&mut self, child: Node<'_, '_>, pos: &Pos) -> Result<()> {
        self.attributes(child, pos, &["value"])?;
        let value = self.required(child, pos, "value")?;
        let dir = pos.path.parent().unwrap_or(Path::new("")).join(&value);
        if !dir.is_dir() {
            return Err(
                pos.err(format!("<path value=\"{value}\">: {} is not a directory", dir.display()))
            );
        }
        self.search.insert(0, dir);
        Ok(())
    }

    /// `<ref id [name]>`: an object defined earlier, or a stand-in for one defined later.
    fn reference(&mut self, child: Node<'_, '_>, pos: Pos) -> Result<Prop> {
        self.attributes(child, &pos, &["id", "name"])?;
        let id = self.required(child, &pos, "id")?;
        let object = match self.ids.get(&id) {
            Some(object) => object.clone(),
            None => {
                self.forward_refs = true;
                let tag = FORWARD_REF.to_string();
                Rc::new(Object { tag, kind: id, id: None, pos: pos.clone(), props: Vec::new() })
            }
        };
        let name = self.attr(child, &pos, "name")?.unwrap_or_default();
        Ok(Prop { name, value: Value::Object(object), pos })
    }

    /// An object element (`<shape>`, `<bsdf>`, ...) with its properties, remembered by its id.
    fn object(
        &mut self,
        child: Node<'_, '_>,
        at: &dyn Fn(Node<'_, '_>) -> Pos,
        t: &str,
        pos: Pos,
    ) -> Result<Prop> {
        self.attributes(child, &pos, &["type", "id", "name"])?;
        let Some(kind) = self.attr(child, &pos, "type")? else {
            return Err(pos.err(format!(
                "<{t}> needs a type attribute naming its plugin, e.g. <{t} type=\"...\">"
            )));
        };
        let id = self.attr(child, &pos, "id")?;
        let name = self.attr(child, &pos, "name")?.unwrap_or_default();
        if self.nesting >= MAX_NESTING {
            return Err(pos
                .err(format!("objects nested more than {MAX_NESTING} deep; no scene needs that")));
        }
        self.nesting += 1;
        let inner = self.children(child, at, false);
        self.nesting -= 1;
        let object = Rc::new(Object {
            tag: t.to_string(),
            kind,
            id: id.clone(),
            pos: pos.clone(),
            props: inner?,
        });
        if let Some(id) = id {
            if let Some(first) = self.ids.get(&id) {
                return Err(pos.err(format!(
                    "id \"{id}\" is already used by {} at line {}; ids must be unique",
                    first.describe(),
                    first.pos.line
                )));
            }
            self.ids.insert(id, object.clone());
        }
        Ok(Prop { name, value: Value::Object(object), pos })
    }

    fn include(&mut self, node: Node<'_, '_>, pos: &Pos, top: bool) -> Result<Vec<Prop>> {
        self.attributes(node, pos, &["filename"])?;
        let name = self.required(node, pos, "filename")?;
        self.includes += 1;
        if self.includes > MAX_INCLUDES {
            return Err(pos.err(format!(
                "more than {MAX_INCLUDES} <include> elements in all; include each file once"
            )));
        }
        let dir = pos.path.parent().unwrap_or(Path::new(""));
        let file =
            resolve(&name, dir, &self.search, &self.root_dir).unwrap_or_else(|| dir.join(&name));
        let text = crate::files::read_to_string(&file).map_err(|e| {
            pos.err(format!("<include filename=\"{name}\">: cannot read {}: {e}", file.display()))
        })?;
        let key = file.canonicalize().unwrap_or_else(|_| file.clone());
        if self.stack.is_empty() {
            self.stack.push(pos.path.canonicalize().unwrap_or_else(|_| pos.path.to_path_buf()));
        }
        if let Some(i) = self.stack.iter().position(|f| *f == key) {
            let chain: Vec<String> =
                self.stack[i..].iter().map(|f| f.display().to_string()).collect();
            return Err(pos.err(format!(
                "cyclic include: {} includes {} again; remove one of these includes",
                chain.join(" -> "),
                key.display()
            )));
        }
        if self.stack.len() > MAX_NESTING {
            return Err(pos.err(format!(
                "includes nested more than {MAX_NESTING} deep; no scene needs that"
            )));
        }
        self.stack.push(key);
        let (_, props) = self.file(&file, &text, top)?;
        self.stack.pop();
        Ok(props)
    }

    /// The steps of a `<transform>`, in document order.
    fn transform(
        &mut self,
        node: Node<'_, '_>,
        at: &dyn Fn(Node<'_, '_>) -> Pos,
    ) -> Result<Vec<TransformStep>> {
        let mut steps = Vec::new();
        for child in node.children() {
            if child.is_text() && child.text().is_some_and(|t| !t.trim().is_empty()) {
                return Err(at(child).err("unexpected text inside <transform>"));
            }
            if !child.is_element() {
                continue;
            }
            let pos = at(child);
            let step = match child.tag_name().name() {
                "translate" => {
                    self.attributes(child, &pos, &["x", "y", "z", "value"])?;
                    TransformStep::Translate(self.xyz(child, &pos, 0.0)?)
                }
                "scale" => {
                    self.attributes(child, &pos, &["x", "y", "z", "value"])?;
                    TransformStep::Scale(Rgb::Rgb(self.xyz(child, &pos, 1.0)?.into()))
                }
                "rotate" => {
                    self.attributes(child, &pos, &["x", "y", "z", "value", "angle"])?;
                    let axis = self.xyz(child, &pos, 0.0)?;
                    let angle = self.required(child, &pos, "angle")?;
                    let angle = number(&angle).ok_or_else(|| {
                        pos.err(format!("<rotate angle=\"{angle}\">: the angle must be a number"))
                    })?;
                    mitsuba_rotation(axis, angle)
                }
                "matrix" => {
                    self.attributes(child, &pos, &["value"])?;
                    let v = self.required(child, &pos, "value")?;
                    let n = numbers(&v).unwrap_or_default();
                    // Row by row: a 4x4 matrix, or the linear part of one (3x3).
                    let k = match n.len() {
                        16 => 4,
                        9 => 3,
                        _ => {
                            return Err(pos.err(
                                "<matrix value=\"...\"> needs 16 numbers (a 4x4 matrix row by row) \
                                 or 9 (3x3)",
                            ));
                        }
                    };
                    TransformStep::Matrix(std::array::from_fn(|r| {
                        std::array::from_fn(|c| match (r < k && c < k, r == c) {
                            (true, _) => n[k * r + c],
                            (false, diagonal) => f32::from(u8::from(diagonal)),
                        })
                    }))
                }
                "lookat" => {
                    self.attributes(child, &pos, &["origin", "target", "up"])?;
                    let mut v = [Vec3::ZERO; 3];
                    for (slot, name) in v.iter_mut().zip(["origin", "target", "up"]) {
                        let text = match self.attr(child, &pos, name)? {
                            Some(t) => t,
                            None if name == "up" => continue,
                            None => self.required(child, &pos, name)?,
                        };
                        *slot = vec3(&text).ok_or_else(|| {
                            pos.err(format!("<lookat {name}=\"{text}\">: needs three numbers"))
                        })?;
                    }
                    let [origin, target, mut up] = v;
                    if up == Vec3::ZERO {
                        // As Mitsuba: a direction perpendicular to the view.
                        up = perpendicular((target - origin).normalize_or_zero());
                    }
                    TransformStep::Lookat { origin, target, up }
                }
                other => {
                    return Err(pos.err(format!(
                        "unknown element <{other}> in <transform>; use translate, rotate, scale, \
                         matrix or lookat"
                    )));
                }
            };
            if child.children().any(|c| c.is_element()) {
                return Err(pos.err(format!("<{}> holds no elements", child.tag_name().name())));
            }
            steps.push(step);
        }
        Ok(steps)
    }

    /// A `<spectrum type="...">`: Mitsuba's `d65`, which its RGB variants read as white times
    /// its `scale`. (Its `blackbody` has no RGB form: Mitsuba's RGB variants refuse it too.)
    fn typed_spectrum(
        &mut self,
        node: Node<'_, '_>,
        pos: &Pos,
        at: &dyn Fn(Node<'_, '_>) -> Pos,
    ) -> Result<Value> {
        self.attributes(node, pos, &["name", "type"])?;
        let kind = self.required(node, pos, "type")?;
        match kind.as_str() {
            "d65" => {
                let mut scale = 1.0;
                for child in node.children().filter(|c| c.is_element()) {
                    let child_pos = at(child);
                    let is_scale = child.tag_name().name() == "float"
                        && child.attribute("name") == Some("scale");
                    match self.value(child, &child_pos)? {
                        Value::Float(v) if is_scale => scale = v,
                        _ => {
                            return Err(child_pos
                                .err("<spectrum type=\"d65\"> takes only <float name=\"scale\">"));
                        }
                    }
                }
                Ok(Value::Rgb(Rgb::Grey(scale as f32)))
            }
            "blackbody" => Err(pos.err(
                "a blackbody spectrum exists only in Mitsuba's spectral variants (its RGB variants \
                 refuse it too); zerovar renders as the RGB variants do: give the colour as <rgb>",
            )),
            other => Err(pos.err(format!(
                "<spectrum type=\"{other}\"> is not supported; zerovar reads type \"d65\", \
                 wavelength:value lists and single values"
            ))),
        }
    }

    /// The value of a property element.
    fn value(&mut self, node: Node<'_, '_>, pos: &Pos) -> Result<Value> {
        let tag = node.tag_name().name();
        if node.children().any(|c| c.is_element()) {
            return Err(pos.err(format!("<{tag}> holds no elements")));
        }
        if tag == "point" || tag == "vector" {
            self.attributes(node, pos, &["name", "value", "x", "y", "z"])?;
            let v = self.xyz(node, pos, 0.0)?;
            return Ok(if tag == "point" { Value::Point(v) } else { Value::Vector(v) });
        }
        self.attributes(node, pos, &["name", "value"])?;
        let text = self.required(node, pos, "value")?;
        let bad =
            |what: &str| pos.err(format!("<{tag} value=\"{text}\">: the value must be {what}"));
        Ok(match tag {
            "float" => Value::Float(text.trim().parse().map_err(|_| bad("a number"))?),
            "integer" => Value::Integer(text.trim().parse().map_err(|_| bad("an integer"))?),
            "boolean" => match text.trim().to_ascii_lowercase().as_str() {
                "true" => Value::Boolean(true),
                "false" => Value::Boolean(false),
                _ => return Err(bad("true or false")),
            },
            "string" => Value::String(text),
            "rgb" => match numbers(&text).as_deref() {
                Some([v]) => Value::Rgb(Rgb::Grey(*v)),
                Some([r, g, b]) => Value::Rgb(Rgb::Rgb([*r, *g, *b])),
                _ => return Err(bad("three numbers \"r, g, b\" or one grey value")),
            },
            _ if text.contains(':') => {
                Value::SpectrumPairs(spectrum_pairs(&text).map_err(|what| bad(&what))?)
            }
            _ => match numbers(&text).as_deref() {
                Some([v]) => Value::Spectrum(*v),
                _ => return Err(bad("one number or wavelength:value pairs (nm)")),
            },
        })
    }

    /// A vector from `value` (three numbers, or one for all three) or from `x`, `y`, `z`
    /// attributes defaulting to `missing`.
    fn xyz(&mut self, node: Node<'_, '_>, pos: &Pos, missing: f32) -> Result<Vec3> {
        let tag = node.tag_name().name();
        if let Some(text) = self.attr(node, pos, "value")? {
            if ["x", "y", "z"].iter().any(|a| node.attribute(*a).is_some()) {
                return Err(pos.err(format!("<{tag}>: give either value or x, y, z, not both")));
            }
            return match numbers(&text).as_deref() {
                Some([v]) => Ok(Vec3::splat(*v)),
                Some([x, y, z]) => Ok(Vec3::new(*x, *y, *z)),
                _ => Err(pos.err(format!(
                    "<{tag} value=\"{text}\">: the value must be three numbers (or one)"
                ))),
            };
        }
        let mut v = [missing; 3];
        for (slot, a) in v.iter_mut().zip(["x", "y", "z"]) {
            if let Some(text) = self.attr(node, pos, a)? {
                *slot = number(&text).ok_or_else(|| {
                    pos.err(format!("<{tag} {a}=\"{text}\">: the value must be a number"))
                })?;
            }
        }
        Ok(Vec3::from_array(v))
    }

    /// Rejects attributes outside `allowed`.
    fn attributes(&self, node: Node<'_, '_>, pos: &Pos, allowed: &[&str]) -> Result<()> {
        match node.attributes().find(|a| !allowed.contains(&a.name())) {
            Some(a) => Err(pos.err(format!(
                "<{}> has no attribute `{}`; it takes {}",
                node.tag_name().name(),
                a.name(),
                allowed.join(", ")
            ))),
            None => Ok(()),
        }
    }

    /// An attribute with `$name` references replaced.
    fn attr(&self, node: Node<'_, '_>, pos: &Pos, name: &str) -> Result<Option<String>> {
        let Some(text) = node.attribute(name) else { return Ok(None) };
        let mut out = String::with_capacity(text.len());
        let mut rest = text;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            // As Mitsuba: the longest parameter name the text goes on with.
            let Some((key, value)) = self
                .params
                .iter()
                .filter(|(k, _)| !k.is_empty() && after.starts_with(k.as_str()))
                .max_by_key(|(k, _)| k.len())
            else {
                let len = after
                    .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                    .unwrap_or(after.len());
                let key = &after[..len];
                return Err(pos.err(format!(
                    "`${key}` in {name}=\"{text}\" names no <default> (nor -D {key}=...); \
                     add <default name=\"{key}\" value=\"...\"/> before it"
                )));
            };
            out.push_str(value);
            rest = &after[key.len()..];
        }
        out.push_str(rest);
        Ok(Some(out))
    }

    fn required(&self, node: Node<'_, '_>, pos: &Pos, name: &str) -> Result<String> {
        self.attr(node, pos, name)?.ok_or_else(|| {
            pos.err(format!("<{}> needs a `{name}` attribute", node.tag_name().name()))
        })
    }
}

/// Where a file name given in directory `dir` points: relative to `dir`, or else (as Mitsuba
/// resolves names) to a `<path>` directory or the scene file's directory.
pub(super) fn resolve(
    name: &str,
    dir: &Path,
    search: &[PathBuf],
    root_dir: &Path,
) -> Option<PathBuf> {
    std::iter::once(dir)
        .chain(search.iter().map(PathBuf::as_path))
        .chain(std::iter::once(root_dir))
        .map(|d| d.join(name))
        .find(|f| f.is_file())
}

fn number(text: &str) -> Option<f32> {
    text.trim().parse().ok()
}

/// The pairs of a `<spectrum value="400:0.1, 500:0.4, ...">`, separated by commas and/or
/// white space as Mitsuba's tokenizer separates them, or what they must be.
fn spectrum_pairs(text: &str) -> std::result::Result<Vec<[f64; 2]>, String> {
    let mut pairs: Vec<[f64; 2]> = Vec::new();
    for item in text.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()) {
        let pair = item.split_once(':').and_then(|(w, v)| {
            let (w, v) = (w.trim().parse::<f64>().ok()?, v.trim().parse::<f64>().ok()?);
            (w.is_finite() && v.is_finite()).then_some([w, v])
        });
        let Some(pair) = pair else {
            let hint = if item.starts_with(':') || item.ends_with(':') {
                " (no space around the `:`, as Mitsuba's tokenizer splits there)"
            } else {
                ""
            };
            return Err(format!("wavelength:value pairs of numbers (nm), not `{item}`{hint}"));
        };
        if let Some(last) = pairs.last()
            && pair[0] <= last[0]
        {
            return Err(format!(
                "pairs in increasing order of wavelength; {} nm follows {} nm",
                pair[0], last[0]
            ));
        }
        pairs.push(pair);
    }
    if pairs.len() < 2 {
        return Err("at least two wavelength:value pairs (nm), or one number".into());
    }
    Ok(pairs)
}

/// Numbers separated by commas and/or white space.
fn numbers(text: &str) -> Option<Vec<f32>> {
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| t.parse().ok())
        .collect()
}

/// The first tangent of the orthonormal basis Mitsuba builds around a unit vector (Duff et
/// al. 2017, "Building an Orthonormal Basis, Revisited").
fn perpendicular(n: Vec3) -> Vec3 {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x)
}

fn vec3(text: &str) -> Option<Vec3> {
    match numbers(text)?.as_slice() {
        [x, y, z] => Some(Vec3::new(*x, *y, *z)),
        _ => None,
    }
}

/// Mitsuba 3 builds `<rotate>` from its axis as given, without normalising it (measured on
/// 3.9.1: x="1" y="1" angle="35" scales and shears as well as rotating), so an axis that is
/// not of unit length becomes the same matrix here, cos(a) I + sin(a) [axis]x +
/// (1 - cos(a)) axis axis^T, and a unit axis stays an ordinary rotation.
fn mitsuba_rotation(axis: Vec3, angle: f32) -> TransformStep {
    let length = axis.as_dvec3().length();
    if length == 0.0 || (length - 1.0).abs() < 1e-6 {
        return TransformStep::Rotate { axis, angle };
    }
    let a = axis.as_dvec3();
    let (sin, cos) = f64::from(angle).to_radians().sin_cos();
    let m = glam::DMat3::from_diagonal(glam::DVec3::splat(cos))
        + glam::DMat3::from_cols(
            glam::DVec3::new(0.0, a.z, -a.y),
            glam::DVec3::new(-a.z, 0.0, a.x),
            glam::DVec3::new(a.y, -a.x, 0.0),
        ) * sin
        + glam::DMat3::from_cols(a * a.x, a * a.y, a * a.z) * (1.0 - cos);
    let row = |r: usize| {
        let r = m.row(r);
        [r.x as f32, r.y as f32, r.z as f32, 0.0]
    };
    TransformStep::Matrix([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]])
}
