//! An analytic rectangle: the square `[-1, 1]^2` of the `z = 0` plane under an affine
//! transform (a parallelogram in world space), the `rectangle` shape of scene files.
//!
//! Rooms are built from rectangles, and every path segment in one ends on a wall. One
//! Moller-Trumbore test with both barycentric coordinates in `[0, 1]` covers the whole
//! parallelogram, where the two-triangle mesh it replaced (`Mesh::rectangle`, which the tests
//! compare) cost two tests and two primitives in the BVH. Hits, normals and texture
//! coordinates are the mesh's.

use super::PrimHit;
use crate::math::{Aabb, Ray};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};

/// A rectangle placed by an affine transform.
#[derive(Clone, Debug)]
pub struct Parallelogram {
    /// The image of the corner `(-1, -1)` (texture coordinates `(0, 0)`).
    origin: Vec3A,
    /// The images of the edges to `(1, -1)` and to `(-1, 1)`: `u` and `v` run along them.
    edge_u: Vec3A,
    edge_v: Vec3A,
    /// Unit normal `edge_u x edge_v` (the image of +z, or its opposite under a mirroring
    /// transform, as the mesh's winding gave).
    pub(super) normal: Vec3A,
    area: f32,
}

impl Parallelogram {
    /// The square `[-1, 1]^2` at `z = 0` placed by `to_world`; `None` if the transform
    /// flattens it (zero area).
    pub fn new(to_world: &Transform) -> Option<Self> {
        let origin = to_world.point(Vec3A::new(-1.0, -1.0, 0.0));
        let edge_u = to_world.point(Vec3A::new(1.0, -1.0, 0.0)) - origin;
        let edge_v = to_world.point(Vec3A::new(-1.0, 1.0, 0.0)) - origin;
        let cross = edge_u.cross(edge_v);
        let area = cross.length();
        (area > 0.0 && area.is_finite()).then(|| Self {
            origin,
            edge_u,
            edge_v,
            normal: cross / area,
            area,
        })
    }

