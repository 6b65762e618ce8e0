//! An analytic cylinder as Mitsuba 3 defines it: the open tube (no end caps) of radius 1 around
//! the z axis of its object space, from z = 0 to z = 1, its normals pointing out. Its transform
//! may rotate and translate it, scale it uniformly across its axis and stretch it along the
//! axis; nothing else keeps it a round tube (Mitsuba warns and renders something else).

use super::PrimHit;
use crate::math::{Aabb, Frame, Ray};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};
use std::f32::consts::{PI, TAU};

/// A cylinder in world space.
#[derive(Clone, Debug)]
pub struct Cylinder {
    /// Where the centre line starts.
    origin: Vec3A,
    /// Object space's axes in world space: x and y across the tube, z along it.
    axes: Frame,
    radius: f32,
    length: f32,
}

impl Cylinder {
    /// The unit tube placed by `to_world`; `None` unless its linear part maps x and y to
    /// perpendicular vectors of one length, both perpendicular to the image of z, without a
    /// mirroring.
    pub fn new(to_world: &Transform) -> Option<Self> {
        let m = to_world.matrix().matrix3;
        let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
        let (radius, ry, length) = (x.length(), y.length(), z.length());
        if !(radius > 0.0 && ry > 0.0 && length > 0.0 && radius.is_finite() && length.is_finite()) {
            return None;
        }
        let tol = 1e-4;
        let (xu, yu, zu) = (x / radius, y / ry, z / length);
        let round = (radius - ry).abs() <= tol * radius
            && xu.dot(yu).abs() <= tol
            && xu.dot(zu).abs() <= tol
            && yu.dot(zu).abs() <= tol
            && xu.cross(yu).dot(zu) > 0.0;
        round.then(|| Self {
            origin: to_world.point(Vec3A::ZERO),
            axes: Frame { x: xu, y: yu, z: zu },
            radius,
            length,
        })
    }

    /// Radius in world space.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// Length of the centre line in world space.
    pub fn length(&self) -> f32 {
        self.length
    }

    pub(super) fn bounds(&self) -> Aabb {
        // The end circles bound the tube: along world axis i a circle of radius r around axis
        // a reaches r sqrt(1 - a_i^2) from its centre.
        let a = self.axes.z;
        let reach = self.radius * (Vec3A::ONE - a * a).max(Vec3A::ZERO).sqrt();
        let ends = [self.origin, self.origin + a * self.length];
        let mut b = Aabb::EMPTY;
        for c in ends {
            b = b.grow(c - reach).grow(c + reach);
        }
        b
    }

    pub(super) fn area(&self) -> f32 {
        TAU * self.radius * self.length
    }

    #[inline]
    pub(super) fn intersect(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        self.crossing(ray, 0.0, t_max)
    }

