//! Surface scattering: index-matched null boundaries, Lambertian diffuse, smooth dielectric,
//! Mitsuba's thin dielectric (a slab of negligible thickness: specular reflection, or
//! transmission straight through), Mitsuba's smooth plastic (a diffuse base under a smooth
//! dielectric coating: a specular lobe and a diffuse one, each weighted by Fresnel), the
//! rough dielectric and rough plastic of `rough` over the distributions of `microfacet`, and
//! the smooth and rough metals of `conductor`.
//!
//! Directions are in the local shading frame (z = shading normal on the shape's front side) and
//! both point away from the surface: `wo` towards where the path came from, `wi` where it goes.
//! Like Mitsuba 3, the diffuse BSDF is one-sided (black seen from the back) unless
//! `two_sided`, and the dielectric scales transported radiance by 1/eta^2 when refracting.
//! Reflectances are textures: a constant, Mitsuba's checkerboard, or an image (`bitmap`).

mod bitmap;
mod conductor;
mod conductors;
mod microfacet;
mod rough;
#[cfg(test)]
mod testing;

pub use bitmap::{Bitmap, Wrap, srgb_to_linear};
pub use conductor::{Conductor, Metal, RoughConductor};
pub use microfacet::{MIN_ALPHA, Microfacet, MicrofacetKind, Roughness};
pub use rough::{RoughDielectric, RoughPlastic};

use crate::math::{Spectrum, cosine_hemisphere};
use glam::{Vec2, Vec3A};
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

/// A reflectance that may vary over the surface.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// The same value everywhere.
    Constant(Spectrum),
    /// Mitsuba's checkerboard in uv space.
    Checkerboard {
        /// Value where the u and v halves agree.
        color0: Spectrum,
        /// Value elsewhere.
        color1: Spectrum,
        /// Checks per unit of uv (Mitsuba's `to_uv` scale).
        scale: Vec2,
    },
    /// Mitsuba's bitmap: an image.
    Bitmap(Arc<Bitmap>),
}

impl Texture {
    /// The mean over the surface, per channel (a checkerboard's two colours in equal parts).
    pub fn mean(&self) -> Spectrum {
        match *self {
            Texture::Constant(c) => c,
            Texture::Checkerboard { color0, color1, .. } => 0.5 * (color0 + color1),
            Texture::Bitmap(ref b) => b.mean(),
        }
    }

    /// The value at `uv` as one number, as Mitsuba's `eval_1` reads a texture given for a
    /// roughness or an opacity: the luminance, with (Mitsuba's own convention there) a
    /// checkerboard's two values the other way round from [`Self::eval`].
    #[inline]
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        match *self {
            Texture::Constant(c) => luminance_1(c),
            Texture::Checkerboard { color0, color1, scale } => {
                let p = (uv * scale).fract_gl();
                luminance_1(if (p.x > 0.5) == (p.y > 0.5) { color1 } else { color0 })
            }
            Texture::Bitmap(ref b) => luminance_1(b.eval(uv)),
        }
    }

    /// The least and the greatest value [`Self::eval_1`] takes anywhere.
    pub fn range_1(&self) -> (f32, f32) {
        match *self {
            Texture::Constant(c) => (luminance_1(c), luminance_1(c)),
            Texture::Checkerboard { color0, color1, .. } => {
                let (a, b) = (luminance_1(color0), luminance_1(color1));
                (a.min(b), a.max(b))
            }
            // Bilinear weights are convex: lookups stay within the texels' range.
            Texture::Bitmap(ref b) => b.range_1(),
        }
    }

    /// The value at texture coordinates `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Spectrum {
        match *self {
            Texture::Constant(c) => c,
            Texture::Checkerboard { color0, color1, scale } => {
                let p = (uv * scale).fract_gl();
                if (p.x > 0.5) == (p.y > 0.5) { color0 } else { color1 }
            }
            Texture::Bitmap(ref b) => b.eval(uv),
        }
    }
}

/// A colour as one number: the value itself where the channels agree (so that a number given
/// for a roughness is used exactly), else the luminance.
#[inline]
fn luminance_1(c: Spectrum) -> f32 {
    if c.x == c.y && c.y == c.z { c.x } else { crate::math::luminance(c) }
}

