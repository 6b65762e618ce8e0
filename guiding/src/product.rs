//! Closed-form products of vMF lobes, and the fixed-capacity lobe sets that hold the products
//! of an incident-radiance mixture with a phase function or a clamped cosine.
//!
//! The product of two vMF densities is an unnormalised vMF density:
//! `vMF(w; m1, k1) vMF(w; m2, k2) = I vMF(w; m, k)` with `k m = k1 m1 + k2 m2` and
//! `I = N(k1) N(k2) / N(k) exp(k - k1 - k2)`, where `N` is the normalisation. `I` is also the
//! convolution of the two lobes evaluated at the angle between their means, which is how the
//! in-scattered radiance is computed. Its exponent is never positive and is evaluated as
//! `-k1 k2 |m1 - m2|^2 / (k + k1 + k2)`, free of cancellation; everything is kept in logarithms
//! until the weights of a whole product mixture are normalised, so opposing sharp lobes whose
//! product integral underflows every float still give a usable, normalised mixture.

use crate::mixture::{ONE_BELOW, pick};
use crate::vmf;
use glam::{DVec3, Vec2, Vec3};

/// The product lobe of two vMF lobes and the logarithm of the integral of their product.
///
/// Returns `(mean, kappa, ln I)`. When the lobes cancel (`kappa` of the product is zero) the
/// mean is `mean_a`, which is irrelevant for a uniform lobe.
#[inline]
pub fn vmf_product(mean_a: Vec3, kappa_a: f32, mean_b: Vec3, kappa_b: f32) -> (Vec3, f32, f64) {
    let (ka, kb) = (f64::from(kappa_a), f64::from(kappa_b));
    let (ma, mb) = (mean_a.as_dvec3(), mean_b.as_dvec3());
    let sum: DVec3 = ma * ka + mb * kb;
    let k = sum.length();
    let denom = k + ka + kb;
    let exponent = if denom > 0.0 { -ka * kb * (ma - mb).length_squared() / denom } else { 0.0 };
    let log_i = vmf::log_normalization(ka) + vmf::log_normalization(kb) - vmf::log_normalization(k)
        + exponent;
    let mean = if k > 1e-12 * denom && k > 0.0 { (sum / k).as_vec3() } else { mean_a };
    (mean, k as f32, log_i)
}

/// The integral over the sphere of the product of two normalised vMF lobes, which is also
/// their convolution at the angle between the means.
#[inline]
pub fn vmf_product_integral(mean_a: Vec3, kappa_a: f32, mean_b: Vec3, kappa_b: f32) -> f64 {
    vmf_product(mean_a, kappa_a, mean_b, kappa_b).2.exp()
}

/// The vMF lobe used for the clamped cosine `max(0, dot(n, w))` of diffuse surfaces; its
/// shape is the least-squares fit that Open PGL also uses.
pub const COSINE_KAPPA: f32 = 2.188_53;

/// Most lobes the second factor of a product may have (a phase-function fit or a cosine).
const MAX_FACTOR_LOBES: usize = 8;

/// A fixed-capacity set of weighted vMF lobes in structure-of-arrays form, with the weight
/// and the normalisation multiplied together for evaluation.
#[derive(Clone, Debug)]
pub(crate) struct LobeSet<const N: usize> {
    mean: [Vec3; N],
    kappa: [f32; N],
    weight: [f32; N],
    norm: [f32; N],
    weighted_norm: [f32; N],
    len: usize,
}

impl<const N: usize> Default for LobeSet<N> {
    fn default() -> Self {
        let mut s = Self {
            mean: [Vec3::Z; N],
            kappa: [0.0; N],
            weight: [0.0; N],
            norm: [0.0; N],
            weighted_norm: [0.0; N],
            len: 0,
        };
        s.set_uniform();
        s
    }
}

impl<const N: usize> LobeSet<N> {
    pub(crate) fn set_uniform(&mut self) {
        self.len = 1;
        self.mean[0] = Vec3::Z;
        self.kappa[0] = 0.0;
        self.weight[0] = 1.0;
        self.norm[0] = vmf::normalization(0.0);
        self.weighted_norm[0] = self.norm[0];
    }

    pub(crate) fn len(&self) -> usize {
        self.len
    }

    pub(crate) fn lobe(&self, k: usize) -> (Vec3, f32, f32) {
        (self.mean[k], self.kappa[k], self.weight[k])
    }

    /// The normalisation of lobe `k`.
    pub(crate) fn norm(&self, k: usize) -> f32 {
        self.norm[k]
    }

