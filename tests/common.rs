//! Helpers shared by the integration tests: scenes from text, per-channel estimates.

use glam::Vec2;
use std::path::{Path, PathBuf};
use zerovar::integrators::VolPath;
use zerovar::rng::Sampler;
use zerovar::scene::Scene;
use zerovar::stats::Counters;
use zerovar_testkit::MeanEstimate;

/// A scene from TOML text (relative paths resolve against the test's temporary directory).
pub(crate) fn scene(text: &str) -> Scene {
    zerovar::scene::load_str(&temp_dir().join("test.toml"), text, &[])
        .unwrap_or_else(|e| panic!("{e}"))
}

/// A fresh directory for this test process.
pub(crate) fn temp_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("zerovar-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `contents` to a file in the temporary directory and returns its path.
pub(crate) fn write(name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = temp_dir().join(name);
    std::fs::write(&path, contents).unwrap();
    path
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

/// The path of a file in the repository.
pub(crate) fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// Mean luminance of each quadrant of a film with its standard error, from the per-pixel
/// sample variances.
pub(crate) fn quadrant_means(f: &zerovar::film::Film) -> [(f64, f64); 4] {
    let (w, h) = (f.width() as usize, f.height() as usize);
    let (mut sum, mut var, mut count) = ([0.0f64; 4], [0.0f64; 4], [0usize; 4]);
    for (i, p) in f.pixels().iter().enumerate() {
        let k = (i % w >= w / 2) as usize + 2 * (i / w >= h / 2) as usize;
        let n = p.count as f64;
        let m = zerovar::math::luminance(glam::Vec3A::from_array(p.mean())) as f64;
        sum[k] += m;
        var[k] += (p.lum_sq / n - m * m).max(0.0) / (n - 1.0);
        count[k] += 1;
    }
    std::array::from_fn(|k| (sum[k] / count[k] as f64, var[k].sqrt() / count[k] as f64))
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
pub(crate) fn assert_quadrants_agree(
    a: [(f64, f64); 4],
    b: [(f64, f64); 4],
    z_max: f64,
    what: &str,
) {
    for (k, ((ma, sa), (mb, sb))) in a.into_iter().zip(b).enumerate() {
        let z = (ma - mb) / (sa * sa + sb * sb).sqrt();
        assert!(z.abs() < z_max, "{what}: quadrant {k}: {ma} +- {sa} vs {mb} +- {sb} (z = {z:.2})");
    }
}
