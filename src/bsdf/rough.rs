//! Mitsuba's rough BSDFs over a microfacet distribution: `roughdielectric`, a rough boundary
//! between two indices of refraction (Walter et al. 2007), and `roughplastic`, a diffuse base
//! under a rough dielectric coating whose reflection is a microfacet lobe and whose
//! transmission, tabulated over the angle, scales the base's light in and out.
//!
//! Each draws a visible micro-normal and then reflects or refracts about it; the sample's
//! weight is the BSDF over the full density of its direction, so that next-event estimation
//! and guiding, which evaluate both, see the same numbers.

use super::microfacet::{Microfacet, Roughness, directional_albedo};
use super::{
    BsdfSample, Texture, fresnel, front_side, refract, specular_sampling_weight, specular_share,
    under_coating,
};
use crate::math::{Spectrum, cosine_hemisphere, reflect};
use glam::{Vec2, Vec3A};
use std::f32::consts::FRAC_1_PI;

/// Mitsuba's `roughdielectric`.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughDielectric {
    /// The boundary's micro-normals.
    pub roughness: Roughness,
    /// Interior over exterior index of refraction.
    pub eta: f32,
}

/// The half-vector of a pair of directions, facing the front, with the relative index along
/// `wo`'s side; `None` for grazing or degenerate pairs.
struct Half {
    m: Vec3A,
    reflect: bool,
    eta: f32,
}

impl RoughDielectric {
    fn half(&self, wo: Vec3A, wi: Vec3A) -> Option<Half> {
        if wo.z == 0.0 || wi.z == 0.0 {
            return None;
        }
        let reflect = wo.z * wi.z > 0.0;
        let eta = if wo.z > 0.0 { self.eta } else { 1.0 / self.eta };
        let h = (wo + wi * if reflect { 1.0 } else { eta }).normalize_or_zero();
        let m = if h.z < 0.0 { -h } else { h };
        // Micro- and macro-surface must agree on each direction's side.
        (m.z > 0.0 && wo.dot(m) * wo.z > 0.0 && wi.dot(m) * wi.z > 0.0).then_some(Half {
            m,
            reflect,
            eta,
        })
    }

    /// BSDF times |cos wi| at texture coordinates `uv`, with radiance scaled by 1/eta^2 when
    /// it refracts (Mitsuba's radiance transport).
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> f32 {
        self.eval_with(&self.roughness.at(uv), wo, wi)
    }

    fn eval_with(&self, mf: &Microfacet, wo: Vec3A, wi: Vec3A) -> f32 {
        let Some(Half { m, reflect, eta }) = self.half(wo, wi) else { return 0.0 };
        let (d, g) = (mf.d(m), mf.g(wo, wi, m));
        let f = fresnel(wo.dot(m), self.eta).0;
        if reflect {
            return f * d * g / (4.0 * wo.z.abs());
        }
        let (om, im) = (wo.dot(m), wi.dot(m));
        let denom = om + eta * im;
        // eta^2 of the half-vector's Jacobian cancels the 1/eta^2 of radiance.
        ((1.0 - f) * d * g * om * im / (wo.z * denom * denom)).abs()
    }

    /// The density of [`Self::sample`] drawing `wi`.
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> f32 {
        self.pdf_with(&self.roughness.at(uv), wo, wi)
    }

    fn pdf_with(&self, mf: &Microfacet, wo: Vec3A, wi: Vec3A) -> f32 {
        let Some(Half { m, reflect, eta }) = self.half(wo, wi) else { return 0.0 };
        let v = if wo.z > 0.0 { wo } else { -wo };
        let f = fresnel(wo.dot(m), self.eta).0;
        let im = wi.dot(m);
        let jacobian = if reflect {
            1.0 / (4.0 * im.abs())
        } else {
            let denom = wo.dot(m) + eta * im;
            eta * eta * im.abs() / (denom * denom)
        };
        mf.visible_pdf(v, m) * if reflect { f } else { 1.0 - f } * jacobian
    }

