//! An environment map: a lat-long RGB image at infinity, importance-sampled by luminance times
//! sin(theta) so bright regions (a sun in a sky) get the samples.
//!
//! Mapping as in Mitsuba 3: image u = phi / 2pi, v = theta / pi, with the local direction
//! (sin theta sin phi, cos theta, -sin theta cos phi), then rotated by `to_world`. Pixels are
//! piecewise constant, so the sampling density and the looked-up radiance agree exactly.

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
    rows: Distribution1D,
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
        let mut columns = Vec::with_capacity(height);
        let mut row_weights = Vec::with_capacity(height);
        for y in 0..height {
            let sin_theta = (PI * (y as f32 + 0.5) / height as f32).sin() as f64;
            let row = &pixels[y * width..(y + 1) * width];
            let dist =
                Distribution1D::new(row.iter().map(|p| luminance(*p).max(0.0) as f64 * sin_theta));
            row_weights.push(dist.as_ref().map_or(0.0, |d| d.total()));
            columns.push(dist);
        }
        let rows = Distribution1D::new(row_weights)?;
        Some(Self { width, height, pixels, to_world, rows, columns })
    }

    /// Radiance arriving from world direction `d` (pointing away from the scene).
    #[inline]
    pub fn eval(&self, d: Vec3A) -> Spectrum {
        let (x, y, _) = self.pixel_of(d);
        self.pixels[y * self.width + x]
    }

    fn pixel_of(&self, d: Vec3A) -> (usize, usize, f32) {
        let l = self.to_world.inv_vector(d).normalize();
        let phi = l.x.atan2(-l.z).rem_euclid(TAU);
        // From the vector, not acos(y): near the poles an f32 cosine cannot resolve theta.
        let sin_theta = (l.x * l.x + l.z * l.z).sqrt();
        let theta = sin_theta.atan2(l.y);
        let x = ((phi / TAU * self.width as f32) as usize).min(self.width - 1);
        let y = ((theta / PI * self.height as f32) as usize).min(self.height - 1);
        (x, y, sin_theta)
    }

    /// Samples a world direction; returns it with its radiance and solid-angle density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3A, Spectrum, f32)> {
        let (y, uy) = self.rows.sample(u.y);
        let (x, ux) = self.columns[y].as_ref()?.sample(u.x);
        let phi = TAU * (x as f32 + ux) / self.width as f32;
        let theta = PI * (y as f32 + uy) / self.height as f32;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let d = self.to_world.vector(Vec3A::new(st * sp, ct, -st * cp)).normalize();
        // Evaluate at the direction as stored so sample, eval and pdf agree exactly even where
        // rounding moves it across a pixel edge.
        let pdf = self.pdf(d);
        (pdf > 0.0).then(|| (d, self.eval(d), pdf))
    }

    /// Solid-angle density of sampling world direction `d`.
    pub fn pdf(&self, d: Vec3A) -> f32 {
        let (x, y, sin_theta) = self.pixel_of(d);
        self.pdf_pixel(x, y, sin_theta)
    }

    fn pdf_pixel(&self, x: usize, y: usize, sin_theta: f32) -> f32 {
        let Some(col) = &self.columns[y] else { return 0.0 };
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let p = self.rows.prob(y) * col.prob(x);
        // A pixel covers (2pi / w)(pi / h) in (phi, theta); dw = sin(theta) dtheta dphi.
        (p * (self.width * self.height) as f64 / (2.0 * (PI as f64).powi(2) * sin_theta as f64))
            as f32
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

    #[test]
    fn mapping_follows_mitsuba() {
        // u = 0.25 (phi = pi/2), v = 0.5 (theta = pi/2) is local +x.
        let w = 4;
        let pixels = (0..w * 2).map(|i| Spectrum::splat(i as f32 + 1.0)).collect();
        let m = EnvMap::new(w, 2, pixels, Transform::IDENTITY).unwrap();
        assert_eq!(m.eval(Vec3A::new(1.0, -0.01, 0.0)).x, 6.0);
        assert_eq!(m.eval(Vec3A::new(0.0, 0.5, -1.0)).x, 1.0);
    }
}
