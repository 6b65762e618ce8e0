//! The von Mises-Fisher (vMF) lobe on the unit sphere: density, sampling, and the mean cosine
//! A(kappa) with its inverse.
//!
//! Every formula here is written in the form that stays finite and accurate for concentrations
//! from 0 to 1e6 (methods.md, "numerically hard cases"):
//! - the density is `kappa / (2 pi (1 - exp(-2 kappa))) * exp(kappa (cos - 1))`, whose exponent
//!   is never positive, with `expm1` for the normalisation and the limit `1 / (4 pi)` at 0;
//! - `cos - 1` is computed as `-|d - mu|^2 / 2`, which keeps full precision for the nearly
//!   aligned directions where sharp lobes live (`cos` itself has no digits left there);
//! - sampling draws `b = cos - 1 = ln(1 + u expm1(-2 kappa)) / kappa` with `ln_1p`, and the sine
//!   from `sin^2 = -b (2 + b)`, never from `1 - cos^2`.

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Concentrations below this are treated as exactly uniform by the series expansions.
const KAPPA_SERIES: f64 = 1e-6;

/// Above this, `e^{-2 kappa}` is below half an ulp of one in f64.
const KAPPA_LARGE: f64 = 20.0;

/// One weighted vMF lobe. In a [`Mixture`](crate::Mixture) the weights sum to one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct VmfLobe {
    /// Unit mean direction.
    pub mean: Vec3,
    /// Concentration (0 is uniform; the width is about `1 / sqrt(kappa)` radians).
    pub kappa: f32,
    /// Mixture weight.
    pub weight: f32,
}

impl Default for VmfLobe {
    fn default() -> Self {
        Self { mean: Vec3::Z, kappa: 0.0, weight: 0.0 }
    }
}

impl VmfLobe {
    /// The normalised density of this lobe at the unit direction `dir` (the weight is ignored).
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        normalization(self.kappa) * (self.kappa * cos_minus_one(self.mean, dir)).exp()
    }

    /// Draws a direction from this lobe (the weight is ignored).
    #[inline]
    pub fn sample(&self, u: Vec2) -> Vec3 {
        sample(self.mean, self.kappa, u)
    }
}

/// `dot(a, b) - 1` for unit vectors, exact to rounding even when `a` and `b` nearly coincide.
#[inline]
pub fn cos_minus_one(a: Vec3, b: Vec3) -> f32 {
    -0.5 * (a - b).length_squared()
}

/// The vMF normalisation `kappa / (2 pi (1 - exp(-2 kappa)))`, so that the density is
/// `normalization(kappa) * exp(kappa (cos - 1))`. Equals `1 / (4 pi)` at `kappa = 0`.
#[inline]
pub fn normalization(kappa: f32) -> f32 {
    normalization_f64(f64::from(kappa)) as f32
}

/// [`normalization`] in double precision.
#[inline]
pub fn normalization_f64(kappa: f64) -> f64 {
    if kappa < KAPPA_SERIES {
        // kappa / (1 - e^{-2 kappa}) = (1 + kappa + kappa^2 / 3 + ...) / 2.
        (1.0 + kappa) / (4.0 * PI)
    } else if kappa > KAPPA_LARGE {
        // 1 - e^{-2 kappa} rounds to 1: skip expm1 on the hot path.
        kappa * (0.5 / PI)
    } else {
        kappa * (0.5 / PI) / one_minus_exp_minus_2(kappa)
    }
}

/// `1 / normalization_f64(kappa)`, `2 pi (1 - exp(-2 kappa)) / kappa`, without dividing by
/// the normalisation.
#[inline]
pub fn inverse_normalization_f64(kappa: f64) -> f64 {
    if kappa < KAPPA_SERIES {
        // 4 pi / (1 + kappa), to first order, as the series of `normalization_f64`.
        4.0 * PI * (1.0 - kappa)
    } else if kappa > KAPPA_LARGE {
        2.0 * PI / kappa
    } else {
        2.0 * PI * one_minus_exp_minus_2(kappa) / kappa
    }
}

