//! Scenes assembled in code rather than read from a file: a host application builds the same
//! element descriptions a scene file holds (`desc`), and `SceneBuilder::build` compiles and
//! validates them exactly as `load` does, with the same errors. Elements have constructors
//! for the common cases; anything else is a struct literal with `..Default::default()`.
//!
//! ```
//! use glam::Vec3;
//! use zerovar::scene::SceneBuilder;
//! use zerovar::scene::desc::{
//!     BsdfDesc, CameraDesc, LightDesc, MediumDesc, PhaseDesc, Rgb, ShapeDesc,
//! };
//!
//! let eye = Vec3::new(0.0, 1.0, 5.0);
//! let camera = CameraDesc::look_at(eye, Vec3::Y, 40.0, [64, 48]);
//! let fog = MediumDesc {
//!     phase: Some(PhaseDesc::hg(0.3)),
//!     ..MediumDesc::homogeneous(Rgb::Grey(1.5), Rgb::Grey(0.9))
//! };
//! let sphere = ShapeDesc {
//!     interior: Some("fog".into()),
//!     ..ShapeDesc::sphere(Vec3::Y, 1.0, BsdfDesc::null())
//! };
//! let scene = SceneBuilder::new(camera)
//!     .medium("fog", fog)
//!     .shape(sphere)
//!     .light(LightDesc::point(Vec3::new(1.5, 3.0, 1.5), Rgb::Grey(30.0)))
//!     .build()?;
//! assert_eq!(scene.media().len(), 1);
//! # Ok::<(), zerovar::scene::SceneError>(())
//! ```

use super::desc::{
    BsdfDesc, CameraDesc, LightDesc, MediumDesc, PhaseDesc, RenderDesc, Rgb, SceneDesc, ShapeDesc,
};
use super::{Scene, SceneError, Sources, build};
use glam::Vec3;
use std::path::PathBuf;
use toml::Spanned;

/// What errors name as the file of a scene built in code.
const NAME: &str = "<scene built in code>";

/// A scene under construction; [`build`](Self::build) validates and compiles it.
#[derive(Debug)]
pub struct SceneBuilder {
    dir: PathBuf,
    desc: SceneDesc,
}

/// Wraps a value without a place in any file (errors then name the element only).
fn unplaced<T>(value: T) -> Spanned<T> {
    Spanned::new(0..0, value)
}

impl SceneBuilder {
    /// A scene seen by `camera`, with the default render settings and nothing in it.
    pub fn new(camera: CameraDesc) -> Self {
        Self {
            dir: PathBuf::new(),
            desc: SceneDesc {
                defaults: toml::Table::new(),
                camera: unplaced(camera),
                render: RenderDesc::default(),
                medium: None,
                media: Default::default(),
                shapes: Vec::new(),
                lights: Vec::new(),
            },
        }
    }

    /// The directory that file names in elements (meshes, grids, environment maps) are
    /// relative to; the current directory by default.
    pub fn in_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.dir = dir.into();
        self
    }

    /// Sample count, path depth, roulette depth and seed.
    pub fn render(mut self, render: RenderDesc) -> Self {
        self.desc.render = render;
        self
    }

    /// Adds the medium `name` (replacing one of that name), for shapes' `interior` and
    /// `exterior`, the camera's `medium` and [`global_medium`](Self::global_medium).
    pub fn medium(mut self, name: &str, medium: MediumDesc) -> Self {
        self.desc.media.insert(name.to_string(), unplaced(medium));
        self
    }

    /// The medium filling all space not enclosed by a shape with another medium.
    pub fn global_medium(mut self, name: &str) -> Self {
        self.desc.medium = Some(unplaced(name.to_string()));
        self
    }

    /// Adds a shape.
    pub fn shape(mut self, shape: ShapeDesc) -> Self {
        self.desc.shapes.push(unplaced(shape));
        self
    }

    /// Adds a light other than an area emitter (those are a shape's `emitter`).
    pub fn light(mut self, light: LightDesc) -> Self {
        self.desc.lights.push(unplaced(light));
        self
    }

    /// Validates and compiles the scene, as [`load`](super::load) does a file.
    pub fn build(self) -> Result<Scene, SceneError> {
        let path = self.dir.join(NAME);
        let mut sources = Sources::default();
        sources.push(path.clone(), String::new());
        build::build(&path, &sources, self.desc)
    }
}

impl CameraDesc {
    /// A camera at `origin` looking at `target` with +y up, `fov` degrees across the width.
    pub fn look_at(origin: Vec3, target: Vec3, fov: f32, resolution: [u32; 2]) -> Self {
        Self {
            origin,
            target,
            up: Vec3::Y,
            fov,
            fov_axis: Default::default(),
            resolution: resolution.map(i64::from),
            medium: None,
            near_clip: 0.0,
            far_clip: f32::INFINITY,
            filter: Default::default(),
            mirror: false,
            aperture_radius: 0.0,
            focus_distance: None,
        }
    }
}

impl ShapeDesc {
    /// A sphere with the surface `bsdf`.
    pub fn sphere(center: Vec3, radius: f32, bsdf: BsdfDesc) -> Self {
        Self {
            kind: "sphere".into(),
            center: Some(center),
            radius: Some(radius),
            bsdf: Some(bsdf),
            ..Default::default()
        }
    }

    /// A shape of `kind` (`cube`, `rectangle`, `disk`; see the scene format) placed by
    /// `transform`, with the surface `bsdf`.
    pub fn placed(kind: &str, transform: Vec<super::desc::TransformStep>, bsdf: BsdfDesc) -> Self {
        Self { kind: kind.into(), transform, bsdf: Some(bsdf), ..Default::default() }
    }
}

impl BsdfDesc {
    /// No surface: a boundary between media.
    pub fn null() -> Self {
        Self { kind: "null".into(), ..Default::default() }
    }

    /// A Lambertian surface.
    pub fn diffuse(reflectance: Rgb) -> Self {
        Self {
            kind: "diffuse".into(),
            reflectance: Some(super::desc::TextureDesc::Constant(reflectance)),
            ..Default::default()
        }
    }
}

impl MediumDesc {
    /// A homogeneous medium (isotropic unless `phase` is set).
    pub fn homogeneous(sigma_t: Rgb, albedo: Rgb) -> Self {
        Self {
            kind: "homogeneous".into(),
            sigma_t: Some(sigma_t),
            albedo: Some(super::desc::AlbedoDesc::Constant(albedo)),
            ..Default::default()
        }
    }
}

impl PhaseDesc {
    /// Henyey-Greenstein with mean cosine `g`.
    pub fn hg(g: f32) -> Self {
        Self { kind: "hg".into(), g: Some(g), ..Self::default() }
    }
}

impl LightDesc {
    /// A point light of radiant intensity `intensity` (W/sr).
    pub fn point(position: Vec3, intensity: Rgb) -> Self {
        Self {
            kind: "point".into(),
            position: Some(position),
            intensity: Some(intensity),
            ..Default::default()
        }
    }

    /// Uniform radiance from every direction.
    pub fn constant(radiance: Rgb) -> Self {
        Self { kind: "constant".into(), radiance: Some(radiance), ..Default::default() }
    }
}
