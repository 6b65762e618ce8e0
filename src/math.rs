//! Small geometric and sampling building blocks shared by every other module: rays, bounding
//! boxes, orthonormal frames, the warps that turn uniform numbers into directions and points,
//! and the RGB `Spectrum` type.
//!
//! zerovar renders in linear RGB (as Mitsuba's `*_rgb` variants do), so a spectrum is a
//! `Vec3A`: three channels in one SIMD register.

use glam::{Vec2, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI, TAU};

/// Linear RGB radiance, reflectance or coefficients, one SIMD register.
pub type Spectrum = Vec3A;

/// 1 / (4 pi): the density of the uniform distribution on the sphere.
pub const INV_FOUR_PI: f32 = 0.25 * FRAC_1_PI;

/// Offset applied along a ray's direction when it leaves a surface, relative to the scene's
/// size, so the next intersection does not find the same surface again.
pub const RAY_EPSILON: f32 = 1e-4;

/// The denominator offset of relative errors, `(I - R)^2 / (R^2 + eps)`: the relMSE of image
/// comparisons, and the weights the renderer derives from estimated relative errors.
pub const RELATIVE_EPSILON: f64 = 1e-3;

/// A ray `origin + t * direction` with `direction` of unit length.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3A,
    /// Unit direction of travel.
    pub direction: Vec3A,
}

impl Ray {
    /// A ray from `origin` along the unit vector `direction`.
    #[inline]
    pub fn new(origin: Vec3A, direction: Vec3A) -> Self {
        Self { origin, direction }
    }

    /// The point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3A {
        self.origin + self.direction * t
    }
}

/// An axis-aligned bounding box; the empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3A,
    /// Upper corner.
    pub max: Vec3A,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The box containing nothing; the identity of `union`.
    pub const EMPTY: Aabb =
        Aabb { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };

    /// The box spanned by two corners in any order.
    pub fn from_points(a: Vec3A, b: Vec3A) -> Self {
        Self { min: a.min(b), max: a.max(b) }
    }

    /// Whether the box contains no point.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// The smallest box containing both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    /// The smallest box containing this one and `p`.
    pub fn grow(&self, p: Vec3A) -> Aabb {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }

    /// Centre point.
    pub fn center(&self) -> Vec3A {
        0.5 * (self.min + self.max)
    }

    /// Edge lengths.
    pub fn extent(&self) -> Vec3A {
        (self.max - self.min).max(Vec3A::ZERO)
    }

    /// Surface area (0 for the empty box).
    pub fn surface_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Whether `p` lies inside or on the boundary.
    pub fn contains(&self, p: Vec3A) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The parametric range `[t0, t1]` of `ray` inside the box clipped to `[t_min, t_max]`, or
    /// `None`. `inv_dir` is `1 / ray.direction` (infinite components are fine).
    #[inline]
    pub fn intersect(
        &self,
        ray: &Ray,
        inv_dir: Vec3A,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32)> {
        let t0 = (self.min - ray.origin) * inv_dir;
        let t1 = (self.max - ray.origin) * inv_dir;
        // 0 * inf (a ray in a slab's plane) is NaN; it must not constrain the range, so it
        // reads as -inf for the near bound and +inf for the far one.
        let (t0n, t1n) = (t0.is_nan_mask(), t1.is_nan_mask());
        let lo = Vec3A::NEG_INFINITY;
        let hi = Vec3A::INFINITY;
        let near_v = Vec3A::select(t0n, lo, t0).min(Vec3A::select(t1n, lo, t1));
        let far_v = Vec3A::select(t0n, hi, t0).max(Vec3A::select(t1n, hi, t1));
        let near = near_v.max_element().max(t_min);
        let far = far_v.min_element().min(t_max);
        (near <= far).then_some((near, far))
    }
}

/// Whether `x` is a positive number (false for zero, negatives and NaN): the guard before
/// dividing by a density.
#[inline]
pub fn positive(x: f32) -> bool {
    x > 0.0
}

/// A right-handed orthonormal basis whose `z` axis is a given unit vector.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// First tangent.
    pub x: Vec3A,
    /// Second tangent.
    pub y: Vec3A,
    /// The axis the frame was built around.
    pub z: Vec3A,
}

impl Frame {
    /// Builds a frame around the unit vector `n` (Duff et al. 2017, branchless).
    #[inline]
    pub fn from_z(n: Vec3A) -> Self {
        let sign = 1f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let x = Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let y = Vec3A::new(b, sign + n.y * n.y * a, -n.y);
        Self { x, y, z: n }
    }

    /// World vector to local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3A) -> Vec3A {
        Vec3A::new(v.dot(self.x), v.dot(self.y), v.dot(self.z))
    }

    /// Local coordinates to a world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3A) -> Vec3A {
        self.x * v.x + self.y * v.y + self.z * v.z
    }
}

/// Uniformly distributed direction on the unit sphere.
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3A {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (TAU * u.y).sin_cos();
    Vec3A::new(r * c, r * s, z)
}

