//! Statistical test helpers shared by zerovar's crates (and, in [`files`], the repository's
//! files and a scratch directory for integration tests).
//!
//! Every sampler in zerovar is checked the same way: samples are binned and compared with the
//! counts its own pdf predicts (a chi-square goodness-of-fit test), the pdf is integrated by
//! quadrature to check that it is normalised, and Monte Carlo estimators are compared with
//! analytic answers by a z-test whose tolerance comes from the estimator's own standard error.
//! Keeping these in one crate means the renderer and the guiding library use identical checks.
//!
//! Sharp spherical distributions (a vMF lobe with kappa = 1e6 is about a milliradian wide) are
//! handled by a graded polar grid about a chosen axis: bin edges are uniform in
//! `theta / (theta + theta_scale)`, so bins are fine inside the lobe and coarse outside.

pub mod files;
mod quadrature;
mod special;

pub use quadrature::{GaussLegendre, integrate_1d};
pub use special::{chi2_survival, ln_gamma, regularized_gamma_q};

use glam::DVec3;

/// The outcome of a chi-square goodness-of-fit test.
#[derive(Clone, Debug)]
pub struct Chi2Outcome {
    /// The Pearson statistic, sum of (observed - expected)^2 / expected over the pooled bins.
    pub statistic: f64,
    /// Degrees of freedom: pooled bins minus one.
    pub dof: usize,
    /// Probability of a statistic at least this large if the samples follow the pdf.
    pub p_value: f64,
    /// Number of bins after pooling those with small expected counts.
    pub bins: usize,
    /// Total expected count over all bins divided by the sample count: the pdf's integral
    /// over the binned domain (1 when nothing is lost outside it).
    pub expected_fraction: f64,
}

impl Chi2Outcome {
    /// Panics with a readable message when the test rejects at significance `alpha`.
    pub fn assert_pass(&self, alpha: f64, what: &str) {
        assert!(
            self.p_value >= alpha,
            "{what}: chi-square rejects the pdf (statistic {:.2}, dof {}, p = {:.3e} < {alpha:e})",
            self.statistic,
            self.dof,
            self.p_value
        );
    }
}

/// Pearson's chi-square test of observed against expected counts.
///
/// Bins whose expected count is below 5 are pooled with their neighbours (in order), so the
/// chi-square approximation holds. A bin that observes samples where nothing was expected makes
/// the test fail outright (p = 0), as the sampler produced values its pdf calls impossible.
pub fn chi2_test(observed: &[f64], expected: &[f64]) -> Chi2Outcome {
    assert_eq!(observed.len(), expected.len(), "observed and expected bin counts differ in length");
    let n_obs: f64 = observed.iter().sum();
    let n_exp: f64 = expected.iter().sum();
    let mut pooled: Vec<(f64, f64)> = Vec::new();
    let (mut acc_o, mut acc_e) = (0.0, 0.0);
    for (&o, &e) in observed.iter().zip(expected) {
        if e <= 0.0 && o > 0.0 {
            return Chi2Outcome {
                statistic: f64::INFINITY,
                dof: 0,
                p_value: 0.0,
                bins: 0,
                expected_fraction: n_exp / n_obs.max(1.0),
            };
        }
        acc_o += o;
        acc_e += e;
        if acc_e >= 5.0 {
            pooled.push((acc_o, acc_e));
            acc_o = 0.0;
            acc_e = 0.0;
        }
    }
    if acc_e > 0.0 || acc_o > 0.0 {
        match pooled.last_mut() {
            Some(last) => {
                last.0 += acc_o;
                last.1 += acc_e;
            }
            None => pooled.push((acc_o, acc_e)),
        }
    }
    let statistic: f64 = pooled.iter().map(|&(o, e)| (o - e) * (o - e) / e).sum();
    let dof = pooled.len().saturating_sub(1);
    let p_value = if dof == 0 { 1.0 } else { chi2_survival(statistic, dof as f64) };
    Chi2Outcome {
        statistic,
        dof,
        p_value,
        bins: pooled.len(),
        expected_fraction: n_exp / n_obs.max(1.0),
    }
}

