//! The scene file's structure as plain serde types, mirroring the TOML one to one.
//!
//! Elements are flat tables with a `type` field and the union of their kinds' fields as
//! options; `build` rejects a field that the element's kind does not take. Keeping the tables
//! flat (rather than serde's tagged enums) keeps the TOML parser's exact line and column in
//! every error, and `deny_unknown_fields` catches misspelt keys.

use glam::Vec3;
use serde::Deserialize;
use std::collections::BTreeMap;
use toml::Spanned;

/// A colour: one number for grey or `[r, g, b]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rgb {
    /// The same value in every channel.
    Grey(f32),
    /// Red, green, blue.
    Rgb([f32; 3]),
}

impl<'de> Deserialize<'de> for Rgb {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(RgbVisitor)
    }
}

/// Reads a colour, saying what a colour is when the value is not one.
struct RgbVisitor;

impl<'de> serde::de::Visitor<'de> for RgbVisitor {
    type Value = Rgb;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a colour: one number, or three in brackets [r, g, b]")
    }

    fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Rgb, E> {
        Ok(Rgb::Grey(v as f32))
    }

    fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Rgb, E> {
        Ok(Rgb::Grey(v as f32))
    }

    fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Rgb, E> {
        Ok(Rgb::Grey(v as f32))
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Rgb, A::Error> {
        let mut c = Vec::with_capacity(3);
        while let Some(v) = seq.next_element::<f64>()? {
            c.push(v as f32);
        }
        match c[..] {
            [r, g, b] => Ok(Rgb::Rgb([r, g, b])),
            _ => Err(serde::de::Error::custom(format!(
                "a colour has three channels [r, g, b] (or is one number), not {}",
                c.len()
            ))),
        }
    }
}

impl Rgb {
    /// As three channels.
    pub fn channels(self) -> [f32; 3] {
        match self {
            Rgb::Grey(v) => [v; 3],
            Rgb::Rgb(c) => c,
        }
    }
}

/// The whole scene file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneDesc {
    /// Named values that `"$name"` strings refer to and `-D name=value` overrides.
    #[serde(default)]
    pub defaults: toml::Table,
    /// The camera.
    pub camera: Spanned<CameraDesc>,
    /// Integrator and sampling settings.
    #[serde(default)]
    pub render: RenderDesc,
    /// Name of the medium filling all space not enclosed by a shape with another medium.
    pub medium: Option<Spanned<String>>,
    /// Named media.
    #[serde(default)]
    pub media: BTreeMap<String, Spanned<MediumDesc>>,
    /// Shapes.
    #[serde(default)]
    pub shapes: Vec<Spanned<ShapeDesc>>,
    /// Lights other than area emitters (those are attached to shapes).
    #[serde(default)]
    pub lights: Vec<Spanned<LightDesc>>,
}

/// `[render]`: how the image is sampled.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RenderDesc {
    /// Samples per pixel when the command line gives no budget.
    pub spp: u32,
    /// Longest path in scattering events (-1: unlimited), counted as Mitsuba counts it.
    pub max_depth: i64,
    /// Depth from which Russian roulette may end paths.
    pub rr_depth: u32,
    /// Seed of the random streams when the command line gives none.
    pub seed: u64,
    /// Emitters seen directly from the camera (before any scattering event) count zero, as
    /// with Mitsuba's `hide_emitters`: a cloud against a black background, lit by its sky.
    pub hide_emitters: bool,
    /// Every surface hit is a scattering event, as Mitsuba's `path` integrator counts them
    /// (set by the XML reader for it): a thin dielectric's transmission then counts depth and
    /// blocks shadow rays, where Mitsuba's `volpath` takes it as a null event.
    #[serde(skip)]
    pub surface_events_only: bool,
}

impl Default for RenderDesc {
    fn default() -> Self {
        Self {
            spp: 64,
            max_depth: -1,
            rr_depth: 5,
            seed: 0,
            hide_emitters: false,
            surface_events_only: false,
        }
    }
}