    pub(super) fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in [
            self.origin,
            self.origin + self.edge_u,
            self.origin + self.edge_v,
            self.origin + self.edge_u + self.edge_v,
        ] {
            b = b.grow(p);
        }
        b
    }

    #[inline]
    pub(super) fn intersect(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        let pv = ray.direction.cross(self.edge_v);
        let det = self.edge_u.dot(pv);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let tv = ray.origin - self.origin;
        let u = tv.dot(pv) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let qv = tv.cross(self.edge_u);
        let v = ray.direction.dot(qv) * inv;
        if !(0.0..=1.0).contains(&v) {
            return None;
        }
        let t = self.edge_v.dot(qv) * inv;
        (t > 0.0 && t < t_max).then_some(PrimHit { t, b: Vec2::new(u, v) })
    }

    pub(super) fn surface(&self, _ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        let p = self.origin + self.edge_u * hit.b.x + self.edge_v * hit.b.y;
        (p, self.normal, self.normal, hit.b)
    }

    pub(super) fn tangent(&self) -> Vec3A {
        self.edge_u
    }

    pub(super) fn area(&self) -> f32 {
        self.area
    }

    /// A uniformly distributed point and the normal.
    pub(super) fn sample_area(&self, u: Vec2) -> (Vec3A, Vec3A) {
        (self.origin + self.edge_u * u.x + self.edge_v * u.y, self.normal)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Geometry, Mesh};
    use super::*;
    use crate::rng::Sampler;
    use glam::Vec3;

    fn transforms() -> Vec<(&'static str, Transform)> {
        let rotate = Transform::rotate(Vec3::new(1.0, 2.0, 0.5), 40.0).unwrap();
        let shear = glam::Mat3::from_cols(
            Vec3::new(1.0, 0.3, -0.2),
            Vec3::new(0.2, 1.5, 0.4),
            Vec3::new(-0.3, 0.2, 0.7),
        );
        let shear =
            Transform::new(glam::Affine3A::from_mat3_translation(shear, Vec3::new(0.5, -1.0, 2.0)))
                .unwrap();
        let mirror = Transform::scale(Vec3::new(-2.0, 1.0, 1.0)).unwrap();
        vec![
            ("identity", Transform::IDENTITY),
            ("rotated", rotate.then(&Transform::translate(Vec3::new(0.3, -2.0, 1.0)))),
            ("sheared", shear),
            ("mirrored", mirror.then(&rotate)),
        ]
    }

    #[test]
    fn hits_normals_and_uvs_match_the_two_triangle_mesh() {
        for (what, to_world) in transforms() {
            let shape = Geometry::Parallelogram(Parallelogram::new(&to_world).unwrap());
            let mesh = Geometry::Mesh(Mesh::rectangle(&to_world));
            let centre = to_world.point(Vec3A::ZERO);
            let mut sampler = Sampler::new(11, 0, 0);
            let (mut hits, mut edge_cases) = (0, 0);
            for _ in 0..4000 {
                // Rays from around the rectangle towards points near it, half of them hitting.
                let o = centre
                    + Vec3A::new(sampler.next_1d(), sampler.next_1d(), sampler.next_1d()) * 8.0
                    - Vec3A::splat(4.0);
                let target = to_world.point(Vec3A::new(
                    2.4 * sampler.next_1d() - 1.2,
                    2.4 * sampler.next_1d() - 1.2,
                    0.0,
                ));
                let ray = Ray::new(o, (target - o).normalize());
                let a = shape.intersect(0, &ray, f32::INFINITY);
                let b = (0..2).find_map(|i| {
                    mesh.intersect(i, &ray, f32::INFINITY).map(|h| (mesh.surface(i, &ray, h), h.t))
                });
                match (a, b) {
                    (Some(h), Some(((p, ng, ns, uv), t))) => {
                        hits += 1;
                        let (pa, nga, nsa, uva) = shape.surface(0, &ray, h);
                        // Both planes are rounded images of the same corners: a grazing ray
                        // turns their difference into a larger one along the ray.
                        let grazing = ray.direction.dot(ng).abs().max(1e-3);
                        let scale = (1.0 + o.length() + t) / grazing;
                        assert!((h.t - t).abs() <= 1e-5 * scale, "{what}: t {} vs {t}", h.t);
                        assert!((pa - p).length() <= 1e-5 * scale, "{what}: {pa} vs {p}");
                        assert!((nga - ng).length() < 1e-5 && (nsa - ns).length() < 1e-5, "{what}");
                        assert!((uva - uv).length() < 1e-5 * scale, "{what}: uv {uva} vs {uv}");
                    }
                    (None, None) => {}
                    (a, b) => {
                        // Only a ray through the very border may differ.
                        let t = a.map(|h| h.t).or(b.map(|x| x.1)).unwrap();
                        let local = to_world.inv_point(ray.at(t));
                        let border = (local.x.abs() - 1.0).abs().min((local.y.abs() - 1.0).abs());
                        assert!(border < 1e-4, "{what}: hit {a:?} vs mesh {b:?} at {local}");
                        edge_cases += 1;
                    }
                }
            }
            assert!(hits > 1000 && edge_cases < 5, "{what}: {hits} hits, {edge_cases} edge cases");
            assert!((shape.area() - mesh.area()).abs() <= 1e-5 * mesh.area(), "{what}: area");
        }
    }

    #[test]
    fn area_sampling_is_uniform_over_the_rectangle() {
        // Chi-square over an 8x8 grid of the rectangle's own coordinates, recovered by the
        // inverse transform: uniform in area is uniform in (u, v) for an affine map.
        let to_world = transforms().remove(2).1;
        let shape = Parallelogram::new(&to_world).unwrap();
        let mut sampler = Sampler::new(5, 0, 0);
        let n = 64_000;
        let mut counts = vec![0.0f64; 64];
        for _ in 0..n {
            let (p, normal) = shape.sample_area(sampler.next_2d());
            assert!((normal - shape.normal).length() < 1e-6);
            let local = to_world.inv_point(p);
            assert!(
                local.z.abs() < 1e-4 && local.x.abs() <= 1.0 + 1e-4 && local.y.abs() <= 1.0 + 1e-4
            );
            let cell = |c: f32| (((c + 1.0) * 4.0) as usize).min(7);
            counts[cell(local.y) * 8 + cell(local.x)] += 1.0;
        }
        let expected = vec![n as f64 / 64.0; 64];
        zerovar_testkit::chi2_test(&counts, &expected).assert_pass(1e-3, "rectangle area sampling");
    }

    #[test]
    fn a_flattened_rectangle_is_refused() {
        let flat = Transform::scale(Vec3::new(1.0, 0.0, 1.0));
        assert!(flat.is_none_or(|t| Parallelogram::new(&t).is_none()));
    }
}
