//! Online weighted expectation-maximisation of a vMF mixture, with MAP priors.
//!
//! A region keeps the sufficient statistics of every sample it has seen: per lobe, the sum of
//! weight times responsibility and the sum of weight times responsibility times direction.
//! Each update runs a few EM iterations on the new batch, each iteration combining the batch's
//! statistics (recomputed with the current mixture) with the stored ones, then folds the
//! batch into the stored statistics (stepwise EM, Cappe and Moulines). The stored statistics
//! are first scaled so the batch gets the step size `t^-alpha` at the `t`-th update of the
//! region; `alpha = 1` gives every sample equal weight, so batched updates approach the fit
//! of all samples at once.
//!
//! The M-step uses the MAP priors of Open PGL's variant: a Dirichlet prior on the weights,
//! `pi_k = (v + N_k) / (v K + N)`, and a prior on each lobe's mean cosine,
//! `r_k = (b r0 + r_k N_k) / (b + N_k)`, clamped to `A(max_kappa)`. `N_k` counts samples
//! (weights rescaled to the batch's sample count), so the priors mean the same whatever the
//! units of radiance. A lobe without data keeps its mean and falls back to the prior.
//!
//! Everything runs in sample order in f64, so a fit depends only on its samples.

use crate::directional::mixture::{MAX_LOBES, Mixture};
use crate::directional::vmf::{self, VmfLobe};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

/// A training direction with its weight (radiance / pdf), as the EM sees it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WeightedDir {
    pub(crate) dir: Vec3,
    pub(crate) weight: f64,
    /// The density the direction was sampled with (used by split and merge).
    pub(crate) pdf: f32,
    /// One over the distance from the region's pivot to where the light came from (0 for
    /// light from infinitely far, or without parallax).
    pub(crate) inv_distance: f32,
}

/// Settings of the EM (a subset of `FieldConfig`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct EmSettings {
    pub(crate) iterations: u32,
    pub(crate) weight_prior: f64,
    pub(crate) mean_cosine_prior: f64,
    pub(crate) mean_cosine_prior_strength: f64,
    pub(crate) max_kappa: f64,
    pub(crate) step_exponent: f64,
    pub(crate) initial_kappa: f32,
}

/// Accumulated sufficient statistics of one region.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct EmStats {
    weight: [f64; MAX_LOBES],
    moment: [DVec3; MAX_LOBES],
    /// Per lobe, the sum of weight times responsibility times inverse source distance.
    inv_distance: [f64; MAX_LOBES],
    /// Sum of sample weights (all samples, so total / count estimates the fluence).
    pub(crate) total_weight: f64,
    /// Number of samples, zero-weight ones included.
    pub(crate) count: f64,
    /// Number of samples with positive weight: the evidence the MAP priors compete with.
    pub(crate) positive_count: f64,
    /// Updates that brought samples to this region.
    pub(crate) updates: u32,
}

impl Default for EmStats {
    fn default() -> Self {
        Self {
            weight: [0.0; MAX_LOBES],
            moment: [DVec3::ZERO; MAX_LOBES],
            inv_distance: [0.0; MAX_LOBES],
            total_weight: 0.0,
            count: 0.0,
            positive_count: 0.0,
            updates: 0,
        }
    }
}

impl EmStats {
    /// Splits lobe `k`'s statistics in halves, lobe `k` along `a` and the new lobe `new`
    /// along `b`, keeping the mean cosine.
    pub(crate) fn split_lobe(&mut self, k: usize, new: usize, a: DVec3, b: DVec3) {
        let half = 0.5 * self.moment[k].length();
        self.weight[k] *= 0.5;
        self.weight[new] = self.weight[k];
        self.inv_distance[k] *= 0.5;
        self.inv_distance[new] = self.inv_distance[k];
        self.moment[k] = a * half;
        self.moment[new] = b * half;
    }

    /// Adds lobe `j`'s statistics to lobe `i`, then moves lobe `last` into slot `j`.
    pub(crate) fn merge_lobes(&mut self, i: usize, j: usize, last: usize) {
        self.weight[i] += self.weight[j];
        self.moment[i] += self.moment[j];
        self.inv_distance[i] += self.inv_distance[j];
        self.weight[j] = self.weight[last];
        self.moment[j] = self.moment[last];
        self.inv_distance[j] = self.inv_distance[last];
        self.weight[last] = 0.0;
        self.moment[last] = DVec3::ZERO;
        self.inv_distance[last] = 0.0;
    }

