//! A mixture of up to [`MAX_LOBES`] vMF lobes with weights summing to one: the directional
//! part `V_L(w)` of the incident radiance `L(x, w) = Phi(x) V_L(w)` in a region.
//!
//! Storage is a fixed array, so mixtures live inside regions and sampling distributions without
//! heap allocation; each lobe's normalisation is cached because evaluating it needs `expm1`.

use crate::GuidingError;
use crate::directional::lanes::{self, LANES};
use crate::directional::vmf::{self, VmfLobe};
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// The largest number of lobes a mixture holds.
pub const MAX_LOBES: usize = 32;

/// A normalised mixture of vMF lobes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mixture {
    lobes: [VmfLobe; MAX_LOBES],
    norms: [f32; MAX_LOBES],
    len: u32,
}

impl Default for Mixture {
    fn default() -> Self {
        Self::uniform()
    }
}

impl Mixture {
    /// The uniform distribution over the sphere (one lobe with `kappa = 0`).
    pub fn uniform() -> Self {
        let mut m =
            Self { lobes: [VmfLobe::default(); MAX_LOBES], norms: [0.0; MAX_LOBES], len: 1 };
        m.lobes[0] = VmfLobe { mean: Vec3::Z, kappa: 0.0, weight: 1.0 };
        m.refresh();
        m
    }

    /// A mixture of the given lobes, with weights rescaled to sum to one and means normalised.
    ///
    /// Fails for no lobes, more than [`MAX_LOBES`], non-finite values, zero-length means,
    /// negative weights or concentrations, or weights summing to zero.
    pub fn new(lobes: &[VmfLobe]) -> Result<Self, GuidingError> {
        let bad = |s: String| Err(GuidingError::InvalidMixture(s));
        if lobes.is_empty() || lobes.len() > MAX_LOBES {
            return bad(format!("{} lobes (need 1 to {MAX_LOBES})", lobes.len()));
        }
        let mut total = 0.0f64;
        for (i, l) in lobes.iter().enumerate() {
            let len = l.mean.length();
            if !(l.mean.is_finite() && len > 0.0) {
                return bad(format!("lobe {i} has mean {}", l.mean));
            }
            if !(l.kappa.is_finite() && l.kappa >= 0.0) {
                return bad(format!("lobe {i} has kappa {}", l.kappa));
            }
            if !(l.weight.is_finite() && l.weight >= 0.0) {
                return bad(format!("lobe {i} has weight {}", l.weight));
            }
            total += f64::from(l.weight);
        }
        if total <= 0.0 {
            return bad("weights sum to zero".into());
        }
        let mut m = Self {
            lobes: [VmfLobe::default(); MAX_LOBES],
            norms: [0.0; MAX_LOBES],
            len: lobes.len() as u32,
        };
        for (dst, src) in m.lobes.iter_mut().zip(lobes) {
            *dst = VmfLobe {
                mean: src.mean.normalize(),
                kappa: src.kappa,
                weight: (f64::from(src.weight) / total) as f32,
            };
        }
        m.refresh();
        Ok(m)
    }

    /// Builds from lobes the EM has already made valid; recomputes the cached normalisations.
    pub(crate) fn from_valid(lobes: &[VmfLobe]) -> Self {
        debug_assert!(!lobes.is_empty() && lobes.len() <= MAX_LOBES);
        let mut m = Self {
            lobes: [VmfLobe::default(); MAX_LOBES],
            norms: [0.0; MAX_LOBES],
            len: lobes.len() as u32,
        };
        m.lobes[..lobes.len()].copy_from_slice(lobes);
        m.refresh();
        m
    }

    fn refresh(&mut self) {
        let n = self.len as usize;
        for (norm, lobe) in self.norms[..n].iter_mut().zip(&self.lobes[..n]) {
            *norm = vmf::normalization(lobe.kappa);
        }
    }

    /// The lobes in use.
    #[inline]
    pub fn lobes(&self) -> &[VmfLobe] {
        &self.lobes[..self.len as usize]
    }

    /// The cached normalisations of the lobes in use.
    #[inline]
    pub(crate) fn norms(&self) -> &[f32] {
        &self.norms[..self.len as usize]
    }

    /// The number of lobes in use.
    #[inline]
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// Always false: a mixture has at least one lobe.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The density at the unit direction `dir` (per steradian).
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        let n = self.len as usize;
        let mut sum = [0.0f32; LANES];
        for (lobes, norms) in self.lobes[..n].chunks(LANES).zip(self.norms[..n].chunks(LANES)) {
            // The exponents lobe by lobe, then the exponentials of a whole block at once.
            let mut exponent = [0.0f32; LANES];
            let mut weighted_norm = [0.0f32; LANES];
            for (j, (l, &norm)) in lobes.iter().zip(norms).enumerate() {
                exponent[j] = l.kappa * vmf::cos_minus_one(l.mean, dir);
                weighted_norm[j] = l.weight * norm;
            }
            for j in 0..LANES {
                sum[j] += weighted_norm[j] * lanes::exp(exponent[j]);
            }
        }
        sum.iter().sum()
    }

    /// Draws a direction: `u.x` picks the lobe and is then reused, rescaled, for the lobe.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Vec3 {
        let lobes = self.lobes();
        let (k, ux) = pick(lobes.iter().map(|l| l.weight), lobes.len(), u.x);
        lobes[k].sample(Vec2::new(ux, u.y))
    }

    /// Draws a direction and returns it with its density, `pdf(sample(u))`.
    #[inline]
    pub fn sample_with_pdf(&self, u: Vec2) -> (Vec3, f32) {
        let d = self.sample(u);
        (d, self.pdf(d))
    }

    /// Bytes of memory one mixture occupies.
    pub const fn memory_bytes() -> usize {
        std::mem::size_of::<Self>()
    }
}

