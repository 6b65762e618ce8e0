//! Compiling a parsed scene description into a `Scene`: every value is validated here, with
//! an error naming the file, line and element, and the fix.

use super::desc::*;
use super::{RenderSettings, Scene, SceneError, Sources, Surface};
use crate::accel::Bvh;
use crate::bsdf::{
    Bitmap, Bsdf, Conductor, MIN_ALPHA, Metal, Microfacet, MicrofacetKind, Plastic, RoughConductor,
    RoughDielectric, RoughPlastic, Roughness, Texture, Wrap, srgb_to_linear,
};
use crate::camera::Camera;
use crate::filter::{FilterTable, PixelFilter};
use crate::lights::{EnvMap, Light};
use crate::math::{Frame, Spectrum};
use crate::media::{
    AlbedoField, DensityField, Grid, Heterogeneous, Medium, MediumKind, VdbGrid, VolGrid,
};
use crate::phase::{Lobe, PhaseFunction};
use crate::shapes::{Cuboid, Cylinder, Disk, Geometry, Mesh, Parallelogram, Sphere};
use crate::tracking::Tracker;
use crate::transform::Transform;
use glam::{Vec2, Vec3, Vec3A};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Most pixels a camera may have: a film holds 72 bytes per pixel, and a render keeps several
/// (training passes, the render phase), so 2^25 pixels stay within a few gigabytes.
const MAX_PIXELS: u64 = 1 << 25;

/// The most pixels along either side of the image.
pub(crate) const MAX_SIDE: i64 = 1 << 15;

/// The widest pixel filter (tent radius or Gaussian stddev), in pixels: wider blurs a whole
/// image of the largest size into a few pixels' worth of detail.
const MAX_FILTER_WIDTH: f32 = 1024.0;

/// The largest coordinate a camera's origin or target may have: a ray's squared length
/// overflows single precision near 1.8e19, and far below that the scene cannot be resolved.
const MAX_COORDINATE: f32 = 1e15;

/// The camera, its placement and resolution checked.
fn camera(cx: &Ctx<'_>, cam: &CameraDesc) -> Result<Camera> {
    cx.finite(
        "camera origin, target and up",
        &[cam.origin, cam.target, cam.up].map(|v| v.to_array()).concat(),
    )?;
    let far = [cam.origin, cam.target].into_iter().find(|p| p.abs().max_element() > MAX_COORDINATE);
    if let Some(p) = far {
        return cx.err(format!(
            "camera point {:?} lies beyond +-{MAX_COORDINATE:e}, where single-precision ray \
             arithmetic overflows; move the scene nearer the origin",
            p.to_array()
        ));
    }
    let Some(to_world) = Transform::look_at(cam.origin, cam.target, cam.up) else {
        return cx.err("origin equals target, or up is parallel to the view direction");
    };
    // A mirror flips the camera's local x (its left) before the look-at frame.
    let to_world = match Transform::scale(glam::Vec3::new(-1.0, 1.0, 1.0)) {
        Some(flip) if cam.mirror => flip.then(&to_world),
        _ => to_world,
    };
    if !(cam.fov > 0.0 && cam.fov < 180.0) {
        return cx.err(format!("fov {} must lie strictly between 0 and 180 degrees", cam.fov));
    }
    if cam.resolution.iter().any(|r| !(1..=MAX_SIDE).contains(r)) {
        return cx.err(format!(
            "resolution {:?} must be between 1 and {MAX_SIDE} pixels per axis",
            cam.resolution
        ));
    }
    let resolution = cam.resolution.map(|r| r as u32);
    let pixels = u64::from(resolution[0]) * u64::from(resolution[1]);
    if pixels > MAX_PIXELS {
        return cx.err(format!(
            "resolution {:?} is {pixels} pixels, more than {MAX_PIXELS} (8192 x 4096): a render holds \
             about 72 bytes per pixel in each of several images; lower the resolution",
            cam.resolution
        ));
    }
    if !(cam.near_clip >= 0.0 && cam.near_clip.is_finite()) {
        return cx.err(format!("near_clip {} must be a finite distance, 0 or more", cam.near_clip));
    }
    if cam.far_clip.is_nan() || cam.far_clip <= cam.near_clip {
        return cx
            .err(format!("far_clip {} must lie beyond near_clip {}", cam.far_clip, cam.near_clip));
    }
    let (what, width) = match cam.filter {
        PixelFilter::Box => ("", 1.0),
        PixelFilter::Tent { radius } => ("tent radius", radius),
        PixelFilter::Gaussian { stddev } => ("gaussian stddev", stddev),
        PixelFilter::Mitchell { .. } => ("", 1.0),
        PixelFilter::Lanczos { lobes } => ("lanczos lobes", lobes as f32),
    };
    if !(width > 0.0 && width <= MAX_FILTER_WIDTH) {
        return cx.err(format!(
            "pixel filter: {what} {width} must be above 0 and at most {MAX_FILTER_WIDTH} pixels"
        ));
    }
    if let PixelFilter::Mitchell { b, c } = cam.filter
        && !(b.is_finite() && c.is_finite())
    {
        return cx.err(format!("pixel filter: mitchell B {b} and C {c} must be finite numbers"));
    }
    let filter = match FilterTable::new(cam.filter) {
        Ok(f) => f,
        Err(why) => return cx.err(format!("pixel filter: {why}")),
    };
    if !(cam.aperture_radius >= 0.0 && cam.aperture_radius.is_finite()) {
        return cx.err(format!(
            "aperture_radius {} must be a finite radius, 0 (a pinhole) or more",
            cam.aperture_radius
        ));
    }
    let focus = cam.focus_distance.unwrap_or(cam.far_clip);
    if cam.aperture_radius > 0.0 && !(focus > 0.0 && focus.is_finite()) {
        return cx.err(match cam.focus_distance {
            None => "a thin lens (aperture_radius above 0) needs focus_distance where there is \
                     no far clipping plane"
                .to_string(),
            Some(f) => format!("focus_distance {f} must be a finite distance above 0"),
        });
    }
    let camera = Camera::new(to_world, cam.fov, cam.fov_axis, resolution)
        .with_lens(cam.aperture_radius, focus);
    Ok(camera.with_clip(cam.near_clip, cam.far_clip).with_filter(filter))
}

/// The file being built and the element being looked at, for error messages.
struct Ctx<'a> {
    path: &'a Path,
    sources: &'a Sources,
    offset: usize,
    place: String,
}

type Result<T> = std::result::Result<T, SceneError>;

