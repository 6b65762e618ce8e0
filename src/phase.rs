//! Phase functions: how a medium redistributes light at a scattering event.
//!
//! Convention (used everywhere in zerovar and in the guiding crate): the angle is measured
//! between the direction the path was travelling (`ray_dir`) and the new direction, so
//! `g > 0` is forward scattering. Every phase function here is normalised over the sphere, so
//! its value is also its sampling density and a sampled direction carries weight 1.

use crate::math::{Frame, INV_FOUR_PI, uniform_sphere};
use glam::{Vec2, Vec3A};
use std::f64::consts::PI;

/// Below this |g|, Henyey-Greenstein sampling uses the isotropic warp: the inverse CDF divides
/// by g and loses all precision, while the density differs from isotropic by O(g).
const HG_ISOTROPIC_G: f32 = 1e-4;

/// Up to this |g| the Henyey-Greenstein density is evaluated in single precision.
const HG_SINGLE_G: f32 = 0.7;

/// A phase function of a medium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhaseFunction {
    /// Uniform over the sphere.
    Isotropic,
    /// Henyey-Greenstein with mean cosine `g` in (-1, 1).
    HenyeyGreenstein {
        /// Mean cosine of the scattering angle.
        g: f32,
    },
    /// Rayleigh scattering, `3 / (16 pi) (1 + cos^2)`.
    Rayleigh,
    /// Mitsuba's `blendphase`: `(1 - weight) first + weight second`.
    Blend {
        /// The second lobe's share, in [0, 1].
        weight: f32,
        /// The lobe at weight 0.
        first: Lobe,
        /// The lobe at weight 1.
        second: Lobe,
    },
}

/// One lobe of a blended phase function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lobe {
    /// Uniform over the sphere.
    Isotropic,
    /// Henyey-Greenstein with mean cosine `g` in (-1, 1).
    HenyeyGreenstein {
        /// Mean cosine of the scattering angle.
        g: f32,
    },
    /// Rayleigh scattering.
    Rayleigh,
}

impl Lobe {
    /// The lobe as a phase function of its own.
    pub fn alone(self) -> PhaseFunction {
        match self {
            Lobe::Isotropic => PhaseFunction::Isotropic,
            Lobe::HenyeyGreenstein { g } => PhaseFunction::HenyeyGreenstein { g },
            Lobe::Rayleigh => PhaseFunction::Rayleigh,
        }
    }
}

impl PhaseFunction {
    /// Mean cosine of the scattering angle.
    pub fn mean_cosine(&self) -> f32 {
        match *self {
            PhaseFunction::Isotropic | PhaseFunction::Rayleigh => 0.0,
            PhaseFunction::HenyeyGreenstein { g } => g,
            PhaseFunction::Blend { weight, first, second } => {
                (1.0 - weight) * first.alone().mean_cosine() + weight * second.alone().mean_cosine()
            }
        }
    }

    /// Value (= density) for a path travelling along `ray_dir` that continues along `wi`.
    #[inline]
    pub fn eval(&self, ray_dir: Vec3A, wi: Vec3A) -> f32 {
        match *self {
            PhaseFunction::Isotropic => INV_FOUR_PI,
            PhaseFunction::HenyeyGreenstein { g } => hg_vectors(g, ray_dir, wi),
            PhaseFunction::Rayleigh => rayleigh(ray_dir.dot(wi).clamp(-1.0, 1.0)),
            PhaseFunction::Blend { weight, first, second } => {
                (1.0 - weight) * first.alone().eval(ray_dir, wi)
                    + weight * second.alone().eval(ray_dir, wi)
            }
        }
    }

