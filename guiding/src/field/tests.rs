//! Tests of the field: tree growth, lookups, updates, determinism and persistence.

use super::*;
use crate::VolumeDistribution;
use crate::directional::vmf;
use glam::Vec2;
use rand_pcg::Pcg32;
use rand_pcg::rand_core::Rng;

fn u01(rng: &mut Pcg32) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// A sample at `pos` seeing a point light at `light` (radiance ~ 1 / distance^2 inside a small
/// cone, so the direction is learnable) from a uniformly sampled direction.
fn sample_at(rng: &mut Pcg32, pos: Vec3, light: Vec3) -> Sample {
    let direction = vmf::sample(Vec3::Z, 0.0, Vec2::new(u01(rng), u01(rng)));
    let to_light = light - pos;
    let d2 = to_light.length_squared();
    let radiance = if direction.dot(to_light.normalize()) > 0.99 { 10.0 / d2 } else { 0.0 };
    Sample {
        position: pos,
        direction,
        radiance,
        pdf: 1.0 / (4.0 * std::f32::consts::PI),
        distance: d2.sqrt(),
        volume: true,
    }
}

/// Samples from a dense cluster near the origin and a sparse spread over a large box.
fn clustered_batch(seed: u64, n: usize) -> Vec<Sample> {
    let mut rng = Pcg32::new(seed, 17);
    let light = Vec3::new(0.0, 0.0, 20.0);
    (0..n)
        .map(|i| {
            let pos = if i % 10 != 0 {
                Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng)) * 0.5
            } else {
                Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng)) * 50.0 - Vec3::splat(25.0)
            };
            sample_at(&mut rng, pos, light)
        })
        .collect()
}

fn small_config() -> FieldConfig {
    FieldConfig { max_samples_per_leaf: 1000, ..FieldConfig::default() }
}

#[test]
fn empty_field_has_no_regions_to_return() {
    let field = Field::new(FieldConfig::default()).unwrap();
    assert!(!field.is_trained());
    assert!(field.lookup(Vec3::ZERO, 0.5).is_none());
    let mut d = VolumeDistribution::default();
    assert!(!d.init(&field, Vec3::ONE, 0.1));
    assert_eq!(d.fluence(), 0.0);
    assert!((d.pdf(Vec3::X) - 1.0 / (4.0 * std::f32::consts::PI)).abs() < 1e-7);
}

#[test]
fn tree_splits_where_samples_are_dense() {
    let mut field = Field::new(small_config()).unwrap();
    for pass in 0..4 {
        field.update(&clustered_batch(pass, 20_000)).unwrap();
    }
    field.tree.validate(field.regions.len()).unwrap();
    let stats = field.stats();
    assert!(stats.regions > 20, "{stats:?}");
    // 90% of the samples fall in the 0.5-wide cluster, 10% spread over a 50-wide box: leaves
    // hold similar sample counts, so about nine times as many leaves cover the cluster, and
    // they are far smaller.
    let in_cluster = |p: Vec3| p.cmpge(Vec3::ZERO).all() && p.cmple(Vec3::splat(0.5)).all();
    let dense = field.regions.iter().filter(|r| in_cluster(r.centre())).count();
    let sparse = field.regions.len() - dense;
    assert!(dense >= 4 * sparse, "{dense} leaves in the cluster, {sparse} outside");
    let (d, _) = field.tree.lookup(Vec3::splat(0.25));
    let (s, _) = field.tree.lookup(Vec3::new(20.0, -20.0, 20.0));
    let (rd, rs) = (&field.regions[d], &field.regions[s]);
    assert!(rd.depth() > rs.depth(), "dense depth {}, sparse depth {}", rd.depth(), rs.depth());
    assert!(rd.spread < 0.2 && rs.spread > 5.0, "spreads {} and {}", rd.spread, rs.spread);
    // No leaf holds many more samples than the threshold since it was created.
    for r in &field.regions {
        assert!(r.spatial.count < 2.0 * 1000.0 || r.depth >= field.config.max_depth);
    }
    assert_eq!(stats.total_samples, 80_000);
    assert_eq!(stats.iterations, 4);
}

#[test]
fn sparse_samples_do_not_split() {
    let mut field = Field::new(small_config()).unwrap();
    // 900 samples spread over a huge box: below the threshold, the root stays a leaf.
    let mut rng = Pcg32::new(3, 3);
    let batch: Vec<_> = (0..900)
        .map(|_| {
            let pos = Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng)) * 1000.0;
            sample_at(&mut rng, pos, Vec3::splat(2000.0))
        })
        .collect();
    field.update(&batch).unwrap();
    assert_eq!(field.stats().regions, 1);
}

