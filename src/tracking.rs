//! Free-flight sampling and transmittance estimation through one medium along one ray segment.
//!
//! Each medium gets the cheapest correct estimator when the scene is built ("model only what a
//! scene needs"): closed forms for homogeneous media (with one-sample MIS over the colour
//! channels when the extinction is chromatic), delta tracking for heterogeneous media with grey
//! extinction, and spectral tracking with history-aware event probabilities (Kutz et al. 2017)
//! for heterogeneous media with chromatic extinction. Ratio tracking estimates transmittance for
//! shadow rays. All of them are unbiased per channel; the tests check them against `exp(-tau)`.

use crate::math::{Ray, Spectrum, channel_mean};
use crate::media::{Medium, MediumKind};
use crate::rng::Sampler;
use crate::stats::Counters;

/// The free-flight and transmittance strategy chosen for a medium.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tracker {
    /// Homogeneous, grey extinction: exponential sampling, exact transmittance.
    Analytic,
    /// Homogeneous, chromatic extinction: a channel picked by path throughput, MIS weights.
    AnalyticSpectral,
    /// Heterogeneous, grey extinction: delta tracking against the global majorant.
    Delta,
    /// Heterogeneous, chromatic extinction: spectral tracking.
    Spectral,
}

impl Tracker {
    /// The cheapest unbiased tracker for `medium`.
    pub fn for_medium(medium: &Medium) -> Self {
        match (&medium.kind, medium.is_chromatic()) {
            (MediumKind::Homogeneous { .. }, false) => Tracker::Analytic,
            (MediumKind::Homogeneous { .. }, true) => Tracker::AnalyticSpectral,
            (MediumKind::Heterogeneous(_), false) => Tracker::Delta,
            (MediumKind::Heterogeneous(_), true) => Tracker::Spectral,
        }
    }

    /// A short human-readable description, for `zerovar check`.
    pub fn describe(&self) -> &'static str {
        match self {
            Tracker::Analytic => "closed-form exponential sampling",
            Tracker::AnalyticSpectral => "closed-form sampling with channel MIS (chromatic)",
            Tracker::Delta => "delta tracking, ratio-tracking shadow rays",
            Tracker::Spectral => "spectral tracking (chromatic), ratio-tracking shadow rays",
        }
    }
}

/// Where a free flight ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FlightEvent {
    /// A real scattering event at distance `t`.
    Scatter {
        /// Ray parameter of the event.
        t: f32,
    },
    /// The flight passed `t_max` (to the next surface or to infinity).
    Escape,
}

/// The outcome of a free flight: the event, the per-channel factor for the path throughput and
/// the medium emission collected on the way (already multiplied by the incoming throughput).
#[derive(Clone, Copy, Debug)]
pub struct Flight {
    /// Where the flight ended.
    pub event: FlightEvent,
    /// Multiplies the path throughput; for a scatter it includes the albedo.
    pub weight: Spectrum,
    /// Emitted radiance collected along the flight.
    pub emitted: Spectrum,
}

