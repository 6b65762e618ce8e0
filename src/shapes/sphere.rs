//! An analytic sphere. Only similarity transforms are allowed (as in Mitsuba), so it stays a
//! sphere in world space and can be sampled by the solid angle it subtends.

use super::{AreaSample, PrimHit, area_pdf_to_solid_angle};
use crate::math::{Aabb, Frame, Ray, uniform_cone, uniform_sphere};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI, TAU};

/// A sphere in world space; `to_world` keeps the object frame for texture coordinates.
#[derive(Clone, Debug)]
pub struct Sphere {
    center: Vec3A,
    radius: f32,
    to_world: Transform,
}

impl Sphere {
    /// A unit sphere placed by a similarity transform `to_world` (checked by the caller).
    pub fn new(to_world: Transform) -> Self {
        Self { center: to_world.point(Vec3A::ZERO), radius: to_world.uniform_scale(), to_world }
    }

    /// Centre in world space.
    pub fn center(&self) -> Vec3A {
        self.center
    }

    /// Radius in world space.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    pub(super) fn bounds(&self) -> Aabb {
        Aabb {
            min: self.center - Vec3A::splat(self.radius),
            max: self.center + Vec3A::splat(self.radius),
        }
    }

    pub(super) fn area(&self) -> f32 {
        4.0 * PI * self.radius * self.radius
    }

    #[inline]
    pub(super) fn intersect(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        self.crossing(ray, 0.0, t_max)
    }

    /// The nearest crossing in `(t_min, t_max)`.
    #[inline]
    pub(super) fn crossing(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<PrimHit> {
        let oc = ray.origin - self.center;
        let b = oc.dot(ray.direction);
        // The discriminant from the closest-approach vector loses no precision for rays that
        // start far away (Hearn and Baker's formulation, as in Ray Tracing Gems ch. 7).
        let f = oc - b * ray.direction;
        let disc = self.radius * self.radius - f.length_squared();
        if disc < 0.0 {
            return None;
        }
        let c = oc.length_squared() - self.radius * self.radius;
        let q = -b - disc.sqrt().copysign(b);
        let (mut t0, mut t1) = (c / q, q);
        if q == 0.0 {
            (t0, t1) = (0.0, 0.0);
        }
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        let t = if t0 > t_min { t0 } else { t1 };
        (t > t_min && t < t_max).then_some(PrimHit { t, b: Vec2::ZERO })
    }

    pub(super) fn surface(&self, ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        let n = (ray.at(hit.t) - self.center).normalize();
        // Re-project onto the surface so spawned rays start at the right distance.
        let p = self.center + n * self.radius;
        let local = self.to_world.inv_vector(n).normalize();
        let mut u = local.y.atan2(local.x) * (0.5 * FRAC_1_PI);
        if u < 0.0 {
            u += 1.0;
        }
        let v = local.z.clamp(-1.0, 1.0).acos() * FRAC_1_PI;
        (p, n, n, Vec2::new(u, v))
    }

    /// Along the parallel, as the azimuth `u` grows; zero at the poles.
    pub(super) fn tangent(&self, p: Vec3A) -> Vec3A {
        let local = self.to_world.inv_vector(p - self.center);
        self.to_world.vector(Vec3A::new(-local.y, local.x, 0.0))
    }

    pub(super) fn sample(&self, reference: Vec3A, u: Vec2) -> Option<AreaSample> {
        let to_center = self.center - reference;
        let d2 = to_center.length_squared();
        let r2 = self.radius * self.radius;
        if d2 <= r2 * 1.0001 {
            // Inside (or on) the sphere: sample the whole surface by area.
            let n = uniform_sphere(u);
            let p = self.center + n * self.radius;
            let pdf = area_pdf_to_solid_angle(reference, p, n, 1.0 / self.area());
            return (pdf > 0.0 && pdf.is_finite()).then_some(AreaSample {
                p,
                n,
                pdf_solid_angle: pdf,
            });
        }
        // Outside: sample the cone of directions the sphere subtends.
        let sin2_max = r2 / d2;
        let one_minus_cos_max = one_minus_sqrt_one_minus(sin2_max);
        let frame = Frame::from_z(to_center / d2.sqrt());
        let dir = frame.to_world(uniform_cone(u, one_minus_cos_max));
        let ray = Ray::new(reference, dir);
        // Numerically the cone edge can graze past the sphere; snap to the closest point.
        let t = match self.intersect(&ray, f32::INFINITY) {
            Some(h) => h.t,
            None => to_center.dot(dir),
        };
        let n = (ray.at(t) - self.center).normalize();
        let p = self.center + n * self.radius;
        Some(AreaSample { p, n, pdf_solid_angle: 1.0 / (TAU * one_minus_cos_max) })
    }

    pub(super) fn pdf(&self, reference: Vec3A, p: Vec3A, n: Vec3A) -> f32 {
        let d2 = (self.center - reference).length_squared();
        let r2 = self.radius * self.radius;
        if d2 <= r2 * 1.0001 {
            return area_pdf_to_solid_angle(reference, p, n, 1.0 / self.area());
        }
        1.0 / (TAU * one_minus_sqrt_one_minus(r2 / d2))
    }
}

/// 1 - sqrt(1 - x) without cancellation for small x.
#[inline]
fn one_minus_sqrt_one_minus(x: f32) -> f32 {
    x / (1.0 + (1.0 - x).max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn far_ray_hits_precisely() {
        let s = Sphere::new(Transform::translate(Vec3::new(0.0, 0.0, 1e4)));
        let r = Ray::new(Vec3A::ZERO, Vec3A::Z);
        let h = s.intersect(&r, f32::INFINITY).unwrap();
        assert!((h.t - (1e4 - 1.0)).abs() < 1e-2, "{}", h.t);
        let inside = Ray::new(Vec3A::new(0.0, 0.0, 1e4), Vec3A::X);
        assert!((s.intersect(&inside, f32::INFINITY).unwrap().t - 1.0).abs() < 1e-3);
    }

    #[test]
    fn cone_pdf_integrates_to_one() {
        // The solid angle of the cone times its uniform density is one.
        let s = Sphere::new(Transform::scale(Vec3::splat(0.5)).unwrap());
        let reference = Vec3A::new(0.0, 0.0, -3.0);
        let sample = s.sample(reference, Vec2::new(0.3, 0.7)).unwrap();
        let cos_max = (1.0 - 0.25 / 9.0f32).sqrt();
        assert!((sample.pdf_solid_angle * TAU * (1.0 - cos_max) - 1.0).abs() < 1e-3);
        assert!(((sample.p - s.center).length() - 0.5).abs() < 1e-5);
        assert!((sample.p - reference).dot(sample.n) < 0.0, "sampled the visible side");
    }
}
