//! The adaptive spatial kd-tree that partitions space into regions.
//!
//! The root covers all of space, so every position has a leaf. A leaf splits once it has seen
//! enough samples, on the axis where its samples spread most, at their mean: dense parts of the
//! scene get small regions, sparse parts keep large ones. Nodes live in one vector, children
//! side by side, and a uniform grid of start nodes (`start_grid`) lets most lookups skip
//! the descent.

use super::node::{LEAF, Node};
use super::start_grid::StartGrid;
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

/// The tree of regions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct KdTree {
    nodes: Vec<Node>,
    /// Where lookups start; derived from `nodes` (not saved), and empty (start at the root)
    /// from a split until [`index_cells`](Self::index_cells) runs.
    #[serde(skip)]
    starts: StartGrid,
}

impl KdTree {
    /// One leaf, for region 0, covering everything.
    pub(crate) fn new() -> Self {
        Self {
            nodes: vec![Node { split: 0.0, axis: LEAF, child: 0 }],
            starts: StartGrid::default(),
        }
    }

    /// The region containing `pos` and the index of its leaf node. Positions exactly on a
    /// split plane go to the upper side.
    #[inline]
    pub(crate) fn lookup(&self, pos: Vec3) -> (usize, usize) {
        self.descend(pos, self.starts.start(pos))
    }

    /// [`lookup`](Self::lookup) from node `from`, which must contain `pos`.
    #[inline]
    fn descend(&self, pos: Vec3, from: usize) -> (usize, usize) {
        // Indexed by the axis without glam's per-component match, which costs a hard-to-predict
        // branch at every level; the fourth slot is never read (inner nodes have axis < 3).
        let p = [pos.x, pos.y, pos.z, 0.0];
        let mut i = from;
        loop {
            let n = self.nodes[i];
            if n.axis == LEAF {
                return (n.child as usize, i);
            }
            i = n.child as usize + usize::from(p[usize::from(n.axis & 3)] >= n.split);
        }
    }

    /// How far from `pos` along `dir` the leaf containing `pos` reaches: the distance to the
    /// nearest of its bounding planes ahead (infinite where the leaf is unbounded that way).
    /// A descent from the root, which keeps the leaf's bounds; `pos` on a split plane belongs
    /// to the upper side, so a ray leaving downwards from it gets 0.
    pub(crate) fn exit(&self, pos: Vec3, dir: Vec3) -> f32 {
        let p = [pos.x, pos.y, pos.z, 0.0];
        let (mut lo, mut hi) = ([f32::NEG_INFINITY; 4], [f32::INFINITY; 4]);
        let mut i = 0;
        loop {
            let n = self.nodes[i];
            if n.axis == LEAF {
                break;
            }
            let a = usize::from(n.axis & 3);
            let upper = p[a] >= n.split;
            if upper {
                lo[a] = n.split;
            } else {
                hi[a] = n.split;
            }
            i = n.child as usize + usize::from(upper);
        }
        let d = [dir.x, dir.y, dir.z];
        (0..3)
            .filter_map(|a| match d[a] {
                x if x > 0.0 => Some((hi[a] - p[a]) / x),
                x if x < 0.0 => Some((lo[a] - p[a]) / x),
                _ => None,
            })
            .fold(f32::INFINITY, f32::min)
            .max(0.0)
    }

    /// Turns leaf `node` into an inner node; its lower half keeps region `lower`, its upper
    /// half gets region `upper`.
    pub(crate) fn split(&mut self, node: usize, axis: usize, split: f32, lower: u32, upper: u32) {
        debug_assert_eq!(self.nodes[node].axis, LEAF);
        let child = self.nodes.len() as u32;
        self.nodes.push(Node { split: 0.0, axis: LEAF, child: lower });
        self.nodes.push(Node { split: 0.0, axis: LEAF, child: upper });
        self.nodes[node] = Node { split, axis: axis as u8, child };
        self.starts = StartGrid::default();
    }

    /// Builds the grid of start nodes for the tree as it is (after splits, and after loading).
    pub(crate) fn index_cells(&mut self) {
        self.starts = StartGrid::build(&self.nodes);
    }

    pub(crate) fn node_count(&self) -> usize {
        self.nodes.len()
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node>() + self.starts.memory_bytes()
    }

    /// Depth of the deepest leaf (the root alone has depth 0).
    pub(crate) fn depth(&self) -> u32 {
        let mut stack = vec![(0usize, 0u32)];
        let mut deepest = 0;
        while let Some((i, d)) = stack.pop() {
            let n = self.nodes[i];
            if n.axis == LEAF {
                deepest = deepest.max(d);
            } else {
                stack.push((n.child as usize, d + 1));
                stack.push((n.child as usize + 1, d + 1));
            }
        }
        deepest
    }

