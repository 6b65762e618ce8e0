//! Mitsuba's conductors: `conductor`, a smooth metal mirror, and `roughconductor`, a metal
//! with microfacet roughness, both reflecting with the Fresnel reflectance of a complex index
//! of refraction `eta + i k` per channel (Mitsuba's named materials, or given values; the
//! default, Mitsuba's `none`, reflects everything). One-sided unless two-sided.

use super::microfacet::{Microfacet, Roughness};
use super::{BsdfSample, front_side, mirror};
use crate::math::{Spectrum, reflect};
use glam::{Vec2, Vec3A};

/// A metal's optics: its complex index of refraction and a factor on its reflection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metal {
    /// Real part of the index of refraction, per channel.
    pub eta: Spectrum,
    /// Imaginary part (absorption), per channel.
    pub k: Spectrum,
    /// A factor on the reflection (Mitsuba's `specular_reflectance`).
    pub specular: Spectrum,
    /// Whether the back side is the same metal, not black.
    pub two_sided: bool,
}

impl Metal {
    /// The index of Mitsuba's named `material` (`none`: eta 0, k 1, a perfect mirror), or
    /// `None` for a name Mitsuba does not know.
    pub fn named(material: &str) -> Option<(Spectrum, Spectrum)> {
        if material == "none" {
            return Some((Spectrum::ZERO, Spectrum::ONE));
        }
        super::conductors::CONDUCTORS
            .iter()
            .find(|(name, _, _)| *name == material)
            .map(|&(_, eta, k)| (Spectrum::from(eta), Spectrum::from(k)))
    }

    /// The names of Mitsuba's conductors besides `none`.
    pub fn names() -> impl Iterator<Item = &'static str> {
        super::conductors::CONDUCTORS.iter().map(|(name, _, _)| *name)
    }

    /// The reflection (Fresnel times the factor) at `cos` to the normal.
    fn reflectance(&self, cos: f32) -> Spectrum {
        let f = |eta: f32, k: f32| fresnel_conductor(cos, eta, k);
        self.specular
            * Spectrum::new(
                f(self.eta.x, self.k.x),
                f(self.eta.y, self.k.y),
                f(self.eta.z, self.k.z),
            )
    }

    /// `wo` and `wi` as the front sees them, and whether they were mirrored.
    fn front(&self, wo: Vec3A, wi: Vec3A) -> (Vec3A, Vec3A, bool) {
        front_side(self.two_sided, wo, wi)
    }
}

/// The unpolarised Fresnel reflectance of a conductor of index `eta + i k` at `cos` (between
/// 0 and 1) from a medium of index 1: the exact expression with a^2 + b^2 = |n^2 - sin^2|.
fn fresnel_conductor(cos: f32, eta: f32, k: f32) -> f32 {
    let (cos, eta, k) = (f64::from(cos.clamp(0.0, 1.0)), f64::from(eta), f64::from(k));
    let (cos2, sin2) = (cos * cos, 1.0 - cos * cos);
    let t0 = eta * eta - k * k - sin2;
    let a2b2 = (t0 * t0 + 4.0 * eta * eta * k * k).sqrt();
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let t1 = a2b2 + cos2;
    let t2 = 2.0 * cos * a;
    let rs = if t1 + t2 > 0.0 { (t1 - t2) / (t1 + t2) } else { 1.0 };
    let t3 = cos2 * a2b2 + sin2 * sin2;
    let t4 = t2 * sin2;
    let rp = if t3 + t4 > 0.0 { rs * (t3 - t4) / (t3 + t4) } else { rs };
    (0.5 * (rs + rp)).clamp(0.0, 1.0) as f32
}

/// Mitsuba's `conductor`: a mirror.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conductor(pub Metal);

