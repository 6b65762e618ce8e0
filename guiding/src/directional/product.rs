//! Closed-form products of vMF lobes, and the fixed-capacity lobe sets that hold the products
//! of an incident-radiance mixture with a phase function or a clamped cosine.
//!
//! The product of two vMF densities is an unnormalised vMF density:
//! `vMF(w; m1, k1) vMF(w; m2, k2) = I vMF(w; m, k)` with `k m = k1 m1 + k2 m2` and
//! `I = N(k1) N(k2) / N(k) exp(k - k1 - k2)`, where `N` is the normalisation. `I` is also the
//! convolution of the two lobes evaluated at the angle between their means, which is how the
//! in-scattered radiance is computed. Its exponent is never positive and is evaluated as
//! `-k1 k2 |m1 - m2|^2 / (k + k1 + k2)`, free of cancellation. A product mixture whose
//! exponents all lie far below zero is formed relative to the largest, so opposing sharp lobes
//! whose product integral underflows every float still give a usable, normalised mixture.
//!
//! Lobe sets are blocks of eight lobes in structure-of-arrays form, evaluated a block at a
//! time with the branch-free functions of `lanes`, which the compiler vectorises.

// Lane loops index several arrays in step, the form the vectoriser turns into vector code.
#![allow(clippy::needless_range_loop)]

use crate::directional::lanes::{self, LANES};
use crate::directional::mixture::{MAX_LOBES, ONE_BELOW, pick};
use crate::directional::vmf;
use glam::{DVec3, Vec2, Vec3};
use std::f32::consts::PI;

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

/// One block of [`LANES`] lobes in structure-of-arrays form, the unit the lane-wise loops
/// work on. Lanes past a set's length carry zero weight (and a valid uniform lobe), so whole
/// blocks can be evaluated without masks.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Block {
    x: [f32; LANES],
    y: [f32; LANES],
    z: [f32; LANES],
    kappa: [f32; LANES],
    weight: [f32; LANES],
    /// The weight times the lobe's normalisation, the factor in front of the exponential in
    /// the density (the normalisation alone is never needed).
    weighted_norm: [f32; LANES],
}

impl Block {
    const EMPTY: Block = Block {
        x: [0.0; LANES],
        y: [0.0; LANES],
        z: [1.0; LANES],
        kappa: [0.0; LANES],
        weight: [0.0; LANES],
        weighted_norm: [0.0; LANES],
    };

    #[inline]
    fn set(&mut self, j: usize, mean: Vec3, kappa: f32, weight: f32, norm: f32) {
        (self.x[j], self.y[j], self.z[j]) = (mean.x, mean.y, mean.z);
        self.kappa[j] = kappa;
        self.weight[j] = weight;
        self.weighted_norm[j] = weight * norm;
    }

    #[inline]
    fn mean(&self, j: usize) -> Vec3 {
        Vec3::new(self.x[j], self.y[j], self.z[j])
    }
}

/// The product, lane by lane, of a block of lobes with one lobe about `axis` of
/// concentration `kb`: the product lobes' unnormalised means `kappa' m'`, their
/// concentrations, the exponents of the product integrals (`-inf` for lanes without weight)
/// and the reciprocals of the product lobes' normalisations.
#[derive(Clone, Copy, Default)]
struct BlockProduct {
    sx: [f32; LANES],
    sy: [f32; LANES],
    sz: [f32; LANES],
    kappa: [f32; LANES],
    exponent: [f32; LANES],
    inv_norm: [f32; LANES],
}

impl BlockProduct {
    /// `-ka kb |m - axis|^2 / (k' + ka + kb)` is the product integral's exponent in the form
    /// free of cancellation; `1 / N(k') = 4 pi (1 - e^{-2k'}) / (2k')`.
    #[inline(always)]
    fn new(b: &Block, axis: Vec3, kb: f32) -> Self {
        let mut p = BlockProduct::default();
        for j in 0..LANES {
            let ka = b.kappa[j];
            let sx = b.x[j] * ka + axis.x * kb;
            let sy = b.y[j] * ka + axis.y * kb;
            let sz = b.z[j] * ka + axis.z * kb;
            let k = (sx * sx + sy * sy + sz * sz).sqrt();
            (p.sx[j], p.sy[j], p.sz[j]) = (sx, sy, sz);
            let (dx, dy, dz) = (b.x[j] - axis.x, b.y[j] - axis.y, b.z[j] - axis.z);
            let denom = k + ka + kb;
            let e = -ka * kb * (dx * dx + dy * dy + dz * dz) / denom.max(f32::MIN_POSITIVE);
            p.kappa[j] = k;
            p.exponent[j] = if b.weight[j] > 0.0 { e } else { f32::NEG_INFINITY };
            p.inv_norm[j] = 4.0 * PI * lanes::one_minus_exp_neg_over(2.0 * k);
        }
        p
    }
}