/// `1 - exp(-2 kappa)` for `kappa > 0`: expm1 where it matters, and the several times cheaper
/// exp for `2 kappa > 0.5`, where the subtraction loses under two bits (products of mixtures
/// compute one per product lobe, 32 per HG product).
#[inline]
fn one_minus_exp_minus_2(kappa: f64) -> f64 {
    if kappa > 0.25 { 1.0 - (-2.0 * kappa).exp() } else { -(-2.0 * kappa).exp_m1() }
}

/// The natural logarithm of [`normalization_f64`], finite for every `kappa >= 0`.
#[inline]
pub fn log_normalization(kappa: f64) -> f64 {
    if kappa < KAPPA_SERIES {
        kappa.ln_1p() - (4.0 * PI).ln()
    } else {
        kappa.ln() - (2.0 * PI).ln() - (-(-2.0 * kappa).exp_m1()).ln()
    }
}

/// Draws a direction from the vMF lobe with unit mean `mean` and concentration `kappa`, from
/// two uniform numbers in `[0, 1)`.
///
/// `u.x` picks `cos theta` by inverting the CDF; `u.y` picks the azimuth.
#[inline]
pub fn sample(mean: Vec3, kappa: f32, u: Vec2) -> Vec3 {
    let b = sample_cos_minus_one(kappa, u.x);
    let sin_theta = (-b * (2.0 + b)).max(0.0).sqrt();
    let (sin_phi, cos_phi) = (std::f32::consts::TAU * u.y).sin_cos();
    let (t, s) = mean.any_orthonormal_pair();
    (t * (sin_theta * cos_phi) + s * (sin_theta * sin_phi) + mean * (1.0 + b)).normalize()
}

/// `cos theta - 1` of a vMF sample: `ln(1 - u + u exp(-2 kappa)) / kappa`, in `[-2, 0]`.
/// In single precision: `expm1` and `ln_1p` keep it to a few ulps relative even where it is
/// tiny (kappa 1e6), and the sampler runs once per guided vertex.
#[inline]
fn sample_cos_minus_one(kappa: f32, u: f32) -> f32 {
    let b = if f64::from(kappa) < KAPPA_SERIES {
        -2.0 * u
    } else {
        // exp(-2 kappa) is below f32's rounding of 1 long before KAPPA_LARGE.
        let m = if f64::from(kappa) > KAPPA_LARGE { -1.0 } else { (-2.0 * kappa).exp_m1() };
        (u * m).ln_1p() / kappa
    };
    b.clamp(-2.0, 0.0)
}

/// The mean cosine `A(kappa) = coth(kappa) - 1/kappa` of a vMF lobe (its mean resultant length).
#[inline]
pub fn mean_cosine(kappa: f32) -> f32 {
    mean_cosine_f64(f64::from(kappa)) as f32
}

/// [`mean_cosine`] in double precision.
pub fn mean_cosine_f64(kappa: f64) -> f64 {
    if kappa <= 0.0 {
        0.0
    } else if kappa < 0.05 {
        // coth and 1/kappa cancel; the series is exact to ~1e-13 relative here.
        let k2 = kappa * kappa;
        kappa * (1.0 / 3.0 - k2 * (1.0 / 45.0 - k2 * (2.0 / 945.0)))
    } else {
        // coth(kappa) = 1 + 2 / expm1(2 kappa), which does not overflow.
        1.0 + 2.0 / (2.0 * kappa).exp_m1() - 1.0 / kappa
    }
}

/// dA/dkappa = 1/kappa^2 - 1/sinh^2(kappa), written to avoid cancellation and overflow.
fn mean_cosine_derivative(kappa: f64) -> f64 {
    if kappa < 0.05 {
        let k2 = kappa * kappa;
        1.0 / 3.0 - k2 * (1.0 / 15.0 - k2 * (2.0 / 189.0))
    } else {
        let e = (-2.0 * kappa).exp();
        1.0 / (kappa * kappa) - 4.0 * e / ((1.0 - e) * (1.0 - e))
    }
}