    /// A micro-normal visible from `wo`, then reflection with the Fresnel probability or
    /// refraction; `None` where the new direction leaves on the side its lobe cannot reach.
    pub fn sample(&self, wo: Vec3A, uv: Vec2, u1: f32, u2: Vec2) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let mf = self.roughness.at(uv);
        let v = if wo.z > 0.0 { wo } else { -wo };
        let m = mf.sample_visible(v, u2);
        let (f, cos_t, eta_it) = fresnel(wo.dot(m), self.eta);
        let reflected = u1 < f;
        let wi = if reflected { reflect(wo, m) } else { refract(wo, m, cos_t, eta_it) };
        if (wi.z * wo.z > 0.0) != reflected {
            return None;
        }
        let pdf = self.pdf_with(&mf, wo, wi);
        let value = self.eval_with(&mf, wo, wi);
        (pdf > 0.0 && value.is_finite()).then(|| BsdfSample {
            wi,
            weight: Spectrum::splat(value / pdf),
            pdf,
            delta: false,
            eta: if reflected { 1.0 } else { eta_it },
        })
    }
}

/// Table resolution of the coating's transmission over the cosine, as Mitsuba's.
const TABLE: usize = 64;
/// Midpoint-rule resolution (per axis of the visible normals' sample square) of the coating's
/// reflectance integrals.
const QUADRATURE: usize = 48;

/// Mitsuba's `roughplastic`, with what it precomputes.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughPlastic {
    /// The base's albedo.
    pub diffuse: Texture,
    /// A factor on the coating's specular reflection.
    pub specular: Spectrum,
    /// Coating over outside index of refraction.
    pub eta: f32,
    /// Mitsuba's `nonlinear`.
    pub nonlinear: bool,
    /// Whether the back side is the same plastic, not black.
    pub two_sided: bool,
    /// The coating's micro-normals.
    pub microfacet: Microfacet,
    specular_weight: f32,
    /// The coating's reflectance of diffuse light from inside.
    internal: f32,
    /// The coating's transmission from outside at cosines i / (TABLE - 1).
    transmission: [f32; TABLE],
}

impl RoughPlastic {
    /// A rough plastic, its coating's transmission and internal reflectance computed as
    /// Mitsuba does (one-sided).
    pub fn new(
        diffuse: Texture,
        specular: Spectrum,
        eta: f32,
        nonlinear: bool,
        microfacet: Microfacet,
    ) -> Self {
        let specular_weight = specular_sampling_weight(&diffuse, specular);
        let cosines = (0..TABLE).map(|i| (i as f32 / (TABLE - 1) as f32).max(1e-6));
        let mut transmission = [0.0; TABLE];
        let mut internal = 0.0;
        for (i, cos) in cosines.enumerate() {
            transmission[i] = directional_albedo(&microfacet, cos, eta, true, QUADRATURE);
            internal += directional_albedo(&microfacet, cos, 1.0 / eta, false, QUADRATURE) * cos;
        }
        // Mitsuba's estimate of 2 int R(mu) mu dmu: twice the mean over the table's cosines.
        let internal = 2.0 * internal / TABLE as f32;
        Self {
            diffuse,
            specular,
            eta,
            nonlinear,
            two_sided: false,
            microfacet,
            specular_weight,
            internal,
            transmission,
        }
    }

    /// The same plastic on both sides, or only on the front.
    pub fn with_two_sided(self, two_sided: bool) -> Self {
        Self { two_sided, ..self }
    }

    /// `wo` and `wi` as the front sees them, and whether they were mirrored.
    pub(super) fn front(&self, wo: Vec3A, wi: Vec3A) -> (Vec3A, Vec3A, bool) {
        front_side(self.two_sided, wo, wi)
    }

    /// The coating's transmission at `cos`, linear in the table.
    fn transmission(&self, cos: f32) -> f32 {
        let x = cos.clamp(0.0, 1.0) * (TABLE - 1) as f32;
        let i = (x as usize).min(TABLE - 2);
        let w = x - i as f32;
        (1.0 - w) * self.transmission[i] + w * self.transmission[i + 1]
    }

    fn specular_probability(&self, cos_o: f32) -> f32 {
        let t = self.transmission(cos_o);
        specular_share(1.0 - t, t, self.specular_weight)
    }