/// A polar grid over the sphere about `axis`, graded towards the axis.
#[derive(Clone, Copy, Debug)]
pub struct SphereGrid {
    /// The pole of the grid; put it on the sharpest feature of the pdf.
    pub axis: DVec3,
    /// Angular scale (radians) of the finest bins: about the width of the sharpest feature.
    /// Use `f64::INFINITY` for bins uniform in theta.
    pub theta_scale: f64,
    /// Number of bins along theta.
    pub n_theta: usize,
    /// Number of bins along phi.
    pub n_phi: usize,
}

impl SphereGrid {
    /// A grid suited to a lobe of concentration `kappa` about `axis` (width about 1/sqrt(kappa)).
    pub fn for_lobe(axis: DVec3, kappa: f64) -> Self {
        let theta_scale = if kappa > 1.0 { 2.0 / kappa.sqrt() } else { f64::INFINITY };
        Self { axis: axis.normalize(), theta_scale, n_theta: 24, n_phi: 16 }
    }

    /// Bins uniform in theta and phi about `axis`.
    pub fn uniform(axis: DVec3) -> Self {
        Self { axis: axis.normalize(), theta_scale: f64::INFINITY, n_theta: 24, n_phi: 16 }
    }

    fn frame(&self) -> (DVec3, DVec3, DVec3) {
        let z = self.axis.normalize();
        let (x, y) = z.any_orthonormal_pair();
        (x, y, z)
    }

    // theta -> t in [0, t_max]; uniform bins in t are graded toward the pole.
    fn warp(&self, theta: f64) -> f64 {
        if self.theta_scale.is_infinite() { theta } else { theta / (theta + self.theta_scale) }
    }

    fn unwarp(&self, t: f64) -> f64 {
        if self.theta_scale.is_infinite() { t } else { self.theta_scale * t / (1.0 - t) }
    }

    fn theta_edge(&self, i: usize) -> f64 {
        let t_max = self.warp(std::f64::consts::PI);
        if i == self.n_theta {
            std::f64::consts::PI
        } else {
            self.unwarp(t_max * i as f64 / self.n_theta as f64)
        }
    }

    /// The bin of a direction, or `None` for a zero or non-finite vector.
    pub fn bin(&self, d: DVec3) -> Option<usize> {
        let len = d.length();
        if !len.is_finite() || len == 0.0 {
            return None;
        }
        let d = d / len;
        let (x, y, z) = self.frame();
        // atan2 of the sine and cosine keeps full precision near the pole.
        let theta = d.cross(z).length().atan2(d.dot(z));
        let phi = d.dot(y).atan2(d.dot(x)).rem_euclid(std::f64::consts::TAU);
        let t_max = self.warp(std::f64::consts::PI);
        let it = ((self.warp(theta) / t_max) * self.n_theta as f64) as usize;
        let ip = ((phi / std::f64::consts::TAU) * self.n_phi as f64) as usize;
        Some(it.min(self.n_theta - 1) * self.n_phi + ip.min(self.n_phi - 1))
    }

    /// Integral of `f` over every bin, by Gauss-Legendre quadrature in (theta, phi) per bin.
    pub fn integrate_bins(&self, f: &dyn Fn(DVec3) -> f64) -> Vec<f64> {
        let (x, y, z) = self.frame();
        let gl = GaussLegendre::new(8);
        let mut out = vec![0.0; self.n_theta * self.n_phi];
        for it in 0..self.n_theta {
            let (t0, t1) = (self.theta_edge(it), self.theta_edge(it + 1));
            for ip in 0..self.n_phi {
                let p0 = std::f64::consts::TAU * ip as f64 / self.n_phi as f64;
                let p1 = std::f64::consts::TAU * (ip + 1) as f64 / self.n_phi as f64;
                out[it * self.n_phi + ip] = gl.integrate_2d(t0, t1, p0, p1, |theta, phi| {
                    let (st, ct) = theta.sin_cos();
                    let (sp, cp) = phi.sin_cos();
                    f(x * (st * cp) + y * (st * sp) + z * ct) * st
                });
            }
        }
        out
    }

    /// Integral of `f` over the whole sphere.
    pub fn integrate(&self, f: &dyn Fn(DVec3) -> f64) -> f64 {
        self.integrate_bins(f).iter().sum()
    }

