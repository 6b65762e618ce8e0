//! Free-flight sampling and transmittance estimation through one medium along one ray segment.
//!
//! Every tracker of the method notes sits behind one interface (`Tracker`, `sample_flight`,
//! `transmittance_tracked`): closed forms for homogeneous media (with one-sample MIS over the
//! colour channels when the extinction is chromatic), regular tracking through
//! piecewise-constant spans, ray marching (biased, a baseline only), delta tracking, weighted
//! delta tracking, analog and weighted decomposition tracking, and spectral tracking with max,
//! average and history-aware collision probabilities, alone or with decomposition (Kutz et al.
//! 2017). Transmittance uses closed forms, ratio tracking or residual ratio tracking.
//!
//! Heterogeneous media are walked span by span through their coarse bound grid (a 3D DDA over
//! `media::MajorantGrid`), so each span has a local majorant and minorant: delta and ratio
//! tracking restart their exponential steps at span boundaries (memoryless), decomposition uses
//! the minorant as its control. The estimators are generic over `TrackedRay`, which tests also
//! implement for analytic extinction profiles.
//!
//! Guided flights steer the same trackers (`Steer`, `steered_flight_along`): a steer may choose
//! the event at each tentative collision that reads the density, and keeps the ratio by which
//! the tracker's weight is corrected.
//!
//! `TrackerChoice::Auto` picks per medium: closed form for homogeneous media, delta tracking
//! for grey grids, spectral tracking (history-aware) only for chromatic grids. Decomposition
//! pays where density lookups are dear; on the bench's grids the control's exponential per
//! cell costs more than the lookups it saves (see docs/experiments.md).

mod choice;
mod estimators;
mod steer;

pub(crate) use choice::explain;
pub use choice::{TrackerChoice, TrackerError, candidates};
pub use estimators::{SpectralEvent, SpectralProbabilities};
pub use steer::{Steer, Tentative, Unsteered};

use crate::math::{Ray, Spectrum};
use crate::media::{Coefficients, Dda, Heterogeneous, Medium, MediumKind};
use crate::rng::Sampler;
use crate::stats::Counters;

/// The free-flight and transmittance strategy of a medium.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Tracker {
    /// Homogeneous, grey extinction: exponential sampling, exact transmittance.
    Analytic,
    /// Homogeneous, chromatic extinction: a channel picked by path throughput, MIS weights.
    AnalyticSpectral,
    /// Regular tracking: exact optical depth through piecewise-constant spans (grey).
    Regular,
    /// Ray marching with a fixed stride: BIASED, a baseline only (grey).
    RayMarching,
    /// Delta (Woodcock) tracking against local majorants; ratio-tracking shadow rays (grey).
    Delta,
    /// Weighted delta tracking: majorants may under-estimate, signed weights (grey).
    WeightedDelta,
    /// Analog decomposition tracking: control = local minorant, residual delta-tracked (grey).
    Decomposition,
    /// Weighted decomposition tracking: control and majorant need not bound (grey).
    WeightedDecomposition,
    /// Spectral tracking with history-aware average probabilities (chromatic or grey).
    Spectral,
    /// Spectral tracking with max probabilities.
    SpectralMax,
    /// Spectral tracking with (history-free) average probabilities.
    SpectralAverage,
    /// Spectral tracking with history-aware probabilities, combined with decomposition.
    SpectralDecomposition,
}

impl Tracker {
    /// Every tracker, in the order `--help` lists them.
    pub const ALL: [Tracker; 12] = [
        Tracker::Analytic,
        Tracker::AnalyticSpectral,
        Tracker::Regular,
        Tracker::RayMarching,
        Tracker::Delta,
        Tracker::WeightedDelta,
        Tracker::Decomposition,
        Tracker::WeightedDecomposition,
        Tracker::Spectral,
        Tracker::SpectralMax,
        Tracker::SpectralAverage,
        Tracker::SpectralDecomposition,
    ];

    /// What `auto` picks for `medium`.
    pub fn for_medium(medium: &Medium) -> Self {
        match (&medium.kind, medium.is_chromatic()) {
            (MediumKind::Homogeneous { .. }, false) => Tracker::Analytic,
            (MediumKind::Homogeneous { .. }, true) => Tracker::AnalyticSpectral,
            (MediumKind::Heterogeneous(_), false) => Tracker::Delta,
            (MediumKind::Heterogeneous(_), true) => Tracker::Spectral,
        }
    }

