//! Participating media, their volumes and phase functions, mapped onto `MediumDesc`.
//!
//! `homogeneous` takes `sigma_t` and `albedo` or `sigma_a` and `sigma_s`. `heterogeneous`
//! becomes a grid medium: its extinction volume (a `gridvolume` `.vol` file, or a constant,
//! filling the unit cube placed by the volume's `to_world`, empty outside it as in Mitsuba)
//! gives the density and the box, a constant extinction becomes the grid's tint, and an albedo
//! grid must share the extinction's box. Mitsuba's defaults: sigma_t 1, albedo 0.75, hg g 0.8.
//! As a zerovar extension, a `gridvolume` filename may name an OpenVDB `.vdb` file (with an
//! optional `<string name="grid_name">`); its own index-to-world map places it, and the
//! volume's `to_world` then moves it, as for `.vdb` densities in TOML scenes.

use super::props::{COLOR, Props, color};
use super::tree::{Object, Value};
use super::{Conv, Result, compose, spanned};
use crate::scene::build::is_vdb;
use crate::scene::desc::{AlbedoDesc, DensityDesc, MediumDesc, PhaseDesc, Rgb, TransformStep};
use std::rc::Rc;

/// A medium property that may be a volume.
enum Volume {
    /// A constant, with the box it fills.
    Constant(Rgb, Vec<TransformStep>),
    /// A `.vol` or `.vdb` file (relative to the scene file), its box and (`.vdb`) grid name.
    Grid(String, Vec<TransformStep>, Option<String>),
}

impl Conv {
    /// The name of the medium `o` in the description, adding it on first use.
    pub(super) fn medium(&mut self, o: &Rc<Object>) -> Result<String> {
        if let Some(name) = self.medium_names.get(&Rc::as_ptr(o)) {
            return Ok(name.clone());
        }
        let mut name = match &o.id {
            Some(id) => id.clone(),
            None => format!(
                "{}:{}:{}",
                o.pos.path.file_name().unwrap_or_default().to_string_lossy(),
                o.pos.line,
                o.pos.column
            ),
        };
        // Two files of the same name in different directories, or an id that looks like a
        // place, must not make two media share a name (the second would replace the first).
        let base = name.clone();
        for n in 2.. {
            if !self.media.contains_key(&name) {
                break;
            }
            name = format!("{base}#{n}");
        }
        let desc = self.medium_desc(o)?;
        self.media.insert(name.clone(), spanned(&o.pos, desc));
        self.medium_names.insert(Rc::as_ptr(o), name.clone());
        Ok(name)
    }

    fn medium_desc(&self, o: &Rc<Object>) -> Result<MediumDesc> {
        let p = Props::new(o);
        let mut d = MediumDesc::default();
        match o.kind.as_str() {
            "homogeneous" => {
                d.kind = "homogeneous".into();
                // Mitsuba allows a spatially varying albedo here; a constant volume is a colour.
                if let Some(prop) = p.raw("albedo")
                    && matches!(&prop.value, Value::Object(o) if o.kind == "gridvolume")
                {
                    return Err(p.wrong(
                        prop,
                        "a colour or a constvolume in a homogeneous medium (for an albedo grid, \
                         use a heterogeneous medium)",
                    ));
                }
                let a = match self.volume(&p, "albedo")? {
                    None => None,
                    Some(Volume::Constant(c, _)) => Some(c),
                    Some(Volume::Grid(..)) => {
                        return Err(p.err("an albedo grid needs a heterogeneous medium"));
                    }
                };
                let t = p.color("sigma_t")?;
                match (t, a, p.color("sigma_a")?, p.color("sigma_s")?) {
                    (t, a, None, None) => {
                        d.sigma_t = t;
                        d.albedo = a.map(AlbedoDesc::Constant);
                    }
                    (None, None, Some(a), Some(s)) => {
                        let (a, s) = (a.channels(), s.channels());
                        let t: [f32; 3] = std::array::from_fn(|i| a[i] + s[i]);
                        let albedo =
                            std::array::from_fn(|i| if t[i] > 0.0 { s[i] / t[i] } else { 0.0 });
                        d.sigma_t = Some(Rgb::Rgb(t));
                        d.albedo = Some(AlbedoDesc::Constant(Rgb::Rgb(albedo)));
                    }
                    _ => {
                        return Err(p.err(
                            "give sigma_t and albedo, or both sigma_a and sigma_s, not a mixture",
                        ));
                    }
                }
            }
            "heterogeneous" => {
                d.kind = "grid".into();
                let (density, tint, transform) = match self.volume(&p, "sigma_t")? {
                    None => (DensityDesc::Constant(1.0), None, Vec::new()),
                    Some(Volume::Constant(c, t)) => (DensityDesc::Constant(1.0), Some(c), t),
                    Some(Volume::Grid(f, t, grid_name)) => {
                        d.grid_name = grid_name;
                        (DensityDesc::File(f), None, t)
                    }
                };
                d.albedo = match self.volume(&p, "albedo")? {
                    None => None,
                    Some(Volume::Constant(c, _)) => Some(AlbedoDesc::Constant(c)),
                    Some(Volume::Grid(f, t, _)) => {
                        let same = compose(&t, &o.pos, "albedo to_world")?
                            .m
                            .abs_diff_eq(compose(&transform, &o.pos, "sigma_t to_world")?.m, 1e-6);
                        if !same {
                            return Err(p.err(
                                "the albedo grid must fill the same box as sigma_t; give both \
                                 volumes the same to_world",
                            ));
                        }
                        Some(AlbedoDesc::File(f))
                    }
                };
                (d.density, d.sigma_t, d.transform) = (Some(density), tint, transform);
            }
            other => {
                return Err(p.err(format!(
                    "unknown or unsupported medium `{other}`; use homogeneous or heterogeneous"
                )));
            }
        }
        d.scale = p.float("scale")?;
        d.phase = p.object("phase")?.map(phase).transpose()?;
        // Sampling choices that leave the expected image alone: zerovar makes its own.
        p.boolean("sample_emitters")?;
        // Mitsuba's promise that the extinction is grey, which lets it skip spectral MIS; a
        // chromatic extinction under it renders wrongly there, so that is refused.
        if p.boolean("has_spectral_extinction")? == Some(false)
            && matches!(d.sigma_t, Some(Rgb::Rgb([r, g, b])) if r != g || g != b)
        {
            return Err(p.err(
                "has_spectral_extinction is false but sigma_t differs between channels; remove \
                 it or set it to true",
            ));
        }
        if d.kind == "grid" {
            p.integer("majorant_resolution_factor")?;
            p.float("majorant_factor")?;
        }
        p.finish()?;
        Ok(d)
    }