    /// Chi-square test of sampled directions against the density `pdf` (per steradian).
    pub fn chi2(&self, samples: &[DVec3], pdf: &dyn Fn(DVec3) -> f64) -> Chi2Outcome {
        let mut observed = vec![0.0; self.n_theta * self.n_phi];
        let mut invalid = 0.0;
        for &s in samples {
            match self.bin(s) {
                Some(b) => observed[b] += 1.0,
                None => invalid += 1.0,
            }
        }
        let n = samples.len() as f64;
        let mut expected: Vec<f64> = self.integrate_bins(pdf).into_iter().map(|p| p * n).collect();
        // Invalid samples go to a bin of their own with nothing expected, failing the test.
        observed.push(invalid);
        expected.push(0.0);
        chi2_test(&observed, &expected)
    }
}

/// Chi-square test of 1-D samples against a density on `edges[0]..edges[last]`, plus point
/// masses (`atoms`: value and probability) that get bins of their own.
///
/// Samples that equal an atom's value are counted in its bin; samples outside the edges and
/// matching no atom are counted in a bin with zero expectation, which fails the test.
pub fn chi2_1d(
    samples: &[f64],
    pdf: &dyn Fn(f64) -> f64,
    edges: &[f64],
    atoms: &[(f64, f64)],
) -> Chi2Outcome {
    assert!(edges.len() >= 2, "need at least one bin");
    let nb = edges.len() - 1;
    let n = samples.len() as f64;
    let mut observed = vec![0.0; nb + atoms.len() + 1];
    'samples: for &s in samples {
        for (k, &(a, _)) in atoms.iter().enumerate() {
            if s == a {
                observed[nb + k] += 1.0;
                continue 'samples;
            }
        }
        if !(s >= edges[0] && s <= edges[nb]) {
            observed[nb + atoms.len()] += 1.0;
            continue;
        }
        let i = edges.partition_point(|&e| e <= s).clamp(1, nb) - 1;
        observed[i] += 1.0;
    }
    let mut expected: Vec<f64> =
        edges.windows(2).map(|w| integrate_1d(pdf, w[0], w[1], 16) * n).collect();
    expected.extend(atoms.iter().map(|&(_, p)| p * n));
    expected.push(0.0);
    chi2_test(&observed, &expected)
}

/// Bin edges that split `lo..hi` into `n` bins of equal mass under a known CDF.
pub fn equal_mass_edges(cdf: &dyn Fn(f64) -> f64, lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (c0, c1) = (cdf(lo), cdf(hi));
    let mut edges = vec![lo];
    for i in 1..n {
        let target = c0 + (c1 - c0) * i as f64 / n as f64;
        let (mut a, mut b) = (lo, hi);
        for _ in 0..200 {
            let m = 0.5 * (a + b);
            if cdf(m) < target { a = m } else { b = m }
        }
        edges.push(0.5 * (a + b));
    }
    edges.push(hi);
    edges
}

/// Mean and standard error of a sample, for z-tests of Monte Carlo estimators.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeanEstimate {
    /// Number of samples.
    pub n: u64,
    /// Sample mean.
    pub mean: f64,
    m2: f64,
}

impl MeanEstimate {
    /// Adds one sample (Welford's update, stable for long runs).
    pub fn push(&mut self, x: f64) {
        self.n += 1;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
    }

    /// Unbiased sample variance.
    pub fn variance(&self) -> f64 {
        if self.n < 2 { 0.0 } else { self.m2 / (self.n - 1) as f64 }
    }

    /// Standard error of the mean.
    pub fn std_error(&self) -> f64 {
        (self.variance() / self.n.max(1) as f64).sqrt()
    }

    /// z-score of the mean against `expected`.
    pub fn z(&self, expected: f64) -> f64 {
        let se = self.std_error();
        if se == 0.0 {
            if self.mean == expected { 0.0 } else { f64::INFINITY }
        } else {
            (self.mean - expected) / se
        }
    }

    /// Panics unless the mean is within `z_max` standard errors of `expected`.
    pub fn assert_matches(&self, expected: f64, z_max: f64, what: &str) {
        let z = self.z(expected);
        assert!(
            z.abs() <= z_max,
            "{what}: mean {:.6} differs from expected {expected:.6} by {z:.2} standard errors \
             (se {:.3e}, n {})",
            self.mean,
            self.std_error(),
            self.n
        );
    }
}

impl FromIterator<f64> for MeanEstimate {
    fn from_iter<I: IntoIterator<Item = f64>>(samples: I) -> Self {
        let mut m = Self::default();
        samples.into_iter().for_each(|x| m.push(x));
        m
    }
}

