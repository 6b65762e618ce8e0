//! What a guided flight returns (its event, weight and an extra collision for delta lights)
//! and where that extra collision goes: shared by the general guided distance sampler
//! (`distance`) and the closed-form flight of grey homogeneous media (`plain_flight`).

use super::RadianceCache;
use super::equiangular::MAX_POINT_LIGHTS;
use crate::lights::PointLight;
use crate::math::{Ray, Spectrum, is_grey};
use crate::media::{Medium, MediumKind};

/// The guided stretch ends where the standard transmittance falls to exp(-CUT); beyond it the
/// rare remaining collisions follow the standard exponential.
pub(super) const CUT: f32 = 8.0;
/// The share of an extra collision's density that aims at point lights (equiangular) where
/// the ray has some, the rest following the direct-light grid. Half: a one-sample mixture of
/// two strategies at one half each weighs no sample more than twice what either alone would,
/// so it is never far from the better one, whatever the scene.
pub(super) const EQUIANGULAR_SHARE: f32 = 0.5;

/// The equiangular share of an extra collision's density for a ray whose grid parts are `d`:
/// [`EQUIANGULAR_SHARE`] beside a grid with light along the ray, all of it where the grid has
/// none (a spot light's cone, narrower near the light than the grid's cells, can fall between
/// the parts' middles), nothing without point lights to aim at; `None` when neither knows of
/// any light (no extra collision).
pub(super) fn equiangular_share(d: &DirectStretch, towards: bool) -> Option<f32> {
    match (d.total > 0.0 && d.total.is_finite(), towards) {
        (true, true) => Some(EQUIANGULAR_SHARE),
        (false, true) => Some(1.0),
        (true, false) if d.own_variance > MIN_OWN_VARIANCE => Some(0.0),
        _ => None,
    }
}

/// Without point lights, a ray takes an extra collision only where the flight's own collision
/// would estimate the grid's delta-light in-scattering along it with a relative variance above
/// this (see [`DirectStretch::own_variance`]). Light on a share `f` of where the flight
/// collides gives about `1 / f - 1`, so 1 means "concentrated on less than half of it" (a
/// shaft); a medium lit all through by the sun gives nearly 0, and there an extra collision
/// costs a shadow ray for little. The rule reads only the ray's own light, not the scene's
/// size or brightness. Point lights always get one: the grid cannot see their `1 / r^2`.
pub(super) const MIN_OWN_VARIANCE: f32 = 1.0;

/// Whether an unguided flight along `ray` up to `t_max` through `medium` takes an extra
/// collision aimed at `point_lights`: in grey homogeneous fog, only where its own collision
/// would estimate some light's in-scattering with a relative variance above
/// `MIN_OWN_VARIANCE` (1), as the sun's rule; elsewhere always. Near a light at distance `d`
/// from the ray's stretch, nearest at `t`, that variance is about
/// `exp(sigma t) / (2 pi sigma d) - 1`: the light's `1 / r^2` peak, of width `d`, against a
/// collision density `sigma exp(-sigma t)`. A light whose peak lies past the stretch an extra
/// collision covers (`CUT` mean free paths) gets none. The rule reads the ray alone in units
/// of the mean free path, so it holds for any scene's scale; rays it passes keep a bounded
/// variance.
pub fn free_path_needs_extra(
    medium: &Medium,
    ray: &Ray,
    t_max: f32,
    point_lights: &[PointLight],
) -> bool {
    let MediumKind::Homogeneous { sigma_t, .. } = medium.kind else { return true };
    if !is_grey(sigma_t) {
        return true;
    }
    let sigma = sigma_t.x;
    if sigma.is_nan() || sigma <= 0.0 {
        return false; // no collisions, and nothing to estimate the light from
    }
    let end = t_max.min(CUT / sigma);
    // The lights the extra collision would aim at (`Equiangular` takes the first of them).
    point_lights.iter().take(MAX_POINT_LIGHTS).any(|light| {
        let Some((start, stop)) = light.reach(ray, end) else { return false };
        let foot = (light.position - ray.origin).dot(ray.direction);
        if foot > end && end < t_max {
            // Its peak lies past the stretch, which the standard tail covers: within the
            // stretch its light is at least exp(-CUT) of what it is there.
            return false;
        }
        let t = foot.max(start).min(stop);
        let d = (light.position - ray.at(t)).length();
        (sigma * t).exp() > (1.0 + MIN_OWN_VARIANCE) * std::f32::consts::TAU * sigma * d
    })
}

