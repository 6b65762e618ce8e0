//! Triangle meshes: from OBJ and PLY files, and the rectangle and cube of Mitsuba built as meshes.
//! Vertices are transformed to world space when the scene is built.

use super::PrimHit;
use crate::distribution::Distribution1D;
use crate::math::{Aabb, Ray, uniform_triangle};
use crate::transform::Transform;
use glam::{Vec2, Vec3A};
use std::path::Path;

/// Why a mesh could not be built.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The OBJ reader failed.
    #[error("cannot read OBJ: {0}")]
    Obj(String),
    /// The PLY reader failed.
    #[error(transparent)]
    Ply(#[from] super::ply::PlyError),
    /// The serialized-mesh reader failed.
    #[error(transparent)]
    Serialized(#[from] super::serialized::SerializedError),
    /// The file could not be read at all.
    #[error("cannot read the file: {0}")]
    Io(#[from] std::io::Error),
    /// The file holds no triangle.
    #[error("the mesh has no triangles")]
    Empty,
    /// A vertex index points past the vertex list.
    #[error("triangle {triangle} refers to vertex {index}, but there are only {count} vertices")]
    BadIndex {
        /// Triangle number.
        triangle: usize,
        /// Offending index.
        index: u32,
        /// Number of vertices.
        count: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("vertex {0} has a non-finite coordinate")]
    NonFinite(usize),
}

/// A triangle mesh in world space.
#[derive(Clone, Debug)]
pub struct Mesh {
    positions: Vec<Vec3A>,
    normals: Option<Vec<Vec3A>>,
    uvs: Option<Vec<Vec2>>,
    indices: Vec<[u32; 3]>,
    /// Per triangle, its first vertex and the two edges from it, as the intersection test
    /// reads them: one contiguous load instead of an index and three scattered vertices.
    edges: Vec<[Vec3A; 3]>,
    /// Triangle areas, for uniform area sampling.
    areas: Distribution1D,
}

impl Mesh {
    /// Builds a mesh from object-space data placed by `to_world`, checking every index.
    pub fn new(
        positions: Vec<Vec3A>,
        normals: Option<Vec<Vec3A>>,
        uvs: Option<Vec<Vec2>>,
        indices: Vec<[u32; 3]>,
        to_world: &Transform,
    ) -> Result<Self, MeshError> {
        if indices.is_empty() {
            return Err(MeshError::Empty);
        }
        let count = positions.len();
        for (triangle, tri) in indices.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= count) {
                return Err(MeshError::BadIndex { triangle, index, count });
            }
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinite(i));
        }
        let positions: Vec<Vec3A> = positions.into_iter().map(|p| to_world.point(p)).collect();
        let normals =
            normals.filter(|n| n.len() == count && n.iter().all(|v| v.is_finite())).map(|n| {
                n.into_iter().map(|v| to_world.normal(v).normalize_or_zero()).collect::<Vec<_>>()
            });
        let uvs = uvs.filter(|uv| uv.len() == count);
        let mut mesh = Self {
            positions,
            normals,
            uvs,
            indices,
            edges: Vec::new(),
            areas: Distribution1D::default(),
        };
        mesh.edges = (0..mesh.indices.len())
            .map(|i| {
                let (p0, p1, p2) = mesh.vertices(i as u32);
                [p0, p1 - p0, p2 - p0]
            })
            .collect();
        let areas = (0..mesh.indices.len()).map(|i| {
            let (p0, p1, p2) = mesh.vertices(i as u32);
            0.5 * (p1 - p0).cross(p2 - p0).length() as f64
        });
        mesh.areas = Distribution1D::new(areas).ok_or(MeshError::Empty)?;
        Ok(mesh)
    }

    /// Reads an OBJ file (all objects merged, polygons triangulated); `flip_v` turns texture
    /// coordinates `(u, v)` into `(u, 1 - v)`, as Mitsuba does by default.
    pub fn from_obj(
        path: &Path,
        to_world: &Transform,
        face_normals: bool,
        flip_v: bool,
    ) -> Result<Self, MeshError> {
        let options =
            tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
        crate::files::check(path)?;
        let (models, _) =
            tobj::load_obj(path, &options).map_err(|e| MeshError::Obj(e.to_string()))?;
        let (mut positions, mut normals, mut uvs, mut indices) = (vec![], vec![], vec![], vec![]);
        let mut all_have_normals = !face_normals;
        let mut all_have_uvs = true;
        for m in &models {
            let mesh = &m.mesh;
            let base = positions.len() as u32;
            let n = mesh.positions.len() / 3;
            positions.extend(mesh.positions.chunks_exact(3).map(|c| Vec3A::new(c[0], c[1], c[2])));
            all_have_normals &= mesh.normals.len() == 3 * n;
            all_have_uvs &= mesh.texcoords.len() == 2 * n;
            normals.extend(mesh.normals.chunks_exact(3).map(|c| Vec3A::new(c[0], c[1], c[2])));
            let v = |v: f32| if flip_v { 1.0 - v } else { v };
            uvs.extend(mesh.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], v(c[1]))));
            indices.extend(
                mesh.indices.chunks_exact(3).map(|c| [c[0] + base, c[1] + base, c[2] + base]),
            );
        }
        Self::new(
            positions,
            all_have_normals.then_some(normals),
            all_have_uvs.then_some(uvs),
            indices,
            to_world,
        )
    }

    /// Reads a PLY file (ASCII or binary; polygons fan-triangulated). Vertex normals are used
    /// unless `face_normals`, as for OBJ.
    pub fn from_ply(
        path: &Path,
        to_world: &Transform,
        face_normals: bool,
        flip_v: bool,
    ) -> Result<Self, MeshError> {
        Self::from_ply_bytes(&crate::files::read(path)?, to_world, face_normals, flip_v)
    }

    /// Reads mesh `index` of a Mitsuba `.serialized` file. Vertex normals are used unless
    /// `face_normals`, as for OBJ; texture coordinates as written.
    pub fn from_serialized(
        path: &Path,
        index: u32,
        to_world: &Transform,
        face_normals: bool,
    ) -> Result<Self, MeshError> {
        Self::from_serialized_bytes(&crate::files::read(path)?, index, to_world, face_normals)
    }

    /// `from_serialized` on the file's bytes.
    pub fn from_serialized_bytes(
        data: &[u8],
        index: u32,
        to_world: &Transform,
        face_normals: bool,
    ) -> Result<Self, MeshError> {
        let mesh = super::serialized::read(data, index)?;
        let normals = mesh.normals.filter(|_| !face_normals);
        Self::new(mesh.positions, normals, mesh.uvs, mesh.triangles, to_world)
    }

    /// `from_ply` on the file's bytes.
    pub fn from_ply_bytes(
        data: &[u8],
        to_world: &Transform,
        face_normals: bool,
        flip_v: bool,
    ) -> Result<Self, MeshError> {
        let ply = super::ply::read(data)?;
        let normals = ply.normals.filter(|_| !face_normals);
        let uvs = ply.uvs.map(|uvs| {
            uvs.into_iter().map(|t| if flip_v { Vec2::new(t.x, 1.0 - t.y) } else { t }).collect()
        });
        Self::new(ply.positions, normals, uvs, ply.triangles, to_world)
    }

    /// Mitsuba's `rectangle`: [-1, 1]^2 in the z = 0 plane, facing +z, as two triangles: the
    /// tests' reference for the analytic `Parallelogram` that scenes use.
    #[cfg(test)]
    pub(crate) fn rectangle(to_world: &Transform) -> Self {
        let p = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        let positions = p.iter().map(|&(x, y)| Vec3A::new(x, y, 0.0)).collect();
        let uvs = p.iter().map(|&(x, y)| Vec2::new(0.5 * (x + 1.0), 0.5 * (y + 1.0))).collect();
        Self::new(positions, None, Some(uvs), vec![[0, 1, 2], [0, 2, 3]], to_world)
            .expect("a rectangle under an invertible transform is a valid mesh")
    }

    /// Mitsuba's `cube`: [-1, 1]^3 with outward faces, each face with its own [0, 1]^2 uvs.
    pub fn cube(to_world: &Transform) -> Self {
        let mut positions = Vec::with_capacity(24);
        let mut uvs = Vec::with_capacity(24);
        let mut indices = Vec::with_capacity(12);
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let (n, u, v) = super::cuboid::face_axes(axis, sign);
                let base = positions.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    positions.push(n + u * a + v * b);
                    uvs.push(Vec2::new(0.5 * (a + 1.0), 0.5 * (b + 1.0)));
                }
                // Wound to face outwards whichever way u and v turn about the normal.
                if u.cross(v).dot(n) > 0.0 {
                    indices.push([base, base + 1, base + 2]);
                    indices.push([base, base + 2, base + 3]);
                } else {
                    indices.push([base, base + 2, base + 1]);
                    indices.push([base, base + 3, base + 2]);
                }
            }
        }
        Self::new(positions, None, Some(uvs), indices, to_world)
            .expect("a cube under an invertible transform is a valid mesh")
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// Total area.
    pub fn area(&self) -> f32 {
        self.areas.total() as f32
    }

    /// Bounds of all vertices.
    pub fn bounds(&self) -> Aabb {
        self.positions.iter().fold(Aabb::EMPTY, |b, &p| b.grow(p))
    }

    #[inline]
    fn vertices(&self, i: u32) -> (Vec3A, Vec3A, Vec3A) {
        let [a, b, c] = self.indices[i as usize];
        (self.positions[a as usize], self.positions[b as usize], self.positions[c as usize])
    }

    pub(super) fn triangle_bounds(&self, i: u32) -> Aabb {
        let (a, b, c) = self.vertices(i);
        Aabb::from_points(a, b).grow(c)
    }

    /// Moller-Trumbore intersection.
    #[inline]
    pub(super) fn intersect_triangle(&self, i: u32, ray: &Ray, t_max: f32) -> Option<PrimHit> {
        let [p0, e1, e2] = self.edges[i as usize];
        let pv = ray.direction.cross(e2);
        let det = e1.dot(pv);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let tv = ray.origin - p0;
        let b1 = tv.dot(pv) * inv;
        if !(0.0..=1.0).contains(&b1) {
            return None;
        }
        let qv = tv.cross(e1);
        let b2 = ray.direction.dot(qv) * inv;
        if b2 < 0.0 || b1 + b2 > 1.0 {
            return None;
        }
        let t = e2.dot(qv) * inv;
        (t > 0.0 && t < t_max).then_some(PrimHit { t, b: Vec2::new(b1, b2) })
    }

    /// Triangle `i`'s geometric normal, as `surface` computes it.
    pub(super) fn normal(&self, i: u32) -> Vec3A {
        let [_, e1, e2] = self.edges[i as usize];
        e1.cross(e2).normalize()
    }

    pub(super) fn surface(&self, i: u32, _ray: &Ray, hit: PrimHit) -> (Vec3A, Vec3A, Vec3A, Vec2) {
        let [a, b, c] = self.indices[i as usize];
        let (p0, p1, p2) = self.vertices(i);
        let (b1, b2) = (hit.b.x, hit.b.y);
        let b0 = 1.0 - b1 - b2;
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let ng = (p1 - p0).cross(p2 - p0).normalize();
        let ns = match &self.normals {
            Some(n) => {
                let s = (n[a as usize] * b0 + n[b as usize] * b1 + n[c as usize] * b2)
                    .normalize_or_zero();
                // Shading normals live on the geometric side so both agree on front and back.
                if s == Vec3A::ZERO {
                    ng
                } else if s.dot(ng) < 0.0 {
                    -s
                } else {
                    s
                }
            }
            None => ng,
        };
        let uv = match &self.uvs {
            Some(t) => t[a as usize] * b0 + t[b as usize] * b1 + t[c as usize] * b2,
            None => Vec2::new(b1, b2),
        };
        (p, ng, ns, uv)
    }

    /// Triangle `i`'s derivative of the position along `u`: from its texture coordinates, or
    /// along its first edge (Mitsuba's barycentric parameterization) without them or where
    /// they are degenerate, as Mitsuba keeps it there.
    pub(super) fn tangent(&self, i: u32) -> Vec3A {
        let (p0, p1, p2) = self.vertices(i);
        let Some(t) = &self.uvs else { return p1 - p0 };
        let [a, b, c] = self.indices[i as usize];
        let (d0, d1) = (t[b as usize] - t[a as usize], t[c as usize] - t[a as usize]);
        let det = d0.x * d1.y - d0.y * d1.x;
        if det == 0.0 { p1 - p0 } else { ((p1 - p0) * d1.y - (p2 - p0) * d0.y) / det }
    }

    /// A uniformly distributed point on the mesh and the triangle's geometric normal.
    pub(super) fn sample_area(&self, u: Vec2) -> (Vec3A, Vec3A) {
        let (i, ux) = self.areas.sample(u.x);
        let (b1, b2) = uniform_triangle(Vec2::new(ux, u.y));
        let (p0, p1, p2) = self.vertices(i as u32);
        let p = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
        (p, (p1 - p0).cross(p2 - p0).normalize())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_faces_point_outward() {
        let c = Mesh::cube(&Transform::IDENTITY);
        assert_eq!(c.triangle_count(), 12);
        assert!((c.area() - 24.0).abs() < 1e-4);
        for i in 0..12 {
            let (p0, p1, p2) = c.vertices(i);
            let n = (p1 - p0).cross(p2 - p0);
            assert!(n.dot((p0 + p1 + p2) / 3.0) > 0.0, "triangle {i} faces inward");
        }
    }

    /// The cube's texture coordinates are Mitsuba 3's (`src/shapes/cube.cpp`): each face's
    /// corners with their uv, one corner per row. A ray at each face, aimed near a corner,
    /// finds that corner's uv.
    #[test]
    fn cube_texture_coordinates_are_mitsubas() {
        let corners: [([f32; 3], [f32; 2]); 24] = [
            ([1., -1., -1.], [0., 1.]),
            ([1., -1., 1.], [1., 1.]),
            ([-1., -1., 1.], [1., 0.]),
            ([-1., -1., -1.], [0., 0.]),
            ([1., 1., -1.], [0., 1.]),
            ([-1., 1., -1.], [1., 1.]),
            ([-1., 1., 1.], [1., 0.]),
            ([1., 1., 1.], [0., 0.]),
            ([1., -1., -1.], [0., 1.]),
            ([1., 1., -1.], [1., 1.]),
            ([1., 1., 1.], [1., 0.]),
            ([1., -1., 1.], [0., 0.]),
            ([1., -1., 1.], [0., 1.]),
            ([1., 1., 1.], [1., 1.]),
            ([-1., 1., 1.], [1., 0.]),
            ([-1., -1., 1.], [0., 0.]),
            ([-1., -1., 1.], [0., 1.]),
            ([-1., 1., 1.], [1., 1.]),
            ([-1., 1., -1.], [1., 0.]),
            ([-1., -1., -1.], [0., 0.]),
            ([1., 1., -1.], [0., 1.]),
            ([1., -1., -1.], [1., 1.]),
            ([-1., -1., -1.], [1., 0.]),
            ([-1., 1., -1.], [0., 0.]),
        ];
        let c = Mesh::cube(&Transform::IDENTITY);
        for face in corners.chunks(4) {
            let centre = face.iter().map(|(p, _)| Vec3A::from(*p)).sum::<Vec3A>() / 4.0;
            for &(p, uv) in face {
                let target = centre + 0.9 * (Vec3A::from(p) - centre);
                let ray = Ray::new(target + 2.0 * centre, -centre);
                let (i, h) = (0..12)
                    .filter_map(|i| c.intersect_triangle(i, &ray, 10.0).map(|h| (i, h)))
                    .min_by(|a, b| a.1.t.total_cmp(&b.1.t))
                    .unwrap();
                let got = c.surface(i, &ray, h).3;
                let want = Vec2::splat(0.5) + 0.9 * (Vec2::from(uv) - Vec2::splat(0.5));
                assert!((got - want).length() < 1e-5, "corner {p:?}: uv {got} vs {want}");
            }
        }
    }

    #[test]
    fn rectangle_faces_plus_z_and_hits() {
        let r = Mesh::rectangle(&Transform::IDENTITY);
        let ray = Ray::new(Vec3A::new(0.5, 0.25, 2.0), -Vec3A::Z);
        let hit = (0..2).find_map(|i| r.intersect_triangle(i, &ray, 10.0).map(|h| (i, h))).unwrap();
        let (p, ng, _, uv) = r.surface(hit.0, &ray, hit.1);
        assert!((p - Vec3A::new(0.5, 0.25, 0.0)).length() < 1e-6);
        assert!((ng - Vec3A::Z).length() < 1e-6);
        assert!((uv - Vec2::new(0.75, 0.625)).length() < 1e-6);
    }

    #[test]
    fn bad_index_is_an_error() {
        let err =
            Mesh::new(vec![Vec3A::ZERO; 3], None, None, vec![[0, 1, 5]], &Transform::IDENTITY);
        assert!(matches!(err, Err(MeshError::BadIndex { index: 5, .. })));
    }
}