    /// Each lobe's weighted mean inverse source distance (the reciprocal of a weighted
    /// harmonic mean distance; 0 for a lobe of light from infinitely far or without data).
    pub(crate) fn lobe_inverse_distances(&self) -> [f32; MAX_LOBES] {
        std::array::from_fn(|k| {
            let w = self.weight[k];
            if w > 0.0 { (self.inv_distance[k] / w) as f32 } else { 0.0 }
        })
    }

    /// Checks the statistics are finite and non-negative (a loaded field's come from a file).
    pub(crate) fn validate(&self) -> Result<(), String> {
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        let lobes_ok = (0..MAX_LOBES)
            .all(|k| ok(self.weight[k]) && ok(self.inv_distance[k]) && self.moment[k].is_finite());
        if lobes_ok && ok(self.total_weight) && ok(self.count) && ok(self.positive_count) {
            Ok(())
        } else {
            Err("EM statistics that are negative or not finite".into())
        }
    }

    /// Scales every statistic by `f`, used when a region splits in two.
    pub(crate) fn scale(&mut self, f: f64) {
        self.weight.iter_mut().for_each(|w| *w *= f);
        self.moment.iter_mut().for_each(|m| *m *= f);
        self.inv_distance.iter_mut().for_each(|d| *d *= f);
        self.total_weight *= f;
        self.count *= f;
        self.positive_count *= f;
    }
}

/// The starting mixture: `k` lobes spread evenly over the sphere (a Fibonacci lattice), equal
/// weights, concentration `kappa`.
pub(crate) fn initial_mixture(k: usize, kappa: f32) -> Mixture {
    let k = k.clamp(1, MAX_LOBES);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let lobes: Vec<VmfLobe> = (0..k)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / k as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            let mean = DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3();
            VmfLobe { mean, kappa: if k == 1 { 0.0 } else { kappa }, weight: 1.0 / k as f32 }
        })
        .collect();
    Mixture::from_valid(&lobes)
}

/// A starting mixture placed on the data: weighted farthest-point seeding. The first mean is
/// the direction of the heaviest sample; each next one maximises weight times distance
/// (`1 - cos`) to the nearest mean chosen so far. Deterministic (ties go to the first sample),
/// and it avoids the local optimum of two lobes sharing one mode that a fixed start invites.
/// Lobes beyond the number of distinct heavy directions keep their lattice positions.
pub(crate) fn seed_mixture(k: usize, kappa: f32, samples: &[WeightedDir]) -> Mixture {
    let lattice = initial_mixture(k, kappa);
    let mut lobes: Vec<VmfLobe> = lattice.lobes().to_vec();
    let mut distance: Vec<f64> = vec![1.0; samples.len()];
    for lobe in lobes.iter_mut() {
        let mut best = (0usize, 0.0f64);
        for (i, s) in samples.iter().enumerate() {
            let score = s.weight * distance[i];
            if score > best.1 {
                best = (i, score);
            }
        }
        if best.1 <= 0.0 {
            break;
        }
        let mean = samples[best.0].dir;
        lobe.mean = mean;
        for (d, s) in distance.iter_mut().zip(samples) {
            *d = d.min(-f64::from(vmf::cos_minus_one(mean, s.dir)));
        }
    }
    Mixture::from_valid(&lobes)
}

/// Per-lobe responsibilities of one direction, written into `out`; the logarithmic form keeps
/// them finite when every lobe's density underflows.
#[inline]
fn responsibilities(lobes: &[VmfLobe], log_prior: &[f32], dir: Vec3, out: &mut [f32]) {
    let mut max = f32::NEG_INFINITY;
    for (k, l) in lobes.iter().enumerate() {
        out[k] = log_prior[k] + l.kappa * vmf::cos_minus_one(l.mean, dir);
        max = max.max(out[k]);
    }
    let mut sum = 0.0;
    for o in out[..lobes.len()].iter_mut() {
        *o = (*o - max).exp();
        sum += *o;
    }
    let inv = 1.0 / sum;
    out[..lobes.len()].iter_mut().for_each(|o| *o *= inv);
}