    /// The nearest crossing of the tube in `(t_min, t_max)`.
    #[inline]
    pub(super) fn crossing(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<PrimHit> {
        // In object space (rotated, not scaled), where t is the world's. Double precision: the
        // quadratic loses digits for rays far from the tube or nearly along it.
        let o = self.axes.to_local(ray.origin - self.origin).as_dvec3();
        let d = self.axes.to_local(ray.direction).as_dvec3();
        let a = d.x * d.x + d.y * d.y;
        if a == 0.0 {
            return None; // along the axis: never meets the wall
        }
        let r = f64::from(self.radius);
        let b = d.x * o.x + d.y * o.y;
        let c = o.x * o.x + o.y * o.y - r * r;
        // Closest approach in the cross-section, for a discriminant without cancellation.
        let (fx, fy) = (o.x - b / a * d.x, o.y - b / a * d.y);
        let disc = a * (r * r - (fx * fx + fy * fy));
        if disc < 0.0 {
            return None;
        }
        let q = -b - disc.sqrt().copysign(b);
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
        let (t0, t1) = (t0.min(t1), t0.max(t1));
        [t0, t1].into_iter().find_map(|t| {
            let z = o.z + t * d.z;
            let t = t as f32;
            (t > t_min && t < t_max && (0.0..=f64::from(self.length)).contains(&z))
                .then_some(PrimHit { t, b: Vec2::ZERO })
        })
    }

    pub(super) fn surface(&self, ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        let local = self.axes.to_local(ray.at(hit.t) - self.origin);
        let across = Vec2::new(local.x, local.y);
        let radial = across.try_normalize().unwrap_or(Vec2::X);
        let n = self.axes.x * radial.x + self.axes.y * radial.y;
        // Re-projected onto the wall so spawned rays start at the right distance.
        let p = self.origin + self.axes.z * local.z + n * self.radius;
        let mut u = radial.y.atan2(radial.x) / TAU;
        if u < 0.0 {
            u += 1.0;
        }
        (p, n, n, Vec2::new(u, local.z / self.length))
    }

    /// Around the tube, as the azimuth `u` grows.
    pub(super) fn tangent(&self, p: Vec3A) -> Vec3A {
        let local = self.axes.to_local(p - self.origin);
        self.axes.x * -local.y + self.axes.y * local.x
    }

    pub(super) fn sample_area(&self, u: Vec2) -> (Vec3A, Vec3A) {
        let (sin, cos) = (2.0 * PI * u.y).sin_cos();
        let n = self.axes.x * cos + self.axes.y * sin;
        (self.origin + self.axes.z * (u.x * self.length) + n * self.radius, n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Affine3A, Mat3A};

    fn tube(radius: f32, length: f32, axis: Vec3A, origin: Vec3A) -> Cylinder {
        let f = Frame::from_z(axis.normalize());
        let m = Affine3A::from_mat3_translation(
            Mat3A::from_cols(f.x * radius, f.y * radius, f.z * length).into(),
            origin.into(),
        );
        Cylinder::new(&Transform::new(m).unwrap()).expect("a round tube")
    }

    #[test]
    fn rays_meet_the_wall_where_it_is_and_only_there() {
        let c = tube(0.5, 2.0, Vec3A::new(0.3, 1.0, -0.2), Vec3A::new(1.0, -1.0, 0.5));
        let mut s = crate::rng::Sampler::new(3, 0, 0);
        // Where the ray crosses the wall first, by marching: the radial distance passing the
        // radius between two steps, with the step's middle within the tube's length.
        let (steps, reach) = (4000, 12.0f32);
        let h = reach / steps as f32;
        let side = |ray: &Ray, t: f32| {
            let q = c.axes.to_local(ray.at(t) - c.origin);
            ((q.x * q.x + q.y * q.y).sqrt() - 0.5, q.z)
        };
        let marched = |ray: &Ray| {
            (0..steps).find_map(|k| {
                let (t0, t1) = (k as f32 * h, (k + 1) as f32 * h);
                let ((f0, _), (f1, _)) = (side(ray, t0), side(ray, t1));
                let z = side(ray, 0.5 * (t0 + t1)).1;
                ((f0 < 0.0) != (f1 < 0.0) && (0.0..=2.0).contains(&z)).then_some(t0)
            })
        };
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..3000 {
            // From around the tube, towards points near its axis (past its ends too).
            let o = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d()) * 6.0 - Vec3A::splat(3.0);
            let o = o + c.origin + c.axes.z;
            let aim = c.origin
                + c.axes.z * (2.6 * s.next_1d() - 0.3)
                + 0.8 * crate::math::uniform_sphere(s.next_2d());
            let ray = Ray::new(o, (aim - o).normalize());
            match (c.intersect(&ray, reach), marched(&ray)) {
                (Some(hit), Some(t)) => {
                    hits += 1;
                    assert!((hit.t - t).abs() < 2.0 * h, "hit at {}, marched to {t}", hit.t);
                    let (p, n, _, uv) = c.surface(&ray, hit);
                    let local = c.axes.to_local(p - c.origin);
                    let r = (local.x * local.x + local.y * local.y).sqrt();
                    assert!((r - 0.5).abs() < 1e-4, "radius {r}");
                    assert!((ray.at(hit.t) - p).length() < 1e-3);
                    assert!(n.dot(c.axes.z).abs() < 1e-5 && (n.length() - 1.0).abs() < 1e-5);
                    assert!(n.dot(p - c.origin - c.axes.z * local.z) > 0.0, "normal points in");
                    assert!((0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y));
                }
                (None, None) => misses += 1,
                // A grazing ray's two crossings may share one step, which marching cannot see.
                (Some(hit), None) => {
                    let next = c.crossing(&ray, hit.t, reach).map_or(f32::INFINITY, |n| n.t);
                    assert!(next - hit.t < 2.0 * h, "hit at {} that marching missed", hit.t);
                }
                (None, Some(t)) => panic!("marching crossed the wall at {t}, the tube did not"),
            }
        }
        assert!(hits > 300 && misses > 300, "{hits} hits, {misses} misses");
    }

    #[test]
    fn a_ray_inside_the_tube_leaves_it_once_and_open_ends_let_rays_through() {
        let c = tube(1.0, 2.0, Vec3A::Z, Vec3A::ZERO);
        let inside = Ray::new(Vec3A::new(0.2, 0.0, 1.0), Vec3A::X);
        let h = c.intersect(&inside, f32::INFINITY).expect("leaves through the wall");
        assert!((h.t - 0.8).abs() < 1e-6);
        assert!(c.crossing(&inside, h.t, f32::INFINITY).is_none());
        // Along the axis, and out through an open end.
        assert!(c.intersect(&Ray::new(Vec3A::new(0.0, 0.0, -1.0), Vec3A::Z), 10.0).is_none());
        let slanted = Ray::new(Vec3A::new(0.0, 0.0, 1.5), Vec3A::new(0.3, 0.0, 1.0).normalize());
        assert!(c.intersect(&slanted, f32::INFINITY).is_none());
        // From outside through both walls.
        let across = Ray::new(Vec3A::new(-3.0, 0.0, 1.0), Vec3A::X);
        let first = c.intersect(&across, f32::INFINITY).unwrap();
        let second = c.crossing(&across, first.t, f32::INFINITY).unwrap();
        assert!((first.t - 2.0).abs() < 1e-6 && (second.t - 4.0).abs() < 1e-6);
    }

    #[test]
    fn area_samples_are_uniform_on_the_wall_and_bounded() {
        let c = tube(0.7, 3.0, Vec3A::new(1.0, 1.0, 0.0), Vec3A::new(0.0, 2.0, 0.0));
        assert!((c.area() - TAU * 0.7 * 3.0).abs() < 1e-4);
        let b = c.bounds();
        let mut s = crate::rng::Sampler::new(5, 0, 0);
        // Uniform by area: equal shares of samples in equal bands along and around the axis.
        let mut bins = [0u32; 16];
        let n = 64_000;
        for _ in 0..n {
            let (p, normal) = c.sample_area(s.next_2d());
            assert!(p.cmpge(b.min - 1e-4).all() && p.cmple(b.max + 1e-4).all());
            let local = c.axes.to_local(p - c.origin);
            assert!(((local.x * local.x + local.y * local.y).sqrt() - 0.7).abs() < 1e-4);
            assert!(normal.dot(c.axes.z).abs() < 1e-5);
            let along = ((local.z / 3.0) * 4.0).clamp(0.0, 3.999) as usize;
            let mut phi = local.y.atan2(local.x) / TAU;
            if phi < 0.0 {
                phi += 1.0;
            }
            bins[along * 4 + (phi * 4.0).clamp(0.0, 3.999) as usize] += 1;
        }
        let expected = n as f64 / 16.0;
        let chi2: f64 = bins.iter().map(|&k| (f64::from(k) - expected).powi(2) / expected).sum();
        // 15 degrees of freedom: p = 1e-3 at 37.7.
        assert!(chi2 < 37.7, "chi-square {chi2}: {bins:?}");
    }

    #[test]
    fn only_round_unmirrored_tubes_are_accepted() {
        let scaled = |s: [f32; 3]| {
            Transform::scale(glam::Vec3::from_array(s)).and_then(|t| Cylinder::new(&t))
        };
        assert!(scaled([2.0, 2.0, 5.0]).is_some());
        assert!(scaled([2.0, 1.0, 5.0]).is_none(), "an elliptic tube");
        assert!(scaled([-2.0, 2.0, 5.0]).is_none(), "a mirrored tube");
        let sheared = Transform::new(Affine3A::from_mat3(glam::Mat3::from_cols(
            glam::Vec3::X,
            glam::Vec3::Y,
            glam::Vec3::new(0.5, 0.0, 1.0),
        )))
        .unwrap();
        assert!(Cylinder::new(&sheared).is_none(), "a sheared tube");
    }
}