impl Ctx<'_> {
    fn at(&mut self, offset: usize, place: String) {
        self.offset = offset;
        self.place = place;
    }

    fn err<T>(&self, message: impl Into<String>) -> Result<T> {
        Err(self.sources.invalid(self.offset, &self.place, &message.into()))
    }

    fn file(&self, name: &str) -> PathBuf {
        self.path.parent().unwrap_or(Path::new(".")).join(name)
    }

    /// Rejects fields given for a kind that does not take them.
    fn only(&self, kind: &str, fields: &[(&str, bool)]) -> Result<()> {
        match fields.iter().find(|(_, present)| *present) {
            Some((name, _)) => self.err(format!("`{name}` does not apply to {kind}; remove it")),
            None => Ok(()),
        }
    }

    fn finite(&self, what: &str, v: &[f32]) -> Result<()> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            self.err(format!("{what} must be finite"))
        }
    }

    fn colour(&self, what: &str, c: Rgb, max: Option<f32>) -> Result<Spectrum> {
        let v = c.channels();
        self.finite(what, &v)?;
        if v.iter().any(|x| *x < 0.0) {
            return self
                .err(format!("{what} {v:?} has a negative channel; colours are non-negative"));
        }
        if let Some(m) = max.filter(|m| v.iter().any(|x| x > m)) {
            let v =
                if v[0] == v[1] && v[1] == v[2] { format!("{}", v[0]) } else { format!("{v:?}") };
            return self
                .err(format!("{what} {v} exceeds {m}: it is a share of light, in [0, {m}]"));
        }
        Ok(Spectrum::from_array(v))
    }

    fn required<T: Clone>(&self, what: &str, v: &Option<T>) -> Result<T> {
        match v {
            Some(v) => Ok(v.clone()),
            None => self.err(format!("`{what}` is required here")),
        }
    }

    fn direction(&self, what: &str, v: Vec3) -> Result<Vec3A> {
        self.finite(what, &v.to_array())?;
        match v.try_normalize() {
            Some(d) => Ok(d.into()),
            None => self.err(format!("{what} has zero length; give a non-zero vector")),
        }
    }

    fn transform(&self, steps: &[TransformStep]) -> Result<Transform> {
        for step in steps {
            match step {
                TransformStep::Translate(v) => self.finite("translate", &v.to_array())?,
                TransformStep::Rotate { axis, angle } => {
                    self.finite("rotate", &[axis.x, axis.y, axis.z, *angle])?
                }
                TransformStep::Scale(s) => self.finite("scale", &s.channels())?,
                TransformStep::Matrix(rows) => self.finite("matrix", rows.as_flattened())?,
                TransformStep::Lookat { .. } => {}
            }
        }
        compose(steps).or_else(|i| {
            self.err(format!(
                "transform step {} is degenerate (zero axis or scale, origin = target, up \
                 parallel to the view, or a matrix that is singular or not affine)",
                i + 1
            ))
        })
    }
}

/// A transform list composed in document order; `Err(i)` names the first degenerate step.
pub(super) fn compose(steps: &[TransformStep]) -> std::result::Result<Transform, usize> {
    let mut t = Transform::IDENTITY;
    for (i, step) in steps.iter().enumerate() {
        let next = match step {
            TransformStep::Translate(v) => Some(Transform::translate(*v)),
            TransformStep::Rotate { axis, angle } => Transform::rotate(*axis, *angle),
            TransformStep::Scale(s) => Transform::scale(Vec3::from_array(s.channels())),
            TransformStep::Matrix(rows) => Transform::from_rows(*rows),
            TransformStep::Lookat { origin, target, up } => {
                Transform::look_at(*origin, *target, *up)
            }
        };
        t = t.then(&next.ok_or(i)?);
    }
    Ok(t)
}

pub(super) fn build(path: &Path, sources: &Sources, desc: SceneDesc) -> Result<Scene> {
    let mut cx = Ctx { path, sources, offset: 0, place: String::new() };

    let mut media = Vec::new();
    let mut names = HashMap::new();
    for (name, m) in &desc.media {
        cx.at(m.span().start, format!("media.{name}"));
        if name == "vacuum" {
            return cx.err("`vacuum` means no medium; choose another name");
        }
        names.insert(name.clone(), media.len() as u32);
        media.push(medium(&cx, name, m.get_ref())?);
    }
    let lookup = |cx: &Ctx<'_>, what: &str, name: &Option<String>, fallback: Option<u32>| match name
    {
        None => Ok(fallback),
        Some(n) if n == "vacuum" => Ok(None),
        Some(n) => match names.get(n) {
            Some(i) => Ok(Some(*i)),
            None => {
                let known: Vec<&str> = desc.media.keys().map(String::as_str).collect();
                cx.err(format!(
                    "{what} `{n}` is not a medium of this scene (known: vacuum, {})",
                    known.join(", ")
                ))
            }
        },
    };
    cx.at(desc.medium.as_ref().map_or(0, |m| m.span().start), "medium".into());
    let global_medium =
        lookup(&cx, "medium", &desc.medium.as_ref().map(|m| m.get_ref().clone()), None)?;

    let cam = desc.camera.get_ref();
    cx.at(desc.camera.span().start, "camera".into());
    let camera = camera(&cx, cam)?;
    let camera_medium = lookup(&cx, "camera medium", &cam.medium, global_medium)?;

    let r = &desc.render;
    cx.at(0, "render".into());
    if r.spp == 0 {
        return cx.err("spp must be at least 1");
    }
    if r.max_depth < -1 || r.max_depth > u32::MAX as i64 {
        return cx.err(format!("max_depth {} must be -1 (unlimited) or a depth >= 0", r.max_depth));
    }
    let settings = RenderSettings {
        spp: r.spp,
        max_depth: (r.max_depth >= 0).then_some(r.max_depth as u32),
        rr_depth: r.rr_depth,
        seed: r.seed,
        hide_emitters: r.hide_emitters,
        surface_events_only: r.surface_events_only,
    };

    let mut shapes = Vec::new();
    let mut surfaces = Vec::new();
    let mut lights = Vec::new();
    for (i, s) in desc.shapes.iter().enumerate() {
        let d = s.get_ref();
        cx.at(s.span().start, format!("shapes[{i}] ({})", d.kind));
        shapes.push(geometry(&cx, d)?);
        let light = match &d.emitter {
            Some(e) => {
                let radiance = cx.colour("emitter radiance", e.radiance, None)?;
                lights.push(Light::Area { shape: i as u32, flip: d.flip_normals, radiance });
                Some(lights.len() as u32 - 1)
            }
            None => None,
        };
        surfaces.push(Surface {
            bsdf: bsdf(&cx, d.bsdf.as_ref())?,
            interior: lookup(&cx, "interior", &d.interior, global_medium)?,
            exterior: lookup(&cx, "exterior", &d.exterior, global_medium)?,
            keeps_medium: d.keeps_medium,
            light,
            flip: d.flip_normals,
            kind: d.kind.clone(),
        });
    }
    if settings.surface_events_only
        && let Some(i) = surfaces.iter().position(|s| matches!(s.bsdf, Bsdf::Mask { .. }))
    {
        cx.at(desc.shapes[i].span().start, format!("shapes[{i}]"));
        return cx.err(
            "a mask under Mitsuba's `path` integrator is not supported (zerovar passes masks as \
             null events); use <integrator type=\"volpath\">",
        );
    }
    for (i, l) in desc.lights.iter().enumerate() {
        let d = l.get_ref();
        cx.at(l.span().start, format!("lights[{i}] ({})", d.kind));
        lights.push(light(&cx, d)?);
    }
    let infinite_lights =
        lights.iter().enumerate().filter(|(_, l)| l.is_infinite()).map(|(i, _)| i as u32).collect();
    let delta_lights =
        lights.iter().enumerate().filter(|(_, l)| l.is_delta()).map(|(i, _)| i as u32).collect();
    let point_lights = lights.iter().filter_map(Light::point_light).collect();
    let trackers = media.iter().map(Tracker::for_medium).collect();
    let bvh = Bvh::build(&shapes);
    let unbounded = [camera_medium, global_medium];
    let world = bounding_sphere(&bvh, unbounded.iter().flatten().map(|&m| &media[m as usize]));
    Ok(Scene {
        path: path.to_path_buf(),
        shapes,
        surfaces,
        bvh,
        media,
        trackers,
        lights,
        infinite_lights,
        delta_lights,
        point_lights,
        camera,
        camera_medium,
        global_medium,
        settings,
        world,
    })
}

