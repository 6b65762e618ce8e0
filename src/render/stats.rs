//! The `--stats` report: the counters of a finished render per path, with what training and
//! adaptive guiding did.

use crate::stats::Counters;
use serde::Serialize;

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
    /// Adaptive guiding: which tiles the pilot chose to guide.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<super::select::Selection>,
    /// The firefly diagnostic: the largest samples and their paths.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fireflies: Option<super::fireflies::FireflyReport>,
    /// Density lookups per path made by guided flights (included in the total above).
    pub guided_density_lookups_per_path: f64,
    /// Guiding-field queries per path.
    pub field_lookups_per_path: f64,
    /// Exact products of a region's mixture with the phase function per path.
    pub products_per_path: f64,
    /// Products with one vMF lobe standing in for the phase function per path.
    pub lobe_products_per_path: f64,
    /// Extra collisions for delta lights per path.
    pub extra_collisions_per_path: f64,
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
    /// Training's share of the whole render's seconds.
    pub share: f64,
    /// Why training stopped.
    pub stop: super::training::TrainingStop,
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
            selection: None,
            fireflies: None,
            guided_density_lookups_per_path: per_path(c.guided_density_lookups),
            field_lookups_per_path: per_path(c.field_lookups),
            products_per_path: per_path(c.products),
            lobe_products_per_path: per_path(c.lobe_products),
            extra_collisions_per_path: per_path(c.extra_collisions),
        }
    }
}