/// A surface's scattering model.
// Rough plastic carries its coating's table inline: a scene has few surfaces, and the walk
// borrows them rather than copying.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum Bsdf {
    /// No surface at all: a boundary between media that light passes straight through.
    Null,
    /// Lambertian reflection.
    Diffuse {
        /// Albedo of the surface.
        reflectance: Texture,
        /// Whether the back side reflects too.
        two_sided: bool,
    },
    /// A smooth boundary between two indices of refraction.
    Dielectric {
        /// Interior over exterior index of refraction.
        eta: f32,
    },
    /// A thin slab of dielectric, such as a window pane: light reflects specularly or passes
    /// through without changing direction, with the slab's internal reflections summed.
    ThinDielectric {
        /// Slab over surrounding index of refraction.
        eta: f32,
    },
    /// Mitsuba's `plastic`: a smooth dielectric coating over a diffuse base, one-sided.
    Plastic(Plastic),
    /// Mitsuba's `roughdielectric`: a rough boundary between two indices of refraction.
    RoughDielectric(RoughDielectric),
    /// Mitsuba's `roughplastic`: a rough dielectric coating over a diffuse base.
    RoughPlastic(RoughPlastic),
    /// Mitsuba's `conductor`: a metal mirror.
    Conductor(Conductor),
    /// Mitsuba's `roughconductor`: a rough metal.
    RoughConductor(RoughConductor),
    /// Mitsuba's `mask`: the nested BSDF with probability `opacity`, else nothing (light
    /// passes straight through, as through a null surface: see [`Bsdf::null_transmission`]).
    /// Where the path scatters, it has already been decided that it does, so the nested
    /// BSDF's own values and densities apply there.
    Mask {
        /// The share of light that meets the nested BSDF, read as one number
        /// ([`Texture::eval_1`]).
        opacity: Texture,
        /// What it meets.
        nested: Box<Bsdf>,
    },
}

/// The parameters of [`Bsdf::Plastic`], with what it precomputes from them.
#[derive(Clone, Debug, PartialEq)]
pub struct Plastic {
    /// The base's albedo.
    pub diffuse: Texture,
    /// A factor on the coating's specular reflection.
    pub specular: Spectrum,
    /// Coating over outside index of refraction.
    pub eta: f32,
    /// Mitsuba's `nonlinear`: the internal reflections at the coating tint the base's colour.
    pub nonlinear: bool,
    /// Whether the back side is the same plastic (Mitsuba's `twosided`), not black.
    pub two_sided: bool,
    /// The coating's reflectance of diffuse light from inside.
    fdr_int: f32,
    /// How strongly the specular lobe is sampled against the diffuse one.
    specular_weight: f32,
}

impl Plastic {
    /// A plastic with Mitsuba's derived constants.
    pub fn new(diffuse: Texture, specular: Spectrum, eta: f32, nonlinear: bool) -> Self {
        let specular_weight = specular_sampling_weight(&diffuse, specular);
        let fdr_int = fresnel_diffuse_reflectance(1.0 / eta);
        Self { diffuse, specular, eta, nonlinear, two_sided: false, fdr_int, specular_weight }
    }

    /// The same plastic on both sides, or only on the front.
    pub fn with_two_sided(self, two_sided: bool) -> Self {
        Self { two_sided, ..self }
    }

    /// The directions `wo`, `wi` as the front side sees them.
    fn front(&self, wo: Vec3A, wi: Vec3A) -> (Vec3A, Vec3A, bool) {
        front_side(self.two_sided, wo, wi)
    }

    /// The probability of sampling the specular lobe for `cos_o` (Fresnel times its weight).
    fn specular_probability(&self, f_o: f32) -> f32 {
        specular_share(f_o, 1.0 - f_o, self.specular_weight)
    }

    /// The diffuse lobe's BSDF (without the cosine) for Fresnel terms `f_o` and `f_i`.
    fn diffuse_value(&self, uv: Vec2, f_o: f32, f_i: f32) -> Spectrum {
        let base = under_coating(self.diffuse.eval(uv), self.fdr_int, self.nonlinear);
        base * ((1.0 - f_o) * (1.0 - f_i) / (self.eta * self.eta) * FRAC_1_PI)
    }
}

/// `v` mirrored through the surface plane.
fn mirror(v: Vec3A) -> Vec3A {
    Vec3A::new(v.x, v.y, -v.z)
}

/// `wo` and `wi` as the front of a surface sees them, and whether they were mirrored: a
/// two-sided surface seen from behind behaves as its front.
fn front_side(two_sided: bool, wo: Vec3A, wi: Vec3A) -> (Vec3A, Vec3A, bool) {
    if two_sided && wo.z < 0.0 { (mirror(wo), mirror(wi), true) } else { (wo, wi, false) }
}

/// A sample drawn on the front side, mirrored back where the front was a mirror image.
fn from_front(bs: BsdfSample, flipped: bool) -> BsdfSample {
    BsdfSample { wi: if flipped { mirror(bs.wi) } else { bs.wi }, ..bs }
}