    /// Checks the structure: every node reachable exactly once, every region referenced by
    /// exactly one leaf. Loading a field runs this, so corrupt data cannot make lookups panic.
    pub(crate) fn validate(&self, regions: usize) -> Result<(), String> {
        let mut seen = vec![false; regions];
        let mut reached = vec![false; self.nodes.len()];
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = *self.nodes.get(i).ok_or_else(|| format!("node {i} does not exist"))?;
            if std::mem::replace(&mut reached[i], true) {
                return Err(format!("node {i} is reached twice"));
            }
            if n.axis == LEAF {
                let r = n.child as usize;
                if r >= regions || std::mem::replace(&mut seen[r], true) {
                    return Err(format!("leaf {i} refers to region {r} badly"));
                }
            } else if n.axis < 3 && n.split.is_finite() {
                stack.push(n.child as usize);
                stack.push(n.child as usize + 1);
            } else {
                return Err(format!("node {i} has axis {} and split {}", n.axis, n.split));
            }
        }
        if !reached.iter().all(|&r| r) || !seen.iter().all(|&s| s) {
            return Err("unreachable nodes or regions without a leaf".into());
        }
        Ok(())
    }
}

/// Running first and second moments of the positions a leaf has seen since it was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct SpatialStats {
    pub(crate) count: f64,
    sum: DVec3,
    sum_sq: DVec3,
}

impl SpatialStats {
    pub(crate) fn add(&mut self, p: Vec3) {
        let p = p.as_dvec3();
        self.count += 1.0;
        self.sum += p;
        self.sum_sq += p * p;
    }

    pub(crate) fn mean(&self) -> DVec3 {
        if self.count > 0.0 { self.sum / self.count } else { DVec3::ZERO }
    }

    pub(crate) fn variance(&self) -> DVec3 {
        if self.count < 2.0 {
            return DVec3::ZERO;
        }
        let m = self.mean();
        (self.sum_sq / self.count - m * m).max(DVec3::ZERO)
    }

