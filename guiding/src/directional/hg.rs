//! The Henyey-Greenstein (HG) phase function and its representation by a few vMF lobes.
//!
//! Convention: `cos theta = dot(ray_dir, new_dir)`, where `ray_dir` is the direction the path
//! was travelling and `new_dir` the direction it continues in (which is also the direction,
//! pointing away from the vertex, that light arrives from). `g > 0` scatters forward.
//!
//! **The vMF fit.** HG is exactly a continuous mixture of vMF lobes about the same axis. From
//! `x^{-3/2} = Gamma(3/2)^{-1} int t^{1/2} e^{-x t} dt` with `x = (1-g)^2 + 2g(1 - cos)`,
//!
//! `HG(cos) = int_0^inf w(kappa) vMF_kappa(cos) dkappa`,
//! `w(kappa) = (1-g^2) / sqrt(pi) (2g)^{-3/2} kappa^{-1/2} (1 - e^{-2 kappa}) e^{-beta kappa}`,
//! `beta = (1-g)^2 / (2g)`,
//!
//! and `w` integrates to one. We cut the kappa axis into [`HG_LOBES`] cells, equally wide in
//! `ln kappa` between the 2% and 98% quantiles of `w` (the outer cells reach 0 and infinity);
//! each cell becomes one lobe carrying the cell's mass, with the concentration whose mean
//! cosine is the cell's average mean cosine. The fitted mixture therefore has exactly HG's
//! total mass and mean cosine `g`, and its error is measured in the tests (L1 distance to HG).
//! Fits are tabulated over `|g|` once, on first use, and interpolated; negative `g` mirrors the
//! axis. `|g|` is clamped to [`G_MAX`], as pbrt does, since HG degenerates to a delta at 1.

use crate::directional::vmf;
use glam::{Vec2, Vec3};
use std::f64::consts::PI;
use std::sync::OnceLock;

/// The number of vMF lobes representing one HG lobe.
pub const HG_LOBES: usize = 4;

/// The largest `|g|` the fit represents; larger values are clamped to it.
pub const G_MAX: f32 = 0.99;

/// Below this `|g|`, HG is treated as isotropic (its deviation is below `3 |g|` relative).
const G_ISOTROPIC: f32 = 1e-4;

const TABLE_SIZE: usize = 256;

const QUANTILE_LO: f64 = 0.02;
const QUANTILE_HI: f64 = 0.98;

/// The density of the HG phase function at `cos_theta` (per steradian).
#[inline]
pub fn hg_pdf(cos_theta: f32, g: f32) -> f32 {
    let g = f64::from(g);
    let denom = 1.0 + g * g - 2.0 * g * f64::from(cos_theta);
    ((1.0 - g * g) / (4.0 * PI * denom * denom.max(0.0).sqrt())) as f32
}

/// Draws a new path direction from HG about `ray_dir` (the direction the path travelled).
#[inline]
pub fn hg_sample(ray_dir: Vec3, g: f32, u: Vec2) -> Vec3 {
    let gd = f64::from(g);
    let u0 = f64::from(u.x);
    let cos_theta = if g.abs() < 1e-3 {
        1.0 - 2.0 * u0
    } else {
        let s = (1.0 - gd * gd) / (1.0 - gd + 2.0 * gd * u0);
        ((1.0 + gd * gd - s * s) / (2.0 * gd)).clamp(-1.0, 1.0)
    };
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt() as f32;
    let (sp, cp) = (std::f32::consts::TAU * u.y).sin_cos();
    let (t, b) = ray_dir.any_orthonormal_pair();
    (t * (sin_theta * cp) + b * (sin_theta * sp) + ray_dir * cos_theta as f32).normalize()
}

/// HG approximated by [`HG_LOBES`] vMF lobes about `axis_sign * ray_dir`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HgFit {
    /// Concentrations of the lobes.
    pub kappa: [f32; HG_LOBES],
    /// Weights of the lobes (summing to one).
    pub weight: [f32; HG_LOBES],
    /// +1 for `g >= 0` (lobes about `ray_dir`), -1 for `g < 0` (about `-ray_dir`).
    pub axis_sign: f32,
}

impl HgFit {
    /// The density of the fitted mixture between unit directions `ray_dir` and `new_dir`,
    /// accurate for sharp lobes (it takes `cos - 1` from the difference of the vectors).
    pub fn pdf_between(&self, ray_dir: Vec3, new_dir: Vec3) -> f32 {
        let cm1 = vmf::cos_minus_one(ray_dir * self.axis_sign, new_dir);
        (0..HG_LOBES)
            .map(|i| {
                self.weight[i] * vmf::normalization(self.kappa[i]) * (self.kappa[i] * cm1).exp()
            })
            .sum()
    }

    /// The density of the fitted mixture at `cos_theta = dot(ray_dir, new_dir)`.
    pub fn pdf(&self, cos_theta: f32) -> f32 {
        let c = self.axis_sign * cos_theta;
        (0..HG_LOBES)
            .map(|i| {
                self.weight[i]
                    * vmf::normalization(self.kappa[i])
                    * (self.kappa[i] * (c - 1.0)).exp()
            })
            .sum()
    }
}