/// How strongly a coated surface samples its specular lobe against its base, as Mitsuba
/// weighs them: the mean specular factor over the sum of it and the base's mean albedo.
fn specular_sampling_weight(diffuse: &Texture, specular: Spectrum) -> f32 {
    let (d, s) = (channel_mean(diffuse.mean()), channel_mean(specular));
    if d + s > 0.0 { s / (d + s) } else { 0.5 }
}

/// The probability of the specular lobe, given the coating's reflected and transmitted shares
/// at the incoming angle and the sampling weight.
fn specular_share(reflected: f32, transmitted: f32, weight: f32) -> f32 {
    let spec = reflected * weight;
    let diff = transmitted * (1.0 - weight);
    if spec + diff > 0.0 { spec / (spec + diff) } else { 0.0 }
}

/// A base of albedo `d` under a coating that reflects `internal` of the diffuse light inside
/// back down: brightened by 1 / (1 - internal), or tinted, 1 / (1 - d internal), if `nonlinear`.
fn under_coating(d: Spectrum, internal: f32, nonlinear: bool) -> Spectrum {
    let inner =
        if nonlinear { Spectrum::ONE - d * internal } else { Spectrum::splat(1.0 - internal) };
    d / inner
}

/// The mean of the three channels.
fn channel_mean(c: Spectrum) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// The share of diffuse light a smooth boundary of relative index `eta` reflects: the fit of
/// Egan and Hilgeman (1973) below 1, of d'Eon and Irving (2011) above, as Mitsuba computes it.
fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    if eta < 1.0 {
        -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta
    } else {
        let x = 1.0 / eta;
        let c = [0.919317, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881];
        c.iter().rev().fold(0.0, |acc, &k| acc * x + k)
    }
}

/// A sampled continuation direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// The new direction, local frame.
    pub wi: Vec3A,
    /// BSDF times cosine over pdf.
    pub weight: Spectrum,
    /// Density (meaningless when `delta`).
    pub pdf: f32,
    /// Whether the direction was chosen from a discrete set (no MIS, no light sampling).
    pub delta: bool,
    /// Relative index of refraction crossed (1 for reflection), for Russian roulette.
    pub eta: f32,
}

impl Bsdf {
    /// The share of light that passes straight through the surface at `cos` (a ray's cosine
    /// with the normal, either side), as Mitsuba's null component: 1 for a null surface,
    /// `1 - R'` for a thin dielectric, `None` for a surface nothing passes straight through.
    /// Paths and shadow rays cross it as they cross a null surface, without a scattering
    /// event (Mitsuba neither counts its depth nor blocks next-event estimation there).
    /// A textured mask's share is read at texture coordinates `uv`.
    #[inline]
    pub fn null_transmission(&self, cos: f32, uv: Vec2) -> Option<f32> {
        match *self {
            Bsdf::Null => Some(1.0),
            Bsdf::ThinDielectric { eta } => Some(1.0 - thin_reflectance(cos, eta)),
            Bsdf::Mask { ref opacity, .. } => Some(1.0 - opacity.eval_1(uv)),
            _ => None,
        }
    }

    /// Whether light passes straight through anywhere on the surface (a null surface, a thin
    /// dielectric or a mask), so that a shadow ray must look at the crossing.
    #[inline]
    pub fn may_pass(&self) -> bool {
        matches!(self, Bsdf::Null | Bsdf::ThinDielectric { .. } | Bsdf::Mask { .. })
    }

    /// Whether the share passing depends on where the surface is hit (a textured mask).
    #[inline]
    pub fn passes_by_texture(&self) -> bool {
        matches!(self, Bsdf::Mask { opacity, .. } if !matches!(opacity, Texture::Constant(_)))
    }

    /// Whether the BSDF depends on the direction of the tangent about the normal (a brushed
    /// rough surface), so that its frame must follow the surface's parameterization.
    pub fn is_anisotropic(&self) -> bool {
        match self {
            Bsdf::RoughConductor(r) => r.roughness.is_anisotropic(),
            Bsdf::RoughDielectric(r) => r.roughness.is_anisotropic(),
            Bsdf::Mask { nested, .. } => nested.is_anisotropic(),
            _ => false,
        }
    }

    /// Whether next-event estimation can help at this surface.
    pub fn has_smooth_component(&self) -> bool {
        if let Bsdf::Mask { nested, .. } = self {
            return nested.has_smooth_component();
        }
        matches!(
            self,
            Bsdf::Diffuse { .. }
                | Bsdf::Plastic(_)
                | Bsdf::RoughDielectric(_)
                | Bsdf::RoughPlastic(_)
                | Bsdf::RoughConductor(_)
        )
    }

