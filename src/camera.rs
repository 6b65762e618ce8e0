//! The perspective pinhole camera, placed by a look-at transform (Mitsuba 3 conventions: the
//! field of view is measured along the horizontal axis by default, image x runs to the right
//! and image y downwards), with a box pixel filter: a sample lands uniformly in its pixel.

use crate::math::Ray;
use crate::transform::Transform;
use glam::{Vec2, Vec3A};

/// Which image axis the field of view spans.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FovAxis {
    /// Horizontal (Mitsuba's default).
    #[default]
    X,
    /// Vertical.
    Y,
}

/// A perspective camera.
#[derive(Clone, Debug)]
pub struct Camera {
    to_world: Transform,
    origin: Vec3A,
    tan_half: Vec2,
    resolution: [u32; 2],
}

impl Camera {
    /// A camera whose local frame is `to_world` (from `Transform::look_at`), with `fov_degrees`
    /// along `axis`.
    pub fn new(to_world: Transform, fov_degrees: f32, axis: FovAxis, resolution: [u32; 2]) -> Self {
        let aspect = resolution[0] as f32 / resolution[1] as f32;
        let t = (0.5 * fov_degrees.to_radians()).tan();
        let tan_half = match axis {
            FovAxis::X => Vec2::new(t, t / aspect),
            FovAxis::Y => Vec2::new(t * aspect, t),
        };
        let origin = to_world.point(Vec3A::ZERO);
        Self { to_world, origin, tan_half, resolution }
    }

    /// Image width and height in pixels.
    pub fn resolution(&self) -> [u32; 2] {
        self.resolution
    }

    /// The camera position.
    pub fn origin(&self) -> Vec3A {
        self.origin
    }

    /// The primary ray through film position `film` (pixels, continuous, origin top left).
    #[inline]
    pub fn ray(&self, film: Vec2) -> Ray {
        let ndc = Vec2::new(film.x / self.resolution[0] as f32, film.y / self.resolution[1] as f32);
        // Local +x is the camera's left, +y its up (look-at frame), so both axes flip.
        let local = Vec3A::new(
            (1.0 - 2.0 * ndc.x) * self.tan_half.x,
            (1.0 - 2.0 * ndc.y) * self.tan_half.y,
            1.0,
        );
        Ray::new(self.origin, self.to_world.vector(local).normalize())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn image_right_is_world_right_and_fov_is_horizontal() {
        let to_world = Transform::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y).unwrap();
        let cam = Camera::new(to_world, 90.0, FovAxis::X, [200, 100]);
        let centre = cam.ray(Vec2::new(100.0, 50.0));
        assert!((centre.direction - Vec3A::new(0.0, 0.0, -1.0)).length() < 1e-6);
        let right = cam.ray(Vec2::new(200.0, 50.0)).direction;
        assert!((right - Vec3A::new(1.0, 0.0, -1.0).normalize()).length() < 1e-5, "{right}");
        let top = cam.ray(Vec2::new(100.0, 0.0)).direction;
        assert!((top - Vec3A::new(0.0, 0.5, -1.0).normalize()).length() < 1e-5, "{top}");
    }
}