    /// The axis of largest variance and the mean along it, if the samples spread at all.
    pub(crate) fn split_plane(&self) -> Option<(usize, f32)> {
        let v = self.variance();
        let axis = if v.x >= v.y && v.x >= v.z {
            0
        } else if v.y >= v.z {
            1
        } else {
            2
        };
        let m = self.mean()[axis];
        // Variance below float resolution at this coordinate means the points coincide.
        let resolution = (m.abs() * 1e-6).max(1e-12);
        (v[axis].sqrt() > resolution).then_some((axis, m as f32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_follows_splits() {
        let mut t = KdTree::new();
        assert_eq!(t.lookup(Vec3::splat(5.0)).0, 0);
        t.split(0, 0, 1.0, 0, 1);
        assert_eq!(t.lookup(Vec3::new(0.5, 0.0, 0.0)).0, 0);
        assert_eq!(t.lookup(Vec3::new(1.0, 0.0, 0.0)).0, 1);
        let (_, leaf) = t.lookup(Vec3::new(3.0, 0.0, 0.0));
        t.split(leaf, 2, -1.0, 1, 2);
        assert_eq!(t.lookup(Vec3::new(3.0, 0.0, -2.0)).0, 1);
        assert_eq!(t.lookup(Vec3::new(3.0, 0.0, 0.0)).0, 2);
        assert_eq!(t.depth(), 2);
        t.validate(3).unwrap();
        assert!(t.validate(4).is_err());
    }

    /// A tree of `leaves` leaves from splits of random leaves at random planes through the
    /// box -5..5 (a plain xorshift, so the test needs no generator).
    fn random_tree(leaves: usize, seed: u64) -> KdTree {
        let mut state = seed | 1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut t = KdTree::new();
        for r in 1..leaves {
            let p = Vec3::new(next(), next(), next()) * 10.0 - 5.0;
            let (region, leaf) = t.lookup(p);
            let axis = (next() * 3.0) as usize % 3;
            t.split(leaf, axis, p[axis], region as u32, r as u32);
        }
        t
    }

    #[test]
    fn exits_are_where_a_ray_leaves_its_leaf() {
        let tree = random_tree(60, 7);
        let mut state = 11u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut checked = 0;
        for _ in 0..2000 {
            let pos = Vec3::new(next(), next(), next()) * 10.0 - 5.0;
            let dir = Vec3::new(next(), next(), next()) * 2.0 - 1.0;
            let Some(dir) = dir.try_normalize() else { continue };
            let (leaf, _) = tree.lookup(pos);
            let t = tree.exit(pos, dir);
            assert!(t >= 0.0, "{t}");
            if !t.is_finite() {
                continue;
            }
            // Just before the exit the ray is still in the leaf, just after it is not.
            let (before, after) = (pos + dir * (t - 1e-3).max(0.0), pos + dir * (t + 1e-3));
            assert_eq!(tree.lookup(before).0, leaf, "{pos} {dir} {t}");
            assert_ne!(tree.lookup(after).0, leaf, "{pos} {dir} {t}");
            checked += 1;
        }
        assert!(checked > 1000, "{checked}");
        // One leaf covers everything: no exit.
        assert_eq!(KdTree::new().exit(Vec3::ZERO, Vec3::X), f32::INFINITY);
    }

    #[test]
    fn start_grid_lookups_find_the_leaf_a_descent_from_the_root_finds() {
        for (leaves, seed) in [(2, 1), (40, 2), (1000, 3), (3000, 4)] {
            let mut t = random_tree(leaves, seed);
            t.validate(leaves).unwrap();
            t.index_cells();
            assert!(!t.starts.start.is_empty(), "{leaves} leaves");
            let mut points: Vec<Vec3> = Vec::new();
            // A lattice over and past the box, finer than the cells.
            for i in 0..=60 {
                for j in 0..=60 {
                    for k in 0..=15 {
                        let f = |v: i32, n: f32| v as f32 / n * 14.0 - 7.0;
                        points.push(Vec3::new(f(i, 60.0), f(j, 60.0), f(k, 15.0)));
                    }
                }
            }
            // Exactly on every split plane and a hair either side, and on cell boundaries.
            for n in t.nodes.iter().filter(|n| n.axis < 3) {
                for v in [n.split, n.split.next_down(), n.split.next_up()] {
                    let mut p = Vec3::splat(0.3);
                    p[usize::from(n.axis)] = v;
                    points.push(p);
                }
            }
            for a in 0..3 {
                for c in 0..t.starts.dims[a] {
                    if t.starts.scale[a] > 0.0 {
                        let mut p = Vec3::splat(-0.2);
                        p[a] = t.starts.origin[a] + c as f32 / t.starts.scale[a];
                        points.extend([p, Vec3::from_array(p.to_array().map(f32::next_up))]);
                    }
                }
            }
            points.extend([
                Vec3::NAN,
                Vec3::INFINITY,
                Vec3::NEG_INFINITY,
                Vec3::new(f32::NAN, 0.0, 0.0),
            ]);
            // Levels a descent from `from` goes down to reach `p`'s leaf.
            let levels = |p: Vec3, from: usize| {
                let (mut i, mut n) = (from, 0);
                while t.nodes[i].axis != LEAF {
                    let node = t.nodes[i];
                    i = node.child as usize + usize::from(p[usize::from(node.axis)] >= node.split);
                    n += 1;
                }
                n
            };
            let (mut from_root, mut from_start) = (0, 0);
            for &p in &points {
                assert_eq!(t.lookup(p), t.descend(p, 0), "{leaves} leaves, {p}");
                if p.abs().max_element() < 5.0 {
                    from_root += levels(p, 0);
                    from_start += levels(p, t.starts.start(p));
                }
            }
            // The grid is worth having: among the splits, it saves most of each descent.
            if leaves > 2 {
                assert!(from_start * 2 < from_root, "{leaves} leaves: {from_start} of {from_root}");
            }
            // A split discards the grid, so lookups never read a stale one.
            let (region, leaf) = t.lookup(Vec3::splat(0.1));
            t.split(leaf, 0, 0.1, region as u32, leaves as u32);
            assert_eq!(t.lookup(Vec3::splat(0.1)).0, leaves);
            assert_eq!(t.lookup(Vec3::splat(0.1)), t.descend(Vec3::splat(0.1), 0));
        }
        // One leaf, or splits along one axis only: nothing to skip, or a grid of one row.
        let mut t = KdTree::new();
        t.index_cells();
        assert_eq!(t.lookup(Vec3::ONE), (0, 0));
        for (i, x) in [1.0f32, 2.0, 3.0].into_iter().enumerate() {
            let (region, leaf) = t.lookup(Vec3::new(x, 7.0, -7.0));
            t.split(leaf, 0, x, region as u32, i as u32 + 1);
        }
        t.index_cells();
        assert_eq!(t.starts.dims[1..], [1, 1]);
        for x in [-1.0f32, 1.0, 1.5, 2.0, 2.9, 3.0, 9.0] {
            for y in [-1e30f32, 0.0, f32::INFINITY] {
                let p = Vec3::new(x, y, 0.5);
                assert_eq!(t.lookup(p), t.descend(p, 0), "{p}");
            }
        }
    }

    #[test]
    fn split_plane_is_axis_of_largest_variance_at_mean() {
        let mut s = SpatialStats::default();
        for i in 0..100 {
            let x = i as f32 * 0.01;
            s.add(Vec3::new(x, 5.0 + 3.0 * x, 1.0));
        }
        let (axis, at) = s.split_plane().unwrap();
        assert_eq!(axis, 1);
        assert!((at - (5.0 + 3.0 * 0.495)).abs() < 1e-4);
        let mut same = SpatialStats::default();
        (0..10).for_each(|_| same.add(Vec3::new(1e3, 2.0, 3.0)));
        assert!(same.split_plane().is_none());
    }
}
