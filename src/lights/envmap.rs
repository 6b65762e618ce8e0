//! An environment map: a lat-long RGB image at infinity, interpolated bilinearly as Mitsuba 3's
//! `envmap` does, and importance-sampled so bright regions (a sun in a sky) get the samples.
//!
//! Mapping as in Mitsuba 3: u = phi / 2pi, v = theta / pi, with the local direction
//! (sin theta sin phi, cos theta, -sin theta cos phi), then rotated by `to_world`. Texel
//! column i sits at u = (i + 1/2) / w and wraps around in phi; texel row j sits at
//! v = j / (h - 1), so the first and last rows lie on the poles (measured on Mitsuba 3.9.1).
//!
//! Sampling picks one of the w x (h - 1) cells between four neighbouring texels with
//! probability proportional to the mean luminance of its corners times sin(theta) at its
//! centre, then a point uniformly in (u, v) within the cell. The mean of the corners is
//! positive exactly when the bilinear radiance is positive somewhere in the cell, so every
//! direction with radiance has a positive density, and the density stays exactly that of what
//! is sampled whatever the weights are.

use crate::distribution::Distribution1D;
use crate::math::{Spectrum, luminance};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};
use std::f32::consts::{PI, TAU};

/// A lat-long environment map with its sampling tables.
#[derive(Clone, Debug)]
pub struct EnvMap {
    width: usize,
    height: usize,
    pixels: Vec<Spectrum>,
    to_world: Transform,
    /// Cell rows (h - 1 of them; 1 for a one-row image).
    rows: Distribution1D,
    /// Per cell row, its w cells.
    columns: Vec<Option<Distribution1D>>,
}

impl EnvMap {
    /// An environment map from row-major pixels (already multiplied by the scale). `None` when
    /// the image is black, since nothing could be sampled.
    pub fn new(
        width: usize,
        height: usize,
        pixels: Vec<Spectrum>,
        to_world: Transform,
    ) -> Option<Self> {
        if width == 0 || height == 0 || pixels.len() != width * height {
            return None;
        }
        let cell_rows = (height - 1).max(1);
        let mut columns = Vec::with_capacity(cell_rows);
        let mut row_weights = Vec::with_capacity(cell_rows);
        let lum = |x: usize, y: usize| luminance(pixels[y * width + x]).max(0.0) as f64;
        for j in 0..cell_rows {
            let (j0, j1) = (j, (j + 1).min(height - 1));
            let sin_theta = (PI * (j as f32 + 0.5) / cell_rows as f32).sin() as f64;
            let dist = Distribution1D::new((0..width).map(|i| {
                let (i0, i1) = (i, (i + 1) % width);
                0.25 * (lum(i0, j0) + lum(i1, j0) + lum(i0, j1) + lum(i1, j1)) * sin_theta
            }));
            row_weights.push(dist.as_ref().map_or(0.0, |d| d.total()));
            columns.push(dist);
        }
        let rows = Distribution1D::new(row_weights)?;
        Some(Self { width, height, pixels, to_world, rows, columns })
    }

    fn cell_rows(&self) -> usize {
        (self.height - 1).max(1)
    }