/// The concentration whose mean cosine is `r`: the inverse of [`mean_cosine`]. Values of `r`
/// at or below 0 give 0; values at or above 1 give `f32::MAX`-free large concentrations, so
/// callers should clamp `r` (the EM clamps it to `A(max_kappa)`).
#[inline]
pub fn kappa_from_mean_cosine(r: f32) -> f32 {
    kappa_from_mean_cosine_f64(f64::from(r)) as f32
}

/// [`kappa_from_mean_cosine`] in double precision: safeguarded Newton iteration, accurate to
/// about 1e-12 relative over the whole range.
pub fn kappa_from_mean_cosine_f64(r: f64) -> f64 {
    if r.is_nan() || r <= 0.0 {
        return 0.0;
    }
    if r >= 1.0 {
        return 1e12;
    }
    // Bracket [lo, hi] with A(lo) <= r <= A(hi); A(k) < 1 - 1/k + 2 e^{-2k} gives the upper end.
    let (mut lo, mut hi) = (0.0f64, (1.0 / (1.0 - r)).max(3.0 * r) + 1.0);
    // Banerjee's approximation is a good start everywhere.
    let mut k = (r * (3.0 - r * r) / (1.0 - r * r)).clamp(lo, hi);
    for _ in 0..100 {
        let f = mean_cosine_f64(k) - r;
        if f > 0.0 {
            hi = k;
        } else {
            lo = k;
        }
        let d = mean_cosine_derivative(k);
        let mut next = k - f / d;
        if !(next > lo && next < hi && next.is_finite()) {
            next = 0.5 * (lo + hi);
        }
        if (next - k).abs() <= 1e-14 * k.max(1e-300) {
            return next;
        }
        k = next;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use rand_pcg::Pcg32;

    #[test]
    fn normalization_and_its_inverse_agree_with_the_expm1_form() {
        // Across the switch from expm1 to exp at kappa = 0.25 and up to the large-kappa form:
        // the cheap form loses under two bits (relative error a few 1e-16).
        for kappa in [1e-5f64, 0.1, 0.249, 0.25, 0.2500001, 0.3, 1.0, 5.0, 19.9, 20.1, 1e3] {
            let exact = kappa / (2.0 * PI * -(-2.0 * kappa).exp_m1());
            let n = normalization_f64(kappa);
            assert!((n / exact - 1.0).abs() < 2e-15, "kappa {kappa}: {n} vs {exact}");
            let inv = inverse_normalization_f64(kappa);
            assert!((inv * exact - 1.0).abs() < 2e-15, "kappa {kappa}: inverse {inv}");
        }
    }
    use rand_pcg::rand_core::Rng;
    use zerovar_testkit::{MeanEstimate, SphereGrid};

    pub(crate) const KAPPAS: [f32; 7] = [0.0, 1e-6, 1e-3, 1.0, 100.0, 1e4, 1e6];

    fn uniform(rng: &mut Pcg32) -> f32 {
        (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    fn axis() -> Vec3 {
        Vec3::new(0.3, -0.5, 0.8).normalize()
    }

    #[test]
    fn pdf_integrates_to_one() {
        for &kappa in &KAPPAS {
            let lobe = VmfLobe { mean: axis(), kappa, weight: 1.0 };
            let grid = SphereGrid::for_lobe(axis().as_dvec3(), f64::from(kappa));
            let integral = grid.integrate(&|d: DVec3| f64::from(lobe.pdf(d.as_vec3())));
            assert!((integral - 1.0).abs() < 1e-4, "kappa {kappa}: integral {integral}");
        }
    }

    #[test]
    fn samples_follow_the_pdf() {
        let mut rng = Pcg32::new(7, 11);
        for &kappa in &KAPPAS {
            let lobe = VmfLobe { mean: axis(), kappa, weight: 1.0 };
            let samples: Vec<DVec3> = (0..40_000)
                .map(|_| lobe.sample(Vec2::new(uniform(&mut rng), uniform(&mut rng))).as_dvec3())
                .collect();
            let grid = SphereGrid::for_lobe(axis().as_dvec3(), f64::from(kappa));
            grid.chi2(&samples, &|d: DVec3| f64::from(lobe.pdf(d.as_vec3())))
                .assert_pass(1e-3, &format!("vMF kappa {kappa}"));
        }
    }

    #[test]
    fn sampled_mean_cosine_is_a_of_kappa() {
        let mut rng = Pcg32::new(3, 5);
        for &kappa in &KAPPAS {
            let m: MeanEstimate = (0..100_000)
                .map(|_| {
                    let d = sample(axis(), kappa, Vec2::new(uniform(&mut rng), uniform(&mut rng)));
                    // cos - 1 keeps the digits a sharp lobe needs.
                    1.0 + f64::from(cos_minus_one(axis(), d))
                })
                .collect();
            m.assert_matches(mean_cosine_f64(f64::from(kappa)), 4.0, &format!("kappa {kappa}"));
        }
    }

    #[test]
    fn mean_cosine_matches_direct_formula_and_limits() {
        for &k in &[0.06f64, 0.5, 1.0, 3.0, 10.0] {
            let direct = 1.0 / k.tanh() - 1.0 / k;
            assert!((mean_cosine_f64(k) - direct).abs() < 1e-12, "kappa {k}");
        }
        // Series and closed form agree where they meet.
        let (a, b) = (mean_cosine_f64(0.0499999), mean_cosine_f64(0.0500001));
        assert!((a - b).abs() < 1e-7);
        assert_eq!(mean_cosine_f64(0.0), 0.0);
        assert!((mean_cosine_f64(1e6) - (1.0 - 1e-6)).abs() < 1e-15);
    }

    #[test]
    fn inverse_mean_cosine_round_trips() {
        let mut k = 1e-7f64;
        while k < 2e6 {
            let back = kappa_from_mean_cosine_f64(mean_cosine_f64(k));
            // A is flat in kappa for large kappa (dA = dk / k^2), so the round trip can only be
            // as good as the rounding of A: relative error ~ eps * k.
            let tol = 1e-9 + 4.0 * f64::EPSILON * k;
            assert!(((back - k) / k).abs() < tol, "kappa {k}: got {back}");
            k *= 1.7;
        }
        assert_eq!(kappa_from_mean_cosine_f64(0.0), 0.0);
        assert_eq!(kappa_from_mean_cosine_f64(-0.3), 0.0);
        // The f32 entry points agree within the conditioning of f32 (relative 1e-7 * kappa).
        for &k in &[1e-3f32, 0.5, 2.0, 50.0, 500.0] {
            let back = kappa_from_mean_cosine(mean_cosine(k));
            assert!(((back - k) / k).abs() < 1e-5 + 2e-7 * k, "kappa {k}: {back}");
        }
    }

    #[test]
    fn normalization_is_stable() {
        assert!((normalization_f64(0.0) - 1.0 / (4.0 * PI)).abs() < 1e-16);
        for &k in &KAPPAS {
            let k = f64::from(k);
            let n = normalization_f64(k);
            assert!(n.is_finite() && n > 0.0);
            assert!((log_normalization(k) - n.ln()).abs() < 1e-12);
        }
        assert!((normalization_f64(1e6) - 1e6 / (2.0 * PI)).abs() < 1e-6);
        // Continuity across the series threshold.
        let (a, b) = (normalization_f64(0.99e-6), normalization_f64(1.01e-6));
        assert!((a - b).abs() / a < 1e-7);
    }

    #[test]
    fn extreme_uniforms_give_unit_directions() {
        for &kappa in &KAPPAS {
            for &u in &[0.0f32, 1e-30, 0.5, 1.0 - f32::EPSILON] {
                let d = sample(axis(), kappa, Vec2::new(u, u));
                assert!(d.is_finite() && (d.length() - 1.0).abs() < 1e-5, "{kappa} {u} {d}");
            }
        }
    }
}
