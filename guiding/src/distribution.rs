//! The per-thread sampling distribution a renderer queries at each scattering vertex in a
//! medium: the incident-radiance mixture of the region at the vertex, optionally multiplied by
//! the phase function (or a clamped cosine), with sampling, pdf and radiance estimates.
//!
//! It holds fixed-size arrays only, so one value per thread is reused for every vertex
//! without touching the allocator. `sample` and `pdf` describe the same normalised mixture,
//! so `pdf(sample(u))` equals the pdf returned by `sample_with_pdf(u)` to float rounding.

use crate::directional::hg::{self, HG_LOBES};
use crate::directional::lanes::{self, LANES};
use crate::directional::mixture::MAX_LOBES;
use crate::directional::product::{COSINE_KAPPA, LobeSet, RegionLanes};
use crate::directional::vmf;
use crate::field::Field;
use glam::{Vec2, Vec3};

/// Lobes a product can have: every mixture lobe times every lobe of the phase-function fit.
pub const MAX_PRODUCT_LOBES: usize = MAX_LOBES * HG_LOBES;

/// What `sample` and `pdf` currently describe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProductKind {
    /// The incident-radiance mixture alone.
    None,
    /// Incident radiance times the Henyey-Greenstein phase function.
    HenyeyGreenstein,
    /// Incident radiance with its lobes reweighted by their convolution with the
    /// Henyey-Greenstein phase function (`apply_hg_weights`).
    HenyeyGreensteinWeights,
    /// Incident radiance times one vMF lobe of the Henyey-Greenstein phase function's mean
    /// cosine (`apply_hg_lobe_product`).
    HenyeyGreensteinLobe,
    /// Incident radiance times a clamped cosine.
    Cosine,
    /// Incident radiance with its lobes reweighted by their mean clamped cosine
    /// (`apply_cosine_weights`).
    CosineWeights,
    /// The product had no usable weight (corrupt input); the distribution fell back to the
    /// phase function's (or cosine's) own vMF fit.
    Fallback,
}

/// A guided directional distribution at one point of a medium (see the module docs).
///
/// Directions are incident-light directions pointing away from the vertex, which are also the
/// new path directions. Typical use per vertex:
/// ```
/// # use zerovar_guiding::{Field, FieldConfig, VolumeDistribution};
/// # use glam::{Vec2, Vec3};
/// # let field = Field::new(FieldConfig::default()).unwrap();
/// let mut d = VolumeDistribution::default(); // once per thread
/// if d.init(&field, Vec3::ZERO, 0.5) {
///     d.apply_hg_product(Vec3::Z, 0.7);
///     let (dir, pdf) = d.sample_with_pdf(Vec2::new(0.3, 0.6));
/// } // else: sample the phase function
/// ```
#[derive(Clone, Debug)]
pub struct VolumeDistribution {
    pub(crate) base: LobeSet<{ MAX_LOBES / LANES }>,
    /// Each base lobe's mean cosine (reweighting's convolutions need them).
    base_mean_cosine: [[f32; LANES]; MAX_LOBES / LANES],
    product: LobeSet<{ MAX_PRODUCT_LOBES / LANES }>,
    kind: ProductKind,
    fluence: f32,
    region: Option<u32>,
    /// The last `|g|` of [`apply_hg_lobe_product`](Self::apply_hg_lobe_product) and its
    /// lobe's concentration: a scene has few phase functions, and inverting the mean cosine
    /// takes a few Newton steps.
    hg_lobe: (f32, f32),
}

impl Default for VolumeDistribution {
    fn default() -> Self {
        Self {
            base: LobeSet::default(),
            base_mean_cosine: [[0.0; LANES]; MAX_LOBES / LANES],
            product: LobeSet::default(),
            kind: ProductKind::None,
            fluence: 0.0,
            region: None,
            hg_lobe: (0.0, 0.0),
        }
    }
}