/// One batch's statistics under `mixture`.
fn e_step(mixture: &Mixture, samples: &[WeightedDir]) -> EmStats {
    let lobes = mixture.lobes();
    let mut log_prior = [0.0f32; MAX_LOBES];
    for (lp, l) in log_prior.iter_mut().zip(lobes) {
        *lp = (f64::from(l.weight).ln() + vmf::log_normalization(f64::from(l.kappa))) as f32;
    }
    let mut stats = EmStats::default();
    let mut gamma = [0.0f32; MAX_LOBES];
    for s in samples {
        stats.count += 1.0;
        if s.weight <= 0.0 {
            continue;
        }
        stats.positive_count += 1.0;
        stats.total_weight += s.weight;
        responsibilities(lobes, &log_prior[..lobes.len()], s.dir, &mut gamma);
        let d = s.dir.as_dvec3();
        for (k, &g) in gamma[..lobes.len()].iter().enumerate() {
            let wg = s.weight * f64::from(g);
            stats.weight[k] += wg;
            stats.moment[k] += d * wg;
            stats.inv_distance[k] += wg * f64::from(s.inv_distance);
        }
    }
    stats
}

/// The MAP M-step from combined statistics.
fn m_step(mixture: &Mixture, s: &EmStats, cfg: &EmSettings) -> Mixture {
    let old = mixture.lobes();
    let k_count = old.len() as f64;
    let total: f64 = s.weight[..old.len()].iter().sum();
    let n = s.positive_count;
    let r_max = vmf::mean_cosine_f64(cfg.max_kappa);
    let mut lobes = [VmfLobe::default(); MAX_LOBES];
    for (k, l) in old.iter().enumerate() {
        // Sample-count share of the lobe: weights in sample units, independent of radiance units.
        let n_k = if total > 0.0 { n * s.weight[k] / total } else { 0.0 };
        let weight = (cfg.weight_prior + n_k) / (cfg.weight_prior * k_count + n);
        let len = s.moment[k].length();
        let (mean, r) = if len > 0.0 && s.weight[k] > 0.0 && len.is_finite() {
            ((s.moment[k] / len).as_vec3(), (len / s.weight[k]).min(1.0))
        } else {
            (l.mean, cfg.mean_cosine_prior)
        };
        let beta = cfg.mean_cosine_prior_strength;
        let r = if beta + n_k > 0.0 {
            (beta * cfg.mean_cosine_prior + r * n_k) / (beta + n_k)
        } else {
            r
        };
        let r = r.clamp(0.0, r_max);
        lobes[k] = VmfLobe {
            mean,
            kappa: vmf::kappa_from_mean_cosine_f64(r).min(cfg.max_kappa) as f32,
            weight: weight as f32,
        };
    }
    // The prior already normalises the weights; renormalise away the rounding.
    let sum: f32 = lobes[..old.len()].iter().map(|l| l.weight).sum();
    lobes[..old.len()].iter_mut().for_each(|l| l.weight /= sum);
    Mixture::from_valid(&lobes[..old.len()])
}

/// Folds a batch into a region's statistics and refits its mixture (see the module docs).
pub(crate) fn update(
    mixture: &mut Mixture,
    stats: &mut EmStats,
    samples: &[WeightedDir],
    cfg: &EmSettings,
) {
    if samples.is_empty() {
        return;
    }
    stats.updates += 1;
    let n_batch = samples.len() as f64;
    if stats.count > 0.0 {
        // Step size eta = t^-alpha for the batch: old statistics get (1 - eta) / eta times the
        // batch's sample count. With alpha = 1 and equal batches this is exactly 1.
        let eta = f64::from(stats.updates).powf(-cfg.step_exponent);
        let lambda = ((1.0 - eta) / eta * n_batch / stats.count).min(1.0);
        stats.scale(lambda);
    }
    if stats.total_weight <= 0.0 {
        // Nothing learned yet: start from the data rather than from the lattice.
        *mixture = seed_mixture(mixture.len(), cfg.initial_kappa, samples);
    }
    let mut batch = EmStats::default();
    for _ in 0..cfg.iterations.max(1) {
        batch = e_step(mixture, samples);
        if batch.total_weight + stats.total_weight <= 0.0 {
            break; // no sample carries light: nothing to fit yet
        }
        let combined = combine(stats, &batch);
        *mixture = m_step(mixture, &combined, cfg);
    }
    *stats = combine(stats, &batch);
    stats.updates = stats.updates.max(1);
}

