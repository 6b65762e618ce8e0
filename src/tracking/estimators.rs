//! The free-flight and transmittance estimators, generic over what a ray sees (`TrackedRay`):
//! a sequence of spans with local bounds, and coefficient lookups. Every tentative collision
//! that reads the density counts one density lookup.
//!
//! Absorption is never sampled as an event: a scatter's weight carries the albedo, and medium
//! emission is scored by collision estimators (each tentative collision scores the absorption
//! it stands for divided by the rate or probability it was drawn with), so every tracker
//! handles emission without a separate path.

use super::steer::{Steer, Tentative};
use super::{Flight, FlightEvent, TrackedRay};
use crate::math::{Spectrum, channel_mean, luminance};
use crate::media::Coefficients;
use crate::rng::Sampler;
use crate::stats::Counters;

/// An exponential step of rate `rate`; `u` in [0, 1).
#[inline]
pub(super) fn exp_step(u: f32, rate: f32) -> f32 {
    unit_exponential(u) / rate
}

/// `-ln(1 - u)`, an exponential variate of rate one from `u` in [0, 1). The sampler's `u` is a
/// multiple of 2^-24, so `1 - u` is exact and `ln` (several times cheaper than `ln_1p`) loses
/// nothing.
#[inline]
pub(crate) fn unit_exponential(u: f32) -> f32 {
    -(1.0 - u).ln()
}

#[inline]
fn escape(weight: Spectrum, emitted: Spectrum) -> Flight {
    Flight { event: FlightEvent::Escape, weight, emitted }
}

#[inline]
fn scatter(t: f32, weight: Spectrum, emitted: Spectrum) -> Flight {
    Flight { event: FlightEvent::Scatter { t }, weight, emitted }
}

/// Tentative collisions at `rate` over `(t0, t1)`, one density lookup each: `visit(t,
/// coefficients, sampler, counters)` decides at each, and its first `Some` ends the walk. The
/// exponential restarts at every span boundary, which its memorylessness allows.
#[inline]
fn tentative<R: TrackedRay, T>(
    r: &R,
    (t0, t1): (f32, f32),
    rate: f32,
    (s, c): (&mut Sampler, &mut Counters),
    mut visit: impl FnMut(f32, Coefficients, &mut Sampler, &mut Counters) -> Option<T>,
) -> Option<T> {
    if rate <= 0.0 {
        return None;
    }
    let mut t = t0;
    loop {
        t += exp_step(s.next_1d(), rate);
        if t >= t1 {
            return None;
        }
        let co = r.coefficients(t);
        c.density_lookups += 1;
        if let Some(v) = visit(t, co, s, c) {
            return Some(v);
        }
    }
}

/// The emission `sigma_a L_e` of extinction `sigma` with albedo `albedo`.
#[inline]
fn absorbed(sigma: Spectrum, albedo: Spectrum, emission: Spectrum) -> Spectrum {
    sigma * (Spectrum::ONE - albedo) * emission
}

/// Regular tracking: exact optical depth span by span, for piecewise-constant extinction
/// (each span's majorant is its extinction). Grey.
pub(super) fn regular<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    s: &mut Sampler,
    c: &mut Counters,
) -> Flight {
    let target = unit_exponential(s.next_1d());
    let mut acc = 0.0f32;
    for seg in r.segments() {
        let mu = seg.majorant.max_element();
        c.density_lookups += 1;
        if mu <= 0.0 {
            continue;
        }
        let d = mu * (seg.t1 - seg.t0);
        if acc + d > target {
            let t = seg.t0 + (target - acc) / mu;
            let a = r.albedo(t);
            return scatter(t, a, beta * (Spectrum::ONE - a) * emission);
        }
        acc += d;
    }
    escape(Spectrum::ONE, Spectrum::ZERO)
}

/// Optical depths per step of ray marching, at the span's majorant.
const MARCH_TAU: f32 = 1.0;

