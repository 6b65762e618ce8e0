//! Geometry: analytic spheres, disks, cylinders, rectangles and boxes (squares and cubes under
//! an affine map) and triangle meshes, their ray intersection, surface parameterisation and area
//! sampling for emitters.
//!
//! Everything is stored in world space once the scene is built, so a ray never needs to be
//! transformed during traversal; the acceleration structure (`accel`) refers to primitives by
//! (shape, index) and asks this module to intersect them.

mod cuboid;
mod cylinder;
mod disk;
mod mesh;
mod parallelogram;
mod ply;
mod serialized;
mod sphere;

pub use cuboid::Cuboid;
pub use cylinder::Cylinder;
pub use disk::Disk;
pub use mesh::{Mesh, MeshError};
pub use parallelogram::Parallelogram;
pub use ply::PlyError;
pub use sphere::Sphere;

use crate::math::{Aabb, Ray};
use glam::{Vec2, Vec3A};

/// Result of a primitive intersection: just enough to find the closest hit.
#[derive(Clone, Copy, Debug)]
pub struct PrimHit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Barycentric coordinates (triangles) or unused.
    pub b: Vec2,
}

/// A point on a surface with its local geometry.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    /// Ray parameter.
    pub t: f32,
    /// Position.
    pub p: Vec3A,
    /// Unit geometric normal, on the shape's front side (after `flip_normals`).
    pub ng: Vec3A,
    /// Unit shading normal, on the same side as `ng`.
    pub ns: Vec3A,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Index of the shape in the scene.
    pub shape: u32,
    /// Index of the primitive within the shape (a mesh's triangle).
    pub prim: u32,
}

/// A point sampled on a surface.
#[derive(Clone, Copy, Debug)]
pub struct AreaSample {
    /// Position.
    pub p: Vec3A,
    /// Unit front-facing normal.
    pub n: Vec3A,
    /// Density with respect to solid angle as seen from the reference point.
    pub pdf_solid_angle: f32,
}

/// The geometry of one shape.
#[derive(Clone, Debug)]
pub enum Geometry {
    /// An analytic sphere.
    Sphere(Sphere),
    /// An analytic disk (an ellipse under non-uniform scaling).
    Disk(Disk),
    /// An analytic open tube (Mitsuba's cylinder).
    Cylinder(Cylinder),
    /// An analytic box (a cube under an affine map).
    Cuboid(Cuboid),
    /// An analytic rectangle (a square under an affine map).
    Parallelogram(Parallelogram),
    /// A triangle mesh.
    Mesh(Mesh),
}

impl Geometry {
    /// Number of primitives the acceleration structure should hold for this shape.
    pub fn primitive_count(&self) -> usize {
        match self {
            Geometry::Mesh(m) => m.triangle_count(),
            _ => 1,
        }
    }

    /// Bounds of primitive `i`.
    pub fn primitive_bounds(&self, i: u32) -> Aabb {
        match self {
            Geometry::Sphere(s) => s.bounds(),
            Geometry::Disk(d) => d.bounds(),
            Geometry::Cylinder(c) => c.bounds(),
            Geometry::Cuboid(c) => c.bounds(),
            Geometry::Parallelogram(r) => r.bounds(),
            Geometry::Mesh(m) => m.triangle_bounds(i),
        }
    }

    /// Intersects primitive `i` within `(0, t_max)`.
    #[inline]
    pub fn intersect(&self, i: u32, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        match self {
            Geometry::Sphere(s) => s.intersect(ray, t_max),
            Geometry::Disk(d) => d.intersect(ray, t_max),
            Geometry::Cylinder(c) => c.intersect(ray, t_max),
            Geometry::Cuboid(c) => c.intersect(ray, t_max),
            Geometry::Parallelogram(r) => r.intersect(ray, t_max),
            Geometry::Mesh(m) => m.intersect_triangle(i, ray, t_max),
        }
    }

    /// Where a ray that met primitive `i` at `t` meets it next, within `t_max`: closed shapes
    /// (spheres, boxes) and tubes are crossed twice, flat primitives only once.
    #[inline]
    pub fn next_crossing(&self, _i: u32, ray: &Ray, t: f32, t_max: f32) -> Option<PrimHit> {
        match self {
            Geometry::Sphere(s) => s.crossing(ray, t, t_max),
            Geometry::Cuboid(c) => c.crossing(ray, t, t_max),
            Geometry::Cylinder(c) => c.crossing(ray, t, t_max),
            Geometry::Disk(_) | Geometry::Parallelogram(_) | Geometry::Mesh(_) => None,
        }
    }