/// The sphere around the shapes (Mitsuba's scene bounds), and around the boxes of `open`
/// media (the camera's and the global one) where they are grids, which no shape need enclose:
/// where lights at infinity are placed (see [`Scene::infinite_reach`]).
fn bounding_sphere<'m>(bvh: &Bvh, open: impl Iterator<Item = &'m Medium>) -> (glam::Vec3A, f32) {
    let boxes = open.filter_map(|m| match &m.kind {
        MediumKind::Heterogeneous(h) => Some(h.bounds()),
        MediumKind::Homogeneous { .. } => None,
    });
    let b = boxes.fold(bvh.bounds(), |a, b| a.union(&b));
    if b.is_empty() || !(b.min.is_finite() && b.max.is_finite()) {
        return (glam::Vec3A::ZERO, 0.0);
    }
    (b.center(), 0.5 * (b.max - b.min).length())
}

fn geometry(cx: &Ctx<'_>, d: &ShapeDesc) -> Result<Geometry> {
    let to_world = cx.transform(&d.transform)?;
    let not_sphere = [("center", d.center.is_some()), ("radius", d.radius.is_some())];
    let not_cylinder = [("p0", d.p0.is_some()), ("p1", d.p1.is_some())];
    let not_obj = [
        ("filename", d.filename.is_some()),
        ("face_normals", d.face_normals.is_some()),
        ("flip_tex_coords", d.flip_tex_coords.is_some()),
        ("shape_index", d.shape_index.is_some()),
    ];
    match d.kind.as_str() {
        "sphere" => {
            cx.only("spheres", &[not_obj.as_slice(), &not_cylinder].concat())?;
            let center = d.center.unwrap_or(Vec3::ZERO);
            let radius = d.radius.unwrap_or(1.0);
            cx.finite("center", &center.to_array())?;
            if !(radius > 0.0 && radius.is_finite()) {
                return cx.err(format!("radius {radius} must be positive"));
            }
            let local = Transform::scale(Vec3::splat(radius))
                .map(|s| s.then(&Transform::translate(center)))
                .map(|t| t.then(&to_world))
                .filter(Transform::is_similarity);
            match local {
                Some(t) => Ok(Geometry::Sphere(Sphere::new(t))),
                None => cx.err(
                    "a sphere's transform must scale uniformly (use an obj mesh for ellipsoids)",
                ),
            }
        }
        "cylinder" => {
            cx.only("cylinders", &[&[not_sphere[0]], not_obj.as_slice()].concat())?;
            cylinder(cx, d, to_world)
        }
        "cube" | "rectangle" | "disk" => {
            let not_these = [not_sphere.as_slice(), &not_cylinder, &not_obj].concat();
            cx.only(&format!("{}s", d.kind), &not_these)?;
            Ok(match d.kind.as_str() {
                "cube" => Geometry::Cuboid(Cuboid::new(to_world)),
                "rectangle" => match Parallelogram::new(&to_world) {
                    Some(r) => Geometry::Parallelogram(r),
                    None => return cx.err("the transform flattens the rectangle to zero area"),
                },
                _ => Geometry::Disk(Disk::new(to_world)),
            })
        }
        "obj" | "ply" | "serialized" => {
            let only_obj = [("flip_tex_coords", d.kind == "serialized" && d.flip_tex_coords.is_some())];
            let only_serialized = [("shape_index", d.kind != "serialized" && d.shape_index.is_some())];
            cx.only(
                &format!("{} meshes", d.kind),
                &[not_sphere.as_slice(), &not_cylinder, &only_obj, &only_serialized].concat(),
            )?;
            let file = cx.file(&cx.required("filename", &d.filename)?);
            if !file.is_file() {
                return cx.err(format!("{}: no such file", file.display()));
            }
            let face_normals = d.face_normals.unwrap_or(false);
            let mesh = match d.kind.as_str() {
                "obj" => {
                    let flip = d.flip_tex_coords.unwrap_or(true);
                    Mesh::from_obj(&file, &to_world, face_normals, flip)
                }
                // Mitsuba's PLY reader flips v only when asked.
                "ply" => {
                    let flip = d.flip_tex_coords.unwrap_or(false);
                    Mesh::from_ply(&file, &to_world, face_normals, flip)
                }
                _ => {
                    let index = d.shape_index.unwrap_or(0);
                    Mesh::from_serialized(&file, index, &to_world, face_normals)
                }
            };
            mesh.map(Geometry::Mesh).or_else(|e| cx.err(format!("{}: {e}", file.display())))
        }
        other => cx.err(format!(
            "unknown shape type `{other}`; use sphere, cube, rectangle, disk, cylinder, obj, ply or \
             serialized"
        )),
    }
}

