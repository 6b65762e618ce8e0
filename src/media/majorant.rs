//! A coarse grid of density bounds over the unit cube, and the 3D DDA that walks a ray through
//! it, so that trackers use majorants and minorants that are tight locally (as pbrt-v4 does).
//!
//! Each coarse cell stores the minimum and maximum of the density over the cell:
//!
//! - for a voxel grid, over every voxel in the cell's trilinear footprint (the voxels whose
//!   value any point of the cell interpolates, borders clamped, padded by a rounding margin):
//!   an interpolated value is a convex combination of these, so the bounds are exact bounds;
//! - for the noise cloud, from a rigorous bound of the noise: every gradient-noise octave is a
//!   convex blend of dot products `g . d` with `|g_i| <= 1` and `|d_i| <= 1`, so its magnitude
//!   is at most 3, and the octave average too. With the exact range of the spherical base term
//!   `1 - |2p - 1|` over the cell this bounds the clamped density without sampling it. The bound
//!   is loose inside the cloud (mostly [0, 1]) but exact (zero) where the base term rules the
//!   cloud out, which is all it promises.

use super::DensityField;
use super::noise::NoiseCloud;
use crate::math::Ray;
use glam::Vec3A;

/// Density bounds per coarse cell over the unit cube.
#[derive(Clone, Debug)]
pub struct MajorantGrid {
    res: [usize; 3],
    min: Vec<f32>,
    max: Vec<f32>,
}

/// One piece of a ray inside one coarse cell: the ray parameters it spans and the cell's
/// density bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellSpan {
    /// Ray parameter where the span starts.
    pub t0: f32,
    /// Ray parameter where the span ends.
    pub t1: f32,
    /// A lower bound of the density over the cell.
    pub min: f32,
    /// An upper bound of the density over the cell.
    pub max: f32,
}

/// Voxels per coarse cell along each axis for voxel grids.
const VOXELS_PER_CELL: usize = 2;
/// Coarse cells per axis for the noise cloud.
const NOISE_CELLS: usize = 16;

impl MajorantGrid {
    /// Builds the bounds of `density`.
    pub fn build(density: &DensityField) -> Self {
        match density {
            DensityField::Grid(g) => {
                let res = g.resolution().map(|r| r.div_ceil(VOXELS_PER_CELL).clamp(1, 64));
                let fine = g.resolution();
                Self::from_fn(res, |lo, hi| {
                    // Voxel centres sit at (i + 0.5) / r; a point x interpolates voxels
                    // floor(x r - 0.5) and the next, clamped to the grid.
                    let range = |a: usize| {
                        let r = fine[a] as f32;
                        let i0 = ((lo[a] - 1e-4) * r - 0.5).floor().max(0.0) as usize;
                        let i1 = (((hi[a] + 1e-4) * r - 0.5).floor() + 1.0).max(0.0) as usize;
                        (i0.min(fine[a] - 1), i1.min(fine[a] - 1))
                    };
                    let (x0, x1) = range(0);
                    let (y0, y1) = range(1);
                    let (z0, z1) = range(2);
                    let (mut mn, mut mx) = (f32::INFINITY, 0.0f32);
                    for z in z0..=z1 {
                        for y in y0..=y1 {
                            for x in x0..=x1 {
                                // Over every channel: an RGB density's bounds hold for each.
                                let (lo, hi) = g.voxel_range(x, y, z);
                                mn = mn.min(lo);
                                mx = mx.max(hi);
                            }
                        }
                    }
                    (mn.max(0.0), mx)
                })
            }
            DensityField::Noise(n) => {
                Self::from_fn([NOISE_CELLS; 3], |lo, hi| noise_bounds(n, lo, hi))
            }
            DensityField::Custom(f) => {
                let top = f.max_density();
                Self::from_fn([NOISE_CELLS; 3], |lo, hi| {
                    let (a, b) = f.bounds(lo, hi);
                    // A local bound may not exceed the global one, nor the control the majorant.
                    let b = b.min(top).max(0.0);
                    (a.clamp(0.0, b), b)
                })
            }
        }
    }