impl VolumeDistribution {
    /// Loads the region of `field` at `pos` (`u` in `[0, 1)` drives the stochastic spatial
    /// filter, if enabled), its parallax-aware lobes re-aimed from the region's centre to
    /// `pos`. Returns false, and becomes a uniform distribution with zero radiance, when the
    /// field has no trained region there: the renderer should then fall back to
    /// phase-function sampling. Any product applied before is dropped.
    pub fn init(&mut self, field: &Field, pos: Vec3, u: f32) -> bool {
        self.kind = ProductKind::None;
        match field.lookup_index(pos, u) {
            Some(index) => {
                let region = &field.regions()[index];
                self.load_lanes(&region.lanes);
                if region.lanes.parallax {
                    self.base.shift_means(&region.lanes.inv_distance, region.centre() - pos);
                }
                self.fluence = region.fluence();
                self.region = Some(index as u32);
                true
            }
            None => {
                self.base.set_uniform();
                self.base_mean_cosine[0][0] = 0.0;
                self.fluence = 0.0;
                self.region = None;
                false
            }
        }
    }

    /// Copies a region's lobes and mean cosines (only the blocks in use).
    #[inline]
    fn load_lanes(&mut self, lanes: &RegionLanes) {
        self.base.copy_used_from(&lanes.lobes);
        let n = lanes.lobes.blocks_used();
        self.base_mean_cosine[..n].copy_from_slice(&lanes.mean_cosine[..n]);
    }

    /// Index of the region loaded by `init`, if any (stable until the next `Field::update`).
    pub fn region_index(&self) -> Option<u32> {
        self.region
    }

    /// Replaces the distribution by the normalised product of the incident-radiance mixture
    /// with the Henyey-Greenstein phase function, `cos theta = dot(ray_dir, new_dir)`;
    /// `ray_dir` is the unit direction the path was travelling, `g > 0` scatters forward.
    pub fn apply_hg_product(&mut self, ray_dir: Vec3, g: f32) {
        let fit = hg::hg_vmf_fit(g);
        let factor: [(f32, f32); HG_LOBES] = std::array::from_fn(|i| (fit.kappa[i], fit.weight[i]));
        self.kind = if self.product.set_product(&self.base, ray_dir * fit.axis_sign, &factor) {
            ProductKind::HenyeyGreenstein
        } else {
            ProductKind::Fallback
        };
    }

    /// Replaces the distribution by the normalised product of the incident-radiance mixture
    /// with one vMF lobe standing in for the Henyey-Greenstein phase function: the lobe whose
    /// mean cosine is `|g|`, about `ray_dir` (about `-ray_dir` for `g < 0`). It makes one
    /// product lobe per mixture lobe where [`apply_hg_product`] makes [`HG_LOBES`], so it costs
    /// about what [`apply_hg_weights`] costs; unlike the reweighted lobes it keeps the phase
    /// function's forward peak inside each broad lobe (light from all around a vertex), which
    /// is where most of the product is at moderate `g`. HG's heavy tail beyond the lobe is left
    /// to the phase-function sampling the walk mixes in.
    ///
    /// [`apply_hg_product`]: Self::apply_hg_product
    /// [`apply_hg_weights`]: Self::apply_hg_weights
    pub fn apply_hg_lobe_product(&mut self, ray_dir: Vec3, g: f32) {
        let g_abs = g.abs().min(hg::G_MAX);
        if self.hg_lobe.0 != g_abs {
            self.hg_lobe = (g_abs, vmf::kappa_from_mean_cosine(g_abs));
        }
        let kappa = self.hg_lobe.1;
        let axis = if g < 0.0 { -ray_dir } else { ray_dir };
        self.kind = if self.product.set_product(&self.base, axis, &[(kappa, 1.0)]) {
            ProductKind::HenyeyGreensteinLobe
        } else {
            ProductKind::Fallback
        };
    }

    /// Replaces the distribution by the incident-radiance mixture with each lobe's weight
    /// multiplied by the lobe's convolution with the Henyey-Greenstein phase function, the
    /// lobes' shapes kept: an approximate product with the phase function at a third of the
    /// cost of [`apply_hg_product`] (one phase evaluation per lobe instead of
    /// [`HG_LOBES`] lobe products, and a mixture of the region's size to sample and evaluate).
    /// The convolution is taken as HG with `g` times the lobe's mean cosine, which is exact
    /// for a uniform lobe and in the limit of a sharp one, and right in the first moment in
    /// between. Close to the exact product where the phase function is broad next to the
    /// radiance lobes (moderate `g`); for strongly forward scattering the exact product's
    /// reshaped lobes matter. Left without a product where no lobe keeps any weight.
    ///
    /// [`apply_hg_product`]: Self::apply_hg_product
    pub fn apply_hg_weights(&mut self, ray_dir: Vec3, g: f32) {
        let mean_cosine = &self.base_mean_cosine;
        let ok = self.product.set_reweighted(&self.base, |mean, _, k| {
            lanes::hg_pdf(ray_dir.dot(mean), g * mean_cosine[k / LANES][k % LANES])
        });
        self.kind = if ok { ProductKind::HenyeyGreensteinWeights } else { ProductKind::None };
    }

