//! Free-flight sampling and transmittance estimation against exp(-tau), with tau analytic for
//! homogeneous slabs and by quadrature of the density for heterogeneous ones.

use glam::{Vec3, Vec3A};
use zerovar::math::{Ray, Spectrum};
use zerovar::media::{
    AlbedoField, DensityField, Grid, Heterogeneous, Medium, MediumKind, NoiseCloud, VolGrid,
};
use zerovar::phase::PhaseFunction;
use zerovar::rng::Sampler;
use zerovar::stats::Counters;
use zerovar::tracking::{FlightEvent, Tracker, sample_flight, transmittance};
use zerovar::transform::Transform;
use zerovar_testkit::{MeanEstimate, integrate_1d};

const N: u64 = 40_000;
const Z: f64 = 4.5;

fn medium(kind: MediumKind) -> Medium {
    Medium { name: "m".into(), kind, phase: PhaseFunction::Isotropic, emission: Spectrum::ZERO }
}

fn heterogeneous(density: DensityField, scale: f32, tint: Spectrum) -> Medium {
    let to_world = Transform::scale(Vec3::new(2.0, 1.0, 1.0)).unwrap();
    medium(MediumKind::Heterogeneous(Box::new(Heterogeneous::new(
        to_world,
        density,
        scale,
        tint,
        AlbedoField::Constant(Spectrum::splat(0.5)),
    ))))
}

/// A ray crossing the box [0, 2] x [0, 1]^2 along x, off the voxel centres.
fn ray() -> Ray {
    Ray::new(Vec3A::new(-0.5, 0.37, 0.61), Vec3A::new(1.0, 0.02, -0.01).normalize())
}

/// exp(-tau) per channel, tau by quadrature of the extinction along the ray, over the part of
/// the ray inside the box (x from 0 to 2), where the extinction is continuous.
fn reference(m: &Medium, ray: &Ray, t_max: f32) -> [f64; 3] {
    let dx = ray.direction.x as f64;
    let (t0, t1) = (0.5 / dx, (2.5 / dx).min(t_max as f64));
    let tau = |c: usize| {
        integrate_1d(&|t| m.coefficients(ray.at(t as f32)).sigma_t[c] as f64, t0, t1, 2000)
    };
    [0, 1, 2].map(|c| (-tau(c)).exp())
}

/// Per channel: the escape weight of free flights (zero on a collision) and the ratio/analytic
/// transmittance estimate, each against `expected`.
fn check(m: &Medium, t_max: f32, expected: [f64; 3], what: &str) {
    let tracker = Tracker::for_medium(m);
    let ray = ray();
    let mut counters = Counters::default();
    let mut flight: [MeanEstimate; 3] = Default::default();
    let mut ratio: [MeanEstimate; 3] = Default::default();
    for i in 0..N {
        let mut s = Sampler::new(11, 0, i);
        let f = sample_flight(m, tracker, &ray, t_max, Spectrum::ONE, &mut s, &mut counters);
        let escaped = if f.event == FlightEvent::Escape { f.weight } else { Spectrum::ZERO };
        let tr = transmittance(m, &ray, t_max, &mut s, &mut counters);
        for c in 0..3 {
            flight[c].push(escaped[c] as f64);
            ratio[c].push(tr[c] as f64);
        }
    }
    for c in 0..3 {
        // When (nearly) every flight escapes the sample variance can be zero; the Bernoulli
        // variance of escaping with probability T is then the floor of the standard error.
        let bernoulli = (expected[c] * (1.0 - expected[c]) / N as f64).sqrt();
        let z = (flight[c].mean - expected[c]) / flight[c].std_error().max(bernoulli);
        assert!(
            z.abs() < Z,
            "{what}: free-flight escape, channel {c} ({tracker:?}): {:?} vs {}",
            flight[c],
            expected[c]
        );
        if ratio[c].std_error() > 0.0 {
            ratio[c].assert_matches(expected[c], Z, &format!("{what}: transmittance, channel {c}"));
        } else {
            let e = (ratio[c].mean - expected[c]).abs();
            assert!(e < 1e-5 * expected[c].max(1e-30), "{what}: analytic transmittance off by {e}");
        }
    }
}

#[test]
fn homogeneous_slabs_match_exp_minus_tau() {
    for sigma in [1e-6f32, 0.3, 2.0, 40.0] {
        let m = medium(MediumKind::Homogeneous {
            sigma_t: Spectrum::splat(sigma),
            albedo: Spectrum::splat(0.5),
        });
        let expected = [(-(sigma as f64) * 1.5).exp(); 3];
        check(&m, 1.5, expected, &format!("grey sigma {sigma}"));
    }
    let sigma = Spectrum::new(0.2, 1.0, 3.0);
    let m = medium(MediumKind::Homogeneous { sigma_t: sigma, albedo: Spectrum::splat(0.5) });
    check(&m, 1.2, sigma.to_array().map(|s| (-(s as f64) * 1.2).exp()), "chromatic");
}

#[test]
fn heterogeneous_slabs_match_quadrature() {
    // A ramp grid: trilinear between voxel centres, clamped outside them.
    let vol = VolGrid::new([4, 2, 2], 1, (0..16).map(|i| (i % 4) as f32 * 0.5 + 0.1).collect())
        .expect("a valid grid");
    let grid = heterogeneous(DensityField::Grid(Grid::new(vol)), 1.5, Spectrum::ONE);
    check(&grid, 10.0, reference(&grid, &ray(), 10.0), "ramp grid, delta tracking");
    let noise = heterogeneous(DensityField::Noise(NoiseCloud::default()), 6.0, Spectrum::ONE);
    // A ray through the middle of the cloud, ending inside it.
    check(&noise, 1.6, reference(&noise, &ray(), 1.6), "noise cloud, delta tracking");
    let chroma = heterogeneous(
        DensityField::Noise(NoiseCloud::default()),
        6.0,
        Spectrum::new(0.3, 1.0, 1.8),
    );
    assert_eq!(Tracker::for_medium(&chroma), Tracker::Spectral);
    check(
        &chroma,
        10.0,
        reference(&chroma, &ray(), 10.0),
        "chromatic noise cloud, spectral tracking",
    );
}
