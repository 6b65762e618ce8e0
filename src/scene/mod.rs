//! Scenes: loading a TOML description and compiling it into what the integrators query.
//!
//! `load` reads and validates a file into a `Scene` in one step: transforms applied, meshes
//! read, a BVH built, media compiled with the tracker each one needs, lights with their
//! sampling tables. Every error names the file and the place (line, element) and says what to
//! change; nothing is silently clamped.

mod build;
mod builder;
pub mod desc;
mod load;
mod xml;

use crate::accel::{Bvh, BvhHit, ShadowTrace};
use crate::bsdf::Bsdf;
use crate::camera::Camera;
use crate::lights::Light;
use crate::math::{Aabb, Frame, RAY_EPSILON, Ray};
use crate::media::Medium;
use crate::shapes::{Geometry, SurfaceHit};
use crate::tracking::{Tracker, TrackerChoice, TrackerError};
use glam::{Vec2, Vec3A};
use std::path::{Path, PathBuf};
use thiserror::Error;

pub use builder::SceneBuilder;

/// Why a scene could not be loaded.
#[derive(Debug, Error)]
pub enum SceneError {
    /// A file could not be read.
    #[error("{path}: cannot read: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system error.
        error: std::io::Error,
    },
    /// The TOML does not parse or does not fit the scene format.
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{path}:{line}: {place}: {message}")]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// 1-based line of the element.
        line: usize,
        /// The element, e.g. `shapes[2] (sphere)`.
        place: String,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// Code asked for a medium the scene does not have.
    #[error("no medium named `{name}`; the scene's media are: {known}")]
    UnknownMedium {
        /// The name asked for.
        name: String,
        /// The scene's media.
        known: String,
    },
    /// A `-D` override names no default.
    #[error("-D {key}: no such default; {message}")]
    Define {
        /// The key given.
        key: String,
        /// What the scene offers.
        message: String,
    },
}

impl SceneError {
    pub(crate) fn invalid(
        path: &Path,
        source: &str,
        offset: Option<usize>,
        place: &str,
        message: &str,
    ) -> Self {
        SceneError::Invalid {
            path: path.to_path_buf(),
            // Element spans may start at the whitespace before the element's header.
            line: offset.map_or(0, |o| {
                let skip = source.get(o..).map_or(0, |rest| rest.len() - rest.trim_start().len());
                load::line_col(source, o + skip).0
            }),
            place: place.to_string(),
            message: message.to_string(),
        }
    }
}

/// The text a description was parsed from, so that a span's byte offset names a file and a
/// line: one TOML file, or an XML scene and the files it includes, laid end to end (a file's
/// spans are offset by the lengths of the files before it).
#[derive(Debug, Default)]
pub(crate) struct Sources {
    files: Vec<(PathBuf, String)>,
}

impl Sources {
    /// Adds a file and returns the offset its spans start at.
    pub(crate) fn push(&mut self, path: PathBuf, text: String) -> usize {
        let base = self.files.iter().map(|(_, t)| t.len()).sum();
        self.files.push((path, text));
        base
    }

    /// An `Invalid` error at `offset`, in whichever file holds it.
    pub(crate) fn invalid(&self, offset: usize, place: &str, message: &str) -> SceneError {
        let mut base = 0;
        for (i, (path, text)) in self.files.iter().enumerate() {
            if offset < base + text.len() || i + 1 == self.files.len() {
                return SceneError::invalid(path, text, Some(offset - base), place, message);
            }
            base += text.len();
        }
        SceneError::invalid(Path::new(""), "", None, place, message)
    }
}

/// A shape's surface properties.
#[derive(Clone, Debug)]
pub struct Surface {
    /// Scattering model.
    pub bsdf: Bsdf,
    /// Medium behind the (possibly flipped) normal.
    pub interior: Option<u32>,
    /// Medium in front of the normal.
    pub exterior: Option<u32>,
    /// No medium transition: rays keep their medium here (`interior` and `exterior` unused).
    pub keeps_medium: bool,
    /// The area light this shape carries.
    pub light: Option<u32>,
    /// Whether the normals were flipped.
    pub flip: bool,
    /// Short description (kind), for reports.
    pub kind: String,
}

impl Surface {
    /// The medium beyond the surface for a ray going `inward` (against the normal) from
    /// `current`.
    #[inline]
    pub fn medium_beyond(&self, inward: bool, current: Option<u32>) -> Option<u32> {
        if self.keeps_medium {
            current
        } else if inward {
            self.interior
        } else {
            self.exterior
        }
    }
}

