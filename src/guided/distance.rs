//! Guided distance sampling: the zero-variance collision density along a ray in a medium,
//! `p(t) ~ T(t) [sigma_s L_s(x_t, w) + sigma_a L_e] / L(x, w)`, with the end of the ray
//! (surface or infinity) as the remaining event.
//!
//! In heterogeneous media the transmittance is unknown, so guiding works in the
//! null-collision form (seed notes, section 3.2), on top of the medium's own tracker: it draws
//! its tentative collisions as always, and at each one that reads the density a steer
//! (`tracking::Steer`) may scatter with a probability of its choice, the weight corrected by
//! its ratio to the tracker's. The zero-variance choice weighs in-scattered radiance
//! `sigma_s L_s` against the radiance the path finds by going on, `sigma_n L(x, w)`, with the
//! cache read again where the ray leaves its region; mixing it with the tracker's own choice
//! keeps it robust.
//!
//! In homogeneous media the ray's stretch inside the medium is cut into segments where it
//! leaves each of the cache's regions. For each segment the cache gives the conditional
//! probability of colliding in it once the walk has reached it (the estimated radiance the
//! segment sends back over the radiance entering it), and inside a segment the offset follows
//! a truncated exponential of a proxy coefficient. Segments are built lazily, only as far as
//! the walk goes (the incremental CDF: no normalisation pass over the whole ray), so a flight
//! pays one lookup per region it reaches. The
//! standard strategy uses the same segments with the exponential's own probabilities, so the
//! one-sample mixture `alpha p_guided + (1 - alpha) p_standard` has an exact density. The
//! weights use the exact transmittance, so every channel stays unbiased. There, too, a flight
//! may add an extra collision for next-event estimation of delta lights (see
//! [`guided_flight`]).

use super::RadianceCache;
use super::equiangular::Equiangular;
use super::flight::{
    CUT, DirectStretch, direct_stretch, equiangular_share, exp, exp_m1, power_heuristic,
};
pub use super::flight::{ExtraCollision, GuidedEvent, GuidedFlight, free_path_needs_extra};
use super::plain_flight::plain_flight;
use crate::lights::PointLight;
use crate::math::{Ray, Spectrum, is_grey, luminance, positive};
use crate::media::{Medium, MediumKind};
use crate::rng::Sampler;
use crate::stats::Counters;
use crate::tracking::{
    FlightEvent, MediumRay, Steer, Tentative, TrackedRay, Tracker, ratio_tracking,
    sample_flight_along, steered_flight_along, transmittance_homogeneous,
};

/// Equal parts a guided flight cuts its guided stretch into, besides the cache's region
/// boundaries: one, so a flight looks the cache up once per region it reaches. Equal parts
/// finer than the regions cost more lookups than they save, and extra collisions already
/// follow delta lights in 16 parts (see docs/experiments.md).
pub const SEGMENTS: usize = 1;
/// Most segments of the guided stretch (equal parts and region crossings together); the last
/// runs to the stretch's end, so a ray through many small regions costs at most this many
/// lookups.
pub const MAX_SEGMENTS: usize = 8;
/// The shortest segment a region boundary may cut, as a share of the guided stretch (of a
/// heterogeneous flight's stretch through the medium, for its refreshes): a ray grazing a
/// region's corner is not worth a lookup.
const MIN_SEGMENT: f32 = 1.0 / 32.0;
/// How many times a heterogeneous flight refreshes its cache estimates along the medium's
/// stretch at most: once per region its tentative collisions reach, up to this.
const REFRESHES: usize = MAX_SEGMENTS;
/// Bounds of the guided per-segment probability relative to the standard one, so a cache
/// that is wrong (zero, or off by orders of magnitude) can neither remove support nor force
/// every path into one segment.
const MIN_RELATIVE: f32 = 0.1;
const MAX_PROBABILITY: f32 = 0.95;

#[derive(Clone, Copy, Debug, Default)]
struct Segment {
    start: f32,
    length: f32,
    /// Per channel: the channel's weight times its transmittance to the segment's start,
    /// normalised to a largest entry of 1 (the mixture's mass still in play).
    mass: Spectrum,
    /// Per channel: 1 - exp(-sigma_c length).
    collide: Spectrum,
    /// The standard probability of colliding in the segment once there.
    p_std: f32,
    p_guided: f32,
}