impl Conductor {
    /// The mirror direction, weighted by the reflectance; `None` from behind a one-sided metal.
    pub fn sample(&self, wo: Vec3A) -> Option<BsdfSample> {
        let (front, _, _) = self.0.front(wo, wo);
        if front.z <= 0.0 {
            return None;
        }
        // The mirror direction is the same seen from either side.
        let (wi, weight) = (Vec3A::new(-wo.x, -wo.y, wo.z), self.0.reflectance(front.z));
        Some(BsdfSample { wi, weight, pdf: 1.0, delta: true, eta: 1.0 })
    }
}

/// Mitsuba's `roughconductor`.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughConductor {
    /// The metal.
    pub metal: Metal,
    /// Its micro-normals.
    pub roughness: Roughness,
}

impl RoughConductor {
    /// BSDF times |cos wi| at texture coordinates `uv`.
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> Spectrum {
        self.eval_with(&self.roughness.at(uv), wo, wi)
    }

    fn eval_with(&self, mf: &Microfacet, wo: Vec3A, wi: Vec3A) -> Spectrum {
        let (wo, wi, _) = self.metal.front(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Spectrum::ZERO;
        }
        let h = (wo + wi).normalize();
        self.metal.reflectance(wo.dot(h)) * (mf.d(h) * mf.g(wo, wi, h) / (4.0 * wo.z))
    }