    /// A colour or a nested `<volume>`.
    fn volume(&self, p: &Props<'_>, name: &'static str) -> Result<Option<Volume>> {
        let Some(prop) = p.raw(name) else { return Ok(None) };
        let Value::Object(o) = &prop.value else {
            let c = color(prop, &p.obj.tag)
                .ok_or_else(|| p.wrong(prop, &format!("{COLOR} or a <volume>")))?;
            return Ok(Some(Volume::Constant(c, Vec::new())));
        };
        let v = Props::new(o);
        if o.tag != "volume" {
            return Err(p.wrong(prop, &format!("{COLOR} or a <volume>")));
        }
        let transform = v.transform("to_world")?.unwrap_or(&[]).to_vec();
        let volume = match o.kind.as_str() {
            "constvolume" => {
                Volume::Constant(v.color("value")?.unwrap_or(Rgb::Grey(1.0)), transform)
            }
            "gridvolume" => {
                let Some((file, fprop)) = v.string("filename")? else {
                    return Err(v.err("give the grid as <string name=\"filename\" value=\"...\"/>"));
                };
                let file = self.file(file, fprop)?;
                for (option, allowed) in [("filter_type", "trilinear"), ("wrap_mode", "clamp")] {
                    if let Some((value, at)) = v.string(option)?
                        && value != allowed
                    {
                        return Err(at.pos.err(format!(
                            "{option} \"{value}\" is not supported; zerovar's grids are {allowed}"
                        )));
                    }
                }
                // Options that change nothing in Mitsuba's RGB variants (`raw`, `accel`), and a
                // majorant hint (`max_value`): zerovar bounds its grids itself.
                v.boolean("raw")?;
                v.boolean("accel")?;
                v.float("max_value")?;
                let mut transform = transform;
                if let Some(at) = v.raw("use_grid_bbox")
                    && v.boolean("use_grid_bbox")? == Some(true)
                {
                    // The grid fills the box its .vol header gives, which to_world then moves.
                    if is_vdb(&file) {
                        return Err(at.pos.err(
                            "use_grid_bbox applies to .vol files; a .vdb grid is placed by its own \
                             index-to-world map",
                        ));
                    }
                    let [lo, hi] = crate::media::VolGrid::read_bounds(&self.root_dir.join(&file))
                        .map_err(|e| at.pos.err(e.to_string()))?;
                    let mut steps = vec![
                        TransformStep::Scale(Rgb::Rgb((hi - lo).to_array())),
                        TransformStep::Translate(lo),
                    ];
                    steps.append(&mut transform);
                    transform = steps;
                }
                // A zerovar extension: Mitsuba reads only .vol files here.
                let grid_name = match v.string("grid_name")? {
                    Some((_, at)) if !is_vdb(&file) => {
                        return Err(at.pos.err("grid_name applies only to a .vdb filename"));
                    }
                    g => g.map(|(name, _)| name.to_string()),
                };
                Volume::Grid(file, transform, grid_name)
            }
            other => {
                return Err(
                    v.err(format!("unknown volume `{other}`; use constvolume or gridvolume"))
                );
            }
        };
        v.finish()?;
        Ok(Some(volume))
    }
}

fn phase(o: &Rc<Object>) -> Result<PhaseDesc> {
    let p = Props::new(o);
    let mut d = PhaseDesc { kind: o.kind.clone(), ..PhaseDesc::default() };
    match o.kind.as_str() {
        "isotropic" | "rayleigh" => {}
        "hg" => d.g = Some(p.float("g")?.unwrap_or(0.8)),
        "blendphase" => {
            d.weight = Some(p.float("weight")?.unwrap_or(0.5));
            // As written, whatever their names: what Mitsuba 3.9 renders (its documentation
            // says by name; docs/experiments.md).
            let nested = p.objects("phase");
            if nested.len() != 2 {
                return Err(p.err(format!(
                    "a blendphase blends exactly two <phase> elements, not {}",
                    nested.len()
                )));
            }
            d.phases = Some(nested.iter().map(|(_, o)| phase(o)).collect::<Result<_>>()?);
        }
        other => {
            return Err(p.err(format!(
                "unknown phase function `{other}`; use isotropic, hg, rayleigh or blendphase"
            )));
        }
    }
    p.finish()?;
    Ok(d)
}
