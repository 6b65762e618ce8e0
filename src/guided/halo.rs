//! Directions towards the glow around point lights in a medium.
//!
//! The single-scattered light along a ray that passes a point light at distance `h` grows as
//! `1 / h`: seen from a vertex, the glow around the light is a spike of radiance `1 / theta`
//! at angle `theta` from the light. Phase or BSDF sampling, and a vMF mixture fitted to it,
//! draw directions near the spike with a bounded density, so the rare path that passes
//! close to the light brings back a huge value (a firefly whose variance grows as the
//! logarithm of the closest distance: without bound). This strategy draws the angle from the
//! light uniformly within a cap (density `1 / (2 pi theta_cap sin theta)`), which follows the
//! spike, and mixed in at a small share it bounds those weights.

use crate::lights::PointLight;
use crate::math::Frame;
use arrayvec::ArrayVec;
use glam::{Vec2, Vec3A};

/// Lights whose glow the strategy aims at (the first point and spot lights).
const MAX_LIGHTS: usize = 8;

/// The cap's angular radius: directions whose rays pass the light within a tenth of its
/// distance. The spike's variance is spread evenly over the decades of the angle, so any
/// cap removes its divergence; a tenth of a radian keeps the cap a small part of the sphere
/// (0.25%) wherever the vertex is.
pub const CAP: f32 = 0.1;

/// The share of the strategy in a vertex's direction mixture where some light's glow may be
/// seen: it lowers every other strategy's density by a tenth, so where it does not help it
/// costs at most a ninth more variance.
pub const SHARE: f32 = 0.1;

/// A cosine below which a unit direction is surely outside every cap (acos 0.994 = 0.1096 >
/// [`CAP`], a margin far beyond rounding): most directions skip the exact angle's atan2.
const OUTSIDE_CAP_COS: f32 = 0.994;

/// The directions towards the lights seen from one vertex.
#[derive(Clone, Debug)]
pub struct Halo {
    axes: ArrayVec<Vec3A, MAX_LIGHTS>,
}

impl Halo {
    /// The caps about the lights seen from `x` (spot lights too, from anywhere: a ray that
    /// passes close to the light crosses its cone near the apex); `None` without any.
    pub fn at(x: Vec3A, lights: &[PointLight]) -> Option<Self> {
        let mut axes = ArrayVec::new();
        for light in lights.iter().take(MAX_LIGHTS) {
            let to = light.position - x;
            let r = to.length();
            if r > 0.0 && r.is_finite() {
                axes.push(to / r);
            }
        }
        (!axes.is_empty()).then_some(Self { axes })
    }

    /// A direction: `pick` chooses the light, `u` the angle from it and the azimuth.
    pub fn sample(&self, pick: f32, u: Vec2) -> Vec3A {
        let n = self.axes.len();
        let axis = self.axes[((pick * n as f32) as usize).min(n - 1)];
        let theta = (u.x * CAP).max(1e-6);
        let (s, c) = theta.sin_cos();
        let (sp, cp) = (std::f32::consts::TAU * u.y).sin_cos();
        Frame::from_z(axis).to_world(Vec3A::new(s * cp, s * sp, c)).normalize()
    }

    /// The density of [`sample`](Self::sample) at `w` (per steradian).
    pub fn pdf(&self, w: Vec3A) -> f32 {
        let sum: f32 = self
            .axes
            .iter()
            .map(|&a| {
                in_cap(w, a)
                    .map_or(0.0, |s| 1.0 / (std::f32::consts::TAU * CAP * s.max(1e-6f32.sin())))
            })
            .sum();
        sum / self.axes.len() as f32
    }

    /// Whether `w` lies in some light's cap, where its ray may pass close to the light and
    /// bring back far more than a fitted mixture says.
    pub fn covers(&self, w: Vec3A) -> bool {
        self.axes.iter().any(|&a| in_cap(w, a).is_some())
    }
}