/// The distance distribution of one ray through one medium.
#[derive(Clone, Debug)]
pub struct GuidedDistance {
    ray: Ray,
    /// The extinction per channel.
    sigma: Spectrum,
    alpha: f32,
    guided_end: f32,
    t_max: f32,
    lookup_u: f32,
    emission: f32,
    /// Equal parts of the guided stretch, and the one the next segment starts in.
    parts: usize,
    part: usize,
    /// Segments built so far: lazily, only as far as the walk goes (the incremental CDF).
    segments: [Segment; MAX_SEGMENTS + 1],
    built: usize,
    /// Where the last built segment of the guided stretch ends, and whether it ends the
    /// stretch; whether the last segment (the stretch's, or the tail) is built.
    reached: f32,
    stretch_done: bool,
    complete: bool,
    /// Whether the guided stretch reached the end of the ray (no tail segment).
    ends_at_t_max: bool,
    /// The standard strategy's weight of each channel (summing to 1).
    pick: Spectrum,
    /// The extra collision's weights, once computed.
    direct: Option<DirectStretch>,
    /// The extra collision's equiangular part, towards point lights (see [`aim_at`]).
    ///
    /// [`aim_at`]: Self::aim_at
    towards: Option<Equiangular>,
}

impl GuidedDistance {
    /// The distribution for `ray` over `(0, t_max)` in a homogeneous `medium`, or `None` when
    /// the ray cannot collide (empty medium) or the medium is heterogeneous.
    /// `alpha` is the probability of the guided strategy; `lookup_u` drives the cache's
    /// spatial filter for every lookup of this ray; the guided stretch is cut into `parts`
    /// equal parts ([`SEGMENTS`] in guided flights), and where `alpha` is above 0 also where
    /// the ray leaves each of the cache's regions, up to [`MAX_SEGMENTS`] segments.
    ///
    /// # Panics
    /// If `parts` is not within 1 to [`MAX_SEGMENTS`].
    ///
    /// The standard strategy is the one-sample mixture over channels of exponential free
    /// paths, each channel weighted by `pick` (the path throughput: history-aware, which keeps
    /// chromatic weights bounded); the guided one shares its shape inside each segment.
    pub fn new(
        medium: &Medium,
        ray: &Ray,
        t_max: f32,
        pick: Spectrum,
        alpha: f32,
        lookup_u: f32,
        parts: usize,
    ) -> Option<Self> {
        assert!((1..=MAX_SEGMENTS).contains(&parts), "{parts} segments");
        let MediumKind::Homogeneous { sigma_t: sigma, .. } = medium.kind else {
            // Heterogeneous media are guided in the null-collision form instead.
            return None;
        };
        let total = pick.element_sum();
        let pick = if total > 0.0 { pick / total } else { Spectrum::splat(1.0 / 3.0) };
        let mean = pick.dot(sigma);
        if !positive(mean) || t_max <= 0.0 || t_max.is_nan() {
            return None;
        }
        let guided_end = t_max.min(CUT / mean);
        Some(Self {
            ray: *ray,
            sigma,
            alpha,
            guided_end,
            t_max,
            lookup_u,
            emission: luminance(medium.emission),
            parts,
            part: 0,
            segments: [Segment::default(); MAX_SEGMENTS + 1],
            built: 0,
            reached: 0.0,
            stretch_done: false,
            complete: false,
            ends_at_t_max: guided_end >= t_max,
            pick,
            direct: None,
            towards: None,
        })
    }

    /// Lets the extra collision aim at point and spot `lights` too: its density becomes
    /// the mixture of the grid's with the equiangular one over the guided stretch
    /// (half of it where the grid knows of light along the ray, all of it where not).
    pub fn aim_at(&mut self, lights: &[PointLight]) {
        self.towards = Equiangular::new(&self.ray, self.guided_end, lights);
    }

    /// Builds the next segment, with its guided probability; false once every segment is
    /// built. A segment of the guided stretch ends at the end of its equal part, or where
    /// the ray leaves the cache's region (where guided; the last allowed segment runs to the
    /// stretch's end); past the stretch comes the tail, which follows the exponential.
    fn build_next(
        &mut self,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        counters: &mut Counters,
    ) -> bool {
        if self.complete {
            return false;
        }
        let k = self.built;
        let (start, end, mass) = if !self.stretch_done {
            // A segment of the guided stretch, from where the last one ended.
            let start = self.reached;
            let mass = match k.checked_sub(1) {
                None => self.pick,
                Some(j) => self.segments[j].mass * exp(-self.sigma * self.segments[j].length),
            };
            let end = self.segment_end(k, start, cache);
            self.stretch_done = end >= self.guided_end;
            self.reached = end;
            (start, end, mass)
        } else if self.ends_at_t_max {
            self.complete = true;
            return false;
        } else {
            // The tail, from the cut on: its mass from the start, which may lie many mean
            // free paths in.
            let start = self.guided_end;
            let log = Spectrum::select(
                self.pick.cmpgt(Spectrum::ZERO),
                ln(self.pick) - self.sigma * start,
                Spectrum::splat(f32::NEG_INFINITY),
            );
            self.complete = true;
            (start, self.t_max, exp(log - Spectrum::splat(log.max_element())))
        };
        let mass = Spectrum::select(mass.cmpgt(Spectrum::ZERO), mass, Spectrum::ZERO);
        let top = mass.max_element();
        let mass = if top > 0.0 { mass / top } else { mass };
        let length = end - start;
        let positive_sigma = self.sigma.cmpgt(Spectrum::ZERO);
        let collide = if length.is_finite() {
            Spectrum::select(positive_sigma, -exp_m1(-self.sigma * length), Spectrum::ZERO)
        } else {
            Spectrum::select(positive_sigma, Spectrum::ONE, Spectrum::ZERO)
        };
        let p_std = mass.dot(collide) / mass.element_sum();
        self.segments[k] = Segment { start, length, mass, collide, p_std, p_guided: p_std };
        self.built += 1;
        if !self.complete {
            self.compute(k, medium, cache, counters);
        }
        true
    }