/// Ray marching: midpoint-rule optical depth with a fixed stride (one optical depth at the
/// span's majorant). BIASED: kept as a baseline only. Grey.
pub(super) fn ray_marching<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    s: &mut Sampler,
    c: &mut Counters,
) -> Flight {
    let target = unit_exponential(s.next_1d());
    let mut acc = 0.0f32;
    for seg in r.segments() {
        let mu_bar = seg.majorant.max_element();
        if mu_bar <= 0.0 {
            continue;
        }
        let h = MARCH_TAU / mu_bar;
        let mut t = seg.t0;
        while t < seg.t1 {
            let end = (t + h).min(seg.t1);
            let co = r.coefficients(0.5 * (t + end));
            c.density_lookups += 1;
            let mu = co.sigma_t.x;
            let d = mu * (end - t);
            if acc + d > target {
                let tc = t + (target - acc) / mu;
                return scatter(tc, co.albedo, beta * (Spectrum::ONE - co.albedo) * emission);
            }
            acc += d;
            t = end;
        }
    }
    escape(Spectrum::ONE, Spectrum::ZERO)
}

/// Delta (Woodcock) tracking against each span's majorant (restarted at span boundaries, which
/// the exponential's memorylessness allows). Grey; analog: needs majorants that bound.
pub(super) fn delta<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    s: &mut Sampler,
    c: &mut Counters,
    steer: &mut impl Steer,
) -> Flight {
    let emissive = emission.max_element() > 0.0;
    let mut emitted = Spectrum::ZERO;
    for seg in r.segments() {
        let mu_bar = seg.majorant.max_element();
        let hit = tentative(r, (seg.t0, seg.t1), mu_bar, (s, c), |t, co, s, c| {
            let sigma_t = co.sigma_t.x;
            if emissive {
                emitted += beta * absorbed(co.sigma_t, co.albedo, emission) / mu_bar * steer.gain();
            }
            let u = s.next_1d();
            let at = Tentative {
                t,
                p_std: sigma_t / mu_bar,
                scatter: luminance(beta * co.albedo) * sigma_t,
                null: luminance(beta) * (mu_bar - sigma_t),
            };
            steer.scatters(at, u, u * mu_bar < sigma_t, c).then(|| scatter(t, co.albedo, emitted))
        });
        if let Some(flight) = hit {
            return flight;
        }
    }
    escape(Spectrum::ONE, emitted)
}

/// Weighted delta tracking (seed section 3.4): the majorant may under-estimate; real and null
/// collisions are picked in proportion to `|mu_t|` and `|mu_bar - mu_t|` and the weight takes
/// the signed ratio. Grey.
pub(super) fn weighted_delta<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    s: &mut Sampler,
    c: &mut Counters,
    steer: &mut impl Steer,
) -> Flight {
    let emissive = emission.max_element() > 0.0;
    let mut emitted = Spectrum::ZERO;
    let mut w = 1.0f32;
    for seg in r.segments() {
        let mu_bar = seg.majorant.max_element();
        let hit = tentative(r, (seg.t0, seg.t1), mu_bar, (s, c), |t, co, s, c| {
            let mu_t = co.sigma_t.x;
            let mu_n = mu_bar - mu_t;
            if emissive {
                emitted +=
                    beta * w * absorbed(co.sigma_t, co.albedo, emission) / mu_bar * steer.gain();
            }
            let total = mu_t.abs() + mu_n.abs();
            let u = s.next_1d();
            let path = luminance(beta).abs() * w.abs();
            let at = Tentative {
                t,
                p_std: mu_t.abs() / total,
                scatter: path * luminance(co.albedo) * mu_t.abs(),
                null: path * mu_n.abs(),
            };
            if steer.scatters(at, u, u * total < mu_t.abs(), c) {
                w *= mu_t.signum() * total / mu_bar;
                return Some(scatter(t, co.albedo * w, emitted));
            }
            w *= mu_n.signum() * total / mu_bar;
            None
        });
        if let Some(flight) = hit {
            return flight;
        }
    }
    escape(Spectrum::splat(w), emitted)
}