/// Picks an index from non-negative weights summing to about one, and rescales `u` to `[0, 1)`
/// within the picked interval so it can drive the next decision.
#[inline]
pub(crate) fn pick(weights: impl Iterator<Item = f32>, len: usize, u: f32) -> (usize, f32) {
    let mut acc = 0.0f32;
    let mut last_positive = 0;
    for (k, w) in weights.enumerate() {
        if w > 0.0 {
            if u < acc + w {
                return (k, ((u - acc) / w).clamp(0.0, ONE_BELOW));
            }
            last_positive = k;
        }
        acc += w;
    }
    // Rounding left u above the final sum: it belongs to the last lobe that has weight.
    debug_assert!(last_positive < len.max(1));
    (last_positive, ONE_BELOW)
}

/// The largest f32 below one.
pub(crate) const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use rand_pcg::Pcg32;
    use rand_pcg::rand_core::Rng;
    use zerovar_testkit::SphereGrid;

    fn u01(rng: &mut Pcg32) -> f32 {
        (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    pub(crate) fn three_lobes() -> Mixture {
        Mixture::new(&[
            VmfLobe { mean: Vec3::new(1.0, 0.0, 0.2), kappa: 10.0, weight: 0.5 },
            VmfLobe { mean: Vec3::new(-0.3, 1.0, 0.0), kappa: 5.0, weight: 0.3 },
            VmfLobe { mean: Vec3::new(0.0, -0.2, -1.0), kappa: 500.0, weight: 0.2 },
        ])
        .unwrap()
    }

    #[test]
    fn mixture_pdf_integrates_and_sampling_matches() {
        let m = three_lobes();
        let pdf = |d: DVec3| f64::from(m.pdf(d.as_vec3()));
        // A grid graded about the sharp lobe resolves it; the broad lobes need no grading.
        for l in m.lobes().iter().filter(|l| l.kappa > 100.0) {
            let grid = SphereGrid::for_lobe(l.mean.as_dvec3(), f64::from(l.kappa));
            assert!((grid.integrate(&pdf) - 1.0).abs() < 1e-4);
        }
        let mut rng = Pcg32::new(1, 2);
        let samples: Vec<DVec3> = (0..60_000)
            .map(|_| m.sample(Vec2::new(u01(&mut rng), u01(&mut rng))).as_dvec3())
            .collect();
        for l in m.lobes().iter().filter(|l| l.kappa > 100.0) {
            let grid = SphereGrid::for_lobe(l.mean.as_dvec3(), f64::from(l.kappa));
            grid.chi2(&samples, &pdf).assert_pass(1e-3, "3-lobe mixture");
        }
        for _ in 0..1000 {
            let u = Vec2::new(u01(&mut rng), u01(&mut rng));
            let (d, p) = m.sample_with_pdf(u);
            assert_eq!(d, m.sample(u));
            assert_eq!(p, m.pdf(d));
        }
    }

    #[test]
    fn invalid_lobes_are_rejected() {
        let ok = VmfLobe { mean: Vec3::Z, kappa: 1.0, weight: 1.0 };
        assert!(Mixture::new(&[]).is_err());
        assert!(Mixture::new(&[VmfLobe { weight: -1.0, ..ok }]).is_err());
        assert!(Mixture::new(&[VmfLobe { weight: f32::NAN, ..ok }]).is_err());
        assert!(Mixture::new(&[VmfLobe { kappa: f32::INFINITY, ..ok }]).is_err());
        assert!(Mixture::new(&[VmfLobe { mean: Vec3::ZERO, ..ok }]).is_err());
        assert!(Mixture::new(&[VmfLobe { weight: 0.0, ..ok }]).is_err());
        assert!(Mixture::new(&[ok; MAX_LOBES + 1]).is_err());
        let m = Mixture::new(&[ok, VmfLobe { weight: 3.0, ..ok }]).unwrap();
        assert_eq!(m.lobes()[1].weight, 0.75);
    }

    #[test]
    fn pick_handles_zero_weights_and_rounding() {
        let w = [0.0f32, 0.5, 0.0, 0.5, 0.0];
        assert_eq!(pick(w.iter().copied(), 5, 0.0).0, 1);
        assert_eq!(pick(w.iter().copied(), 5, 0.7).0, 3);
        assert_eq!(pick(w.iter().copied(), 5, 1.0).0, 3);
        let (k, u) = pick(w.iter().copied(), 5, 0.25);
        assert_eq!(k, 1);
        assert!((u - 0.5).abs() < 1e-6);
    }
}
