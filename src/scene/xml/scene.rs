//! The top of a Mitsuba scene: the objects `<scene>` holds, the perspective sensor with its
//! film, reconstruction filter, sampler and medium, and the integrator, mapped onto the
//! camera and render settings of a `SceneDesc`. Defaults are Mitsuba's (768x576 film, 4
//! samples, the `path` integrator, max_depth -1, rr_depth 5).

use super::props::Props;
use super::tree::{Object, Value};
use super::{Conv, Result, compose, spanned};
use crate::camera::FovAxis;
use crate::filter::PixelFilter;
use crate::scene::build::MAX_SIDE;
use crate::scene::desc::{CameraDesc, LightDesc, RenderDesc, SceneDesc, TransformStep};
use glam::Vec3;
use std::rc::Rc;

/// The plugins the sensor and integrator take, for messages.
const INTEGRATORS: &str = "path, volpath, volpathmis, prb, prbvolpath or moment";

pub(super) fn scene(conv: &mut Conv, root: &Object) -> Result<SceneDesc> {
    let (mut sensor, mut integrator) = (None, None);
    let (mut shapes, mut lights) = (Vec::new(), Vec::new());
    for p in &root.props {
        let Value::Object(o) = &p.value else {
            return Err(p.pos.err(format!(
                "<scene> holds plugins, not properties such as {} `{}`",
                p.value.tag(),
                p.name
            )));
        };
        match o.tag.as_str() {
            "sensor" | "integrator" => {
                let slot = if o.tag == "sensor" { &mut sensor } else { &mut integrator };
                if slot.is_some() {
                    return Err(o.pos.err(format!(
                        "a second <{}>; zerovar renders a scene with one <{}>",
                        o.tag, o.tag
                    )));
                }
                *slot = Some(o);
            }
            "shape" => shapes.push(super::shapes::shape(conv, o)?),
            "emitter" => {
                let light = super::shapes::light(conv, o)?;
                let environment = |l: &toml::Spanned<LightDesc>| {
                    matches!(l.get_ref().kind.as_str(), "constant" | "envmap")
                };
                if environment(&light) && lights.iter().any(environment) {
                    return Err(o.pos.err(format!(
                        "{}: a second environment emitter; Mitsuba takes one (constant or \
                         envmap) per scene",
                        o.describe()
                    )));
                }
                lights.push(light);
            }
            // Definitions for `<ref>`: checked here, used where referenced.
            "bsdf" => {
                super::shapes::bsdf(conv, o)?;
            }
            "texture" => {
                super::shapes::texture(conv, o)?;
            }
            "medium" => {
                conv.medium(o)?;
            }
            other => {
                return Err(o.pos.err(format!(
                    "{} does not belong directly in <scene>; put it inside the {} that uses it",
                    o.describe(),
                    match other {
                        "film" | "sampler" => "<sensor>",
                        "rfilter" => "<film>",
                        _ => "<medium>",
                    }
                )));
            }
        }
    }
    let Some(sensor) = sensor else {
        return Err(root.pos.err(
            "the scene has no <sensor>; add <sensor type=\"perspective\"> with a fov and a \
             to_world transform",
        ));
    };
    let (camera, render) = camera(conv, sensor)?;
    let Integrator { kind, max_depth, rr_depth, hide_emitters } = match integrator {
        Some(o) => self::integrator(o)?,
        None => Integrator { kind: "path", max_depth: -1, rr_depth: 5, hide_emitters: false },
    };
    if kind == "path" {
        let null =
            shapes.iter().any(|s| s.get_ref().bsdf.as_ref().is_some_and(|b| b.kind == "null"));
        if !conv.media.is_empty() || null {
            let pos = integrator.map_or(&root.pos, |o| &o.pos);
            return Err(pos.err(
                "Mitsuba's `path` integrator (the default when there is no <integrator>) \
                 ignores media and null surfaces, which zerovar always renders; use \
                 <integrator type=\"volpath\">",
            ));
        }
    }
    Ok(SceneDesc {
        defaults: toml::Table::new(),
        camera,
        render: RenderDesc {
            max_depth,
            rr_depth,
            hide_emitters,
            surface_events_only: kind == "path",
            ..render
        },
        medium: None,
        media: std::mem::take(&mut conv.media),
        shapes,
        lights,
    })
}

