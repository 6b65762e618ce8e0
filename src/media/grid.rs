//! Dense voxel grids placed in the world by a transform of the unit cube, sampled with
//! cell-centred trilinear interpolation and clamped at the border (Mitsuba's `gridvolume`).

use super::vol::VolGrid;
use crate::math::Spectrum;
use glam::Vec3A;

/// A grid of one (density) or three (RGB density or albedo) channels over the unit cube.
#[derive(Clone, Debug)]
pub struct Grid {
    res: [usize; 3],
    channels: usize,
    data: Vec<f32>,
    max: f32,
}

impl Grid {
    /// Wraps a validated `.vol` grid.
    pub fn new(vol: VolGrid) -> Self {
        let max = vol.data.iter().copied().fold(0.0f32, f32::max);
        Self { res: vol.resolution, channels: vol.channels, data: vol.data, max }
    }

    /// Values per voxel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Resolution along x, y, z.
    pub fn resolution(&self) -> [usize; 3] {
        self.res
    }

    /// The largest value of any channel: a majorant of the interpolated field.
    pub fn max_value(&self) -> f32 {
        self.max
    }

    /// The smallest and largest channel of voxel `(x, y, z)`.
    #[inline]
    pub fn voxel_range(&self, x: usize, y: usize, z: usize) -> (f32, f32) {
        let i = ((z * self.res[1] + y) * self.res[0] + x) * self.channels;
        let v = &self.data[i..i + self.channels];
        (v.iter().copied().fold(f32::INFINITY, f32::min), v.iter().copied().fold(0.0, f32::max))
    }

    /// The interpolated first channel at a point of the unit cube.
    #[inline]
    pub fn scalar(&self, p: Vec3A) -> f32 {
        let mut v = 0.0;
        self.trilinear(p, |i, w| v += w * self.data[i]);
        v
    }

    /// The interpolated RGB value (a one-channel grid is grey).
    #[inline]
    pub fn rgb(&self, p: Vec3A) -> Spectrum {
        if self.channels < 3 {
            return Spectrum::splat(self.scalar(p));
        }
        let mut v = Spectrum::ZERO;
        self.trilinear(p, |i, w| {
            v += w * Spectrum::new(self.data[i], self.data[i + 1], self.data[i + 2])
        });
        v
    }

    /// Calls `f(first value index, weight)` for the eight voxels around `p`.
    #[inline]
    fn trilinear(&self, p: Vec3A, mut f: impl FnMut(usize, f32)) {
        let [rx, ry, rz] = self.res;
        let axis = |x: f32, r: usize| -> (usize, usize, f32) {
            // Voxel centres sit at (i + 0.5) / r; outside the outer centres the value is clamped.
            let c = (x * r as f32 - 0.5).clamp(0.0, (r - 1) as f32);
            let i0 = (c as usize).min(r - 1);
            (i0, (i0 + 1).min(r - 1), c - i0 as f32)
        };
        let (x0, x1, fx) = axis(p.x, rx);
        let (y0, y1, fy) = axis(p.y, ry);
        let (z0, z1, fz) = axis(p.z, rz);
        let idx = |x: usize, y: usize, z: usize| ((z * ry + y) * rx + x) * self.channels;
        for (z, wz) in [(z0, 1.0 - fz), (z1, fz)] {
            for (y, wy) in [(y0, 1.0 - fy), (y1, fy)] {
                f(idx(x0, y, z), (1.0 - fx) * wy * wz);
                f(idx(x1, y, z), fx * wy * wz);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_centres_and_clamps_outside() {
        let g = Grid::new(VolGrid { resolution: [2, 1, 1], channels: 1, data: vec![1.0, 3.0] });
        assert_eq!(g.scalar(Vec3A::new(0.25, 0.5, 0.5)), 1.0);
        assert_eq!(g.scalar(Vec3A::new(0.5, 0.5, 0.5)), 2.0);
        assert_eq!(g.scalar(Vec3A::new(0.75, 0.1, 0.9)), 3.0);
        assert_eq!(g.scalar(Vec3A::new(1.0, 0.5, 0.5)), 3.0);
        assert_eq!(g.scalar(Vec3A::new(0.0, 0.5, 0.5)), 1.0);
        assert_eq!(g.max_value(), 3.0);
    }
}