    /// Copies a mixture (weights summing to one, normalisations cached).
    pub(crate) fn set_from(&mut self, mixture: &crate::Mixture) {
        let n = mixture.len().min(N);
        for (k, (l, &norm)) in mixture.lobes()[..n].iter().zip(mixture.norms()).enumerate() {
            self.mean[k] = l.mean;
            self.kappa[k] = l.kappa;
            self.weight[k] = l.weight;
            self.norm[k] = norm;
            self.weighted_norm[k] = l.weight * norm;
        }
        self.len = n;
    }

    /// Sets this set to the normalised product of `base` with the mixture `factor` (lobes
    /// given as mean, kappa, weight). Returns false, leaving the set as `factor` alone, when
    /// the product has no usable weight (only possible for corrupt input).
    ///
    /// Each product weight is `w_k w_i N_k N_i / N(k') exp(e)`, `e` the (non-positive)
    /// exponent of the product integral. The factors before `exp` stay within f64 range for
    /// any kappa up to 1e6, so only `exp(e)` could underflow: it is taken relative to the
    /// largest exponent, which makes the largest term exactly representable.
    pub(crate) fn set_product<const M: usize>(
        &mut self,
        base: &LobeSet<M>,
        factor: &[(Vec3, f32, f32)],
    ) -> bool {
        let mut linear = [0.0f64; N];
        let mut exponent = [0.0f64; N];
        let mut max = f64::NEG_INFINITY;
        let mut n = 0;
        debug_assert!(factor.len() <= MAX_FACTOR_LOBES);
        let factor_norms: [f64; MAX_FACTOR_LOBES] = std::array::from_fn(|i| {
            factor.get(i).map_or(0.0, |f| vmf::normalization_f64(f64::from(f.1)))
        });
        for k in 0..base.len {
            if base.weight[k] <= 0.0 {
                continue;
            }
            let (ma, ka) = (base.mean[k].as_dvec3(), f64::from(base.kappa[k]));
            let lin_base = f64::from(base.weight[k]) * f64::from(base.norm[k]);
            for (i, &(fm, fk, fw)) in factor.iter().enumerate().take(MAX_FACTOR_LOBES) {
                if fw <= 0.0 || n == N {
                    continue;
                }
                let (mb, kb) = (fm.as_dvec3(), f64::from(fk));
                let sum = ma * ka + mb * kb;
                let kp = sum.length();
                let denom = kp + ka + kb;
                let e =
                    if denom > 0.0 { -ka * kb * (ma - mb).length_squared() / denom } else { 0.0 };
                // Divisions dominate this loop (32 products per HG product): one reciprocal
                // serves the mean and the normalisation.
                let inv_norm = vmf::inverse_normalization_f64(kp);
                self.mean[n] = if kp > 1e-12 * denom && kp > 0.0 {
                    (sum * (1.0 / kp)).as_vec3()
                } else {
                    base.mean[k]
                };
                self.kappa[n] = kp as f32;
                self.norm[n] = (1.0 / inv_norm) as f32;
                linear[n] = lin_base * f64::from(fw) * factor_norms[i] * inv_norm;
                exponent[n] = e;
                max = max.max(e);
                n += 1;
            }
        }
        let mut total = 0.0;
        for (l, &e) in linear[..n].iter_mut().zip(&exponent[..n]) {
            // Single precision suffices: the result is a weight stored as f32, and a term whose
            // exponent lies 87 below the largest one (where f32 underflows) weighs nothing.
            *l *= f64::from(((e - max) as f32).exp());
            total += *l;
        }
        if n == 0 || !(total.is_finite() && total > 0.0 && max.is_finite()) {
            self.set_factor(factor);
            return false;
        }
        let inv = 1.0 / total;
        for (k, &l) in linear[..n].iter().enumerate() {
            let w = (l * inv) as f32;
            self.weight[k] = w;
            self.weighted_norm[k] = w * self.norm[k];
        }
        self.len = n;
        true
    }

    /// Sets this set to the lobes of `base` with lobe `k`'s weight multiplied by
    /// `factor(mean, kappa)`, renormalised. Returns false when no weight is left (a factor
    /// that is zero, negative or not finite everywhere); the set is then not usable.
    pub(crate) fn set_reweighted<const M: usize>(
        &mut self,
        base: &LobeSet<M>,
        factor: impl Fn(Vec3, f32) -> f32,
    ) -> bool {
        let n = base.len.min(N);
        let mut total = 0.0f32;
        for k in 0..n {
            let w = base.weight[k] * factor(base.mean[k], base.kappa[k]);
            self.weight[k] = if w > 0.0 && w.is_finite() { w } else { 0.0 };
            total += self.weight[k];
        }
        if !(total > 0.0 && total.is_finite()) {
            return false;
        }
        let inv = 1.0 / total;
        for k in 0..n {
            self.mean[k] = base.mean[k];
            self.kappa[k] = base.kappa[k];
            self.norm[k] = base.norm[k];
            self.weight[k] *= inv;
            self.weighted_norm[k] = self.weight[k] * self.norm[k];
        }
        self.len = n;
        true
    }

