//! The hot kernels of a guided walk: Henyey-Greenstein sampling, one free flight through the
//! cloud per tracker and steered by a trained field, a shadow ray's transmittance through the
//! cloud, guided distance sampling along a camera ray of the fog room with a trained field
//! (the ray's intersection included), and one whole camera path, unguided and fully guided.
//! `cargo bench --bench kernels`. (Whole paths per tracker: `--bench tracking`; vMF products
//! and field lookups: `cargo bench -p zerovar-guiding`.)

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{Vec2, Vec3A};
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;
use zerovar::guided::distance::{GuidedDistance, SEGMENTS, guided_flight};
use zerovar::guided::{Components, FieldCache, NoCache, RadianceCache, TrainedField};
use zerovar::integrators::walk::{PathStart, WalkContext, WalkSettings, radiance};
use zerovar::integrators::{VolPath, shadow_transmittance};
use zerovar::math::Ray;
use zerovar::phase::PhaseFunction;
use zerovar::render::{Budget, RenderOptions, TrainBudget, train};
use zerovar::rng::Sampler;
use zerovar::scene::Scene;
use zerovar::stats::Counters;
use zerovar::tracking::{Tracker, sample_flight};

const BATCH: u64 = 256;

fn load(path: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    zerovar::scene::load(&path, &[]).expect("scene")
}

/// A field trained on `scene` by four passes (1 + 2 + 4 + 8 spp), as `zerovar render` would.
fn trained(scene: &Scene) -> TrainedField {
    let mut options = RenderOptions::unguided(Budget::Samples(1), 0);
    options.guiding.components = Components::FULL;
    options.guiding.train = TrainBudget::Passes(4);
    train(scene, &options, &|_, _| true).expect("training").0
}

/// A camera ray through a random point of the film.
fn camera_ray(scene: &Scene, s: &mut Sampler) -> Ray {
    let [w, h] = scene.camera().resolution().map(|r| r as f32);
    scene.camera().ray(s.next_2d() * Vec2::new(w, h))
}

fn phase(c: &mut Criterion) {
    let mut group = c.benchmark_group("phase");
    for g in [0.0f32, 0.6, 0.99] {
        let hg = PhaseFunction::HenyeyGreenstein { g };
        let mut s = Sampler::new(1, 0, 0);
        group.bench_function(format!("hg-sample-g{g}"), |b| {
            b.iter(|| black_box(hg.sample(Vec3A::Z, s.next_2d())))
        });
    }
    group.finish();
}

fn transmittance(c: &mut Criterion) {
    let scene = load("scenes/cloud.toml");
    let medium = scene.camera_medium();
    let mut s = Sampler::new(2, 0, 0);
    let mut counters = Counters::default();
    // Shadow rays from the camera to random points across the cloud's bounding box.
    let bounds = scene.bounds();
    c.bench_function("transmittance/cloud-shadow-ray", |b| {
        b.iter(|| {
            let u = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d());
            let target = bounds.min + u * (bounds.max - bounds.min);
            let origin = scene.camera().origin();
            let to = target - origin;
            let ray = Ray::new(origin, to.normalize());
            black_box(shadow_transmittance(&scene, ray, to.length(), medium, &mut s, &mut counters))
        })
    });
}