    /// Where guided segment `k`, starting at `start`, ends: exactly at the stretch's end for
    /// the last one.
    fn segment_end(&mut self, k: usize, start: f32, cache: &impl RadianceCache) -> f32 {
        if k + 1 >= MAX_SEGMENTS {
            return self.guided_end;
        }
        let part_end = if self.part + 1 >= self.parts {
            self.guided_end
        } else {
            self.guided_end * (self.part + 1) as f32 / self.parts as f32
        };
        let mut end = part_end;
        if self.alpha > 0.0 {
            let shortest = MIN_SEGMENT * self.guided_end;
            // Probed a little inside, off the boundary the last segment ended on.
            let probe = start + 0.25 * shortest;
            let exit = probe + cache.region_exit(self.ray.at(probe), self.ray.direction);
            end = end.min(exit.max(start + shortest));
        }
        if end >= part_end {
            self.part += 1;
            end = part_end;
        }
        end
    }

    /// Computes the guided probability of segment `k` from the cache; nothing at `alpha` 0,
    /// where no guided probability counts, so that such flights pay for no lookup.
    fn compute(
        &mut self,
        k: usize,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        counters: &mut Counters,
    ) {
        let s = &mut self.segments[k];
        if self.alpha == 0.0 {
            return;
        }
        let mid = self.ray.at(s.start + 0.5 * s.length);
        counters.field_lookups += 1;
        let g = medium.phase.mean_cosine();
        let Some(e) = cache.estimates(mid, self.lookup_u, self.ray.direction, g) else {
            return;
        };
        let c = medium.coefficients(mid);
        let sigma_t = luminance(c.sigma_t);
        let sigma_s = luminance(c.sigma_t * c.albedo);
        if !(sigma_t > 0.0 && e.incident > 0.0) {
            // No collision expected here, or no light known to enter: keep the floor only.
            s.p_guided = MIN_RELATIVE * s.p_std;
            return;
        }
        let source = sigma_s * e.inscattered + (sigma_t - sigma_s).max(0.0) * self.emission;
        let collide = -(-sigma_t * s.length).exp_m1() / sigma_t;
        let raw = collide * source / e.incident;
        s.p_guided = if raw.is_finite() {
            raw.clamp(MIN_RELATIVE * s.p_std, MAX_PROBABILITY.max(s.p_std))
        } else {
            s.p_std
        };
    }

    /// Builds segments up to `k`; false when there is no segment `k`.
    fn ensure(
        &mut self,
        k: usize,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        counters: &mut Counters,
    ) -> bool {
        while self.built <= k {
            if !self.build_next(medium, cache, counters) {
                return false;
            }
        }
        true
    }

    /// Density of the offset `x` inside segment `s` (truncated exponential).
    fn offset_pdf(&self, s: &Segment, x: f32) -> f32 {
        let density = s.mass * self.sigma * exp(-self.sigma * x);
        density.element_sum() / s.mass.dot(s.collide)
    }

    /// Samples a collision distance, or `None` for passing the end of the ray; returns it with
    /// the mixture density of the distance (or the mixture probability of passing) and the
    /// standard strategy's density (or probability) over the mixture's.
    pub fn sample(
        &mut self,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        sampler: &mut Sampler,
        counters: &mut Counters,
    ) -> (Option<f32>, f32, f32) {
        // The standard strategy's density over the mixture's, zero where the mixture has none.
        let standard_share = |standard: f32, mix: f32| if mix > 0.0 { standard / mix } else { 0.0 };
        let guided = sampler.next_1d() < self.alpha;
        match self.draw(guided, medium, cache, sampler, counters) {
            Some((t, k, g, s)) => {
                let seg = self.segments[k];
                let mix = self.alpha * g * seg.p_guided + (1.0 - self.alpha) * s * seg.p_std;
                let density = mix * self.offset_pdf(&seg, t - seg.start);
                (Some(t), density, standard_share(s * seg.p_std, mix))
            }
            None => {
                // The draw went past every segment, so all are built.
                let (g, s) = self.survival(self.built);
                let mix = self.alpha * g + (1.0 - self.alpha) * s;
                (None, mix, standard_share(s, mix))
            }
        }
    }