/// Parts of the guided stretch an extra collision for delta lights picks among: finer than
/// the segments, because its cache lookups are cheap (see [`RadianceCache::direct`]).
pub(super) const DIRECT_SEGMENTS: usize = 16;

#[derive(Clone, Copy, Debug)]
pub(super) struct DirectStretch {
    pub(super) weights: [f32; DIRECT_SEGMENTS],
    pub(super) total: f32,
    /// The relative variance of the estimate the flight's own (standard) collision makes of
    /// the in-scattering the weights sum: `sum p_j D_j^2 / (sum p_j D_j)^2 - 1` over the parts'
    /// collision probabilities `p_j` and in-scattering `D_j` (0 for light spread along the ray
    /// as the collisions are; large for a narrow shaft).
    pub(super) own_variance: f32,
    /// The length of a part, and per channel the probability of colliding within one.
    pub(super) length: f32,
    pub(super) collide: Spectrum,
    /// Per channel, the transmittance through one part.
    pub(super) decay: Spectrum,
}

impl DirectStretch {
    /// The part that holds ray parameter `t` of the stretch.
    #[inline]
    pub(super) fn part_of(&self, t: f32) -> usize {
        ((t / self.length) as usize).min(DIRECT_SEGMENTS - 1)
    }

    /// The part a uniform `u` picks in proportion to the weights: the first whose cumulative
    /// weight passes `u total`, or the last weighted one if rounding leaves `u total` past
    /// them all; `None` when no part has any weight.
    pub(super) fn pick(&self, u: f32) -> Option<usize> {
        let v = u * self.total;
        let mut below = 0.0;
        (0..DIRECT_SEGMENTS)
            .filter(|&j| self.weights[j] > 0.0)
            .find(|&j| {
                below += self.weights[j];
                v < below
            })
            .or_else(|| (0..DIRECT_SEGMENTS).rev().find(|&j| self.weights[j] > 0.0))
    }
}

/// The weights by which an extra collision for delta lights picks among the
/// `DIRECT_SEGMENTS` equal parts of `ray`'s guided stretch `(0, guided_end)`, and their sum:
/// the standard probability (channels mixed by `pick`, which sums to 1) of colliding in each
/// part times the cache's delta-light in-scattering at its middle (HG with `g`). The tail past
/// the stretch gets none (the flight's own collision covers it).
pub(super) fn direct_stretch(
    ray: &Ray,
    guided_end: f32,
    sigma: Spectrum,
    pick: Spectrum,
    g: f32,
    cache: &mut impl RadianceCache,
) -> DirectStretch {
    let h = guided_end / DIRECT_SEGMENTS as f32;
    let mut d = DirectStretch {
        weights: [0.0; DIRECT_SEGMENTS],
        total: 0.0,
        own_variance: 0.0,
        length: h,
        collide: Spectrum::ZERO,
        decay: Spectrum::ONE,
    };
    let dir = ray.direction;
    cache.direct_along(ray.origin, dir * h, dir, g, &mut d.weights);
    if !d.weights.iter().any(|&w| w > 0.0) {
        return d; // most rays miss a shaft of sunlight: no weights, no exponentials
    }
    let collide =
        Spectrum::select(sigma.cmpgt(Spectrum::ZERO), -exp_m1(-sigma * h), Spectrum::ZERO);
    let decay = exp(-sigma * h);
    (d.collide, d.decay) = (collide, decay);
    let (mut mass, mut total, mut second) = (pick, 0.0, 0.0);
    for w in &mut d.weights {
        let direct = *w;
        *w = positive_or_zero(mass.dot(collide) * direct);
        total += *w;
        second += *w * direct;
        mass *= decay;
    }
    d.total = total;
    d.own_variance = second / (total * total) - 1.0;
    d
}

/// Where a guided flight ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GuidedEvent {
    /// A real collision at `t` that scatters.
    Scatter {
        /// Ray parameter.
        t: f32,
    },
    /// A real collision that absorbs the path (its emission is in `emitted`).
    Absorb,
    /// The flight passed the end of the ray.
    Pass,
}