/// The vMF fit of HG with asymmetry `g` (see the module documentation).
pub fn hg_vmf_fit(g: f32) -> HgFit {
    let axis_sign = if g < 0.0 { -1.0 } else { 1.0 };
    let ga = if g.is_finite() { g.abs().min(G_MAX) } else { 0.0 };
    if ga < G_ISOTROPIC {
        return HgFit {
            kappa: [0.0; HG_LOBES],
            weight: [1.0 / HG_LOBES as f32; HG_LOBES],
            axis_sign,
        };
    }
    let table = table();
    let x = ga / G_MAX * (TABLE_SIZE - 1) as f32;
    let i = (x as usize).min(TABLE_SIZE - 2);
    let t = x - i as f32;
    let (a, b) = (&table[i], &table[i + 1]);
    let mut fit = HgFit { kappa: [0.0; HG_LOBES], weight: [0.0; HG_LOBES], axis_sign };
    for l in 0..HG_LOBES {
        fit.kappa[l] = a.kappa[l] + t * (b.kappa[l] - a.kappa[l]);
        fit.weight[l] = a.weight[l] + t * (b.weight[l] - a.weight[l]);
    }
    fit
}

fn table() -> &'static [HgFit] {
    static TABLE: OnceLock<Vec<HgFit>> = OnceLock::new();
    TABLE.get_or_init(|| {
        (0..TABLE_SIZE)
            .map(|i| fit_exact(f64::from(G_MAX) * i as f64 / (TABLE_SIZE - 1) as f64))
            .collect()
    })
}

/// The weight `w(kappa)` of HG's exact vMF scale mixture (module documentation).
fn kappa_density(g: f64, kappa: f64) -> f64 {
    let beta = (1.0 - g) * (1.0 - g) / (2.0 * g);
    (1.0 - g * g) / PI.sqrt() * (2.0 * g).powf(-1.5) / kappa.sqrt()
        * -(-2.0 * kappa).exp_m1()
        * (-beta * kappa).exp()
}