/// The perspective or thin-lens sensor: the camera, and the sampler's spp and seed.
fn camera(conv: &mut Conv, o: &Rc<Object>) -> Result<(toml::Spanned<CameraDesc>, RenderDesc)> {
    let p = Props::new(o);
    if o.kind != "perspective" && o.kind != "thinlens" {
        return Err(p.err("zerovar has the `perspective` and `thinlens` sensors"));
    }
    // Mitsuba's thin lens asks for its aperture; its focus defaults to the far plane.
    let (aperture_radius, focus_distance) = if o.kind == "thinlens" {
        let Some(r) = p.float("aperture_radius")? else {
            return Err(p.err("a thinlens sensor needs <float name=\"aperture_radius\" .../>"));
        };
        (r, p.float("focus_distance")?)
    } else {
        // Mitsuba reads it for every projective camera; a pinhole has no use for it.
        p.float("focus_distance")?;
        (0.0, None)
    };
    let fov = p.float("fov")?;
    let focal_length = p.string("focal_length")?;
    if fov.is_some() && focal_length.is_some() {
        return Err(p.err("give either `fov` or `focal_length`, not both (as Mitsuba asks)"));
    }
    let fov_axis = p.string("fov_axis")?;
    let steps = p.transform("to_world")?.unwrap_or(&[]);
    // Mitsuba's defaults and rules: its camera rays start on the near plane.
    let near_clip = p.float("near_clip")?.unwrap_or(0.01);
    let far_clip = p.float("far_clip")?.unwrap_or(1e4);
    if !(near_clip > 0.0 && near_clip.is_finite()) {
        return Err(
            p.err(format!("near_clip {near_clip} must be greater than 0 (as Mitsuba asks)"))
        );
    }
    if far_clip.is_nan() || far_clip <= near_clip {
        return Err(p.err(format!(
            "far_clip {far_clip} must be greater than near_clip {near_clip} (as Mitsuba asks)"
        )));
    }
    let medium = p.object("medium")?.map(|m| conv.medium(m)).transpose()?;
    let (resolution, filter) = match p.object("film")? {
        Some(f) => film(f)?,
        None => ([768, 576], MITSUBA_FILTER),
    };
    let render = match p.object("sampler")? {
        Some(s) => sampler(s)?,
        None => RenderDesc { spp: 4, ..RenderDesc::default() },
    };
    p.finish()?;

    let aspect = resolution[0] as f64 / resolution[1] as f64;
    // The horizontal field of view whose tangent span across the image's diagonal is
    // `diagonal`.
    let across_width = |diagonal: f64| {
        let width = diagonal / (1.0 + 1.0 / (aspect * aspect)).sqrt();
        (2.0 * (0.5 * width).atan()).to_degrees() as f32
    };
    // Mitsuba reads the axis in any case.
    let fov_axis = fov_axis.map(|(name, prop)| (name.to_ascii_lowercase(), prop));
    let axis = |fov: f32| match fov_axis.as_ref().map(|(name, prop)| (name.as_str(), prop)) {
        None | Some(("x", _)) => Ok((fov, FovAxis::X)),
        Some(("y", _)) => Ok((fov, FovAxis::Y)),
        Some(("smaller", _)) if resolution[0] > resolution[1] => Ok((fov, FovAxis::Y)),
        Some(("smaller", _)) => Ok((fov, FovAxis::X)),
        Some(("larger", _)) if resolution[0] > resolution[1] => Ok((fov, FovAxis::X)),
        Some(("larger", _)) => Ok((fov, FovAxis::Y)),
        Some(("diagonal", _)) => {
            let span = 2.0 * (0.5 * f64::from(fov)).to_radians().tan();
            Ok((across_width(span), FovAxis::X))
        }
        Some((other, prop)) => Err(prop.pos.err(format!(
            "fov_axis \"{other}\" is not supported; use x, y, diagonal, smaller or larger"
        ))),
    };
    let (fov, fov_axis) = match fov {
        Some(fov) => axis(fov)?,
        None => {
            // Mitsuba's default: a 50 mm lens on a 36 x 24 mm film, its field of view spanning
            // the image's diagonal (`fov_axis` then does not apply).
            let (text, pos) = focal_length.map_or(("50mm", &o.pos), |(t, prop)| (t, &prop.pos));
            let mm = text.strip_suffix("mm").unwrap_or(text).trim().parse::<f64>();
            let Some(mm) = mm.ok().filter(|v| *v > 0.0 && v.is_finite()) else {
                return Err(pos.err(format!(
                    "focal_length \"{text}\" is not a length in millimetres; give it as \"50mm\""
                )));
            };
            (across_width(36.0f64.hypot(24.0) / mm), FovAxis::X)
        }
    };
    let (origin, target, up, mirror) = match steps {
        [TransformStep::Lookat { origin, target, up }] => (*origin, *target, *up, false),
        _ => {
            let t = compose(steps, &o.pos, "the sensor's to_world")?;
            let m = t.m.matrix3;
            let lengths = [m.x_axis, m.y_axis, m.z_axis].map(|c| c.length());
            if lengths.iter().any(|l| (l - 1.0).abs() > 1e-3) {
                return Err(p.err(
                    "the to_world transform scales; Mitsuba rejects scale factors in a \
                     camera's to_world too, so remove the <scale>",
                ));
            }
            // A mirror (Mitsuba allows it: a scale of -1) flips the image left to right.
            let origin = Vec3::from(t.m.translation);
            (origin, origin + Vec3::from(m.z_axis), Vec3::from(m.y_axis), m.determinant() < 0.0)
        }
    };
    let camera = CameraDesc {
        origin,
        target,
        up,
        fov,
        fov_axis,
        resolution,
        medium,
        near_clip,
        far_clip,
        filter,
        mirror,
        aperture_radius,
        focus_distance: focus_distance.or(Some(far_clip)),
    };
    Ok((spanned(&o.pos, camera), render))
}

