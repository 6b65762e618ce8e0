//! Counters gathered while rendering: every thread counts its work, and the counters are
//! summed per pass (the `--stats` report, `render::RenderStats`, is derived from them).

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
    /// Products of a region's mixture with one vMF lobe standing in for the phase function.
    pub lobe_products: u64,
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
        self.lobe_products += o.lobe_products;
        self.extra_collisions += o.extra_collisions;
    }
}