/// Mitsuba's cylinder: the unit tube scaled to `radius` across and to the length from `p0` to
/// `p1` along, turned onto that axis (by the frame Mitsuba builds around it, which places u's
/// seam) and moved to `p0`, then `to_world`.
fn cylinder(cx: &Ctx<'_>, d: &ShapeDesc, to_world: Transform) -> Result<Geometry> {
    let (p0, p1) = (d.p0.unwrap_or(Vec3::ZERO), d.p1.unwrap_or(Vec3::Z));
    let radius = d.radius.unwrap_or(1.0);
    cx.finite("p0", &p0.to_array())?;
    cx.finite("p1", &p1.to_array())?;
    if !(radius > 0.0 && radius.is_finite()) {
        return cx.err(format!("radius {radius} must be positive"));
    }
    let axis = p1 - p0;
    let length = axis.length();
    if !(length > 0.0 && length.is_finite()) {
        return cx.err(format!("p0 {p0} and p1 {p1} must be apart: they give the tube's axis"));
    }
    let f = crate::math::Frame::from_z((axis / length).into());
    let cols = [f.x * radius, f.y * radius, f.z * length].map(Vec3::from);
    let local = Transform::new(glam::Affine3A::from_mat3_translation(
        glam::Mat3::from_cols(cols[0], cols[1], cols[2]),
        p0,
    ));
    match local.map(|t| t.then(&to_world)).as_ref().and_then(Cylinder::new) {
        Some(c) => Ok(Geometry::Cylinder(c)),
        None => cx.err(
            "a cylinder's transform may rotate, translate, scale uniformly across the axis and \
             stretch along it, nothing else (no shear, no mirroring: use an obj mesh for other \
             tubes)",
        ),
    }
}

fn bsdf(cx: &Ctx<'_>, d: Option<&BsdfDesc>) -> Result<Bsdf> {
    let Some(d) = d else {
        return Ok(Bsdf::Diffuse {
            reflectance: Texture::Constant(Spectrum::splat(0.5)),
            two_sided: false,
        });
    };
    let diffuse_only =
        [("reflectance", d.reflectance.is_some()), ("two_sided", d.two_sided.is_some())];
    let dielectric_only = [("int_ior", d.int_ior.is_some()), ("ext_ior", d.ext_ior.is_some())];
    let plastic_only = [
        ("diffuse_reflectance", d.diffuse_reflectance.is_some()),
        ("specular_reflectance", d.specular_reflectance.is_some()),
        ("nonlinear", d.nonlinear.is_some()),
    ];
    let rough_only = [
        ("distribution", d.distribution.is_some()),
        ("alpha", d.alpha.is_some()),
        ("alpha_u", d.alpha_u.is_some()),
        ("alpha_v", d.alpha_v.is_some()),
    ];
    let metal_only =
        [("material", d.material.is_some()), ("eta", d.eta.is_some()), ("k", d.k.is_some())];
    let what = format!("{} surfaces", d.kind);
    if d.kind != "mask" {
        cx.only(&what, &[("opacity", d.opacity.is_some()), ("nested", d.nested.is_some())])?;
    }
    // What neither a null surface nor a mask (whose parameters are its nested BSDF's) takes.
    let any_surface =
        [diffuse_only.as_slice(), &dielectric_only, &plastic_only, &rough_only, &metal_only]
            .concat();
    match d.kind.as_str() {
        "mask" => {
            cx.only(&what, &any_surface)?;
            mask(cx, d)
        }
        "null" => {
            cx.only(&what, &any_surface)?;
            Ok(Bsdf::Null)
        }
        "diffuse" => {
            cx.only(
                &what,
                &[dielectric_only.as_slice(), &plastic_only, &rough_only, &metal_only].concat(),
            )?;
            let reflectance = texture(cx, "reflectance", d.reflectance.as_ref())?;
            Ok(Bsdf::Diffuse { reflectance, two_sided: d.two_sided.unwrap_or(false) })
        }
        "dielectric" | "thindielectric" | "roughdielectric" => {
            let rough = d.kind == "roughdielectric";
            let other = if rough { &[][..] } else { &rough_only[..] };
            cx.only(&what, &[diffuse_only.as_slice(), &plastic_only, &metal_only, other].concat())?;
            // Mitsuba's defaults: BK7 glass inside, air outside.
            let eta = relative_ior(cx, d, 1.5046)?;
            Ok(match d.kind.as_str() {
                "dielectric" => Bsdf::Dielectric { eta },
                "thindielectric" => Bsdf::ThinDielectric { eta },
                _ => {
                    if eta == 1.0 {
                        return cx.err(
                            "a rough dielectric needs int_ior and ext_ior to differ; an \
                             index-matched boundary is a null bsdf",
                        );
                    }
                    Bsdf::RoughDielectric(RoughDielectric { roughness: roughness(cx, d)?, eta })
                }
            })
        }
        "plastic" | "roughplastic" => {
            let rough = d.kind == "roughplastic";
            let other = if rough { &[][..] } else { &rough_only[..] };
            cx.only(
                &what,
                &[&[("reflectance", d.reflectance.is_some())][..], &metal_only, other].concat(),
            )?;
            let diffuse = texture(cx, "diffuse_reflectance", d.diffuse_reflectance.as_ref())?;
            let specular = d.specular_reflectance.unwrap_or(Rgb::Grey(1.0));
            let specular = cx.colour("specular_reflectance", specular, Some(1.0))?;
            // Mitsuba's defaults: polypropylene inside, air outside.
            let eta = relative_ior(cx, d, 1.49)?;
            let (nonlinear, two_sided) =
                (d.nonlinear.unwrap_or(false), d.two_sided.unwrap_or(false));
            Ok(if rough {
                let p = RoughPlastic::new(diffuse, specular, eta, nonlinear, microfacet(cx, d)?);
                Bsdf::RoughPlastic(p.with_two_sided(two_sided))
            } else {
                Bsdf::Plastic(
                    Plastic::new(diffuse, specular, eta, nonlinear).with_two_sided(two_sided),
                )
            })
        }
        "conductor" | "roughconductor" => {
            let rough = d.kind == "roughconductor";
            let other = if rough { &[][..] } else { &rough_only[..] };
            let not_metal = [
                ("reflectance", d.reflectance.is_some()),
                ("diffuse_reflectance", d.diffuse_reflectance.is_some()),
                ("nonlinear", d.nonlinear.is_some()),
            ];
            cx.only(&what, &[dielectric_only.as_slice(), &not_metal, other].concat())?;
            let metal = metal(cx, d)?;
            Ok(if rough {
                Bsdf::RoughConductor(RoughConductor { metal, roughness: roughness(cx, d)? })
            } else {
                Bsdf::Conductor(Conductor(metal))
            })
        }
        other => cx.err(format!(
            "unknown bsdf type `{other}`; use null, diffuse, dielectric, thindielectric, plastic, \
             conductor, roughdielectric, roughplastic or roughconductor"
        )),
    }
}