/// The sine of the angle between unit vectors `w` and `a` where that angle is within [`CAP`]:
/// most directions are rejected by their cosine alone, the rest by the angle as atan2 of the
/// sine and cosine, accurate near the axis where acos of a rounded cosine is not.
#[inline]
fn in_cap(w: Vec3A, a: Vec3A) -> Option<f32> {
    let c = w.dot(a);
    if c < OUTSIDE_CAP_COS {
        return None;
    }
    let s = w.cross(a).length();
    (s.atan2(c) <= CAP).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use zerovar_testkit::{MeanEstimate, chi2_1d};

    fn point(position: Vec3A) -> PointLight {
        PointLight { position, cone: None }
    }

    /// The cheap cosine test never decides a direction that the exact angle puts inside the
    /// cap: directions from 0.05 to 0.15 rad about the light, against atan2 alone.
    #[test]
    fn the_early_rejection_agrees_with_the_exact_angle() {
        let axis = Vec3A::new(0.3, -0.5, 0.8).normalize();
        let frame = Frame::from_z(axis);
        let mut sampler = crate::rng::Sampler::new(9, 0, 0);
        let halo = Halo { axes: [axis].into_iter().collect() };
        let (mut inside, mut outside) = (0, 0);
        for _ in 0..100_000 {
            let theta = 0.05 + 0.1 * sampler.next_1d();
            let phi = std::f32::consts::TAU * sampler.next_1d();
            let local = Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            let w = frame.to_world(local).normalize();
            let exact = w.cross(axis).length().atan2(w.dot(axis)) <= CAP;
            assert_eq!(halo.covers(w), exact, "theta {theta}");
            assert_eq!(halo.pdf(w) > 0.0, exact, "theta {theta}");
            if exact { inside += 1 } else { outside += 1 }
        }
        assert!(inside > 40_000 && outside > 40_000, "{inside} {outside}");
    }

    /// Samples about one light: the angle from it is uniform in the cap (chi-square of the
    /// angle against the density's marginal, integrated over the azimuth from `pdf`).
    #[test]
    fn the_angle_from_the_light_follows_the_density() {
        let x = Vec3A::new(0.2, -0.1, 0.4);
        let halo = Halo::at(x, &[point(Vec3A::new(1.0, 2.0, -0.5))]).expect("a light");
        let axis = halo.axes[0];
        let mut sampler = crate::rng::Sampler::new(3, 0, 0);
        // The angle by atan2 of the sine and cosine: acos of a rounded cosine near the axis
        // would be inaccurate (or NaN).
        let angle = |w: Vec3A| f64::from(w.cross(axis).length().atan2(w.dot(axis)));
        let angles: Vec<f64> = (0..200_000)
            .map(|_| angle(halo.sample(sampler.next_1d(), sampler.next_2d())))
            .collect();
        // The marginal density of the angle: pdf times sin(theta) over the azimuth.
        let frame = Frame::from_z(axis);
        let marginal = |theta: f64| {
            let steps = 64;
            (0..steps)
                .map(|k| {
                    let phi = std::f64::consts::TAU * (k as f64 + 0.5) / steps as f64;
                    let (s, c) = (theta.sin() as f32, theta.cos() as f32);
                    let local = Vec3A::new(s * phi.cos() as f32, s * phi.sin() as f32, c);
                    f64::from(halo.pdf(frame.to_world(local))) * theta.sin()
                })
                .sum::<f64>()
                * std::f64::consts::TAU
                / steps as f64
        };
        let edges: Vec<f64> = (0..=40).map(|i| f64::from(CAP) * f64::from(i) / 40.0).collect();
        chi2_1d(&angles, &marginal, &edges, &[]).assert_pass(1e-4, "angle from the light");
    }

    /// `E[g / pdf]` over samples is the integral of `g` over the caps, for two lights (caps
    /// apart and overlapping): the density is the sampler's, and it integrates to one.
    #[test]
    fn weighted_samples_integrate_over_the_caps() {
        let x = Vec3A::ZERO;
        let apart = [point(Vec3A::new(3.0, 0.0, 0.0)), point(Vec3A::new(0.0, 0.0, -2.0))];
        let overlapping = [point(Vec3A::new(3.0, 0.0, 0.0)), point(Vec3A::new(3.0, 0.15, 0.0))];
        for (what, lights) in [("apart", apart), ("overlapping", overlapping)] {
            let halo = Halo::at(x, &lights).expect("lights");
            let mut sampler = crate::rng::Sampler::new(4, 0, 0);
            // 1 on the union of the caps, and g = x^2 + 1 there.
            let in_caps =
                |w: Vec3A| halo.axes.iter().any(|a| w.cross(*a).length().atan2(w.dot(*a)) <= CAP);
            let g = |w: Vec3A| f64::from(w.x) * f64::from(w.x) + 1.0;
            let (mut area, mut moment) = (MeanEstimate::default(), MeanEstimate::default());
            for _ in 0..400_000 {
                let w = halo.sample(sampler.next_1d(), sampler.next_2d());
                let p = f64::from(halo.pdf(w));
                assert!(p > 0.0 && p.is_finite() && in_caps(w), "{what}: {w} with density {p}");
                area.push(1.0 / p);
                moment.push(g(w) / p);
            }
            // The caps' area (solid angle) and the integral of g over them: over each cap in
            // its own polar coordinates, less the overlap counted twice.
            let over_cap = |axis: Vec3A, f: &dyn Fn(Vec3A) -> f64| {
                let frame = Frame::from_z(axis);
                let n = 1500;
                let (dt, dp) = (f64::from(CAP) / n as f64, std::f64::consts::TAU / n as f64);
                let mut sum = 0.0;
                for i in 0..n {
                    let theta = (i as f64 + 0.5) * dt;
                    for k in 0..n {
                        let phi = (k as f64 + 0.5) * dp;
                        let (st, ct) = (theta.sin(), theta.cos());
                        let local =
                            Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                        sum += f(frame.to_world(local)) * st * dt * dp;
                    }
                }
                sum
            };
            let (a, b) = (halo.axes[0], halo.axes[1]);
            let in_b = |w: Vec3A| w.cross(b).length().atan2(w.dot(b)) <= CAP;
            let union = |f: &dyn Fn(Vec3A) -> f64| {
                over_cap(a, f) + over_cap(b, f) - over_cap(a, &|w| if in_b(w) { f(w) } else { 0.0 })
            };
            let exact_area = union(&|_| 1.0);
            let exact_moment = union(&g);
            area.assert_matches(exact_area, 4.0, &format!("{what}: area"));
            moment.assert_matches(exact_moment, 4.0, &format!("{what}: moment"));
        }
    }

    #[test]
    fn no_light_or_a_vertex_at_the_light_gives_no_caps() {
        assert!(Halo::at(Vec3A::Y * 2.0, &[point(Vec3A::Y * 2.0)]).is_none(), "at the light");
        assert!(Halo::at(Vec3A::ZERO, &[]).is_none());
    }
}
