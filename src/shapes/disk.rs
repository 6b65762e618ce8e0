//! An analytic disk: the unit disk in the z = 0 plane of its object space, facing +z, placed by
//! any affine transform (a non-uniform scale makes it an ellipse).

use super::PrimHit;
use crate::math::{Aabb, Ray, concentric_disk};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI};

/// A disk in world space.
#[derive(Clone, Debug)]
pub struct Disk {
    to_world: Transform,
    normal: Vec3A,
    area: f32,
}

impl Disk {
    /// The unit disk placed by `to_world`.
    pub fn new(to_world: Transform) -> Self {
        let ex = to_world.vector(Vec3A::X);
        let ey = to_world.vector(Vec3A::Y);
        let normal = to_world.normal(Vec3A::Z).normalize();
        Self { to_world, normal, area: PI * ex.cross(ey).length() }
    }

    pub(super) fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            b = b.grow(self.to_world.point(Vec3A::new(x, y, 0.0)));
        }
        b
    }

    pub(super) fn area(&self) -> f32 {
        self.area
    }

    #[inline]
    pub(super) fn intersect(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        let o = self.to_world.inv_point(ray.origin);
        let d = self.to_world.inv_vector(ray.direction);
        if d.z == 0.0 {
            return None;
        }
        // Object-space t equals world-space t because the direction is mapped, not renormalised.
        let t = -o.z / d.z;
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        let (x, y) = (o.x + t * d.x, o.y + t * d.y);
        (x * x + y * y <= 1.0).then_some(PrimHit { t, b: Vec2::new(x, y) })
    }

    pub(super) fn surface(&self, _ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        let p = self.to_world.point(Vec3A::new(hit.b.x, hit.b.y, 0.0));
        let r = hit.b.length();
        let mut v = hit.b.y.atan2(hit.b.x) * (0.5 * FRAC_1_PI);
        if v < 0.0 {
            v += 1.0;
        }
        (p, self.normal, self.normal, Vec2::new(r, v))
    }

    /// Outwards along the radius (`u` is the radius); zero at the centre.
    pub(super) fn tangent(&self, p: Vec3A) -> Vec3A {
        let local = self.to_world.inv_point(p);
        let r = (local.x * local.x + local.y * local.y).sqrt();
        if r > 0.0 {
            self.to_world.vector(Vec3A::new(local.x / r, local.y / r, 0.0))
        } else {
            Vec3A::ZERO
        }
    }

    pub(super) fn sample_area(&self, u: Vec2) -> (Vec3A, Vec3A) {
        let d = concentric_disk(u);
        (self.to_world.point(Vec3A::new(d.x, d.y, 0.0)), self.normal)
    }
}
