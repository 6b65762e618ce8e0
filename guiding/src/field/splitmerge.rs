//! Splitting and merging of lobes by a chi-square criterion (after Ruppert, Herholz and
//! Lensch 2020), enabled by `FieldConfig::split_merge`.
//!
//! The fit's quality is the chi-square divergence between the normalised target
//! `t(w) = L(w) / Phi` and the mixture `q`, `int (t - q)^2 / q`, which is the variance factor
//! of an importance-sampling estimator that samples `q`. Responsibilities `gamma_k` split it
//! into per-lobe shares, estimated from the samples `w_i` drawn with density `p_i` as
//! `chi2_k = mean_i gamma_ik p_i (w_i / Phi - q_i / p_i)^2 / q_i`.
//! A lobe whose share exceeds `split_threshold` covers structure it cannot represent: it is
//! split in two along the principal axis of its samples' spread in the tangent plane. Two
//! lobes that nearly coincide (normalised overlap `int v_i v_j / sqrt(int v_i^2 int v_j^2)`
//! above `1 - merge_threshold`) are merged, moment-preserving. The sufficient statistics are
//! split and merged with the lobes, so the next EM update continues from them.

use crate::config::FieldConfig;
use crate::directional::em::EmStats;
use crate::directional::em::WeightedDir;
use crate::directional::mixture::{MAX_LOBES, Mixture};
use crate::directional::vmf::{self, VmfLobe};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

/// Samples a region must gather between two split-and-merge checks.
const CHECK_SAMPLES: f64 = 2000.0;

/// Per-lobe statistics for the split and merge decisions, gathered since the last check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct LobeStats {
    chi2: [f64; MAX_LOBES],
    weight: [f64; MAX_LOBES],
    /// Weighted second moments of directions, upper triangle (xx, xy, xz, yy, yz, zz).
    second: [[f64; 6]; MAX_LOBES],
    count: f64,
}

impl Default for LobeStats {
    fn default() -> Self {
        Self {
            chi2: [0.0; MAX_LOBES],
            weight: [0.0; MAX_LOBES],
            second: [[0.0; 6]; MAX_LOBES],
            count: 0.0,
        }
    }
}

impl LobeStats {
    pub(crate) fn scale(&mut self, f: f64) {
        self.chi2.iter_mut().for_each(|c| *c *= f);
        self.weight.iter_mut().for_each(|c| *c *= f);
        self.second.iter_mut().flatten().for_each(|c| *c *= f);
        self.count *= f;
    }

    fn covariance(&self, k: usize) -> DMat3 {
        let s = &self.second[k];
        let inv = if self.weight[k] > 0.0 { 1.0 / self.weight[k] } else { 0.0 };
        DMat3::from_cols(
            DVec3::new(s[0], s[1], s[2]) * inv,
            DVec3::new(s[1], s[3], s[4]) * inv,
            DVec3::new(s[2], s[4], s[5]) * inv,
        )
    }
}

/// What splitting and merging change in a region: its mixture, the EM statistics the next
/// update continues from, and the statistics gathered for these decisions.
pub(super) struct Lobes<'a> {
    pub(super) mixture: &'a mut Mixture,
    pub(super) em: &'a mut EmStats,
    pub(super) stats: &'a mut LobeStats,
}

/// Gathers the batch's statistics and, once enough samples were seen, splits and merges.
pub(super) fn update(region: &mut Lobes<'_>, samples: &[WeightedDir], config: &FieldConfig) {
    let fluence = {
        let n = samples.len() as f64;
        samples.iter().map(|s| s.weight).sum::<f64>() / n
    };
    if !(fluence > 0.0 && fluence.is_finite()) {
        return;
    }
    let mixture = region.mixture.clone();
    let lobes = mixture.lobes();
    let stats = &mut *region.stats;
    for s in samples {
        stats.count += 1.0;
        let q = f64::from(mixture.pdf(s.dir));
        if q.is_nan() || q <= 0.0 {
            continue;
        }
        let p = f64::from(s.pdf);
        let d = s.dir.as_dvec3();
        let excess = p * (s.weight / fluence - q / p).powi(2) / q;
        for (k, l) in lobes.iter().enumerate() {
            let gamma = f64::from(l.weight * l.pdf(s.dir)) / q;
            stats.chi2[k] += gamma * excess;
            let wg = s.weight * gamma;
            stats.weight[k] += wg;
            let m = &mut stats.second[k];
            m[0] += wg * d.x * d.x;
            m[1] += wg * d.x * d.y;
            m[2] += wg * d.x * d.z;
            m[3] += wg * d.y * d.y;
            m[4] += wg * d.y * d.z;
            m[5] += wg * d.z * d.z;
        }
    }
    if stats.count < CHECK_SAMPLES {
        return;
    }
    split(region, config);
    merge(region, config);
    *region.stats = LobeStats::default();
}