/// Cosine-weighted direction on the hemisphere about +z (Malley's method on a concentric disk).
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3A {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3A::new(d.x, d.y, z)
}

/// Uniform point on the unit disk, by Shirley's low-distortion concentric map.
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, 0.25 * PI * (o.y / o.x))
    } else {
        (o.y, 0.5 * PI - 0.25 * PI * (o.x / o.y))
    };
    let (s, c) = theta.sin_cos();
    Vec2::new(r * c, r * s)
}

/// Uniform direction in the cone of half-angle `acos(cos_max)` about +z.
///
/// The cosine is drawn as `1 - u (1 - cos_max)` with `1 - cos_max` passed separately, so very
/// narrow cones (the sun is 0.27 degrees wide) keep their precision.
#[inline]
pub fn uniform_cone(u: Vec2, one_minus_cos_max: f32) -> Vec3A {
    let b = u.x * one_minus_cos_max; // 1 - cos(theta)
    let cos_t = 1.0 - b;
    let sin_t = (b * (2.0 - b)).max(0.0).sqrt();
    let (s, c) = (TAU * u.y).sin_cos();
    Vec3A::new(sin_t * c, sin_t * s, cos_t)
}

/// Uniform barycentric coordinates on a triangle (square-root parameterisation).
#[inline]
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

/// Power heuristic with exponent 2 for two strategies with one sample each.
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    if a.is_infinite() {
        return 1.0;
    }
    if a + b == 0.0 { 0.0 } else { a / (a + b) }
}

/// Luminance of linear sRGB (Rec. 709 primaries).
#[inline]
pub fn luminance(c: Spectrum) -> f32 {
    c.dot(Vec3A::new(0.212_671, 0.715_160, 0.072_169))
}

/// Mean of the three channels.
#[inline]
pub fn channel_mean(c: Spectrum) -> f32 {
    (c.x + c.y + c.z) * (1.0 / 3.0)
}

/// Whether every channel is finite.
#[inline]
pub fn is_finite(c: Spectrum) -> bool {
    c.is_finite()
}

/// Whether the three channels are equal (a grey spectrum).
#[inline]
pub fn is_grey(c: Spectrum) -> bool {
    c.x == c.y && c.y == c.z
}

/// Reflects `v` about the unit normal `n` (both pointing away from the surface).
#[inline]
pub fn reflect(v: Vec3A, n: Vec3A) -> Vec3A {
    2.0 * v.dot(n) * n - v
}

/// Spherical angles of a unit vector about +z: (cos theta, phi in [0, 2 pi)).
#[inline]
pub fn spherical_angles(d: Vec3A) -> (f32, f32) {
    let phi = d.y.atan2(d.x);
    (d.z.clamp(-1.0, 1.0), if phi < 0.0 { phi + TAU } else { phi })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal_for_all_poles() {
        for n in [Vec3A::Z, -Vec3A::Z, Vec3A::X, Vec3A::new(0.0, -1e-8, -1.0).normalize()] {
            let f = Frame::from_z(n);
            assert!((f.x.length() - 1.0).abs() < 1e-5 && (f.y.length() - 1.0).abs() < 1e-5);
            assert!(f.x.dot(f.y).abs() < 1e-5 && f.x.dot(n).abs() < 1e-5);
            assert!((f.x.cross(f.y) - n).length() < 1e-5, "right-handed for {n}");
            let v = Vec3A::new(0.3, -0.2, 0.9);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn aabb_grazing_ray_is_finite() {
        let b = Aabb::from_points(Vec3A::ZERO, Vec3A::ONE);
        let r = Ray::new(Vec3A::new(-1.0, 0.0, 0.5), Vec3A::X);
        let hit = b.intersect(&r, r.direction.recip(), 0.0, f32::INFINITY);
        assert_eq!(hit, Some((1.0, 2.0)));
        // Along the far face, and backwards (a -0 direction component) on the near one.
        let r = Ray::new(Vec3A::new(-1.0, 1.0, 0.5), Vec3A::X);
        assert_eq!(b.intersect(&r, r.direction.recip(), 0.0, f32::INFINITY), Some((1.0, 2.0)));
        let r = Ray::new(Vec3A::new(2.0, 0.0, 0.5), Vec3A::new(-1.0, -0.0, 0.0));
        assert_eq!(b.intersect(&r, r.direction.recip(), 0.0, f32::INFINITY), Some((1.0, 2.0)));
        let r = Ray::new(Vec3A::new(-1.0, -0.5, 0.5), Vec3A::X);
        assert_eq!(b.intersect(&r, r.direction.recip(), 0.0, f32::INFINITY), None);
    }

    #[test]
    fn narrow_cone_keeps_precision() {
        let one_minus = 1e-9;
        let d = uniform_cone(Vec2::new(0.5, 0.25), one_minus);
        assert!(d.is_finite() && d.z <= 1.0 && d.y > 0.0);
    }
}