    /// The name `--tracker` takes.
    pub fn name(&self) -> &'static str {
        match self {
            Tracker::Analytic => "analytic",
            Tracker::AnalyticSpectral => "analytic-spectral",
            Tracker::Regular => "regular",
            Tracker::RayMarching => "ray-marching-biased",
            Tracker::Delta => "delta",
            Tracker::WeightedDelta => "weighted-delta",
            Tracker::Decomposition => "decomposition",
            Tracker::WeightedDecomposition => "weighted-decomposition",
            Tracker::Spectral => "spectral",
            Tracker::SpectralMax => "spectral-max",
            Tracker::SpectralAverage => "spectral-average",
            Tracker::SpectralDecomposition => "spectral-decomposition",
        }
    }

    /// The tracker a steered flight uses in its place ([`steered_flight_along`]): itself where
    /// it draws tentative collisions; delta tracking for regular tracking, ray marching and
    /// the grey closed form, which draw none; spectral tracking for the chromatic closed form.
    pub fn steerable(self) -> Self {
        match self {
            Tracker::Analytic | Tracker::Regular | Tracker::RayMarching => Tracker::Delta,
            Tracker::AnalyticSpectral => Tracker::Spectral,
            other => other,
        }
    }

    /// Whether the estimates are unbiased (all but ray marching).
    pub fn is_unbiased(&self) -> bool {
        *self != Tracker::RayMarching
    }

    /// A short human-readable description, for `zerovar check`.
    pub fn describe(&self) -> &'static str {
        match self {
            Tracker::Analytic => "closed-form exponential sampling",
            Tracker::AnalyticSpectral => "closed-form sampling with channel MIS (chromatic)",
            Tracker::Regular => {
                "regular tracking (exact optical depth per piecewise-constant span)"
            }
            Tracker::RayMarching => {
                "ray marching, BIASED baseline (midpoint rule, 1 optical depth per step)"
            }
            Tracker::Delta => "delta tracking on the majorant grid, ratio-tracking shadow rays",
            Tracker::WeightedDelta => {
                "weighted delta tracking on the majorant grid, ratio-tracking shadow rays"
            }
            Tracker::Decomposition => {
                "decomposition tracking (control = grid minorant), residual ratio tracking"
            }
            Tracker::WeightedDecomposition => {
                "weighted decomposition tracking (control = grid minorant), residual ratio tracking"
            }
            Tracker::Spectral => {
                "spectral tracking, history-aware probabilities, ratio-tracking shadow rays"
            }
            Tracker::SpectralMax => {
                "spectral tracking, max probabilities, ratio-tracking shadow rays"
            }
            Tracker::SpectralAverage => {
                "spectral tracking, average probabilities, ratio-tracking shadow rays"
            }
            Tracker::SpectralDecomposition => {
                "spectral + decomposition tracking (history-aware), residual ratio tracking"
            }
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

/// A span of a ray with bounds of the extinction over it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Ray parameter where the span starts.
    pub t0: f32,
    /// Ray parameter where the span ends.
    pub t1: f32,
    /// Per channel: a majorant of the extinction (weighted trackers allow it to under-estimate).
    pub majorant: Spectrum,
    /// Per channel: a minorant (the decomposition control; weighted trackers allow it to
    /// over-estimate).
    pub minorant: Spectrum,
}

/// What a tracker sees along one ray: its spans, in order, and coefficient lookups by ray
/// parameter.
pub trait TrackedRay {
    /// The iterator of spans.
    type Segments<'s>: Iterator<Item = Segment>
    where
        Self: 's;
    /// The spans covering the part of the ray to track, in order.
    fn segments(&self) -> Self::Segments<'_>;
    /// Extinction and albedo at ray parameter `t` (one density lookup).
    fn coefficients(&self, t: f32) -> Coefficients;
    /// The albedo at ray parameter `t` (no density lookup).
    fn albedo(&self, t: f32) -> Spectrum;
}

/// A ray through a `Medium` within `(0, t_max)`, clipped to a heterogeneous medium's box.
#[derive(Clone, Debug)]
pub struct MediumRay<'a> {
    medium: &'a Medium,
    local: Ray,
    t0: f32,
    t1: f32,
}

impl<'a> MediumRay<'a> {
    /// The part of `ray` within `(0, t_max)` inside `medium`; `None` if it misses the medium.
    pub fn new(medium: &'a Medium, ray: &Ray, t_max: f32) -> Option<Self> {
        match &medium.kind {
            MediumKind::Homogeneous { .. } => {
                Some(Self { medium, local: *ray, t0: 0.0, t1: t_max })
            }
            MediumKind::Heterogeneous(h) => {
                let (t0, t1) = h.clip(ray, t_max)?;
                Some(Self { medium, local: h.local_ray(ray), t0, t1 })
            }
        }
    }