    /// Draws from one strategy: the distance, its segment and both strategies' probabilities
    /// of reaching that segment; `None` past the end of the ray.
    fn draw(
        &mut self,
        guided: bool,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        sampler: &mut Sampler,
        counters: &mut Counters,
    ) -> Option<(f32, usize, f32, f32)> {
        let (mut g, mut s) = (1.0f32, 1.0f32);
        let mut k = 0;
        while self.ensure(k, medium, cache, counters) {
            let seg = self.segments[k];
            let p = if guided { seg.p_guided } else { seg.p_std };
            if sampler.next_1d() < p {
                return Some((seg.start + self.offset(&seg, sampler), k, g, s));
            }
            g *= 1.0 - seg.p_guided;
            s *= 1.0 - seg.p_std;
            k += 1;
        }
        None
    }

    /// An offset inside `seg`: a channel by its share of the segment's collisions, then
    /// its truncated exponential, cut to stay inside the segment.
    fn offset(&self, seg: &Segment, sampler: &mut Sampler) -> f32 {
        let share = seg.mass * seg.collide;
        let v = sampler.next_1d() * share.element_sum();
        let c = if v < share.x {
            0
        } else if v < share.x + share.y || share.z == 0.0 {
            1
        } else {
            2
        };
        let u = sampler.next_1d();
        (-(-u * seg.collide[c]).ln_1p() / self.sigma[c]).min(seg.length * (1.0 - 1e-6))
    }

    /// The weights of the extra collision's parts (see [`direct_stretch`]), computed once.
    fn direct_weights(&mut self, medium: &Medium, cache: &mut impl RadianceCache) -> DirectStretch {
        if let Some(d) = self.direct {
            return d;
        }
        let g = medium.phase.mean_cosine();
        let d = direct_stretch(&self.ray, self.guided_end, self.sigma, self.pick, g, cache);
        self.direct = Some(d);
        d
    }

    /// Whether [`sample_direct`](Self::sample_direct) draws an extra collision along this
    /// ray: always towards point lights ([`aim_at`](Self::aim_at)), and for the light of the
    /// cache's grid only where it is concentrated along the ray (where the flight's own
    /// collision would estimate it with a relative variance above 1).
    pub fn takes_extra(&mut self, medium: &Medium, cache: &mut impl RadianceCache) -> bool {
        let d = self.direct_weights(medium, cache);
        equiangular_share(&d, self.towards.is_some()).is_some()
    }

    /// Part `j` of the guided stretch as a segment (for its offsets and their density).
    fn part(&self, d: &DirectStretch, j: usize) -> Segment {
        let start = j as f32 * d.length;
        let mass = Spectrum::select(
            self.pick.cmpgt(Spectrum::ZERO),
            self.pick * exp(-self.sigma * start),
            Spectrum::ZERO,
        );
        Segment { start, length: d.length, mass, collide: d.collide, ..Default::default() }
    }

    /// Samples a collision for next-event estimation of delta lights: `(t, its density)`, the
    /// density following the cache's delta-light in-scattering over the guided stretch (mixed
    /// with the equiangular density towards point lights, see [`aim_at`](Self::aim_at));
    /// `None` where the cache knows of none along it.
    pub fn sample_direct(
        &mut self,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        sampler: &mut Sampler,
    ) -> Option<(f32, f32)> {
        let d = self.direct_weights(medium, cache);
        let share = equiangular_share(&d, self.towards.is_some())?;
        let u = sampler.next_1d();
        let (t, j) = match &self.towards {
            Some(e) if u < share => {
                let t = e.sample(u / share, sampler.next_1d(), self.guided_end);
                (t, d.part_of(t))
            }
            _ => {
                let j = d.pick((u - share) / (1.0 - share))?;
                let part = self.part(&d, j);
                (part.start + self.offset(&part, sampler), j)
            }
        };
        Some((t, self.mixed_density(&d, share, j, t)))
    }

    /// The extra collision's density at `t` in part `j` of the guided stretch: the grid's,
    /// mixed with the equiangular one at `share` where the flight aims at point lights.
    fn mixed_density(&self, d: &DirectStretch, share: f32, j: usize, t: f32) -> f32 {
        let grid = if d.weights[j] == 0.0 {
            0.0
        } else {
            let part = self.part(d, j);
            d.weights[j] / d.total * self.offset_pdf(&part, t - part.start)
        };
        match &self.towards {
            Some(e) => (1.0 - share) * grid + share * e.pdf(t),
            None => grid,
        }
    }

    /// The density of [`sample_direct`](Self::sample_direct) at `t`.
    pub fn direct_density(
        &mut self,
        t: f32,
        medium: &Medium,
        cache: &mut impl RadianceCache,
    ) -> f32 {
        let d = self.direct_weights(medium, cache);
        match equiangular_share(&d, self.towards.is_some()) {
            Some(share) if t >= 0.0 && t < self.guided_end => {
                self.mixed_density(&d, share, d.part_of(t), t)
            }
            _ => 0.0,
        }
    }