    /// Completes a hit into the full local geometry (without the shape index and flip).
    pub fn surface(&self, i: u32, ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        match self {
            Geometry::Sphere(s) => s.surface(ray, hit),
            Geometry::Disk(d) => d.surface(ray, hit),
            Geometry::Cylinder(c) => c.surface(ray, hit),
            Geometry::Cuboid(c) => c.surface(ray, hit),
            Geometry::Parallelogram(r) => r.surface(ray, hit),
            Geometry::Mesh(m) => m.surface(i, ray, hit),
        }
    }

    /// The derivative of the position along `u` (its direction; zero where there is none) at
    /// point `p` on primitive `i`, whose geometric normal there is `ng` (either side), as
    /// Mitsuba 3 parameterizes each shape: the direction a brushed (anisotropic) surface's
    /// tangent follows.
    pub fn tangent(&self, i: u32, p: Vec3A, ng: Vec3A) -> Vec3A {
        match self {
            Geometry::Sphere(s) => s.tangent(p),
            Geometry::Disk(d) => d.tangent(p),
            Geometry::Cylinder(c) => c.tangent(p),
            Geometry::Cuboid(c) => c.tangent(p, ng),
            Geometry::Parallelogram(r) => r.tangent(),
            Geometry::Mesh(m) => m.tangent(i),
        }
    }

    /// The geometric normal at a hit, as [`Self::surface`] gives it, without the rest: what a
    /// shadow ray crossing a boundary needs.
    pub fn normal(&self, i: u32, ray: &Ray, hit: PrimHit) -> Vec3A {
        match self {
            Geometry::Cuboid(c) => c.normal(hit),
            Geometry::Parallelogram(r) => r.normal,
            Geometry::Mesh(m) => m.normal(i),
            _ => self.surface(i, ray, hit).1,
        }
    }

    /// Surface area.
    pub fn area(&self) -> f32 {
        match self {
            Geometry::Sphere(s) => s.area(),
            Geometry::Disk(d) => d.area(),
            Geometry::Cylinder(c) => c.area(),
            Geometry::Cuboid(c) => c.area(),
            Geometry::Parallelogram(r) => r.area(),
            Geometry::Mesh(m) => m.area(),
        }
    }

    /// Samples a point as seen from `reference`, returning its solid-angle density.
    /// Normals are the geometry's own (before any flip).
    pub fn sample(&self, reference: Vec3A, u: Vec2) -> Option<AreaSample> {
        match self {
            Geometry::Sphere(s) => s.sample(reference, u),
            Geometry::Disk(d) => area_to_solid_angle(reference, d.sample_area(u), d.area()),
            Geometry::Cylinder(c) => area_to_solid_angle(reference, c.sample_area(u), c.area()),
            Geometry::Cuboid(c) => area_to_solid_angle(reference, c.sample_area(u), c.area()),
            Geometry::Parallelogram(r) => {
                area_to_solid_angle(reference, r.sample_area(u), r.area())
            }
            Geometry::Mesh(m) => area_to_solid_angle(reference, m.sample_area(u), m.area()),
        }
    }

    /// Solid-angle density of `sample` for a point `p` with normal `n` seen from `reference`.
    pub fn pdf(&self, reference: Vec3A, p: Vec3A, n: Vec3A) -> f32 {
        match self {
            Geometry::Sphere(s) => s.pdf(reference, p, n),
            _ => area_pdf_to_solid_angle(reference, p, n, 1.0 / self.area()),
        }
    }
}

fn area_to_solid_angle(reference: Vec3A, (p, n): (Vec3A, Vec3A), area: f32) -> Option<AreaSample> {
    let pdf = area_pdf_to_solid_angle(reference, p, n, 1.0 / area);
    (pdf > 0.0 && pdf.is_finite()).then_some(AreaSample { p, n, pdf_solid_angle: pdf })
}

