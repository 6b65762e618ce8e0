//! Shapes with their BSDFs, textures, media and area emitters, and the other emitters, mapped
//! onto `ShapeDesc`, `BsdfDesc` and `LightDesc`. Mitsuba's defaults apply (diffuse 0.5, black on an emitting shape, unit
//! intensities and radiances, spot cutoff 20 degrees); plugins zerovar lacks are errors that
//! name them.

use super::props::{COLOR, Props, color};
use super::tree::{Object, Value};
use super::{Conv, Result, compose, spanned};
use crate::scene::desc::{
    BitmapDesc, BsdfDesc, CheckerboardDesc, EmitterDesc, LightDesc, Rgb, ShapeDesc, TextureDesc,
};
use glam::{Vec3, Vec3A};
use std::rc::Rc;
use toml::Spanned;

const SHAPES: &str = "sphere, cube, rectangle, disk, cylinder, obj, ply or serialized";
const BSDFS: &str = "null, diffuse, dielectric, thindielectric, plastic, conductor, \
                     roughdielectric, roughplastic, roughconductor, mask, or twosided around \
                     diffuse, plastic, conductor or their rough kinds";
const EMITTERS: &str = "point, spot, directional, constant, envmap, and area inside a <shape>";

pub(super) fn shape(conv: &mut Conv, o: &Rc<Object>) -> Result<Spanned<ShapeDesc>> {
    let p = Props::new(o);
    match o.kind.as_str() {
        "sphere" | "cube" | "rectangle" | "disk" | "cylinder" | "obj" | "ply" | "serialized" => {}
        other => return Err(p.err(format!("unknown shape `{other}`; use {SHAPES}"))),
    }
    let (center, radius) = match o.kind.as_str() {
        "sphere" => (p.vector("center")?, p.float("radius")?),
        "cylinder" => (None, p.float("radius")?),
        _ => (None, None),
    };
    let (p0, p1) =
        if o.kind == "cylinder" { (p.vector("p0")?, p.vector("p1")?) } else { (None, None) };
    let (mut filename, mut face_normals, mut flip_uv, mut shape_index) = (None, None, true, None);
    if ["obj", "ply", "serialized"].contains(&o.kind.as_str()) {
        let Some((name, prop)) = p.string("filename")? else {
            return Err(p.err("give the mesh as <string name=\"filename\" value=\"...\"/>"));
        };
        filename = Some(conv.file(name, prop)?);
        face_normals = p.boolean("face_normals")?;
        // Mitsuba's OBJ reader flips v by default, its PLY reader only when asked.
        if o.kind == "obj" || o.kind == "ply" {
            flip_uv = p.boolean("flip_tex_coords")?.unwrap_or(o.kind == "obj");
        }
        if o.kind == "serialized" {
            shape_index =
                match p.integer("shape_index")? {
                    None => None,
                    Some(i) => Some(u32::try_from(i).map_err(|_| {
                        p.err(format!("shape_index {i} must be a mesh number from 0"))
                    })?),
                };
        }
    }
    let transform = p.transform("to_world")?.unwrap_or(&[]).to_vec();
    let flip_normals = p.boolean("flip_normals")?.unwrap_or(false);
    let bsdf = p.object("bsdf")?.map(|b| bsdf(conv, b)).transpose()?;
    let (mut interior, mut exterior) = (None, None);
    for (prop, m) in p.objects("medium") {
        let slot = match prop.name.as_str() {
            "interior" => &mut interior,
            "exterior" => &mut exterior,
            other => {
                return Err(prop.pos.err(format!(
                    "a shape's medium is named \"interior\" or \"exterior\", not \"{other}\"; \
                     add name=\"interior\" or name=\"exterior\""
                )));
            }
        };
        *slot = Some(conv.medium(m)?);
    }
    let emitter = match p.object("emitter")? {
        None => None,
        Some(e) => {
            let ep = Props::new(e);
            if e.kind != "area" {
                return Err(
                    ep.err("a shape holds only an `area` emitter; put other emitters in <scene>")
                );
            }
            let radiance = ep.color("radiance")?.unwrap_or(Rgb::Grey(1.0));
            sampling_weight(conv, &ep)?;
            ep.finish()?;
            Some(EmitterDesc { radiance })
        }
    };
    p.finish()?;
    // Mitsuba gives an emitting shape without a <bsdf> a black diffuse one: the light's own
    // surface reflects nothing (any other shape gets the reflecting diffuse 0.5 default).
    let bsdf = match bsdf {
        None if emitter.is_some() => Some(BsdfDesc {
            kind: "diffuse".into(),
            reflectance: Some(TextureDesc::Constant(Rgb::Grey(0.0))),
            two_sided: None,
            ..Default::default()
        }),
        b => b,
    };
    let desc = ShapeDesc {
        kind: o.kind.clone(),
        center,
        radius,
        p0,
        p1,
        filename,
        face_normals,
        flip_tex_coords: (o.kind == "obj" || o.kind == "ply").then_some(flip_uv),
        shape_index,
        transform,
        flip_normals,
        bsdf,
        keeps_medium: interior.is_none() && exterior.is_none(),
        interior,
        exterior,
        emitter,
    };
    Ok(spanned(&o.pos, desc))
}

