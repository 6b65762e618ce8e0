//! Single scattering from a point light in an infinite thin homogeneous medium against a
//! numerically integrated answer: L = int_0^inf T(t) sigma_s p(theta(t)) I T(r) / r^2 dt,
//! for HG, Rayleigh and blended phase functions, and for a ray passing close to the light,
//! where only the extra collision aimed at it keeps the estimate's variance bounded.

use crate::common::scene;
use glam::{Vec2, Vec3A};
use zerovar::guided::NoCache;
use zerovar::integrators::VolPath;
use zerovar::integrators::walk::{self, WalkContext, WalkSettings};
use zerovar::phase::hg;
use zerovar::rng::Sampler;
use zerovar::stats::Counters;
use zerovar_testkit::{MeanEstimate, integrate_1d};

/// Where the point light of [`scene_text`] stands.
const LIGHT: [f32; 3] = [0.6, 0.4, -2.0];

fn scene_text(sigma_t: f64, albedo: f64, phase: &str) -> String {
    scene_with_light(sigma_t, albedo, phase, LIGHT)
}

fn scene_with_light(sigma_t: f64, albedo: f64, phase: &str, light: [f32; 3]) -> String {
    let [x, y, z] = light;
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
position = [{x}, {y}, {z}]
intensity = 5
"#
    )
}

fn reference(sigma_t: f64, albedo: f64, phase: &dyn Fn(f32) -> f64, dir: Vec3A) -> f64 {
    reference_with_light(sigma_t, albedo, phase, dir, LIGHT)
}

fn reference_with_light(
    sigma_t: f64,
    albedo: f64,
    phase: &dyn Fn(f32) -> f64,
    dir: Vec3A,
    light: [f32; 3],
) -> f64 {
    let light = Vec3A::from(light).as_dvec3();
    let d = dir.as_dvec3();
    let f = |t: f64| {
        let p = d * t;
        let to = light - p;
        let r = to.length();
        let cos = d.dot(to / r) as f32;
        (-sigma_t * t).exp() * sigma_t * albedo * phase(cos) * 5.0 * (-sigma_t * r).exp() / (r * r)
    };
    // The integrand peaks at the closest approach to the light (t about 2), over a width of
    // the ray's distance from it; beyond 200 the remainder is below 1e-9.
    let foot = light.dot(d);
    integrate_1d(&f, 0.0, foot - 0.1, 4000)
        + integrate_1d(&f, foot - 0.1, foot + 0.1, 20_000)
        + integrate_1d(&f, foot + 0.1, 8.0, 4000)
        + integrate_1d(&f, 8.0, 200.0, 4000)
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
    // The denser fog's ray passes far enough from the light (in mean free paths) that it
    // takes no extra collision for it; the others take one.
    let cases: [(f64, f64, String, Density); 6] = [
        (0.05, 0.8, "{ type = \"hg\", g = 0.0 }".into(), Box::new(hg_of(0.0))),
        (0.6, 0.8, "{ type = \"hg\", g = 0.0 }".into(), Box::new(hg_of(0.0))),
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
        let est: MeanEstimate = (0..400_000)
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
        let takes_extra = sigma_t < 0.5;
        assert_eq!(counters.extra_collisions > 0, takes_extra, "sigma_t {sigma_t}: {counters:?}");
        // A 1% bias is 4.5 standard errors.
        assert!(est.std_error() < 0.0022 * expected, "too noisy to see a 1% bias: {est:?}");
    }
}

/// A ray passing 0.005 from a point light. From free-path collisions alone, next-event estimates
/// near the light carry `1 / r^2` at a density that stays bounded there: their relative variance
/// grows as the inverse of the ray's distance from the light (and diverges for rays that
/// meet it, as a pixel's do). The extra collision aimed at the light (equiangular, on by
/// default and unguided) bounds it; both match quadrature, and without it the same samples
/// spread at least 5x as far, so the bound is what the first check sees.
#[test]
fn point_light_collisions_bound_the_variance_near_the_light() {
    let light = [0.005, 0.0, -2.0];
    let text = scene_with_light(0.1, 0.9, "{ type = \"hg\", g = 0.3 }", light);
    let s = scene(&text);
    let ray = s.camera().ray(Vec2::splat(0.5));
    let expected =
        reference_with_light(0.1, 0.9, &|cos| f64::from(hg(0.3, cos)), ray.direction, light);
    let aimed = VolPath::from_scene(&s).settings();
    assert!(aimed.point_light_collisions, "extra collisions for point lights are the default");
    let free = WalkSettings { point_light_collisions: false, ..aimed };
    let estimate = |settings: &WalkSettings| -> MeanEstimate {
        let mut counters = Counters::default();
        (0..150_000)
            .map(|i| {
                let mut sampler = Sampler::new(5, 0, i);
                let mut cache = NoCache;
                let mut ctx = WalkContext::new(&mut cache);
                let start = walk::PathStart::unbounded(ray, s.camera_medium());
                f64::from(
                    walk::radiance(settings, &s, start, &mut ctx, &mut sampler, &mut counters).x,
                )
            })
            .collect()
    };
    let (with, without) = (estimate(&aimed), estimate(&free));
    with.assert_matches(expected, 4.5, "aimed at the light");
    assert!(with.std_error() < 0.0022 * expected, "aimed at the light: {with:?} of {expected}");
    without.assert_matches(expected, 4.5, "free paths alone");
    assert!(
        without.std_error() > 5.0 * with.std_error(),
        "free paths alone {without:?} against aimed {with:?}"
    );
}