    /// Replaces the distribution by the normalised product of the incident-radiance mixture
    /// with the clamped cosine `max(0, dot(normal, dir))`, approximated by one vMF lobe.
    pub fn apply_cosine_product(&mut self, normal: Vec3) {
        self.kind = if self.product.set_product(&self.base, normal, &[(COSINE_KAPPA, 1.0)]) {
            ProductKind::Cosine
        } else {
            ProductKind::Fallback
        };
    }

    /// Replaces the distribution by the incident-radiance mixture with each lobe's weight
    /// multiplied by the lobe's mean clamped cosine `E[max(0, dot(normal, w))]` about
    /// `normal`, the lobes' shapes kept: the cosine counterpart of
    /// [`apply_hg_weights`](Self::apply_hg_weights), at four fifths of the cost of
    /// [`apply_cosine_product`](Self::apply_cosine_product) (see docs/experiments.md) and a
    /// mixture of the region's size to sample and evaluate rather than a product mixture. The
    /// mean is taken as `A max(0, cos) + (1 - A) / 4` for a lobe of mean cosine `A` about a
    /// mean at angle `cos` to the normal: exact for a uniform lobe (1/4) and in the limit of a
    /// sharp one, so lobes below the surface keep only what their spread reaches above it.
    /// Left without a product where no lobe keeps any weight.
    pub fn apply_cosine_weights(&mut self, normal: Vec3) {
        let mean_cosine = &self.base_mean_cosine;
        let ok = self.product.set_reweighted(&self.base, |mean, _, k| {
            let a = mean_cosine[k / LANES][k % LANES];
            a * normal.dot(mean).max(0.0) + (1.0 - a) * 0.25
        });
        self.kind = if ok { ProductKind::CosineWeights } else { ProductKind::None };
    }

    /// Drops any product, so `sample` and `pdf` describe the incident radiance alone.
    pub fn clear_product(&mut self) {
        self.kind = ProductKind::None;
    }

    /// What `sample` and `pdf` currently describe.
    pub fn product_kind(&self) -> ProductKind {
        self.kind
    }