/// A block's means re-aimed by `offset` times each lane's inverse source distance, unit
/// length (a lane keeps its mean bit for bit when its light comes from infinitely far, and
/// where the sum vanishes: the source at the query point). Written as whole-lane array
/// operations, which the compiler vectorises.
#[inline(always)]
fn shifted(b: &Block, inv: &[f32; LANES], offset: Vec3) -> [[f32; LANES]; 3] {
    let mut out = [[0.0; LANES]; 3];
    for j in 0..LANES {
        let x = b.x[j] + offset.x * inv[j];
        let y = b.y[j] + offset.y * inv[j];
        let z = b.z[j] + offset.z * inv[j];
        let len2 = x * x + y * y + z * z;
        let ok = len2 > 1e-12 && inv[j] > 0.0;
        let inv_len = 1.0 / len2.max(1e-12).sqrt();
        out[0][j] = if ok { x * inv_len } else { b.x[j] };
        out[1][j] = if ok { y * inv_len } else { b.y[j] };
        out[2][j] = if ok { z * inv_len } else { b.z[j] };
    }
    out
}

/// Adds each lane's weighted density at `dir` to `sum`, for the block's lobes with means
/// `mean` (its own, or re-aimed ones).
#[inline(always)]
fn add_density(sum: &mut [f32; LANES], b: &Block, mean: [&[f32; LANES]; 3], dir: Vec3) {
    for j in 0..LANES {
        let (dx, dy, dz) = (mean[0][j] - dir.x, mean[1][j] - dir.y, mean[2][j] - dir.z);
        // kappa (cos - 1), with cos - 1 = -|m - dir|^2 / 2 (see `vmf::cos_minus_one`).
        let e = -0.5 * b.kappa[j] * (dx * dx + dy * dy + dz * dz);
        sum[j] += b.weighted_norm[j] * lanes::exp(e);
    }
}

/// A fixed-capacity set of weighted vMF lobes: `B` blocks of [`LANES`] lobes.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct LobeSet<const B: usize> {
    blocks: [Block; B],
    len: usize,
}

impl<const B: usize> Default for LobeSet<B> {
    fn default() -> Self {
        let mut s = Self { blocks: [Block::EMPTY; B], len: 0 };
        s.set_uniform();
        s
    }
}

impl<const B: usize> LobeSet<B> {
    /// Most lobes the set holds.
    pub(crate) const CAPACITY: usize = B * LANES;

    pub(crate) fn set_uniform(&mut self) {
        self.blocks[0] = Block::EMPTY;
        self.blocks[0].set(0, Vec3::Z, 0.0, 1.0, vmf::normalization(0.0));
        self.len = 1;
    }

    /// The number of lanes in use (lobes, and lanes of zero weight between them).
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    pub(crate) fn blocks_used(&self) -> usize {
        self.len.div_ceil(LANES)
    }

    /// Gives the lanes from `len` to the end of their block zero weight.
    fn clear_tail(&mut self) {
        if let Some(b) = self.blocks.get_mut(self.len / LANES) {
            for j in self.len % LANES..LANES {
                b.set(j, Vec3::Z, 0.0, 0.0, 0.0);
            }
        }
    }

    /// Lobe `k` as (mean, kappa, weight).
    #[cfg(test)]
    pub(crate) fn lobe(&self, k: usize) -> (Vec3, f32, f32) {
        let (b, j) = (&self.blocks[k / LANES], k % LANES);
        (b.mean(j), b.kappa[j], b.weight[j])
    }

    /// Copies a mixture (weights summing to one, normalisations cached).
    pub(crate) fn set_from(&mut self, mixture: &crate::Mixture) {
        let n = mixture.len().min(Self::CAPACITY);
        for (k, (l, &norm)) in mixture.lobes()[..n].iter().zip(mixture.norms()).enumerate() {
            self.blocks[k / LANES].set(k % LANES, l.mean, l.kappa, l.weight, norm);
        }
        self.len = n;
        self.clear_tail();
    }