/// Integrator settings.
#[derive(Clone, Copy, Debug)]
pub struct RenderSettings {
    /// Default samples per pixel.
    pub spp: u32,
    /// Longest path in scattering events; `None` is unlimited.
    pub max_depth: Option<u32>,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
    /// Default seed.
    pub seed: u64,
    /// Emitters and infinite lights that a path finds before its first scattering event
    /// count zero (Mitsuba's `hide_emitters`).
    pub hide_emitters: bool,
    /// Every surface hit scatters, none is a null event but a null surface's (Mitsuba's
    /// `path` integrator; see `RenderDesc::surface_events_only`).
    pub surface_events_only: bool,
}

/// A surface a shadow ray passes straight through (null, or a thin dielectric): where, the
/// share of light that passes, and the medium beyond it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Crossing {
    /// Ray parameter of the crossing.
    pub(crate) t: f32,
    /// The share of light passing (`Bsdf::null_transmission`).
    pub(crate) passes: f32,
    /// The medium the ray travels in after it.
    pub(crate) medium: Option<u32>,
}

/// A compiled scene, ready to render.
#[derive(Debug)]
pub struct Scene {
    /// The file it came from.
    pub(crate) path: PathBuf,
    /// Shape geometry in world space.
    pub(crate) shapes: Vec<Geometry>,
    /// Per-shape surface properties (same indices as `shapes`).
    pub(crate) surfaces: Vec<Surface>,
    /// Acceleration structure over all shapes.
    pub(crate) bvh: Bvh,
    /// Media.
    pub(crate) media: Vec<Medium>,
    /// The tracker of each medium.
    pub(crate) trackers: Vec<Tracker>,
    /// All lights, area lights included.
    pub(crate) lights: Vec<Light>,
    /// Indices of lights at infinity.
    pub(crate) infinite_lights: Vec<u32>,
    /// Indices of delta lights (guided flights draw extra collisions for them).
    pub(crate) delta_lights: Vec<u32>,
    /// Positions of the point and spot lights (extra collisions aim at them).
    pub(crate) point_lights: Vec<crate::lights::PointLight>,
    /// The camera.
    pub(crate) camera: Camera,
    /// The medium around the camera.
    pub(crate) camera_medium: Option<u32>,
    /// The medium filling otherwise unassigned space.
    pub(crate) global_medium: Option<u32>,
    /// Integrator settings.
    pub(crate) settings: RenderSettings,
    /// The centre and radius of the sphere around the shapes and bounded media.
    pub(crate) world: (glam::Vec3A, f32),
}

/// Loads, validates and compiles a scene file: TOML, or a Mitsuba 3 scene if the name ends in
/// `.xml`. `defines` override `[defaults]` (TOML) or `<default>` (XML) entries.
pub fn load(path: &Path, defines: &[(String, String)]) -> Result<Scene, SceneError> {
    let source = crate::files::read_to_string(path)
        .map_err(|error| SceneError::Io { path: path.to_path_buf(), error })?;
    load_str(path, &source, defines)
}

/// Compiles scene text; `path` names the file, anchors relative paths and, ending in `.xml`,
/// selects the Mitsuba 3 format.
pub fn load_str(
    path: &Path,
    source: &str,
    defines: &[(String, String)],
) -> Result<Scene, SceneError> {
    let is_xml = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml"));
    let (desc, sources) = if is_xml {
        xml::parse(path, source, defines)?
    } else {
        let desc = load::parse(path, source, defines)?;
        let mut sources = Sources::default();
        sources.push(path.to_path_buf(), source.to_string());
        (desc, sources)
    };
    build::build(path, &sources, desc)
}

impl Scene {
    /// How far from `p` a shadow ray towards a light at infinity (a directional light, a
    /// constant or mapped sky) reaches: twice the larger of the scene's bounding radius and
    /// `p`'s distance from its centre, where Mitsuba places such lights. Every shape and
    /// bounded medium lies within it, so only a medium without bounds sees a difference from
    /// an infinite distance: the light comes through that much of it, as in Mitsuba, where an
    /// infinite one would let none through.
    pub fn infinite_reach(&self, p: glam::Vec3A) -> f32 {
        let (centre, radius) = self.world;
        2.0 * radius.max((p - centre).length()).max(1e-5)
    }

    /// The file the scene came from (empty for a scene built in code).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The medium around the camera, as an index into [`Scene::media`].
    pub fn camera_medium(&self) -> Option<u32> {
        self.camera_medium
    }

    /// The medium filling otherwise unassigned space, as an index into [`Scene::media`].
    pub fn global_medium(&self) -> Option<u32> {
        self.global_medium
    }

    /// The media, in the order the scene names them.
    pub fn media(&self) -> &[Medium] {
        &self.media
    }