/// `[camera]`: a perspective pinhole camera.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    /// Eye position.
    pub origin: Vec3,
    /// Point looked at.
    pub target: Vec3,
    /// Up direction.
    #[serde(default = "up")]
    pub up: Vec3,
    /// Field of view in degrees.
    pub fov: f32,
    /// Axis the field of view spans: "x" (default) or "y".
    #[serde(default)]
    pub fov_axis: crate::camera::FovAxis,
    /// Width and height in pixels (checked when the scene is built).
    pub resolution: [i64; 2],
    /// Medium around the camera (default: the global medium).
    pub medium: Option<String>,
    /// Distance of the near clipping plane from the eye, along the view axis: rays start on
    /// it (default 0; Mitsuba's XML default is 0.01).
    #[serde(default)]
    pub near_clip: f32,
    /// Distance of the far clipping plane: nothing beyond it is seen (default: none).
    #[serde(default = "no_far_clip")]
    pub far_clip: f32,
    /// How each pixel's samples spread over the film (default: a box, uniform in the pixel).
    #[serde(default)]
    pub filter: crate::filter::PixelFilter,
    /// Whether the image is mirrored left to right, as a Mitsuba camera whose `to_world`
    /// scales by -1 sees it (default false).
    #[serde(default)]
    pub mirror: bool,
    /// A thin lens's aperture radius (default 0: a pinhole, everything sharp).
    #[serde(default)]
    pub aperture_radius: f32,
    /// A thin lens's distance of sharp focus along the view axis (default: the far clipping
    /// plane, as in Mitsuba; required with an aperture and no far plane).
    pub focus_distance: Option<f32>,
}

fn up() -> Vec3 {
    Vec3::Y
}

fn no_far_clip() -> f32 {
    f32::INFINITY
}

/// One step of a transform list, applied in the order written.
#[derive(Clone, Debug, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum TransformStep {
    /// Move by a vector.
    Translate(Vec3),
    /// Rotate about an axis through the origin, angle in degrees.
    Rotate {
        /// Rotation axis.
        axis: Vec3,
        /// Angle in degrees (counter-clockwise looking down the axis).
        angle: f32,
    },
    /// Scale uniformly or per axis.
    Scale(Rgb),
    /// A 4x4 matrix, row-major (the last row must be 0 0 0 1).
    Matrix([[f32; 4]; 4]),
    /// Place the local frame at `origin` with +z towards `target`.
    Lookat {
        /// New origin.
        origin: Vec3,
        /// Point the local +z axis looks at.
        target: Vec3,
        /// Up direction.
        #[serde(default = "up")]
        up: Vec3,
    },
}

/// `bsdf = { type = ... }`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BsdfDesc {
    /// "null", "diffuse", "dielectric", "thindielectric", "plastic", "conductor", the rough
    /// "roughdielectric", "roughplastic" or "roughconductor", or "mask" around another.
    #[serde(rename = "type")]
    pub kind: String,
    /// Diffuse: reflectance (a colour or a checkerboard table).
    pub reflectance: Option<TextureDesc>,
    /// Diffuse: reflect on both sides.
    pub two_sided: Option<bool>,
    /// Dielectric, thindielectric, plastic and their rough kinds: interior (slab, coating)
    /// index of refraction.
    pub int_ior: Option<f32>,
    /// Dielectric, thindielectric, plastic and their rough kinds: exterior index of refraction.
    pub ext_ior: Option<f32>,
    /// Plastic, roughplastic: the base's albedo (a colour or a checkerboard table).
    pub diffuse_reflectance: Option<TextureDesc>,
    /// Plastic, conductor and their rough kinds: a factor on the specular reflection.
    pub specular_reflectance: Option<Rgb>,
    /// Plastic, roughplastic: Mitsuba's `nonlinear` (internal reflections tint the base).
    pub nonlinear: Option<bool>,
    /// Conductor, roughconductor: one of Mitsuba's named metals ("Au", "Cu", ...; "none", a
    /// perfect mirror, by default).
    pub material: Option<String>,
    /// Conductor, roughconductor: the real part of the index of refraction (instead of a
    /// `material`; 0 when only `k` is given).
    pub eta: Option<Rgb>,
    /// Conductor, roughconductor: the imaginary part (1 when only `eta` is given).
    pub k: Option<Rgb>,
    /// The rough kinds: "beckmann" (the default) or "ggx".
    pub distribution: Option<String>,
    /// The rough kinds: the roughness (default 0.1), a number or a texture (read as one
    /// number: its luminance).
    pub alpha: Option<TextureDesc>,
    /// Roughconductor, roughdielectric: the roughness along the tangent (the direction of
    /// growing `u`), with `alpha_v`, instead of `alpha`.
    pub alpha_u: Option<TextureDesc>,
    /// Roughconductor, roughdielectric: the roughness along the bitangent.
    pub alpha_v: Option<TextureDesc>,
    /// Mask: the share of light that meets `nested` (default 0.5), a number or a texture;
    /// the rest passes through.
    pub opacity: Option<TextureDesc>,
    /// Mask: the BSDF behind the mask.
    pub nested: Option<Box<BsdfDesc>>,
}

