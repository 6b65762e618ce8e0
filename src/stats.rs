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
    /// The part of `density_lookups` made by guided flights in heterogeneous media, counted
    /// apart because their cost per lookup differs from the trackers' (the cost model of
    /// adaptive guiding weighs them separately).
    pub guided_density_lookups: u64,
    /// Samples that came out NaN or infinite and were dropped.
    pub invalid_samples: u64,
    /// Guiding-field queries: a region's distribution loaded at a vertex, or its estimates
    /// read for guided distances.
    pub field_lookups: u64,
    /// Exact products of a region's mixture with a phase function.
    pub products: u64,
    /// Approximate products: a region's lobes reweighted by the phase function.
    pub reweighted_products: u64,
    /// Extra collisions of guided flights for next-event estimation of delta lights.
    pub extra_collisions: u64,
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Self) {
        self.paths += o.paths;
        self.walks += o.walks;
        self.segments += o.segments;
        self.medium_scatters += o.medium_scatters;
        self.surface_scatters += o.surface_scatters;
        self.density_lookups += o.density_lookups;
        self.guided_density_lookups += o.guided_density_lookups;
        self.invalid_samples += o.invalid_samples;
        self.field_lookups += o.field_lookups;
        self.products += o.products;
        self.reweighted_products += o.reweighted_products;
        self.extra_collisions += o.extra_collisions;
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
    /// Adaptive guiding: which tiles the pilot chose to guide.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<crate::render::Selection>,
    /// The firefly diagnostic: the largest samples and their paths.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fireflies: Option<crate::render::FireflyReport>,
    /// Density lookups per path made by guided flights (included in the total above).
    pub guided_density_lookups_per_path: f64,
    /// Guiding-field queries per path.
    pub field_lookups_per_path: f64,
    /// Exact products of a region's mixture with the phase function per path.
    pub products_per_path: f64,
    /// Reweighted (approximate) products with the phase function per path.
    pub reweighted_products_per_path: f64,
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
    pub stop: crate::render::TrainingStop,
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
            reweighted_products_per_path: per_path(c.reweighted_products),
            extra_collisions_per_path: per_path(c.extra_collisions),
        }
    }
}