#[test]
fn learned_direction_points_at_the_light() {
    let mut field = Field::new(small_config()).unwrap();
    for pass in 0..3 {
        field.update(&clustered_batch(pass + 10, 20_000)).unwrap();
    }
    let region = field.lookup(Vec3::splat(0.25), 0.5).unwrap();
    let to_light = (Vec3::new(0.0, 0.0, 20.0) - Vec3::splat(0.25)).normalize();
    let m = region.mixture();
    assert!(m.pdf(to_light) > 20.0 * m.pdf(-to_light), "{m:?}");
    // Fluence: the light subtends a cone of solid angle 2 pi (1 - 0.99) with radiance 10 / d^2.
    let d2 = (Vec3::new(0.0, 0.0, 20.0) - Vec3::splat(0.25)).length_squared();
    let expect = 10.0 / d2 * std::f32::consts::TAU * 0.01;
    assert!((region.fluence() - expect).abs() < 0.2 * expect, "{} vs {expect}", region.fluence());
}

#[test]
fn fluence_is_an_unbiased_mean_of_weights() {
    // One region, samples of a known radiance field: L(w) = 3 vMF(w; z, 5) + 0.5, whose
    // integral is 3 + 0.5 * 4 pi. Sampled from a cosine-free vMF lobe, so weights vary.
    let lobe = crate::VmfLobe { mean: Vec3::new(0.0, 0.6, 0.8), kappa: 3.0, weight: 1.0 };
    let light = crate::VmfLobe { mean: Vec3::Z, kappa: 5.0, weight: 1.0 };
    let mut rng = Pcg32::new(8, 8);
    let samples: Vec<Sample> = (0..20_000)
        .map(|_| {
            let direction = lobe.sample(Vec2::new(u01(&mut rng), u01(&mut rng)));
            let radiance = 3.0 * light.pdf(direction) + 0.5;
            Sample {
                position: Vec3::ZERO,
                direction,
                radiance,
                pdf: lobe.pdf(direction),
                distance: 1.0,
                volume: true,
            }
        })
        .collect();
    let mut field =
        Field::new(FieldConfig { max_samples_per_leaf: 1 << 30, ..Default::default() }).unwrap();
    field.update(&samples).unwrap();
    let est: zerovar_testkit::MeanEstimate = samples.iter().map(|s| s.weight()).collect();
    let expect = 3.0 + 0.5 * 4.0 * std::f64::consts::PI;
    est.assert_matches(expect, 4.0, "fluence estimator");
    let fluence = f64::from(field.regions()[0].fluence());
    assert!((fluence - est.mean).abs() < 1e-5 * est.mean, "{fluence} vs {}", est.mean);
}

#[test]
fn invalid_samples_are_rejected_with_their_index() {
    let mut field = Field::new(small_config()).unwrap();
    let good = clustered_batch(1, 10);
    type Spoil = fn(&mut Sample);
    let cases: [(Spoil, &str); 6] = [
        (|s| s.radiance = f32::NAN, "radiance"),
        (|s| s.radiance = -1.0, "radiance"),
        (|s| s.pdf = 0.0, "pdf"),
        (|s| s.pdf = f32::INFINITY, "pdf"),
        (|s| s.direction = Vec3::new(1.0, 1.0, 0.0), "direction"),
        (|s| s.position = Vec3::new(f32::NAN, 0.0, 0.0), "position"),
    ];
    for (spoil, what) in cases {
        let mut batch = good.clone();
        spoil(&mut batch[7]);
        let err = field.update(&batch).unwrap_err();
        match &err {
            GuidingError::InvalidSample { index: 7, reason } => {
                assert!(reason.contains(what), "{reason}")
            }
            e => panic!("unexpected error {e}"),
        }
        assert!(err.to_string().contains("sample 7"));
    }
    // Checked in parallel, the first invalid sample is still the one named.
    let mut big = clustered_batch(2, 100_000);
    for i in [99_000, 70_001, 70_000] {
        big[i].pdf = -1.0;
    }
    let err = field.update(&big).unwrap_err();
    assert!(matches!(err, GuidingError::InvalidSample { index: 70_000, .. }), "{err}");
    // Nothing was learned from the rejected batches.
    assert_eq!(field.iterations(), 0);
    assert!(!field.is_trained());
}