pub(super) fn bsdf(conv: &Conv, o: &Rc<Object>) -> Result<BsdfDesc> {
    let p = Props::new(o);
    let mut d = BsdfDesc { kind: o.kind.clone(), ..Default::default() };
    match o.kind.as_str() {
        "null" => {}
        "diffuse" => d.reflectance = texture_prop(conv, &p, "reflectance")?,
        "dielectric" | "thindielectric" => (d.int_ior, d.ext_ior) = iors(&p)?,
        "roughdielectric" => {
            (d.int_ior, d.ext_ior) = iors(&p)?;
            roughness(conv, &p, &mut d)?;
        }
        "conductor" | "roughconductor" => {
            d.material = p.string("material")?.map(|(s, _)| s.to_string());
            d.eta = p.color("eta")?;
            d.k = p.color("k")?;
            d.specular_reflectance = p.color("specular_reflectance")?;
            if o.kind == "roughconductor" {
                roughness(conv, &p, &mut d)?;
            }
        }
        "plastic" | "roughplastic" => {
            d.diffuse_reflectance = texture_prop(conv, &p, "diffuse_reflectance")?;
            d.specular_reflectance = p.color("specular_reflectance")?;
            (d.int_ior, d.ext_ior) = iors(&p)?;
            d.nonlinear = p.boolean("nonlinear")?;
            if o.kind == "roughplastic" {
                roughness(conv, &p, &mut d)?;
            }
        }
        "mask" => {
            let inner = p.objects("bsdf");
            d.opacity = texture_prop(conv, &p, "opacity")?;
            p.finish()?;
            let [(_, inner)] = inner.as_slice() else {
                return Err(p.err("mask wraps exactly one <bsdf>"));
            };
            d.nested = Some(Box::new(bsdf(conv, inner)?));
            return Ok(d);
        }
        "twosided" => {
            let inner = p.objects("bsdf");
            p.finish()?;
            let [(_, inner)] = inner.as_slice() else {
                return Err(p.err("twosided wraps exactly one <bsdf>"));
            };
            let sided = ["diffuse", "plastic", "roughplastic", "conductor", "roughconductor"];
            if !sided.contains(&inner.kind.as_str()) {
                return Err(p.err(format!(
                    "zerovar's two-sided surfaces are diffuse, plastic, conductor or their rough \
                     kinds, not `{}`",
                    inner.kind
                )));
            }
            return Ok(BsdfDesc { two_sided: Some(true), ..bsdf(conv, inner)? });
        }
        other => return Err(p.err(format!("unknown or unsupported bsdf `{other}`; use {BSDFS}"))),
    }
    p.finish()?;
    Ok(d)
}

/// A rough surface's `distribution` and `alpha` (or `alpha_u` and `alpha_v`), each a number
/// or a texture. `sample_visible` is accepted and has no effect: zerovar always samples
/// visible normals, which changes noise, not the image.
fn roughness(conv: &Conv, p: &Props<'_>, d: &mut BsdfDesc) -> Result<()> {
    d.distribution = p.string("distribution")?.map(|(s, _)| s.to_lowercase());
    d.alpha = texture_prop(conv, p, "alpha")?;
    d.alpha_u = texture_prop(conv, p, "alpha_u")?;
    d.alpha_v = texture_prop(conv, p, "alpha_v")?;
    p.boolean("sample_visible")?;
    Ok(())
}