/// Integrates `w` on a fine grid in `ln kappa` and cuts it into cells, one per lobe.
fn fit_exact(g: f64) -> HgFit {
    if g < f64::from(G_ISOTROPIC) {
        return HgFit {
            kappa: [0.0; HG_LOBES],
            weight: [1.0 / HG_LOBES as f32; HG_LOBES],
            axis_sign: 1.0,
        };
    }
    let beta = (1.0 - g) * (1.0 - g) / (2.0 * g);
    // Below kappa_lo the density grows like kappa^{3/2} in ln kappa; above kappa_hi it is
    // e^{-50}: neither end carries mass that matters.
    let (t0, t1) = ((1e-7 * (1.0f64).min(1.0 / beta)).ln(), (60.0 / beta).ln());
    const N: usize = 8000;
    let h = (t1 - t0) / N as f64;
    let f = |j: usize| {
        let k = (t0 + h * j as f64).exp();
        let m = kappa_density(g, k) * k;
        (m, m * vmf::mean_cosine_f64(k))
    };
    // First pass: the cumulative mass on the grid, to find the quantiles that bound the cells.
    let mut cdf = Vec::with_capacity(N + 1);
    let mut samples = Vec::with_capacity(N + 1);
    let mut cumulative = 0.0;
    for j in 0..=N {
        let (m, a) = f(j);
        if let Some(&(pm, _)) = samples.last() {
            cumulative += 0.5 * h * (m + pm);
        }
        samples.push((m, a));
        cdf.push(cumulative);
    }
    let quantile = |p: f64| -> f64 {
        let j = cdf.partition_point(|&c| c < p * cumulative);
        t0 + h * j as f64
    };
    // Cells equally wide in ln kappa between the QUANTILE_LO and QUANTILE_HI quantiles (the
    // outer cells reach to the ends): lumping a wide range of ln kappa into one lobe is what
    // costs accuracy, and equal-mass cells would lump the whole broad tail into one.
    let (lo, hi) = (quantile(QUANTILE_LO), quantile(QUANTILE_HI));
    let cell_of = |t: f64| -> usize {
        let x = (t - lo) / (hi - lo) * HG_LOBES as f64;
        (x.max(0.0) as usize).min(HG_LOBES - 1)
    };
    let mut mass = [0.0f64; HG_LOBES];
    let mut moment = [0.0f64; HG_LOBES];
    for j in 1..=N {
        let ((m, a), (pm, pa)) = (samples[j], samples[j - 1]);
        let cell = cell_of(t0 + h * (j as f64 - 0.5));
        mass[cell] += 0.5 * h * (m + pm);
        moment[cell] += 0.5 * h * (a + pa);
    }
    let total: f64 = mass.iter().sum();
    let mut fit = HgFit { kappa: [0.0; HG_LOBES], weight: [0.0; HG_LOBES], axis_sign: 1.0 };
    for l in 0..HG_LOBES {
        fit.weight[l] = (mass[l] / total) as f32;
        fit.kappa[l] = if mass[l] > 0.0 {
            vmf::kappa_from_mean_cosine_f64(moment[l] / mass[l]) as f32
        } else {
            0.0
        };
    }
    fit
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use zerovar_testkit::integrate_1d;

    pub(crate) const GS: [f32; 5] = [-0.99, -0.5, 0.0, 0.5, 0.99];

    /// `2 pi int_{-1}^{1} f(c) dc` for a zonal function peaked at `c = 1`, integrated in
    /// `ln(1 - c)` so that peaks of width 1e-5 are resolved.
    pub(crate) fn zonal_integral(f: &dyn Fn(f64) -> f64) -> f64 {
        let tail = integrate_1d(&|t: f64| f(1.0 - t.exp()) * t.exp(), (1e-14f64).ln(), 0.0, 400);
        let body = integrate_1d(f, -1.0, 0.0, 200);
        2.0 * PI * (tail + body)
    }

    #[test]
    fn hg_is_normalised_with_mean_cosine_g() {
        for &g in &GS {
            // Integrate the mirrored function for g < 0 so the peak is at c = 1.
            let s = f64::from(g.signum());
            let norm = zonal_integral(&|c| f64::from(hg_pdf((s * c) as f32, g)));
            let mean = zonal_integral(&|c| s * c * f64::from(hg_pdf((s * c) as f32, g)));
            assert!((norm - 1.0).abs() < 1e-4, "g {g}: {norm}");
            assert!((mean - f64::from(g)).abs() < 1e-4, "g {g}: {mean}");
        }
    }

    #[test]
    fn kappa_density_integrates_to_one() {
        for &g in &[0.001f64, 0.1, 0.5, 0.9, 0.99] {
            let fit = fit_exact(g);
            let s: f32 = fit.weight.iter().sum();
            assert!((s - 1.0).abs() < 1e-6);
            // The unnormalised total must be one too: check by a direct integral.
            let beta = (1.0 - g) * (1.0 - g) / (2.0 * g);
            let (t0, t1) = ((1e-7 * (1.0f64).min(1.0 / beta)).ln(), (60.0 / beta).ln());
            let total = integrate_1d(&|t: f64| kappa_density(g, t.exp()) * t.exp(), t0, t1, 2000);
            assert!((total - 1.0).abs() < 1e-6, "g {g}: {total}");
        }
    }

    #[test]
    fn fit_keeps_mass_and_mean_cosine_and_is_close_to_hg() {
        for &g in &[0.1f32, 0.3, 0.5, 0.7, 0.9, 0.95, 0.99] {
            let fit = hg_vmf_fit(g);
            let mean: f64 = (0..HG_LOBES)
                .map(|l| f64::from(fit.weight[l]) * vmf::mean_cosine_f64(f64::from(fit.kappa[l])))
                .sum();
            // Exact at table nodes; interpolation between nodes moves it slightly.
            assert!((mean - f64::from(g)).abs() < 2e-3, "g {g}: mean cosine {mean}");
            let l1 =
                zonal_integral(&|c| f64::from((hg_pdf(c as f32, g) - fit.pdf(c as f32)).abs()));
            eprintln!("g {g}: L1 error {l1:.4}");
            assert!(l1 < HG_FIT_L1_BOUND, "g {g}: L1 error {l1}");
        }
    }

    /// Bound on the L1 distance between HG and its fit, over `|g| <= G_MAX` (measured: 0.003 at
    /// g = 0.1, 0.03 at 0.5, 0.06 at 0.9, 0.13 at 0.99).
    pub(crate) const HG_FIT_L1_BOUND: f64 = 0.14;

    #[test]
    fn negative_g_mirrors() {
        let (a, b) = (hg_vmf_fit(0.6), hg_vmf_fit(-0.6));
        assert_eq!(a.kappa, b.kappa);
        assert_eq!(b.axis_sign, -1.0);
        assert!((a.pdf(0.3) - b.pdf(-0.3)).abs() < 1e-6);
    }

    #[test]
    fn hg_sampling_follows_pdf() {
        use rand_pcg::Pcg32;
        use rand_pcg::rand_core::Rng;
        use zerovar_testkit::SphereGrid;
        let mut rng = Pcg32::new(9, 1);
        let mut u = || (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
        let axis = Vec3::new(0.0, 0.6, 0.8);
        for &g in &GS {
            let samples: Vec<_> =
                (0..40_000).map(|_| hg_sample(axis, g, Vec2::new(u(), u())).as_dvec3()).collect();
            let grid = SphereGrid::for_lobe(axis.as_dvec3() * f64::from(g.signum()), 100.0);
            grid.chi2(&samples, &|d| f64::from(hg_pdf(d.as_vec3().dot(axis), g)))
                .assert_pass(1e-3, &format!("HG g {g}"));
        }
    }
}