#[test]
fn degenerate_batches_give_no_nan() {
    let mut field = Field::new(small_config()).unwrap();
    // All weights zero: counted, nothing trained.
    let mut zero = clustered_batch(2, 3000);
    zero.iter_mut().for_each(|s| s.radiance = 0.0);
    field.update(&zero).unwrap();
    assert!(!field.is_trained());
    // All samples in one direction at one point.
    let one: Vec<_> = (0..3000)
        .map(|_| Sample {
            position: Vec3::ONE,
            direction: Vec3::Y,
            radiance: 1.0,
            pdf: 1.0,
            distance: 1.0,
            volume: true,
        })
        .collect();
    field.update(&one).unwrap();
    // One weight of 1e30.
    let mut huge = clustered_batch(3, 3000);
    huge[5].radiance = 1e30;
    field.update(&huge).unwrap();
    let mut d = VolumeDistribution::default();
    for r in field.regions() {
        for l in r.mixture().lobes() {
            assert!(l.mean.is_finite() && l.kappa.is_finite() && l.weight.is_finite());
        }
        assert!(r.fluence().is_finite());
    }
    for p in [Vec3::ONE, huge[5].position, Vec3::ZERO, Vec3::splat(10.0)] {
        if d.init(&field, p, 0.3) {
            d.apply_hg_product(Vec3::X, 0.9);
            let (w, pdf) = d.sample_with_pdf(Vec2::new(0.3, 0.3));
            assert!(w.is_finite() && pdf.is_finite() && pdf > 0.0);
            assert!(d.inscattered_radiance(Vec3::X, 0.9).is_finite());
            assert!(d.incident_radiance(w).is_finite());
        }
    }
}

#[test]
fn update_is_deterministic_across_thread_counts() {
    let batches: Vec<_> = (0..3).map(|i| clustered_batch(i + 40, 15_000)).collect();
    let train = || {
        let mut f =
            Field::new(FieldConfig { split_merge: true, spatial_filter: true, ..small_config() })
                .unwrap();
        batches.iter().for_each(|b| f.update(b).unwrap());
        (f.regions, f.tree)
    };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(train);
    let many = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(train);
    assert!(one == many, "fields differ between 1 and 4 threads");
}

#[test]
fn saved_and_loaded_field_answers_identically() {
    let mut field = Field::new(FieldConfig { spatial_filter: true, ..small_config() }).unwrap();
    for pass in 0..2 {
        field.update(&clustered_batch(pass + 20, 20_000)).unwrap();
    }
    let mut bytes = Vec::new();
    field.save(&mut bytes).unwrap();
    let loaded = Field::load(bytes.as_slice()).unwrap();
    assert_eq!(loaded.regions(), field.regions());
    assert_eq!(loaded.stats().regions, field.stats().regions);
    let mut rng = Pcg32::new(5, 5);
    let (mut a, mut b) = (VolumeDistribution::default(), VolumeDistribution::default());
    for _ in 0..2000 {
        let pos = Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng)) * 60.0 - Vec3::splat(30.0);
        let u = u01(&mut rng);
        assert_eq!(field.lookup_index(pos, u), loaded.lookup_index(pos, u));
        assert_eq!(a.init(&field, pos, u), b.init(&loaded, pos, u));
        let ray = vmf::sample(Vec3::Z, 0.0, Vec2::new(u01(&mut rng), u01(&mut rng)));
        let uv = Vec2::new(u01(&mut rng), u01(&mut rng));
        assert_eq!(a.incident_radiance(ray).to_bits(), b.incident_radiance(ray).to_bits());
        assert_eq!(
            a.inscattered_radiance(ray, 0.7).to_bits(),
            b.inscattered_radiance(ray, 0.7).to_bits()
        );
        assert_eq!(a.fluence().to_bits(), b.fluence().to_bits());
        a.apply_hg_weights(ray, 0.6);
        b.apply_hg_weights(ray, 0.6);
        assert_eq!(a.pdf(-ray).to_bits(), b.pdf(-ray).to_bits());
        a.apply_hg_product(ray, -0.4);
        b.apply_hg_product(ray, -0.4);
        let (sa, pa) = a.sample_with_pdf(uv);
        let (sb, pb) = b.sample_with_pdf(uv);
        assert_eq!((sa.to_array(), pa.to_bits()), (sb.to_array(), pb.to_bits()));
    }
    // Training continues identically from the loaded field.
    let mut loaded = loaded;
    let next = clustered_batch(99, 5000);
    field.update(&next).unwrap();
    loaded.update(&next).unwrap();
    assert_eq!(loaded.regions(), field.regions());
}

