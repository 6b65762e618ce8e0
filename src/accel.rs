//! A bounding volume hierarchy over every primitive of the scene (triangles, spheres, disks).
//!
//! Built top-down with binned surface-area-heuristic splits and flattened into a depth-first
//! array, traversed with a fixed-size stack (no allocation per ray). A hand-written BVH keeps
//! the primitive test inline with our own shape enum and `Vec3A` rays; the BVH crates on
//! crates.io are built on nalgebra types and allocate per traversal.

use crate::math::{Aabb, Ray};
use crate::shapes::{Geometry, PrimHit};
use glam::Vec3A;

const BINS: usize = 16;
const MAX_LEAF: usize = 4;
const STACK: usize = 128;
/// Below this depth splits follow the SAH; deeper ones split at the median, which bounds the
/// tree depth by `SAH_DEPTH + log2(n)` and so keeps traversal within `STACK`.
const SAH_DEPTH: usize = 48;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: index of the first primitive. Interior: index of the second child (the first
    /// child follows the node directly).
    offset: u32,
    /// Number of primitives in a leaf; 0 for an interior node.
    count: u16,
    axis: u8,
}

/// A primitive reference: shape index and primitive index within the shape.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PrimRef {
    /// Shape index.
    pub(crate) shape: u32,
    /// Primitive index within the shape (triangle number for meshes).
    pub(crate) index: u32,
}

/// The closest intersection found by a traversal.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BvhHit {
    /// The primitive hit.
    pub(crate) prim: PrimRef,
    /// Parametric hit data.
    pub(crate) hit: PrimHit,
}

/// The hierarchy.
#[derive(Clone, Debug, Default)]
pub(crate) struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<PrimRef>,
}

struct BuildPrim {
    bounds: Aabb,
    centroid: glam::Vec3A,
    prim: PrimRef,
}