    /// Draws a unit direction from two uniform numbers in `[0, 1)`.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Vec3 {
        match self.kind {
            ProductKind::None => self.base.sample(u),
            _ => self.product.sample(u),
        }
    }

    /// The density of `sample` at the unit direction `dir` (per steradian).
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match self.kind {
            ProductKind::None => self.base.pdf(dir),
            _ => self.product.pdf(dir),
        }
    }

    /// Draws a direction and returns it with its density.
    #[inline]
    pub fn sample_with_pdf(&self, u: Vec2) -> (Vec3, f32) {
        let d = self.sample(u);
        (d, self.pdf(d))
    }

    /// The normalised incident-radiance mixture `V_L(dir)`, before any product (for
    /// resampling schemes that weigh candidates by incident radiance).
    #[inline]
    pub fn incident_radiance_pdf(&self, dir: Vec3) -> f32 {
        self.base.pdf(dir)
    }

    /// The estimated incident radiance `L(x, dir) = Phi(x) V_L(dir)`, from direction `dir`
    /// (pointing away from the vertex).
    #[inline]
    pub fn incident_radiance(&self, dir: Vec3) -> f32 {
        self.fluence * self.base.pdf(dir)
    }

    /// The estimated fluence `Phi(x)`, the integral of incident radiance over the sphere.
    #[inline]
    pub fn fluence(&self) -> f32 {
        self.fluence
    }

    /// The estimated in-scattered radiance `L_s(x, ray_dir) = int L(x, w) f_HG(dot(ray_dir, w))
    /// dw` for a path travelling along `ray_dir` (HG convention as in `apply_hg_product`).
    ///
    /// Exact for the vMF fit of HG (each term is a closed-form vMF convolution); the fit's
    /// L1 error bounds the difference to the true HG convolution by that error times the
    /// largest incident radiance.
    pub fn inscattered_radiance(&self, ray_dir: Vec3, g: f32) -> f32 {
        if self.fluence == 0.0 {
            return 0.0;
        }
        let fit = hg::hg_vmf_fit(g);
        let factor: [(f32, f32); HG_LOBES] = std::array::from_fn(|i| (fit.kappa[i], fit.weight[i]));
        self.fluence * self.base.convolution(ray_dir * fit.axis_sign, &factor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::directional::hg::tests::{GS, HG_FIT_L1_BOUND, zonal_integral};
    use crate::directional::mixture::Mixture;
    use crate::directional::vmf::VmfLobe;
    use crate::testutil::MultiGrid;
    use glam::DVec3;
    use rand_pcg::Pcg32;
    use rand_pcg::rand_core::Rng;

    fn u01(rng: &mut Pcg32) -> f32 {
        (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    fn with_mixture(m: &Mixture, fluence: f32) -> VolumeDistribution {
        let mut d = VolumeDistribution::default();
        d.load_lanes(&RegionLanes::new(m, &[0.0; crate::directional::mixture::MAX_LOBES]));
        d.fluence = fluence;
        d
    }

    fn radiance_mixture(kappa: f32) -> Mixture {
        Mixture::new(&[
            VmfLobe { mean: Vec3::new(0.2, 0.1, 1.0), kappa, weight: 0.7 },
            VmfLobe { mean: Vec3::new(-1.0, 0.3, 0.0), kappa: 4.0, weight: 0.3 },
        ])
        .unwrap()
    }

    const RAY: Vec3 = Vec3::new(0.0, 0.6, 0.8);

    /// Quadrature grids on every sharp feature of a product.
    fn product_grid(d: &VolumeDistribution) -> MultiGrid {
        let features: Vec<(DVec3, f64, f64)> = (0..d.product.len())
            .map(|k| d.product.lobe(k))
            .map(|(m, kappa, w)| (m.as_dvec3(), f64::from(kappa), f64::from(w)))
            .collect();
        MultiGrid::new(&features)
    }

    /// Asserts that `d`'s density integrates to one within `tolerance`, that every sample's
    /// returned density is its `pdf`, positive and finite, and that `n` samples pass a
    /// chi-square test against it.
    fn assert_normalised_and_sampled(
        d: &VolumeDistribution,
        rng: &mut Pcg32,
        n: usize,
        tolerance: f64,
        what: &str,
    ) {
        let grid = product_grid(d);
        let pdf = |w: DVec3| f64::from(d.pdf(w.as_vec3()));
        let integral = grid.integrate(&pdf);
        assert!((integral - 1.0).abs() < tolerance, "{what}: integrates to {integral}");
        let samples: Vec<DVec3> = (0..n)
            .map(|_| {
                let (w, p) = d.sample_with_pdf(Vec2::new(u01(rng), u01(rng)));
                assert_eq!(p, d.pdf(w));
                assert!(p > 0.0 && p.is_finite(), "{what}: density {p}");
                w.as_dvec3()
            })
            .collect();
        let mut u = || f64::from(u01(rng));
        grid.chi2(&samples, &pdf, &mut u).assert_pass(1e-3, what);
    }

    #[test]
    fn hg_product_is_normalised_and_sampling_matches_pdf() {
        let mut rng = Pcg32::new(21, 4);
        for &kappa in &[0.0f32, 1.0, 100.0, 1e4] {
            for &g in &GS {
                let mut d = with_mixture(&radiance_mixture(kappa), 1.0);
                d.apply_hg_product(RAY, g);
                assert_eq!(d.product_kind(), ProductKind::HenyeyGreenstein);
                let what = format!("kappa {kappa} g {g}");
                assert_normalised_and_sampled(&d, &mut rng, 30_000, 2e-4, &what);
            }
        }
    }

    #[test]
    fn hg_lobe_product_is_normalised_and_sampling_matches_pdf() {
        let mut rng = Pcg32::new(27, 5);
        for &kappa in &[0.0f32, 1.0, 100.0, 1e4] {
            for &g in &GS {
                let mut d = with_mixture(&radiance_mixture(kappa), 1.0);
                d.apply_hg_lobe_product(RAY, g);
                assert_eq!(d.product_kind(), ProductKind::HenyeyGreensteinLobe);
                let what = format!("one lobe: kappa {kappa} g {g}");
                assert_normalised_and_sampled(&d, &mut rng, 30_000, 2e-4, &what);
            }
        }
    }

    #[test]
    fn hg_weights_are_normalised_and_sampling_matches_pdf() {
        let mut rng = Pcg32::new(33, 6);
        for &kappa in &[0.0f32, 1.0, 100.0, 1e4] {
            for &g in &GS {
                let mut d = with_mixture(&radiance_mixture(kappa), 1.0);
                d.apply_hg_weights(RAY, g);
                assert_eq!(d.product_kind(), ProductKind::HenyeyGreensteinWeights);
                let what = format!("weights: kappa {kappa} g {g}");
                assert_normalised_and_sampled(&d, &mut rng, 30_000, 2e-4, &what);
            }
        }
    }

    #[test]
    fn re_aimed_lobes_stay_normalised_and_sampling_matches_pdf() {
        // Parallax-aware lobes re-aimed for a query point away from the region's centre: one
        // lobe's source is 1.5 away, the other at infinity, and the sharp lobe's source sits
        // at the query point itself (it must keep its mean, not become NaN).
        let mut rng = Pcg32::new(5, 8);
        let m = Mixture::new(&[
            VmfLobe { mean: Vec3::new(0.2, 0.1, 1.0).normalize(), kappa: 30.0, weight: 0.5 },
            VmfLobe { mean: Vec3::new(-1.0, 0.3, 0.0).normalize(), kappa: 4.0, weight: 0.3 },
            VmfLobe { mean: Vec3::X, kappa: 1e4, weight: 0.2 },
        ])
        .unwrap();
        let mut inv = [0.0; MAX_LOBES];
        (inv[0], inv[1], inv[2]) = (1.0 / 1.5, 0.0, 1.0 / 0.8);
        let lanes = RegionLanes::new(&m, &inv);
        assert!(lanes.parallax);
        // From the centre, the query point lies 0.8 along +x: at the third lobe's source.
        let offset = Vec3::new(-0.8, 0.0, 0.0);
        for product in [false, true] {
            let mut d = VolumeDistribution::default();
            d.load_lanes(&lanes);
            d.fluence = 1.0;
            d.base.shift_means(&lanes.inv_distance, offset);
            let want = (m.lobes()[0].mean * 1.5 + offset).normalize();
            assert!((d.base.lobe(0).0 - want).length() < 1e-6, "{:?}", d.base.lobe(0));
            assert_eq!(d.base.lobe(1).0, m.lobes()[1].mean);
            assert_eq!(d.base.lobe(2).0, Vec3::X);
            let probe = Vec3::new(0.3, -0.2, 0.9).normalize();
            let direct = lanes.lobes.pdf_shifted(probe, &lanes.inv_distance, offset);
            assert!((direct - d.pdf(probe)).abs() <= 1e-6 * direct, "{direct} {}", d.pdf(probe));
            if product {
                d.apply_hg_product(RAY, 0.8);
            } else {
                d.apply_hg_weights(RAY, 0.4);
            }
            let what = format!("re-aimed, exact product {product}");
            assert_normalised_and_sampled(&d, &mut rng, 30_000, 2e-4, &what);
        }
    }

    #[test]
    fn hg_weights_follow_each_lobes_convolution_with_hg() {
        // A uniform lobe and a sharp one: the reweighting is exact in both limits, so the
        // weight ratio equals the ratio of the lobes' true convolutions with HG (quadrature).
        let sharp = Vec3::new(0.6, 0.0, 0.8);
        let m = Mixture::new(&[
            VmfLobe { mean: sharp, kappa: 1e4, weight: 0.5 },
            VmfLobe { mean: Vec3::Z, kappa: 0.0, weight: 0.5 },
        ])
        .unwrap();
        for &g in &[-0.7f32, 0.3, 0.6, 0.9] {
            let mut d = with_mixture(&m, 1.0);
            d.apply_hg_weights(RAY, g);
            let convolution = |lobe: &VmfLobe| {
                let grid = MultiGrid::new(&[
                    (lobe.mean.as_dvec3(), f64::from(lobe.kappa), 1.0),
                    (RAY.as_dvec3(), f64::from(hg::hg_vmf_fit(g).kappa[HG_LOBES - 1]), 1.0),
                ]);
                grid.integrate(&|w| {
                    f64::from(lobe.pdf(w.as_vec3())) * hg_pdf_f64(RAY.as_dvec3(), w, g)
                })
            };
            let want = convolution(&m.lobes()[0]) / convolution(&m.lobes()[1]);
            let got = f64::from(d.product.lobe(0).2) / f64::from(d.product.lobe(1).2);
            assert!((got / want - 1.0).abs() < 2e-3, "g {g}: ratio {got} vs {want}");
        }
    }

    #[test]
    fn hg_weights_without_any_weight_leave_the_mixture_alone() {
        // Lobes whose weights all vanish after reweighting (a corrupt mixture) must not give
        // a NaN distribution.
        let mut d = with_mixture(&radiance_mixture(5.0), 1.0);
        d.apply_hg_weights(Vec3::new(f32::NAN, 0.0, 0.0), 0.5);
        assert_eq!(d.product_kind(), ProductKind::None);
        let (w, p) = d.sample_with_pdf(Vec2::new(0.3, 0.7));
        assert!(w.is_finite() && p > 0.0 && p.is_finite());
    }

    #[test]
    fn cosine_weights_are_normalised_and_sampling_matches_pdf() {
        let mut rng = Pcg32::new(9, 2);
        for &kappa in &[0.0f32, 3.0, 1e4] {
            let mut d = with_mixture(&radiance_mixture(kappa), 1.0);
            d.apply_cosine_weights(Vec3::Z);
            assert_eq!(d.product_kind(), ProductKind::CosineWeights);
            let what = format!("cosine weights: kappa {kappa}");
            assert_normalised_and_sampled(&d, &mut rng, 30_000, 2e-4, &what);
        }
    }

    #[test]
    fn cosine_weights_follow_each_lobes_mean_clamped_cosine() {
        // Exact for a uniform lobe and a sharp one: their weight ratio is the ratio of their
        // true mean clamped cosines (quadrature), here 0.6 against 1/4, and a sharp lobe below
        // the surface gets no weight.
        let above = Vec3::new(0.8, 0.0, 0.6);
        let m = Mixture::new(&[
            VmfLobe { mean: above, kappa: 1e5, weight: 0.4 },
            VmfLobe { mean: Vec3::Z, kappa: 0.0, weight: 0.3 },
            VmfLobe { mean: -above, kappa: 1e5, weight: 0.3 },
        ])
        .unwrap();
        let mut d = with_mixture(&m, 1.0);
        d.apply_cosine_weights(Vec3::Z);
        let mean_cosine = |lobe: &VmfLobe| {
            let grid = MultiGrid::new(&[(lobe.mean.as_dvec3(), f64::from(lobe.kappa), 1.0)]);
            grid.integrate(&|w| f64::from(lobe.pdf(w.as_vec3())) * w.z.max(0.0))
        };
        let want = 0.4 * mean_cosine(&m.lobes()[0]) / (0.3 * mean_cosine(&m.lobes()[1]));
        let got = f64::from(d.product.lobe(0).2) / f64::from(d.product.lobe(1).2);
        assert!((got / want - 1.0).abs() < 1e-3, "ratio {got} vs {want}");
        assert!(d.product.lobe(2).2 < 1e-4, "below: {}", d.product.lobe(2).2);
    }

    #[test]
    fn cosine_product_is_normalised_and_sampling_matches_pdf() {
        let mut rng = Pcg32::new(5, 8);
        let mut d = with_mixture(&radiance_mixture(30.0), 1.0);
        let normal = Vec3::new(0.0, 0.0, 1.0);
        d.apply_cosine_product(normal);
        assert_eq!(d.product_kind(), ProductKind::Cosine);
        let grid = product_grid(&d);
        let pdf = |w: DVec3| f64::from(d.pdf(w.as_vec3()));
        assert!((grid.integrate(&pdf) - 1.0).abs() < 1e-4);
        let samples: Vec<DVec3> = (0..40_000)
            .map(|_| d.sample(Vec2::new(u01(&mut rng), u01(&mut rng))).as_dvec3())
            .collect();
        let mut u = || f64::from(u01(&mut rng));
        grid.chi2(&samples, &pdf, &mut u).assert_pass(1e-3, "cosine product");
    }

    #[test]
    fn uniform_radiance_times_hg_is_the_hg_fit() {
        // With isotropic incident light the product is the phase function's own fit.
        let mut d = with_mixture(&Mixture::uniform(), 1.0);
        for &g in &GS {
            d.apply_hg_product(RAY, g);
            let fit = hg::hg_vmf_fit(g);
            for w in [RAY, -RAY, Vec3::X, Vec3::new(0.0, 0.8, 0.6)] {
                let expect = fit.pdf(RAY.dot(w));
                assert!((d.pdf(w) - expect).abs() <= 1e-4 * expect, "g {g}: {} {expect}", d.pdf(w));
            }
        }
    }

    /// HG in double precision from `1 - cos = |a - b|^2 / 2`, for reference integrals of
    /// sharp phase functions.
    fn hg_pdf_f64(ray: DVec3, w: DVec3, g: f32) -> f64 {
        let g = f64::from(g);
        let one_minus_cos = 0.5 * (ray - w.normalize()).length_squared();
        let denom = (1.0 - g) * (1.0 - g) + 2.0 * g * one_minus_cos;
        (1.0 - g * g) / (4.0 * std::f64::consts::PI * denom * denom.sqrt())
    }

    #[test]
    fn inscattered_radiance_matches_quadrature() {
        for &kappa in &[0.0f32, 2.0, 50.0] {
            let m = radiance_mixture(kappa);
            let fluence = 3.0f32;
            let d = with_mixture(&m, fluence);
            let l = |w: DVec3| f64::from(fluence) * f64::from(m.pdf(w.as_vec3()));
            let l_max = f64::from(fluence)
                * f64::from(m.pdf(m.lobes()[0].mean)).max(f64::from(m.pdf(m.lobes()[1].mean)));
            for &g in &GS {
                let got = f64::from(d.inscattered_radiance(RAY, g));
                // Exact against the fitted phase function...
                let fit = hg::hg_vmf_fit(g);
                let axis = RAY.as_dvec3() * f64::from(fit.axis_sign);
                // The integrand's features: the phase lobes and the radiance lobes.
                let mut features: Vec<(DVec3, f64, f64)> = (0..HG_LOBES)
                    .map(|i| (axis, f64::from(fit.kappa[i]), f64::from(fit.weight[i])))
                    .collect();
                features.extend(
                    m.lobes()
                        .iter()
                        .map(|l| (l.mean.as_dvec3(), f64::from(l.kappa), f64::from(l.weight))),
                );
                let grid = MultiGrid::new(&features);
                let with_fit =
                    grid.integrate(&|w| l(w) * f64::from(fit.pdf_between(RAY, w.as_vec3())));
                assert!((got - with_fit).abs() < 1e-4 * with_fit, "{kappa} {g}: {got} {with_fit}");
                // ...and within the fit's L1 error times the largest radiance of true HG.
                let with_hg = grid.integrate(&|w| l(w) * hg_pdf_f64(RAY.as_dvec3(), w, g));
                assert!(
                    (got - with_hg).abs() <= HG_FIT_L1_BOUND * l_max,
                    "{kappa} {g}: {got} vs true HG {with_hg}"
                );
            }
        }
        // Sanity of the quadrature helper on the same grids: HG is normalised.
        assert!((zonal_integral(&|c| f64::from(hg::hg_pdf(c as f32, 0.9))) - 1.0).abs() < 1e-4);
    }

    #[test]
    fn incident_radiance_and_fluence() {
        let m = radiance_mixture(10.0);
        let d = with_mixture(&m, 2.5);
        assert_eq!(d.fluence(), 2.5);
        let w = Vec3::new(0.3, 0.3, 0.9).normalize();
        assert!((d.incident_radiance(w) - 2.5 * m.pdf(w)).abs() < 1e-6);
        assert_eq!(d.incident_radiance_pdf(w), d.pdf(w));
    }
}
