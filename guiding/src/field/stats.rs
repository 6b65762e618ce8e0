//! Counts, memory and timing of a field, for logs and benchmarks.

use serde::{Deserialize, Serialize};

/// A summary of a [`Field`](crate::Field), from `Field::stats`.
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