/// Analog decomposition tracking (seed section 4.1): a closed-form flight in the control (each
/// span's minorant, no lookup) races delta tracking of the residual against its own majorant
/// (span majorant minus minorant); the first collision wins. Grey; needs bounding spans.
pub(super) fn decomposition<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    s: &mut Sampler,
    c: &mut Counters,
    steer: &mut impl Steer,
) -> Flight {
    let emissive = emission.max_element() > 0.0;
    let mut emitted = Spectrum::ZERO;
    for seg in r.segments() {
        let mu_c = seg.minorant.min_element().max(0.0);
        let mu_r = (seg.majorant.max_element() - mu_c).max(0.0);
        let t_c = if mu_c > 0.0 { seg.t0 + exp_step(s.next_1d(), mu_c) } else { f32::INFINITY };
        let end = t_c.min(seg.t1);
        let hit = tentative(r, (seg.t0, end), mu_r, (s, c), |t, co, s, c| {
            let residual = co.sigma_t.x - mu_c;
            if emissive {
                let sigma = co.sigma_t - Spectrum::splat(mu_c);
                emitted += beta * absorbed(sigma, co.albedo, emission) / mu_r * steer.gain();
            }
            let u = s.next_1d();
            let at = Tentative {
                t,
                p_std: residual / mu_r,
                scatter: luminance(beta * co.albedo) * residual,
                null: luminance(beta) * (mu_r - residual),
            };
            steer.scatters(at, u, u * mu_r < residual, c).then(|| scatter(t, co.albedo, emitted))
        });
        if let Some(flight) = hit {
            return flight;
        }
        if t_c < seg.t1 {
            let a = r.albedo(t_c);
            let own = beta * (Spectrum::ONE - a) * emission * steer.gain();
            return scatter(t_c, a, emitted + own);
        }
    }
    escape(Spectrum::ONE, emitted)
}

/// The sampling rate of a weighted decomposition: the span majorant, or twice the control when
/// the control exceeds it (any rate above the control keeps the estimator unbiased). A span
/// whose bounds coincide is taken as constant: its control then carries every collision.
#[inline]
fn decomposition_rate(mu_bar: f32, mu_c: f32) -> f32 {
    if mu_bar >= mu_c { mu_bar } else { 2.0 * mu_c }
}

/// Weighted decomposition tracking (seed section 4.2): one collision stream at the span
/// majorant; the control is picked with probability `mu_c / mu_bar` without a lookup, otherwise
/// residual and null collisions are picked by magnitude with signed weights, so neither the
/// control nor the majorant needs to bound. Grey.
pub(super) fn weighted_decomposition<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    s: &mut Sampler,
    c: &mut Counters,
    steer: &mut impl Steer,
) -> Flight {
    let emissive = emission.max_element() > 0.0;
    let mut emitted = Spectrum::ZERO;
    let mut w = 1.0f32;
    for seg in r.segments() {
        let mu_c = seg.minorant.min_element().max(0.0);
        let rate = decomposition_rate(seg.majorant.max_element(), mu_c);
        if rate <= 0.0 {
            continue;
        }
        let p_c = mu_c / rate;
        let q = 1.0 - p_c;
        let mut t = seg.t0;
        loop {
            t += exp_step(s.next_1d(), rate);
            if t >= seg.t1 {
                break;
            }
            if s.next_1d() < p_c {
                // Control collision: weight mu_c / (rate p_c) = 1.
                let a = r.albedo(t);
                emitted += beta * w * (Spectrum::ONE - a) * emission * steer.gain();
                return scatter(t, a * w, emitted);
            }
            let co = r.coefficients(t);
            c.density_lookups += 1;
            let residual = co.sigma_t.x - mu_c;
            let null = rate - co.sigma_t.x;
            if emissive {
                let sigma = co.sigma_t - Spectrum::splat(mu_c);
                emitted +=
                    beta * w * absorbed(sigma, co.albedo, emission) / (rate * q) * steer.gain();
            }
            let total = residual.abs() + null.abs();
            let u = s.next_1d();
            let path = luminance(beta).abs() * w.abs();
            let at = Tentative {
                t,
                p_std: residual.abs() / total,
                scatter: path * luminance(co.albedo) * residual.abs(),
                null: path * null.abs(),
            };
            if steer.scatters(at, u, u * total < residual.abs(), c) {
                w *= residual.signum() * total / (rate * q);
                return scatter(t, co.albedo * w, emitted);
            }
            w *= null.signum() * total / (rate * q);
        }
    }
    escape(Spectrum::splat(w), emitted)
}