    /// Whether a guiding field of incident radiance helps at this surface, choosing directions
    /// and deciding roulette and splitting: where the BSDF has a diffuse part, and at rough
    /// metal, where guiding paid at every roughness measured, narrow lobes included (the
    /// mixture keeps the BSDF's own share). Not at rough glass, where it lost
    /// (docs/experiments.md, 2026-12-07).
    pub fn guides(&self) -> bool {
        if let Bsdf::Mask { nested, .. } = self {
            return nested.guides();
        }
        matches!(
            self,
            Bsdf::Diffuse { .. }
                | Bsdf::Plastic(_)
                | Bsdf::RoughPlastic(_)
                | Bsdf::RoughConductor(_)
        )
    }

    /// BSDF times |cos wi| for a pair of local directions.
    #[inline]
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> Spectrum {
        match *self {
            Bsdf::Diffuse { ref reflectance, two_sided } => {
                let (wo_z, wi_z) =
                    if two_sided && wo.z < 0.0 { (-wo.z, -wi.z) } else { (wo.z, wi.z) };
                if wo_z <= 0.0 || wi_z <= 0.0 {
                    return Spectrum::ZERO;
                }
                reflectance.eval(uv) * (FRAC_1_PI * wi_z)
            }
            Bsdf::Plastic(ref p) => {
                let (wo, wi, _) = p.front(wo, wi);
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return Spectrum::ZERO;
                }
                let (f_o, f_i) = (fresnel(wo.z, p.eta).0, fresnel(wi.z, p.eta).0);
                p.diffuse_value(uv, f_o, f_i) * wi.z
            }
            Bsdf::RoughDielectric(ref r) => Spectrum::splat(r.eval(wo, wi, uv)),
            Bsdf::RoughConductor(ref r) => r.eval(wo, wi, uv),
            Bsdf::Mask { ref nested, .. } => nested.eval(wo, wi, uv),
            Bsdf::RoughPlastic(ref p) => {
                let (wo, wi, _) = p.front(wo, wi);
                p.eval(wo, wi, uv)
            }
            _ => Spectrum::ZERO,
        }
    }

    /// Density of sampling `wi` at texture coordinates `uv` (zero for delta components).
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> f32 {
        match *self {
            Bsdf::Diffuse { two_sided, .. } => {
                let (wo_z, wi_z) =
                    if two_sided && wo.z < 0.0 { (-wo.z, -wi.z) } else { (wo.z, wi.z) };
                if wo_z <= 0.0 || wi_z <= 0.0 { 0.0 } else { FRAC_1_PI * wi_z }
            }
            Bsdf::Plastic(ref p) => {
                let (wo, wi, _) = p.front(wo, wi);
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return 0.0;
                }
                (1.0 - p.specular_probability(fresnel(wo.z, p.eta).0)) * FRAC_1_PI * wi.z
            }
            Bsdf::RoughDielectric(ref r) => r.pdf(wo, wi, uv),
            Bsdf::RoughConductor(ref r) => r.pdf(wo, wi, uv),
            Bsdf::Mask { ref nested, .. } => nested.pdf(wo, wi, uv),
            Bsdf::RoughPlastic(ref p) => {
                let (wo, wi, _) = p.front(wo, wi);
                p.pdf(wo, wi)
            }
            _ => 0.0,
        }
    }

    /// Samples a continuation; `None` when the surface absorbs the path.
    pub fn sample(&self, wo: Vec3A, uv: Vec2, u1: f32, u2: Vec2) -> Option<BsdfSample> {
        match *self {
            Bsdf::Null => {
                Some(BsdfSample { wi: -wo, weight: Spectrum::ONE, pdf: 1.0, delta: true, eta: 1.0 })
            }
            Bsdf::Diffuse { ref reflectance, two_sided } => {
                let side = if two_sided && wo.z < 0.0 { -1.0 } else { 1.0 };
                if wo.z * side <= 0.0 {
                    return None;
                }
                let mut wi = cosine_hemisphere(u2);
                wi.z *= side;
                let pdf = FRAC_1_PI * wi.z.abs();
                (pdf > 0.0).then(|| BsdfSample {
                    wi,
                    weight: reflectance.eval(uv),
                    pdf,
                    delta: false,
                    eta: 1.0,
                })
            }
            Bsdf::Dielectric { eta } => sample_dielectric(eta, wo, u1),
            Bsdf::ThinDielectric { eta } => Some(sample_thin_dielectric(eta, wo, u1)),
            Bsdf::Plastic(ref p) => {
                let (wo, _, flipped) = p.front(wo, wo);
                Some(from_front(sample_plastic(p, wo, uv, u1, u2)?, flipped))
            }
            Bsdf::RoughDielectric(ref r) => r.sample(wo, uv, u1, u2),
            Bsdf::Conductor(c) => c.sample(wo),
            Bsdf::RoughConductor(ref r) => r.sample(wo, uv, u2),
            Bsdf::Mask { ref nested, .. } => nested.sample(wo, uv, u1, u2),
            Bsdf::RoughPlastic(ref p) => {
                let (wo, _, flipped) = p.front(wo, wo);
                Some(from_front(p.sample(wo, uv, u1, u2)?, flipped))
            }
        }
    }
}

