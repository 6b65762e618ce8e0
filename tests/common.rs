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
        let ray = scene.camera.ray(film);
        let l = integrator.radiance(scene, ray, scene.camera_medium, &mut s, &mut counters);
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
