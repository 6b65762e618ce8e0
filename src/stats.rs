//! Counters gathered while rendering, and the statistics report written by `--stats`.

use serde::Serialize;

/// Per-thread event counters, summed over tiles after a pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Camera paths traced.
    pub paths: u64,
    /// Walks traced: camera paths plus the copies made by splitting.
    pub walks: u64,
    /// Path segments traced (camera ray and every continuation).
    pub segments: u64,
    /// Real scattering events in media.
    pub medium_scatters: u64,
    /// Scattering events on surfaces (null surfaces excluded).
    pub surface_scatters: u64,
    /// Density lookups by trackers.
    pub density_lookups: u64,
    /// Samples that came out NaN or infinite and were dropped.
    pub invalid_samples: u64,
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Self) {
        self.paths += o.paths;
        self.walks += o.walks;
        self.segments += o.segments;
        self.medium_scatters += o.medium_scatters;
        self.surface_scatters += o.surface_scatters;
        self.density_lookups += o.density_lookups;
        self.invalid_samples += o.invalid_samples;
    }
}

/// The `--stats` report.
#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    /// The scene file.
    pub scene: String,
    /// Samples per pixel rendered.
    pub spp: u32,
    /// Image width and height.
    pub resolution: [u32; 2],
    /// Seed of the random streams.
    pub seed: u64,
    /// Threads used.
    pub threads: usize,
    /// Wall-clock seconds of rendering (excluding loading and output).
    pub seconds: f64,
    /// Camera paths per second.
    pub paths_per_second: f64,
    /// Mean number of segments per path.
    pub mean_path_length: f64,
    /// Mean real scattering events (medium and surface) per path.
    pub scatter_events_per_path: f64,
    /// Mean density lookups per path.
    pub density_lookups_per_path: f64,
    /// Samples dropped as NaN or infinite (zero unless something is wrong).
    pub invalid_samples: u64,
    /// Walks per camera path: 1 without splitting.
    pub splitting_factor: f64,
    /// Guiding: training, when a field was trained.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub training: Option<TrainingStats>,
}

/// The training part of `--stats`.
#[derive(Clone, Debug, Serialize)]
pub struct TrainingStats {
    /// Training passes.
    pub passes: u32,
    /// Samples per pixel over all training passes.
    pub spp: u32,
    /// Seconds of training, field updates included.
    pub seconds: f64,
    /// Training samples learned from.
    pub samples: u64,
    /// Regions of the field.
    pub regions: usize,
    /// vMF lobes over all regions.
    pub lobes: usize,
    /// Memory of the field in bytes.
    pub memory_bytes: usize,
}

impl RenderStats {
    /// Derives the report from the counters of a finished render.
    pub fn from_counters(c: &Counters, seconds: f64) -> Self {
        let per_path = |x: u64| if c.paths > 0 { x as f64 / c.paths as f64 } else { 0.0 };
        Self {
            scene: String::new(),
            spp: 0,
            resolution: [0, 0],
            seed: 0,
            threads: 0,
            seconds,
            paths_per_second: if seconds > 0.0 { c.paths as f64 / seconds } else { 0.0 },
            mean_path_length: per_path(c.segments),
            scatter_events_per_path: per_path(c.medium_scatters + c.surface_scatters),
            density_lookups_per_path: per_path(c.density_lookups),
            invalid_samples: c.invalid_samples,
            splitting_factor: if c.paths > 0 { c.walks as f64 / c.paths as f64 } else { 1.0 },
            training: None,
        }
    }
}