/// A texture-valued property `name`: a number, a colour or a nested `<texture>`.
fn texture_prop(conv: &Conv, p: &Props<'_>, name: &'static str) -> Result<Option<TextureDesc>> {
    let Some(prop) = p.raw(name) else { return Ok(None) };
    Ok(Some(match &prop.value {
        Value::Object(t) if t.tag == "texture" => texture(conv, t)?,
        _ => TextureDesc::Constant(
            color(prop, &p.obj.tag)
                .ok_or_else(|| p.wrong(prop, &format!("{COLOR} or a <texture>")))?,
        ),
    }))
}

/// `int_ior` and `ext_ior`: numbers, or the names of Mitsuba's materials.
fn iors(p: &Props<'_>) -> Result<(Option<f32>, Option<f32>)> {
    let mut out = [None, None];
    for (name, slot) in ["int_ior", "ext_ior"].into_iter().zip(&mut out) {
        *slot = match p.raw(name) {
            None => None,
            Some(prop) => match &prop.value {
                Value::Float(v) => Some(*v as f32),
                Value::Integer(v) => Some(*v as f32),
                Value::String(material) => match named_ior(material) {
                    Some(ior) => Some(ior),
                    None => {
                        return Err(prop.pos.err(format!(
                            "{name} \"{material}\" is not one of Mitsuba's named materials ({}); \
                             give the index as a <float>",
                            NAMED_IORS.map(|(n, _)| n).join(", ")
                        )));
                    }
                },
                _ => return Err(p.wrong(prop, "a <float> or a material's name")),
            },
        };
    }
    Ok((out[0], out[1]))
}

/// A `<texture>`: the checkerboard, scaled by a `to_uv` transform.
pub(super) fn texture(conv: &Conv, o: &Rc<Object>) -> Result<TextureDesc> {
    let p = Props::new(o);
    if o.kind != "checkerboard" && o.kind != "bitmap" {
        return Err(p.err(format!(
            "the `{}` texture is not supported; zerovar has `checkerboard` and `bitmap`",
            o.kind
        )));
    }
    let scale = match p.transform("to_uv")? {
        None => None,
        Some(steps) => {
            let t = compose(steps, &o.pos, "to_uv")?;
            let (m, offset) = (t.m.matrix3, t.m.translation);
            if m.x_axis.y != 0.0 || m.y_axis.x != 0.0 || offset.x != 0.0 || offset.y != 0.0 {
                return Err(p.err(
                    "to_uv may only scale u and v (zerovar's textures have a scale, no rotation \
                     or offset)",
                ));
            }
            Some([m.x_axis.x, m.y_axis.y])
        }
    };
    let desc = if o.kind == "bitmap" {
        let Some((name, prop)) = p.string("filename")? else {
            return Err(p.err("give the image as <string name=\"filename\" value=\"...\"/>"));
        };
        TextureDesc::Bitmap(BitmapDesc {
            kind: "bitmap".into(),
            filename: conv.file(name, prop)?,
            filter_type: p.string("filter_type")?.map(|(s, _)| s.to_string()),
            wrap_mode: p.string("wrap_mode")?.map(|(s, _)| s.to_string()),
            raw: p.boolean("raw")?,
            scale,
        })
    } else {
        TextureDesc::Checkerboard(CheckerboardDesc {
            kind: "checkerboard".into(),
            color0: p.color("color0")?,
            color1: p.color("color1")?,
            scale,
        })
    };
    p.finish()?;
    Ok(desc)
}