    /// The free-flight estimator of each medium (same indices as [`Scene::media`]).
    pub fn trackers(&self) -> &[Tracker] {
        &self.trackers
    }

    /// Every light, area lights included.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// Shape geometry in world space.
    pub fn shapes(&self) -> &[Geometry] {
        &self.shapes
    }

    /// Each shape's surface (same indices as [`Scene::shapes`]).
    pub fn surfaces(&self) -> &[Surface] {
        &self.surfaces
    }

    /// Re-chooses every medium's tracker; an error (and no change) if a forced tracker cannot
    /// apply to some medium.
    pub fn set_tracker(&mut self, choice: TrackerChoice) -> Result<(), TrackerError> {
        let trackers = self.media.iter().map(|m| choice.pick(m)).collect::<Result<Vec<_>, _>>()?;
        self.trackers = trackers;
        Ok(())
    }

    /// Sets medium `i`'s tracker, which the caller knows can handle it
    /// ([`crate::tracking::candidates`]).
    pub(crate) fn set_medium_tracker(&mut self, i: usize, tracker: Tracker) {
        debug_assert!(tracker.check(&self.media[i]).is_ok());
        self.trackers[i] = tracker;
    }

    /// The integrator settings and the defaults of a render.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }
    /// Replaces the medium named `name` (keeping the name), for media built in code such as a
    /// `DensityField::Custom`; every medium's tracker is chosen again automatically.
    pub fn replace_medium(&mut self, name: &str, mut medium: Medium) -> Result<(), SceneError> {
        let Some(i) = self.media.iter().position(|m| m.name == name) else {
            let known: Vec<&str> = self.media.iter().map(|m| m.name.as_str()).collect();
            return Err(SceneError::UnknownMedium {
                name: name.to_string(),
                known: known.join(", "),
            });
        };
        medium.name = name.to_string();
        self.media[i] = medium;
        self.trackers = self.media.iter().map(Tracker::for_medium).collect();
        Ok(())
    }