/// The film's resolution and pixel filter.
fn film(o: &Rc<Object>) -> Result<([i64; 2], PixelFilter)> {
    let p = Props::new(o);
    if o.kind != "hdrfilm" {
        return Err(p.err("zerovar has only the `hdrfilm` film"));
    }
    let size = |name: &'static str, default: i64| -> Result<i64> {
        match p.integer(name)? {
            None => Ok(default),
            Some(v) if (1..=MAX_SIDE).contains(&v) => Ok(v),
            Some(v) => Err(p.err(format!("{name} {v} must be between 1 and {MAX_SIDE} pixels"))),
        }
    };
    let resolution = [size("width", 768)?, size("height", 576)?];
    // The output file's format: zerovar always writes float RGB EXR and a PNG preview.
    for (name, allowed) in [
        ("pixel_format", &["rgb", "rgba"][..]),
        ("component_format", &["float16", "float32"]),
        ("file_format", &["openexr", "exr"]),
    ] {
        if let Some((v, prop)) = p.string(name)?
            && !allowed.contains(&v)
        {
            return Err(prop.pos.err(format!(
                "{name} \"{v}\" is not supported; zerovar writes a float RGB EXR ({})",
                allowed.join(" or ")
            )));
        }
    }
    let filter = match p.object("rfilter")? {
        Some(f) => rfilter(f)?,
        None => MITSUBA_FILTER,
    };
    p.finish()?;
    Ok((resolution, filter))
}

/// The most lobes of a Lanczos filter: wider ones accept too few of the sampler's proposals
/// (see `filter::MIN_ACCEPTANCE`).
const MAX_LANCZOS_LOBES: u32 = 8;

/// Mitsuba's pixel filter where a film names none.
const MITSUBA_FILTER: PixelFilter = PixelFilter::Gaussian { stddev: 0.5 };

/// The float `name` of `p` (`default` without it), which must be positive and finite.
fn positive(p: &Props<'_>, name: &'static str, default: f32) -> Result<f32> {
    let v = p.float(name)?.unwrap_or(default);
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(p.err(format!("{name} {v} must be a positive number of pixels")))
    }
}

/// An `<rfilter>`: `box` (radius 0.5 only), `tent` (`radius`), `gaussian` (`stddev`),
/// `mitchell` (`B`, `C`), `catmullrom` or `lanczos` (`lobes`).
fn rfilter(o: &Rc<Object>) -> Result<PixelFilter> {
    let p = Props::new(o);
    let filter = match o.kind.as_str() {
        "box" => match p.float("radius")? {
            None | Some(0.5) => PixelFilter::Box,
            Some(r) => {
                return Err(p.err(format!(
                    "a box filter of radius {r}: zerovar's box filter is its pixel (radius \
                     0.5); remove the radius, or use a tent or gaussian filter"
                )));
            }
        },
        "tent" => PixelFilter::Tent { radius: positive(&p, "radius", 1.0)? },
        "gaussian" => PixelFilter::Gaussian { stddev: positive(&p, "stddev", 0.5)? },
        "mitchell" => {
            let (b, c) = (p.float("B")?.unwrap_or(1.0 / 3.0), p.float("C")?.unwrap_or(1.0 / 3.0));
            PixelFilter::Mitchell { b, c }
        }
        "catmullrom" => PixelFilter::Mitchell { b: 0.0, c: 0.5 },
        "lanczos" => {
            let lobes = p.integer("lobes")?.unwrap_or(3);
            match u32::try_from(lobes).ok().filter(|l| (1..=MAX_LANCZOS_LOBES).contains(l)) {
                Some(lobes) => PixelFilter::Lanczos { lobes },
                None => {
                    return Err(p.err(format!(
                        "lanczos lobes {lobes}: give 1 to {MAX_LANCZOS_LOBES} (the radius in \
                         pixels)"
                    )));
                }
            }
        }
        other => {
            return Err(p.err(format!(
                "the `{other}` pixel filter is not supported; use box, tent, gaussian, \
                 mitchell, catmullrom or lanczos"
            )));
        }
    };
    p.finish()?;
    Ok(filter)
}