/// Mitsuba's `mask` around a BSDF that does not itself let light straight through.
fn mask(cx: &Ctx<'_>, d: &BsdfDesc) -> Result<Bsdf> {
    let Some(inner) = d.nested.as_deref() else {
        return cx.err("a mask needs the BSDF behind it: `nested = { type = ... }`");
    };
    let opacity = match &d.opacity {
        None => Texture::Constant(Spectrum::splat(0.5)),
        Some(t) => texture_within(cx, "opacity", t, Some(1.0))?,
    };
    let nested = bsdf(cx, Some(inner))?;
    if nested.may_pass() {
        return cx.err(format!(
            "a mask around a `{}` (which light passes itself) is not supported; mask a surface \
             that scatters",
            inner.kind
        ));
    }
    Ok(Bsdf::Mask { opacity, nested: Box::new(nested) })
}

/// A conductor's metal: Mitsuba's named `material` (default `none`, a perfect mirror), or its
/// `eta` and `k`; and the factor `specular_reflectance`.
fn metal(cx: &Ctx<'_>, d: &BsdfDesc) -> Result<Metal> {
    let (eta, k) = match (&d.material, d.eta, d.k) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return cx.err("give a conductor either `material` or `eta` and `k`, not both");
        }
        (Some(name), None, None) => match Metal::named(name) {
            Some(v) => v,
            None => {
                return cx.err(format!(
                    "material \"{name}\" is not one of Mitsuba's conductors (none, {}); give `eta` \
                     and `k` instead",
                    Metal::names().collect::<Vec<_>>().join(", ")
                ));
            }
        },
        (None, eta, k) => (
            cx.colour("eta", eta.unwrap_or(Rgb::Grey(0.0)), None)?,
            cx.colour("k", k.unwrap_or(Rgb::Grey(1.0)), None)?,
        ),
    };
    let specular = d.specular_reflectance.unwrap_or(Rgb::Grey(1.0));
    let specular = cx.colour("specular_reflectance", specular, Some(1.0))?;
    Ok(Metal { eta, k, specular, two_sided: d.two_sided.unwrap_or(false) })
}

/// The micro-normals of a rough surface: Mitsuba's `distribution` (default Beckmann) and
/// `alpha` (default 0.1), or `alpha_u` and `alpha_v` together; each a number or a texture.
fn roughness(cx: &Ctx<'_>, d: &BsdfDesc) -> Result<Roughness> {
    let kind = microfacet_kind(cx, d)?;
    let (u, v) = match (&d.alpha, &d.alpha_u, &d.alpha_v) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return cx.err("give either `alpha` or `alpha_u` and `alpha_v`, not both");
        }
        (None, Some(_), None) | (None, None, Some(_)) => {
            return cx.err("anisotropic roughness needs both `alpha_u` and `alpha_v`");
        }
        (None, None, None) => return Ok(Microfacet::isotropic(kind, 0.1).into()),
        (Some(a), None, None) => (alpha_texture(cx, "alpha", a)?, None),
        (None, Some(u), Some(v)) => {
            (alpha_texture(cx, "alpha_u", u)?, Some(alpha_texture(cx, "alpha_v", v)?))
        }
    };
    Ok(match (&u, &v) {
        (Texture::Constant(_), None) => Microfacet::isotropic(kind, u.eval_1(Vec2::ZERO)).into(),
        (Texture::Constant(_), Some(Texture::Constant(_))) => {
            let (alpha_u, alpha_v) = (u.eval_1(Vec2::ZERO), v.unwrap().eval_1(Vec2::ZERO));
            Roughness::Constant(Microfacet { kind, alpha_u, alpha_v })
        }
        _ => Roughness::Textured { kind, alpha_u: Arc::new(u), alpha_v: v.map(Arc::new) },
    })
}

/// A rough surface with one constant roughness (`roughplastic`, whose `alpha` Mitsuba takes
/// as a number only).
fn microfacet(cx: &Ctx<'_>, d: &BsdfDesc) -> Result<Microfacet> {
    if d.alpha_u.is_some() || d.alpha_v.is_some() {
        return cx.err(format!(
            "a {} takes one `alpha`, as in Mitsuba; alpha_u and alpha_v are for roughconductor \
             and roughdielectric",
            d.kind
        ));
    }
    match roughness(cx, d)? {
        Roughness::Constant(m) => Ok(m),
        Roughness::Textured { .. } => cx.err(format!(
            "a {}'s `alpha` is a number, as in Mitsuba; textured roughness is for \
             roughconductor and roughdielectric",
            d.kind
        )),
    }
}

/// Mitsuba's `distribution` (default Beckmann).
fn microfacet_kind(cx: &Ctx<'_>, d: &BsdfDesc) -> Result<MicrofacetKind> {
    match d.distribution.as_deref() {
        None | Some("beckmann") => Ok(MicrofacetKind::Beckmann),
        Some("ggx") => Ok(MicrofacetKind::Ggx),
        Some(other) => {
            cx.err(format!("unknown microfacet distribution `{other}`; use beckmann or ggx"))
        }
    }
}

/// A roughness `name`: a number or a texture read as one number, at least [`MIN_ALPHA`]
/// everywhere.
fn alpha_texture(cx: &Ctx<'_>, name: &str, d: &TextureDesc) -> Result<Texture> {
    let t = texture_within(cx, name, d, None)?;
    let (lo, hi) = t.range_1();
    if !(lo.is_finite() && hi.is_finite() && lo >= MIN_ALPHA) {
        let at = if lo == hi { format!("{lo}") } else { format!("down to {lo}") };
        return cx.err(format!(
            "{name} {at} is not a roughness zerovar renders: give at least {MIN_ALPHA} (for a \
             smooth surface use dielectric, plastic or conductor)"
        ));
    }
    Ok(t)
}

/// Interior over exterior index of refraction, with Mitsuba's default interior `int` and air
/// outside.
fn relative_ior(cx: &Ctx<'_>, d: &BsdfDesc, int: f32) -> Result<f32> {
    let (int, ext) = (d.int_ior.unwrap_or(int), d.ext_ior.unwrap_or(1.000277));
    if !(int > 0.0 && ext > 0.0 && int.is_finite() && ext.is_finite()) {
        return cx.err("indices of refraction must be positive");
    }
    Ok(int / ext)
}

