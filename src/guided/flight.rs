//! What a guided flight returns (its event, weight and an extra collision for delta lights)
//! and where that extra collision goes: shared by the general guided distance sampler
//! (`distance`) and the closed-form flight of grey homogeneous media (`plain_flight`).

use super::RadianceCache;
use crate::math::{Ray, Spectrum};

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
        (true, false) => Some(0.0),
        (false, false) => None,
    }
}

/// Parts of the guided stretch an extra collision for delta lights picks among: finer than
/// the segments, because its cache lookups are cheap (see [`RadianceCache::direct`]).
pub(super) const DIRECT_SEGMENTS: usize = 16;

#[derive(Clone, Copy, Debug)]
pub(super) struct DirectStretch {
    pub(super) weights: [f32; DIRECT_SEGMENTS],
    pub(super) total: f32,
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
    let mut mass = pick;
    for w in &mut d.weights {
        *w = positive_or_zero(mass.dot(collide) * *w);
        d.total += *w;
        mass *= decay;
    }
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