    /// The ray parameters where the tracked part starts and ends.
    pub fn range(&self) -> (f32, f32) {
        (self.t0, self.t1)
    }

    fn heterogeneous(&self) -> Option<&'a Heterogeneous> {
        match &self.medium.kind {
            MediumKind::Heterogeneous(h) => Some(h),
            MediumKind::Homogeneous { .. } => None,
        }
    }
}

/// The spans of a `MediumRay`.
#[derive(Clone, Debug)]
pub enum MediumSpans<'a> {
    /// One span of constant extinction.
    One(Option<Segment>),
    /// The cells of a bound grid.
    Grid {
        /// The DDA through the grid.
        dda: Dda<'a>,
        /// Extinction per unit density.
        per_density: Spectrum,
    },
}

impl Iterator for MediumSpans<'_> {
    type Item = Segment;

    #[inline]
    fn next(&mut self) -> Option<Segment> {
        match self {
            MediumSpans::One(s) => s.take(),
            MediumSpans::Grid { dda, per_density } => dda.next().map(|c| Segment {
                t0: c.t0,
                t1: c.t1,
                majorant: *per_density * c.max,
                minorant: *per_density * c.min,
            }),
        }
    }
}

impl TrackedRay for MediumRay<'_> {
    type Segments<'s>
        = MediumSpans<'s>
    where
        Self: 's;

    #[inline]
    fn segments(&self) -> MediumSpans<'_> {
        match &self.medium.kind {
            MediumKind::Homogeneous { sigma_t, .. } => MediumSpans::One(Some(Segment {
                t0: self.t0,
                t1: self.t1,
                majorant: *sigma_t,
                minorant: *sigma_t,
            })),
            MediumKind::Heterogeneous(h) => MediumSpans::Grid {
                dda: h.bound_grid().spans(&self.local, self.t0, self.t1),
                per_density: h.extinction_per_density(),
            },
        }
    }

    #[inline]
    fn coefficients(&self, t: f32) -> Coefficients {
        match self.heterogeneous() {
            Some(h) => h.coefficients_local(self.local.at(t)),
            None => self.medium.coefficients(self.local.origin),
        }
    }

    #[inline]
    fn albedo(&self, t: f32) -> Spectrum {
        match self.heterogeneous() {
            Some(h) => h.albedo_local(self.local.at(t)),
            None => self.medium.coefficients(self.local.origin).albedo,
        }
    }
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
        (MediumKind::Homogeneous { sigma_t, albedo }, Tracker::AnalyticSpectral) => {
            analytic_spectral(medium, *sigma_t, *albedo, t_max, beta, sampler)
        }
        _ => match MediumRay::new(medium, ray, t_max) {
            Some(r) => sample_flight_along(&r, tracker, medium.emission, beta, sampler, counters),
            None => Flight {
                event: FlightEvent::Escape,
                weight: Spectrum::ONE,
                emitted: Spectrum::ZERO,
            },
        },
    }
}