    /// Samples a new direction; returns it with its density.
    #[inline]
    pub fn sample(&self, ray_dir: Vec3A, u: Vec2) -> (Vec3A, f32) {
        match *self {
            PhaseFunction::Rayleigh => {
                let cos = sample_rayleigh_cos(u.x);
                let sin = ((1.0 - cos) * (1.0 + cos)).max(0.0).sqrt();
                let (sin_phi, cos_phi) = (std::f32::consts::TAU * u.y).sin_cos();
                let local = Vec3A::new(sin * cos_phi, sin * sin_phi, cos);
                let wi = Frame::from_z(ray_dir).to_world(local).normalize();
                (wi, self.eval(ray_dir, wi))
            }
            PhaseFunction::Blend { weight, first, second } => {
                // One lobe by its share, the number reused for its own draw; the density is
                // the blend's, so the sample weighs one.
                let (lobe, x) = if u.x < weight {
                    (second, u.x / weight)
                } else {
                    (first, (u.x - weight) / (1.0 - weight))
                };
                let (wi, _) = lobe.alone().sample(ray_dir, Vec2::new(x.min(ONE_BELOW), u.y));
                (wi, self.eval(ray_dir, wi))
            }
            PhaseFunction::HenyeyGreenstein { g } if g.abs() >= HG_ISOTROPIC_G => {
                // In f64: near the peak 1 - cos^2 is below an f32 cosine's resolution.
                let cos = sample_hg_cos(g, u.x);
                let sin = ((1.0 - cos) * (1.0 + cos)).max(0.0).sqrt() as f32;
                let (sin_phi, cos_phi) = (std::f32::consts::TAU * u.y).sin_cos();
                let local = Vec3A::new(sin * cos_phi, sin * sin_phi, cos as f32);
                let wi = Frame::from_z(ray_dir).to_world(local).normalize();
                // The density of the sampled cosine, from the f64 cosine itself (no
                // renormalised vectors): `eval` of the stored f32 direction agrees to ~1e-6.
                let gd = f64::from(g);
                (wi, hg_from_denominator(gd, 1.0 + gd * gd - 2.0 * gd * cos))
            }
            _ => {
                let wi = uniform_sphere(u);
                (wi, self.eval(ray_dir, wi))
            }
        }
    }
}

/// The largest f32 below 1.
const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

/// The Rayleigh density for the cosine between travel and new direction.
#[inline]
pub fn rayleigh(cos: f32) -> f32 {
    (3.0 / (16.0 * std::f32::consts::PI)) * (1.0 + cos * cos)
}

/// Inverse CDF of the Rayleigh cosine distribution: the real root of
/// `c^3 + 3 c + 4 - 8 u = 0`, `a - 1 / a` with `a = cbrt(z + sqrt(z^2 + 1))`, `z = 4 u - 2`
/// (Cardano), taken for `z >= 0` and mirrored, where it does not cancel.
#[inline]
fn sample_rayleigh_cos(u: f32) -> f32 {
    let z = 4.0 * f64::from(u) - 2.0;
    let a = (z.abs() + (z * z + 1.0).sqrt()).cbrt();
    ((a - 1.0 / a).copysign(z) as f32).clamp(-1.0, 1.0)
}

/// The Henyey-Greenstein density for the cosine between travel and new direction.
#[inline]
pub fn hg(g: f32, cos: f32) -> f32 {
    let (g, cos) = (g as f64, cos.clamp(-1.0, 1.0) as f64);
    hg_from_denominator(g, 1.0 + g * g - 2.0 * g * cos)
}

/// The Henyey-Greenstein density between two directions. Near the peak (|g| -> 1) the
/// denominator 1 + g^2 - 2 g cos cancels to (1 - |g|)^2, finer than an f32 cosine resolves, so
/// it is rebuilt from the chord |a -+ b|^2 = 2 (1 -+ cos), which keeps full precision there.
#[inline]
fn hg_vectors(g: f32, a: Vec3A, b: Vec3A) -> f32 {
    if g.abs() <= HG_SINGLE_G {
        // The denominator stays above (1 - |g|)^2 = 0.09: single precision keeps it to 1e-6,
        // for a third of the time (it runs for every next-event estimate and mixture density).
        let denom = 1.0 + g * g - 2.0 * g * a.dot(b).clamp(-1.0, 1.0);
        return (1.0 - g * g) * (0.25 / std::f32::consts::PI) / (denom * denom.sqrt());
    }
    let g = g as f64;
    // Renormalised in f64: an f32 length error of 1e-7 would swamp (1 - |g|)^2 otherwise.
    let (a, b) = (a.as_dvec3().normalize(), b.as_dvec3().normalize());
    let denom = if g >= 0.0 {
        (1.0 - g) * (1.0 - g) + g * (a - b).length_squared()
    } else {
        (1.0 + g) * (1.0 + g) - g * (a + b).length_squared()
    };
    hg_from_denominator(g, denom)
}

#[inline]
fn hg_from_denominator(g: f64, denom: f64) -> f32 {
    ((1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())) as f32
}