/// How spectral tracking sets its collision probabilities (Kutz et al. 2017).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpectralProbabilities {
    /// In proportion to the largest channel of each coefficient.
    Max,
    /// In proportion to the channel average of each coefficient.
    Average,
    /// In proportion to the channel average of the coefficient times the path throughput.
    History,
}

/// An event inside spectral tracking, reported to an observer with the path throughput after
/// it (the incoming throughput times the flight's weight so far).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpectralEvent {
    /// A null collision.
    Null,
    /// A real scattering collision (the weight includes the albedo).
    Scatter,
}

#[inline]
fn probability(p: SpectralProbabilities, path: Spectrum, sigma: Spectrum) -> f32 {
    match p {
        SpectralProbabilities::Max => sigma.abs().max_element(),
        SpectralProbabilities::Average => channel_mean(sigma.abs()),
        SpectralProbabilities::History => channel_mean((path * sigma).abs()),
    }
}

/// Spectral tracking: one collision stream at the largest channel of each span's majorant,
/// scatter and null picked with the chosen probabilities, per-channel weights `mu_x / (mu_bar
/// P_x)` (signed, so an under-estimating majorant stays unbiased).
#[allow(clippy::too_many_arguments)]
pub(super) fn spectral<R: TrackedRay>(
    r: &R,
    probs: SpectralProbabilities,
    emission: Spectrum,
    beta: Spectrum,
    (s, c): (&mut Sampler, &mut Counters),
    steer: &mut impl Steer,
    observe: &mut impl FnMut(SpectralEvent, Spectrum),
) -> Flight {
    let emissive = emission.max_element() > 0.0;
    let mut emitted = Spectrum::ZERO;
    let mut w = Spectrum::ONE;
    for seg in r.segments() {
        let mu_bar = seg.majorant.max_element();
        let hit = tentative(r, (seg.t0, seg.t1), mu_bar, (s, c), |t, co, s, c| {
            let sigma_s = co.sigma_t * co.albedo;
            let sigma_n = Spectrum::splat(mu_bar) - co.sigma_t;
            let path = beta * w;
            if emissive {
                emitted += path * absorbed(co.sigma_t, co.albedo, emission) / mu_bar * steer.gain();
            }
            let p_s = probability(probs, path, sigma_s);
            let p_n = probability(probs, path, sigma_n);
            let total = p_s + p_n;
            if total.is_nan() || total <= 0.0 {
                return Some(escape(Spectrum::ZERO, emitted));
            }
            let u = s.next_1d();
            let at = Tentative {
                t,
                p_std: p_s / total,
                scatter: luminance((path * sigma_s).abs()),
                null: luminance((path * sigma_n).abs()),
            };
            if steer.scatters(at, u, u * total < p_s, c) {
                w *= sigma_s * (total / (mu_bar * p_s));
                observe(SpectralEvent::Scatter, beta * w);
                return Some(scatter(t, w, emitted));
            }
            w *= sigma_n * (total / (mu_bar * p_n));
            observe(SpectralEvent::Null, beta * w);
            None
        });
        if let Some(flight) = hit {
            return flight;
        }
    }
    escape(w, emitted)
}

