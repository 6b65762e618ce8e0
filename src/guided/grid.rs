//! The direct fluence of training paths on a fine uniform grid: where extra collisions for
//! next-event estimation of delta lights go (`distance::ExtraCollision`).
//!
//! The field's regions adapt to where training paths scatter, not to where direct light
//! changes, and a shaft of sunlight through a window is narrower than most of them. Next-event
//! records are plentiful (one per training vertex), and a lookup in a uniform grid costs a
//! few multiplications, so a ray can ask it at many points.

use super::DirectRecord;
use glam::{UVec3, Vec3A};
use std::io::{Read, Write};
use zerovar_guiding::GuidingError;

/// Most cells a saved grid may claim (64 along the longest side gives at most 2^18).
const MAX_CELLS: u64 = 1 << 24;
/// Cells along the grid's longest side.
const CELLS_LONGEST: f32 = 64.0;
/// The share of records the grid's box may leave out on each side of each axis: paths in an
/// open medium wander far, and a box around all of them would spread its cells thin.
const OUTLIERS: f64 = 1e-3;

/// The mean next-event estimate of the fluence in each cell of a uniform grid over the
/// training vertices' bounding box (zero outside it and in cells without records).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DirectGrid {
    min: Vec3A,
    /// Cells per unit length.
    scale: f32,
    dims: UVec3,
    /// Each cell's fluence with its mantissa cut to 7 bits (bfloat16): a sampling density
    /// needs no more, and half the bytes keep more of the grid in cache (its reads along
    /// rays wait on memory).
    values: Vec<u16>,
    /// The box of cells with light, in grid coordinates (derived from `values`): a read
    /// outside it is zero without touching memory, and most of a ray's parts lie outside a
    /// shaft of sunlight.
    lit: (Vec3A, Vec3A),
}

/// `v` as bfloat16 (the high half of its bits: truncation, which keeps 0 and sign).
#[inline]
fn to_bf16(v: f32) -> u16 {
    (v.to_bits() >> 16) as u16
}

#[inline]
fn from_bf16(v: u16) -> f32 {
    f32::from_bits(u32::from(v) << 16)
}

impl DirectGrid {
    /// The grid of `records`' mean fluence per cell.
    pub fn build(records: &[DirectRecord]) -> Self {
        let (min, max) = bounds(records);
        let extent = (max - min).max_element();
        if !(extent > 0.0 && extent.is_finite()) {
            return Self::default();
        }
        // Cells a hair larger than extent / CELLS_LONGEST, so the maximum falls inside.
        let scale = CELLS_LONGEST / (extent * (1.0 + 1e-5));
        let dims = ((max - min) * scale).floor().as_uvec3() + UVec3::ONE;
        let mut grid = Self { min, scale, dims, ..Self::default() };
        let n = (dims.x * dims.y * dims.z) as usize;
        let (mut sums, mut counts) = (vec![0.0f64; n], vec![0u32; n]);
        for r in records {
            if let Some(i) = grid.index(r.position) {
                sums[i] += f64::from(r.fluence);
                counts[i] += 1;
            }
        }
        grid.values = sums
            .iter()
            .zip(&counts)
            .map(|(&s, &c)| to_bf16(if c > 0 { (s / f64::from(c)) as f32 } else { 0.0 }))
            .collect();
        grid.lit = grid.lit_box();
        grid
    }

    /// The smallest box of whole cells holding every cell with light (an empty box if none).
    fn lit_box(&self) -> (Vec3A, Vec3A) {
        let (mut lo, mut hi) = (self.dims, UVec3::ZERO);
        let (nx, ny) = (self.dims.x as usize, self.dims.y as usize);
        for (i, _) in self.values.iter().enumerate().filter(|(_, v)| from_bf16(**v) > 0.0) {
            let c = UVec3::new((i % nx) as u32, ((i / nx) % ny) as u32, (i / (nx * ny)) as u32);
            lo = lo.min(c);
            hi = hi.max(c + UVec3::ONE);
        }
        (lo.as_vec3a(), hi.as_vec3a())
    }