    fn from_fn(res: [usize; 3], f: impl Fn(Vec3A, Vec3A) -> (f32, f32)) -> Self {
        let n = res[0] * res[1] * res[2];
        let (mut min, mut max) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for z in 0..res[2] {
            for y in 0..res[1] {
                for x in 0..res[0] {
                    let lo = Vec3A::new(
                        x as f32 / res[0] as f32,
                        y as f32 / res[1] as f32,
                        z as f32 / res[2] as f32,
                    );
                    let hi = Vec3A::new(
                        (x + 1) as f32 / res[0] as f32,
                        (y + 1) as f32 / res[1] as f32,
                        (z + 1) as f32 / res[2] as f32,
                    );
                    let (a, b) = f(lo, hi);
                    min.push(a);
                    max.push(b);
                }
            }
        }
        Self { res, min, max }
    }

    /// Cells along x, y, z.
    pub fn resolution(&self) -> [usize; 3] {
        self.res
    }

    /// The bounds `(min, max)` of cell `(x, y, z)`.
    pub fn cell(&self, x: usize, y: usize, z: usize) -> (f32, f32) {
        let i = (z * self.res[1] + y) * self.res[0] + x;
        (self.min[i], self.max[i])
    }

    /// The spans of `local` (a ray in the unit cube's space) over `(t0, t1)`, which must lie
    /// inside the cube, cell by cell in order (a 3D DDA).
    pub fn spans(&self, local: &Ray, t0: f32, t1: f32) -> Dda<'_> {
        let res = Vec3A::new(self.res[0] as f32, self.res[1] as f32, self.res[2] as f32);
        let p = (local.origin + local.direction * t0).clamp(Vec3A::ZERO, Vec3A::ONE) * res;
        let mut cell = [0i32; 3];
        let mut step = [0i32; 3];
        let mut next = [f32::INFINITY; 3];
        let mut delta = [f32::INFINITY; 3];
        for a in 0..3 {
            let r = self.res[a] as i32;
            cell[a] = (p[a] as i32).clamp(0, r - 1);
            let d = local.direction[a];
            if d > 0.0 {
                step[a] = 1;
                next[a] = ((cell[a] + 1) as f32 / res[a] - local.origin[a]) / d;
                delta[a] = 1.0 / (res[a] * d);
            } else if d < 0.0 {
                step[a] = -1;
                next[a] = (cell[a] as f32 / res[a] - local.origin[a]) / d;
                delta[a] = -1.0 / (res[a] * d);
            }
        }
        Dda { grid: self, cell, step, next, delta, t: t0, t1 }
    }
}

/// The iterator of `MajorantGrid::spans`.
#[derive(Clone, Debug)]
pub struct Dda<'a> {
    grid: &'a MajorantGrid,
    cell: [i32; 3],
    step: [i32; 3],
    next: [f32; 3],
    delta: [f32; 3],
    t: f32,
    t1: f32,
}

impl Iterator for Dda<'_> {
    type Item = CellSpan;

    #[inline]
    fn next(&mut self) -> Option<CellSpan> {
        if self.t >= self.t1 {
            return None;
        }
        let a = if self.next[0] < self.next[1] {
            if self.next[0] < self.next[2] { 0 } else { 2 }
        } else if self.next[1] < self.next[2] {
            1
        } else {
            2
        };
        let mut end = self.next[a].min(self.t1).max(self.t);
        let [x, y, z] = self.cell.map(|c| c as usize);
        let (min, max) = self.grid.cell(x, y, z);
        self.cell[a] += self.step[a];
        if self.cell[a] < 0 || self.cell[a] >= self.grid.res[a] as i32 {
            // Left the grid: the clipped interval ends here up to rounding.
            end = self.t1;
        }
        let span = CellSpan { t0: self.t, t1: end, min, max };
        self.t = end;
        self.next[a] += self.delta[a];
        Some(span)
    }
}