/// The outcome of a guided flight, as `tracking::Flight`.
#[derive(Clone, Copy, Debug)]
pub struct GuidedFlight {
    /// The event.
    pub event: GuidedEvent,
    /// Multiplies the path throughput (zero after an absorption).
    pub weight: Spectrum,
    /// Emitted radiance collected, already multiplied by the incoming throughput.
    pub emitted: Spectrum,
    /// The standard strategy's density of this flight over the mixture's: how much guiding
    /// multiplied the weight relative to standard tracking (1 when the flight was not
    /// guided). The walk stops guiding paths whose guided decisions compounded too much.
    pub gain: f32,
    /// The MIS weight of next-event estimation of delta lights at a scattering collision
    /// (1 unless `extra` estimates the same light too).
    pub delta_share: f32,
    /// A second collision, for next-event estimation of delta lights alone (see
    /// [`guided_flight`](super::distance::guided_flight)).
    pub extra: Option<ExtraCollision>,
}

impl GuidedFlight {
    pub(super) fn new(event: GuidedEvent, weight: Spectrum, gain: f32) -> Self {
        Self { event, weight, emitted: Spectrum::ZERO, gain, delta_share: 1.0, extra: None }
    }
}

/// A collision drawn only to estimate the light delta lights scatter into the ray there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtraCollision {
    /// Ray parameter.
    pub t: f32,
    /// Multiplies the incoming throughput and the phase-weighted delta-light estimate at `t`:
    /// `T(t) sigma_s(t)` over the extra collision's density there, times its power-heuristic
    /// weight against the flight's own density (whose other half is the flight's
    /// `delta_share`).
    pub weight: Spectrum,
}

/// The power heuristic's weight (exponent 2) of a strategy of density `a` against one of
/// density `b`, `a^2 / (a^2 + b^2)`, as a ratio so that no square overflows: 0 where `a` is 0.
///
/// It joins a flight's own collision and its extra collision for delta lights. The extra one
/// follows the lit parts of the ray closely and the flight's own collision does not (it must
/// also lead the path on), and where one strategy is much the better, the power heuristic
/// gives it more of the estimate than the balance heuristic does: less error at the same cost
/// (see docs/experiments.md).
#[inline]
pub(super) fn power_heuristic(a: f32, b: f32) -> f32 {
    if a > 0.0 {
        let r = b / a;
        1.0 / (1.0 + r * r)
    } else {
        0.0
    }
}

#[inline]
pub(super) fn positive_or_zero(v: f32) -> f32 {
    if v > 0.0 && v.is_finite() { v } else { 0.0 }
}

#[inline]
pub(super) fn exp(v: Spectrum) -> Spectrum {
    per_channel(v, f32::exp)
}

#[inline]
pub(super) fn exp_m1(v: Spectrum) -> Spectrum {
    per_channel(v, f32::exp_m1)
}