/// Spectral tracking combined with weighted decomposition: per channel the control is each
/// span's minorant; the control is picked with a history-aware probability and costs no
/// lookup; otherwise residual scatter and null are picked history-aware, as in `spectral`.
#[allow(clippy::too_many_arguments)]
pub(super) fn spectral_decomposition<R: TrackedRay>(
    r: &R,
    emission: Spectrum,
    beta: Spectrum,
    (s, c): (&mut Sampler, &mut Counters),
    steer: &mut impl Steer,
    observe: &mut impl FnMut(SpectralEvent, Spectrum),
) -> Flight {
    let emissive = emission.max_element() > 0.0;
    let mut emitted = Spectrum::ZERO;
    let mut w = Spectrum::ONE;
    for seg in r.segments() {
        let mu_c = seg.minorant.max(Spectrum::ZERO);
        let rate = decomposition_rate(seg.majorant.max_element(), mu_c.max_element());
        if rate <= 0.0 {
            continue;
        }
        let mut t = seg.t0;
        loop {
            t += exp_step(s.next_1d(), rate);
            if t >= seg.t1 {
                break;
            }
            let path = beta * w;
            let norm = channel_mean(path.abs());
            if norm.is_nan() || norm <= 0.0 {
                return escape(Spectrum::ZERO, emitted);
            }
            let p_c = channel_mean((path * mu_c).abs()) / (rate * norm);
            let u = s.next_1d();
            if u < p_c {
                let a = r.albedo(t);
                let f = mu_c / (rate * p_c);
                emitted += path * f * (Spectrum::ONE - a) * emission * steer.gain();
                w *= f * a;
                observe(SpectralEvent::Scatter, beta * w);
                return scatter(t, w, emitted);
            }
            let q = 1.0 - p_c;
            let co = r.coefficients(t);
            c.density_lookups += 1;
            let residual = co.sigma_t - mu_c;
            let residual_s = residual * co.albedo;
            let null = Spectrum::splat(rate) - co.sigma_t;
            if emissive {
                emitted +=
                    path * absorbed(residual, co.albedo, emission) / (rate * q) * steer.gain();
            }
            let p_s = channel_mean((path * residual_s).abs());
            let p_n = channel_mean((path * null).abs());
            let total = p_s + p_n;
            if total.is_nan() || total <= 0.0 {
                return escape(Spectrum::ZERO, emitted);
            }
            let u = s.next_1d();
            let at = Tentative {
                t,
                p_std: p_s / total,
                scatter: luminance((path * residual_s).abs()),
                null: luminance((path * null).abs()),
            };
            if steer.scatters(at, u, u * total < p_s, c) {
                w *= residual_s * (total / (rate * q * p_s));
                observe(SpectralEvent::Scatter, beta * w);
                return scatter(t, w, emitted);
            }
            w *= null * (total / (rate * q * p_n));
            observe(SpectralEvent::Null, beta * w);
        }
    }
    escape(w, emitted)
}

/// Russian roulette for transmittance estimates: once the estimate is small, survive with 1/2
/// and double, which bounds the cost in dense media without bias.
#[inline]
fn roulette(tr: &mut Spectrum, s: &mut Sampler) -> bool {
    let m = tr.abs().max_element();
    if m.is_nan() || m <= 0.0 {
        return false;
    }
    if m < 0.05 {
        if s.next_1d() >= 0.5 {
            return false;
        }
        *tr *= 2.0;
    }
    true
}