/// Mitsuba's plastic: the specular lobe with probability `specular_probability`, else the
/// diffuse one by cosine sampling; the weight is the chosen lobe's value over its probability.
fn sample_plastic(p: &Plastic, wo: Vec3A, uv: Vec2, u1: f32, u2: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let f_o = fresnel(wo.z, p.eta).0;
    let specular = p.specular_probability(f_o);
    if u1 < specular {
        let wi = Vec3A::new(-wo.x, -wo.y, wo.z);
        let weight = p.specular * (f_o / specular);
        return Some(BsdfSample { wi, weight, pdf: specular, delta: true, eta: 1.0 });
    }
    let wi = cosine_hemisphere(u2);
    let pdf = (1.0 - specular) * FRAC_1_PI * wi.z;
    if pdf.is_nan() || pdf <= 0.0 {
        return None;
    }
    let f_i = fresnel(wi.z, p.eta).0;
    let weight = p.diffuse_value(uv, f_o, f_i) * (wi.z / pdf);
    Some(BsdfSample { wi, weight, pdf, delta: false, eta: 1.0 })
}

/// Fresnel reflectance of an unpolarised wave; returns (F, cos_t, eta_it) where `cos_t` is the
/// signed cosine of the refracted direction (opposite side to `cos_i`).
fn fresnel(cos_i: f32, eta: f32) -> (f32, f32, f32) {
    let eta_it = if cos_i >= 0.0 { eta } else { 1.0 / eta };
    let cos_i_abs = cos_i.abs();
    let sin2_t = (1.0 - cos_i_abs * cos_i_abs).max(0.0) / (eta_it * eta_it);
    if sin2_t >= 1.0 {
        return (1.0, 0.0, eta_it);
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i_abs - eta_it * cos_t) / (cos_i_abs + eta_it * cos_t);
    let rp = (eta_it * cos_i_abs - cos_t) / (eta_it * cos_i_abs + cos_t);
    let f = 0.5 * (rs * rs + rp * rp);
    (f, if cos_i >= 0.0 { -cos_t } else { cos_t }, eta_it)
}

/// `v` refracted through a boundary of normal `m`, with the signed cosine `cos_t` and relative
/// index `eta_it` that [`fresnel`] returned for `v . m`.
fn refract(v: Vec3A, m: Vec3A, cos_t: f32, eta_it: f32) -> Vec3A {
    (m * (v.dot(m) / eta_it + cos_t) - v / eta_it).normalize()
}

fn sample_dielectric(eta: f32, wo: Vec3A, u: f32) -> Option<BsdfSample> {
    let (f, cos_t, eta_it) = fresnel(wo.z, eta);
    if u < f {
        let wi = Vec3A::new(-wo.x, -wo.y, wo.z);
        return Some(BsdfSample { wi, weight: Spectrum::ONE, pdf: f, delta: true, eta: 1.0 });
    }
    let wi = Vec3A::new(-wo.x / eta_it, -wo.y / eta_it, cos_t).normalize();
    // Radiance is compressed into a smaller solid angle when entering the denser side.
    let scale = 1.0 / (eta_it * eta_it);
    Some(BsdfSample { wi, weight: Spectrum::splat(scale), pdf: 1.0 - f, delta: true, eta: eta_it })
}

/// Reflectance of a thin slab: light that enters bounces between the two faces, so of the
/// Fresnel reflectance R at each face the slab reflects R + T^2 R (1 + R^2 + R^4 + ...) =
/// R + T^2 R / (1 - R^2) with T = 1 - R, which simplifies to 2R / (1 + R); it transmits the
/// rest. Both faces see the same angle, so the side the light comes from does not matter.
fn thin_reflectance(cos_i: f32, eta: f32) -> f32 {
    let r = fresnel(cos_i.abs(), eta).0;
    2.0 * r / (1.0 + r)
}