    fn index(&self, x: Vec3A) -> Option<usize> {
        let c = (x - self.min) * self.scale;
        if !(c.cmpge(Vec3A::ZERO).all() && c.is_finite()) {
            return None;
        }
        let c = c.as_uvec3();
        (c.cmplt(self.dims).all()).then(|| (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize)
    }

    /// The direct fluence at `start + (j + 0.5) step` for each `out[j]`: a ray's parts, stepped
    /// through in grid coordinates.
    #[inline]
    pub fn fluence_along(&self, start: Vec3A, step: Vec3A, out: &mut [f32]) {
        let d = step * self.scale;
        let c0 = (start - self.min) * self.scale + 0.5 * d;
        let (lo, hi) = self.lit;
        out.fill(0.0);
        // The parts whose middles may lie in the lit box (a part more on each side against
        // rounding); each is still checked exactly, as `c0 + j d` accumulates.
        let (first, end) = parts_within(c0, d, lo, hi, out.len());
        let mut c = c0;
        for (j, v) in out.iter_mut().enumerate().take(end) {
            if j >= first && c.cmpge(lo).all() && c.cmplt(hi).all() {
                let i = c.as_uvec3();
                *v = from_bf16(
                    self.values[(i.x + self.dims.x * (i.y + self.dims.y * i.z)) as usize],
                );
            }
            c += d;
        }
    }

    /// Writes the grid: its corner and cells per unit length (f32), its cells along each axis
    /// (u32) and every cell's value (f32), x fastest, all little-endian.
    pub(super) fn write(&self, w: &mut impl Write) -> std::io::Result<()> {
        for v in self.min.to_array().into_iter().chain([self.scale]) {
            w.write_all(&v.to_le_bytes())?;
        }
        for d in self.dims.to_array() {
            w.write_all(&d.to_le_bytes())?;
        }
        self.values.iter().try_for_each(|&v| w.write_all(&from_bf16(v).to_le_bytes()))
    }

    /// Reads what [`write`](Self::write) wrote, checking it describes a grid of fluences.
    pub(super) fn read(r: &mut impl Read) -> Result<Self, GuidingError> {
        let mut f = || -> Result<f32, GuidingError> { Ok(f32::from_le_bytes(read4(r)?)) };
        let min = Vec3A::new(f()?, f()?, f()?);
        let scale = f()?;
        let dims = UVec3::new(
            u32::from_le_bytes(read4(r)?),
            u32::from_le_bytes(read4(r)?),
            u32::from_le_bytes(read4(r)?),
        );
        let n = dims.as_u64vec3().element_product();
        if n == 0 {
            return Ok(Self::default());
        }
        if n > MAX_CELLS || !(min.is_finite() && scale.is_finite() && scale > 0.0) {
            return Err(GuidingError::Decode(format!(
                "the direct-light grid (corner {min}, {scale} cells per unit, {dims} cells) is not \
                 one `zerovar train` writes"
            )));
        }
        let mut values = Vec::with_capacity(n as usize);
        for _ in 0..n {
            let v = f32::from_le_bytes(read4(r)?);
            if !(v.is_finite() && v >= 0.0) {
                return Err(GuidingError::Decode(format!("direct-light grid fluence {v}")));
            }
            values.push(to_bf16(v));
        }
        let mut grid = Self { min, scale, dims, values, ..Self::default() };
        grid.lit = grid.lit_box();
        Ok(grid)
    }

    /// The direct fluence at `x` (zero outside the grid).
    #[inline]
    pub fn fluence(&self, x: Vec3A) -> f32 {
        self.index(x).map_or(0.0, |i| from_bf16(self.values[i]))
    }
}

/// The range `first..end` of `j` in `0..n` outside which `c0 + j d` is certainly outside the
/// box `[lo, hi)` (empty if the line misses it), widened by one on each side.
fn parts_within(c0: Vec3A, d: Vec3A, lo: Vec3A, hi: Vec3A, n: usize) -> (usize, usize) {
    let (mut a, mut b) = (0.0f32, n as f32);
    for k in 0..3 {
        if d[k] == 0.0 {
            if !(c0[k] >= lo[k] && c0[k] < hi[k]) {
                return (0, 0);
            }
            continue;
        }
        let (t0, t1) = ((lo[k] - c0[k]) / d[k], (hi[k] - c0[k]) / d[k]);
        // `max` and `min` ignore NaN, so a ray of NaN leaves the whole range to the exact
        // checks.
        a = a.max(t0.min(t1));
        b = b.min(t0.max(t1));
    }
    if a > b {
        return (0, 0);
    }
    let first = (a.floor() - 1.0).max(0.0) as usize;
    let end = ((b.ceil() + 1.0).max(0.0) as usize).min(n);
    (first, end)
}

/// The box holding all finite record positions but the `OUTLIERS` on each side of each axis.
fn bounds(records: &[DirectRecord]) -> (Vec3A, Vec3A) {
    let mut coords: Vec<f32> = Vec::with_capacity(records.len());
    let (mut min, mut max) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for axis in 0..3 {
        coords.clear();
        coords.extend(records.iter().filter(|r| r.position.is_finite()).map(|r| r.position[axis]));
        if coords.is_empty() {
            break;
        }
        let cut = (coords.len() as f64 * OUTLIERS) as usize;
        let last = coords.len() - 1;
        min[axis] = *coords.select_nth_unstable_by(cut, f32::total_cmp).1;
        max[axis] = *coords.select_nth_unstable_by(last - cut, f32::total_cmp).1;
    }
    (min, max)
}

fn read4(r: &mut impl Read) -> Result<[u8; 4], GuidingError> {
    let mut b = [0u8; 4];
    r.read_exact(&mut b).map_err(|e| GuidingError::Decode(format!("truncated: {e}")))?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(x: f32, y: f32, z: f32, fluence: f32) -> DirectRecord {
        DirectRecord { position: Vec3A::new(x, y, z), fluence, direction: Vec3A::X }
    }

    #[test]
    fn cells_hold_their_records_mean_and_rays_read_them_in_steps() {
        // A lit slab x < 2 in a box 0..8 x 0..2 x 0..1: 64 cells along x, of 1/8 each.
        let mut records = Vec::new();
        for i in 0..64 {
            for j in 0..16 {
                let (x, y) = ((i as f32 + 0.5) / 8.0, (j as f32 + 0.5) / 8.0);
                let lit = if x < 2.0 { 4.0 } else { 0.0 };
                // Two records per point whose mean is `lit`.
                records.push(record(x, y, 0.5, lit * 0.5));
                records.push(record(x, y, 0.5, lit * 1.5));
            }
        }
        records.push(record(0.0, 0.0, 0.0, 0.0));
        records.push(record(8.0, 2.0, 1.0, 0.0));
        let grid = DirectGrid::build(&records);
        // Light only in x < 2 (16 of 64 cells), every y, the one layer of z: reads skip the
        // rest.
        assert_eq!((grid.dims.x, grid.dims.z), (64, 1));
        assert_eq!(grid.lit, (Vec3A::ZERO, Vec3A::new(16.0, 16.0, 1.0)));
        assert_eq!(grid.fluence(Vec3A::new(1.0, 1.0, 0.5)), 4.0);
        assert_eq!(grid.fluence(Vec3A::new(3.0, 1.0, 0.5)), 0.0);
        // Outside the box, and not a point at all.
        assert_eq!(grid.fluence(Vec3A::new(-0.1, 1.0, 0.5)), 0.0);
        assert_eq!(grid.fluence(Vec3A::new(8.5, 1.0, 0.5)), 0.0);
        assert_eq!(grid.fluence(Vec3A::splat(f32::NAN)), 0.0);
        // A ray's parts read what single lookups read, out of the box included.
        let (start, step) = (Vec3A::new(-1.0, 0.3, 0.5), Vec3A::new(0.7, 0.1, 0.0));
        let mut along = [f32::NAN; 16];
        grid.fluence_along(start, step, &mut along);
        for (j, v) in along.iter().enumerate() {
            assert_eq!(*v, grid.fluence(start + (j as f32 + 0.5) * step), "part {j}");
        }
        assert!(along.contains(&4.0) && along.contains(&0.0));
        // Values are kept to 8 significant bits, from below (a sampling density needs no more).
        for v in [0.3f32, 1e-20, 7.7e20, 1.0 / 3.0] {
            let q = from_bf16(to_bf16(v));
            assert!(q <= v && q > v * (1.0 - 1.0 / 128.0), "{v} -> {q}");
        }
    }

    /// Reads along a ray skip the parts outside the lit box by a range computed up front;
    /// every part must still read what a lookup at its middle reads, whatever the ray: from
    /// inside or outside, along an axis (steps of zero), backwards, grazing the box.
    #[test]
    fn reads_along_any_ray_match_single_lookups() {
        // Light in a ball of radius 0.8 about (2, 1.5, 1) in a 4 x 3 x 2 box of records.
        let mut records = Vec::new();
        let mut sampler = crate::rng::Sampler::new(3, 0, 0);
        let centre = Vec3A::new(2.0, 1.5, 1.0);
        for _ in 0..50_000 {
            let u = Vec3A::new(sampler.next_1d(), sampler.next_1d(), sampler.next_1d());
            let p = u * Vec3A::new(4.0, 3.0, 2.0);
            let lit = if (p - centre).length() < 0.8 { 1.0 + p.x } else { 0.0 };
            records.push(record(p.x, p.y, p.z, lit));
        }
        let grid = DirectGrid::build(&records);
        assert!(grid.lit.0.cmpgt(Vec3A::ZERO).all(), "the lit box is inside the grid");
        let mut lit_parts = 0;
        for i in 0..4000 {
            let mut v = || 6.0 * sampler.next_1d() - 1.5;
            let start = Vec3A::new(v(), v(), v());
            // Towards a point near the light, reached at about the middle of the ray.
            let target = centre + (Vec3A::new(v(), v(), v()) - 1.5) / 3.0;
            let mut step = (target - start) / (4.0 + 8.0 * sampler.next_1d());
            // Steps along an axis or in a plane, and tiny ones.
            match i % 5 {
                0 => step.x = 0.0,
                1 => (step.y, step.z) = (0.0, 0.0),
                2 => step *= 1e-6,
                _ => {}
            }
            let mut along = [f32::NAN; 16];
            grid.fluence_along(start, step, &mut along);
            for (j, v) in along.iter().enumerate() {
                let expected = grid.fluence(start + (j as f32 + 0.5) * step);
                assert_eq!(*v, expected, "ray {i} from {start} by {step}, part {j}");
                lit_parts += usize::from(*v > 0.0);
            }
        }
        assert!(lit_parts > 1000, "{lit_parts} parts in the light");
    }

    #[test]
    fn degenerate_records_give_an_empty_grid() {
        for records in
            [vec![], vec![record(1.0, 1.0, 1.0, 2.0)], vec![record(f32::NAN, 0.0, 0.0, 1.0)]]
        {
            let grid = DirectGrid::build(&records);
            assert_eq!(grid, DirectGrid::default());
            assert_eq!(grid.fluence(Vec3A::ONE), 0.0);
            let mut along = [1.0; 4];
            grid.fluence_along(Vec3A::ZERO, Vec3A::X, &mut along);
            assert_eq!(along, [0.0; 4]);
        }
    }
}