    /// Re-aims each lobe at the point its light comes from as seen from a point `offset`
    /// away from where the lobes were fitted: mean `m` becomes `normalize(m + offset
    /// inv_distance)`, i.e. `normalize(m d + pivot - x)` for `offset = pivot - x`. Lobes of
    /// light from infinitely far (inverse distance 0) keep their means, as does a lobe whose
    /// source lies at the query point itself.
    #[inline]
    pub(crate) fn shift_means(&mut self, inv_distance: &[[f32; LANES]], offset: Vec3) {
        let n = self.blocks_used();
        for (b, inv) in self.blocks[..n].iter_mut().zip(inv_distance) {
            [b.x, b.y, b.z] = shifted(b, inv, offset);
        }
    }

    /// The density of the lobes as [`shift_means`](Self::shift_means) would leave them,
    /// without changing the set.
    #[inline]
    pub(crate) fn pdf_shifted(
        &self,
        dir: Vec3,
        inv_distance: &[[f32; LANES]],
        offset: Vec3,
    ) -> f32 {
        let mut sum = [0.0f32; LANES];
        for (b, inv) in self.blocks[..self.blocks_used()].iter().zip(inv_distance) {
            let [x, y, z] = shifted(b, inv, offset);
            add_density(&mut sum, b, [&x, &y, &z], dir);
        }
        sum.iter().sum()
    }

    /// Copies `other`'s lobes (only the blocks in use).
    #[inline]
    pub(crate) fn copy_used_from(&mut self, other: &Self) {
        let n = other.blocks_used();
        self.blocks[..n].copy_from_slice(&other.blocks[..n]);
        self.len = other.len;
    }

    /// Sets this set to the normalised product of `base` with the mixture `factor` of lobes
    /// about one `axis` (given as kappa, weight). Returns false, leaving the set as `factor`
    /// alone, when the product has no usable weight (only possible for corrupt input).
    ///
    /// Each product weight is `w_k w_i N_k N_i / N(k') exp(e)`, `e` the (non-positive)
    /// exponent of the product integral. The factors before `exp` stay within f32 range for
    /// any kappa up to 1e6, so only `exp(e)` could underflow. Where even the largest
    /// exponent is far below zero (lobes facing away from each other) the products are formed
    /// again with `exp(e - max e)`, which makes the largest term exactly representable. Lanes
    /// without weight in `base` give lanes without weight here.
    pub(crate) fn set_product<const M: usize>(
        &mut self,
        base: &LobeSet<M>,
        axis: Vec3,
        factor: &[(f32, f32)],
    ) -> bool {
        // exp(-40) ~ 4e-18 leaves the weights' f32 range intact.
        const SHIFT_BELOW: f32 = -40.0;
        let (mut out, mut max, mut total) = self.fill_product(base, axis, factor, 0.0);
        if max < SHIFT_BELOW && max.is_finite() {
            (out, max, total) = self.fill_product(base, axis, factor, max);
        }
        if out == 0 || !(total.is_finite() && total > 0.0 && max.is_finite()) {
            self.set_factor(axis, factor);
            return false;
        }
        let inv = 1.0 / total;
        for o in &mut self.blocks[..out] {
            for j in 0..LANES {
                o.weight[j] *= inv;
                o.weighted_norm[j] *= inv;
            }
        }
        self.len = out * LANES;
        true
    }

    /// The products of [`set_product`](Self::set_product) with weights scaled by
    /// `exp(-shift)` and not normalised: returns the blocks filled, the largest exponent and
    /// the sum of the weights.
    #[inline(always)]
    fn fill_product<const M: usize>(
        &mut self,
        base: &LobeSet<M>,
        axis: Vec3,
        factor: &[(f32, f32)],
        shift: f32,
    ) -> (usize, f32, f32) {
        let mut lane_max = [f32::NEG_INFINITY; LANES];
        // Summed lane by lane: one running sum would be a chain of dependent additions.
        let mut lane_total = [0.0f32; LANES];
        let mut out = 0;
        for &(kb, fw) in factor.iter().filter(|f| f.1 > 0.0) {
            let factor_lin = fw / (4.0 * PI * lanes::one_minus_exp_neg_over(2.0 * kb));
            for b in &base.blocks[..base.blocks_used()] {
                if out == B {
                    break;
                }
                let p = BlockProduct::new(b, axis, kb);
                let o = &mut self.blocks[out];
                // Arithmetic in place of selects keeps this loop vector code.
                for j in 0..LANES {
                    let k = p.kappa[j];
                    let inv_k = 1.0 / k.max(f32::MIN_POSITIVE);
                    // A product that cancels exactly to uniform gets the axis as its mean
                    // (any unit vector would do).
                    let uniform = f32::from(u8::from(k <= 0.0));
                    o.x[j] = p.sx[j] * inv_k + axis.x * uniform;
                    o.y[j] = p.sy[j] * inv_k + axis.y * uniform;
                    o.z[j] = p.sz[j] * inv_k + axis.z * uniform;
                    o.kappa[j] = k;
                    // weight * norm: the product lobe's normalisation cancels.
                    let wn = b.weighted_norm[j] * factor_lin * lanes::exp(p.exponent[j] - shift);
                    o.weighted_norm[j] = wn;
                    o.weight[j] = wn * p.inv_norm[j];
                    lane_max[j] = lane_max[j].max(p.exponent[j]);
                    lane_total[j] += o.weight[j];
                }
                out += 1;
            }
        }
        let max = lane_max.iter().fold(f32::NEG_INFINITY, |m, &e| m.max(e));
        (out, max, lane_total.iter().sum())
    }