/// An image file's pixels as linear RGB, as Mitsuba's bitmaps read them: OpenEXR and Radiance
/// HDR as stored, PNG (8 or 16 bits) and JPEG decoded from sRGB unless `raw`.
fn read_picture(
    file: &Path,
    raw: bool,
) -> std::result::Result<(usize, usize, Vec<[f32; 3]>), String> {
    // A regular file of bounded size: not a pipe that blocks the read.
    crate::files::check(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let is = |ext: &str| file.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext));
    if is("exr") {
        return crate::output::read_exr(file).map_err(|e| e.to_string());
    }
    let (kind, linear) = if is("png") {
        ("PNG", false)
    } else if is("jpg") || is("jpeg") {
        ("JPEG", false)
    } else if is("hdr") {
        ("Radiance HDR", true)
    } else {
        return Err(format!(
            "{}: zerovar reads OpenEXR, Radiance HDR (.hdr), PNG and JPEG images; convert the \
             image to one of them",
            file.display()
        ));
    };
    let cannot = |e: image::ImageError| format!("{}: cannot read {kind}: {e}", file.display());
    // The header's size first, so a corrupt one cannot exhaust memory.
    let (w, h) = image::image_dimensions(file).map_err(cannot)?;
    if u64::from(w) * u64::from(h) > crate::output::MAX_EXR_PIXELS as u64 {
        return Err(format!(
            "{}: {w} x {h} pixels, more than the {} zerovar reads",
            file.display(),
            crate::output::MAX_EXR_PIXELS
        ));
    }
    let image = image::open(file).map_err(cannot)?.into_rgb32f();
    let decode = |v: f32| if linear || raw { v } else { srgb_to_linear(v) };
    Ok((w as usize, h as usize, image.pixels().map(|p| p.0.map(decode)).collect()))
}

/// Mitsuba's bitmap texture from its image file (see [`read_picture`]), of reflectances in
/// [0, 1].
fn bitmap(cx: &Ctx<'_>, d: &BitmapDesc, most: Option<f32>) -> Result<Texture> {
    let file = cx.file(&d.filename);
    let (width, height, texels) =
        read_picture(&file, d.raw.unwrap_or(false)).or_else(|e| cx.err(e))?;
    let bilinear = match d.filter_type.as_deref() {
        None | Some("bilinear") => true,
        Some("nearest") => false,
        Some(other) => return cx.err(format!("filter_type `{other}`: use bilinear or nearest")),
    };
    let wrap = match d.wrap_mode.as_deref() {
        None | Some("repeat") => Wrap::Repeat,
        Some("mirror") => Wrap::Mirror,
        Some("clamp") => Wrap::Clamp,
        Some(other) => return cx.err(format!("wrap_mode `{other}`: use repeat, mirror or clamp")),
    };
    let scale = d.scale.unwrap_or([1.0, 1.0]);
    cx.finite("bitmap scale", &scale)?;
    let Some(b) = Bitmap::new(width, height, texels, bilinear, wrap, Vec2::from_array(scale))
    else {
        return cx.err(format!("{}: the image is empty", file.display()));
    };
    let max = b.max();
    let min = b.min();
    if max.is_nan() || min.is_nan() || min < 0.0 || !b.mean().is_finite() {
        return cx.err(format!("{}: texel values must be finite and non-negative", file.display()));
    }
    if let Some(most) = most.filter(|&m| max > m) {
        return cx.err(format!(
            "{}: texel values reach {max}; a reflectance or opacity lies in [0, {most}] (scale \
             the image, or save it as PNG)",
            file.display()
        ));
    }
    Ok(Texture::Bitmap(Arc::new(b)))
}

/// A reflectance texture `name` (0.5 grey when absent, as in Mitsuba).
fn texture(cx: &Ctx<'_>, name: &str, d: Option<&TextureDesc>) -> Result<Texture> {
    match d {
        None => Ok(Texture::Constant(Spectrum::splat(0.5))),
        Some(d) => texture_within(cx, name, d, Some(1.0)),
    }
}

/// A texture `name` whose values may not exceed `most`.
fn texture_within(cx: &Ctx<'_>, name: &str, d: &TextureDesc, most: Option<f32>) -> Result<Texture> {
    Ok(match d {
        TextureDesc::Constant(c) => Texture::Constant(cx.colour(name, *c, most)?),
        TextureDesc::Checkerboard(c) => {
            if c.kind != "checkerboard" {
                return cx.err(format!("unknown texture `{}`; use checkerboard or bitmap", c.kind));
            }
            let scale = c.scale.unwrap_or([1.0, 1.0]);
            cx.finite("checkerboard scale", &scale)?;
            Texture::Checkerboard {
                color0: cx.colour("color0", c.color0.unwrap_or(Rgb::Grey(0.4)), most)?,
                color1: cx.colour("color1", c.color1.unwrap_or(Rgb::Grey(0.2)), most)?,
                scale: Vec2::from_array(scale),
            }
        }
        TextureDesc::Bitmap(b) => {
            if b.kind != "bitmap" {
                return cx.err(format!("unknown texture `{}`; use checkerboard or bitmap", b.kind));
            }
            bitmap(cx, b, most)?
        }
    })
}

fn phase(cx: &Ctx<'_>, d: Option<&PhaseDesc>) -> Result<PhaseFunction> {
    let Some(p) = d else { return Ok(PhaseFunction::Isotropic) };
    if p.kind != "blendphase" {
        return Ok(lobe(cx, p)?.alone());
    }
    cx.only("blendphase", &[("g", p.g.is_some())])?;
    let weight = p.weight.unwrap_or(0.5);
    if !(0.0..=1.0).contains(&weight) {
        return cx.err(format!("blendphase weight {weight} must lie in [0, 1]"));
    }
    match p.phases.as_deref() {
        Some([first, second]) => {
            Ok(PhaseFunction::Blend { weight, first: lobe(cx, first)?, second: lobe(cx, second)? })
        }
        _ => cx.err("blendphase blends exactly two phases: give `phases = [{ ... }, { ... }]`"),
    }
}

/// A phase function that is not a blend.
fn lobe(cx: &Ctx<'_>, p: &PhaseDesc) -> Result<Lobe> {
    let blend = [("weight", p.weight.is_some()), ("phases", p.phases.is_some())];
    match p.kind.as_str() {
        "isotropic" | "rayleigh" => {
            cx.only(
                &format!("{} phase functions", p.kind),
                &[&[("g", p.g.is_some())], &blend[..]].concat(),
            )?;
            Ok(if p.kind == "isotropic" { Lobe::Isotropic } else { Lobe::Rayleigh })
        }
        "hg" => {
            cx.only("hg phase functions", &blend)?;
            let g = cx.required("g", &p.g)?;
            if !(g > -1.0 && g < 1.0) {
                return cx.err(format!("HG g = {g} must lie strictly between -1 and 1"));
            }
            Ok(if g == 0.0 { Lobe::Isotropic } else { Lobe::HenyeyGreenstein { g } })
        }
        "blendphase" => cx.err(
            "a blendphase inside a blendphase is not supported; blend two \
                                isotropic, hg or rayleigh phases",
        ),
        other => cx.err(format!(
            "unknown phase function `{other}`; use isotropic, hg, rayleigh or blendphase"
        )),
    }
}