#[test]
fn region_lanes_follow_the_mixture_through_training() {
    // The lane copy every lookup loads must be refreshed whenever EM or split-and-merge
    // change a mixture: its density must match the mixture's in every region, every pass.
    let mut field = Field::new(small_config()).unwrap();
    let mut rng = Pcg32::new(8, 3);
    for pass in 0..3 {
        field.update(&clustered_batch(pass + 40, 20_000)).unwrap();
        assert!(field.regions().len() > 4);
        for (i, r) in field.regions().iter().enumerate() {
            for _ in 0..50 {
                let d = vmf::sample(Vec3::Z, 0.0, Vec2::new(u01(&mut rng), u01(&mut rng)));
                let (lanes, mixture) = (r.density(d), r.mixture().pdf(d));
                assert!(
                    (lanes - mixture).abs() <= 1e-5 * mixture + 1e-9,
                    "pass {pass} region {i}: {lanes} vs {mixture}"
                );
            }
        }
    }
}

#[test]
fn loading_rejects_other_versions_and_garbage() {
    let field = Field::new(FieldConfig::default()).unwrap();
    let mut bytes = Vec::new();
    field.save(&mut bytes).unwrap();
    let mut other = bytes.clone();
    other[8..12].copy_from_slice(&7u32.to_le_bytes());
    match Field::load(other.as_slice()) {
        Err(GuidingError::Version { found: 7, expected }) => {
            assert_eq!(expected, crate::FORMAT_VERSION)
        }
        r => panic!("expected a version error, got {r:?}"),
    }
    assert!(matches!(Field::load(&b"not a field at all"[..]), Err(GuidingError::BadMagic)));
    assert!(matches!(Field::load(&bytes[..bytes.len() - 3]), Err(GuidingError::Decode(_))));
    assert!(Field::load(bytes.as_slice()).is_ok());
    // Well-formed data describing a region lookups cannot use.
    let mut bad = field.clone();
    bad.regions[0].em.scale(f64::NAN);
    let mut bytes = Vec::new();
    bad.save(&mut bytes).unwrap();
    match Field::load(bytes.as_slice()) {
        Err(GuidingError::Decode(e)) => assert!(e.contains("region 0"), "{e}"),
        r => panic!("expected a decode error, got {r:?}"),
    }
}

#[test]
fn spatial_filter_picks_nearby_trained_regions() {
    let mut field = Field::new(FieldConfig { spatial_filter: true, ..small_config() }).unwrap();
    for pass in 0..2 {
        field.update(&clustered_batch(pass + 30, 20_000)).unwrap();
    }
    let pos = Vec3::splat(0.25);
    let home = field.lookup_index(pos, 0.0).unwrap();
    let picks: std::collections::BTreeSet<usize> =
        (0..100).filter_map(|i| field.lookup_index(pos, i as f32 / 100.0)).collect();
    assert!(picks.len() > 1, "the filter never left the home region");
    assert!(picks.contains(&home));
    for &p in &picks {
        assert!(field.regions()[p].is_trained());
        let dist = (field.regions()[p].centre() - pos).length();
        assert!(dist < 0.5, "picked a region {dist} away");
    }
    // Without the filter the lookup ignores u.
    let plain = Field {
        config: FieldConfig { spatial_filter: false, ..field.config.clone() },
        ..field.clone()
    };
    assert!(
        (0..10).all(|i| plain.lookup_index(pos, i as f32 / 10.0) == plain.lookup_index(pos, 0.0))
    );
}

/// A field of one region over the cube `[-0.5, 0.5]^3`, trained on a light at `light`.
fn one_region_field(parallax: bool, light: Vec3) -> Field {
    let config = FieldConfig { max_samples_per_leaf: 1 << 30, parallax, ..FieldConfig::default() };
    let mut field = Field::new(config).unwrap();
    let mut rng = Pcg32::new(21, 5);
    for _ in 0..3 {
        let batch: Vec<_> = (0..20_000)
            .map(|_| {
                let pos = Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng)) - Vec3::splat(0.5);
                sample_at(&mut rng, pos, light)
            })
            .collect();
        field.update(&batch).unwrap();
    }
    assert_eq!(field.regions().len(), 1);
    field
}

/// The angle, in degrees, between `dir` and the mean of the heaviest lobe `d` holds.
fn heaviest_lobe_error(d: &VolumeDistribution, dir: Vec3) -> f32 {
    let (mean, _, _) =
        (0..MAX_LOBES).map(|k| d.base.lobe(k)).max_by(|a, b| a.2.total_cmp(&b.2)).unwrap();
    mean.dot(dir).clamp(-1.0, 1.0).acos().to_degrees()
}