fn free_flight(c: &mut Criterion) {
    let scene = load("scenes/cloud.toml");
    let medium = &scene.media()[0];
    let mut group = c.benchmark_group("free-flight-cloud");
    let trackers = [
        Tracker::Delta,
        Tracker::WeightedDelta,
        Tracker::Decomposition,
        Tracker::WeightedDecomposition,
        Tracker::Spectral,
        Tracker::SpectralDecomposition,
        Tracker::RayMarching,
    ];
    for tracker in trackers {
        let mut s = Sampler::new(5, 0, 0);
        let mut counters = Counters::default();
        // From the cloud's centre in random directions, to the box around it.
        let centre = Vec3A::new(0.0, 1.2, 0.0);
        group.bench_function(tracker.name(), |b| {
            b.iter(|| {
                let dir = zerovar::math::uniform_sphere(s.next_2d());
                let ray = Ray::new(centre, dir);
                let t_max = scene.intersect(&ray, f32::INFINITY).map_or(10.0, |h| h.t);
                black_box(sample_flight(
                    medium,
                    tracker,
                    &ray,
                    t_max,
                    Vec3A::ONE,
                    &mut s,
                    &mut counters,
                ))
            })
        });
    }
    // The guided flight with a trained field over the medium's delta tracking, at the default
    // distance alpha 0 and steered towards the zero-variance collision density at 0.5: against
    // `delta` and `decomposition` above, what guiding a flight costs.
    let field = trained(&scene);
    let mut cache = FieldCache::with_direct(&field.field, field.direct.as_ref(), false);
    for (label, alpha) in [("guided-default-delta", 0.0), ("guided-steered-delta", 0.5)] {
        let mut s = Sampler::new(5, 0, 0);
        let mut counters = Counters::default();
        let centre = Vec3A::new(0.0, 1.2, 0.0);
        group.bench_function(label, |b| {
            b.iter(|| {
                let dir = zerovar::math::uniform_sphere(s.next_2d());
                let ray = Ray::new(centre, dir);
                let t_max = scene.intersect(&ray, f32::INFINITY).map_or(10.0, |h| h.t);
                black_box(guided_flight(
                    medium,
                    Tracker::Delta,
                    &ray,
                    t_max,
                    Vec3A::ONE,
                    alpha,
                    None,
                    &mut cache,
                    &mut s,
                    &mut counters,
                ))
            })
        });
    }
    group.finish();
}

fn guided_distance(c: &mut Criterion) {
    let scene = load("scenes/fog-room.toml");
    let field = trained(&scene);
    let medium = &scene.media()[scene.camera_medium().expect("the camera is in the fog") as usize];
    let mut cache = FieldCache::with_direct(&field.field, field.direct.as_ref(), false);
    let mut s = Sampler::new(3, 0, 0);
    let mut counters = Counters::default();
    c.bench_function("guided-distance/fog-room-camera-ray", |b| {
        b.iter(|| {
            let ray = camera_ray(&scene, &mut s);
            let t_max = scene.intersect(&ray, f32::INFINITY).map_or(50.0, |h| h.t);
            let (one, u) = (Vec3A::ONE, s.next_1d());
            let mut d = GuidedDistance::new(medium, &ray, t_max, one, 0.5, u, SEGMENTS)?;
            Some(black_box(d.sample(medium, &mut cache, &mut s, &mut counters)))
        })
    });
}

/// `BATCH` camera paths of `scene` with `settings`; returns the summed radiance.
fn paths<C: RadianceCache>(
    scene: &Scene,
    settings: &WalkSettings,
    cache: &mut C,
    first: u64,
    counters: &mut Counters,
) -> f32 {
    let mut sum = 0.0;
    for i in first..first + BATCH {
        let mut s = Sampler::new(4, 0, i);
        let [w, h] = scene.camera().resolution().map(|r| r as f32);
        let film = s.next_2d() * Vec2::new(w, h);
        let start = PathStart::camera(scene, film, &mut s);
        let mut ctx = WalkContext { cache: &mut *cache, pixel: None, recorder: None, trace: None };
        sum += radiance(settings, scene, start, &mut ctx, &mut s, counters).x;
    }
    sum
}

fn full_path(c: &mut Criterion) {
    let mut group = c.benchmark_group("path");
    for name in ["fog-room", "cloud"] {
        let scene = load(&format!("scenes/{name}.toml"));
        let field = trained(&scene);
        let unguided = VolPath::from_scene(&scene).settings();
        let guided = WalkSettings {
            guide: Components::FULL,
            alpha: 0.5,
            surface_alpha: zerovar::render::DEFAULT_SURFACE_ALPHA,
            ..unguided
        };
        let mut counters = Counters::default();
        // Each strategy traces the same sequence of camera samples.
        let mut first = 0;
        group.bench_function(format!("{name}-unguided-x{BATCH}"), |b| {
            b.iter(|| {
                first += BATCH;
                black_box(paths(&scene, &unguided, &mut NoCache, first, &mut counters))
            })
        });
        let mut cache = FieldCache::with_direct(&field.field, field.direct.as_ref(), false);
        let mut first = 0;
        group.bench_function(format!("{name}-guided-full-x{BATCH}"), |b| {
            b.iter(|| {
                first += BATCH;
                black_box(paths(&scene, &guided, &mut cache, first, &mut counters))
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    targets = phase, free_flight, transmittance, guided_distance, full_path
}
criterion_main!(benches);