fn medium(cx: &Ctx<'_>, name: &str, d: &MediumDesc) -> Result<Medium> {
    let scale = d.scale.unwrap_or(1.0);
    if !(scale >= 0.0 && scale.is_finite()) {
        return cx.err(format!("scale {scale} must be finite and non-negative"));
    }
    let sigma_t = cx.colour("sigma_t", d.sigma_t.unwrap_or(Rgb::Grey(1.0)), None)? * scale;
    if !sigma_t.is_finite() {
        return cx.err("sigma_t * scale overflows");
    }
    let constant_albedo = |a: &Option<AlbedoDesc>| match a {
        None => Ok(Spectrum::splat(0.75)),
        Some(AlbedoDesc::Constant(c)) => cx.colour("albedo", *c, Some(1.0)),
        Some(AlbedoDesc::File(_)) => cx.err("this medium type takes a constant albedo, not a file"),
    };
    let kind = match d.kind.as_str() {
        "homogeneous" => {
            cx.only(
                "homogeneous media",
                &[
                    ("density", d.density.is_some()),
                    ("grid_name", d.grid_name.is_some()),
                    ("noise", d.noise.is_some()),
                    ("transform", !d.transform.is_empty()),
                ],
            )?;
            MediumKind::Homogeneous { sigma_t, albedo: constant_albedo(&d.albedo)? }
        }
        "grid" => {
            cx.only("grid media", &[("noise", d.noise.is_some())])?;
            // A three-channel density is a grey density times this colour.
            let mut tint = Spectrum::ONE;
            // A `.vdb` grid brings its own placement, which the medium's transform then moves.
            let mut placement = None;
            let density = match cx.required("density", &d.density)? {
                DensityDesc::File(f) if is_vdb(&f) => {
                    let (grid, cube_to_vdb) = read_vdb(cx, &cx.file(&f), d.grid_name.as_deref())?;
                    if matches!(d.albedo, Some(AlbedoDesc::File(_))) {
                        return cx.err(
                            "an albedo grid needs a .vol density on the same unit cube; give a \
                             constant albedo with a .vdb density",
                        );
                    }
                    placement = Some(cube_to_vdb);
                    grid
                }
                DensityDesc::File(f) => {
                    let (grid, colour) = read_density(cx, &cx.file(&f))?;
                    tint = colour;
                    grid
                }
                DensityDesc::Constant(v) => {
                    if !(v >= 0.0 && v.is_finite()) {
                        return cx.err(format!("density {v} must be finite and non-negative"));
                    }
                    Grid::new(VolGrid { resolution: [1, 1, 1], channels: 1, data: vec![v] })
                }
            };
            if d.grid_name.is_some() && placement.is_none() {
                return cx.err("`grid_name` applies only to a .vdb density; remove it");
            }
            let albedo = match &d.albedo {
                Some(AlbedoDesc::File(f)) if is_vdb(f) => {
                    return cx.err("albedo grids are read from .vol files; .vdb holds densities");
                }
                Some(AlbedoDesc::File(f)) => {
                    AlbedoField::Grid(read_grid(cx, &cx.file(f), &[1, 3])?)
                }
                a => AlbedoField::Constant(constant_albedo(a)?),
            };
            if let AlbedoField::Grid(g) = &albedo
                && g.max_value() > 1.0
            {
                return cx.err(format!(
                    "albedo grid holds {} > 1; an albedo lies in [0, 1]",
                    g.max_value()
                ));
            }
            let peak = density.max_value() * (sigma_t * tint).max_element();
            if !peak.is_finite() {
                return cx.err(format!(
                    "the grid's largest density {} times the extinction {} overflows single \
                     precision; lower the scale or the extinction",
                    density.max_value(),
                    (sigma_t * tint).max_element()
                ));
            }
            let to_world = cx.transform(&d.transform)?;
            let to_world = placement.map_or(to_world, |p| p.then(&to_world));
            MediumKind::Heterogeneous(Box::new(Heterogeneous::new(
                to_world,
                DensityField::Grid(density),
                1.0,
                sigma_t * tint,
                albedo,
            )))
        }
        "noise" => {
            cx.only(
                "noise media",
                &[("density", d.density.is_some()), ("grid_name", d.grid_name.is_some())],
            )?;
            let noise = d.noise.unwrap_or_default();
            let n = [noise.frequency, noise.amplitude, noise.threshold, noise.sharpness];
            cx.finite("noise parameters", &n)?;
            if !(noise.frequency > 0.0 && noise.sharpness > 0.0) || noise.octaves > 16 {
                return cx.err("noise needs frequency > 0, sharpness > 0 and at most 16 octaves");
            }
            let to_world = cx.transform(&d.transform)?;
            let albedo = AlbedoField::Constant(constant_albedo(&d.albedo)?);
            MediumKind::Heterogeneous(Box::new(Heterogeneous::new(
                to_world,
                DensityField::Noise(noise),
                1.0,
                sigma_t,
                albedo,
            )))
        }
        other => {
            return cx
                .err(format!("unknown medium type `{other}`; use homogeneous, grid or noise"));
        }
    };
    let emission = cx.colour("emission", d.emission.unwrap_or(Rgb::Grey(0.0)), None)?;
    Ok(Medium { name: name.to_string(), kind, phase: phase(cx, d.phase.as_ref())?, emission })
}

fn read_grid(cx: &Ctx<'_>, file: &Path, channels: &[usize]) -> Result<Grid> {
    let vol = VolGrid::read(file).or_else(|e| cx.err(e.to_string()))?;
    if !channels.contains(&vol.channels) {
        return cx.err(format!(
            "{}: has {} channels; expected {}",
            file.display(),
            vol.channels,
            channels.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(" or ")
        ));
    }
    Ok(Grid::new(vol))
}

/// A `.vol` density of one channel, or of three: where the three are in one proportion
/// everywhere (a density times a colour, as an RGB extinction grid for Mitsuba often is), the
/// grid of its largest channel and the colour, which keeps lookups to one channel; otherwise
/// the RGB grid itself and white.
fn read_density(cx: &Ctx<'_>, file: &Path) -> Result<(Grid, Spectrum)> {
    let vol = VolGrid::read(file).or_else(|e| cx.err(e.to_string()))?;
    match vol.channels {
        1 => Ok((Grid::new(vol), Spectrum::ONE)),
        3 => {
            let [r, g, b] = [0, 1, 2]
                .map(|c| vol.data.iter().skip(c).step_by(3).fold(0.0f32, |m, &v| m.max(v)));
            let top = r.max(g).max(b);
            if top <= 0.0 {
                let data = vec![0.0; vol.data.len() / 3];
                return Ok((
                    Grid::new(
                        VolGrid::new(vol.resolution, 1, data).or_else(|e| cx.err(e.to_string()))?,
                    ),
                    Spectrum::ONE,
                ));
            }
            let colour = Spectrum::new(r, g, b) / top;
            let main = if r == top {
                0
            } else if g == top {
                1
            } else {
                2
            };
            let proportional = vol.data.chunks_exact(3).all(|v| {
                (0..3).all(|c| {
                    (v[c] - v[main] * colour[c]).abs()
                        <= 1e-4 * top.max(f32::MIN_POSITIVE) + 1e-5 * v[c].abs()
                })
            });
            if !proportional {
                // Channels that vary apart: a grid of three densities, tracked spectrally.
                return Ok((Grid::new(vol), Spectrum::ONE));
            }
            let density: Vec<f32> = vol.data.chunks_exact(3).map(|v| v[main]).collect();
            let grid =
                VolGrid::new(vol.resolution, 1, density).or_else(|e| cx.err(e.to_string()))?;
            Ok((Grid::new(grid), colour))
        }
        n => cx.err(format!("{}: has {n} channels; expected 1 or 3 (RGB)", file.display())),
    }
}

