//! Single scattering from a point light in an infinite thin homogeneous medium against a
//! numerically integrated answer: L = int_0^inf T(t) sigma_s p(theta(t)) I T(r) / r^2 dt,
//! for HG, Rayleigh and blended phase functions.

use crate::common::scene;
use glam::{Vec2, Vec3A};
use zerovar::integrators::VolPath;
use zerovar::phase::hg;
use zerovar::rng::Sampler;
use zerovar::stats::Counters;
use zerovar_testkit::{MeanEstimate, integrate_1d};

fn scene_text(sigma_t: f64, albedo: f64, phase: &str) -> String {
    format!(
        r#"
medium = "air"

[render]
max_depth = 2

[camera]
origin = [0, 0, 0]
target = [0, 0, -1]
fov = 30
resolution = [1, 1]

[media.air]
type = "homogeneous"
sigma_t = {sigma_t}
albedo = {albedo}
phase = {phase}

[[lights]]
type = "point"
position = [0.6, 0.4, -2.0]
intensity = 5
"#
    )
}

fn reference(sigma_t: f64, albedo: f64, phase: &dyn Fn(f32) -> f64, dir: Vec3A) -> f64 {
    let light = Vec3A::new(0.6, 0.4, -2.0).as_dvec3();
    let d = dir.as_dvec3();
    let f = |t: f64| {
        let p = d * t;
        let to = light - p;
        let r = to.length();
        let cos = d.dot(to / r) as f32;
        (-sigma_t * t).exp() * sigma_t * albedo * phase(cos) * 5.0 * (-sigma_t * r).exp() / (r * r)
    };
    // The integrand peaks near the closest approach to the light (t about 2); beyond 200 the
    // remainder is below 1e-9.
    integrate_1d(&f, 0.0, 8.0, 4000) + integrate_1d(&f, 8.0, 200.0, 4000)
}

/// A phase function's density of the scattering cosine.
type Density = Box<dyn Fn(f32) -> f64>;

/// The Rayleigh density, written out here independently of the renderer's.
fn rayleigh(cos: f32) -> f64 {
    3.0 / (16.0 * std::f64::consts::PI) * (1.0 + f64::from(cos).powi(2))
}

#[test]
fn point_light_single_scattering_matches_quadrature() {
    let hg_of = |g: f32| move |cos: f32| f64::from(hg(g, cos));
    let cases: [(f64, f64, String, Density); 5] = [
        (0.05, 0.8, "{ type = \"hg\", g = 0.0 }".into(), Box::new(hg_of(0.0))),
        (0.1, 0.9, "{ type = \"hg\", g = 0.7 }".into(), Box::new(hg_of(0.7))),
        (0.02, 1.0, "{ type = \"hg\", g = -0.5 }".into(), Box::new(hg_of(-0.5))),
        (0.1, 0.9, "{ type = \"rayleigh\" }".into(), Box::new(rayleigh)),
        (
            0.1,
            0.9,
            "{ type = \"blendphase\", weight = 0.3, phases = [{ type = \"hg\", g = 0.8 }, { type = \"rayleigh\" }] }"
                .into(),
            Box::new(move |cos| 0.7 * f64::from(hg(0.8, cos)) + 0.3 * rayleigh(cos)),
        ),
    ];
    for (sigma_t, albedo, phase, density) in cases {
        let s = scene(&scene_text(sigma_t, albedo, &phase));
        let integrator = VolPath::from_scene(&s);
        let ray = s.camera().ray(Vec2::splat(0.5));
        let expected = reference(sigma_t, albedo, &density, ray.direction);
        let mut counters = Counters::default();
        let est: MeanEstimate = (0..200_000)
            .map(|i| {
                let mut sampler = Sampler::new(3, 0, i);
                integrator.radiance(&s, ray, s.camera_medium(), &mut sampler, &mut counters).x
                    as f64
            })
            .collect();
        est.assert_matches(
            expected,
            4.5,
            &format!("single scattering sigma_t {sigma_t} phase {phase}"),
        );
        assert!(est.std_error() < 0.02 * expected, "too noisy to test anything: {est:?}");
    }
}