/// A reflectance: a colour or `{ type = "checkerboard", ... }`.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum TextureDesc {
    /// A constant colour.
    Constant(Rgb),
    /// A checkerboard.
    Checkerboard(CheckerboardDesc),
    /// An image.
    Bitmap(BitmapDesc),
}

/// Mitsuba's bitmap texture: `{ type = "bitmap", filename = "wood.png" }`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BitmapDesc {
    /// Must be "bitmap".
    #[serde(rename = "type")]
    pub kind: String,
    /// A PNG (sRGB-encoded unless `raw`) or OpenEXR (linear) image, relative to the scene.
    pub filename: String,
    /// "bilinear" (the default) or "nearest".
    pub filter_type: Option<String>,
    /// "repeat" (the default), "mirror" or "clamp".
    pub wrap_mode: Option<String>,
    /// Take a PNG's values as linear (default false: decode sRGB).
    pub raw: Option<bool>,
    /// Image tiles per unit of uv, [u, v] (default 1).
    pub scale: Option<[f32; 2]>,
}

/// Mitsuba's checkerboard texture.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckerboardDesc {
    /// Must be "checkerboard".
    #[serde(rename = "type")]
    pub kind: String,
    /// Colour where the u and v halves agree (default 0.4).
    pub color0: Option<Rgb>,
    /// The other colour (default 0.2).
    pub color1: Option<Rgb>,
    /// Checks per unit of uv, one number or [u, v] (default 1).
    pub scale: Option<[f32; 2]>,
}

/// `emitter = { radiance = ... }` on a shape.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmitterDesc {
    /// Emitted radiance.
    pub radiance: Rgb,
}

/// `[[shapes]]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeDesc {
    /// "sphere", "cube", "rectangle", "disk", "cylinder", "obj", "ply" or "serialized".
    #[serde(rename = "type")]
    pub kind: String,
    /// Sphere: centre (default origin).
    pub center: Option<Vec3>,
    /// Sphere, cylinder: radius (default 1).
    pub radius: Option<f32>,
    /// Cylinder: where its centre line starts (default origin).
    pub p0: Option<Vec3>,
    /// Cylinder: where its centre line ends (default (0, 0, 1)).
    pub p1: Option<Vec3>,
    /// Obj, ply, serialized: the file, relative to the scene file.
    pub filename: Option<String>,
    /// Obj, ply, serialized: ignore the file's vertex normals.
    pub face_normals: Option<bool>,
    /// Obj: turn texture coordinates `(u, v)` into `(u, 1 - v)` (default true, as in Mitsuba).
    pub flip_tex_coords: Option<bool>,
    /// Serialized: which mesh of the file (default 0).
    pub shape_index: Option<u32>,
    /// Transform steps applied in order.
    #[serde(default)]
    pub transform: Vec<TransformStep>,
    /// Turn the shape inside out.
    #[serde(default)]
    pub flip_normals: bool,
    /// The surface (default: diffuse 0.5).
    pub bsdf: Option<BsdfDesc>,
    /// Medium inside (behind the normals).
    pub interior: Option<String>,
    /// Medium outside.
    pub exterior: Option<String>,
    /// Rays crossing or leaving the shape keep the medium they travel in, whatever `interior`
    /// and `exterior` say: Mitsuba's rule for a shape that names no medium (set by the XML
    /// reader; TOML shapes without media border the global medium instead).
    #[serde(skip)]
    pub keeps_medium: bool,
    /// Make the shape an area light.
    pub emitter: Option<EmitterDesc>,
}