/// Rigorous bounds of the noise cloud's density over the box `[lo, hi]`.
fn noise_bounds(n: &NoiseCloud, lo: Vec3A, hi: Vec3A) -> (f32, f32) {
    // q = 2p - 1; the base term is 1 - |q|.
    let qlo = lo * 2.0 - Vec3A::ONE;
    let qhi = hi * 2.0 - Vec3A::ONE;
    let nearest = Vec3A::ZERO.clamp(qlo, qhi);
    let farthest = Vec3A::select(qlo.abs().cmpgt(qhi.abs()), qlo, qhi);
    let (base_max, base_min) = (1.0 - nearest.length(), 1.0 - farthest.length());
    // |noise| <= 3 (see the module notes), plus a rounding margin.
    let noise = 3.01 * n.amplitude.abs();
    let shaped = |b: f32| ((b - n.threshold) * n.sharpness).clamp(0.0, 1.0);
    let (s_lo, s_hi) = if n.sharpness >= 0.0 {
        (shaped(base_min - noise), shaped(base_max + noise))
    } else {
        (shaped(base_max + noise), shaped(base_min - noise))
    };
    // Points with base + amplitude <= threshold are exactly zero.
    let max = if base_max + n.amplitude <= n.threshold { 0.0 } else { s_hi };
    let min = if base_min + n.amplitude <= n.threshold { 0.0 } else { s_lo };
    (min.min(max), max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::media::{Grid, VolGrid};
    use crate::rng::Sampler;

    fn check_bounds(field: &DensityField, require_tight: bool) {
        let g = MajorantGrid::build(field);
        let mut s = Sampler::new(3, 0, 0);
        let [rx, ry, rz] = g.resolution();
        let mut tight = 0;
        for _ in 0..20_000 {
            let p = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d());
            let c = [
                (p.x * rx as f32) as usize,
                (p.y * ry as f32) as usize,
                (p.z * rz as f32) as usize,
            ];
            let (mn, mx) = g.cell(c[0].min(rx - 1), c[1].min(ry - 1), c[2].min(rz - 1));
            let v = field.at(p);
            assert!(v >= mn - 1e-5 && v <= mx + 1e-5, "{v} outside [{mn}, {mx}] at {p:?}");
            tight += (mx - mn < 0.5) as usize;
        }
        assert!(!require_tight || tight > 0, "bounds are never tight");
    }

    #[test]
    fn grid_bounds_cover_the_trilinear_footprint() {
        let res = [13usize, 7, 9];
        let mut s = Sampler::new(1, 0, 0);
        let data = (0..res[0] * res[1] * res[2]).map(|_| s.next_1d()).collect();
        let grid =
            |data| DensityField::Grid(Grid::new(VolGrid { resolution: res, channels: 1, data }));
        check_bounds(&grid(data), false);
        // A smooth field: the bounds must be tight somewhere.
        check_bounds(
            &grid((0..res[0] * res[1] * res[2]).map(|i| (i % 13) as f32 / 13.0).collect()),
            true,
        );
    }

    #[test]
    fn noise_bounds_hold() {
        check_bounds(&DensityField::Noise(NoiseCloud::default()), false);
    }

    #[test]
    fn dda_visits_cells_in_order_and_covers_the_interval() {
        let res = [5usize, 3, 4];
        let data = (0..60).map(|i| ((i * 37) % 11) as f32).collect();
        let field = DensityField::Grid(Grid::new(VolGrid { resolution: res, channels: 1, data }));
        let g = MajorantGrid::build(&field);
        let mut s = Sampler::new(2, 0, 0);
        let unit = crate::math::Aabb::from_points(Vec3A::ZERO, Vec3A::ONE);
        for _ in 0..2000 {
            let o = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d());
            let d =
                (Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) - Vec3A::splat(0.5)).normalize();
            let ray = Ray::new(o, d);
            let (t0, t1) = unit.intersect(&ray, d.recip(), 0.0, 10.0).unwrap();
            let mut t = t0;
            for span in g.spans(&ray, t0, t1) {
                assert_eq!(span.t0, t);
                assert!(span.t1 >= span.t0);
                for f in [0.1, 0.5, 0.9] {
                    let v = field.at(ray.at(span.t0 + f * (span.t1 - span.t0)));
                    assert!(v >= span.min - 1e-4 && v <= span.max + 1e-4, "{v} vs {span:?}");
                }
                t = span.t1;
            }
            assert_eq!(t, t1);
        }
    }
}