/// `f` of each channel, once for a grey spectrum (most media are grey, and these run several
/// times per flight).
#[inline]
pub(super) fn per_channel(v: Spectrum, f: impl Fn(f32) -> f32) -> Spectrum {
    if v.x == v.y && v.y == v.z {
        Spectrum::splat(f(v.x))
    } else {
        Spectrum::new(f(v.x), f(v.y), f(v.z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Vec2, Vec3A};

    /// Delta-light in-scattering 1 where `x` lies in `[lo, hi)`, 0 elsewhere.
    struct Band {
        lo: f32,
        hi: f32,
    }

    impl RadianceCache for Band {
        fn load(&mut self, _: Vec3A, _: f32) -> bool {
            false
        }
        fn incident(&self, _: Vec3A) -> f32 {
            0.0
        }
        fn mean_radiance(&self) -> f32 {
            0.0
        }
        fn inscattered(&self, _: Vec3A, _: f32) -> f32 {
            0.0
        }
        fn product_hg(&mut self, _: Vec3A, _: f32) -> bool {
            false
        }
        fn product_cosine(&mut self, _: Vec3A) -> bool {
            false
        }
        fn sample(&self, _: Vec2) -> Vec3A {
            Vec3A::X
        }
        fn pdf(&self, _: Vec3A) -> f32 {
            0.0
        }
        fn direct(&mut self, x: Vec3A, _: Vec3A, _: f32) -> f32 {
            if (self.lo..self.hi).contains(&x.x) { 1.0 } else { 0.0 }
        }
    }

    /// The relative variance of the flight's own estimate and the extra-collision rule, for
    /// light on `[lo, hi)` of a ray through a medium of extinction `sigma` per channel.
    fn stretch(sigma: Spectrum, lo: f32, hi: f32) -> DirectStretch {
        let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
        let pick = Spectrum::splat(1.0 / 3.0);
        // The guided stretch of the channels' smallest extinction, as `GuidedDistance` cuts it.
        let end = CUT / sigma.min_element();
        direct_stretch(&ray, end, sigma, pick, 0.0, &mut Band { lo, hi })
    }

    #[test]
    fn extra_collisions_go_where_the_light_is_concentrated_along_the_ray() {
        let sigma = Spectrum::splat(2.0);
        let part = CUT / 2.0 / DIRECT_SEGMENTS as f32; // two parts are one optical depth
        // Light on all of the stretch: the own collision's estimate is exact but for passing.
        let all = stretch(sigma, -1.0, 100.0);
        let expected = 1.0 / (1.0 - (-CUT).exp()) - 1.0;
        assert!((all.own_variance - expected).abs() < 1e-4, "{}", all.own_variance);
        assert_eq!(equiangular_share(&all, false), None);
        // Light on the first two optical depths: 86% of collisions fall there.
        let front = stretch(sigma, 0.0, 4.0 * part);
        let expected = 1.0 / (1.0 - (-2.0f32).exp()) - 1.0;
        assert!((front.own_variance - expected).abs() < 1e-3 * expected, "{}", front.own_variance);
        assert_eq!(equiangular_share(&front, false), None);
        // A shaft from optical depth 2 to 3: 8.6% of collisions, relative variance 10.7.
        let shaft = stretch(sigma, 4.0 * part, 6.0 * part);
        let mass = (-2.0f32).exp() - (-3.0f32).exp();
        let expected = 1.0 / mass - 1.0;
        assert!((shaft.own_variance - expected).abs() < 1e-3 * expected, "{}", shaft.own_variance);
        assert_eq!(equiangular_share(&shaft, false), Some(0.0));
        // Point lights always get an extra collision, with or without light in the grid.
        assert_eq!(equiangular_share(&all, true), Some(EQUIANGULAR_SHARE));
        assert_eq!(equiangular_share(&stretch(sigma, 50.0, 60.0), true), Some(1.0));
        assert_eq!(equiangular_share(&stretch(sigma, 50.0, 60.0), false), None);
    }

    /// The relative variance of the free path's own estimate of a point light's single
    /// scattering into `(0, end)` of a ray along +x, the light at distance `d` from it above
    /// `t0`: `int f^2 / p / (int f)^2 - 1` by quadrature, for `f = exp(-sigma (t + r)) / r^2`
    /// and `p = sigma exp(-sigma t)`.
    fn own_variance(sigma: f64, d: f64, t0: f64, end: f64) -> f64 {
        let f = |t: f64| {
            let r2 = d * d + (t - t0) * (t - t0);
            (-sigma * (t + r2.sqrt())).exp() / r2
        };
        let second = |t: f64| f(t) * f(t) / (sigma * (-sigma * t).exp());
        let near = (t0 - 20.0 * d).max(0.0)..(t0 + 20.0 * d).min(end);
        let integral = |g: &dyn Fn(f64) -> f64| {
            zerovar_testkit::integrate_1d(g, 0.0, near.start, 2000)
                + zerovar_testkit::integrate_1d(g, near.start, near.end, 4000)
                + zerovar_testkit::integrate_1d(g, near.end, end, 2000)
        };
        integral(&second) / integral(&f).powi(2) - 1.0
    }

    /// Unguided flights skip the extra collision only where the free path's own estimate of
    /// the point light is good: over extinctions of 0.05 to 2 and rays passing 0.01 to 3 from
    /// the light, every ray the rule passes has a relative variance below 4 by quadrature,
    /// every ray it takes one above 1, and every ray above 8 takes one. Spot lights the ray
    /// does not reach, lights past the stretch, and media without collisions, never take one;
    /// a ray through a spot's cone near its apex does; chromatic media always.
    #[test]
    fn unguided_flights_take_extra_collisions_where_the_free_path_is_poor() {
        let medium = |sigma_t: Spectrum| Medium {
            name: "fog".into(),
            kind: MediumKind::Homogeneous { sigma_t, albedo: Spectrum::splat(0.9) },
            phase: crate::phase::PhaseFunction::Isotropic,
            emission: Spectrum::ZERO,
        };
        let ray = Ray::new(Vec3A::ZERO, Vec3A::X);
        let (mut taken, mut passed) = (0, 0);
        for sigma in [0.05f32, 0.5, 2.0] {
            let fog = medium(Spectrum::splat(sigma));
            for d in [0.01f32, 0.1, 0.3, 1.0, 3.0] {
                for t0 in [0.5f32, 2.0, 5.0] {
                    let end = (CUT / sigma).min(50.0);
                    if t0 >= end {
                        continue;
                    }
                    let light = PointLight { position: Vec3A::new(t0, d, 0.0), cone: None };
                    let takes = free_path_needs_extra(&fog, &ray, end, &[light]);
                    let exact = own_variance(sigma.into(), d.into(), t0.into(), end.into());
                    let what = format!("sigma {sigma}, d {d}, t0 {t0}: variance {exact:.2}");
                    assert!(takes || exact < 4.0, "{what}, passed");
                    assert!(!takes || exact > 1.0, "{what}, taken");
                    if exact > 8.0 {
                        assert!(takes, "{what}, passed");
                    }
                    if takes { taken += 1 } else { passed += 1 }
                }
            }
        }
        assert!(taken > 5 && passed > 5, "taken {taken}, passed {passed}");
        let near = PointLight { position: Vec3A::new(2.0, 0.01, 0.0), cone: None };
        let fog = medium(Spectrum::splat(0.5));
        assert!(free_path_needs_extra(&fog, &ray, f32::INFINITY, &[near]));
        // A spot light pointing away from the ray reaches none of it.
        let away = PointLight { cone: Some((Vec3A::Y, 0.9)), ..near };
        assert!(!free_path_needs_extra(&fog, &ray, f32::INFINITY, &[away]));
        assert!(!free_path_needs_extra(&medium(Spectrum::ZERO), &ray, 10.0, &[near]));
        // A light past the stretch's cut (8 mean free paths) gets none; one as near past a
        // surface that ends the ray sooner, where the stretch ends, does.
        let beyond = PointLight { position: Vec3A::new(16.5, 0.01, 0.0), cone: None };
        assert!(!free_path_needs_extra(&fog, &ray, f32::INFINITY, &[beyond]));
        let at_wall = PointLight { position: Vec3A::new(4.5, 0.01, 0.0), cone: None };
        assert!(free_path_needs_extra(&fog, &ray, 4.0, &[at_wall]));
        // A spot's cone may end before the ray's nearest point to it: what counts is how near
        // the ray passes within the cone, not where the cone ends.
        let axis = Vec3A::new(-1.0, -0.5, 0.0).normalize();
        let apex = PointLight { position: Vec3A::new(2.0, 0.05, 0.0), cone: Some((axis, 0.7)) };
        let (_, stop) = apex.reach(&ray, 16.0).expect("the ray crosses the cone");
        assert!(stop < 2.0, "the cone ends at {stop}, before the foot");
        assert!(free_path_needs_extra(&fog, &ray, f32::INFINITY, &[apex]));
        // Only the lights an extra collision would aim at count.
        let mut many = vec![PointLight { position: Vec3A::new(2.0, 30.0, 0.0), cone: None }; 8];
        many.push(near);
        assert!(!free_path_needs_extra(&fog, &ray, f32::INFINITY, &many));
        let chromatic = medium(Spectrum::new(0.5, 1.0, 2.0));
        let far = PointLight { position: Vec3A::new(2.0, 30.0, 0.0), cone: None };
        assert!(free_path_needs_extra(&chromatic, &ray, 10.0, &[far]));
    }

    #[test]
    fn a_chromatic_medium_weighs_the_light_by_each_channels_collisions() {
        // Light on the far half of the red channel's stretch: blue, ten times as dense,
        // collides almost only in the near half, so only a third of the collision mass
        // (red's) sees the light.
        let sigma = Spectrum::new(1.0, 10.0, 10.0);
        let half = stretch(sigma, CUT / 2.0, 100.0);
        let red = (-CUT / 2.0).exp() - (-CUT).exp();
        let blue = (-CUT * 5.0).exp();
        let expected = 1.0 / ((red + 2.0 * blue) / 3.0) - 1.0;
        assert!((half.own_variance - expected).abs() < 1e-2 * expected, "{}", half.own_variance);
        assert_eq!(equiangular_share(&half, false), Some(0.0));
    }
}
