//! Reading one plugin's properties by name and type, as Mitsuba's `Properties` does: each
//! lookup records the name it asked for and marks the property used, a value of the wrong type
//! is an error naming both types, and `finish` rejects whatever the plugin did not ask for,
//! listing what it takes.

use super::spectrum::{self, Place};
use super::tree::{Object, Prop, Value};
use crate::scene::SceneError;
use crate::scene::desc::{Rgb, TransformStep};
use glam::Vec3;
use std::cell::RefCell;
use std::rc::Rc;

type Result<T> = std::result::Result<T, SceneError>;

/// The properties of one object, being read.
pub(super) struct Props<'a> {
    pub(super) obj: &'a Object,
    used: RefCell<Vec<bool>>,
    asked: RefCell<Vec<&'static str>>,
}

impl<'a> Props<'a> {
    pub(super) fn new(obj: &'a Object) -> Self {
        Self { obj, used: RefCell::new(vec![false; obj.props.len()]), asked: RefCell::default() }
    }

    /// An error at the object, prefixed with its tag.
    pub(super) fn err(&self, message: impl AsRef<str>) -> SceneError {
        self.obj.pos.err(format!("{}: {}", self.obj.describe(), message.as_ref()))
    }

    /// The property `name`, marked used.
    pub(super) fn raw(&self, name: &'static str) -> Option<&'a Prop> {
        self.asked.borrow_mut().push(name);
        let i = self.obj.props.iter().position(|p| p.name == name)?;
        self.used.borrow_mut()[i] = true;
        Some(&self.obj.props[i])
    }

    /// An error for a property of the wrong type.
    pub(super) fn wrong(&self, p: &Prop, expected: &str) -> SceneError {
        p.pos.err(format!(
            "{}: `{}` must be {expected}, not {}",
            self.obj.describe(),
            p.name,
            p.value.tag()
        ))
    }

    pub(super) fn float(&self, name: &'static str) -> Result<Option<f32>> {
        match self.raw(name) {
            None => Ok(None),
            Some(Prop { value: Value::Float(v), .. }) => Ok(Some(*v as f32)),
            Some(Prop { value: Value::Integer(v), .. }) => Ok(Some(*v as f32)),
            Some(p) => Err(self.wrong(p, "a <float>")),
        }
    }

    pub(super) fn integer(&self, name: &'static str) -> Result<Option<i64>> {
        match self.raw(name) {
            None => Ok(None),
            Some(Prop { value: Value::Integer(v), .. }) => Ok(Some(*v)),
            Some(p) => Err(self.wrong(p, "an <integer>")),
        }
    }

    pub(super) fn boolean(&self, name: &'static str) -> Result<Option<bool>> {
        match self.raw(name) {
            None => Ok(None),
            Some(Prop { value: Value::Boolean(v), .. }) => Ok(Some(*v)),
            Some(p) => Err(self.wrong(p, "a <boolean>")),
        }
    }

    pub(super) fn string(&self, name: &'static str) -> Result<Option<(&'a str, &'a Prop)>> {
        match self.raw(name) {
            None => Ok(None),
            Some(p @ Prop { value: Value::String(v), .. }) => Ok(Some((v.as_str(), p))),
            Some(p) => Err(self.wrong(p, "a <string>")),
        }
    }

    /// A colour: `<rgb>`, `<float>` or a `<spectrum>`.
    pub(super) fn color(&self, name: &'static str) -> Result<Option<Rgb>> {
        match self.raw(name) {
            None => Ok(None),
            Some(p) => color(p, &self.obj.tag).map(Some).ok_or_else(|| self.wrong(p, COLOR)),
        }
    }

    /// A `<point>` or `<vector>`.
    pub(super) fn vector(&self, name: &'static str) -> Result<Option<Vec3>> {
        match self.raw(name) {
            None => Ok(None),
            Some(Prop { value: Value::Point(v) | Value::Vector(v), .. }) => Ok(Some(*v)),
            Some(p) => Err(self.wrong(p, "a <point> or <vector>")),
        }
    }

    pub(super) fn transform(&self, name: &'static str) -> Result<Option<&'a [TransformStep]>> {
        match self.raw(name) {
            None => Ok(None),
            Some(Prop { value: Value::Transform(t), .. }) => Ok(Some(t)),
            Some(p) => Err(self.wrong(p, "a <transform>")),
        }
    }

    /// The nested objects with tag `tag` and the properties holding them, whatever their
    /// names, marked used.
    pub(super) fn objects(&self, tag: &'static str) -> Vec<(&'a Prop, &'a Rc<Object>)> {
        self.asked.borrow_mut().push(tag);
        let mut used = self.used.borrow_mut();
        let mut out = Vec::new();
        for (i, p) in self.obj.props.iter().enumerate() {
            if let Value::Object(o) = &p.value
                && o.tag == tag
            {
                used[i] = true;
                out.push((p, o));
            }
        }
        out
    }

    /// The one nested object with tag `tag`, if any; more than one is an error.
    pub(super) fn object(&self, tag: &'static str) -> Result<Option<&'a Rc<Object>>> {
        match self.objects(tag).as_slice() {
            [] => Ok(None),
            [(_, o)] => Ok(Some(o)),
            [_, (second, _), ..] => Err(second
                .pos
                .err(format!("{} takes one <{tag}>; remove the others", self.obj.describe()))),
        }
    }

    /// Rejects every property and nested object that was not asked for.
    pub(super) fn finish(&self) -> Result<()> {
        let used = self.used.borrow();
        let Some(i) = used.iter().position(|u| !u) else { return Ok(()) };
        let p = &self.obj.props[i];
        let mut asked: Vec<&str> = Vec::new();
        for name in self.asked.borrow().iter() {
            if !asked.contains(name) {
                asked.push(name);
            }
        }
        let takes = if asked.is_empty() {
            "it takes nothing".to_string()
        } else {
            format!("it takes {}", asked.join(", "))
        };
        Err(p.pos.err(match &p.value {
            Value::Object(o) if p.name.is_empty() => {
                format!("{} cannot hold {}; {takes}", self.obj.describe(), o.describe())
            }
            v => format!(
                "{} has no property `{}` ({}) in zerovar's subset; {takes}",
                self.obj.describe(),
                p.name,
                v.tag()
            ),
        }))
    }
}

pub(super) const COLOR: &str = "a colour (<rgb>, <float> or <spectrum>)";

/// A property's value as a colour, if it is one; `tag` is the tag of the object that holds
/// the property (a spectrum inside an `<emitter>` reads differently, see `spectrum`).
pub(super) fn color(p: &Prop, tag: &str) -> Option<Rgb> {
    match &p.value {
        Value::Rgb(c) => Some(*c),
        Value::Float(v) => Some(Rgb::Grey(*v as f32)),
        Value::Integer(v) => Some(Rgb::Grey(*v as f32)),
        Value::Spectrum(v) => Some(spectrum::uniform(*v, Place::of(tag, &p.name))),
        Value::SpectrumPairs(pairs) => Some(spectrum::pairs(pairs, Place::of(tag, &p.name))),
        _ => None,
    }
}
