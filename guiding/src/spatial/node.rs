//! A node of the spatial tree, shared by the tree and its grid of start nodes.

use serde::{Deserialize, Serialize};

/// The `axis` of a leaf.
pub(super) const LEAF: u8 = 3;

/// One node: an inner node splits on `axis` at `split` and has children `child`, `child + 1`;
/// a leaf (`axis == LEAF`) points at the region `child`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Node {
    pub(super) split: f32,
    pub(super) axis: u8,
    pub(super) child: u32,
}