    /// Radiance arriving from world direction `d` (pointing away from the scene).
    #[inline]
    pub fn eval(&self, d: Vec3A) -> Spectrum {
        let (uv, _) = self.uv_of(d);
        // Texel coordinates: columns centred at (i + 1/2) / w, rows at j / (h - 1).
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * (self.height - 1) as f32;
        let xf = x.floor();
        let fx = x - xf;
        let x0 = (xf as i64).rem_euclid(self.width as i64) as usize;
        let x1 = (x0 + 1) % self.width;
        let y0 = (y.floor().max(0.0) as usize).min(self.height.saturating_sub(2));
        let y1 = (y0 + 1).min(self.height - 1);
        let fy = (y - y0 as f32).clamp(0.0, 1.0);
        let p = |x: usize, y: usize| self.pixels[y * self.width + x];
        let top = p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx;
        let bottom = p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// The direction's (u, v) in [0, 1)^2 and its sin(theta).
    fn uv_of(&self, d: Vec3A) -> (Vec2, f32) {
        let l = self.to_world.inv_vector(d).normalize();
        let phi = l.x.atan2(-l.z).rem_euclid(TAU);
        // From the vector, not acos(y): near the poles an f32 cosine cannot resolve theta.
        let sin_theta = (l.x * l.x + l.z * l.z).sqrt();
        let theta = sin_theta.atan2(l.y);
        (Vec2::new((phi / TAU).min(1.0), (theta / PI).clamp(0.0, 1.0)), sin_theta)
    }

    /// The sampling cell holding (u, v).
    fn cell_of(&self, uv: Vec2) -> (usize, usize) {
        let x = ((uv.x * self.width as f32 - 0.5).floor() as i64).rem_euclid(self.width as i64);
        let rows = self.cell_rows();
        let y = ((uv.y * rows as f32) as usize).min(rows - 1);
        (x as usize, y)
    }

    /// Samples a world direction; returns it with its radiance and solid-angle density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3A, Spectrum, f32)> {
        let (y, uy) = self.rows.sample(u.y);
        let (x, ux) = self.columns[y].as_ref()?.sample(u.x);
        let phi = TAU * ((x as f32 + 0.5 + ux) / self.width as f32).fract();
        let theta = PI * (y as f32 + uy) / self.cell_rows() as f32;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let d = self.to_world.vector(Vec3A::new(st * sp, ct, -st * cp)).normalize();
        // Evaluate at the direction as stored so sample, eval and pdf agree exactly even where
        // rounding moves it across a cell edge.
        let pdf = self.pdf(d);
        (pdf > 0.0).then(|| (d, self.eval(d), pdf))
    }

    /// Solid-angle density of sampling world direction `d`.
    pub fn pdf(&self, d: Vec3A) -> f32 {
        let (uv, sin_theta) = self.uv_of(d);
        let (x, y) = self.cell_of(uv);
        let Some(col) = &self.columns[y] else { return 0.0 };
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let p = self.rows.prob(y) * col.prob(x);
        // A cell covers (2pi / w)(pi / rows) in (phi, theta); dw = sin(theta) dtheta dphi.
        let cells = (self.width * self.cell_rows()) as f64;
        (p * cells / (2.0 * (PI as f64).powi(2) * sin_theta as f64)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;
    use glam::DVec3;
    use zerovar_testkit::SphereGrid;

    fn map() -> EnvMap {
        let (w, h) = (16, 8);
        let pixels = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let v =
                    if (x, y) == (5, 2) { 50.0 } else { 0.2 + 0.1 * ((x * 7 + y * 3) % 5) as f32 };
                Spectrum::new(v, 0.5 * v, 0.25 * v)
            })
            .collect();
        EnvMap::new(w, h, pixels, Transform::rotate(glam::Vec3::new(1.0, 2.0, 0.5), 40.0).unwrap())
            .unwrap()
    }

    #[test]
    fn pdf_integrates_to_one_and_matches_samples() {
        let m = map();
        let grid =
            SphereGrid { axis: DVec3::Z, theta_scale: f64::INFINITY, n_theta: 64, n_phi: 64 };
        let total = grid.integrate(&|d: DVec3| m.pdf(d.as_vec3a()) as f64);
        assert!((total - 1.0).abs() < 0.02, "integral {total}");
        let mut s = Sampler::new(5, 0, 0);
        let dirs: Vec<DVec3> = (0..100_000)
            .map(|_| {
                let u = s.next_2d();
                let (d, l, pdf) = m.sample(u).unwrap_or_else(|| panic!("no sample for {u}"));
                assert!((pdf - m.pdf(d)).abs() <= 1e-3 * pdf && l == m.eval(d));
                d.as_dvec3()
            })
            .collect();
        SphereGrid::uniform(DVec3::Y)
            .chi2(&dirs, &|d: DVec3| m.pdf(d.as_vec3a()) as f64)
            .assert_pass(1e-3, "envmap");
    }

