//! Where a point or spot light is and which part of a ray it reaches: what equiangular
//! sampling and the halo direction strategy aim at.

use crate::math::Ray;
use glam::Vec3A;

/// A point or spot light as the samplers that aim at it see it (`Light::point_light`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// Where it is.
    pub position: Vec3A,
    /// A spot light's cone: its unit axis and the cosine of its cutoff half-angle.
    pub cone: Option<(Vec3A, f32)>,
}

impl PointLight {
    /// The part of `(0, end)` of `ray` the light reaches: inside a spot light's cone (a
    /// little wider, for rounding), all of it for a point light or a cone of 90 degrees or
    /// more; `None` if empty.
    pub(crate) fn reach(&self, ray: &Ray, end: f32) -> Option<(f32, f32)> {
        let Some((axis, cos_cutoff)) = self.cone.filter(|c| c.1 > 0.02) else {
            return Some((0.0, end));
        };
        // Inside the forward cone: ((v + t d).a)^2 >= cos^2 |v + t d|^2 with (v + t d).a >= 0.
        // In double precision, and with |d|^2 as it is: near the apex the roots lie within
        // the rounding of single precision of each other, and a |d| off 1 by one rounding moved
        // them off points well inside the cone.
        let (v, d) = ((ray.origin - self.position).as_dvec3(), ray.direction.as_dvec3());
        let axis = axis.as_dvec3();
        let (da, va) = (d.dot(axis), v.dot(axis));
        let cos2 = f64::from(cos_cutoff) * f64::from(cos_cutoff);
        let a = da * da - cos2 * d.length_squared();
        let b = 2.0 * (da * va - cos2 * d.dot(v));
        let c = va * va - cos2 * v.length_squared();
        // The forward half-space of the apex.
        let (mut lo, mut hi) = (0.0f64, f64::from(end));
        if da > 0.0 {
            lo = lo.max(-va / da);
        } else if da < 0.0 {
            hi = hi.min(-va / da);
        } else if va < 0.0 {
            return None;
        }
        // Where the quadratic is non-negative, within the forward half-space: one interval,
        // the cone being convex. A ray steeper than the cone (a > 0) crosses both nappes, and
        // its forward part lies past the larger root when it heads along the axis, before
        // the smaller one otherwise; a shallower one (a < 0) is inside between the roots.
        let disc = b * b - 4.0 * a * c;
        if a.abs() <= 1e-12 {
            // Parallel to the cone's surface: the quadratic is linear.
            if b > 0.0 {
                lo = lo.max(-c / b);
            } else if b < 0.0 {
                hi = hi.min(-c / b);
            } else if c < 0.0 {
                return None;
            }
        } else if disc < 0.0 {
            if a < 0.0 {
                return None;
            }
        } else {
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            let (r1, r2) = if q != 0.0 { (q / a, c / q) } else { (0.0, 0.0) };
            let (r1, r2) = (r1.min(r2), r1.max(r2));
            if a < 0.0 {
                (lo, hi) = (lo.max(r1), hi.min(r2));
            } else if da > 0.0 {
                lo = lo.max(r2);
            } else {
                hi = hi.min(r1);
            }
        }
        // Wider by the rounding of points along the ray in single precision.
        let length = if (hi - lo).is_finite() { (hi - lo).abs() } else { 0.0 };
        let far = if hi.is_finite() { hi.abs() } else { lo.abs() };
        let pad = 1e-4 * length.max(1e-3) + 1e-6 * (v.length() + far);
        let (lo, hi) = ((lo - pad).max(0.0) as f32, (hi + pad).min(f64::from(end)) as f32);
        (hi > lo).then_some((lo, hi))
    }
}