impl Bvh {
    /// Builds the hierarchy over all primitives of `shapes`.
    pub(crate) fn build(shapes: &[Geometry]) -> Self {
        let mut items: Vec<BuildPrim> = Vec::new();
        for (s, g) in shapes.iter().enumerate() {
            for i in 0..g.primitive_count() as u32 {
                let bounds = g.primitive_bounds(i);
                if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
                    continue;
                }
                items.push(BuildPrim {
                    bounds,
                    centroid: bounds.center(),
                    prim: PrimRef { shape: s as u32, index: i },
                });
            }
        }
        let mut bvh =
            Bvh { nodes: Vec::with_capacity(2 * items.len() / MAX_LEAF + 1), prims: Vec::new() };
        if !items.is_empty() {
            let n = items.len();
            bvh.build_node(&mut items, 0, n, 0);
        }
        bvh.prims = items.into_iter().map(|b| b.prim).collect();
        bvh
    }

    /// Bounds of the whole scene.
    pub(crate) fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    fn build_node(
        &mut self,
        items: &mut [BuildPrim],
        start: usize,
        end: usize,
        depth: usize,
    ) -> usize {
        let node_index = self.nodes.len();
        let slice = &mut items[start..end];
        let bounds = slice.iter().fold(Aabb::EMPTY, |b, p| b.union(&p.bounds));
        self.nodes.push(Node {
            bounds,
            offset: start as u32,
            count: (end - start) as u16,
            axis: 0,
        });
        if slice.len() <= MAX_LEAF {
            return node_index;
        }
        let cbounds = slice.iter().fold(Aabb::EMPTY, |b, p| b.grow(p.centroid));
        let ext = cbounds.extent();
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = if ext[axis] <= 0.0 || depth >= SAH_DEPTH {
            // Coincident centroids or a deep tree: split in the middle of the list.
            0
        } else {
            match best_sah_split(slice, &cbounds, axis, bounds.surface_area()) {
                Some(split) => {
                    let lo = cbounds.min[axis];
                    let scale = BINS as f32 / ext[axis];
                    partition(slice, |p| bin_of(p.centroid[axis], lo, scale) < split)
                }
                None if slice.len() <= 16 => return node_index,
                None => 0,
            }
        };
        let mid = if mid == 0 || mid == slice.len() {
            slice.sort_by(|a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
            slice.len() / 2
        } else {
            mid
        };
        self.nodes[node_index].count = 0;
        self.nodes[node_index].axis = axis as u8;
        self.build_node(items, start, start + mid, depth + 1);
        let second = self.build_node(items, start + mid, end, depth + 1);
        self.nodes[node_index].offset = second as u32;
        node_index
    }

    /// The closest intersection along `ray` within `(0, t_max)`.
    #[inline]
    pub(crate) fn intersect(
        &self,
        shapes: &[Geometry],
        ray: &Ray,
        mut t_max: f32,
    ) -> Option<BvhHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv_dir = ray.direction.recip();
        let neg = [inv_dir.x < 0.0, inv_dir.y < 0.0, inv_dir.z < 0.0];
        // With a finite reciprocal no slab distance can be NaN (0 * inf), and the short box
        // test (`hits_box`) gives exactly the NaN-safe test's answer; a ray parallel to an
        // axis (a zero or denormal component) keeps the NaN-safe test, which treats a ray
        // lying in a slab's plane as inside the slab.
        let parallel = !inv_dir.is_finite();
        // An ArrayVec, not an array: zeroing 512 bytes per ray showed in profiles (see
        // docs/experiments.md).
        let mut stack = arrayvec::ArrayVec::<u32, STACK>::new();
        let mut current = 0usize;
        let mut best: Option<BvhHit> = None;
        loop {
            let node = &self.nodes[current];
            if enters(&node.bounds, ray, inv_dir, parallel, t_max) {
                if node.count > 0 {
                    let first = node.offset as usize;
                    for prim in &self.prims[first..first + node.count as usize] {
                        if let Some(hit) =
                            shapes[prim.shape as usize].intersect(prim.index, ray, t_max)
                        {
                            t_max = hit.t;
                            best = Some(BvhHit { prim: *prim, hit });
                        }
                    }
                } else {
                    // Visit the nearer child first so t_max shrinks early.
                    let (near, far) = if neg[node.axis as usize] {
                        (node.offset as usize, current + 1)
                    } else {
                        (current + 1, node.offset as usize)
                    };
                    // The build bounds the depth (SAH_DEPTH), so the stack cannot overflow.
                    stack.push(far as u32);
                    current = near;
                    continue;
                }
            }
            let Some(next) = stack.pop() else { break };
            current = next as usize;
        }
        best
    }
}

/// What a shadow traversal found (see [`Bvh::shadow`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ShadowTrace {
    /// A blocking primitive lies within reach.
    Blocked,
    /// Nothing blocks; every other primitive's crossings within reach are in the list
    /// (unsorted).
    Clear,
    /// Nothing blocking was met, but more crossings than the list holds: the caller must
    /// trace step by step.
    Overflow,
}

