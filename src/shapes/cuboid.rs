//! An analytic box: the cube `[-1, 1]^3` under an affine transform (a parallelepiped in world
//! space), the `cube` shape of scene files.
//!
//! Null-material boxes bound most media, and every path segment inside one ends by
//! intersecting the box, as does every shadow ray leaving it. Taking the ray into the box's
//! frame for a slab test (one affine map and six plane distances) costs a fraction of
//! traversing twelve triangles, and gives the same surface: the same hits, normals and texture
//! coordinates as the cube mesh this shape replaced (`Mesh::cube`, which the tests compare).

use super::PrimHit;
use crate::math::{Aabb, Ray};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};

/// A cube placed by an affine transform.
#[derive(Clone, Debug)]
pub struct Cuboid {
    to_world: Transform,
    /// World-space unit normal of each face, face `2 axis + (sign > 0)`.
    normals: [Vec3A; 6],
    /// Area of each face (opposite faces are equal) and their running sum, for sampling.
    face_area: [f32; 3],
    area: f32,
}

/// The outward normal of face `axis` on side `sign`, and the local directions in which its
/// texture coordinates `u` and `v` grow, as Mitsuba's cube mesh lays them out.
#[inline]
pub(super) fn face_axes(axis: usize, sign: f32) -> (Vec3A, Vec3A, Vec3A) {
    let n = Vec3A::from(glam::Vec3::AXES[axis]) * sign;
    let (u, v) = match (axis, sign > 0.0) {
        (0, true) => (Vec3A::Y, Vec3A::NEG_Z),
        (0, false) => (Vec3A::Y, Vec3A::Z),
        (1, true) => (Vec3A::NEG_X, Vec3A::NEG_Z),
        (1, false) => (Vec3A::Z, Vec3A::X),
        (_, true) => (Vec3A::Y, Vec3A::X),
        (_, false) => (Vec3A::NEG_Y, Vec3A::X),
    };
    (n, u, v)
}

impl Cuboid {
    /// The cube `[-1, 1]^3` placed by `to_world`. Normals point out of the box, or into it for
    /// a mirroring transform (negative determinant), as the triangles of a mirrored mesh do.
    pub fn new(to_world: Transform) -> Self {
        let orientation = to_world.matrix().matrix3.determinant().signum();
        let normals = std::array::from_fn(|face| {
            let (n, _, _) = face_axes(face / 2, if face % 2 == 1 { 1.0 } else { -1.0 });
            to_world.normal(n).normalize() * orientation
        });
        let face_area = std::array::from_fn(|axis| {
            let (_, u, v) = face_axes(axis, 1.0);
            4.0 * to_world.vector(u).cross(to_world.vector(v)).length()
        });
        let area = 2.0 * face_area.iter().sum::<f32>();
        Self { to_world, normals, face_area, area }
    }