fn combine(a: &EmStats, b: &EmStats) -> EmStats {
    let mut c = a.clone();
    for k in 0..MAX_LOBES {
        c.weight[k] += b.weight[k];
        c.moment[k] += b.moment[k];
        c.inv_distance[k] += b.inv_distance[k];
    }
    c.total_weight += b.total_weight;
    c.count += b.count;
    c.positive_count += b.positive_count;
    c
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Vec2;
    use rand_pcg::Pcg32;
    use rand_pcg::rand_core::Rng;

    pub(crate) fn u01(rng: &mut Pcg32) -> f32 {
        (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    pub(crate) fn settings(iterations: u32) -> EmSettings {
        EmSettings {
            iterations,
            weight_prior: 0.01,
            mean_cosine_prior: 0.0,
            mean_cosine_prior_strength: 0.2,
            max_kappa: 32_000.0,
            step_exponent: 1.0,
            initial_kappa: 2.0,
        }
    }

    pub(crate) fn truth() -> Mixture {
        Mixture::new(&[
            VmfLobe { mean: Vec3::new(0.0, 0.0, 1.0), kappa: 40.0, weight: 0.5 },
            VmfLobe { mean: Vec3::new(1.0, 0.0, -0.3), kappa: 8.0, weight: 0.3 },
            VmfLobe { mean: Vec3::new(-0.5, -1.0, -0.2), kappa: 150.0, weight: 0.2 },
        ])
        .unwrap()
    }

    /// Samples drawn uniformly over the sphere and weighted by `scale * truth / (1 / 4 pi)`:
    /// the EM must undo the sampling density, as it does for a renderer's samples.
    pub(crate) fn weighted_samples(n: usize, seed: u64, scale: f64) -> Vec<WeightedDir> {
        let mut rng = Pcg32::new(seed, 3);
        let t = truth();
        (0..n)
            .map(|_| {
                // Half from the truth, half uniform: a defensive mixture keeps weights bounded.
                let u = Vec2::new(u01(&mut rng), u01(&mut rng));
                let dir =
                    if u01(&mut rng) < 0.5 { t.sample(u) } else { vmf::sample(Vec3::Z, 0.0, u) };
                let pdf = 0.5 * f64::from(t.pdf(dir)) + 0.5 / (4.0 * std::f64::consts::PI);
                WeightedDir {
                    dir,
                    weight: scale * f64::from(t.pdf(dir)) / pdf,
                    pdf: pdf as f32,
                    inv_distance: 0.0,
                }
            })
            .collect()
    }

    /// Matches each fitted lobe to the true lobe with the nearest mean.
    fn assert_recovers(fit: &Mixture, what: &str) {
        let t = truth();
        for tl in t.lobes() {
            let fl = fit
                .lobes()
                .iter()
                .max_by(|a, b| a.mean.dot(tl.mean).total_cmp(&b.mean.dot(tl.mean)))
                .unwrap();
            let angle = fl.mean.dot(tl.mean).clamp(-1.0, 1.0).acos();
            // Tolerances: with ~50k samples of which ~10k fall in each lobe, the weight's
            // standard error is ~0.004, the mean's ~1/sqrt(kappa n) < 0.005 rad and kappa's
            // relative error ~sqrt(2/n) ~ 0.015 (weighted samples roughly double variances):
            // the bounds below are about 5 standard errors.
            assert!(
                (fl.weight - tl.weight).abs() < 0.025,
                "{what}: weight {} vs {}",
                fl.weight,
                tl.weight
            );
            assert!(angle < 0.03, "{what}: mean off by {angle} rad (kappa {})", tl.kappa);
            assert!(
                ((fl.kappa - tl.kappa) / tl.kappa).abs() < 0.12,
                "{what}: kappa {} vs {}",
                fl.kappa,
                tl.kappa
            );
        }
    }

    #[test]
    fn em_recovers_a_three_lobe_mixture() {
        let samples = weighted_samples(50_000, 1, 1.0);
        let mut m = initial_mixture(3, 2.0);
        let mut stats = EmStats::default();
        update(&mut m, &mut stats, &samples, &settings(60));
        assert_recovers(&m, "one batch");
        // Fluence: the mean weight estimates the integral of the truth (1) without bias.
        let est: zerovar_testkit::MeanEstimate = samples.iter().map(|s| s.weight).collect();
        est.assert_matches(1.0, 4.0, "fluence of weighted samples");
        assert!((stats.total_weight / stats.count - est.mean).abs() < 1e-12);
    }

    #[test]
    fn batched_updates_approach_the_one_batch_fit() {
        let samples = weighted_samples(50_000, 2, 1.0);
        let mut one = initial_mixture(3, 2.0);
        update(&mut one, &mut EmStats::default(), &samples, &settings(60));
        let mut batched = initial_mixture(3, 2.0);
        let mut stats = EmStats::default();
        for chunk in samples.chunks(5_000) {
            update(&mut batched, &mut stats, chunk, &settings(6));
        }
        assert_recovers(&batched, "ten batches");
        // Both fits see the same samples; they must agree much more closely than either
        // agrees with the truth.
        for a in one.lobes() {
            let bl = batched
                .lobes()
                .iter()
                .max_by(|x, y| x.mean.dot(a.mean).total_cmp(&y.mean.dot(a.mean)))
                .unwrap();
            assert!((a.weight - bl.weight).abs() < 0.01, "{} {}", a.weight, bl.weight);
            assert!(a.mean.dot(bl.mean) > 0.9999, "{} {}", a.mean, bl.mean);
            assert!(((a.kappa - bl.kappa) / a.kappa).abs() < 0.04, "{} {}", a.kappa, bl.kappa);
        }
        assert_eq!(stats.count, 50_000.0);
    }

    #[test]
    fn fit_does_not_depend_on_weight_units() {
        let samples = weighted_samples(5_000, 3, 1.0);
        let scaled: Vec<_> =
            samples.iter().map(|s| WeightedDir { weight: s.weight * 1e20, ..*s }).collect();
        let (mut a, mut b) = (initial_mixture(4, 2.0), initial_mixture(4, 2.0));
        update(&mut a, &mut EmStats::default(), &samples, &settings(10));
        update(&mut b, &mut EmStats::default(), &scaled, &settings(10));
        for (x, y) in a.lobes().iter().zip(b.lobes()) {
            assert!(
                (x.weight - y.weight).abs() < 1e-5
                    && (x.kappa - y.kappa).abs() < 1e-3 * x.kappa.max(1.0)
            );
        }
    }

    fn assert_finite(m: &Mixture) {
        for l in m.lobes() {
            assert!(l.mean.is_finite() && (l.mean.length() - 1.0).abs() < 1e-4, "{l:?}");
            assert!(l.kappa.is_finite() && l.kappa >= 0.0, "{l:?}");
            assert!(l.weight.is_finite() && l.weight >= 0.0, "{l:?}");
        }
        let s: f32 = m.lobes().iter().map(|l| l.weight).sum();
        assert!((s - 1.0).abs() < 1e-5);
        for d in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::Z] {
            assert!(m.pdf(d).is_finite());
        }
    }

    #[test]
    fn degenerate_batches_give_no_nan() {
        let cfg = settings(8);
        // All samples in one direction: one lobe collapses onto it, up to max_kappa.
        let dir = Vec3::new(0.6, 0.0, 0.8);
        let same: Vec<_> = (0..1000)
            .map(|_| WeightedDir { dir, weight: 2.0, pdf: 1.0, inv_distance: 0.0 })
            .collect();
        let mut m = initial_mixture(8, 2.0);
        let mut s = EmStats::default();
        update(&mut m, &mut s, &same, &cfg);
        assert_finite(&m);
        let top = m.lobes().iter().max_by(|a, b| a.weight.total_cmp(&b.weight)).unwrap();
        assert!(top.mean.dot(dir) > 0.9999 && top.kappa > 1000.0, "{top:?}");
        // All weights zero: nothing is learned, nothing breaks.
        let zero: Vec<_> = (0..1000)
            .map(|i| WeightedDir {
                dir: if i % 2 == 0 { Vec3::X } else { Vec3::Y },
                weight: 0.0,
                pdf: 1.0,
                inv_distance: 0.0,
            })
            .collect();
        let mut m0 = initial_mixture(8, 2.0);
        let mut s0 = EmStats::default();
        update(&mut m0, &mut s0, &zero, &cfg);
        assert_finite(&m0);
        assert_eq!(m0, initial_mixture(8, 2.0)); // no light: nothing to seed from or fit
        assert_eq!((s0.count, s0.total_weight), (1000.0, 0.0));
        // One weight of 1e30 among ordinary ones: it dominates, without overflow or NaN.
        let mut huge = weighted_samples(2000, 4, 1.0);
        huge[17].weight = 1e30;
        let mut mh = initial_mixture(8, 2.0);
        let mut sh = EmStats::default();
        update(&mut mh, &mut sh, &huge, &cfg);
        assert_finite(&mh);
        assert!(mh.pdf(huge[17].dir) > 100.0);
        // And then ordinary batches continue without trouble.
        update(&mut mh, &mut sh, &weighted_samples(2000, 5, 1.0), &cfg);
        assert_finite(&mh);
    }

    #[test]
    fn update_is_deterministic() {
        let samples = weighted_samples(3000, 6, 1.0);
        let run = || {
            let mut m = initial_mixture(8, 2.0);
            let mut s = EmStats::default();
            update(&mut m, &mut s, &samples, &settings(5));
            (m, s)
        };
        assert_eq!(run(), run());
    }
}