/// As Mitsuba's `thindielectric`: reflect with probability R', else pass straight through, and
/// either way weight 1 (the choice's probability cancels the lobe's) and no change of index.
fn sample_thin_dielectric(eta: f32, wo: Vec3A, u: f32) -> BsdfSample {
    let r = thin_reflectance(wo.z, eta);
    let (wi, pdf) = if u < r { (Vec3A::new(-wo.x, -wo.y, wo.z), r) } else { (-wo, 1.0 - r) };
    BsdfSample { wi, weight: Spectrum::ONE, pdf, delta: true, eta: 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;

    #[test]
    fn diffuse_reflects_its_albedo_and_is_one_sided() {
        let b = Bsdf::Diffuse {
            reflectance: Texture::Constant(Spectrum::splat(0.7)),
            two_sided: false,
        };
        let wo = Vec3A::new(0.3, 0.1, 0.9).normalize();
        let mut s = Sampler::new(1, 2, 3);
        let dirs: Vec<_> = (0..50_000)
            .map(|_| {
                let bs = b.sample(wo, Vec2::ZERO, 0.5, s.next_2d()).unwrap();
                // The weight is f cos / pdf = the albedo for a Lambertian surface.
                let e = b.eval(wo, bs.wi, Vec2::ZERO).x / b.pdf(wo, bs.wi, Vec2::ZERO);
                assert!((e - 0.7).abs() < 1e-5 && (bs.weight.x - 0.7).abs() < 1e-6);
                bs.wi.as_dvec3()
            })
            .collect();
        let grid = zerovar_testkit::SphereGrid::uniform(glam::DVec3::Z);
        grid.chi2(&dirs, &|d| b.pdf(wo, d.as_vec3a(), Vec2::ZERO) as f64)
            .assert_pass(1e-3, "cosine sampling");
        let total = grid.integrate(&|d| b.pdf(wo, d.as_vec3a(), Vec2::ZERO) as f64);
        assert!((total - 1.0).abs() < 1e-3, "diffuse pdf integrates to {total}");
        assert!(b.sample(-wo, Vec2::ZERO, 0.5, Vec2::splat(0.3)).is_none());
        let two = Bsdf::Diffuse { reflectance: Texture::Constant(Spectrum::ONE), two_sided: true };
        let bs = two.sample(-wo, Vec2::ZERO, 0.5, Vec2::splat(0.3)).unwrap();
        assert!(bs.wi.z < 0.0 && two.eval(-wo, bs.wi, Vec2::ZERO).x > 0.0);
    }

    #[test]
    fn fresnel_matches_known_values_and_conserves_energy() {
        // Normal incidence: ((1 - 1.5) / (1 + 1.5))^2 = 0.04.
        assert!((fresnel(1.0, 1.5).0 - 0.04).abs() < 1e-6);
        // Total internal reflection beyond the critical angle from inside.
        assert_eq!(fresnel(-0.5, 1.5).0, 1.0);
        // Refraction obeys Snell's law.
        let wo = Vec3A::new(0.6, 0.0, 0.8);
        let bs = sample_dielectric(1.5, wo, 0.99).unwrap();
        assert!((bs.wi.x.abs() - 0.6 / 1.5).abs() < 1e-5 && bs.wi.z < 0.0);
        assert!((bs.weight.x - 1.0 / 2.25).abs() < 1e-6);
    }

    #[test]
    fn thin_dielectric_sums_internal_reflections() {
        // Normal incidence, eta 1.5: R = 0.04, R' = 0.04 + 0.96^2 0.04 / (1 - 0.04^2) = 1/13,
        // the value Mitsuba 3.9.1's thindielectric samples reflection with.
        assert!((thin_reflectance(1.0, 1.5) - 1.0 / 13.0).abs() < 1e-6);
        // At cos 0.5 Mitsuba reflects with probability 0.163768 (measured), from either side.
        for cos in [0.5, -0.5] {
            assert!((thin_reflectance(cos, 1.5) - 0.163_767_5).abs() < 1e-5, "{cos}");
        }
        let b = Bsdf::ThinDielectric { eta: 1.5 };
        let wo = Vec3A::new(0.6, 0.0, 0.8);
        let r = thin_reflectance(0.8, 1.5);
        let through = b.sample(wo, Vec2::ZERO, r + 1e-3, Vec2::ZERO).unwrap();
        assert_eq!(through.wi, -wo, "transmission keeps the direction");
        assert!(through.delta && through.eta == 1.0 && through.weight == Spectrum::ONE);
        assert!((through.pdf - (1.0 - r)).abs() < 1e-7);
        let back = b.sample(wo, Vec2::ZERO, r - 1e-3, Vec2::ZERO).unwrap();
        assert_eq!(back.wi, Vec3A::new(-0.6, 0.0, 0.8));
        // The reflected fraction over many uniform numbers is R' (binomial, 5 sigma).
        let mut s = Sampler::new(3, 1, 4);
        let n = 200_000;
        let hits = (0..n)
            .filter(|_| b.sample(wo, Vec2::ZERO, s.next_1d(), Vec2::ZERO).unwrap().wi.z > 0.0)
            .count() as f64;
        let sigma = (f64::from(r) * (1.0 - f64::from(r)) / f64::from(n)).sqrt();
        assert!((hits / f64::from(n) - f64::from(r)).abs() < 5.0 * sigma);
        assert!(!b.has_smooth_component() && b.eval(wo, -wo, Vec2::ZERO) == Spectrum::ZERO);
    }

    /// Mitsuba 3.9.1's `mi.fresnel_diffuse_reflectance`, and the fits' agreement with the
    /// integral they approximate, 2 int_0^1 F(mu) mu dmu.
    #[test]
    fn diffuse_fresnel_reflectance_is_mitsubas_fit() {
        for (eta, mitsuba) in [(1.49, 0.090_299_96), (1.0 / 1.49, 0.590_732_5), (2.4, 0.210_191_57)]
        {
            let fit = fresnel_diffuse_reflectance(eta);
            assert!((fit - mitsuba).abs() < 1e-6, "{eta}: {fit} vs {mitsuba}");
            let n = 100_000;
            let integral: f64 = (0..n)
                .map(|i| {
                    let mu = (i as f64 + 0.5) / n as f64;
                    2.0 * f64::from(fresnel(mu as f32, eta).0) * mu / n as f64
                })
                .sum();
            assert!((f64::from(fit) / integral - 1.0).abs() < 0.01, "{eta}: {fit} vs {integral}");
        }
    }

    /// Smooth plastic: the specular lobe is drawn with its probability, the diffuse lobe's
    /// directions follow its density (chi-square), which integrates to the diffuse probability;
    /// every weight is the lobe's value over its density, and the mean weight (the albedo) is
    /// Fresnel reflection plus the integral of the diffuse lobe.
    #[test]
    fn plastic_samples_its_lobes_by_their_densities() {
        let p = Plastic::new(
            Texture::Constant(Spectrum::new(0.8, 0.5, 0.2)),
            Spectrum::splat(0.9),
            1.49 / 1.000_277,
            false,
        );
        let b = Bsdf::Plastic(p.clone());
        assert!(b.has_smooth_component());
        let grid = zerovar_testkit::SphereGrid::uniform(glam::DVec3::Z);
        for wo in [Vec3A::new(0.3, 0.1, 0.9).normalize(), Vec3A::new(0.95, 0.0, 0.1).normalize()] {
            let f_o = fresnel(wo.z, p.eta).0;
            let specular = p.specular_probability(f_o);
            let mut s = Sampler::new(7, 1, 2);
            let n = 200_000;
            let (mut dirs, mut spec_hits, mut albedo, mut square) = (Vec::new(), 0u32, 0.0, 0.0);
            for _ in 0..n {
                let bs = b.sample(wo, Vec2::ZERO, s.next_1d(), s.next_2d()).unwrap();
                albedo += f64::from(bs.weight.x);
                square += f64::from(bs.weight.x).powi(2);
                if bs.delta {
                    spec_hits += 1;
                    assert_eq!(bs.wi, Vec3A::new(-wo.x, -wo.y, wo.z));
                    assert!((bs.pdf - specular).abs() < 1e-7);
                } else {
                    let (f, pdf) = (b.eval(wo, bs.wi, Vec2::ZERO), b.pdf(wo, bs.wi, Vec2::ZERO));
                    assert!((bs.pdf - pdf).abs() <= 1e-6 * pdf);
                    assert!((bs.weight.x - f.x / pdf).abs() <= 1e-4 * bs.weight.x);
                    dirs.push(bs.wi.as_dvec3());
                }
            }
            let sigma = (f64::from(specular) * (1.0 - f64::from(specular)) / f64::from(n)).sqrt();
            let share = f64::from(spec_hits) / f64::from(n);
            assert!((share - f64::from(specular)).abs() < 5.0 * sigma, "{share} vs {specular}");
            let diffuse = 1.0 - f64::from(specular);
            let conditional = |d: glam::DVec3| b.pdf(wo, d.as_vec3a(), Vec2::ZERO) as f64 / diffuse;
            grid.chi2(&dirs, &conditional).assert_pass(1e-3, "plastic's diffuse lobe");
            let total = grid.integrate(&|d| b.pdf(wo, d.as_vec3a(), Vec2::ZERO) as f64);
            assert!((total - diffuse).abs() < 1e-3 * diffuse, "pdf integrates to {total}");
            // The albedo two ways: the mean weight, and Fresnel reflection plus the diffuse
            // lobe's integral.
            let expected = f64::from(f_o) * 0.9
                + grid.integrate(&|d| b.eval(wo, d.as_vec3a(), Vec2::ZERO).x as f64);
            let mean = albedo / f64::from(n);
            let se = ((square / f64::from(n) - mean * mean) / f64::from(n)).sqrt();
            assert!(se < 2.5e-3 * mean, "too few samples to see a 1% bias: {se}");
            assert!((mean - expected).abs() < 4.0 * se, "albedo {mean} vs {expected} +- {se}");
            assert!(mean < 1.0, "energy: {mean}");
        }
        // One-sided: black from behind; two-sided: the front mirrored.
        let back = Vec3A::new(0.3, 0.1, -0.9).normalize();
        assert!(b.sample(back, Vec2::ZERO, 0.5, Vec2::splat(0.3)).is_none());
        assert_eq!(b.eval(back, Vec3A::Z, Vec2::ZERO), Spectrum::ZERO);
        let two = Bsdf::Plastic(p.with_two_sided(true));
        for u1 in [0.01, 0.99] {
            let (f, r) =
                (two.sample(back, Vec2::ZERO, u1, Vec2::splat(0.3)).unwrap(), mirror(back));
            let front = b.sample(r, Vec2::ZERO, u1, Vec2::splat(0.3)).unwrap();
            assert_eq!(
                (f.wi, f.weight, f.pdf, f.delta),
                (mirror(front.wi), front.weight, front.pdf, front.delta)
            );
            let wi = mirror(front.wi);
            assert_eq!(two.eval(back, wi, Vec2::ZERO), b.eval(r, front.wi, Vec2::ZERO));
            assert_eq!(two.pdf(back, wi, Vec2::ZERO), b.pdf(r, front.wi, Vec2::ZERO));
        }
    }

    /// A mask lets `1 - opacity` through as a null crossing; where the path scatters, the
    /// nested BSDF's own values, densities and samples apply.
    #[test]
    fn mask_passes_its_share_and_scatters_as_its_nested_bsdf() {
        let nested = Bsdf::Diffuse {
            reflectance: Texture::Constant(Spectrum::splat(0.6)),
            two_sided: false,
        };
        let opacity = Texture::Constant(Spectrum::splat(0.3));
        let m = Bsdf::Mask { opacity, nested: Box::new(nested.clone()) };
        assert_eq!(m.null_transmission(0.2, Vec2::ZERO), Some(0.7));
        assert!(m.may_pass() && !m.passes_by_texture());
        // A checkerboard opacity (Mitsuba's `eval_1`: `color1` where the halves agree).
        let checker = Texture::Checkerboard {
            color0: Spectrum::splat(0.9),
            color1: Spectrum::new(0.1, 0.2, 0.3),
            scale: Vec2::ONE,
        };
        let textured = Bsdf::Mask { opacity: checker, nested: Box::new(nested.clone()) };
        assert!(textured.passes_by_texture());
        let agree = 1.0 - crate::math::luminance(Spectrum::new(0.1, 0.2, 0.3));
        assert_eq!(textured.null_transmission(1.0, Vec2::new(0.2, 0.3)), Some(agree));
        assert!((textured.null_transmission(1.0, Vec2::new(0.7, 0.3)).unwrap() - 0.1).abs() < 1e-6);
        assert!(m.has_smooth_component() && m.guides());
        let (wo, wi) =
            (Vec3A::new(0.3, 0.1, 0.9).normalize(), Vec3A::new(-0.2, 0.4, 0.8).normalize());
        assert_eq!(m.eval(wo, wi, Vec2::ZERO), nested.eval(wo, wi, Vec2::ZERO));
        assert_eq!(m.pdf(wo, wi, Vec2::ZERO), nested.pdf(wo, wi, Vec2::ZERO));
        let (a, b) = (
            m.sample(wo, Vec2::ZERO, 0.4, Vec2::splat(0.3)),
            nested.sample(wo, Vec2::ZERO, 0.4, Vec2::splat(0.3)),
        );
        assert_eq!(a.map(|s| (s.wi, s.weight, s.pdf)), b.map(|s| (s.wi, s.weight, s.pdf)));
    }

    #[test]
    fn checkerboard_follows_mitsuba() {
        let t = Texture::Checkerboard {
            color0: Spectrum::splat(0.4),
            color1: Spectrum::splat(0.2),
            scale: Vec2::ONE,
        };
        assert_eq!(t.eval(Vec2::new(0.25, 0.25)).x, 0.4);
        assert_eq!(t.eval(Vec2::new(0.75, 0.25)).x, 0.2);
        assert_eq!(t.eval(Vec2::new(0.75, 0.75)).x, 0.4);
    }
}
