//! Equiangular sampling of a stretch of ray towards point lights (Kulla and Fajardo 2012).
//!
//! Next-event estimation of a point or spot light from a point at distance `r` carries
//! `1 / r^2`: from collisions drawn by any density that stays bounded near the light (the
//! free path, the direct-light grid), the estimate's variance diverges there, and in a fog
//! with a light inside it the largest samples come from collisions within a fraction of a
//! mean free path of the light. The equiangular density over the ray is proportional to
//! `1 / r^2`, so mixed into the extra collision's density it bounds the estimate near the
//! light by the ray's distance from it. A spot light's density covers only the part of the
//! ray inside its cone, where its light is.

use crate::lights::PointLight;
use crate::math::Ray;
use arrayvec::ArrayVec;

/// Point lights an equiangular density aims at; further ones are left to the other
/// strategies (a sampling density may ignore them without bias).
pub(super) const MAX_POINT_LIGHTS: usize = 8;

/// One light seen from the ray: the ray parameter of its foot on the ray, its distance from
/// the ray, the stretch it reaches, and the angles that stretch spans as seen from it.
#[derive(Clone, Copy, Debug)]
struct Towards {
    foot: f32,
    distance: f32,
    start: f32,
    end: f32,
    theta_start: f32,
    span: f32,
}

/// The equiangular density of a stretch `(0, end)` of a ray, averaged over point lights.
#[derive(Clone, Debug)]
pub(super) struct Equiangular {
    lights: ArrayVec<Towards, MAX_POINT_LIGHTS>,
}

impl Equiangular {
    /// The density over `(0, end)` of `ray` towards `lights` (the first
    /// [`MAX_POINT_LIGHTS`]), each over the part of it the light reaches; `None` without
    /// lights or without a stretch any reaches.
    pub(super) fn new(ray: &Ray, end: f32, point_lights: &[PointLight]) -> Option<Self> {
        Self::between(ray, 0.0, end, point_lights)
    }

    /// The same over `(begin, end)`: the part of a ray inside a medium's box.
    pub(super) fn between(
        ray: &Ray,
        begin: f32,
        end: f32,
        point_lights: &[PointLight],
    ) -> Option<Self> {
        if end.is_nan() || end <= begin.max(0.0) {
            return None;
        }
        let mut lights = ArrayVec::new();
        for light in point_lights.iter().take(MAX_POINT_LIGHTS) {
            let Some((start, stop)) = light.reach(ray, end) else { continue };
            let start = start.max(begin);
            if start >= stop {
                continue;
            }
            let to = light.position - ray.origin;
            let foot = to.dot(ray.direction);
            // The cross product keeps the distance accurate for lights near the ray, where
            // |to|^2 - foot^2 would cancel; a light on the ray itself gets a tiny distance,
            // which keeps the density finite and the sampler and its density consistent.
            let scale = to.length().max(1.0);
            let distance = to.cross(ray.direction).length().max(1e-6 * scale);
            let theta_start = ((start - foot) / distance).atan();
            let theta_end = ((stop - foot) / distance).atan();
            let span = theta_end - theta_start;
            if span > 0.0 && span.is_finite() {
                lights.push(Towards { foot, distance, start, end: stop, theta_start, span });
            }
        }
        (!lights.is_empty()).then_some(Self { lights })
    }

    /// A ray parameter in `(0, end)`: `pick` chooses the light, `u` the angle.
    pub(super) fn sample(&self, pick: f32, u: f32, end: f32) -> f32 {
        let n = self.lights.len();
        let l = self.lights[((pick * n as f32) as usize).min(n - 1)];
        let t = l.foot + l.distance * (l.theta_start + u * l.span).tan();
        // Inside the light's stretch and short of the end (not `clamp`: a stretch within
        // rounding of the end may have its start past the bound).
        t.max(l.start).min(l.end).min(end * (1.0 - 1e-6))
    }