/// Converts an area density at `p` (normal `n`) into a solid-angle density from `reference`.
#[inline]
pub fn area_pdf_to_solid_angle(reference: Vec3A, p: Vec3A, n: Vec3A, pdf_area: f32) -> f32 {
    let d = p - reference;
    let dist2 = d.length_squared();
    let cos = (d.dot(n)).abs() / dist2.sqrt();
    if cos <= 0.0 || dist2 == 0.0 { 0.0 } else { pdf_area * dist2 / cos }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Frame;
    use crate::rng::Sampler;
    use crate::transform::Transform;
    use glam::Vec3;

    /// The nearest hit of `ray` on any primitive of `g`: its primitive, point, geometric
    /// normal and uv.
    fn hit(g: &Geometry, ray: &Ray) -> Option<(u32, Vec3A, Vec3A, Vec2)> {
        let n = g.primitive_count() as u32;
        let (i, h) = (0..n)
            .filter_map(|i| g.intersect(i, ray, f32::INFINITY).map(|h| (i, h)))
            .min_by(|a, b| a.1.t.total_cmp(&b.1.t))?;
        let (p, ng, _, uv) = g.surface(i, ray, h);
        Some((i, p, ng, uv))
    }

    /// `tangent` points along the derivative of the position in `u`, for every kind of shape
    /// under rotation, non-uniform scaling and translation: two hits a small step to either
    /// side of each hit give that derivative by finite differences, solved against their
    /// changes in uv.
    #[test]
    fn tangents_follow_u() {
        let place = Transform::rotate(Vec3::new(0.3, 1.0, 0.2), 35.0)
            .unwrap()
            .then(&Transform::translate(Vec3::new(0.2, -0.1, 0.4)));
        let scaled = |s: Vec3| Transform::scale(s).unwrap().then(&place);
        let stretch = scaled(Vec3::new(1.3, 0.8, 1.1));
        let cube = Mesh::cube(&stretch);
        let triangle = Mesh::new(
            vec![
                Vec3A::new(-1.0, -1.0, 0.0),
                Vec3A::new(1.0, -0.5, 0.2),
                Vec3A::new(0.0, 1.0, 0.0),
            ],
            None,
            None,
            vec![[0, 1, 2]],
            &stretch,
        )
        .unwrap();
        let shapes = [
            ("sphere", Geometry::Sphere(Sphere::new(scaled(Vec3::splat(0.9))))),
            ("disk", Geometry::Disk(Disk::new(stretch))),
            ("tube", Geometry::Cylinder(Cylinder::new(&scaled(Vec3::new(0.7, 0.7, 2.0))).unwrap())),
            ("cuboid", Geometry::Cuboid(Cuboid::new(stretch))),
            ("rectangle", Geometry::Parallelogram(Parallelogram::new(&stretch).unwrap())),
            ("mesh with uvs", Geometry::Mesh(cube)),
            ("mesh without uvs", Geometry::Mesh(triangle)),
        ];
        let mut s = Sampler::new(3, 1, 4);
        for (name, g) in &shapes {
            let n = g.primitive_count() as u32;
            let b = (1..n).fold(g.primitive_bounds(0), |b, i| b.union(&g.primitive_bounds(i)));
            let centre = b.center();
            let mut checked = 0;
            for _ in 0..200 {
                let dir = crate::math::uniform_sphere(s.next_2d());
                let target = centre + 0.3 * (crate::math::uniform_sphere(s.next_2d()));
                let ray = Ray::new(target + 6.0 * dir, -dir);
                let Some((i, p, ng, uv)) = hit(g, &ray) else { continue };
                let f = Frame::from_z(ray.direction);
                let step = |e: Vec3A| hit(g, &Ray::new(ray.origin + 1e-3 * e, ray.direction));
                let (Some((i1, p1, _, uv1)), Some((i2, p2, _, uv2))) = (step(f.x), step(f.y))
                else {
                    continue;
                };
                let (du1, du2) = (uv1 - uv, uv2 - uv);
                // Across a seam of the parameterization, or onto another face: no derivative.
                if i1 != i
                    || i2 != i
                    || du1.abs().max_element() > 0.1
                    || du2.abs().max_element() > 0.1
                {
                    continue;
                }
                let det = du1.x * du2.y - du2.x * du1.y;
                if det.abs() < 1e-9 {
                    continue;
                }
                let dp_du = ((p1 - p) * du2.y - (p2 - p) * du1.y) / det;
                let t = g.tangent(i, p, ng);
                let cos = t.normalize().dot(dp_du.normalize());
                assert!(cos > 0.995, "{name} at {p}: tangent {t} against dp/du {dp_du}");
                checked += 1;
            }
            assert!(checked > 50, "{name}: only {checked} hits checked");
        }
    }
}