/// Two-sample z-score of the difference of two independent means.
pub fn z_difference(a: &MeanEstimate, b: &MeanEstimate) -> f64 {
    let se = (a.std_error().powi(2) + b.std_error().powi(2)).sqrt();
    if se == 0.0 {
        if a.mean == b.mean { 0.0 } else { f64::INFINITY }
    } else {
        (a.mean - b.mean) / se
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // A tiny deterministic generator so the tests of the test kit need no dependency.
    struct SplitMix(u64);
    impl SplitMix {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
        }
    }

    fn uniform_sphere(rng: &mut SplitMix) -> DVec3 {
        let z = 1.0 - 2.0 * rng.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = std::f64::consts::TAU * rng.next();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    #[test]
    fn uniform_sphere_passes_and_integrates() {
        let mut rng = SplitMix(7);
        let samples: Vec<_> = (0..50_000).map(|_| uniform_sphere(&mut rng)).collect();
        let pdf = |_: DVec3| 1.0 / (4.0 * std::f64::consts::PI);
        let grid = SphereGrid::uniform(DVec3::new(0.3, 0.2, 0.9));
        assert!((grid.integrate(&pdf) - 1.0).abs() < 1e-9);
        grid.chi2(&samples, &pdf).assert_pass(1e-3, "uniform sphere");
    }

    #[test]
    fn wrong_pdf_is_rejected() {
        // Uniform samples tested against a cosine-weighted upper hemisphere must fail.
        let mut rng = SplitMix(11);
        let samples: Vec<_> = (0..20_000).map(|_| uniform_sphere(&mut rng)).collect();
        let pdf = |d: DVec3| d.z.max(0.0) / std::f64::consts::PI;
        let out = SphereGrid::uniform(DVec3::Z).chi2(&samples, &pdf);
        assert!(out.p_value < 1e-6, "p = {}", out.p_value);
        // A slightly wrong pdf (5% tilt) must also fail with this many samples.
        let tilted = |d: DVec3| (1.0 + 0.05 * d.z) / (4.0 * std::f64::consts::PI);
        let many: Vec<_> = (0..200_000).map(|_| uniform_sphere(&mut rng)).collect();
        assert!(SphereGrid::uniform(DVec3::Z).chi2(&many, &tilted).p_value < 1e-3);
    }

    #[test]
    fn graded_grid_integrates_a_sharp_lobe() {
        let kappa: f64 = 1e6;
        let norm = kappa / (2.0 * std::f64::consts::PI * (-(-2.0 * kappa).exp_m1()));
        let axis = DVec3::new(1.0, 2.0, 3.0).normalize();
        let pdf = |d: DVec3| norm * (kappa * (d.dot(axis) - 1.0)).exp();
        let grid = SphereGrid::for_lobe(axis, kappa);
        assert!((grid.integrate(&pdf) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn chi2_1d_exponential_with_atom() {
        // Exponential with rate 2 truncated at 1: the mass beyond 1 sits at the atom 1.0.
        let mut rng = SplitMix(3);
        let samples: Vec<f64> =
            (0..40_000).map(|_| (-(1.0 - rng.next()).ln() / 2.0).min(1.0)).collect();
        let pdf = |t: f64| 2.0 * (-2.0 * t).exp();
        let cdf = |t: f64| 1.0 - (-2.0 * t).exp();
        let edges = equal_mass_edges(&cdf, 0.0, 1.0, 30);
        let atom = (1.0, (-2.0f64).exp());
        chi2_1d(&samples, &pdf, &edges, &[atom]).assert_pass(1e-3, "truncated exponential");
        // Against a rate of 2.1 it fails.
        let wrong = |t: f64| 2.1 * (-2.1 * t).exp();
        let out = chi2_1d(&samples, &wrong, &edges, &[(1.0, (-2.1f64).exp())]);
        assert!(out.p_value < 1e-3, "p = {}", out.p_value);
    }

    #[test]
    fn mean_estimate_z() {
        let mut rng = SplitMix(5);
        let m: MeanEstimate = (0..100_000).map(|_| rng.next()).collect();
        m.assert_matches(0.5, 4.0, "uniform mean");
        assert!(m.z(0.51).abs() > 4.0);
        assert!((m.variance() - 1.0 / 12.0).abs() < 1e-3);
    }
}
