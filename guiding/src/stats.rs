//! Counts, memory and timing of a field, for logs and benchmarks.

use crate::field::{Field, Region};
use serde::{Deserialize, Serialize};

/// A summary of a [`Field`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldStats {
    /// Leaves of the spatial tree.
    pub regions: usize,
    /// Regions that have seen light (lookups return only these).
    pub trained_regions: usize,
    /// Lobes over all regions.
    pub lobes: usize,
    /// Smallest and largest lobe count of a region.
    pub lobes_min_max: (usize, usize),
    /// Nodes of the spatial tree, inner ones included.
    pub tree_nodes: usize,
    /// Depth of the deepest leaf.
    pub tree_depth: u32,
    /// Heap and inline memory of regions and tree, in bytes.
    pub memory_bytes: usize,
    /// Wall-clock duration of the last `update`, in seconds.
    pub last_update_seconds: f64,
    /// Samples learned from over all updates.
    pub total_samples: u64,
    /// Completed updates.
    pub iterations: u32,
}

impl FieldStats {
    pub(crate) fn of(field: &Field) -> Self {
        let regions = field.regions();
        let counts = regions.iter().map(|r| r.mixture().len());
        Self {
            regions: regions.len(),
            trained_regions: regions.iter().filter(|r| r.is_trained()).count(),
            lobes: counts.clone().sum(),
            lobes_min_max: (counts.clone().min().unwrap_or(0), counts.max().unwrap_or(0)),
            tree_nodes: field.tree.node_count(),
            tree_depth: field.tree.depth(),
            memory_bytes: std::mem::size_of::<Field>()
                + field.regions.capacity() * std::mem::size_of::<Region>()
                + field.tree.memory_bytes(),
            last_update_seconds: field.last_update_seconds,
            total_samples: field.total_samples,
            iterations: field.iterations,
        }
    }
}
