//! A uniform grid over the tree's split planes that tells a lookup where to start descending.
//!
//! A lookup from the root visits a node per level, each load waiting on the one before, and
//! the renderer asks the field about twice per path segment. Each cell of this grid holds the
//! deepest node whose part of space contains the whole cell: a leaf, or a node a few levels
//! above the leaves where split planes cross the cell. A lookup from there finds exactly the
//! leaf a descent from the root finds, because every node above it sends the whole cell the
//! same way: images stay identical and renders get faster (see docs/experiments.md). The grid
//! is rebuilt whenever the tree changes.

use super::node::{LEAF, Node};
use glam::Vec3;

/// Cells per leaf the grid aims at: fewer leave more cells straddling a split plane (their
/// lookups descend from there), more cost memory; half or twice as many render as fast (see
/// docs/experiments.md).
const CELLS_PER_LEAF: usize = 16;
/// Most cells, whatever the tree's size (4 MiB of start nodes).
const MAX_CELLS: usize = 1 << 20;
/// Fraction of a cell by which its box is widened when its start node is chosen: a position's
/// cell is computed in floating point and may be off by a rounding error at a cell boundary,
/// and the widened box still contains it.
const MARGIN: f32 = 1e-3;

/// Start nodes on a uniform grid over the box of the tree's split planes.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct StartGrid {
    /// Per axis, the box a position must lie in to use the grid (the whole line on an axis
    /// without splits).
    pub(super) lo: [f32; 3],
    pub(super) hi: [f32; 3],
    /// Per axis, the origin of cell 0 and cells per unit length (0 on an axis of one cell).
    pub(super) origin: [f32; 3],
    pub(super) scale: [f32; 3],
    pub(super) dims: [u32; 3],
    /// Per cell, x fastest, the node to descend from. Empty: start at the root.
    pub(super) start: Vec<u32>,
}

impl StartGrid {
    /// The grid for the tree of `nodes`.
    pub(crate) fn build(nodes: &[Node]) -> Self {
        let leaves = nodes.iter().filter(|n| n.axis == LEAF).count();
        if leaves < 2 {
            return Self::default();
        }
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for n in nodes.iter().filter(|n| n.axis < 3) {
            let a = usize::from(n.axis);
            lo[a] = lo[a].min(n.split);
            hi[a] = hi[a].max(n.split);
        }
        let extent: [f32; 3] = std::array::from_fn(|a| (hi[a] - lo[a]).max(0.0));
        // Cells of equal sides over the axes that have any extent.
        let spread: Vec<f32> = extent.iter().copied().filter(|&e| e > 0.0).collect();
        let target = (leaves * CELLS_PER_LEAF).min(MAX_CELLS) as f64;
        let side = if spread.is_empty() {
            // Splits on one plane per axis: the cells' size only has to be positive there.
            lo.iter().chain(&hi).filter(|v| v.is_finite()).fold(1.0f32, |m, v| m.max(v.abs()))
        } else {
            let volume: f64 = spread.iter().map(|&e| f64::from(e)).product();
            (volume / target).powf(1.0 / spread.len() as f64) as f32
        };
        let mut grid = Self::default();
        for a in 0..3 {
            if lo[a] > hi[a] {
                // No split on this axis: every position is inside along it, in cell 0.
                (grid.lo[a], grid.hi[a], grid.dims[a]) = (f32::NEG_INFINITY, f32::INFINITY, 1);
                continue;
            }
            // Past the outermost splits on each side, so that positions just beyond them
            // start at a leaf too; by a cell and a half, so that those splits lie mid-cell
            // rather than on a boundary, where the margin would make both neighbours straddle
            // them (all of an axis whose splits share one plane would).
            let (from, to) = (lo[a] - 1.5 * side, hi[a] + 1.5 * side);
            let cells = ((to - from) / side).ceil().clamp(1.0, 1024.0);
            (grid.lo[a], grid.hi[a], grid.origin[a]) = (from, to, from);
            grid.dims[a] = cells as u32;
            grid.scale[a] = cells / (to - from);
        }
        let count = grid.dims.iter().map(|&d| d as usize).product::<usize>();
        if count > MAX_CELLS {
            return Self::default();
        }
        grid.start = Vec::with_capacity(count);
        for z in 0..grid.dims[2] {
            for y in 0..grid.dims[1] {
                for x in 0..grid.dims[0] {
                    let (lo, hi) = grid.cell_box([x, y, z]);
                    grid.start.push(deepest_containing(nodes, lo, hi));
                }
            }
        }
        grid
    }

    /// The box of cell `c`, widened by [`MARGIN`] (unbounded on an axis without splits).
    fn cell_box(&self, c: [u32; 3]) -> ([f32; 3], [f32; 3]) {
        let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
        for a in 0..3 {
            if self.scale[a] > 0.0 {
                let size = 1.0 / self.scale[a];
                lo[a] = self.origin[a] + (c[a] as f32 - MARGIN) * size;
                hi[a] = self.origin[a] + (c[a] as f32 + 1.0 + MARGIN) * size;
            } else {
                (lo[a], hi[a]) = (self.lo[a], self.hi[a]);
            }
        }
        (lo, hi)
    }

    /// The node a lookup of `p` starts from: its cell's, or the root (0) outside the grid.
    #[inline]
    pub(crate) fn start(&self, p: Vec3) -> usize {
        if self.start.is_empty() {
            return 0;
        }
        let mut index = 0usize;
        let mut stride = 1usize;
        for (a, v) in p.to_array().into_iter().enumerate() {
            // Also false for NaN.
            if !(v >= self.lo[a] && v <= self.hi[a]) {
                return 0;
            }
            // Saturating: an infinite coordinate on an axis without splits (scale 0) gives
            // NaN, which casts to 0.
            let c = (((v - self.origin[a]) * self.scale[a]) as u32).min(self.dims[a] - 1);
            index += c as usize * stride;
            stride *= self.dims[a] as usize;
        }
        self.start[index] as usize
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        self.start.capacity() * std::mem::size_of::<u32>()
    }
}

/// The deepest node whose part of space contains the whole box `lo..=hi`: a descent from the
/// root while the box lies entirely on one side of each split (the upper side holds positions
/// on the plane, as in `KdTree::lookup`).
fn deepest_containing(nodes: &[Node], lo: [f32; 3], hi: [f32; 3]) -> u32 {
    let mut i = 0usize;
    loop {
        let n = nodes[i];
        if n.axis == LEAF {
            return i as u32;
        }
        let a = usize::from(n.axis & 3);
        if hi[a] < n.split {
            i = n.child as usize;
        } else if lo[a] >= n.split {
            i = n.child as usize + 1;
        } else {
            return i as u32;
        }
    }
}