    /// The density at ray parameter `t` (within the stretch).
    pub(super) fn pdf(&self, t: f32) -> f32 {
        let sum: f32 = self
            .lights
            .iter()
            .filter(|l| t >= l.start && t <= l.end)
            .map(|l| {
                let x = t - l.foot;
                l.distance / (l.span * (l.distance * l.distance + x * x))
            })
            .sum();
        sum / self.lights.len() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;
    use std::f32::consts::TAU;
    use zerovar_testkit::{chi2_1d, equal_mass_edges, integrate_1d};

    fn point(position: Vec3A) -> PointLight {
        PointLight { position, cone: None }
    }

    fn cases() -> Vec<(Ray, f32, Vec<PointLight>)> {
        let o = Vec3A::new(0.1, -0.2, 0.3);
        let d = Vec3A::new(1.0, 0.2, -0.1).normalize();
        let spot = PointLight {
            position: o + 2.0 * d + Vec3A::new(0.0, 0.8, 0.0),
            cone: Some((-Vec3A::Y, 20f32.to_radians().cos())),
        };
        vec![
            // A light beside the middle of the stretch, one just off the ray, one behind its
            // start, two at once, and a spot light whose cone the ray crosses.
            (Ray::new(o, d), 4.0, vec![point(o + 2.0 * d + Vec3A::new(0.0, 0.3, 0.0))]),
            (Ray::new(o, d), 4.0, vec![point(o + 1.0 * d + Vec3A::new(0.0, 0.0, 1e-3))]),
            (Ray::new(o, d), 10.0, vec![point(o - 3.0 * d + Vec3A::Y)]),
            (
                Ray::new(o, d),
                6.0,
                vec![point(o + 0.5 * d + Vec3A::Y * 0.2), point(o + 5.0 * d - Vec3A::X)],
            ),
            (Ray::new(o, d), 4.0, vec![spot]),
        ]
    }

    /// The distribution function, from the angles (independent of `pdf`).
    fn cdf(e: &Equiangular, t: f64) -> f64 {
        let sum: f64 = e
            .lights
            .iter()
            .map(|l| {
                let t = t.clamp(f64::from(l.start), f64::from(l.end));
                let theta = ((t - f64::from(l.foot)) / f64::from(l.distance)).atan();
                (theta - f64::from(l.theta_start)) / f64::from(l.span)
            })
            .sum();
        sum / e.lights.len() as f64
    }

    #[test]
    fn the_density_integrates_to_one_and_matches_its_distribution() {
        for (k, (ray, end, lights)) in cases().into_iter().enumerate() {
            let e = Equiangular::new(&ray, end, &lights).expect("lights");
            let pdf = |t: f64| f64::from(e.pdf(t as f32));
            let total = integrate_1d(&pdf, 0.0, f64::from(end), 20_000);
            assert!((total - 1.0).abs() < 1e-3, "case {k}: integral {total}");
            assert!((cdf(&e, f64::from(end)) - 1.0).abs() < 1e-5, "case {k}");
            for x in [0.1, 0.9, 1.0, 2.5] {
                let part = integrate_1d(&pdf, 0.0, x, 20_000);
                assert!((part - cdf(&e, x)).abs() < 1e-3, "case {k}: {part} at {x}");
            }
        }
    }

    #[test]
    fn samples_follow_the_density() {
        for (k, (ray, end, lights)) in cases().into_iter().enumerate() {
            let e = Equiangular::new(&ray, end, &lights).expect("lights");
            let mut sampler = crate::rng::Sampler::new(5, k as u64, 0);
            let samples: Vec<f64> = (0..200_000)
                .map(|_| f64::from(e.sample(sampler.next_1d(), sampler.next_1d(), end)))
                .collect();
            // Bins over the stretch the lights reach (the density jumps at its ends).
            let lo = e.lights.iter().map(|l| f64::from(l.start)).fold(f64::INFINITY, f64::min);
            let hi = e.lights.iter().map(|l| f64::from(l.end)).fold(0.0, f64::max);
            let edges = equal_mass_edges(&|t| cdf(&e, t), lo, hi, 64);
            let pdf = |t: f64| f64::from(e.pdf(t as f32));
            chi2_1d(&samples, &pdf, &edges, &[]).assert_pass(1e-4, &format!("case {k}"));
        }
    }

    /// A spot light reaches exactly the points of the ray inside its cone: checked point by
    /// point along random rays through random cones.
    #[test]
    fn a_spot_light_reaches_the_part_of_the_ray_inside_its_cone() {
        let mut sampler = crate::rng::Sampler::new(8, 0, 0);
        let mut u = || 2.0 * sampler.next_1d() - 1.0;
        let (mut crossed, mut missed) = (0, 0);
        for _ in 0..4000 {
            let origin = 2.0 * Vec3A::new(u(), u(), u());
            let direction = Vec3A::new(u(), u(), u()).normalize_or(Vec3A::X);
            let ray = Ray::new(origin, direction);
            let axis = Vec3A::new(u(), u(), u()).normalize_or(Vec3A::Y);
            let cutoff = (5.0 + 80.0 * (0.5 + 0.5 * u())).to_radians();
            let light = PointLight { position: Vec3A::ZERO, cone: Some((axis, cutoff.cos())) };
            let end = 6.0;
            let reach = light.reach(&ray, end);
            let inside = |t: f32| {
                let to = ray.at(t) - light.position;
                to.dot(axis) >= to.length() * cutoff.cos()
            };
            let steps = 2000;
            let mut any = false;
            for i in 0..steps {
                let t = end * (i as f32 + 0.5) / steps as f32;
                // Points well inside or well outside the cone (rounding decides the rest).
                let to = ray.at(t) - light.position;
                let margin = (to.dot(axis) / to.length().max(1e-9) - cutoff.cos()).abs();
                if margin < 1e-3 {
                    continue;
                }
                let within = reach.is_some_and(|(a, b)| t >= a && t <= b);
                assert_eq!(
                    inside(t),
                    within,
                    "{ray:?}, axis {axis}, cutoff {cutoff}, t {t}: {reach:?}"
                );
                any |= inside(t);
            }
            if any { crossed += 1 } else { missed += 1 }
        }
        assert!(crossed > 400 && missed > 400, "crossed {crossed}, missed {missed}");
    }

    /// Rays through points well inside a narrow spot's cone (at least half a degree from its
    /// edge) within 1e-4 to 0.1 of the apex, from 0.5 to 5 away: the part the light reaches
    /// holds every such point. Near the apex the cone's interval along a ray is shorter than
    /// single precision resolves at the ray's scale.
    #[test]
    fn a_spot_light_reaches_points_near_its_apex() {
        let mut sampler = crate::rng::Sampler::new(9, 0, 0);
        let mut u = || sampler.next_1d();
        let position = Vec3A::new(1.1, 2.35, -1.2);
        let axis = Vec3A::new(-0.6, -2.35, -1.0).normalize();
        let cutoff = 12f32.to_radians();
        let light = PointLight { position, cone: Some((axis, cutoff.cos())) };
        let frame = crate::math::Frame::from_z(axis);
        let mut checked = 0;
        for _ in 0..20_000 {
            let (theta, phi) = ((cutoff - 0.5f32.to_radians()) * u().sqrt(), TAU * u());
            let local = Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            let point = position + 10f32.powf(-4.0 + 3.0 * u()) * frame.to_world(local);
            let z = 2.0 * u() - 1.0;
            let a = TAU * u();
            let r = (1.0 - z * z).sqrt();
            let direction = Vec3A::new(r * a.cos(), r * a.sin(), z);
            let t = 0.5 + 4.5 * u();
            let ray = Ray::new(point - t * direction, direction);
            // The point as the walk computes it, checked as the light's cone is.
            let to = ray.at(t) - position;
            if to.dot(axis) < to.length() * (cutoff - 0.25f32.to_radians()).cos() {
                continue;
            }
            checked += 1;
            let reach = light.reach(&ray, 20.0);
            assert!(
                reach.is_some_and(|(a, b)| t >= a && t <= b),
                "{ray:?}, t {t}, distance {}: {reach:?}",
                to.length()
            );
        }
        assert!(checked > 15_000, "{checked}");
    }

    #[test]
    fn a_stretch_that_begins_later_holds_all_the_density() {
        let (ray, end, lights) = cases().swap_remove(3);
        let begin = 1.5;
        let e = Equiangular::between(&ray, begin, end, &lights).expect("lights");
        let pdf = |t: f64| f64::from(e.pdf(t as f32));
        assert_eq!(integrate_1d(&pdf, 0.0, 1.499, 100), 0.0);
        let total = integrate_1d(&pdf, f64::from(begin), f64::from(end), 20_000);
        assert!((total - 1.0).abs() < 1e-3, "integral {total}");
        let mut sampler = crate::rng::Sampler::new(6, 0, 0);
        let samples: Vec<f64> = (0..100_000)
            .map(|_| f64::from(e.sample(sampler.next_1d(), sampler.next_1d(), end)))
            .collect();
        assert!(samples.iter().all(|&t| t >= f64::from(begin) && t < f64::from(end)));
        let edges = equal_mass_edges(&|t| cdf(&e, t), f64::from(begin), f64::from(end), 48);
        chi2_1d(&samples, &pdf, &edges, &[]).assert_pass(1e-4, "from t = 1.5");
        // A stretch that ends before it begins, or lights that reach only before it: none.
        assert!(Equiangular::between(&ray, 3.0, 2.0, &lights).is_none());
        let early = PointLight { position: ray.at(0.5) + Vec3A::Y, cone: Some((-Vec3A::Y, 0.99)) };
        assert!(Equiangular::between(&ray, 0.0, 6.0, &[early]).is_some());
        assert!(Equiangular::between(&ray, 2.0, 6.0, &[early]).is_none());
    }

    #[test]
    fn no_stretch_or_no_light_gives_no_density() {
        let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
        assert!(Equiangular::new(&ray, 0.0, &[point(Vec3A::Y)]).is_none());
        assert!(Equiangular::new(&ray, 1.0, &[]).is_none());
        // A spot light pointing away from the ray.
        let away = PointLight { position: Vec3A::Y, cone: Some((Vec3A::Y, 0.9)) };
        assert!(Equiangular::new(&ray, 1.0, &[away]).is_none());
        // A light on the ray itself: a finite density, samples inside the stretch.
        let e = Equiangular::new(&ray, 2.0, &[point(Vec3A::X)]).expect("a light");
        assert!(e.pdf(0.5).is_finite() && e.pdf(1.0).is_finite());
        let t = e.sample(0.3, 0.999_999, 2.0);
        assert!((0.0..2.0).contains(&t));
        // An infinite stretch: the angle ends at a right angle.
        let e = Equiangular::new(&ray, f32::INFINITY, &[point(Vec3A::Y)]).expect("a light");
        assert!((e.pdf(0.0) - 1.0 / std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    }
}
