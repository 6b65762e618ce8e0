//! Checks shared by the BSDFs' tests: sampling against the density, the albedo two ways, and
//! values against Mitsuba's.

use super::{Bsdf, BsdfSample};
use crate::rng::Sampler;
use glam::{DVec3, Vec2, Vec3A};
use zerovar_testkit::{MeanEstimate, SphereGrid};

/// Samples of `sample` against `pdf` (chi-square on `grid`), the
/// pdf's integral against the share of samples drawn, and the mean weight against the
/// integral of `eval` (the albedo two ways, with the power to see a 1% bias), which may
/// not exceed `most` (1, or eta^2 where radiance is compressed into a denser medium).
pub(crate) fn check(
    what: &str,
    most: f64,
    sample: &dyn Fn(f32, Vec2) -> Option<BsdfSample>,
    pdf: &dyn Fn(Vec3A) -> f32,
    eval: &dyn Fn(Vec3A) -> f32,
    grid: SphereGrid,
) {
    let n = 200_000;
    let mut s = Sampler::new(11, 3, 5);
    let (mut dirs, mut albedo) = (Vec::new(), MeanEstimate::default());
    for _ in 0..n {
        match sample(s.next_1d(), s.next_2d()) {
            Some(bs) => {
                let p = pdf(bs.wi);
                assert!((bs.pdf - p).abs() <= 1e-4 * p, "{what}: pdf {} vs {p}", bs.pdf);
                assert!(bs.weight.x.is_finite() && bs.weight.x >= 0.0, "{what}: {bs:?}");
                albedo.push(f64::from(bs.weight.x));
                dirs.push(bs.wi.as_dvec3());
            }
            None => albedo.push(0.0),
        }
    }
    let drawn = dirs.len() as f64 / f64::from(n);
    let total = grid.integrate(&|d| f64::from(pdf(d.as_vec3a())));
    let sigma = (drawn * (1.0 - drawn) / f64::from(n)).sqrt();
    assert!(
        (total - drawn).abs() < 5.0 * sigma + 2e-3,
        "{what}: pdf integrates to {total}, {drawn} drawn"
    );
    let conditional = |d: DVec3| f64::from(pdf(d.as_vec3a())) / total;
    grid.chi2(&dirs, &conditional).assert_pass(1e-3, what);
    let expected = grid.integrate(&|d| f64::from(eval(d.as_vec3a())));
    assert!(albedo.std_error() < 2.5e-3 * expected.max(1e-3), "{what}: too few samples");
    albedo.assert_matches(expected, 4.0, what);
    assert!(albedo.mean <= most + 4.0 * albedo.std_error(), "{what}: energy {}", albedo.mean);
}

/// Pairs of directions (`wo`, `wi`) at which BSDFs are compared with Mitsuba's.
pub(crate) const PAIRS: [([f32; 3], [f32; 3]); 5] = [
    ([0.3, 0.1, 0.9], [-0.5, 0.1, 0.8]),
    ([0.3, 0.1, 0.9], [-0.2, 0.1, -0.95]),
    ([0.2, -0.3, -0.8], [0.1, 0.4, 0.9]),
    ([0.2, -0.3, -0.8], [-0.3, 0.2, -0.9]),
    ([0.9, 0.0, 0.15], [-0.7, 0.1, 0.3]),
];

/// `bsdf` against Mitsuba 3.9.1's eval (per channel) and pdf for `PAIRS` (its `si.wi` is
/// zerovar's `wo`), within `tolerance` relative.
pub(crate) fn agrees(what: &str, bsdf: Bsdf, mitsuba: [([f32; 3], f32); 5], tolerance: f32) {
    for ((wo, wi), (value, pdf)) in PAIRS.into_iter().zip(mitsuba) {
        let (wo, wi) = (Vec3A::from(wo).normalize(), Vec3A::from(wi).normalize());
        let (v, p) = (bsdf.eval(wo, wi, Vec2::ZERO), bsdf.pdf(wo, wi, Vec2::ZERO));
        let close = |a: f32, b: f32| (a - b).abs() <= tolerance * b.abs().max(1e-6);
        let channels = (0..3).all(|c| close(v[c], value[c]));
        assert!(channels && close(p, pdf), "{what} {wo} -> {wi}: {v} {p} vs {value:?} {pdf}");
    }
}

/// Mitsuba's values where its eval is the same in every channel.
pub(crate) fn grey(values: [(f32, f32); 5]) -> [([f32; 3], f32); 5] {
    values.map(|(v, p)| ([v; 3], p))
}
