//! Guided flights that keep standard tracking's collision density: distance alpha 0 (the
//! default) in a grey, homogeneous, non-emissive medium, the fog of most scenes.
//!
//! There the mixture of `distance::GuidedDistance` reduces to the exponential free path, whose
//! weights are the albedo at a collision and 1 past the ray's end, and what is left of guiding
//! is the extra collision for delta lights. Done in closed form, a flight costs about four
//! transcendental functions instead of sixteen: the transmittance to the flight's collision is
//! `1 - u` of its own draw, and to the extra one the part's decay power times its offset's.
//! The densities are those `GuidedDistance` reports for the same flight (a test compares them).

use super::RadianceCache;
use super::equiangular::Equiangular;
use super::flight::{
    CUT, DirectStretch, ExtraCollision, GuidedEvent, GuidedFlight, direct_stretch,
    equiangular_share, power_heuristic,
};
use crate::lights::PointLight;
use crate::math::{Ray, Spectrum};
use crate::rng::Sampler;

/// A flight along `ray` within `(0, t_max)` through a medium of extinction `sigma` (grey) and
/// single-scattering albedo `albedo`, with an extra collision for delta lights when
/// `extra_nee` gives the point and spot lights (its placement asks `cache` about HG with
/// `g`, and aims at the point lights too).
#[allow(clippy::too_many_arguments)]
pub(super) fn plain_flight(
    sigma: f32,
    albedo: Spectrum,
    g: f32,
    ray: &Ray,
    t_max: f32,
    extra_nee: Option<&[PointLight]>,
    cache: &mut impl RadianceCache,
    sampler: &mut Sampler,
) -> GuidedFlight {
    let pass = GuidedFlight::new(GuidedEvent::Pass, Spectrum::ONE, 1.0);
    if !(sigma > 0.0 && t_max > 0.0) {
        return pass; // nothing to collide with, or no room to
    }
    // The flight: transmittance `survive` to `t`, density `sigma survive`.
    let u = sampler.next_1d();
    let survive = 1.0 - u;
    let t = -survive.ln() / sigma; // 1 - u is exact
    let collides = t < t_max;
    let mut flight =
        if collides { GuidedFlight::new(GuidedEvent::Scatter { t }, albedo, 1.0) } else { pass };
    let Some(points) = extra_nee else { return flight };
    let guided_end = t_max.min(CUT / sigma);
    let d = direct_stretch(
        ray,
        guided_end,
        Spectrum::splat(sigma),
        Spectrum::splat(1.0 / 3.0),
        g,
        cache,
    );
    let towards = Equiangular::new(ray, guided_end, points);
    let Some(share) = equiangular_share(&d, towards.is_some()) else { return flight };
    let (collide, decay) = (d.collide.x, d.decay.x);
    // The extra collision's density at `t` in part `j`, whose transmittance from the part's
    // start is `within`: the grid's, mixed with the equiangular one.
    let density = |t: f32, j: usize, within: f32| {
        let grid = part_density(&d, j, within, sigma);
        towards.as_ref().map_or(grid, |e| (1.0 - share) * grid + share * e.pdf(t))
    };
    let u = sampler.next_1d();
    let drawn = match &towards {
        Some(e) if u < share => {
            // (Without grid weights the parts' decay is not computed: the transmittance
            // directly.)
            let t = e.sample(u / share, sampler.next_1d(), guided_end);
            let j = d.part_of(t);
            let within = (-sigma * (t - j as f32 * d.length)).exp();
            Some((t, j, within, (-sigma * t).exp()))
        }
        _ => d.pick((u - share) / (1.0 - share)).map(|j| {
            // The offset in part j: its truncated exponential, kept inside the part.
            let v = sampler.next_1d();
            let mut within = 1.0 - v * collide; // transmittance from the part's start
            let mut x = -(-v * collide).ln_1p() / sigma;
            let last = d.length * (1.0 - 1e-6);
            if x >= last {
                x = last;
                within = (-sigma * x).exp();
            }
            (j as f32 * d.length + x, j, within, decay.powi(j as i32) * within)
        }),
    };
    if let Some((t, j, within, transmittance)) = drawn
        && let direct = density(t, j, within)
        && direct > 0.0
    {
        let own = sigma * transmittance;
        // T sigma_s = albedo own.
        let weight = albedo * (own * power_heuristic(direct, own) / direct);
        flight.extra = Some(ExtraCollision { t, weight });
    }
    if collides && t < guided_end {
        // The power heuristic's share of the flight's own collision.
        let j = d.part_of(t);
        let within = survive / decay.powi(j as i32);
        let own = sigma * survive;
        flight.delta_share = power_heuristic(own, density(t, j, within));
    }
    flight
}

/// The grid's part of the extra collision's density at a point of part `j` whose
/// transmittance from the part's start is `within`.
#[inline]
fn part_density(d: &DirectStretch, j: usize, within: f32, sigma: f32) -> f32 {
    if d.weights[j] > 0.0 { d.weights[j] / d.total * sigma * within / d.collide.x } else { 0.0 }
}