/// Samples a free flight along `ray` within `(0, t_max)` for a path of throughput `beta`.
pub fn sample_flight(
    medium: &Medium,
    tracker: Tracker,
    ray: &Ray,
    t_max: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Flight {
    match (&medium.kind, tracker) {
        (MediumKind::Homogeneous { sigma_t, albedo }, Tracker::Analytic) => {
            analytic_grey(medium, sigma_t.x, *albedo, t_max, beta, sampler)
        }
        (MediumKind::Homogeneous { sigma_t, albedo }, _) => {
            analytic_spectral(medium, *sigma_t, *albedo, t_max, beta, sampler)
        }
        (MediumKind::Heterogeneous(h), _) => {
            let escape = Flight {
                event: FlightEvent::Escape,
                weight: Spectrum::ONE,
                emitted: Spectrum::ZERO,
            };
            let Some((t0, t1)) = h.clip(ray, t_max) else { return escape };
            let majorant = h.majorant().max_element();
            if majorant <= 0.0 {
                return escape;
            }
            if tracker == Tracker::Spectral {
                spectral_tracking(medium, ray, t0, t1, majorant, beta, sampler, counters)
            } else {
                delta_tracking(medium, ray, t0, t1, majorant, beta, sampler, counters)
            }
        }
    }
}

/// An exponential step of rate `rate`; `u` in [0, 1).
#[inline]
fn exp_step(u: f32, rate: f32) -> f32 {
    -(-u).ln_1p() / rate
}

fn analytic_grey(
    medium: &Medium,
    sigma_t: f32,
    albedo: Spectrum,
    t_max: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
) -> Flight {
    let t = exp_step(sampler.next_1d(), sigma_t);
    if t >= t_max || !t.is_finite() {
        return Flight {
            event: FlightEvent::Escape,
            weight: Spectrum::ONE,
            emitted: Spectrum::ZERO,
        };
    }
    // Collision estimator of the emission: the collision density is sigma_t T(t).
    let emitted = beta * (Spectrum::ONE - albedo) * medium.emission;
    Flight { event: FlightEvent::Scatter { t }, weight: albedo, emitted }
}

fn analytic_spectral(
    medium: &Medium,
    sigma_t: Spectrum,
    albedo: Spectrum,
    t_max: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
) -> Flight {
    // One-sample MIS over channels, each picked in proportion to the path's throughput in it
    // (history-aware): the weights then keep the sum of the throughput's channels, where a
    // uniform pick lets per-channel weights multiply up along deep paths.
    let total = beta.element_sum();
    let pick = if total > 0.0 { beta / total } else { Spectrum::splat(1.0 / 3.0) };
    let u = sampler.next_1d();
    let channel = if u < pick.x {
        0
    } else if u < pick.x + pick.y || pick.z == 0.0 {
        1
    } else {
        2
    };
    let t = exp_step(sampler.next_1d(), sigma_t[channel]);
    if t >= t_max || !t.is_finite() {
        let tr = transmittance_homogeneous(sigma_t, t_max);
        let p = pick.dot(tr);
        let weight = if p > 0.0 { tr / p } else { Spectrum::ZERO };
        return Flight { event: FlightEvent::Escape, weight, emitted: Spectrum::ZERO };
    }
    let tr = transmittance_homogeneous(sigma_t, t);
    let pdf = pick.dot(sigma_t * tr);
    let w = tr / pdf;
    let sigma_s = sigma_t * albedo;
    let emitted = beta * w * (sigma_t - sigma_s) * medium.emission;
    Flight { event: FlightEvent::Scatter { t }, weight: w * sigma_s, emitted }
}

/// `exp(-sigma_t t)` per channel, with `0 * inf` read as no extinction.
#[inline]
pub fn transmittance_homogeneous(sigma_t: Spectrum, t: f32) -> Spectrum {
    let tau = Spectrum::select(sigma_t.cmpeq(Spectrum::ZERO), Spectrum::ZERO, sigma_t * t);
    Spectrum::new((-tau.x).exp(), (-tau.y).exp(), (-tau.z).exp())
}

#[allow(clippy::too_many_arguments)]
fn delta_tracking(
    medium: &Medium,
    ray: &Ray,
    t0: f32,
    t1: f32,
    majorant: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Flight {
    let emissive = medium.is_emissive();
    let mut emitted = Spectrum::ZERO;
    let mut t = t0;
    loop {
        t += exp_step(sampler.next_1d(), majorant);
        if t >= t1 {
            return Flight { event: FlightEvent::Escape, weight: Spectrum::ONE, emitted };
        }
        let c = medium.coefficients(ray.at(t));
        counters.density_lookups += 1;
        let sigma_t = c.sigma_t.x;
        if emissive {
            // Every tentative collision scores sigma_a L_e / majorant (a collision estimator).
            emitted += beta * (c.sigma_t - c.sigma_t * c.albedo) * medium.emission / majorant;
        }
        if sampler.next_1d() * majorant < sigma_t {
            return Flight { event: FlightEvent::Scatter { t }, weight: c.albedo, emitted };
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn spectral_tracking(
    medium: &Medium,
    ray: &Ray,
    t0: f32,
    t1: f32,
    majorant: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Flight {
    let emissive = medium.is_emissive();
    let mut emitted = Spectrum::ZERO;
    let mut weight = Spectrum::ONE;
    let mut t = t0;
    loop {
        t += exp_step(sampler.next_1d(), majorant);
        if t >= t1 {
            return Flight { event: FlightEvent::Escape, weight, emitted };
        }
        let c = medium.coefficients(ray.at(t));
        counters.density_lookups += 1;
        let sigma_s = c.sigma_t * c.albedo;
        let sigma_n = (Spectrum::splat(majorant) - c.sigma_t).max(Spectrum::ZERO);
        let path = beta * weight;
        if emissive {
            emitted += path * (c.sigma_t - sigma_s) * medium.emission / majorant;
        }
        // History-aware probabilities: proportional to the weighted scatter and null terms.
        let p_s = channel_mean(path * sigma_s);
        let p_n = channel_mean(path * sigma_n);
        let total = p_s + p_n;
        if total.is_nan() || total <= 0.0 {
            return Flight { event: FlightEvent::Escape, weight: Spectrum::ZERO, emitted };
        }
        if sampler.next_1d() * total < p_s {
            weight *= sigma_s * (total / (majorant * p_s));
            return Flight { event: FlightEvent::Scatter { t }, weight, emitted };
        }
        weight *= sigma_n * (total / (majorant * p_n));
    }
}

/// An unbiased estimate of the transmittance along `ray` over `(0, t_max)` in `medium`.
pub fn transmittance(
    medium: &Medium,
    ray: &Ray,
    t_max: f32,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    match &medium.kind {
        MediumKind::Homogeneous { sigma_t, .. } => transmittance_homogeneous(*sigma_t, t_max),
        MediumKind::Heterogeneous(h) => {
            let Some((t0, t1)) = h.clip(ray, t_max) else { return Spectrum::ONE };
            let majorant = h.majorant().max_element();
            if majorant <= 0.0 {
                return Spectrum::ONE;
            }
            // Ratio tracking. Once the estimate is small, Russian roulette at each further
            // collision bounds the cost in dense media without bias; surviving with 1/2 only
            // doubles the estimate, which keeps it far from a firefly.
            let mut tr = Spectrum::ONE;
            let mut t = t0;
            loop {
                t += exp_step(sampler.next_1d(), majorant);
                if t >= t1 {
                    return tr;
                }
                let c = h.coefficients(ray.at(t));
                counters.density_lookups += 1;
                tr *= (Spectrum::ONE - c.sigma_t / majorant).max(Spectrum::ZERO);
                let m = tr.max_element();
                if m <= 0.0 {
                    return Spectrum::ZERO;
                }
                if m < 0.05 {
                    if sampler.next_1d() >= 0.5 {
                        return Spectrum::ZERO;
                    }
                    tr *= 2.0;
                }
            }
        }
    }
}