    /// The sum over this set's lobes and the lobes of `factor` about `axis` (kappa, weight) of
    /// `w_k w_i` times the integral of the two normalised lobes' product: the convolution of
    /// this mixture with the factor mixture, evaluated along `axis`.
    pub(crate) fn convolution(&self, axis: Vec3, factor: &[(f32, f32)]) -> f32 {
        let mut sum = [0.0f32; LANES];
        for &(kb, fw) in factor.iter().filter(|f| f.1 > 0.0) {
            let factor_lin = fw / (4.0 * PI * lanes::one_minus_exp_neg_over(2.0 * kb));
            for b in &self.blocks[..self.blocks_used()] {
                let p = BlockProduct::new(b, axis, kb);
                for j in 0..LANES {
                    sum[j] +=
                        b.weighted_norm[j] * factor_lin * p.inv_norm[j] * lanes::exp(p.exponent[j]);
                }
            }
        }
        sum.iter().sum()
    }

    /// Sets this set to the lobes of `base` with lobe `k`'s weight multiplied by
    /// `factor(mean, kappa, k)`, renormalised. Returns false when no weight is left (a factor
    /// that is zero, negative or not finite everywhere); the set is then not usable.
    pub(crate) fn set_reweighted<const M: usize>(
        &mut self,
        base: &LobeSet<M>,
        factor: impl Fn(Vec3, f32, usize) -> f32,
    ) -> bool {
        let blocks = base.blocks_used().min(B);
        let mut lane_total = [0.0f32; LANES];
        for (i, (o, b)) in self.blocks.iter_mut().zip(&base.blocks[..blocks]).enumerate() {
            *o = *b;
            for j in 0..LANES {
                let f = factor(b.mean(j), b.kappa[j], i * LANES + j);
                let w = b.weight[j] * f;
                // Also drops lanes without weight, whatever the factor makes of them.
                let keep = w > 0.0 && w < f32::INFINITY;
                o.weight[j] = if keep { w } else { 0.0 };
                o.weighted_norm[j] = if keep { b.weighted_norm[j] * f } else { 0.0 };
                lane_total[j] += o.weight[j];
            }
        }
        let total: f32 = lane_total.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return false;
        }
        let inv = 1.0 / total;
        for o in &mut self.blocks[..blocks] {
            for j in 0..LANES {
                o.weight[j] *= inv;
                o.weighted_norm[j] *= inv;
            }
        }
        self.len = base.len.min(Self::CAPACITY);
        true
    }

    fn set_factor(&mut self, axis: Vec3, factor: &[(f32, f32)]) {
        let total: f32 = factor.iter().map(|f| f.1.max(0.0)).sum();
        if !(total > 0.0 && total.is_finite()) {
            self.set_uniform();
            return;
        }
        let n = factor.len().min(Self::CAPACITY);
        for (i, &(k, w)) in factor[..n].iter().enumerate() {
            self.blocks[i / LANES].set(
                i % LANES,
                axis,
                k,
                w.max(0.0) / total,
                vmf::normalization(k),
            );
        }
        self.len = n;
        self.clear_tail();
    }

    /// The density at the unit direction `dir`.
    #[inline]
    pub(crate) fn pdf(&self, dir: Vec3) -> f32 {
        let mut sum = [0.0f32; LANES];
        for b in &self.blocks[..self.blocks_used()] {
            add_density(&mut sum, b, [&b.x, &b.y, &b.z], dir);
        }
        sum.iter().sum()
    }

    #[inline]
    pub(crate) fn sample(&self, u: Vec2) -> Vec3 {
        let weights = self.blocks.iter().flat_map(|b| b.weight).take(self.len);
        let (k, ux) = pick(weights, self.len, u.x.min(ONE_BELOW));
        let (b, j) = (&self.blocks[k / LANES], k % LANES);
        vmf::sample(b.mean(j), b.kappa[j], Vec2::new(ux, u.y))
    }
}