impl Bvh {
    /// One traversal for a shadow ray: stops at the first primitive of a shape that `blocks`
    /// within `(0, t_max)`, and otherwise collects every crossing of the others (null
    /// surfaces; closed shapes are crossed twice). Tracing step by step takes a closest-hit
    /// traversal per null surface crossed, twice the work where a room's walls stand behind
    /// a medium's box.
    #[inline]
    pub(crate) fn shadow<const N: usize>(
        &self,
        shapes: &[Geometry],
        ray: &Ray,
        t_max: f32,
        blocks: impl Fn(u32) -> bool,
        crossings: &mut arrayvec::ArrayVec<BvhHit, N>,
    ) -> ShadowTrace {
        crossings.clear();
        if self.nodes.is_empty() {
            return ShadowTrace::Clear;
        }
        let inv_dir = ray.direction.recip();
        let parallel = !inv_dir.is_finite();
        let mut stack = arrayvec::ArrayVec::<u32, STACK>::new();
        let mut current = 0usize;
        let mut full = false;
        loop {
            let node = &self.nodes[current];
            if enters(&node.bounds, ray, inv_dir, parallel, t_max) {
                if node.count == 0 {
                    // Any order: a blocker anywhere ends the search, and every crossing counts.
                    stack.push(node.offset);
                    current += 1;
                    continue;
                }
                let first = node.offset as usize;
                for prim in &self.prims[first..first + node.count as usize] {
                    let shape = &shapes[prim.shape as usize];
                    let mut next = shape.intersect(prim.index, ray, t_max);
                    while let Some(hit) = next {
                        if blocks(prim.shape) {
                            return ShadowTrace::Blocked;
                        }
                        full |= crossings.try_push(BvhHit { prim: *prim, hit }).is_err();
                        next = shape.next_crossing(prim.index, ray, hit.t, t_max);
                    }
                }
            }
            let Some(next) = stack.pop() else { break };
            current = next as usize;
        }
        if full { ShadowTrace::Overflow } else { ShadowTrace::Clear }
    }
}

/// Whether a traversal enters `b`: the NaN-safe box test for a ray `parallel` to an axis,
/// the short one otherwise (see [`Bvh::intersect`]).
#[inline]
fn enters(b: &Aabb, ray: &Ray, inv_dir: Vec3A, parallel: bool, t_max: f32) -> bool {
    if parallel {
        b.intersect(ray, inv_dir, 0.0, t_max).is_some()
    } else {
        hits_box(b, ray.origin, inv_dir, t_max)
    }
}

/// Whether the ray from `origin` meets `b` within `[0, t_max]`, for a finite reciprocal
/// direction `inv_dir`: slab distances are then never NaN, so no masks are needed.
#[inline]
fn hits_box(b: &Aabb, origin: Vec3A, inv_dir: Vec3A, t_max: f32) -> bool {
    let t0 = (b.min - origin) * inv_dir;
    let t1 = (b.max - origin) * inv_dir;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(t_max);
    near <= far
}

#[inline]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// The bin boundary with the lowest SAH cost, or `None` when a leaf is cheaper.
fn best_sah_split(items: &[BuildPrim], cb: &Aabb, axis: usize, parent_area: f32) -> Option<usize> {
    let lo = cb.min[axis];
    let scale = BINS as f32 / cb.extent()[axis];
    let mut bins = [(Aabb::EMPTY, 0usize); BINS];
    for p in items {
        let b = bin_of(p.centroid[axis], lo, scale);
        bins[b].0 = bins[b].0.union(&p.bounds);
        bins[b].1 += 1;
    }
    let mut right_area = [0.0f32; BINS];
    let mut right_count = [0usize; BINS];
    let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
    for i in (1..BINS).rev() {
        acc = acc.union(&bins[i].0);
        cnt += bins[i].1;
        right_area[i] = acc.surface_area();
        right_count[i] = cnt;
    }
    let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
    let mut best = (f32::INFINITY, 0);
    for i in 1..BINS {
        acc = acc.union(&bins[i - 1].0);
        cnt += bins[i - 1].1;
        if cnt == 0 || right_count[i] == 0 {
            continue;
        }
        let cost = acc.surface_area() * cnt as f32 + right_area[i] * right_count[i] as f32;
        if cost < best.0 {
            best = (cost, i);
        }
    }
    // Traversal cost 1 against intersection cost 1 per primitive.
    let leaf_cost = items.len() as f32;
    let split_cost = 0.125 + best.0 / parent_area.max(f32::MIN_POSITIVE);
    (best.1 > 0 && (split_cost < leaf_cost || items.len() > MAX_LEAF * 4)).then_some(best.1)
}