fn split(region: &mut Lobes<'_>, config: &FieldConfig) {
    loop {
        let lobes = region.mixture.lobes();
        if lobes.len() >= config.max_lobes {
            return;
        }
        let n = region.stats.count;
        let Some((k, chi2)) = (0..lobes.len())
            .map(|k| (k, region.stats.chi2[k] / n))
            .max_by(|a, b| a.1.total_cmp(&b.1))
        else {
            return;
        };
        if chi2.is_nan() || chi2 <= f64::from(config.split_threshold) {
            return;
        }
        let lobe = lobes[k];
        let mu = lobe.mean.as_dvec3();
        // Spread of the lobe's samples in its tangent plane.
        let proj = DMat3::IDENTITY - DMat3::from_cols(mu * mu.x, mu * mu.y, mu * mu.z);
        let cov = proj * region.stats.covariance(k) * proj;
        let (axis, variance) = principal_axis(cov);
        let offset = variance.sqrt().clamp(1e-4, 0.5);
        let (a, b) = ((mu + axis * offset).normalize(), (mu - axis * offset).normalize());
        let mut new_lobes: Vec<VmfLobe> = lobes.to_vec();
        // Each half is narrower than the whole: its spread about its own mean is the rest.
        let r = f64::from(vmf::mean_cosine(lobe.kappa));
        let r_half = (r / (1.0 - offset * offset * 0.5).max(0.5))
            .min(vmf::mean_cosine_f64(f64::from(config.max_kappa)));
        let kappa = vmf::kappa_from_mean_cosine_f64(r_half).min(f64::from(config.max_kappa)) as f32;
        new_lobes[k] = VmfLobe { mean: a.as_vec3(), kappa, weight: lobe.weight * 0.5 };
        new_lobes.push(VmfLobe { mean: b.as_vec3(), kappa, weight: lobe.weight * 0.5 });
        region.em.split_lobe(k, new_lobes.len() - 1, a, b);
        let sm = &mut *region.stats;
        sm.chi2[k] *= 0.25; // each half is expected to fit better; stop re-splitting it now
        sm.chi2[new_lobes.len() - 1] = sm.chi2[k];
        sm.weight[k] *= 0.5;
        sm.weight[new_lobes.len() - 1] = sm.weight[k];
        sm.second[new_lobes.len() - 1] = sm.second[k];
        *region.mixture = Mixture::from_valid(&new_lobes);
    }
}

fn merge(region: &mut Lobes<'_>, config: &FieldConfig) {
    loop {
        let lobes = region.mixture.lobes();
        if lobes.len() <= 1 {
            return;
        }
        let mut best = (0, 0, f64::NEG_INFINITY);
        for i in 0..lobes.len() {
            for j in i + 1..lobes.len() {
                let s = overlap(&lobes[i], &lobes[j]);
                if s > best.2 {
                    best = (i, j, s);
                }
            }
        }
        let (i, j, similarity) = best;
        if similarity.is_nan() || 1.0 - similarity >= f64::from(config.merge_threshold) {
            return;
        }
        let (a, b) = (lobes[i], lobes[j]);
        let w = f64::from(a.weight) + f64::from(b.weight);
        let moment = a.mean.as_dvec3()
            * (f64::from(a.weight) * vmf::mean_cosine_f64(f64::from(a.kappa)))
            + b.mean.as_dvec3() * (f64::from(b.weight) * vmf::mean_cosine_f64(f64::from(b.kappa)));
        let len = moment.length();
        let mean = if len > 0.0 { (moment / len).as_vec3() } else { a.mean };
        let kappa = vmf::kappa_from_mean_cosine_f64(if w > 0.0 { len / w } else { 0.0 })
            .min(f64::from(config.max_kappa)) as f32;
        let mut new_lobes: Vec<VmfLobe> = lobes.to_vec();
        new_lobes[i] = VmfLobe { mean, kappa, weight: w as f32 };
        let last = new_lobes.len() - 1;
        new_lobes.swap_remove(j);
        region.em.merge_lobes(i, j, last);
        let sm = &mut *region.stats;
        sm.chi2[i] += sm.chi2[j];
        sm.weight[i] += sm.weight[j];
        for c in 0..6 {
            sm.second[i][c] += sm.second[j][c];
        }
        sm.chi2[j] = sm.chi2[last];
        sm.weight[j] = sm.weight[last];
        sm.second[j] = sm.second[last];
        sm.chi2[last] = 0.0;
        sm.weight[last] = 0.0;
        sm.second[last] = [0.0; 6];
        *region.mixture = Mixture::from_valid(&new_lobes);
    }
}

