//! Test support: quadrature and chi-square over the sphere for densities with several sharp
//! features in different directions, built from `zerovar_testkit::SphereGrid`.
//!
//! One graded grid resolves one sharp feature. For several, each grid `g` takes the share
//! `h_g / sum_j h_j` of the integrand, with `h_g` the weighted vMF lobes of the features on
//! grid `g` plus a uniform floor: the shares sum to one everywhere, and when the features
//! describe the integrand (its lobes and their weights), each grid's part is smooth where that
//! grid is coarse.
//! For the chi-square test each sample goes to grid `g` with probability equal to its share
//! (an independent random number), so the counts of all grids' bins together follow the
//! expected counts that the shares predict.

use glam::DVec3;
use zerovar_testkit::{Chi2Outcome, SphereGrid, chi2_test};

const MAX_GRIDS: usize = 16;

/// A sharp feature of an integrand: axis, concentration and weight of a vMF lobe.
type Feature = (DVec3, f64, f64);

/// The uniform part of every grid's share, so shares stay defined where no feature reaches.
const FLOOR: f64 = 1e-3;

pub(crate) struct MultiGrid {
    /// Each grid with the features it resolves.
    grids: Vec<(SphereGrid, Vec<Feature>)>,
}

fn lobe(axis: DVec3, kappa: f64, d: DVec3) -> f64 {
    let norm = if kappa < 1e-6 {
        1.0 / (4.0 * std::f64::consts::PI)
    } else {
        kappa / (2.0 * std::f64::consts::PI * -(-2.0 * kappa).exp_m1())
    };
    norm * (-0.5 * kappa * (d - axis).length_squared()).exp()
}

impl MultiGrid {
    /// Grids for features `(axis, kappa, weight)`; nearly coincident features share a grid.
    pub(crate) fn new(features: &[(DVec3, f64, f64)]) -> Self {
        let mut grids: Vec<(SphereGrid, Vec<Feature>)> = Vec::new();
        // Sharpest first, so each grid is graded for the sharpest feature on its axis.
        let mut sorted: Vec<(DVec3, f64, f64)> =
            features.iter().map(|&(a, k, w)| (a.normalize(), k, w)).collect();
        sorted.sort_by(|a, b| b.1.total_cmp(&a.1));
        for (axis, kappa, weight) in sorted {
            let home = grids.iter_mut().find(|(grid, _)| {
                let angle = grid.axis.dot(axis).clamp(-1.0, 1.0).acos();
                angle < 0.5 / kappa.max(1.0).sqrt()
            });
            match home {
                Some((_, list)) => list.push((axis, kappa, weight)),
                None => {
                    // Finer than the default grid: the shares vary on the features' scales.
                    let grid =
                        SphereGrid { n_theta: 48, n_phi: 32, ..SphereGrid::for_lobe(axis, kappa) };
                    grids.push((grid, vec![(axis, kappa, weight)]));
                }
            }
        }
        assert!(grids.len() <= MAX_GRIDS, "too many separate features");
        if grids.is_empty() {
            grids.push((SphereGrid::uniform(DVec3::Z), vec![(DVec3::Z, 0.0, 1.0)]));
        }
        Self { grids }
    }

    fn shares(&self, d: DVec3, out: &mut [f64]) {
        let mut sum = 0.0;
        for (o, (_, list)) in out.iter_mut().zip(&self.grids) {
            *o = list.iter().map(|&(a, k, w)| w * lobe(a, k, d)).sum::<f64>() + FLOOR;
            sum += *o;
        }
        out.iter_mut().for_each(|o| *o /= sum);
    }

    pub(crate) fn integrate(&self, f: &dyn Fn(DVec3) -> f64) -> f64 {
        self.expected_bins(f).iter().sum()
    }

    fn expected_bins(&self, f: &dyn Fn(DVec3) -> f64) -> Vec<f64> {
        let mut out = Vec::new();
        for (g, (grid, _)) in self.grids.iter().enumerate() {
            out.extend(grid.integrate_bins(&|d| {
                let mut s = [0.0; MAX_GRIDS];
                self.shares(d, &mut s[..self.grids.len()]);
                f(d) * s[g]
            }));
        }
        out
    }

    /// Chi-square test of `samples` against `pdf`; `u` supplies one uniform number per sample.
    pub(crate) fn chi2(
        &self,
        samples: &[DVec3],
        pdf: &dyn Fn(DVec3) -> f64,
        u: &mut dyn FnMut() -> f64,
    ) -> Chi2Outcome {
        let per_grid: Vec<usize> = self.grids.iter().map(|(g, _)| g.n_theta * g.n_phi).collect();
        let total: usize = per_grid.iter().sum();
        let mut observed = vec![0.0; total + 1];
        let mut s = vec![0.0; self.grids.len()];
        for &d in samples {
            let x = u();
            let valid = d.is_finite() && d.length() > 0.0;
            if !valid {
                observed[total] += 1.0;
                continue;
            }
            self.shares(d.normalize(), &mut s);
            let (mut acc, mut g) = (0.0, self.grids.len() - 1);
            for (i, &share) in s.iter().enumerate() {
                acc += share;
                if x < acc {
                    g = i;
                    break;
                }
            }
            let offset: usize = per_grid[..g].iter().sum();
            match self.grids[g].0.bin(d) {
                Some(b) => observed[offset + b] += 1.0,
                None => observed[total] += 1.0,
            }
        }
        let n = samples.len() as f64;
        let mut expected: Vec<f64> = self.expected_bins(pdf).into_iter().map(|e| e * n).collect();
        expected.push(0.0);
        chi2_test(&observed, &expected)
    }
}