    /// Both strategies' probabilities of reaching segment `k` (of passing, for `self.built`
    /// once every segment is built).
    fn survival(&self, k: usize) -> (f32, f32) {
        self.segments[..k]
            .iter()
            .fold((1.0, 1.0), |(g, s), seg| (g * (1.0 - seg.p_guided), s * (1.0 - seg.p_std)))
    }

    /// The guided and the standard density of colliding at `t`: the mixture's is
    /// `alpha guided + (1 - alpha) standard`.
    pub fn densities(
        &mut self,
        t: f32,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        counters: &mut Counters,
    ) -> (f32, f32) {
        let (mut g, mut s) = (1.0f32, 1.0f32);
        let mut k = 0;
        while self.ensure(k, medium, cache, counters) {
            let seg = self.segments[k];
            // Past the last segment's end (by rounding) counts as in it.
            let inside = t < seg.start + seg.length || !self.ensure(k + 1, medium, cache, counters);
            if t >= seg.start && inside {
                let offset = self.offset_pdf(&seg, t - seg.start);
                return (g * seg.p_guided * offset, s * seg.p_std * offset);
            }
            g *= 1.0 - seg.p_guided;
            s *= 1.0 - seg.p_std;
            k += 1;
        }
        (0.0, 0.0)
    }

    /// The mixture density of colliding at `t` (for tests and MIS).
    pub fn pdf(
        &mut self,
        t: f32,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        counters: &mut Counters,
    ) -> f32 {
        let (g, s) = self.densities(t, medium, cache, counters);
        self.alpha * g + (1.0 - self.alpha) * s
    }

    /// The mixture probability of passing the end of the ray.
    pub fn pass_probability(
        &mut self,
        medium: &Medium,
        cache: &mut impl RadianceCache,
        counters: &mut Counters,
    ) -> f32 {
        while self.build_next(medium, cache, counters) {}
        let (g, s) = self.survival(self.built);
        self.alpha * g + (1.0 - self.alpha) * s
    }

    /// Whether the ray's end is reachable (finite and not cut off by a tail).
    pub fn ends_at_t_max(&self) -> bool {
        self.ends_at_t_max
    }
}