    fn set_factor(&mut self, factor: &[(Vec3, f32, f32)]) {
        let total: f32 = factor.iter().map(|f| f.2.max(0.0)).sum();
        if !(total > 0.0 && total.is_finite()) {
            self.set_uniform();
            return;
        }
        let mut n = 0;
        for &(m, k, w) in factor.iter().take(N) {
            self.mean[n] = m;
            self.kappa[n] = k;
            self.weight[n] = w.max(0.0) / total;
            self.norm[n] = vmf::normalization(k);
            self.weighted_norm[n] = self.weight[n] * self.norm[n];
            n += 1;
        }
        self.len = n;
    }

    #[inline]
    pub(crate) fn pdf(&self, dir: Vec3) -> f32 {
        let n = self.len;
        let mut p = 0.0;
        for k in 0..n {
            p += self.weighted_norm[k]
                * (self.kappa[k] * vmf::cos_minus_one(self.mean[k], dir)).exp();
        }
        p
    }

    #[inline]
    pub(crate) fn sample(&self, u: Vec2) -> Vec3 {
        let n = self.len;
        let (k, ux) = pick(self.weight[..n].iter().copied(), n, u.x.min(ONE_BELOW));
        vmf::sample(self.mean[k], self.kappa[k], Vec2::new(ux, u.y))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zerovar_testkit::SphereGrid;

    #[test]
    fn product_integral_matches_quadrature() {
        let cases = [
            (Vec3::Z, 5.0f32, Vec3::new(0.3, 0.0, 1.0).normalize(), 20.0f32),
            (Vec3::Z, 0.0, Vec3::X, 100.0),
            (Vec3::Z, 1e3, Vec3::new(0.01, 0.0, 1.0).normalize(), 1e3),
            (Vec3::Z, 3.0, -Vec3::Z, 3.0),
            (Vec3::Y, 1e-6, Vec3::X, 1e-3),
        ];
        for &(ma, ka, mb, kb) in &cases {
            let (mean, kappa, log_i) = vmf_product(ma, ka, mb, kb);
            let la = vmf::VmfLobe { mean: ma, kappa: ka, weight: 1.0 };
            let lb = vmf::VmfLobe { mean: mb, kappa: kb, weight: 1.0 };
            let sharp = if ka > kb { (ma, ka) } else { (mb, kb) };
            let grid = SphereGrid::for_lobe(sharp.0.as_dvec3(), f64::from(sharp.1));
            let integral = grid.integrate(&|d: DVec3| {
                f64::from(la.pdf(d.as_vec3())) * f64::from(lb.pdf(d.as_vec3()))
            });
            let rel = (log_i.exp() - integral).abs() / integral;
            assert!(rel < 1e-4, "{ka} {kb}: closed form {} vs quadrature {integral}", log_i.exp());
            // The product is proportional to the product lobe.
            let lp = vmf::VmfLobe { mean, kappa, weight: 1.0 };
            for d in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::new(0.2, 0.3, 0.9).normalize()] {
                let lhs = f64::from(la.pdf(d)) * f64::from(lb.pdf(d));
                let rhs = log_i.exp() * f64::from(lp.pdf(d));
                assert!((lhs - rhs).abs() <= 1e-4 * lhs.max(1e-30), "{lhs} {rhs}");
            }
        }
    }

    #[test]
    fn opposing_sharp_lobes_do_not_underflow_to_nan() {
        let (_, k, log_i) = vmf_product(Vec3::Z, 1e6, -Vec3::Z, 1e6);
        assert_eq!(k, 0.0);
        assert!(log_i.is_finite() && log_i < -1e6);
        let mut base = LobeSet::<4>::default();
        base.set_from(
            &crate::Mixture::new(&[vmf::VmfLobe { mean: Vec3::Z, kappa: 1e6, weight: 1.0 }])
                .unwrap(),
        );
        let mut prod = LobeSet::<4>::default();
        assert!(prod.set_product(&base, &[(-Vec3::Z, 1e6, 1.0)]));
        assert_eq!(prod.len(), 1);
        assert!((prod.pdf(Vec3::X) - 1.0 / (4.0 * std::f32::consts::PI)).abs() < 1e-6);
    }
}
