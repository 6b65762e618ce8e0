//! The perspective camera, a pinhole or Mitsuba's thin lens, placed by a look-at transform
//! (Mitsuba 3 conventions: the field of view is measured along the horizontal axis by default,
//! image x runs to the right and image y downwards), with a pixel filter that spreads each
//! pixel's samples over the film (a box by default: a sample lands uniformly in its pixel; see
//! [`crate::filter`]). A thin lens starts each ray at a point of its aperture, aimed at the
//! point of the focal plane the pinhole's ray would reach, so only that plane is sharp.
//! Rays start on the near clipping plane and reach the far one, as Mitsuba's do: for a
//! camera inside a medium, the near plane decides how much of it lies before the first ray.

use crate::filter::{FilterTable, PixelFilter};
use crate::math::{Ray, concentric_disk};
use crate::rng::Sampler;
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
    /// Distances of the clipping planes from the eye, along the view axis.
    near: f32,
    far: f32,
    /// How a pixel's samples spread over the film.
    filter: FilterTable,
    /// The thin lens's aperture radius (0: a pinhole) and the distance of its focal plane
    /// along the view axis.
    aperture: f32,
    focus: f32,
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
        let filter = FilterTable::new(PixelFilter::Box).expect("the box filter");
        let (near, far) = (0.0, f32::INFINITY);
        let (aperture, focus) = (0.0, 1.0);
        Self { to_world, origin, tan_half, resolution, near, far, filter, aperture, focus }
    }

    /// The camera as Mitsuba's thin lens of aperture radius `aperture` (0 keeps the pinhole),
    /// in focus at distance `focus` along the view axis. Panics unless the aperture is 0 or
    /// the focus is finite and positive (scenes check both when they are built).
    pub fn with_lens(self, aperture: f32, focus: f32) -> Self {
        assert!(
            aperture == 0.0 || (aperture > 0.0 && focus > 0.0 && focus.is_finite()),
            "a thin lens needs an aperture of 0 or more and a finite focus above 0"
        );
        Self { aperture, focus, ..self }
    }

    /// Whether rays start across an aperture, so that each needs a point of the lens.
    pub fn has_lens(&self) -> bool {
        self.aperture > 0.0
    }

    /// The camera with the pixel filter of `filter` (a box by default).
    pub fn with_filter(self, filter: FilterTable) -> Self {
        Self { filter, ..self }
    }

    /// The pixel filter.
    pub fn filter(&self) -> PixelFilter {
        self.filter.filter()
    }

    /// A film position for a sample of `pixel`, drawn from the pixel filter, and the sample's
    /// weight (one but for filters with negative lobes; see [`FilterTable::film_sample`]).
    #[inline]
    pub fn film_sample(&self, pixel: [u32; 2], sampler: &mut Sampler) -> (Vec2, f32) {
        self.filter.film_sample(pixel, self.resolution, sampler)
    }

    /// The camera with clipping planes `near` and `far` (distances along the view axis, with
    /// `0 <= near < far`; the far plane may be infinite): nothing nearer than the near plane
    /// is seen, medium included, and nothing beyond the far one.
    pub fn with_clip(self, near: f32, far: f32) -> Self {
        Self { near, far, ..self }
    }

    /// Image width and height in pixels.
    pub fn resolution(&self) -> [u32; 2] {
        self.resolution
    }

    /// The camera position.
    pub fn origin(&self) -> Vec3A {
        self.origin
    }

    /// The primary ray through film position `film` (pixels, continuous, origin top left),
    /// starting on the near clipping plane (through the lens's centre).
    #[inline]
    pub fn ray(&self, film: Vec2) -> Ray {
        self.ray_and_reach(film, Vec2::splat(0.5)).0
    }

    /// The primary ray through `film` from the point of the lens that `lens` (uniform in the
    /// unit square) picks, and how far along it the far clipping plane lies.
    #[inline]
    pub fn ray_and_reach(&self, film: Vec2, lens: Vec2) -> (Ray, f32) {
        let ndc = Vec2::new(film.x / self.resolution[0] as f32, film.y / self.resolution[1] as f32);
        // Local +x is the camera's left, +y its up (look-at frame), so both axes flip.
        let local = Vec3A::new(
            (1.0 - 2.0 * ndc.x) * self.tan_half.x,
            (1.0 - 2.0 * ndc.y) * self.tan_half.y,
            1.0,
        );
        if self.aperture > 0.0 {
            return self.lens_ray(local, lens);
        }
        // The local direction's length is 1 / cos of its angle to the view axis, along which
        // the planes' distances are measured.
        let (direction, secant) = (self.to_world.vector(local).normalize(), local.length());
        let origin = self.origin + direction * (self.near * secant);
        (Ray::new(origin, direction), (self.far - self.near) * secant)
    }

    /// The thin lens's ray from aperture point `lens` towards where the pinhole's ray along
    /// `local` (local z 1) meets the focal plane.
    fn lens_ray(&self, local: Vec3A, lens: Vec2) -> (Ray, f32) {
        let p = concentric_disk(lens) * self.aperture;
        let start = Vec3A::new(p.x, p.y, 0.0);
        let d = (local * self.focus - start).normalize();
        let (near, far) = (self.near / d.z, self.far / d.z);
        let origin = self.to_world.point(start + d * near);
        (Ray::new(origin, self.to_world.vector(d).normalize()), far - near)
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

    #[test]
    fn rays_run_from_the_near_plane_to_the_far_one() {
        let to_world = Transform::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y).unwrap();
        let cam = Camera::new(to_world, 90.0, FovAxis::X, [200, 100]).with_clip(0.5, 4.0);
        // The image's right edge centre looks 45 degrees off the axis: the planes lie sqrt 2
        // times farther along that ray than along the axis.
        for (film, secant) in
            [(Vec2::new(100.0, 50.0), 1.0f32), (Vec2::new(200.0, 50.0), 2f32.sqrt())]
        {
            let (ray, reach) = cam.ray_and_reach(film, Vec2::splat(0.5));
            let start = Vec3A::new(0.0, 0.0, 5.0) + ray.direction * (0.5 * secant);
            assert!((ray.origin - start).length() < 1e-5, "{film}: {}", ray.origin);
            assert!((ray.origin.z - 4.5).abs() < 1e-5, "the near plane is z = 4.5");
            assert!((reach - 3.5 * secant).abs() < 1e-5, "{film}: reach {reach}");
            assert!((ray.at(reach).z - 1.0).abs() < 1e-5, "the far plane is z = 1");
        }
        let unclipped = Camera::new(to_world, 90.0, FovAxis::X, [200, 100]);
        let (ray, reach) = unclipped.ray_and_reach(Vec2::new(10.0, 20.0), Vec2::splat(0.5));
        assert_eq!((ray.origin, reach), (Vec3A::new(0.0, 0.0, 5.0), f32::INFINITY));
    }

    /// A thin lens's rays through one film position start across the aperture (within its
    /// radius, on the near plane) and all pass where the pinhole's ray meets the focal plane.
    #[test]
    fn thin_lens_rays_meet_on_the_focal_plane() {
        let to_world = Transform::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y).unwrap();
        let pinhole = Camera::new(to_world, 60.0, FovAxis::X, [64, 48]).with_clip(0.1, 100.0);
        let lens = pinhole.clone().with_lens(0.25, 3.0);
        assert!(lens.has_lens() && !pinhole.has_lens());
        let film = Vec2::new(50.0, 10.0);
        let (axis, _) = pinhole.ray_and_reach(film, Vec2::splat(0.5));
        // The focal plane is z = 2 (3 in front of the eye along -z).
        let focus = axis.at((axis.origin.z - 2.0) / -axis.direction.z);
        let mut sampler = Sampler::new(1, 2, 3);
        let (mut spread, mut widest) = (0.0f32, 0.0f32);
        for _ in 0..100 {
            let (ray, reach) = lens.ray_and_reach(film, sampler.next_2d());
            assert!((ray.origin.z - 4.9).abs() < 1e-5, "on the near plane: {}", ray.origin);
            let t = (ray.origin.z - 2.0) / -ray.direction.z;
            assert!((ray.at(t) - focus).length() < 1e-4, "{} vs {focus}", ray.at(t));
            // Back on the lens plane (z = 5) the ray starts within the aperture.
            let back = ray.at(-0.1 / -ray.direction.z);
            let off = (back - Vec3A::new(0.0, 0.0, 5.0)).length();
            assert!(off <= 0.25 + 1e-5, "{back}");
            (spread, widest) = (spread + off * off / 100.0, widest.max(off));
            assert!((ray.at(reach).z - (5.0 - 100.0)).abs() < 1e-2, "far plane: {reach}");
        }
        // Uniform over the aperture: the mean squared distance from its centre is r^2 / 2.
        assert!((spread / (0.25 * 0.25) - 0.5).abs() < 0.15 && widest > 0.2, "{spread} {widest}");
        // The lens's centre is the pinhole.
        assert!((lens.ray(film).direction - axis.direction).length() < 1e-6);
    }
}