/// Normalised overlap of two lobes, in (0, 1], 1 for identical lobes.
fn overlap(a: &VmfLobe, b: &VmfLobe) -> f64 {
    let self_product =
        |l: &VmfLobe| crate::directional::product::vmf_product(l.mean, l.kappa, l.mean, l.kappa).2;
    let cross = crate::directional::product::vmf_product(a.mean, a.kappa, b.mean, b.kappa).2;
    (cross - 0.5 * (self_product(a) + self_product(b))).exp()
}

/// Unit eigenvector of the largest eigenvalue of a symmetric 3x3 matrix, with the eigenvalue.
fn principal_axis(m: DMat3) -> (DVec3, f64) {
    // Start from the longest column, plus a generic tilt, so the start is not orthogonal to
    // the principal axis (nor exactly another eigenvector).
    let mut v = [m.x_axis, m.y_axis, m.z_axis]
        .into_iter()
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
        .unwrap_or(DVec3::ZERO);
    if v.length_squared() == 0.0 {
        return (DVec3::X, 0.0);
    }
    v = v.normalize() + DVec3::new(0.013, 0.017, 0.011);
    v = v.normalize();
    for _ in 0..32 {
        let next = m * v;
        let len = next.length();
        if len == 0.0 {
            return (v.any_orthonormal_vector(), 0.0);
        }
        v = next / len;
    }
    (v, v.dot(m * v).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::sample::Sample;
    use crate::directional::em;
    use crate::field::Field;
    use glam::Vec3;
    use rand_pcg::Pcg32;

    #[test]
    fn principal_axis_of_a_stretched_matrix() {
        let m = DMat3::from_diagonal(DVec3::new(0.1, 3.0, 0.5));
        let (v, l) = principal_axis(m);
        assert!(v.y.abs() > 0.9999 && (l - 3.0).abs() < 1e-9);
    }

    #[test]
    fn overlap_is_one_for_equal_lobes_and_small_for_distant_ones() {
        let a = VmfLobe { mean: Vec3::Z, kappa: 50.0, weight: 1.0 };
        assert!((overlap(&a, &a) - 1.0).abs() < 1e-12);
        let b = VmfLobe { mean: Vec3::X, kappa: 50.0, weight: 1.0 };
        assert!(overlap(&a, &b) < 1e-6);
    }

    /// Two sharp lights seen from one region: a one-lobe start can only fit them by splitting.
    #[test]
    fn split_merge_finds_two_lights_from_one_lobe() {
        let lights = [Vec3::new(0.3, 0.0, 1.0).normalize(), Vec3::new(-0.3, 0.0, 1.0).normalize()];
        let config = crate::FieldConfig {
            initial_lobes: 1,
            max_lobes: 8,
            split_merge: true,
            max_samples_per_leaf: 1 << 30,
            ..Default::default()
        };
        let mut field = Field::new(config.clone()).unwrap();
        let mut plain = Field::new(crate::FieldConfig { split_merge: false, ..config }).unwrap();
        let mut rng = Pcg32::new(4, 4);
        let truth = Mixture::new(&[
            VmfLobe { mean: lights[0], kappa: 300.0, weight: 0.5 },
            VmfLobe { mean: lights[1], kappa: 300.0, weight: 0.5 },
        ])
        .unwrap();
        for _ in 0..6 {
            let samples: Vec<Sample> = (0..4000)
                .map(|_| {
                    let u = glam::Vec2::new(em::tests::u01(&mut rng), em::tests::u01(&mut rng));
                    let direction = vmf::sample(Vec3::Z, 0.0, u);
                    let pdf = 1.0 / (4.0 * std::f32::consts::PI);
                    Sample {
                        position: Vec3::ZERO,
                        direction,
                        radiance: truth.pdf(direction),
                        pdf,
                        distance: 1.0,
                        volume: true,
                    }
                })
                .collect();
            field.update(&samples).unwrap();
            plain.update(&samples).unwrap();
        }
        let m = field.regions()[0].mixture();
        assert!(m.len() >= 2, "no split happened: {m:?}");
        for l in lights {
            let (split, single) = (m.pdf(l), plain.regions()[0].mixture().pdf(l));
            assert!(split > 5.0 * single, "split/merge fit {split} vs single lobe {single}");
        }
    }
}
