//! Criterion benchmarks of the hot paths a renderer pays for at every scattering event
//! (mixture evaluation, sampling, product construction, tree lookup) and of training.

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use glam::{Vec2, Vec3};
use rand_pcg::Pcg32;
use rand_pcg::rand_core::Rng;
use std::hint::black_box;
use zerovar_guiding::{Field, FieldConfig, Mixture, Sample, VmfLobe, VolumeDistribution, vmf};

fn u01(rng: &mut Pcg32) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

fn mixture8() -> Mixture {
    let lobes: Vec<VmfLobe> = (0..8)
        .map(|i| {
            let a = i as f32 * 0.8;
            VmfLobe {
                mean: Vec3::new(a.cos(), a.sin(), 0.3 * a - 1.0),
                kappa: 5.0 + 20.0 * i as f32,
                weight: 1.0,
            }
        })
        .collect();
    Mixture::new(&lobes).unwrap()
}

/// Samples in a unit box lit by a point light, uniformly sampled directions.
fn samples(n: usize, seed: u64) -> Vec<Sample> {
    let mut rng = Pcg32::new(seed, 1);
    let light = Vec3::new(0.5, 0.5, 3.0);
    (0..n)
        .map(|_| {
            let position = Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng));
            let direction = vmf::sample(Vec3::Z, 0.0, Vec2::new(u01(&mut rng), u01(&mut rng)));
            let to_light = (light - position).normalize();
            let radiance = if direction.dot(to_light) > 0.98 { 5.0 } else { 0.05 };
            Sample {
                position,
                direction,
                radiance,
                pdf: 1.0 / (4.0 * std::f32::consts::PI),
                distance: 1.0,
                volume: true,
            }
        })
        .collect()
}

fn trained_field(config: FieldConfig) -> Field {
    let mut field = Field::new(config).unwrap();
    for pass in 0..4 {
        field.update(&samples(100_000, pass)).unwrap();
    }
    field
}

fn bench(c: &mut Criterion) {
    let mut rng = Pcg32::new(7, 7);
    let dirs: Vec<Vec3> = (0..1024)
        .map(|_| vmf::sample(Vec3::Z, 0.0, Vec2::new(u01(&mut rng), u01(&mut rng))))
        .collect();
    let us: Vec<Vec2> = (0..1024).map(|_| Vec2::new(u01(&mut rng), u01(&mut rng))).collect();
    let positions: Vec<Vec3> =
        (0..1024).map(|_| Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng))).collect();
    let m = mixture8();

    let mut g = c.benchmark_group("mixture");
    let mut i = 0;
    g.bench_function("pdf_8_lobes", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(m.pdf(black_box(dirs[i])))
        })
    });
    g.bench_function("sample_8_lobes", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(m.sample(black_box(us[i])))
        })
    });
    g.finish();

    let field = trained_field(FieldConfig { max_samples_per_leaf: 8000, ..FieldConfig::default() });
    let filtered = trained_field(FieldConfig {
        max_samples_per_leaf: 8000,
        spatial_filter: true,
        ..FieldConfig::default()
    });
    eprintln!("benchmark field: {:?}", field.stats());
    let mut d = VolumeDistribution::default();
    assert!(d.init(&field, Vec3::splat(0.5), 0.5));

    let mut g = c.benchmark_group("distribution");
    g.bench_function("init", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.init(&field, black_box(positions[i]), 0.5))
        })
    });
    g.bench_function("init_and_hg_product", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            d.init(&field, black_box(positions[i]), 0.5);
            d.apply_hg_product(black_box(dirs[i]), 0.7);
        })
    });
    g.bench_function("init_and_hg_weights", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            d.init(&field, black_box(positions[i]), 0.5);
            d.apply_hg_weights(black_box(dirs[i]), 0.6);
        })
    });
    g.bench_function("init_and_hg_lobe_product", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            d.init(&field, black_box(positions[i]), 0.5);
            d.apply_hg_lobe_product(black_box(dirs[i]), 0.6);
        })
    });
    g.bench_function("init_and_cosine_weights", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            d.init(&field, black_box(positions[i]), 0.5);
            d.apply_cosine_weights(black_box(dirs[i]));
        })
    });
    g.bench_function("init_and_cosine_product", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            d.init(&field, black_box(positions[i]), 0.5);
            d.apply_cosine_product(black_box(dirs[i]));
        })
    });
    d.init(&field, Vec3::splat(0.5), 0.5);
    d.apply_hg_product(Vec3::X, 0.7);
    g.bench_function("product_sample_with_pdf", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.sample_with_pdf(black_box(us[i])))
        })
    });
    g.bench_function("product_pdf", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.pdf(black_box(dirs[i])))
        })
    });
    d.apply_hg_weights(Vec3::X, 0.6);
    g.bench_function("weights_sample_with_pdf", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.sample_with_pdf(black_box(us[i])))
        })
    });
    g.bench_function("weights_pdf", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.pdf(black_box(dirs[i])))
        })
    });
    d.apply_hg_lobe_product(Vec3::X, 0.6);
    g.bench_function("lobe_product_sample_with_pdf", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.sample_with_pdf(black_box(us[i])))
        })
    });
    g.bench_function("lobe_product_pdf", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.pdf(black_box(dirs[i])))
        })
    });
    g.bench_function("inscattered_radiance", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(d.inscattered_radiance(black_box(dirs[i]), 0.7))
        })
    });
    g.finish();

    let mut g = c.benchmark_group("tree");
    g.bench_function("lookup", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(field.lookup(black_box(positions[i]), 0.3))
        })
    });
    g.bench_function("lookup_spatial_filter", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(filtered.lookup(black_box(positions[i]), us[i].x))
        })
    });
    g.finish();

    let mut g = c.benchmark_group("update");
    g.throughput(Throughput::Elements(1000));
    let batch = samples(1000, 99);
    let one_region =
        trained_field(FieldConfig { max_samples_per_leaf: usize::MAX, ..FieldConfig::default() });
    g.bench_function("em_update_1000_samples", |b| {
        b.iter_batched(
            || one_region.clone(),
            |mut f| {
                f.update(black_box(&batch)).unwrap();
                f
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