/// Samples a free flight along a `TrackedRay` with `tracker`; `emission` is the medium's
/// emitted radiance per unit absorption. The closed-form trackers become regular tracking
/// (grey) and history-aware spectral tracking (chromatic) here.
pub fn sample_flight_along<R: TrackedRay>(
    r: &R,
    tracker: Tracker,
    emission: Spectrum,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Flight {
    steered_flight_along(r, tracker, emission, beta, sampler, counters, &mut Unsteered)
}

/// A free flight along a `TrackedRay` with `tracker`, `steer` choosing the event at each
/// tentative collision that reads the density (see [`Steer`]). The weight returned is the
/// tracker's standard one: the caller corrects it by the steer's [`gain`](Steer::gain), while
/// the emission collected is already weighted by it. Regular tracking and ray marching draw no
/// tentative collisions and ignore `steer`: [`Tracker::steerable`] names the tracker to
/// steer in their place.
pub fn steered_flight_along<R: TrackedRay>(
    r: &R,
    tracker: Tracker,
    emission: Spectrum,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
    steer: &mut impl Steer,
) -> Flight {
    use estimators as e;
    let (s, c) = (sampler, counters);
    let none = &mut |_: SpectralEvent, _: Spectrum| {};
    match tracker {
        Tracker::Analytic | Tracker::Regular => e::regular(r, emission, beta, s, c),
        Tracker::RayMarching => e::ray_marching(r, emission, beta, s, c),
        Tracker::Delta => e::delta(r, emission, beta, s, c, steer),
        Tracker::WeightedDelta => e::weighted_delta(r, emission, beta, s, c, steer),
        Tracker::Decomposition => e::decomposition(r, emission, beta, s, c, steer),
        Tracker::WeightedDecomposition => e::weighted_decomposition(r, emission, beta, s, c, steer),
        Tracker::Spectral | Tracker::AnalyticSpectral => {
            e::spectral(r, SpectralProbabilities::History, emission, beta, (s, c), steer, none)
        }
        Tracker::SpectralMax => {
            e::spectral(r, SpectralProbabilities::Max, emission, beta, (s, c), steer, none)
        }
        Tracker::SpectralAverage => {
            e::spectral(r, SpectralProbabilities::Average, emission, beta, (s, c), steer, none)
        }
        Tracker::SpectralDecomposition => {
            e::spectral_decomposition(r, emission, beta, (s, c), steer, none)
        }
    }
}

/// Spectral tracking (`Spectral*` trackers) along a `TrackedRay`, reporting every null and
/// scatter event with the path throughput after it to `observe` (for tests of the weights).
pub fn spectral_flight_observed<R: TrackedRay>(
    r: &R,
    tracker: Tracker,
    emission: Spectrum,
    beta: Spectrum,
    sampler: &mut Sampler,
    counters: &mut Counters,
    observe: &mut impl FnMut(SpectralEvent, Spectrum),
) -> Flight {
    let probs = match tracker {
        Tracker::SpectralMax => SpectralProbabilities::Max,
        Tracker::SpectralAverage => SpectralProbabilities::Average,
        Tracker::SpectralDecomposition => {
            return estimators::spectral_decomposition(
                r,
                emission,
                beta,
                (sampler, counters),
                &mut Unsteered,
                observe,
            );
        }
        _ => SpectralProbabilities::History,
    };
    estimators::spectral(r, probs, emission, beta, (sampler, counters), &mut Unsteered, observe)
}

/// An estimate of the transmittance along a `TrackedRay` with the shadow-ray estimator that
/// goes with `tracker`: exact for the closed-form and regular trackers (piecewise-constant
/// spans), ray-marched for ray marching (BIASED), residual ratio tracking for the
/// decomposition trackers and ratio tracking for the others.
pub fn transmittance_along<R: TrackedRay>(
    r: &R,
    tracker: Tracker,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    match tracker {
        Tracker::Analytic | Tracker::AnalyticSpectral | Tracker::Regular => {
            estimators::regular_transmittance(r, counters)
        }
        Tracker::RayMarching => estimators::marched_transmittance(r, counters),
        Tracker::Decomposition
        | Tracker::WeightedDecomposition
        | Tracker::SpectralDecomposition => estimators::residual_ratio(r, sampler, counters),
        _ => estimators::ratio(r, sampler, counters),
    }
}

/// Ratio-tracking transmittance along a `TrackedRay` (whatever the tracker).
pub fn ratio_tracking<R: TrackedRay>(
    r: &R,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    estimators::ratio(r, sampler, counters)
}

/// Residual-ratio-tracking transmittance along a `TrackedRay`, with each span's minorant as
/// the control.
pub fn residual_ratio_tracking<R: TrackedRay>(
    r: &R,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    estimators::residual_ratio(r, sampler, counters)
}

/// An unbiased estimate of the transmittance along `ray` over `(0, t_max)` in `medium`: closed
/// form if homogeneous, ratio tracking through the bound grid otherwise.
pub fn transmittance(
    medium: &Medium,
    ray: &Ray,
    t_max: f32,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    transmittance_tracked(medium, Tracker::Delta, ray, t_max, sampler, counters)
}

/// The transmittance estimate that goes with `tracker` (see `transmittance_along`); closed form
/// for every homogeneous medium.
pub fn transmittance_tracked(
    medium: &Medium,
    tracker: Tracker,
    ray: &Ray,
    t_max: f32,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    match &medium.kind {
        MediumKind::Homogeneous { sigma_t, .. } => transmittance_homogeneous(*sigma_t, t_max),
        MediumKind::Heterogeneous(_) => match MediumRay::new(medium, ray, t_max) {
            Some(r) => transmittance_along(&r, tracker, sampler, counters),
            None => Spectrum::ONE,
        },
    }
}

fn analytic_grey(
    medium: &Medium,
    sigma_t: f32,
    albedo: Spectrum,
    t_max: f32,
    beta: Spectrum,
    sampler: &mut Sampler,
) -> Flight {
    let t = estimators::exp_step(sampler.next_1d(), sigma_t);
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
    let t = estimators::exp_step(sampler.next_1d(), sigma_t[channel]);
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
    if tau.x == tau.y && tau.y == tau.z {
        return Spectrum::splat((-tau.x).exp()); // grey: one exponential
    }
    Spectrum::new((-tau.x).exp(), (-tau.y).exp(), (-tau.z).exp())
}