/// `[media.NAME]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MediumDesc {
    /// "homogeneous", "grid" or "noise".
    #[serde(rename = "type")]
    pub kind: String,
    /// Extinction (homogeneous), or a per-channel tint of the density (grid, noise).
    pub sigma_t: Option<Rgb>,
    /// Single-scattering albedo: a colour, or (grid) a `.vol` file.
    pub albedo: Option<AlbedoDesc>,
    /// Multiplies the extinction.
    pub scale: Option<f32>,
    /// Grid: the density, a `.vol` or `.vdb` file or a constant filling the unit cube.
    pub density: Option<DensityDesc>,
    /// Grid with a `.vdb` density: which of the file's float grids (default `density`, or the
    /// only float grid).
    pub grid_name: Option<String>,
    /// Noise: cloud parameters.
    pub noise: Option<crate::media::NoiseCloud>,
    /// Grid, noise: places the unit cube.
    #[serde(default)]
    pub transform: Vec<TransformStep>,
    /// Phase function (default isotropic).
    pub phase: Option<PhaseDesc>,
    /// Emitted radiance per unit absorption.
    pub emission: Option<Rgb>,
}

/// A grid medium's density: a `.vol` or `.vdb` file, or one value filling the unit cube.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum DensityDesc {
    /// The same density everywhere in the cube.
    Constant(f32),
    /// A one-channel `.vol` file, or an OpenVDB float grid (a name ending in `.vdb`).
    File(String),
}

/// A constant albedo or a grid file.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum AlbedoDesc {
    /// A colour.
    Constant(Rgb),
    /// A `.vol` file of one or three channels.
    File(String),
}

/// `phase = { type = ... }`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhaseDesc {
    /// "isotropic", "hg", "rayleigh" or "blendphase".
    #[serde(rename = "type")]
    pub kind: String,
    /// HG mean cosine.
    pub g: Option<f32>,
    /// Blendphase: the second phase's share, in [0, 1] (default 0.5).
    pub weight: Option<f32>,
    /// Blendphase: the two phases blended (isotropic, hg or rayleigh), at weight 0 and 1.
    pub phases: Option<Vec<PhaseDesc>>,
}

/// `[[lights]]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightDesc {
    /// "point", "spot", "directional", "constant" or "envmap".
    #[serde(rename = "type")]
    pub kind: String,
    /// Point, spot: position.
    pub position: Option<Vec3>,
    /// Spot: point on the axis.
    pub target: Option<Vec3>,
    /// Point, spot: radiant intensity.
    pub intensity: Option<Rgb>,
    /// Spot: cutoff half-angle, degrees (default 20).
    pub cutoff_angle: Option<f32>,
    /// Spot: half-angle of full intensity, degrees (default 3/4 of the cutoff).
    pub beam_width: Option<f32>,
    /// Directional: direction the light travels.
    pub direction: Option<Vec3>,
    /// Directional: irradiance on a surface facing the light.
    pub irradiance: Option<Rgb>,
    /// Directional: angular diameter in degrees (default 0, a delta light).
    pub angular_diameter: Option<f32>,
    /// Constant: radiance.
    pub radiance: Option<Rgb>,
    /// Envmap: lat-long image file (OpenEXR, Radiance HDR, PNG or JPEG).
    pub filename: Option<String>,
    /// Envmap: multiplies the image.
    pub scale: Option<f32>,
    /// Envmap: rotates the map.
    #[serde(default)]
    pub transform: Vec<TransformStep>,
}