/// Ratio tracking: the product of `1 - mu_t / mu_bar` over tentative collisions at each span's
/// majorant (signed factors, so an under-estimating majorant stays unbiased).
pub(super) fn ratio<R: TrackedRay>(r: &R, s: &mut Sampler, c: &mut Counters) -> Spectrum {
    let mut tr = Spectrum::ONE;
    for seg in r.segments() {
        let mu_bar = seg.majorant.max_element();
        let ended = tentative(r, (seg.t0, seg.t1), mu_bar, (s, c), |_, co, s, _| {
            tr *= Spectrum::ONE - co.sigma_t / mu_bar;
            (!roulette(&mut tr, s)).then_some(())
        });
        if ended.is_some() {
            return Spectrum::ZERO;
        }
    }
    tr
}

/// Residual ratio tracking: `exp(-mu_c d)` of each span's control (its minorant) times ratio
/// tracking of the residual `mu_t - mu_c` at the residual majorant. Exact control: no lookups
/// and zero variance.
pub(super) fn residual_ratio<R: TrackedRay>(r: &R, s: &mut Sampler, c: &mut Counters) -> Spectrum {
    let mut tr = Spectrum::ONE;
    for seg in r.segments() {
        let mu_c = seg.minorant.max(Spectrum::ZERO);
        let len = seg.t1 - seg.t0;
        tr *= super::transmittance_homogeneous(mu_c, len);
        let mu_r = (seg.majorant - mu_c).abs().max_element();
        let ended = tentative(r, (seg.t0, seg.t1), mu_r, (s, c), |_, co, s, _| {
            tr *= Spectrum::ONE - (co.sigma_t - mu_c) / mu_r;
            (!roulette(&mut tr, s)).then_some(())
        });
        if ended.is_some() {
            return Spectrum::ZERO;
        }
    }
    tr
}

/// Exact transmittance through piecewise-constant spans.
pub(super) fn regular_transmittance<R: TrackedRay>(r: &R, c: &mut Counters) -> Spectrum {
    let mut tr = Spectrum::ONE;
    for seg in r.segments() {
        c.density_lookups += 1;
        tr *= super::transmittance_homogeneous(seg.majorant, seg.t1 - seg.t0);
    }
    tr
}

/// Ray-marched transmittance (midpoint rule, BIASED).
pub(super) fn marched_transmittance<R: TrackedRay>(r: &R, c: &mut Counters) -> Spectrum {
    let mut tau = Spectrum::ZERO;
    for seg in r.segments() {
        let mu_bar = seg.majorant.max_element();
        if mu_bar <= 0.0 {
            continue;
        }
        if !(seg.t1 - seg.t0).is_finite() {
            // An unbounded span is homogeneous: its majorant is its extinction.
            return super::transmittance_homogeneous(seg.majorant, seg.t1 - seg.t0);
        }
        let h = MARCH_TAU / mu_bar;
        let mut t = seg.t0;
        while t < seg.t1 {
            let end = (t + h).min(seg.t1);
            tau += r.coefficients(0.5 * (t + end)).sigma_t * (end - t);
            c.density_lookups += 1;
            t = end;
        }
    }
    Spectrum::new((-tau.x).exp(), (-tau.y).exp(), (-tau.z).exp())
}

#[cfg(test)]
mod tests {
    use super::unit_exponential;

    #[test]
    fn unit_exponential_is_accurate_over_every_sampler_value() {
        // Every 251st multiple of 2^-24 in [0, 1), the ends included: within 2 ulp of f64.
        let mut worst = 0.0f64;
        for k in (0..1u32 << 24).step_by(251).chain([1, (1 << 24) - 1]) {
            let u = k as f32 * (1.0 / (1u32 << 24) as f32);
            let exact = -(-f64::from(u)).ln_1p();
            let got = f64::from(unit_exponential(u));
            if exact > 0.0 {
                let ulp = 2f64.powi(exact.log2().floor() as i32 - 23);
                worst = worst.max((got - exact).abs() / ulp);
            } else {
                assert_eq!(got, 0.0);
            }
        }
        assert!(worst <= 2.0, "worst error {worst} ulp");
    }
}