/// A region's mixture as the lane blocks a [`crate::VolumeDistribution`] works on, with each
/// lobe's mean cosine: derived from the mixture once per field update instead of at every
/// lookup (the transpose, and the mean cosines HG reweighting needs) and never saved.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct RegionLanes {
    pub(crate) lobes: LobeSet<{ MAX_LOBES / LANES }>,
    pub(crate) mean_cosine: [[f32; LANES]; MAX_LOBES / LANES],
    /// Each lobe's inverse source distance from the region's centre (0: infinitely far).
    pub(crate) inv_distance: [[f32; LANES]; MAX_LOBES / LANES],
    /// Whether any lobe has a finite source distance (else lookups skip re-aiming).
    pub(crate) parallax: bool,
    /// The mixture's first moment, `sum_i w_i A(kappa_i) mu_i`: its mean direction, whose
    /// length (0 to 1) says how concentrated the light is.
    pub(crate) mean_direction: glam::Vec3,
}

impl RegionLanes {
    pub(crate) fn new(mixture: &crate::Mixture, inv_distance: &[f32; MAX_LOBES]) -> Self {
        let mut lobes = LobeSet::default();
        lobes.set_from(mixture);
        let mut mean_cosine = [[0.0; LANES]; MAX_LOBES / LANES];
        for (m, b) in mean_cosine.iter_mut().zip(&lobes.blocks) {
            for j in 0..LANES {
                m[j] = lanes::mean_cosine(b.kappa[j]);
            }
        }
        let n = mixture.len();
        let inv: [[f32; LANES]; MAX_LOBES / LANES] = std::array::from_fn(|b| {
            std::array::from_fn(|j| {
                let k = b * LANES + j;
                if k < n { inv_distance[k] } else { 0.0 }
            })
        });
        let parallax = inv_distance[..n].iter().any(|&d| d > 0.0);
        let mean_direction =
            mixture.lobes().iter().map(|l| l.mean * (l.weight * vmf::mean_cosine(l.kappa))).sum();
        Self { lobes, mean_cosine, inv_distance: inv, parallax, mean_direction }
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
        let mut base = LobeSet::<1>::default();
        base.set_from(
            &crate::Mixture::new(&[vmf::VmfLobe { mean: Vec3::Z, kappa: 1e6, weight: 1.0 }])
                .unwrap(),
        );
        let mut prod = LobeSet::<1>::default();
        assert!(prod.set_product(&base, -Vec3::Z, &[(1e6, 1.0)]));
        assert_eq!(prod.lobe(0).1, 0.0);
        assert!((prod.pdf(Vec3::X) - 1.0 / (4.0 * std::f32::consts::PI)).abs() < 1e-6);
    }

    #[test]
    fn mean_direction_is_the_mixtures_first_moment() {
        let cases: [&[(Vec3, f32, f32)]; 4] = [
            &[(Vec3::Z, 0.0, 1.0)],
            &[(Vec3::X, 40.0, 1.0)],
            &[(Vec3::Z, 5.0, 1.0), (-Vec3::Z, 5.0, 1.0)],
            &[(Vec3::new(0.3, 0.4, 0.87).normalize(), 1e4, 0.7), (Vec3::Y, 0.5, 0.3)],
        ];
        for lobes in cases {
            let lobes: Vec<_> = lobes
                .iter()
                .map(|&(mean, kappa, weight)| vmf::VmfLobe { mean, kappa, weight })
                .collect();
            let m = crate::Mixture::new(&lobes).unwrap();
            let got = RegionLanes::new(&m, &[0.0; MAX_LOBES]).mean_direction;
            // The first moment by quadrature, lobe by lobe on a grid graded for it.
            let mut want = glam::DVec3::ZERO;
            for l in m.lobes() {
                let grid = SphereGrid::for_lobe(l.mean.as_dvec3(), f64::from(l.kappa));
                let f = |k: usize| {
                    grid.integrate(&|d: DVec3| f64::from(l.weight * l.pdf(d.as_vec3())) * d[k])
                };
                want += DVec3::new(f(0), f(1), f(2));
            }
            assert!(
                (got.as_dvec3() - want).length() < 1e-4,
                "{lobes:?}: mean direction {got} against quadrature {want}"
            );
        }
    }
}
