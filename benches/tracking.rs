//! Time per camera path of each tracker on the cloud and chromatic scenes (density lookups per
//! path are printed once per tracker). `cargo bench --bench tracking`.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec2;
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;
use zerovar::integrators::VolPath;
use zerovar::rng::Sampler;
use zerovar::scene::Scene;
use zerovar::stats::Counters;
use zerovar::tracking::{Tracker, TrackerChoice};

const PATHS: u64 = 256;

fn load(path: &str, extra: Option<(&str, &str)>) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    let mut text = std::fs::read_to_string(&path).expect("scene file");
    if let Some((from, to)) = extra {
        text = text.replacen(from, to, 1);
    }
    zerovar::scene::load_str(&path, &text, &[]).expect("scene")
}

/// `PATHS` camera paths over the whole film; returns the summed radiance.
fn paths(scene: &Scene, first: u64, counters: &mut Counters) -> f32 {
    let integrator = VolPath::from_scene(scene);
    let [w, h] = scene.camera().resolution().map(|r| r as f32);
    let mut sum = 0.0;
    for i in first..first + PATHS {
        let mut s = Sampler::new(1, 0, i);
        let film = s.next_2d() * Vec2::new(w, h);
        let ray = scene.camera().ray(film);
        sum += integrator.radiance(scene, ray, scene.camera_medium(), &mut s, counters).x;
    }
    sum
}

fn bench_scene(c: &mut Criterion, name: &str, mut scene: Scene, trackers: &[TrackerChoice]) {
    let mut group = c.benchmark_group(name);
    for &choice in trackers {
        scene.set_tracker(choice).expect("tracker applies");
        let label = match choice {
            TrackerChoice::Auto => "auto".to_string(),
            TrackerChoice::Force(t) => t.name().to_string(),
        };
        let mut counters = Counters::default();
        paths(&scene, 0, &mut counters);
        eprintln!(
            "{name}/{label}: {:.2} density lookups per path",
            counters.density_lookups as f64 / PATHS as f64
        );
        let mut first = 0;
        group.bench_function(&label, |b| {
            b.iter(|| {
                first += PATHS;
                black_box(paths(&scene, first, &mut counters))
            })
        });
    }
    group.finish();
}

fn trackers(c: &mut Criterion) {
    let f = TrackerChoice::Force;
    let grey = [
        TrackerChoice::Auto,
        f(Tracker::Delta),
        f(Tracker::WeightedDelta),
        f(Tracker::Decomposition),
        f(Tracker::WeightedDecomposition),
        f(Tracker::Spectral),
        f(Tracker::SpectralDecomposition),
        f(Tracker::RayMarching),
    ];
    bench_scene(c, "cloud", load("scenes/cloud.toml", None), &grey);
    let chromatic = [
        TrackerChoice::Auto,
        f(Tracker::Spectral),
        f(Tracker::SpectralMax),
        f(Tracker::SpectralAverage),
        f(Tracker::SpectralDecomposition),
    ];
    bench_scene(c, "chromatic-box", load("scenes/chromatic-box.toml", None), &chromatic);
    let tinted = Some(("scale = \"$density\"", "scale = \"$density\"\nsigma_t = [1, 0.6, 0.3]"));
    bench_scene(c, "chromatic-cloud", load("scenes/cloud.toml", tinted), &chromatic);
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    targets = trackers
}
criterion_main!(benches);