/// An emitter outside shapes.
pub(super) fn light(conv: &Conv, o: &Rc<Object>) -> Result<Spanned<LightDesc>> {
    let p = Props::new(o);
    let mut d = LightDesc { kind: o.kind.clone(), ..Default::default() };
    let one = Some(Rgb::Grey(1.0));
    let to_world = |p: &Props<'_>| -> Result<Option<crate::transform::Transform>> {
        p.transform("to_world")?.map(|s| compose(s, &o.pos, "to_world")).transpose()
    };
    match o.kind.as_str() {
        "point" => {
            d.intensity = p.color("intensity")?.or(one);
            d.position = match (p.vector("position")?, to_world(&p)?) {
                (Some(_), Some(_)) => return Err(p.err("give position or to_world, not both")),
                (Some(v), None) => Some(v),
                (None, t) => Some(t.map_or(Vec3::ZERO, |t| t.point(Vec3A::ZERO).into())),
            };
        }
        "spot" => {
            d.intensity = p.color("intensity")?.or(one);
            d.cutoff_angle = p.float("cutoff_angle")?;
            d.beam_width = p.float("beam_width")?;
            let t = to_world(&p)?.unwrap_or_default();
            let position = t.point(Vec3A::ZERO);
            d.position = Some(position.into());
            d.target = Some((position + t.vector(Vec3A::Z)).into());
        }
        "directional" => {
            d.irradiance = p.color("irradiance")?.or(one);
            d.direction = match (p.vector("direction")?, to_world(&p)?) {
                (Some(_), Some(_)) => return Err(p.err("give direction or to_world, not both")),
                (Some(v), None) => Some(v),
                (None, t) => Some(t.unwrap_or_default().vector(Vec3A::Z).into()),
            };
        }
        "constant" => d.radiance = p.color("radiance")?.or(one),
        "envmap" => {
            let Some((name, prop)) = p.string("filename")? else {
                return Err(p.err("give the image as <string name=\"filename\" value=\"...\"/>"));
            };
            d.filename = Some(conv.file(name, prop)?);
            d.scale = p.float("scale")?;
            d.transform = p.transform("to_world")?.unwrap_or(&[]).to_vec();
        }
        "area" => {
            return Err(p.err("an area emitter belongs inside the <shape> that emits"));
        }
        other => {
            return Err(p.err(format!("unknown or unsupported emitter `{other}`; use {EMITTERS}")));
        }
    }
    sampling_weight(conv, &p)?;
    p.finish()?;
    Ok(spanned(&o.pos, d))
}

/// An emitter's `sampling_weight`, Mitsuba's share of next-event estimates for it. Weights
/// that are all equal change nothing in Mitsuba's image and are accepted (zerovar picks lights
/// by its own rule). Unequal ones change Mitsuba 3.9.1's image, not only its noise
/// (docs/experiments.md, 2026-12-07), which zerovar does not reproduce: they are an error.
fn sampling_weight(conv: &Conv, p: &Props<'_>) -> Result<()> {
    let given = p.float("sampling_weight")?;
    let pos = p.raw("sampling_weight").map(|prop| prop.pos.clone());
    let w = given.unwrap_or(1.0);
    if !(w > 0.0 && w.is_finite()) {
        return Err(p.err(format!("sampling_weight {w} must be a positive number")));
    }
    let mut first = conv.sampling_weight.borrow_mut();
    match &*first {
        None => *first = Some((w, pos)),
        Some((v, _)) if *v == w => {}
        Some((v, at)) => {
            let at = at.as_ref().map_or("no sampling_weight (1)".to_string(), |a| {
                format!("{v} at line {}", a.line)
            });
            let message = format!(
                "emitters' sampling_weight differ ({w} here, {at} on another): Mitsuba's image \
                 then changes with them, not only its noise, and zerovar does not reproduce \
                 that; give every emitter the same weight, or none"
            );
            return Err(match &pos {
                Some(a) => a.err(message),
                None => p.err(message),
            });
        }
    }
    Ok(())
}

/// Mitsuba's table of named indices of refraction (`int_ior="water"`), the values Mitsuba 3
/// uses.
const NAMED_IORS: [(&str, f32); 23] = [
    ("vacuum", 1.0),
    ("helium", 1.000_036),
    ("hydrogen", 1.000_132),
    ("air", 1.000_277),
    ("carbon dioxide", 1.000_45),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.520_45),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.47),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// The index of refraction of one of Mitsuba's named materials (any case).
fn named_ior(name: &str) -> Option<f32> {
    let name = name.trim().to_lowercase();
    NAMED_IORS.iter().find(|(n, _)| *n == name).map(|&(_, v)| v)
}