/// A guided free flight along `ray` within `(0, t_max)` in `medium`, for throughput `beta`.
/// A heterogeneous medium's flight is its `tracker`'s (the scene's choice for it), steered at
/// its tentative collisions where `alpha` is above 0 (see [`steered_flight_along`]);
/// homogeneous media have closed forms of their own.
///
/// With `extra_nee` (the scene's point and spot lights), a non-emissive medium also returns
/// an [`ExtraCollision`]. In a homogeneous one it is placed by the cache's estimate of
/// the light delta lights (the sun, point lights) scatter into the ray
/// (`RadianceCache::direct`, in 16 parts of the guided stretch), mixed with the equiangular
/// density towards the point lights ([`GuidedDistance::aim_at`]), and gives the
/// flight's own scattering collision a `delta_share` below 1: the two next-event estimates
/// of delta lights combine by the power heuristic, for one shadow ray more. The flight's
/// collision alone cannot follow single scattering closely: its density must also lead the
/// path on, and mixing at `alpha` leaves even a perfectly guided estimate a relative variance
/// of `1 / alpha - 1` (the standard half finds a shaft of sunlight only by chance). The extra
/// collision lowers the error at equal time (see docs/experiments.md). Other lights stay with
/// the flight's own collision: their estimates are MIS-weighted against direction sampling,
/// whose guided density an extra collision would have to load. In a heterogeneous medium the
/// extra collision aims at point and spot lights alone (`NullCollisionExtra`).
///
/// At `alpha` 0 in a grey, non-emissive homogeneous medium the flight takes the closed form of
/// `plain_flight`: the same densities from a quarter of the transcendental functions, so less
/// error at equal time (see docs/experiments.md). In a chromatic one, a ray that takes no extra
/// collision flies the medium's `tracker`, as an unguided walk does.
#[allow(clippy::too_many_arguments)]
pub fn guided_flight(
    medium: &Medium,
    tracker: Tracker,
    ray: &Ray,
    t_max: f32,
    beta: Spectrum,
    alpha: f32,
    extra_nee: Option<&[PointLight]>,
    cache: &mut impl RadianceCache,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> GuidedFlight {
    if let MediumKind::Homogeneous { sigma_t, albedo } = medium.kind
        && alpha == 0.0
        && is_grey(sigma_t)
        && !medium.is_emissive()
    {
        let g = medium.phase.mean_cosine();
        return plain_flight(sigma_t.x, albedo, g, ray, t_max, extra_nee, cache, sampler);
    }
    let pass = GuidedFlight::new(GuidedEvent::Pass, Spectrum::ONE, 1.0);
    let lookup_u = sampler.next_1d();
    if let MediumKind::Heterogeneous(_) = &medium.kind {
        let Some(r) = MediumRay::new(medium, ray, t_max) else { return pass };
        let extra = extra_nee
            .filter(|_| !medium.is_emissive())
            .and_then(|points| NullCollisionExtra::new(&r, ray, points));
        let mut f = tracked_flight(
            medium, tracker, &r, ray, beta, alpha, lookup_u, cache, sampler, counters,
        );
        if let Some(x) = extra {
            if let GuidedEvent::Scatter { t } = f.event {
                f.delta_share = x.own_share(&r, t, counters);
            }
            f.extra = x.sample(medium, &r, ray, sampler, counters);
        }
        return f;
    }
    if let MediumKind::Homogeneous { sigma_t, .. } = medium.kind
        && sigma_t.min_element() <= 0.0
        && sigma_t.max_element() > 0.0
        && t_max.is_infinite()
    {
        // A channel that never collides must be able to escape to infinity, which the guided
        // stretch cannot express: such rays keep the standard tracker.
        return standard_flight(medium, tracker, ray, t_max, beta, sampler, counters);
    }
    let MediumKind::Homogeneous { sigma_t, .. } = medium.kind else { return pass };
    let Some(mut dist) = GuidedDistance::new(medium, ray, t_max, beta, alpha, lookup_u, SEGMENTS)
    else {
        return pass;
    };
    let extra_nee = extra_nee.filter(|_| !medium.is_emissive());
    if let Some(points) = extra_nee {
        dist.aim_at(points);
    }
    let takes_extra = extra_nee.is_some() && dist.takes_extra(medium, cache);
    if alpha == 0.0 && !takes_extra && !medium.is_emissive() {
        // Nothing guided along this ray: the standard tracker's closed form is cheaper than
        // the same density through the segments.
        return standard_flight(medium, tracker, ray, t_max, beta, sampler, counters);
    }
    let (t, pdf, gain) = dist.sample(medium, cache, sampler, counters);
    let (mut delta_share, mut extra) = (1.0, None);
    if takes_extra {
        extra = extra_collision(&mut dist, medium, ray, cache, sampler, counters);
        if let Some(t) = t
            && positive(pdf)
        {
            delta_share = power_heuristic(pdf, dist.direct_density(t, medium, cache));
        }
    }
    let Some(t) = t else {
        let weight = if pdf > 0.0 {
            transmittance_homogeneous(sigma_t, t_max) / pdf
        } else {
            Spectrum::ZERO
        };
        return GuidedFlight { extra, ..GuidedFlight::new(GuidedEvent::Pass, weight, gain) };
    };
    if !positive(pdf) {
        return GuidedFlight::new(GuidedEvent::Absorb, Spectrum::ZERO, 1.0);
    }
    if !medium.is_emissive() {
        let weight = homogeneous_scattering(medium, sigma_t, ray, t) / pdf;
        return GuidedFlight {
            delta_share,
            extra,
            ..GuidedFlight::new(GuidedEvent::Scatter { t }, weight, gain)
        };
    }
    let w = transmittance_homogeneous(sigma_t, t) / pdf;
    emissive_collision(medium, ray, t, (beta, w), lookup_u, gain, cache, sampler, counters)
}

/// The medium's `tracker`'s flight (`tracking::sample_flight`), as an unguided walk flies it,
/// as a guided flight's outcome.
fn standard_flight(
    medium: &Medium,
    tracker: Tracker,
    ray: &Ray,
    t_max: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> GuidedFlight {
    let f = crate::tracking::sample_flight(medium, tracker, ray, t_max, beta, sampler, counters);
    let event = match f.event {
        FlightEvent::Scatter { t } => GuidedEvent::Scatter { t },
        FlightEvent::Escape => GuidedEvent::Pass,
    };
    GuidedFlight { emitted: f.emitted, ..GuidedFlight::new(event, f.weight, 1.0) }
}

/// `T(t) sigma_s(t)` in a homogeneous medium of extinction `sigma_t`.
fn homogeneous_scattering(medium: &Medium, sigma_t: Spectrum, ray: &Ray, t: f32) -> Spectrum {
    let c = medium.coefficients(ray.at(t));
    transmittance_homogeneous(sigma_t, t) * c.sigma_t * c.albedo
}

/// A homogeneous flight's extra collision for delta lights, weighted against the flight's own
/// collision by the power heuristic.
fn extra_collision(
    dist: &mut GuidedDistance,
    medium: &Medium,
    ray: &Ray,
    cache: &mut impl RadianceCache,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Option<ExtraCollision> {
    let MediumKind::Homogeneous { sigma_t, .. } = medium.kind else { return None };
    let (t, direct) = dist.sample_direct(medium, cache, sampler)?;
    let own = dist.pdf(t, medium, cache, counters);
    // A density that underflowed in every channel leaves nothing to weigh (never 0/0).
    let weight = if direct > 0.0 {
        homogeneous_scattering(medium, sigma_t, ray, t) * (power_heuristic(direct, own) / direct)
    } else {
        Spectrum::ZERO
    };
    Some(ExtraCollision { t, weight })
}

/// Extra collisions for point and spot lights in a heterogeneous medium: equiangular over the
/// ray's part inside the medium's box, weighted by a ratio-tracking estimate of the
/// transmittance to them. The flight's own collision has no density in closed form here, so
/// the power heuristic weighs the equiangular density against a stand-in for it, the same at
/// both collisions: any pair of weights that sums to one at every point keeps the two
/// estimates of the lights' in-scattering unbiased together, and a stand-in only decides how
/// well they share it.
struct NullCollisionExtra {
    towards: Equiangular,
}

impl NullCollisionExtra {
    fn new(r: &MediumRay<'_>, ray: &Ray, points: &[PointLight]) -> Option<Self> {
        let (t0, t1) = r.range();
        Equiangular::between(ray, t0, t1, points).map(|towards| Self { towards })
    }

    /// The stand-in for the flight's own collision density at `t`, given the extinction
    /// there: the collision density of delta tracking if the majorants were the extinction
    /// up to `t`.
    fn own_density(r: &MediumRay<'_>, t: f32, sigma_t: f32) -> f32 {
        let mut depth = 0.0;
        for span in r.segments() {
            if span.t0 >= t {
                break;
            }
            depth += span.majorant.max_element() * (span.t1.min(t) - span.t0);
        }
        // Where it underflows, the power heuristic gives the point to the extra collision.
        sigma_t * (-depth).exp()
    }

    /// The share of next-event estimation of delta lights at the flight's own collision at `t`.
    fn own_share(&self, r: &MediumRay<'_>, t: f32, counters: &mut Counters) -> f32 {
        let towards = self.towards.pdf(t);
        if towards <= 0.0 {
            return 1.0;
        }
        counters.density_lookups += 1;
        let own = Self::own_density(r, t, luminance(r.coefficients(t).sigma_t));
        power_heuristic(own, towards)
    }

    /// The extra collision: its point, and the transmittance to it times the scattering
    /// coefficient there over its density, times its share.
    fn sample(
        &self,
        medium: &Medium,
        r: &MediumRay<'_>,
        ray: &Ray,
        sampler: &mut Sampler,
        counters: &mut Counters,
    ) -> Option<ExtraCollision> {
        let (_, t1) = r.range();
        let t = self.towards.sample(sampler.next_1d(), sampler.next_1d(), t1);
        let density = self.towards.pdf(t);
        if !positive(density) {
            return None;
        }
        counters.density_lookups += 1;
        let c = r.coefficients(t);
        let own = Self::own_density(r, t, luminance(c.sigma_t));
        let transmittance = MediumRay::new(medium, ray, t)
            .map_or(Spectrum::ONE, |part| ratio_tracking(&part, sampler, counters));
        let weight =
            transmittance * c.sigma_t * c.albedo * (power_heuristic(density, own) / density);
        Some(ExtraCollision { t, weight })
    }
}

/// A real collision at `t` in an emissive homogeneous medium, reached by a path of throughput
/// `beta` with the flight's transmittance over density `w`: absorb (and emit) or scatter, in
/// proportion to what each brings back (the zero-variance choice), emission `sigma_a L_e`
/// against in-scattered `sigma_s L_s`.
#[allow(clippy::too_many_arguments)]
fn emissive_collision(
    medium: &Medium,
    ray: &Ray,
    t: f32,
    (beta, w): (Spectrum, Spectrum),
    lookup_u: f32,
    gain: f32,
    cache: &mut impl RadianceCache,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> GuidedFlight {
    let x = ray.at(t);
    let c = medium.coefficients(x);
    let sigma_s = c.sigma_t * c.albedo;
    let sigma_a = (c.sigma_t - sigma_s).max(Spectrum::ZERO);
    let emit = luminance(sigma_a * medium.emission);
    counters.field_lookups += 1;
    let scatter = if cache.load(x, lookup_u) {
        luminance(sigma_s) * cache.inscattered(ray.direction, medium.phase.mean_cosine())
    } else {
        luminance(sigma_s) * luminance(medium.emission)
    };
    let p_absorb = if emit <= 0.0 {
        0.0
    } else if luminance(sigma_s) <= 0.0 {
        1.0
    } else {
        let p = emit / (emit + scatter);
        if p.is_finite() { p.clamp(0.05, 0.95) } else { 0.5 }
    };
    if sampler.next_1d() < p_absorb {
        let emitted = beta * w * sigma_a * medium.emission / p_absorb;
        return GuidedFlight {
            emitted,
            ..GuidedFlight::new(GuidedEvent::Absorb, Spectrum::ZERO, 1.0)
        };
    }
    GuidedFlight::new(GuidedEvent::Scatter { t }, w * sigma_s / (1.0 - p_absorb), gain)
}

/// Guided distance sampling in the null-collision form, as a steer of the medium's own tracker
/// along the part of `ray` inside a heterogeneous medium (`ray` places the cache lookups): at
/// each tentative collision the zero-variance choice weighs in-scattered radiance
/// `scatter L_s` against the radiance the path finds by going on, `null L`, bounded away from
/// 0 and 1 so neither event loses support.
///
/// The mixture with standard tracking is one-sample over the whole flight, as in homogeneous
/// media: the strategy is drawn once, and every event is weighted by the prefix's mixture
/// density `alpha P_guided + (1 - alpha) P_std` (products of the per-event probabilities).
/// Mixing event by event instead lets each null collision multiply the weight by up to
/// `1 / (1 - alpha)`; over a long flight that compounds into rare, huge weights, enough for a
/// cloud's render to miss its mean by many standard errors (see docs/experiments.md). This
/// way no weight exceeds `1 / (1 - alpha)` times the standard tracker's.
struct FieldSteer<'a, C> {
    cache: &'a mut C,
    ray: &'a Ray,
    lookup_u: f32,
    /// The phase function's mean cosine, for the cache's in-scattering estimate.
    g: f32,
    alpha: f32,
    /// Whether this flight draws its events from the guided strategy.
    guided: bool,
    /// The shortest stretch one lookup serves (a share of the medium's stretch).
    shortest: f32,
    /// Up to where along the ray the last estimates hold (where the ray leaves their
    /// region), and how many lookups the flight has made.
    until: f32,
    lookups: usize,
    /// The last estimates, `L_s` and `L` (none where the cache knows nothing).
    cached: Option<(f32, f32)>,
    /// The prefix's guided probability over its standard one.
    ratio: f32,
}

impl<C: RadianceCache> Steer for FieldSteer<'_, C> {
    fn scatters(&mut self, at: Tentative, u: f32, standard: bool, counters: &mut Counters) -> bool {
        counters.guided_density_lookups += 1;
        let mut p_guided = at.p_std;
        if at.scatter > 0.0 && at.null > 0.0 {
            if at.t >= self.until {
                counters.field_lookups += 1;
                self.lookups += 1;
                let (x, w) = (self.ray.at(at.t), self.ray.direction);
                self.until = if self.lookups >= REFRESHES {
                    f32::INFINITY
                } else {
                    at.t + self.cache.region_exit(x, w).max(self.shortest)
                };
                self.cached = self
                    .cache
                    .estimates(x, self.lookup_u, w, self.g)
                    .map(|e| (e.inscattered, e.incident));
            }
            if let Some((ls, li)) = self.cached {
                let (a, b) = (at.scatter * ls, at.null * li);
                if a + b > 0.0 && (a + b).is_finite() {
                    p_guided = (a / (a + b)).clamp(0.02, 0.98);
                }
            }
        }
        let scatters = if self.guided { u < p_guided } else { standard };
        if p_guided != at.p_std {
            self.ratio *=
                if scatters { p_guided / at.p_std } else { (1.0 - p_guided) / (1.0 - at.p_std) };
        }
        scatters
    }

    /// A ratio that overflowed means the standard tracker could (all but) never have made
    /// this prefix: its weight is zero, never NaN.
    fn gain(&self) -> f32 {
        let g = 1.0 / (self.alpha * self.ratio + (1.0 - self.alpha));
        if g.is_finite() { g } else { 0.0 }
    }
}

/// A flight along `r`, the part of `ray` inside a heterogeneous medium, with the medium's
/// `tracker`, steered towards the zero-variance collision density at distance `alpha` above 0
/// (see [`FieldSteer`]).
#[allow(clippy::too_many_arguments)]
fn tracked_flight(
    medium: &Medium,
    tracker: Tracker,
    r: &MediumRay<'_>,
    ray: &Ray,
    beta: Spectrum,
    alpha: f32,
    lookup_u: f32,
    cache: &mut impl RadianceCache,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> GuidedFlight {
    let (f, gain) = if alpha > 0.0 {
        let (t0, t1) = r.range();
        let mut steer = FieldSteer {
            cache,
            ray,
            lookup_u,
            g: medium.phase.mean_cosine(),
            alpha,
            guided: sampler.next_1d() < alpha,
            shortest: MIN_SEGMENT * (t1 - t0),
            until: f32::NEG_INFINITY,
            lookups: 0,
            cached: None,
            ratio: 1.0,
        };
        let tracker = tracker.steerable();
        let f =
            steered_flight_along(r, tracker, medium.emission, beta, sampler, counters, &mut steer);
        (f, steer.gain())
    } else {
        (sample_flight_along(r, tracker, medium.emission, beta, sampler, counters), 1.0)
    };
    let event = match f.event {
        FlightEvent::Scatter { t } => GuidedEvent::Scatter { t },
        FlightEvent::Escape => GuidedEvent::Pass,
    };
    GuidedFlight { emitted: f.emitted, ..GuidedFlight::new(event, f.weight * gain, gain) }
}

#[inline]
fn ln(v: Spectrum) -> Spectrum {
    Spectrum::new(v.x.ln(), v.y.ln(), v.z.ln())
}