    /// Integral of the radiance over the sphere by the midpoint rule in (u, v), fine enough
    /// that its error is far below the Monte Carlo error it is compared with.
    fn integral(m: &EnvMap, n: usize) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for j in 0..n {
            let theta = std::f64::consts::PI * (j as f64 + 0.5) / n as f64;
            for i in 0..2 * n {
                let phi = std::f64::consts::TAU * (i as f64 + 0.5) / (2 * n) as f64;
                let l = DVec3::new(theta.sin() * phi.sin(), theta.cos(), -theta.sin() * phi.cos());
                let d = m.to_world.vector(l.as_vec3a());
                let v = m.eval(d);
                for c in 0..3 {
                    sum[c] += v[c] as f64 * theta.sin();
                }
            }
        }
        let cell = std::f64::consts::PI * std::f64::consts::TAU / (2 * n * n) as f64;
        sum.map(|s| s * cell)
    }

    #[test]
    fn sampling_is_unbiased_and_covers_the_radiance() {
        let m = map();
        let expected = integral(&m, 1024);
        let mut s = Sampler::new(9, 0, 0);
        let mut est: [zerovar_testkit::MeanEstimate; 3] = Default::default();
        for _ in 0..200_000 {
            let (_, l, pdf) = m.sample(s.next_2d()).unwrap();
            for c in 0..3 {
                est[c].push(f64::from(l[c] / pdf));
            }
        }
        for c in 0..3 {
            // The quadrature's own error is below 1e-4 of the value; 4.5 standard errors
            // leaves a false alarm in 10^5 runs.
            est[c].assert_matches(expected[c], 4.5, "envmap radiance integral");
        }
        // Wherever there is radiance the density is positive, including near black texels.
        let mut s = Sampler::new(10, 0, 0);
        for _ in 0..100_000 {
            let d = crate::math::uniform_sphere(s.next_2d());
            if m.eval(d).max_element() > 0.0 {
                assert!(m.pdf(d) > 0.0, "no density at {d} with radiance {}", m.eval(d));
            }
        }
    }

    #[test]
    fn lookup_matches_mitsuba_bilinear() {
        // A 4x3 image of 1 + x + 10 y and the radiance Mitsuba 3.9.1's envmap returned at
        // these (u, v): columns centred in their texels and wrapping, rows on the poles.
        let (w, h) = (4, 3);
        let pixels =
            (0..w * h).map(|i| Spectrum::splat((1 + i % w + 10 * (i / w)) as f32)).collect();
        let m = EnvMap::new(w, h, pixels, Transform::IDENTITY).unwrap();
        for (u, v, mitsuba) in [
            (0.125, 1.0 / 6.0, 4.333_334),
            (0.25, 1.0 / 6.0, 4.833_334),
            (0.0, 1.0 / 6.0, 5.833_333),
            (0.99, 1.0 / 6.0, 5.953_333),
            (0.01, 1.0 / 6.0, 5.713_334),
            (0.125, 0.5, 11.0),
            (0.125, 0.25, 6.0),
            (0.125, 0.01, 1.200_006),
            (0.125, 0.99, 20.799_994),
            (0.3, 0.4, 9.7),
            (0.5, 0.5, 12.5),
        ] {
            let (theta, phi) = (PI * v, TAU * u);
            let d = Vec3A::new(theta.sin() * phi.sin(), theta.cos(), -theta.sin() * phi.cos());
            let ours = m.eval(d).x;
            assert!((ours - mitsuba).abs() < 1e-4, "({u}, {v}): {ours} vs Mitsuba's {mitsuba}");
        }
        // A single black texel next to bright ones still gets density where it is lit.
        let mut pixels = vec![Spectrum::ZERO; w * h];
        pixels[5] = Spectrum::ONE;
        let m = EnvMap::new(w, h, pixels, Transform::IDENTITY).unwrap();
        let d = Vec3A::new(0.6, 0.05, 0.7).normalize();
        assert!(m.eval(d).x > 0.0 && m.pdf(d) > 0.0);
    }
}