#[test]
fn parallax_aware_lobes_aim_at_a_nearby_light_from_anywhere_in_the_region() {
    // A light 2 units above a region a unit wide: seen from its sides the light's direction
    // differs from the centre's by 12.7 degrees, more than the light's own 8-degree cone.
    let light = Vec3::new(0.0, 0.0, 2.0);
    let plain = one_region_field(false, light);
    let aware = one_region_field(true, light);
    let mut d = VolumeDistribution::default();
    for x in [Vec3::new(-0.45, 0.0, 0.0), Vec3::new(0.45, 0.0, 0.0), Vec3::new(0.0, 0.4, 0.3)] {
        let to_light = (light - x).normalize();
        assert!(d.init(&plain, x, 0.5));
        let (plain_error, plain_pdf) = (heaviest_lobe_error(&d, to_light), d.pdf(to_light));
        assert!(d.init(&aware, x, 0.5));
        let (aware_error, aware_pdf) = (heaviest_lobe_error(&d, to_light), d.pdf(to_light));
        assert!(aware_error < 3.0, "at {x}: the lobe misses the light by {aware_error} degrees");
        assert!(plain_error > 8.0, "at {x}: without parallax {plain_error} degrees");
        assert!(aware_pdf > 2.0 * plain_pdf, "at {x}: density {aware_pdf} vs {plain_pdf}");
        // The region's own density agrees with the loaded distribution's.
        let region = &aware.regions()[0];
        let r = region.density_at(x, to_light);
        assert!((r - aware_pdf).abs() <= 1e-5 * aware_pdf, "{r} vs {aware_pdf}");
    }
    // The light is 2 units from the centre, so the heaviest lobe learned about that distance.
    let region = &aware.regions()[0];
    let k = (0..region.mixture().len())
        .max_by(|&a, &b| {
            region.mixture().lobes()[a].weight.total_cmp(&region.mixture().lobes()[b].weight)
        })
        .unwrap();
    let distance = 1.0 / region.em.lobe_inverse_distances()[k];
    assert!((distance - 2.0).abs() < 0.2, "learned distance {distance}");
}

#[test]
fn light_from_infinitely_far_is_not_re_aimed() {
    // Samples without a source distance (escaped paths): lookups anywhere see one mixture.
    let mut field =
        Field::new(FieldConfig { max_samples_per_leaf: 1 << 30, ..FieldConfig::default() })
            .unwrap();
    let mut rng = Pcg32::new(4, 4);
    let batch: Vec<_> = (0..20_000)
        .map(|_| {
            let pos = Vec3::new(u01(&mut rng), u01(&mut rng), u01(&mut rng));
            Sample { distance: f32::INFINITY, ..sample_at(&mut rng, pos, Vec3::new(0.0, 0.0, 1e4)) }
        })
        .collect();
    field.update(&batch).unwrap();
    let region = &field.regions()[0];
    assert!(region.em.lobe_inverse_distances().iter().all(|&v| v == 0.0));
    let (mut a, mut b) = (VolumeDistribution::default(), VolumeDistribution::default());
    assert!(a.init(&field, Vec3::ZERO, 0.5) && b.init(&field, Vec3::ONE, 0.5));
    for k in 0..MAX_LOBES {
        assert_eq!(a.base.lobe(k), b.base.lobe(k));
    }
}

#[test]
fn reprojection_moves_sources_to_the_pivot_and_keeps_infinite_ones() {
    let s = Sample {
        position: Vec3::new(1.0, 0.0, 0.0),
        direction: Vec3::Z,
        radiance: 1.0,
        pdf: 1.0,
        distance: 3.0,
        volume: true,
    };
    // The source (1, 0, 3) seen from the origin.
    let (dir, inv) = reproject(&s, Vec3::ZERO, 0.0);
    assert!((dir - Vec3::new(1.0, 0.0, 3.0).normalize()).length() < 1e-6, "{dir}");
    assert!((inv - 1.0 / 10f32.sqrt()).abs() < 1e-6);
    // A source nearer than `near` to its sample is moved out to it first: (1, 0, 5).
    let (dir, inv) = reproject(&s, Vec3::ZERO, 5.0);
    assert!((dir - Vec3::new(1.0, 0.0, 5.0).normalize()).length() < 1e-6, "{dir}");
    assert!((inv - 1.0 / 26f32.sqrt()).abs() < 1e-6);
    // Light from infinitely far keeps its direction and has no distance.
    let far = Sample { distance: f32::INFINITY, ..s };
    assert_eq!(reproject(&far, Vec3::new(7.0, 7.0, 7.0), 1.0), (Vec3::Z, 0.0));
    // A source at the pivot itself has no direction from it: the sample keeps its own.
    let at_pivot = Sample { distance: 3.0, ..s };
    assert_eq!(reproject(&at_pivot, Vec3::new(1.0, 0.0, 3.0), 0.0), (Vec3::Z, 0.0));
}