/// Whether a density file is an OpenVDB file (by its extension, as OpenVDB's tools decide).
pub(super) fn is_vdb(file: &str) -> bool {
    Path::new(file).extension().is_some_and(|e| e.eq_ignore_ascii_case("vdb"))
}

/// A `.vdb` float grid as a dense grid, and the map from its unit cube to the VDB's world
/// space (the medium's local space).
fn read_vdb(cx: &Ctx<'_>, file: &Path, name: Option<&str>) -> Result<(Grid, Transform)> {
    let vdb = VdbGrid::read(file, name).or_else(|e| cx.err(e.to_string()))?;
    let m = vdb.cube_to_world();
    let placement = Transform::new(glam::Affine3A {
        matrix3: m.matrix3.as_mat3().into(),
        translation: m.translation.as_vec3().into(),
    });
    let Some(placement) = placement else {
        return cx.err(format!(
            "{}: grid `{}`: its index-to-world transform does not fit in single precision",
            file.display(),
            vdb.name
        ));
    };
    let vol = VolGrid { resolution: vdb.resolution, channels: 1, data: vdb.data };
    Ok((Grid::new(vol), placement))
}

fn light(cx: &Ctx<'_>, d: &LightDesc) -> Result<Light> {
    let fields = [
        ("position", d.position.is_some()),
        ("target", d.target.is_some()),
        ("intensity", d.intensity.is_some()),
        ("cutoff_angle", d.cutoff_angle.is_some()),
        ("beam_width", d.beam_width.is_some()),
        ("direction", d.direction.is_some()),
        ("irradiance", d.irradiance.is_some()),
        ("angular_diameter", d.angular_diameter.is_some()),
        ("radiance", d.radiance.is_some()),
        ("filename", d.filename.is_some()),
        ("scale", d.scale.is_some()),
        ("transform", !d.transform.is_empty()),
    ];
    let allow = |kind: &str, allowed: &[&str]| {
        let others: Vec<_> = fields.iter().filter(|(n, _)| !allowed.contains(n)).copied().collect();
        cx.only(kind, &others)
    };
    let position = |cx: &Ctx<'_>| -> Result<Vec3A> {
        let p = cx.required("position", &d.position)?;
        cx.finite("position", &p.to_array())?;
        Ok(p.into())
    };
    match d.kind.as_str() {
        "point" => {
            allow("point lights", &["position", "intensity"])?;
            let intensity =
                cx.colour("intensity", cx.required("intensity", &d.intensity)?, None)?;
            Ok(Light::Point { position: position(cx)?, intensity })
        }
        "spot" => {
            allow(
                "spot lights",
                &["position", "target", "intensity", "cutoff_angle", "beam_width"],
            )?;
            let p = position(cx)?;
            let target = cx.required("target", &d.target)?;
            let axis = cx.direction("target - position", Vec3::from(Vec3A::from(target) - p))?;
            let cutoff = d.cutoff_angle.unwrap_or(20.0);
            let beam = d.beam_width.unwrap_or(0.75 * cutoff);
            if !(cutoff > 0.0 && cutoff <= 90.0 && beam >= 0.0 && beam <= cutoff) {
                return cx.err(format!(
                    "cutoff_angle {cutoff} must be in (0, 90] and beam_width {beam} in [0, cutoff_angle]"
                ));
            }
            Ok(Light::Spot {
                position: p,
                frame: Frame::from_z(axis),
                intensity: cx.colour("intensity", cx.required("intensity", &d.intensity)?, None)?,
                cutoff: cutoff.to_radians(),
                beam_width: beam.to_radians(),
            })
        }
        "directional" => {
            allow("directional lights", &["direction", "irradiance", "angular_diameter"])?;
            let dir = cx.direction("direction", cx.required("direction", &d.direction)?)?;
            let diameter = d.angular_diameter.unwrap_or(0.0);
            if !(0.0..180.0).contains(&diameter) {
                return cx.err(format!("angular_diameter {diameter} must be in [0, 180) degrees"));
            }
            let half = 0.5 * diameter.to_radians();
            // 1 - cos(x) = 2 sin^2(x / 2) keeps precision for the sun's 0.27 degrees.
            let one_minus_cos = 2.0 * (0.5 * half).sin().powi(2);
            Ok(Light::Directional {
                to_light: -dir,
                irradiance: cx.colour(
                    "irradiance",
                    cx.required("irradiance", &d.irradiance)?,
                    None,
                )?,
                one_minus_cos,
            })
        }
        "constant" => {
            allow("constant environments", &["radiance"])?;
            Ok(Light::Constant {
                radiance: cx.colour("radiance", cx.required("radiance", &d.radiance)?, None)?,
            })
        }
        "envmap" => {
            allow("environment maps", &["filename", "scale", "transform"])?;
            let file = cx.file(&cx.required("filename", &d.filename)?);
            let scale = d.scale.unwrap_or(1.0);
            if !(scale >= 0.0 && scale.is_finite()) {
                return cx.err(format!("scale {scale} must be finite and non-negative"));
            }
            let to_world = cx.transform(&d.transform)?;
            let (w, h, pixels) = read_picture(&file, false).or_else(|e| cx.err(e))?;
            let pixels: Vec<Spectrum> = pixels.into_iter().map(Spectrum::from_array).collect();
            if let Some(i) = pixels.iter().position(|p| !p.is_finite() || p.min_element() < 0.0) {
                return cx.err(format!(
                    "{}: pixel ({}, {}) is {:?}; radiance must be finite and non-negative",
                    file.display(),
                    i % w,
                    i / w,
                    pixels[i].to_array()
                ));
            }
            let pixels = pixels.into_iter().map(|p| p * scale).collect();
            EnvMap::new(w, h, pixels, to_world).map(|m| Light::EnvMap(Box::new(m))).map_or_else(
                || cx.err(format!("{}: the image is black; remove the light", file.display())),
                Ok,
            )
        }
        other => cx.err(format!(
            "unknown light type `{other}`; use point, spot, directional, constant or envmap \
             (area lights are `emitter` tables on shapes)"
        )),
    }
}
