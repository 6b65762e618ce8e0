//! Helpers shared by the integration tests: scenes from text, per-channel estimates.

use glam::Vec2;
use zerovar::integrators::VolPath;
use zerovar::rng::Sampler;
use zerovar::scene::Scene;
use zerovar::stats::Counters;
use zerovar_testkit::MeanEstimate;
pub(crate) use zerovar_testkit::files::{repo, temp_dir, write};

/// A scene from TOML text (relative paths resolve against the test's temporary directory).
pub(crate) fn scene(text: &str) -> Scene {
    zerovar::scene::load_str(&temp_dir().join("test.toml"), text, &[])
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Per-channel mean estimates of `n` camera paths through uniformly random film positions
/// inside `region` (pixel coordinates, min and max).
pub(crate) fn estimate_region(
    scene: &Scene,
    seed: u64,
    n: u64,
    region: (Vec2, Vec2),
) -> [MeanEstimate; 3] {
    let integrator = VolPath::from_scene(scene);
    let mut counters = Counters::default();
    let mut est: [MeanEstimate; 3] = Default::default();
    for i in 0..n {
        let mut s = Sampler::new(seed, 0, i);
        let film = region.0 + (region.1 - region.0) * s.next_2d();
        let ray = scene.camera().ray(film);
        let l = integrator.radiance(scene, ray, scene.camera_medium(), &mut s, &mut counters);
        assert!(l.is_finite(), "non-finite radiance {l}");
        for c in 0..3 {
            est[c].push(l[c] as f64);
        }
    }
    est
}

/// The mean luminance of one quadrant of a film, with the variance and third cumulant of that
/// mean, from the per-pixel sample moments.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Quadrant {
    pub(crate) mean: f64,
    pub(crate) var: f64,
    pub(crate) k3: f64,
}

impl Quadrant {
    pub(crate) fn std_error(&self) -> f64 {
        self.var.sqrt()
    }
}

/// Each quadrant's mean luminance (see `Quadrant`).
pub(crate) fn quadrant_means(f: &zerovar::film::Film) -> [Quadrant; 4] {
    let (w, h) = (f.width() as usize, f.height() as usize);
    let (mut sum, mut var, mut k3, mut count) =
        ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4], [0usize; 4]);
    for (i, p) in f.pixels().iter().enumerate() {
        let k = (i % w >= w / 2) as usize + 2 * (i / w >= h / 2) as usize;
        let n = p.count as f64;
        // The renderer's luminance weights (`math::luminance`), in double precision: the third
        // moment about the mean cancels badly with a rounded mean.
        let weights = [0.212_671f32, 0.715_160, 0.072_169].map(f64::from);
        let m = p.rgb.iter().zip(weights).map(|(s, c)| s / n * c).sum::<f64>();
        sum[k] += m;
        let (v, c3) = mean_cumulants(n, m, p.lum_sq, p.lum_cube);
        var[k] += v;
        k3[k] += c3;
        count[k] += 1;
    }
    std::array::from_fn(|k| {
        let c = count[k] as f64;
        Quadrant { mean: sum[k] / c, var: var[k] / (c * c), k3: k3[k] / (c * c * c) }
    })
}

/// The variance and third cumulant of the mean `m` of `n` samples whose squares and cubes sum
/// to `sum_sq` and `sum_cube`: the samples' unbiased second and third cumulants over `n` and
/// `n^2`.
fn mean_cumulants(n: f64, m: f64, sum_sq: f64, sum_cube: f64) -> (f64, f64) {
    let m2 = (sum_sq / n - m * m).max(0.0);
    let m3 = sum_cube / n - 3.0 * m * sum_sq / n + 2.0 * m * m * m;
    (m2 / (n - 1.0), m3 / ((n - 1.0) * (n - 2.0)))
}

