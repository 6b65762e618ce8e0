//! Space cut into regions: the adaptive kd-tree whose leaves are the field's regions, and the
//! uniform grid of start nodes that lets most lookups skip the descent from the root.

mod node;
mod start_grid;
mod tree;

pub(crate) use tree::{KdTree, SpatialStats};