/// A `<sampler>`: its sample count and seed. Mitsuba's samplers differ in how they place
/// their samples, not in the image they converge to, so zerovar draws independent samples
/// for each of them; the count is rounded as Mitsuba 3.9 rounds it for that sampler (up to a
/// square for `stratified`, to a `k x ceil(n / k)` grid with `k = floor(sqrt(n))` for
/// `multijitter`, to the square of a prime for `orthogonal`, to a power of 4 from 4 on for
/// `ldsampler`), so a scene's default budget is the sample count Mitsuba renders.
fn sampler(o: &Rc<Object>) -> Result<RenderDesc> {
    let p = Props::new(o);
    let round: fn(u32) -> Option<u32> = match o.kind.as_str() {
        "independent" => Some,
        "stratified" => |n| next_square(n, |_| true),
        "multijitter" => |n| {
            let k = n.isqrt();
            k.checked_mul(n.div_ceil(k))
        },
        "orthogonal" => |n| next_square(n, is_prime),
        "ldsampler" => |n| (1..16).map(|e| 4u32.pow(e)).find(|&p| p >= n),
        other => {
            return Err(p.err(format!(
                "the `{other}` sampler is not supported; use independent, stratified, \
                 multijitter, orthogonal or ldsampler"
            )));
        }
    };
    if matches!(o.kind.as_str(), "stratified" | "multijitter" | "orthogonal") {
        p.boolean("jitter")?;
    }
    if o.kind == "orthogonal" {
        p.float("strength")?;
    }
    let spp = p.integer("sample_count")?.unwrap_or(4);
    let seed = p.integer("seed")?.unwrap_or(0);
    p.finish()?;
    Ok(RenderDesc {
        spp: u32::try_from(spp)
            .ok()
            .filter(|s| *s > 0)
            .ok_or_else(|| p.err(format!("sample_count {spp} must be at least 1")))
            .and_then(|s| {
                round(s).filter(|r| *r <= MAX_SAMPLE_COUNT).ok_or_else(|| {
                    p.err(format!(
                        "sample_count {spp} rounds past {MAX_SAMPLE_COUNT} for the `{}` sampler",
                        o.kind
                    ))
                })
            })?,
        seed: u64::try_from(seed)
            .map_err(|_| p.err(format!("seed {seed} must be non-negative")))?,
        ..RenderDesc::default()
    })
}

/// The most samples per pixel a `<sampler>` may ask for once rounded.
const MAX_SAMPLE_COUNT: u32 = 1 << 30;

/// The smallest `k * k >= n` with `keep(k)`.
fn next_square(n: u32, keep: fn(u32) -> bool) -> Option<u32> {
    (1u32..=1 << 15).find(|&k| k * k >= n && keep(k)).map(|k| k * k)
}

fn is_prime(k: u32) -> bool {
    k >= 2 && (2..).take_while(|d| d * d <= k).all(|d| !k.is_multiple_of(d))
}

/// What an `<integrator>` says.
struct Integrator {
    /// `path` or `volpath` (after unwrapping `moment`; `volpathmis` is `volpath`).
    kind: &'static str,
    max_depth: i64,
    rr_depth: u32,
    hide_emitters: bool,
}

/// The integrator's kind, depths and `hide_emitters`.
fn integrator(o: &Rc<Object>) -> Result<Integrator> {
    let p = Props::new(o);
    let kind = match o.kind.as_str() {
        "moment" => {
            let inner = p.objects("integrator");
            p.finish()?;
            return match inner.as_slice() {
                [(_, i)] => integrator(i),
                _ => Err(p.err("a moment integrator wraps exactly one <integrator>")),
            };
        }
        // The differentiable ones estimate the same image as their plain twins.
        "path" | "prb" => "path",
        "volpath" | "volpathmis" | "prbvolpath" => "volpath",
        other => {
            return Err(
                p.err(format!("the `{other}` integrator is not supported; use {INTEGRATORS}"))
            );
        }
    };
    let max_depth = p.integer("max_depth")?.unwrap_or(-1);
    let rr_depth = p.integer("rr_depth")?.unwrap_or(5);
    let hide_emitters = p.boolean("hide_emitters")?.unwrap_or(false);
    p.finish()?;
    if !(-1..=i64::from(u32::MAX)).contains(&max_depth) {
        return Err(p.err(format!("max_depth {max_depth} must be -1 (unlimited) or a depth >= 0")));
    }
    let rr_depth = u32::try_from(rr_depth)
        .ok()
        .filter(|d| *d > 0)
        .ok_or_else(|| p.err(format!("rr_depth {rr_depth} must be at least 1")))?;
    Ok(Integrator { kind, max_depth, rr_depth, hide_emitters })
}