/// The test statistic for "the two means are equal": their difference in standard errors,
/// with Johnson's (1978) correction for skewness. Path-traced samples are right-skewed, and
/// then a render's mean and its standard-error estimate are correlated (a render that missed
/// rare bright paths has both too low), which gives the plain z a heavy lower tail; the
/// correction, in cumulants `(d + K3 / 6V + K3 d^2 / 3V^2) / sqrt(V)` for a difference `d` of
/// variance `V` and third cumulant `K3`, removes its first-order skew.
pub(crate) fn z_score(a: &Quadrant, b: &Quadrant) -> f64 {
    let d = a.mean - b.mean;
    let v = a.var + b.var;
    if v <= 0.0 {
        return if d == 0.0 { 0.0 } else { f64::INFINITY.copysign(d) };
    }
    let k3 = a.k3 - b.k3;
    (d + k3 / (6.0 * v) + k3 * d * d / (3.0 * v * v)) / v.sqrt()
}

/// Asserts that two renders agree quadrant by quadrant within `z_max` standard errors.
pub(crate) fn assert_same_image(
    a: &zerovar::film::Film,
    b: &zerovar::film::Film,
    z_max: f64,
    what: &str,
) {
    assert_quadrants_agree(quadrant_means(a), quadrant_means(b), z_max, what);
}

/// Asserts that two images' quadrant means (from `quadrant_means`) agree within `z_max`
/// standard errors.
pub(crate) fn assert_quadrants_agree(a: [Quadrant; 4], b: [Quadrant; 4], z_max: f64, what: &str) {
    for (k, (qa, qb)) in a.iter().zip(&b).enumerate() {
        let z = z_score(qa, qb);
        assert!(
            z.abs() < z_max,
            "{what}: quadrant {k}: {} +- {} vs {} +- {} (z = {z:.2})",
            qa.mean,
            qa.std_error(),
            qb.mean,
            qb.std_error()
        );
    }
}

#[test]
fn the_skew_corrected_z_has_normal_tails_for_skewed_samples() {
    // Means of 30 exponential samples (skewness 2) against the exact mean 1: beyond 2.5 the
    // plain z's lower tail is six times the normal 0.62% and its upper tail a quarter of it
    // (measured 3.8% and 0.15%); Johnson's correction halves the lower excess at least and
    // puts the upper tail on the normal one (measured 1.2% and 0.56%). 40000 replicates give
    // a tail rate near 0.6% a standard error of 0.04%, near 1.2% of 0.055%.
    let mut sampler = zerovar::rng::Sampler::new(11, 0, 0);
    let exact = Quadrant { mean: 1.0, var: 0.0, k3: 0.0 };
    let (mut plain, mut corrected) = ([0u32; 2], [0u32; 2]);
    let replicates = 40_000;
    for _ in 0..replicates {
        let n = 30.0;
        let (mut s1, mut s2, mut s3) = (0.0, 0.0, 0.0);
        for _ in 0..30 {
            let x = -(1.0 - f64::from(sampler.next_1d())).ln();
            (s1, s2, s3) = (s1 + x, s2 + x * x, s3 + x * x * x);
        }
        let m = s1 / n;
        let (var, k3) = mean_cumulants(n, m, s2, s3);
        let q = Quadrant { mean: m, var, k3 };
        for (z, tails) in
            [((m - 1.0) / var.sqrt(), &mut plain), (z_score(&q, &exact), &mut corrected)]
        {
            tails[0] += u32::from(z < -2.5);
            tails[1] += u32::from(z > 2.5);
        }
    }
    let rate = |c: u32| f64::from(c) / f64::from(replicates);
    let (plain, corrected) = (plain.map(rate), corrected.map(rate));
    let what = format!("tails beyond -2.5 and 2.5: plain {plain:?}, corrected {corrected:?}");
    assert!(plain[0] > 0.02 && corrected[0] < 0.5 * plain[0], "{what}");
    assert!((corrected[1] - 0.0062).abs() < 0.002, "{what}");
}