    /// BSDF times cos wi, front side.
    pub(super) fn eval(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> Spectrum {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Spectrum::ZERO;
        }
        let mf = &self.microfacet;
        let h = (wo + wi).normalize();
        let f = fresnel(wo.dot(h), self.eta).0;
        let specular = self.specular * (f * mf.d(h) * mf.g(wo, wi, h) / (4.0 * wo.z));
        let base = under_coating(self.diffuse.eval(uv), self.internal, self.nonlinear);
        let through = self.transmission(wo.z) * self.transmission(wi.z);
        specular + base * (FRAC_1_PI / (self.eta * self.eta) * wi.z * through)
    }

    /// The density of [`Self::sample`], front side.
    pub(super) fn pdf(&self, wo: Vec3A, wi: Vec3A) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize();
        let p = self.specular_probability(wo.z);
        let mf = &self.microfacet;
        p * mf.d(h) * mf.g1(wo, h) / (4.0 * wo.z) + (1.0 - p) * FRAC_1_PI * wi.z
    }

    /// The specular lobe (a visible micro-normal's reflection) with its probability, else the
    /// diffuse one by cosine sampling, front side.
    pub(super) fn sample(&self, wo: Vec3A, uv: Vec2, u1: f32, u2: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = if u1 < self.specular_probability(wo.z) {
            reflect(wo, self.microfacet.sample_visible(wo, u2))
        } else {
            cosine_hemisphere(u2)
        };
        let pdf = self.pdf(wo, wi);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let weight = self.eval(wo, wi, uv) / pdf;
        Some(BsdfSample { wi, weight, pdf, delta: false, eta: 1.0 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::microfacet::MicrofacetKind;
    use crate::bsdf::testing::check;
    use glam::DVec3;
    use zerovar_testkit::SphereGrid;

    fn kinds() -> [MicrofacetKind; 2] {
        [MicrofacetKind::Beckmann, MicrofacetKind::Ggx]
    }

    #[test]
    fn rough_dielectric_samples_its_density_and_conserves_energy() {
        for kind in kinds() {
            for (alpha_u, alpha_v, eta) in
                [(0.1, 0.1, 1.5), (0.4, 0.4, 1.33), (0.8, 0.8, 1.5), (0.1, 0.5, 1.5)]
            {
                let microfacet = Microfacet { kind, alpha_u, alpha_v };
                let b = RoughDielectric { roughness: microfacet.into(), eta };
                for wo in [
                    Vec3A::new(0.3, 0.1, 0.9).normalize(),
                    Vec3A::new(0.9, 0.0, 0.15).normalize(),
                    Vec3A::new(0.2, -0.3, -0.8).normalize(),
                ] {
                    let what = format!("roughdielectric {microfacet:?} eta {eta} from {wo}");
                    // One-degree bins about the normal: both lobes resolved, and the horizon,
                    // where reflection's density gives way to transmission's, on a bin edge.
                    let grid = SphereGrid {
                        axis: DVec3::Z,
                        theta_scale: f64::INFINITY,
                        n_theta: 180,
                        n_phi: 180,
                    };
                    let most = if wo.z > 0.0 { 1.0 } else { f64::from(eta * eta) };
                    check(
                        &what,
                        most,
                        &|u1, u2| b.sample(wo, Vec2::ZERO, u1, u2),
                        &|wi| b.pdf(wo, wi, Vec2::ZERO),
                        &|wi| b.eval(wo, wi, Vec2::ZERO),
                        grid,
                    );
                }
            }
        }
    }

    /// Reciprocity with Mitsuba's radiance scaling: f(wo, wi) / eta_o^2 = f(wi, wo) / eta_i^2
    /// (cosines taken out), so the refracted value seen from inside is eta^2 times that seen
    /// from outside.
    #[test]
    fn rough_dielectric_transmission_scales_as_radiance() {
        let b = RoughDielectric {
            roughness: Microfacet::isotropic(MicrofacetKind::Ggx, 0.3).into(),
            eta: 1.5,
        };
        let (a, c) =
            (Vec3A::new(0.3, 0.2, 0.9).normalize(), Vec3A::new(-0.2, 0.1, -0.95).normalize());
        let z = Vec2::ZERO;
        let outside = b.eval(a, c, z) / c.z.abs();
        let inside = b.eval(c, a, z) / a.z.abs();
        assert!((inside / outside - 1.5 * 1.5).abs() < 1e-3 * 2.25, "{inside} vs {outside}");
        // Reflection is symmetric.
        let r = Vec3A::new(-0.5, 0.1, 0.8).normalize();
        assert!((b.eval(a, r, z) / r.z - b.eval(r, a, z) / a.z).abs() < 1e-5);
    }

    #[test]
    fn rough_plastic_samples_its_density() {
        for kind in kinds() {
            for alpha in [0.05, 0.3] {
                let p = RoughPlastic::new(
                    Texture::Constant(Spectrum::new(0.8, 0.5, 0.2)),
                    Spectrum::ONE,
                    1.49 / 1.000_277,
                    false,
                    Microfacet::isotropic(kind, alpha),
                );
                for wo in
                    [Vec3A::new(0.3, 0.1, 0.9).normalize(), Vec3A::new(0.95, 0.0, 0.1).normalize()]
                {
                    let what = format!("roughplastic {kind:?} {alpha} from {wo}");
                    let axis = Vec3A::new(-wo.x, -wo.y, wo.z).as_dvec3();
                    let grid = SphereGrid::for_lobe(axis, (0.5 / f64::from(alpha)).powi(2));
                    check(
                        &what,
                        1.0,
                        &|u1, u2| p.sample(wo, Vec2::ZERO, u1, u2),
                        &|wi| p.pdf(wo, wi),
                        &|wi| p.eval(wo, wi, Vec2::ZERO).x,
                        grid,
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod mitsuba {
    use super::*;
    use crate::bsdf::Bsdf;
    use crate::bsdf::microfacet::MicrofacetKind::{Beckmann, Ggx};
    use crate::bsdf::testing::{agrees, grey};

    #[test]
    fn rough_dielectric_is_mitsubas() {
        let b = |kind| {
            Bsdf::RoughDielectric(RoughDielectric {
                roughness: Microfacet::isotropic(kind, 0.3).into(),
                eta: 1.5,
            })
        };
        let ggx = [
            (0.023_172_09, 0.023_381_995),
            (0.845_898_2, 1.905_640_6),
            (0.296_578_6, 0.132_432_27),
            (0.035_950_12, 0.036_079_478),
            (0.243_761, 0.271_153_1),
        ];
        agrees("ggx", b(Ggx), grey(ggx), 1e-4);
        // Mitsuba's Beckmann masking is a rational fit within 0.35% of the exact one.
        let beckmann = [
            (0.029_528_674, 0.029_528_672),
            (0.751_350_5, 1.690_538_3),
            (0.000_720_946, 0.000_320_420_5),
            (0.039_095_65, 0.039_095_65),
            (0.520_550_8, 0.521_190_8),
        ];
        agrees("beckmann", b(Beckmann), grey(beckmann), 8e-3);
    }

    #[test]
    fn rough_plastic_is_mitsubas() {
        let diffuse = Texture::Constant(Spectrum::new(0.8, 0.5, 0.2));
        let b = |kind, alpha, nonlinear| {
            let mf = Microfacet::isotropic(kind, alpha);
            Bsdf::RoughPlastic(RoughPlastic::new(
                diffuse.clone(),
                Spectrum::ONE,
                1.49 / 1.000_277,
                nonlinear,
                mf,
            ))
        };
        let zero = ([0.0; 3], 0.0);
        let ggx = [
            ([0.199_780_88, 0.136_183_95, 0.072_587_006], 0.309_790_7),
            zero,
            zero,
            zero,
            ([0.336_830_02, 0.316_013_8, 0.295_197_6], 0.623_274_6),
        ];
        agrees("ggx 0.2", b(Ggx, 0.2, false), ggx, 2e-3);
        let beckmann = [
            ([0.186_399_9, 0.099_545_03, 0.046_526_34], 0.288_967_1),
            zero,
            zero,
            zero,
            ([0.052_970_49, 0.029_287_374, 0.014_830_526], 0.076_764_71),
        ];
        agrees("beckmann 0.1 nonlinear", b(Beckmann, 0.1, true), beckmann, 8e-3);
    }
}
