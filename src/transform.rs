//! Affine transforms of shapes, media and lights, with their inverses precomputed.
//!
//! Scene files give a transform as a list of operations applied in document order, as Mitsuba
//! does: `[{ translate = ... }, { rotate = ... }]` first translates, then rotates.

use glam::{Affine3A, Mat3, Mat4, Vec3, Vec3A};

/// An affine map and its inverse.
#[derive(Clone, Copy, Debug)]
pub struct Transform {
    /// Object to world.
    pub(crate) m: Affine3A,
    /// World to object.
    pub(crate) inv: Affine3A,
}

impl Default for Transform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Transform {
    /// The identity.
    pub const IDENTITY: Transform = Transform { m: Affine3A::IDENTITY, inv: Affine3A::IDENTITY };

    /// Wraps an invertible affine map; `None` when it is singular or not finite.
    pub fn new(m: Affine3A) -> Option<Self> {
        let det = m.matrix3.determinant();
        if !det.is_finite() || det.abs() < 1e-12 || !m.translation.is_finite() {
            return None;
        }
        Some(Self { m, inv: m.inverse() })
    }

    /// The object-to-world map (its inverse is kept in step, so it is read-only).
    pub fn matrix(&self) -> Affine3A {
        self.m
    }

    /// A translation.
    pub fn translate(v: Vec3) -> Self {
        Self::new(Affine3A::from_translation(v)).expect("translations are invertible")
    }

    /// Rotation by `degrees` about `axis` (any non-zero length); `None` for a zero axis.
    pub fn rotate(axis: Vec3, degrees: f32) -> Option<Self> {
        let axis = axis.try_normalize()?;
        Self::new(Affine3A::from_axis_angle(axis, degrees.to_radians()))
    }

    /// Scaling by `s` per axis; `None` when a factor is zero.
    pub fn scale(s: Vec3) -> Option<Self> {
        Self::new(Affine3A::from_scale(s))
    }

    /// Mitsuba's look-at: +z towards `target`, +y close to `up`, +x = up x dir (to the left).
    pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Option<Self> {
        let dir = (target - origin).try_normalize()?;
        let left = up.cross(dir).try_normalize()?;
        let new_up = dir.cross(left);
        Self::new(Affine3A::from_mat3_translation(Mat3::from_cols(left, new_up, dir), origin))
    }

    /// A row-major 4x4 matrix; `None` unless its last row is (0, 0, 0, 1) and it is invertible.
    pub fn from_rows(rows: [[f32; 4]; 4]) -> Option<Self> {
        if rows[3] != [0.0, 0.0, 0.0, 1.0] {
            return None;
        }
        let m = Mat4::from_cols_array_2d(&rows).transpose();
        Self::new(Affine3A::from_mat4(m))
    }

    /// `self` followed by `next` (as Mitsuba composes a transform list in document order).
    pub fn then(&self, next: &Transform) -> Transform {
        Transform { m: next.m * self.m, inv: self.inv * next.inv }
    }

    /// Maps a point.
    #[inline]
    pub fn point(&self, p: Vec3A) -> Vec3A {
        self.m.transform_point3a(p)
    }

    /// Maps a vector (no translation).
    #[inline]
    pub fn vector(&self, v: Vec3A) -> Vec3A {
        self.m.transform_vector3a(v)
    }

    /// Maps a normal (by the inverse transpose), not normalised.
    #[inline]
    pub fn normal(&self, n: Vec3A) -> Vec3A {
        self.inv.matrix3.transpose() * n
    }

    /// Maps a world point into object space.
    #[inline]
    pub fn inv_point(&self, p: Vec3A) -> Vec3A {
        self.inv.transform_point3a(p)
    }

    /// Maps a world vector into object space.
    #[inline]
    pub fn inv_vector(&self, v: Vec3A) -> Vec3A {
        self.inv.transform_vector3a(v)
    }

    /// Whether the linear part is a rotation times a uniform scale (angles are preserved).
    pub fn is_similarity(&self) -> bool {
        let c = self.m.matrix3;
        let (a, b, d) = (c.x_axis.length(), c.y_axis.length(), c.z_axis.length());
        let tol = 1e-4 * a.max(b).max(d);
        (a - b).abs() < tol
            && (a - d).abs() < tol
            && c.x_axis.dot(c.y_axis).abs() < tol * a
            && c.x_axis.dot(c.z_axis).abs() < tol * a
            && c.y_axis.dot(c.z_axis).abs() < tol * a
    }

    /// The uniform scale factor of a similarity transform.
    pub fn uniform_scale(&self) -> f32 {
        self.m.matrix3.x_axis.length()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn document_order_composition() {
        // Translate then rotate 90 degrees about z: (0,0,0) -> (1,0,0) -> (0,1,0).
        let t = Transform::translate(Vec3::X).then(&Transform::rotate(Vec3::Z, 90.0).unwrap());
        let p = t.point(Vec3A::ZERO);
        assert!((p - Vec3A::Y).length() < 1e-6, "{p}");
        assert!((t.inv_point(p)).length() < 1e-6);
    }

    #[test]
    fn look_at_matches_mitsuba() {
        let t = Transform::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, 5.0), Vec3::Y).unwrap();
        assert!((t.vector(Vec3A::Z) - Vec3A::Z).length() < 1e-6);
        // +x is the left of a viewer looking down +z with +y up: that is +x in world space.
        assert!((t.vector(Vec3A::X) - Vec3A::X).length() < 1e-6);
        assert!(Transform::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y).is_none());
    }

    #[test]
    fn normals_stay_perpendicular_under_nonuniform_scale() {
        let t = Transform::scale(Vec3::new(1.0, 4.0, 1.0)).unwrap();
        let tangent = t.vector(Vec3A::new(1.0, -1.0, 0.0));
        let n = t.normal(Vec3A::new(1.0, 1.0, 0.0));
        assert!(tangent.dot(n).abs() < 1e-6);
        assert!(!t.is_similarity());
        assert!(Transform::rotate(Vec3::Y, 30.0).unwrap().is_similarity());
        assert!(Transform::scale(Vec3::new(1.0, 0.0, 1.0)).is_none());
    }
}