    pub(super) fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for i in 0..8 {
            let corner = Vec3A::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            );
            b = b.grow(self.to_world.point(corner));
        }
        b
    }

    pub(super) fn area(&self) -> f32 {
        self.area
    }

    /// The nearest crossing of the box's surface in `(0, t_max)`; the face hit travels in
    /// `PrimHit::b.x`.
    #[inline]
    pub(super) fn intersect(&self, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        self.crossing(ray, 0.0, t_max)
    }

    /// The nearest crossing in `(t_min, t_max)`.
    #[inline]
    pub(super) fn crossing(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<PrimHit> {
        // The map is affine, so the local ray keeps the world ray's parameter.
        let o = self.to_world.inv_point(ray.origin);
        let inv_d = self.to_world.inv_vector(ray.direction).recip();
        let t0 = (Vec3A::NEG_ONE - o) * inv_d;
        let t1 = (Vec3A::ONE - o) * inv_d;
        let (near, far) = (t0.min(t1), t0.max(t1));
        let (t_near, t_far) = (near.max_element(), far.min_element());
        // NaN (a ray parallel to a face and lying in its plane) fails every test: a miss.
        let (t, slabs, far_side) =
            if t_near > t_min { (t_near, near, false) } else { (t_far, far, true) };
        if t_near > t_far || t_near.is_nan() || t <= t_min || t >= t_max || t.is_nan() {
            return None;
        }
        let axis = if slabs.x == t {
            0
        } else if slabs.y == t {
            1
        } else {
            2
        };
        // Entering through the face the local direction points away from; leaving through
        // the one it points towards.
        let d = inv_d[axis];
        let positive = (d < 0.0) != far_side;
        let face = 2 * axis + usize::from(positive);
        Some(PrimHit { t, b: Vec2::new(face as f32, 0.0) })
    }

    /// The normal of the face hit.
    pub(super) fn normal(&self, hit: PrimHit) -> Vec3A {
        self.normals[hit.b.x as usize]
    }

    pub(super) fn surface(&self, ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        let face = hit.b.x as usize;
        let (axis, sign) = (face / 2, if face % 2 == 1 { 1.0 } else { -1.0 });
        // Put the point exactly on the face, so rays spawned from it start on the surface.
        let mut q = self.to_world.inv_point(ray.at(hit.t)).clamp(Vec3A::NEG_ONE, Vec3A::ONE);
        q[axis] = sign;
        let (_, u, v) = face_axes(axis, sign);
        let uv = Vec2::new(0.5 * (q.dot(u) + 1.0), 0.5 * (q.dot(v) + 1.0));
        let n = self.normals[face];
        (self.to_world.point(q), n, n, uv)
    }

    /// Along the `u` axis of the face hit at `p` with geometric normal `ng` (either side):
    /// the normal names the face's axis even at an edge, where the point alone could name
    /// either face, and the point names its side.
    pub(super) fn tangent(&self, p: Vec3A, ng: Vec3A) -> Vec3A {
        let along = |face: usize| self.normals[face].dot(ng).abs();
        let axis = (0..3).max_by(|&a, &b| along(2 * a).total_cmp(&along(2 * b))).unwrap_or(0);
        let q = self.to_world.inv_point(p);
        let (_, u, _) = face_axes(axis, if q[axis] > 0.0 { 1.0 } else { -1.0 });
        self.to_world.vector(u)
    }

    /// A point uniformly distributed over the surface, with its normal.
    pub(super) fn sample_area(&self, u: Vec2) -> (Vec3A, Vec3A) {
        // Pick a pair of opposite faces by area, then a side, reusing `u.x` rescaled.
        let half = 0.5 * self.area;
        let mut x = u.x * half;
        let mut axis = 2;
        for (a, &area) in self.face_area.iter().enumerate() {
            if x < area || a == 2 {
                axis = a;
                break;
            }
            x -= area;
        }
        let s = (x / self.face_area[axis]).clamp(0.0, 1.0);
        let (sign, s) = if s < 0.5 { (-1.0, 2.0 * s) } else { (1.0, 2.0 * s - 1.0) };
        let (n, fu, fv) = face_axes(axis, sign);
        let q = n + fu * (2.0 * s - 1.0) + fv * (2.0 * u.y - 1.0);
        let face = 2 * axis + usize::from(sign > 0.0);
        (self.to_world.point(q), self.normals[face])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Geometry, Mesh};
    use glam::{Affine3A, Mat3, Vec3};
    use rand_pcg::Pcg32;
    use rand_pcg::rand_core::Rng;

    fn u01(rng: &mut Pcg32) -> f32 {
        (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    fn vec3(rng: &mut Pcg32) -> Vec3A {
        Vec3A::new(u01(rng), u01(rng), u01(rng))
    }

    fn transforms() -> Vec<Transform> {
        let mut v = vec![Transform::IDENTITY];
        v.push(
            Transform::scale(Vec3::new(2.01, 1.41, 2.01))
                .unwrap()
                .then(&Transform::translate(Vec3::new(0.0, 1.2, 0.0))),
        );
        // Sheared and rotated, and a mirror.
        let shear = Mat3::from_cols(
            Vec3::new(1.0, 0.3, -0.2),
            Vec3::new(0.1, 0.7, 0.4),
            Vec3::new(-0.3, 0.2, 1.5),
        );
        v.push(
            Transform::new(Affine3A::from_mat3_translation(shear, Vec3::new(0.5, -1.0, 2.0)))
                .unwrap(),
        );
        v.push(Transform::scale(Vec3::new(-1.0, 2.0, 0.5)).unwrap());
        v
    }

    fn mesh_hit(mesh: &Geometry, ray: &Ray) -> Option<(f32, Vec3A, Vec2)> {
        let mut best: Option<(u32, PrimHit)> = None;
        for i in 0..12 {
            if let Some(h) = mesh.intersect(i, ray, best.map_or(f32::INFINITY, |b| b.1.t)) {
                best = Some((i, h));
            }
        }
        best.map(|(i, h)| {
            let (_, ng, _, uv) = mesh.surface(i, ray, h);
            (h.t, ng, uv)
        })
    }

    #[test]
    fn hits_normals_and_texture_coordinates_match_the_cube_mesh() {
        let mut rng = Pcg32::new(3, 5);
        for to_world in transforms() {
            let cube = Geometry::Cuboid(Cuboid::new(to_world));
            let mesh = Geometry::Mesh(Mesh::cube(&to_world));
            assert!((cube.area() - mesh.area()).abs() < 1e-4 * mesh.area());
            let (mut hits, mut checked) = (0, 0);
            for _ in 0..4000 {
                // Origins inside and around the box, in its frame.
                let o = vec3(&mut rng) * 6.0 - 3.0;
                let d = vec3(&mut rng) * 2.0 - 1.0;
                let ray = Ray::new(to_world.point(o * 0.5), d.normalize());
                let got = cube.intersect(0, &ray, f32::INFINITY).map(|h| {
                    let (p, ng, _, uv) = cube.surface(0, &ray, h);
                    assert!((p - ray.at(h.t)).length() < 1e-4 * (1.0 + h.t), "point");
                    (h.t, ng, uv)
                });
                let want = mesh_hit(&mesh, &ray);
                match (got, want) {
                    (Some(g), Some(w)) => {
                        hits += 1;
                        assert!((g.0 - w.0).abs() <= 1e-4 * w.0.max(1.0), "t {} vs {}", g.0, w.0);
                        // Near an edge the two may pick different faces at the same point.
                        let local = to_world.inv_point(ray.at(w.0)).abs();
                        let mut sides = [local.x, local.y, local.z];
                        sides.sort_by(f32::total_cmp);
                        if sides[1] < 0.999 {
                            checked += 1;
                            assert!(g.1.dot(w.1) > 0.9999, "normal {} vs {}", g.1, w.1);
                            assert!((g.2 - w.2).length() < 1e-4, "uv {} vs {}", g.2, w.2);
                        }
                    }
                    (None, None) => {}
                    (g, w) => {
                        // Only grazing the surface may the two disagree.
                        let t = g.or(w).unwrap().0;
                        let local = to_world.inv_point(ray.at(t)).abs();
                        let mut sides = [local.x, local.y, local.z];
                        sides.sort_by(f32::total_cmp);
                        assert!(sides[1] > 0.999, "hit {g:?} against {w:?}");
                    }
                }
            }
            assert!(hits > 1000 && checked > 1000, "{hits} hits, {checked} checked");
        }
    }

    #[test]
    fn a_ray_from_inside_leaves_through_the_face_ahead() {
        let c = Cuboid::new(Transform::IDENTITY);
        let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
        let h = c.intersect(&ray, f32::INFINITY).unwrap();
        assert_eq!(h.t, 1.0);
        let (p, n, _, _) = c.surface(&ray, h);
        assert_eq!((p, n), (Vec3A::X, Vec3A::X));
        assert!(c.intersect(&ray, 0.5).is_none());
        // Parallel to a face and in its plane: a miss, not a NaN.
        let graze = Ray::new(Vec3A::new(-2.0, 1.0, 0.0), Vec3A::X);
        assert!(c.intersect(&graze, f32::INFINITY).is_none_or(|h| h.t.is_finite()));
    }

    #[test]
    fn area_sampling_is_uniform_over_the_surface() {
        // Chi-square over 6 faces x 4 x 4 cells, expected counts from the cells' areas.
        let to_world = &transforms()[2];
        let c = Cuboid::new(*to_world);
        let n = 96_000;
        let mut counts = vec![0u32; 96];
        let mut rng = Pcg32::new(9, 1);
        for _ in 0..n {
            let (p, normal) = c.sample_area(Vec2::new(u01(&mut rng), u01(&mut rng)));
            let q = to_world.inv_point(p);
            let axis = (0..3).max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs())).unwrap();
            assert!((q[axis].abs() - 1.0).abs() < 1e-5, "off the surface: {q}");
            let sign = q[axis].signum();
            let face = 2 * axis + usize::from(sign > 0.0);
            assert!(normal.dot(c.normals[face]) > 0.99999);
            let (_, u, v) = face_axes(axis, sign);
            let cell = |x: f32| (((x + 1.0) * 2.0) as usize).min(3);
            counts[face * 16 + cell(q.dot(u)) * 4 + cell(q.dot(v))] += 1;
        }
        let mut chi2 = 0.0;
        for (i, &k) in counts.iter().enumerate() {
            let expected = f64::from(c.face_area[i / 32]) / 16.0 / f64::from(c.area) * n as f64;
            chi2 += (f64::from(k) - expected).powi(2) / expected;
        }
        // 95 degrees of freedom: the 1e-3 upper quantile is 146.
        assert!(chi2 < 146.0, "chi-square {chi2}");
    }
}