fn partition<T>(items: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let mut i = 0;
    for j in 0..items.len() {
        if pred(&items[j]) {
            items.swap(i, j);
            i += 1;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Mesh, Sphere};
    use crate::transform::Transform;
    use glam::{Vec3, Vec3A};

    #[test]
    fn matches_brute_force() {
        // A grid of spheres plus a mesh; the BVH must find the same closest hit as a linear scan.
        let mut shapes = Vec::new();
        for i in 0..8 {
            for j in 0..8 {
                let t = Transform::scale(Vec3::splat(0.3))
                    .unwrap()
                    .then(&Transform::translate(Vec3::new(i as f32, j as f32, 0.0)));
                shapes.push(Geometry::Sphere(Sphere::new(t)));
            }
        }
        shapes.push(Geometry::Mesh(Mesh::cube(&Transform::translate(Vec3::new(3.0, 3.0, 4.0)))));
        let bvh = Bvh::build(&shapes);
        let mut s = crate::rng::Sampler::new(1, 0, 0);
        for _ in 0..2000 {
            let o = Vec3A::new(s.next_1d() * 8.0 - 0.5, s.next_1d() * 8.0 - 0.5, -5.0);
            let d = (Vec3A::new(s.next_1d() * 8.0, s.next_1d() * 8.0, 3.0) - o).normalize();
            let ray = Ray::new(o, d);
            let fast = bvh.intersect(&shapes, &ray, f32::INFINITY).map(|h| h.hit.t);
            let mut slow: Option<f32> = None;
            for g in &shapes {
                for i in 0..g.primitive_count() as u32 {
                    if let Some(h) = g.intersect(i, &ray, slow.unwrap_or(f32::INFINITY)) {
                        slow = Some(h.t);
                    }
                }
            }
            assert_eq!(fast, slow);
        }
    }

    #[test]
    fn axis_parallel_and_boundary_rays_match_brute_force() {
        // Rays along the axes and along diagonals, starting on the cube's face planes, edges
        // and corners (integer coordinates) and just off them: the short box test and the
        // NaN-safe one must find exactly what a linear scan finds.
        let shapes = vec![
            Geometry::Mesh(Mesh::cube(&Transform::translate(Vec3::new(3.0, 3.0, 4.0)))),
            Geometry::Mesh(Mesh::cube(&Transform::translate(Vec3::new(0.0, 0.0, 0.0)))),
        ];
        let bvh = Bvh::build(&shapes);
        let coords = [-2.0f32, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 1.0 + 1e-6, 2.0 - 1e-6];
        let mut dirs = Vec::new();
        for x in [-1.0f32, 0.0, 1.0] {
            for y in [-1.0f32, 0.0, 1.0] {
                for z in [-1.0f32, 0.0, 1.0] {
                    if (x, y, z) != (0.0, 0.0, 0.0) {
                        dirs.push(Vec3A::new(x, y, z).normalize());
                    }
                }
            }
        }
        dirs.push(Vec3A::new(1.0, 1e-40, 0.3).normalize()); // a denormal component
        let mut checked = 0;
        for &x in &coords {
            for &y in &coords {
                for &z in &coords {
                    for &d in &dirs {
                        let ray = Ray::new(Vec3A::new(x, y, z), d);
                        let fast = bvh.intersect(&shapes, &ray, f32::INFINITY).map(|h| h.hit.t);
                        let mut slow: Option<f32> = None;
                        for g in &shapes {
                            for i in 0..g.primitive_count() as u32 {
                                let t_max = slow.unwrap_or(f32::INFINITY);
                                if let Some(h) = g.intersect(i, &ray, t_max) {
                                    slow = Some(h.t);
                                }
                            }
                        }
                        assert_eq!(fast, slow, "origin ({x}, {y}, {z}), direction {d}");
                        checked += usize::from(slow.is_some());
                    }
                }
            }
        }
        assert!(checked > 2_000, "only {checked} rays hit anything");
    }
}