    /// The closest surface hit along `ray` within `(0, t_max)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<SurfaceHit> {
        let h = self.bvh.intersect(&self.shapes, ray, t_max)?;
        let shape = h.prim.shape;
        let (p, mut ng, mut ns, uv) = self.shapes[shape as usize].surface(h.prim.index, ray, h.hit);
        if self.surfaces[shape as usize].flip {
            ng = -ng;
            ns = -ns;
        }
        Some(SurfaceHit { t: h.hit.t, p, ng, ns, uv, shape, prim: h.prim.index })
    }

    /// The shading frame at `hit` whose first axis follows the shape's parameterization (its
    /// derivative along `u` made perpendicular to the shading normal), as Mitsuba 3 builds it
    /// for anisotropic BSDFs; any frame about the normal where that derivative vanishes.
    pub fn tangent_frame(&self, hit: &SurfaceHit) -> Frame {
        let n = hit.ns;
        let dp = self.shapes[hit.shape as usize].tangent(hit.prim, hit.p, hit.ng);
        match (dp - n * n.dot(dp)).try_normalize() {
            Some(s) => Frame { x: s, y: n.cross(s), z: n },
            None => Frame::from_z(n),
        }
    }

    /// Traces a shadow ray that starts in `medium` to `t_max` in one traversal:
    /// [`ShadowTrace::Blocked`] if a surface that lets nothing straight through lies in the way;
    /// otherwise the surfaces it crosses (null ones and thin dielectrics), sorted along the
    /// ray, each with the share of light passing and the medium the ray enters there.
    pub(crate) fn trace_shadow<const N: usize>(
        &self,
        ray: &Ray,
        t_max: f32,
        mut medium: Option<u32>,
        crossings: &mut arrayvec::ArrayVec<Crossing, N>,
    ) -> ShadowTrace {
        crossings.clear();
        let mut hits = arrayvec::ArrayVec::<BvhHit, N>::new();
        let blocks = |shape: u32| !self.surfaces[shape as usize].bsdf.may_pass();
        let trace = self.bvh.shadow(&self.shapes, ray, t_max, blocks, &mut hits);
        if trace == ShadowTrace::Clear {
            hits.sort_unstable_by(|a, b| a.hit.t.total_cmp(&b.hit.t));
            crossings.extend(hits.iter().map(|h| {
                let shape = h.prim.shape as usize;
                let mut ng = self.shapes[shape].normal(h.prim.index, ray, h.hit);
                let s = &self.surfaces[shape];
                if s.flip {
                    ng = -ng;
                }
                let cos = ray.direction.dot(ng);
                medium = s.medium_beyond(cos < 0.0, medium);
                let uv = || self.shapes[shape].surface(h.prim.index, ray, h.hit).3;
                let passes = self.null_transmission(h.prim.shape, cos, uv).unwrap_or(0.0);
                Crossing { t: h.hit.t, passes, medium }
            }));
        }
        trace
    }

    /// The share of light passing straight through surface `shape` at `cos`
    /// (`Bsdf::null_transmission`), but none through a thin dielectric where every surface
    /// hit scatters (`RenderSettings::surface_events_only`).
    /// `uv` gives the texture coordinates there, asked only of a textured mask.
    #[inline]
    pub fn null_transmission(
        &self,
        shape: u32,
        cos: f32,
        uv: impl FnOnce() -> Vec2,
    ) -> Option<f32> {
        let bsdf = &self.surfaces[shape as usize].bsdf;
        if self.settings.surface_events_only && *bsdf != Bsdf::Null {
            return None;
        }
        let uv = if bsdf.passes_by_texture() { uv() } else { Vec2::ZERO };
        bsdf.null_transmission(cos, uv)
    }

    /// The medium a ray leaving `hit` along `dir` travels in, having come in `current`.
    #[inline]
    pub fn medium_after(&self, hit: &SurfaceHit, dir: Vec3A, current: Option<u32>) -> Option<u32> {
        self.surfaces[hit.shape as usize].medium_beyond(dir.dot(hit.ng) < 0.0, current)
    }

    /// World bounds of all shapes.
    pub fn bounds(&self) -> Aabb {
        self.bvh.bounds()
    }

    /// A multi-line summary for `zerovar check`.
    pub fn describe(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let b = self.bounds();
        let triangles: usize = self.shapes.iter().map(Geometry::primitive_count).sum();
        let _ = writeln!(s, "scene    {}", self.path.display());
        let [w, h] = self.camera.resolution();
        let filter = self.camera.filter().describe();
        let _ = writeln!(
            s,
            "camera   {w}x{h}, in medium {}, pixel filter {filter}",
            self.medium_name(self.camera_medium)
        );
        let _ = writeln!(s, "shapes   {} ({} primitives)", self.shapes.len(), triangles);
        if !b.is_empty() {
            let _ = writeln!(s, "bounds   {:?} .. {:?}", b.min.to_array(), b.max.to_array());
        }
        let _ = writeln!(s, "global   medium {}", self.medium_name(self.global_medium));
        let _ = writeln!(s, "media    {}", self.media.len());
        for (m, t) in self.media.iter().zip(&self.trackers) {
            let kind = match &m.kind {
                crate::media::MediumKind::Homogeneous { .. } => "homogeneous",
                crate::media::MediumKind::Heterogeneous(_) => "heterogeneous",
            };
            let _ = writeln!(
                s,
                "  {:<12} {kind}, majorant {:?}: {}",
                m.name,
                m.majorant().to_array(),
                crate::tracking::explain(m, *t)
            );
        }
        let _ = writeln!(s, "lights   {}", self.lights.len());
        for l in &self.lights {
            let kind = match l {
                Light::Point { .. } => "point".to_string(),
                Light::Spot { .. } => "spot".to_string(),
                Light::Area { shape, .. } => format!("area on shape {shape}"),
                Light::Directional { one_minus_cos, .. } if *one_minus_cos > 0.0 => {
                    "sun disk".to_string()
                }
                Light::Directional { .. } => "directional".to_string(),
                Light::Constant { .. } => "constant environment".to_string(),
                Light::EnvMap(_) => "environment map".to_string(),
            };
            let _ = writeln!(s, "  {kind}");
        }
        let depth = self.settings.max_depth.map_or("unlimited".to_string(), |d| d.to_string());
        let _ = writeln!(
            s,
            "render   {} spp, max depth {depth}, rr depth {}, seed {}{}",
            self.settings.spp,
            self.settings.rr_depth,
            self.settings.seed,
            if self.settings.hide_emitters { ", emitters seen directly hidden" } else { "" }
        );
        s
    }

    fn medium_name(&self, m: Option<u32>) -> &str {
        m.map_or("vacuum", |i| self.media[i as usize].name.as_str())
    }
}

/// Origin for a ray leaving a surface point along `dir`, pushed off the surface so the ray does
/// not find the surface it starts on.
#[inline]
pub fn offset_origin(p: Vec3A, ng: Vec3A, dir: Vec3A) -> Vec3A {
    let eps = RAY_EPSILON * (1.0 + p.abs().max_element());
    if dir.dot(ng) >= 0.0 { p + ng * eps } else { p - ng * eps }
}