    /// The density of [`Self::sample`] drawing `wi`.
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, uv: Vec2) -> f32 {
        Self::pdf_with(&self.metal, &self.roughness.at(uv), wo, wi)
    }

    fn pdf_with(metal: &Metal, mf: &Microfacet, wo: Vec3A, wi: Vec3A) -> f32 {
        let (wo, wi, _) = metal.front(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize();
        mf.d(h) * mf.g1(wo, h) / (4.0 * wo.z)
    }

    /// A visible micro-normal's mirror direction; `None` below the surface.
    pub fn sample(&self, wo: Vec3A, uv: Vec2, u: Vec2) -> Option<BsdfSample> {
        let (front, _, flipped) = self.metal.front(wo, wo);
        if front.z <= 0.0 {
            return None;
        }
        let mf = self.roughness.at(uv);
        let wi = reflect(front, mf.sample_visible(front, u));
        if wi.z <= 0.0 {
            return None;
        }
        let wi = if flipped { mirror(wi) } else { wi };
        let pdf = Self::pdf_with(&self.metal, &mf, wo, wi);
        (pdf > 0.0).then(|| BsdfSample {
            wi,
            weight: self.eval_with(&mf, wo, wi) / pdf,
            pdf,
            delta: false,
            eta: 1.0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::microfacet::MicrofacetKind::{Beckmann, Ggx};
    use crate::bsdf::testing::{agrees, check};
    use crate::bsdf::{Bsdf, Texture};
    use glam::DVec3;
    use zerovar_testkit::SphereGrid;

    fn metal(material: &str, specular: Spectrum) -> Metal {
        let (eta, k) = Metal::named(material).unwrap();
        Metal { eta, k, specular, two_sided: false }
    }

    /// Mitsuba 3.9.1's `mi.fresnel_conductor` for gold's and aluminium's red channel and
    /// amorphous carbon's, at three angles; `none` reflects everything.
    #[test]
    fn fresnel_is_mitsubas() {
        let cases = [
            (1.0, 0.143_036, 3.983, 0.966_679_3),
            (1.0, 1.6575, 9.223_81, 0.928_045),
            (1.0, 2.944_05, 0.887_465, 0.279_440_1),
            (0.5, 0.143_036, 3.983, 0.962_210_4),
            (0.5, 1.6575, 9.223_81, 0.913_663_3),
            (0.5, 2.944_05, 0.887_465, 0.297_945_8),
            (0.1, 0.143_036, 3.983, 0.973_434_7),
            (0.1, 1.6575, 9.223_81, 0.844_954),
            (0.1, 2.944_05, 0.887_465, 0.579_278_8),
        ];
        for (cos, eta, k, mitsuba) in cases {
            let f = fresnel_conductor(cos, eta, k);
            assert!((f - mitsuba).abs() < 2e-6, "{cos} {eta} {k}: {f} vs {mitsuba}");
        }
        for cos in [1.0, 0.5, 0.1, 0.0] {
            assert_eq!(fresnel_conductor(cos, 0.0, 1.0), 1.0, "none reflects everything");
        }
        assert_eq!(Metal::named("Au").unwrap().0, Spectrum::new(0.143_036, 0.375_307, 1.442_05));
        assert!(Metal::named("unobtainium").is_none());
    }

    #[test]
    fn rough_conductor_is_mitsubas() {
        let mf = |kind, alpha| Roughness::Constant(Microfacet::isotropic(kind, alpha));
        let zero = ([0.0; 3], 0.0);
        let gold = RoughConductor { metal: metal("Au", Spectrum::ONE), roughness: mf(Ggx, 0.2) };
        let values = [
            ([0.741_401_2, 0.615_033_7, 0.249_368_65], 0.770_160_8),
            zero,
            zero,
            zero,
            ([1.234_984, 1.072_571_6, 0.607_837_4], 1.355_706_1),
        ];
        agrees("gold ggx 0.2", Bsdf::RoughConductor(gold), values, 1e-4);
        let tint = Spectrum::new(0.9, 0.8, 0.7);
        let copper = RoughConductor { metal: metal("Cu", tint), roughness: mf(Beckmann, 0.1) };
        let values = [
            ([0.464_416_6, 0.268_749_6, 0.193_852_2], 0.542_127_25),
            zero,
            zero,
            zero,
            ([0.030_898_096, 0.019_519_225, 0.015_252_29], 0.036_445_79),
        ];
        // Mitsuba's Beckmann masking is a rational fit within 0.35% of the exact one.
        agrees("copper beckmann 0.1", Bsdf::RoughConductor(copper), values, 8e-3);
    }

    /// Sampling against the density and the albedo two ways, front and back of a two-sided
    /// metal (amorphous carbon, whose reflectance varies with the angle, so the weights do),
    /// isotropic and brushed; and a white furnace: a perfect mirror's (`none`) albedo is what
    /// masking leaves (near 1 for a smooth surface, far less for rough GGX), never above 1,
    /// and Mitsuba's.
    #[test]
    fn rough_conductor_samples_its_density() {
        for kind in [Beckmann, Ggx] {
            for (alpha_u, alpha_v) in [(0.05, 0.05), (0.4, 0.4), (0.06, 0.5)] {
                let microfacet = Microfacet { kind, alpha_u, alpha_v };
                let carbon = Metal { two_sided: true, ..metal("a-C", Spectrum::ONE) };
                let b = RoughConductor { metal: carbon, roughness: microfacet.into() };
                let kappa = (0.5 / f64::from(alpha_u.min(alpha_v))).powi(2);
                // An elongated lobe varies fast in azimuth near its axis: finer bins there.
                let (n_theta, n_phi) =
                    if microfacet.is_anisotropic() { (64, 96) } else { (24, 16) };
                let grid =
                    |axis| SphereGrid { n_theta, n_phi, ..SphereGrid::for_lobe(axis, kappa) };
                for wo in [
                    Vec3A::new(0.3, 0.1, 0.9).normalize(),
                    Vec3A::new(0.95, 0.0, 0.1).normalize(),
                    Vec3A::new(0.2, -0.1, -0.9).normalize(),
                ] {
                    let what = format!("roughconductor {microfacet:?} from {wo}");
                    let axis = Vec3A::new(-wo.x, -wo.y, wo.z).as_dvec3();
                    check(
                        &what,
                        1.0,
                        &|_, u2| b.sample(wo, Vec2::ZERO, u2),
                        &|wi| b.pdf(wo, wi, Vec2::ZERO),
                        &|wi| b.eval(wo, wi, Vec2::ZERO).x,
                        grid(axis),
                    );
                }
                if microfacet.is_anisotropic() {
                    continue;
                }
                let alpha = alpha_u;
                let grid = SphereGrid::for_lobe(DVec3::Z, kappa);
                let mirror =
                    RoughConductor { metal: metal("none", Spectrum::ONE), roughness: b.roughness };
                let albedo = grid
                    .integrate(&|d| f64::from(mirror.eval(Vec3A::Z, d.as_vec3a(), Vec2::ZERO).x));
                // Mitsuba 3.9.1's mean sample weight at normal incidence (20000 samples).
                let mitsuba = match (kind, alpha < 0.1) {
                    (_, true) => 0.998,
                    (Ggx, false) => 0.785_26,
                    (Beckmann, false) => 0.989_66,
                };
                assert!(albedo <= 1.0 + 1e-3, "{kind:?} {alpha}: {albedo}");
                assert!((albedo - mitsuba).abs() < 0.01, "{kind:?} {alpha}: {albedo} vs {mitsuba}");
            }
        }
        let one_sided = RoughConductor {
            metal: metal("none", Spectrum::ONE),
            roughness: Microfacet::isotropic(Ggx, 0.3).into(),
        };
        let back = Vec3A::new(0.2, -0.1, -0.9).normalize();
        assert!(one_sided.sample(back, Vec2::ZERO, Vec2::splat(0.4)).is_none());
        assert_eq!(one_sided.eval(back, Vec3A::new(0.1, 0.0, -0.99), Vec2::ZERO), Spectrum::ZERO);
    }

    /// A textured roughness is the constant one of its value at each point: a checkerboard of
    /// two roughnesses (Mitsuba's `eval_1` takes `color1` where the halves agree) samples,
    /// weighs and evaluates in each square as the constant BSDF of that square's value.
    #[test]
    fn textured_roughness_is_the_constant_of_its_value_there() {
        let checker = Texture::Checkerboard {
            color0: Spectrum::splat(0.05),
            color1: Spectrum::splat(0.4),
            scale: Vec2::splat(2.0),
        };
        let map = RoughConductor {
            metal: metal("Au", Spectrum::ONE),
            roughness: Roughness::Textured {
                kind: Ggx,
                alpha_u: std::sync::Arc::new(checker),
                alpha_v: None,
            },
        };
        let wo = Vec3A::new(0.3, 0.1, 0.9).normalize();
        for (uv, alpha) in [(Vec2::new(0.1, 0.1), 0.4), (Vec2::new(0.3, 0.1), 0.05)] {
            let constant = RoughConductor {
                roughness: Microfacet::isotropic(Ggx, alpha).into(),
                ..map.clone()
            };
            let u = Vec2::new(0.3, 0.7);
            let (a, b) = (map.sample(wo, uv, u).unwrap(), constant.sample(wo, uv, u).unwrap());
            assert_eq!((a.wi, a.weight, a.pdf), (b.wi, b.weight, b.pdf), "{uv}");
            assert_eq!(map.pdf(wo, a.wi, uv), constant.pdf(wo, a.wi, Vec2::ZERO));
            assert_eq!(map.eval(wo, a.wi, uv), constant.eval(wo, a.wi, Vec2::ZERO));
        }
    }

    #[test]
    fn smooth_conductor_mirrors_with_its_reflectance() {
        let c = Conductor(metal("Au", Spectrum::splat(0.5)));
        let wo = Vec3A::new(0.6, 0.0, 0.8);
        let bs = c.sample(wo).unwrap();
        assert_eq!(bs.wi, Vec3A::new(-0.6, 0.0, 0.8));
        let expected = 0.5 * fresnel_conductor(0.8, 0.143_036, 3.983);
        assert!(bs.delta && (bs.weight.x - expected).abs() < 1e-6);
        assert!(c.sample(-wo).is_none(), "one-sided");
        let two = Conductor(Metal { two_sided: true, ..c.0 });
        assert_eq!(two.sample(-wo).unwrap().wi, Vec3A::new(0.6, 0.0, -0.8));
    }
}