/// Inverse CDF of the Henyey-Greenstein cosine distribution.
#[inline]
fn sample_hg_cos(g: f32, u: f32) -> f64 {
    let (g, u) = (g as f64, u as f64);
    let s = (1.0 - g * g) / (1.0 + g - 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;
    use glam::DVec3;
    use zerovar_testkit::SphereGrid;

    const GS: [f32; 9] = [-0.999, -0.9, -0.5, -0.01, 0.0, 1e-5, 0.3, 0.9, 0.999];

    fn phase(g: f32) -> PhaseFunction {
        if g == 0.0 { PhaseFunction::Isotropic } else { PhaseFunction::HenyeyGreenstein { g } }
    }

    // The HG peak is about (1 - |g|) wide with a theta^-3 tail; grading the grid at ten peak
    // widths resolves both (8-point Gauss-Legendre per bin integrates HG to 1e-5 this way).
    fn grid_for(g: f32, axis: Vec3A) -> SphereGrid {
        let dir = if g >= 0.0 { axis } else { -axis };
        let width = 1.0 - g.abs() as f64;
        let theta_scale = if g.abs() > 0.1 { 10.0 * width } else { f64::INFINITY };
        SphereGrid { axis: dir.as_dvec3(), theta_scale, n_theta: 48, n_phi: 8 }
    }

    #[test]
    fn pdf_integrates_to_one() {
        let axis = Vec3A::new(0.3, -0.5, 0.8).normalize();
        for g in GS {
            let p = phase(g);
            let grid = grid_for(g, axis);
            let total = grid.integrate(&|d: DVec3| p.eval(axis, d.as_vec3a()) as f64);
            assert!((total - 1.0).abs() < 1e-4, "g={g}: integral {total}");
        }
    }

    #[test]
    fn samples_follow_pdf() {
        let axis = Vec3A::new(-0.2, 0.9, 0.1).normalize();
        for g in GS {
            let p = phase(g);
            let mut s = Sampler::new(7, g.to_bits() as u64, 0);
            let mut dirs = Vec::with_capacity(200_000);
            for _ in 0..200_000 {
                let (d, pdf) = p.sample(axis, s.next_2d());
                let e = p.eval(axis, d);
                assert!((pdf - e).abs() <= 1e-3 * e, "g={g}: pdf {pdf} vs eval {e}");
                dirs.push(d.as_dvec3());
            }
            let grid = grid_for(g, axis);
            grid.chi2(&dirs, &|d: DVec3| p.eval(axis, d.as_vec3a()) as f64)
                .assert_pass(1e-3, &format!("HG g={g}"));
        }
    }

    /// Rayleigh and blends of two lobes: densities that integrate to one, samples that follow
    /// them (with the density `sample` returns equal to `eval`), and the blend's mean cosine.
    #[test]
    fn rayleigh_and_blends_sample_their_densities() {
        let axis = Vec3A::new(0.4, 0.1, -0.9).normalize();
        let hg = |g| Lobe::HenyeyGreenstein { g };
        let cases = [
            (PhaseFunction::Rayleigh, 0.0),
            (PhaseFunction::Blend { weight: 0.3, first: hg(0.8), second: hg(-0.4) }, 0.44),
            (
                PhaseFunction::Blend {
                    weight: 0.5,
                    first: Lobe::Isotropic,
                    second: Lobe::Rayleigh,
                },
                0.0,
            ),
            (PhaseFunction::Blend { weight: 1.0, first: hg(0.5), second: hg(0.9) }, 0.9),
            (PhaseFunction::Blend { weight: 0.0, first: hg(0.5), second: hg(0.9) }, 0.5),
        ];
        for (k, (p, mean)) in cases.into_iter().enumerate() {
            assert!((p.mean_cosine() - mean).abs() < 1e-6, "{p:?}");
            let grid =
                SphereGrid { axis: axis.as_dvec3(), theta_scale: 0.5, n_theta: 48, n_phi: 8 };
            let total = grid.integrate(&|d: DVec3| p.eval(axis, d.as_vec3a()) as f64);
            assert!((total - 1.0).abs() < 1e-4, "{p:?}: integral {total}");
            let mut s = Sampler::new(9, k as u64, 0);
            let mut dirs = Vec::with_capacity(200_000);
            let mut cosines = zerovar_testkit::MeanEstimate::default();
            for _ in 0..200_000 {
                let (d, pdf) = p.sample(axis, s.next_2d());
                let e = p.eval(axis, d);
                assert!((pdf - e).abs() <= 1e-5 * e, "{p:?}: pdf {pdf} vs eval {e}");
                cosines.push(f64::from(d.dot(axis)));
                dirs.push(d.as_dvec3());
            }
            grid.chi2(&dirs, &|d: DVec3| p.eval(axis, d.as_vec3a()) as f64)
                .assert_pass(1e-3, &format!("{p:?}"));
            cosines.assert_matches(f64::from(mean), 4.5, &format!("mean cosine of {p:?}"));
        }
    }

    #[test]
    fn mean_cosine_is_g() {
        let axis = Vec3A::Z;
        for g in [-0.9f32, -0.3, 0.5, 0.95] {
            let p = phase(g);
            let mut s = Sampler::new(3, 1, 0);
            let est: zerovar_testkit::MeanEstimate =
                (0..100_000).map(|_| p.sample(axis, s.next_2d()).0.z as f64).collect();
            est.assert_matches(g as f64, 4.5, &format!("mean cosine, g={g}"));
        }
    }
}
