//! The volumetric random walk shared by the unguided and the guided path tracer.
//!
//! With nothing guided it is the standard volumetric path tracer: free flights from each
//! medium's tracker, next-event estimation at every real scattering event weighed by the power
//! heuristic against phase or BSDF sampling, null surfaces crossed without a bounce, Mitsuba's
//! depth counting and Russian roulette. Each guided component replaces one decision by its
//! zero-variance counterpart mixed with the standard one (`guided`): distances, directions
//! (product sampling) and roulette with splitting (weight windows). A flight may also return
//! an extra collision where delta lights are estimated a second time, weighed against the
//! estimate at its own collision (`guided::distance::guided_flight`): a guided flight's is
//! placed by the field and aimed at point lights, and an unguided flight aims one at point and
//! spot lights alone, which needs no field. Split copies wait on a fixed-size stack, so a walk
//! never allocates.

use crate::accel::ShadowTrace;
use crate::bsdf::Bsdf;
use crate::guided::distance::{
    ExtraCollision, GuidedEvent, GuidedFlight, free_path_needs_extra, guided_flight,
};
use crate::guided::halo::{self, Halo};
use crate::guided::{
    Components, DirectRecord, EXACT_PRODUCT_MIN_G, NoCache, PRODUCT_MIN_G, RadianceCache, window,
};
use crate::integrators::trace::{Continuation, LightSource, Strategy, Trace, TraceEvent};
use crate::lights::Light;
use crate::math::{Frame, Ray, Spectrum, luminance, positive, power_heuristic};
use crate::media::Medium;
use crate::phase::PhaseFunction;
use crate::rng::Sampler;
use crate::scene::{Crossing, Scene, offset_origin};
use crate::shapes::SurfaceHit;
use crate::stats::Counters;
use crate::tracking::{FlightEvent, sample_flight, transmittance_tracked};
use arrayvec::ArrayVec;
use glam::{Vec2, Vec3A};
use zerovar_guiding::{Branch, PathRecorder};

/// A path crossing more null surfaces than this in a row is stuck in degenerate geometry.
const MAX_NULL_CROSSINGS: u32 = 4096;
/// Null surfaces a shadow ray crosses that one traversal collects (more are crossed one at a
/// time).
const SHADOW_CROSSINGS: usize = 8;
/// Split copies waiting to be traced at once, per camera sample.
const STACK: usize = 32;
/// Most walks (the camera path and all its split copies) per camera sample: splitting stops
/// there, so a cache that overestimates wildly cannot make a sample cost without bound.
pub const MAX_WALKS: usize = 64;
/// Depth from which paths steered by weight windows also meet standard roulette.
const WINDOW_RR_DEPTH: u32 = 256;
/// Largest share of guided sampling in every mixture that render options accept
/// (`render::GuidingOptions` refuses more). Standard sampling keeps 20%: a fitted mixture
/// underflows to zero density far from its lobes, where light may still arrive, and a path
/// that goes where the cache says it should not would otherwise carry a weight compounding
/// without bound; with 20% no guided weight exceeds five standard ones. The walk itself uses
/// [`WalkSettings`]' shares as given, up to 1 (the guided strategy alone, for a cache known
/// to be right everywhere).
pub const MAX_ALPHA: f32 = 0.8;

/// Without weight windows, the largest factor by which a path's guided decisions may have
/// multiplied its weight, relative to standard sampling, for it to go on guided. Each decision's
/// factor is at most `1 / (1 - alpha)`, but along a deep path they compound (a dense cloud walks
/// dozens of vertices) into rare, huge weights; past this the path samples as if unguided, so its
/// guided decisions never multiply its weight by more than `MAX_GUIDED_GAIN / (1 - alpha)` (for
/// alpha below 1). The switch depends on the path's past alone, which keeps every estimator
/// unbiased. Weight windows split such paths instead (with them the bound only added error);
/// without them it keeps guided directions in a dense cloud from doing far worse than unguided
/// sampling (see docs/experiments.md).
pub const MAX_GUIDED_GAIN: f32 = 8.0;

/// Settings of the walk.
#[derive(Clone, Copy, Debug)]
pub struct WalkSettings {
    /// Longest path in scattering events; `None` is unlimited.
    pub max_depth: Option<u32>,
    /// Depth from which standard Russian roulette applies.
    pub rr_depth: u32,
    /// Which decisions are guided.
    pub guide: Components,
    /// Probability of the guided strategy in each mixture in media, in [0, 1], used as given
    /// (render options keep it to [`MAX_ALPHA`], which bounds every guided weight).
    pub alpha: f32,
    /// Probability of the guided strategy in each mixture at surfaces, in [0, 1]
    /// (`render::DEFAULT_SURFACE_ALPHA`); used as given, like `alpha`.
    pub surface_alpha: f32,
    /// Probability of the zero-variance collision density in guided flights, in [0, 1]
    /// (`render::DEFAULT_DISTANCE_ALPHA`); used as given, like `alpha`, and zero wherever
    /// `alpha` has stopped guiding the path.
    pub distance_alpha: f32,
    /// Weight windows also after each medium collision, before its next-event estimate
    /// (where roulette is guided), besides the one after each direction.
    pub collision_windows: bool,
    /// Flights through a non-emissive medium take an extra collision aimed at the scene's
    /// point and spot lights (equiangular sampling) even where distances are not guided, so
    /// that next-event estimates near such a light have finite variance; in grey fog only
    /// rays that pass close to a light in units of the mean free path
    /// (`guided::distance::free_path_needs_extra`). On by default.
    pub point_light_collisions: bool,
}

/// What the walk needs to know about the pixel and the training it feeds.
#[derive(Debug)]
pub struct WalkContext<'a, C> {
    /// The radiance cache.
    pub cache: &'a mut C,
    /// The pixel's estimated value (luminance), for weight windows; `None` before any.
    pub pixel: Option<f32>,
    /// Records training samples when set (split copies as branches of the path's tree).
    pub recorder: Option<&'a mut PathRecorder>,
    /// Writes down every decision and every light found when set (the firefly diagnostic).
    pub trace: Option<&'a mut Trace>,
}

impl<'a, C> WalkContext<'a, C> {
    /// A context with `cache`, no pixel estimate, no recorder and no trace.
    pub fn new(cache: &'a mut C) -> Self {
        Self { cache, pixel: None, recorder: None, trace: None }
    }
}

/// How the current direction was chosen, for MIS when it finds an emitter.
#[derive(Clone, Copy)]
struct Previous {
    position: Vec3A,
    pdf: f32,
    delta: bool,
}

/// Everything that continues a path: the unit pushed when a path splits.
#[derive(Clone, Copy)]
struct PathState {
    ray: Ray,
    medium: Option<u32>,
    beta: Spectrum,
    eta: f32,
    depth: u32,
    prev: Previous,
    /// How much the path's guided decisions have multiplied its weight relative to standard
    /// sampling (the product of standard over mixture densities).
    guided_gain: f32,
    /// How far the next segment may reach: the camera's far clipping plane for the first,
    /// unbounded after it.
    reach: f32,
    /// Roulette decided at the last vertex and taken after the flight (survival probability
    /// and rule; see [`continue_path`]).
    roulette: Option<(f32, Continuation)>,
    /// A copy split at a medium vertex before its next-event estimate and direction: the
    /// collision's distance along `ray` and its `delta_share` (see [`Walker::vertex_window`]).
    at_vertex: Option<(f32, f32)>,
    /// Where a split copy goes on in the training recorder's tree.
    branch: Branch,
}

/// Where a path starts: its first ray, how far that ray sees (a camera's far clipping plane,
/// infinite for other rays) and the medium it starts in.
#[derive(Clone, Copy, Debug)]
pub struct PathStart {
    /// The first ray.
    pub ray: Ray,
    /// Distance along it beyond which nothing is seen.
    pub reach: f32,
    /// The medium its origin lies in.
    pub medium: Option<u32>,
}

impl PathStart {
    /// A ray from `medium` that sees as far as it goes.
    pub fn unbounded(ray: Ray, medium: Option<u32>) -> Self {
        Self { ray, reach: f32::INFINITY, medium }
    }

    /// The camera ray of `scene` through film position `film` (pixels), clipped as the
    /// camera clips; a thin lens takes its point of the aperture from `sampler`.
    pub fn camera(scene: &Scene, film: Vec2, sampler: &mut Sampler) -> Self {
        let camera = &scene.camera;
        let lens = if camera.has_lens() { sampler.next_2d() } else { Vec2::splat(0.5) };
        let (ray, reach) = camera.ray_and_reach(film, lens);
        Self { ray, reach, medium: scene.camera_medium }
    }
}

/// Split copies waiting to be traced, and how many walks this camera sample has made.
struct Branches {
    /// Uninitialised until pushed: most camera samples never split, and filling a full array
    /// of states for each of them showed in profiles (memmove; see docs/experiments.md).
    stack: ArrayVec<PathState, STACK>,
    walks: usize,
}

/// Estimates the radiance arriving at the start of a path along its first ray.
pub fn radiance<C: RadianceCache>(
    settings: &WalkSettings,
    scene: &Scene,
    start: PathStart,
    ctx: &mut WalkContext<'_, C>,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    counters.paths += 1;
    // Mitsuba's depth counting: at most 0 scattering events, and not even the camera ray's
    // first hit counts.
    if settings.max_depth == Some(0) {
        return Spectrum::ZERO;
    }
    let PathStart { ray, reach, medium } = start;
    let prev = Previous { position: ray.origin, pdf: 1.0, delta: true };
    let (beta, guided_gain) = (Spectrum::ONE, 1.0);
    let state = PathState {
        ray,
        medium,
        beta,
        eta: 1.0,
        depth: 0,
        prev,
        guided_gain,
        reach,
        roulette: None,
        at_vertex: None,
        branch: Branch::default(),
    };
    let mut branches = Branches { stack: ArrayVec::new(), walks: 1 };
    branches.stack.push(state);
    let mut l = Spectrum::ZERO;
    let mut index = 0;
    while let Some(state) = branches.stack.pop() {
        counters.walks += 1;
        trace(ctx, || TraceEvent::Walk {
            walk: index,
            beta: luminance(state.beta),
            depth: state.depth,
        });
        index += 1;
        if let Some(r) = ctx.recorder.as_deref_mut() {
            r.resume(state.branch);
        }
        l += walk(settings, scene, state, ctx, &mut branches, sampler, counters);
    }
    l
}

/// One walk: a loop of named steps, as a volumetric path tracer reads. Each segment is a
/// flight through the medium the path is in (which may end in a medium vertex), then, where
/// the flight passed, the escape to infinite lights, or the surface hit: its emitter, a null
/// crossing, or a surface vertex.
fn walk<C: RadianceCache>(
    settings: &WalkSettings,
    scene: &Scene,
    mut s: PathState,
    ctx: &mut WalkContext<'_, C>,
    branches: &mut Branches,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    let window_rr = settings.guide.roulette && ctx.pixel.is_some();
    let mut w =
        Walker { settings, scene, ctx, branches, sampler, counters, l: Spectrum::ZERO, window_rr };
    let mut nulls = 0u32;
    loop {
        // Guided decisions mix with standard sampling at `alpha`; without weight windows to
        // split heavy paths, only until they have compounded the path's weight past
        // MAX_GUIDED_GAIN, and the rest of the path samples as if unguided.
        let guiding = window_rr || s.guided_gain < MAX_GUIDED_GAIN;
        let alpha = if guiding { settings.alpha } else { 0.0 };
        if let Some((t, delta_share)) = s.at_vertex.take() {
            // A copy split at a medium vertex scatters there (it is in that vertex's medium).
            let m = s.medium.expect("a vertex copy lies in a medium");
            let loaded = w.load(s.ray.at(t));
            if !w.medium_scatter(&mut s, m, t, alpha, delta_share, loaded) {
                break;
            }
            continue;
        }
        w.counters.segments += 1;
        // Only a camera ray's segment is bounded (by the far clipping plane); what follows,
        // split copies included, is not.
        let reach = std::mem::replace(&mut s.reach, f32::INFINITY);
        let hit = scene.intersect(&s.ray, reach);
        let t_max = hit.as_ref().map_or(reach, |h| h.t);
        if let Some(m) = s.medium {
            match w.flight(&mut s, m, t_max, alpha) {
                Flown::Scattered { t, delta_share } => {
                    if !w.settle(&mut s) || !w.medium_vertex(&mut s, m, t, alpha, delta_share) {
                        break;
                    }
                    nulls = 0;
                    continue;
                }
                Flown::Passed => {}
                Flown::Ended => break,
            }
        }
        if !w.settle(&mut s) {
            break;
        }
        let Some(hit) = hit else {
            w.escape(&s);
            break;
        };
        w.emitter_hit(&s, &hit);
        if w.passes_straight(&s, &hit) {
            nulls += 1;
            if nulls > MAX_NULL_CROSSINGS {
                break;
            }
            s.medium = scene.medium_after(&hit, s.ray.direction, s.medium);
            s.ray = Ray::new(offset_origin(hit.p, hit.ng, s.ray.direction), s.ray.direction);
            continue;
        }
        if !w.surface_vertex(&mut s, &hit, guiding) {
            break;
        }
        nulls = 0;
    }
    w.l
}

/// What one walk's steps share: the settings and scene, the per-thread context (cache, pixel
/// estimate, recorder, trace), the random stream, the counters, the split copies waiting, and
/// the radiance found so far.
struct Walker<'w, 'c, C> {
    settings: &'w WalkSettings,
    scene: &'w Scene,
    ctx: &'w mut WalkContext<'c, C>,
    branches: &'w mut Branches,
    sampler: &'w mut Sampler,
    counters: &'w mut Counters,
    /// Radiance found so far.
    l: Spectrum,
    /// Whether weight windows steer roulette and splitting.
    window_rr: bool,
}

/// How a flight through a medium ended.
enum Flown {
    /// In a real scattering collision at `t`, whose next-event estimate of delta lights
    /// carries `delta_share` of them (the rest is an extra collision's).
    Scattered { t: f32, delta_share: f32 },
    /// Past the end of the ray: the surface or infinity comes next.
    Passed,
    /// The path ended (absorbed, or with no weight left).
    Ended,
}

/// A scattering direction and what drawing it did to the path.
#[derive(Clone, Copy)]
struct DirectionSample {
    wi: Vec3A,
    /// The density it was drawn with (the mixture's).
    pdf: f32,
    /// Multiplies the path weight.
    weight: Spectrum,
    /// Multiplies the path's guided gain (standard density over the mixture's).
    gain: f32,
    /// The phase function's or BSDF's own density of it.
    standard_pdf: f32,
    strategy: Strategy,
    /// Drawn from a delta lobe (and its relative index of refraction).
    delta: bool,
    eta: f32,
}

impl<C: RadianceCache> Walker<'_, '_, C> {
    /// Light `c` found by the path (weight `beta`) at `depth`: added to the estimate, taught to
    /// the training samples of the path's earlier vertices, and traced.
    fn found(
        &mut self,
        c: Spectrum,
        source: LightSource,
        depth: u32,
        beta: Spectrum,
        distance: f32,
    ) {
        self.l += c;
        record_contribution(self.ctx, c);
        if c.max_element() > 0.0 {
            trace(self.ctx, || light_event(depth, source, c, beta, distance));
        }
    }

    /// The flight along the path's ray through medium `m` up to `t_max`: a guided flight with
    /// its extra collision for delta lights when distances are guided; otherwise the medium's
    /// tracker, with an extra collision aimed at point and spot lights alone where the ray
    /// passes close to one ([`WalkSettings::point_light_collisions`]).
    fn flight(&mut self, s: &mut PathState, m: u32, t_max: f32, alpha: f32) -> Flown {
        let (scene, settings) = (self.scene, self.settings);
        let medium = &scene.media[m as usize];
        let guided = settings.guide.distances && alpha > 0.0;
        // One past the last depth an extra collision would not estimate any light.
        let lights_ahead = settings.max_depth.is_none_or(|d| s.depth + 1 < d);
        let tracker = scene.trackers[m as usize];
        let with_extra = if guided {
            // Training paths take extra collisions too: their images are averaged into the
            // result.
            let extra_nee =
                (!scene.delta_lights.is_empty() && lights_ahead).then_some(&scene.point_lights[..]);
            Some(guided_flight(
                medium,
                tracker,
                &s.ray,
                t_max,
                s.beta,
                settings.distance_alpha,
                extra_nee,
                self.ctx.cache,
                self.sampler,
                self.counters,
            ))
        } else if settings.point_light_collisions
            && lights_ahead
            && !scene.point_lights.is_empty()
            && !medium.is_emissive()
            && free_path_needs_extra(medium, &s.ray, t_max, &scene.point_lights)
        {
            // Standard free paths, and the equiangular extra collision, which needs no field:
            // without it, next-event estimates of a point light from collisions near it have
            // infinite variance (docs/experiments.md). The field is not asked where to place it.
            let points = Some(&scene.point_lights[..]);
            Some(guided_flight(
                medium,
                tracker,
                &s.ray,
                t_max,
                s.beta,
                0.0,
                points,
                &mut NoCache,
                self.sampler,
                self.counters,
            ))
        } else {
            None
        };
        let (scatter_t, weight, emitted, delta_share) = match with_extra {
            Some(f) => match self.flown(s, medium, f) {
                Some(event) => event,
                None => return Flown::Ended,
            },
            None => {
                let f = sample_flight(
                    medium,
                    tracker,
                    &s.ray,
                    t_max,
                    s.beta,
                    self.sampler,
                    self.counters,
                );
                let t = match f.event {
                    FlightEvent::Scatter { t } => Some(t),
                    FlightEvent::Escape => None,
                };
                (t, f.weight, f.emitted, 1.0)
            }
        };
        self.found(emitted, LightSource::MediumEmission, s.depth, s.beta, 0.0);
        trace(self.ctx, || TraceEvent::Flight {
            depth: s.depth,
            guided,
            scattered: scatter_t.is_some(),
            t: scatter_t.unwrap_or(t_max),
            weight: luminance(weight),
        });
        s.beta *= weight;
        match scatter_t {
            Some(t) => Flown::Scattered { t, delta_share },
            None if s.beta.max_element() <= 0.0 => Flown::Ended,
            None => Flown::Passed,
        }
    }

    /// What a flight from `guided_flight` leaves the walk: its collision (if any), weight,
    /// emission and delta lights' share at the collision, after its extra collision is
    /// estimated; `None` when it was absorbed (its emission then found).
    fn flown(
        &mut self,
        s: &mut PathState,
        medium: &Medium,
        f: GuidedFlight,
    ) -> Option<(Option<f32>, Spectrum, Spectrum, f32)> {
        s.guided_gain *= f.gain;
        if let Some(extra) = f.extra {
            self.extra_collision(s, medium, extra);
        }
        match f.event {
            GuidedEvent::Scatter { t } => Some((Some(t), f.weight, f.emitted, f.delta_share)),
            GuidedEvent::Pass => Some((None, f.weight, f.emitted, f.delta_share)),
            GuidedEvent::Absorb => {
                self.found(f.emitted, LightSource::MediumEmission, s.depth, s.beta, 0.0);
                None
            }
        }
    }

    /// A guided flight's extra collision: next-event estimation of delta lights alone at its
    /// point, weighted against the flight's own collision. The light is what the last vertex's
    /// continuation brought back, as the next vertex's next-event estimate is (the two share
    /// the delta lights by MIS, so the field learns all of it).
    fn extra_collision(&mut self, s: &PathState, medium: &Medium, extra: ExtraCollision) {
        self.counters.extra_collisions += 1;
        let p = s.ray.at(extra.t);
        let (phase, dir) = (medium.phase, s.ray.direction);
        let direct = sample_light(
            self.scene,
            p,
            None,
            s.medium,
            self.sampler,
            self.counters,
            NeeLights::Delta,
            |wi| Spectrum::splat(phase.eval(dir, wi)),
            |_| 0.0,
        );
        let c = s.beta * extra.weight * direct.contribution;
        self.found(c, LightSource::ExtraCollision, s.depth, s.beta, direct.distance);
    }

    /// A real scattering collision at `t` in medium `m`: the weight window on what the
    /// vertex is expected to bring back, then [`Self::medium_scatter`] for each copy. False
    /// when the path ends here.
    fn medium_vertex(
        &mut self,
        s: &mut PathState,
        m: u32,
        t: f32,
        alpha: f32,
        delta_share: f32,
    ) -> bool {
        self.counters.medium_scatters += 1;
        s.depth += 1;
        if self.settings.max_depth.is_some_and(|d| s.depth >= d) || s.beta.max_element() <= 0.0 {
            return false;
        }
        let loaded = self.load(s.ray.at(t));
        if self.window_rr
            && self.settings.collision_windows
            && loaded
            && !self.vertex_window(s, m, t, delta_share)
        {
            return false;
        }
        self.medium_scatter(s, m, t, alpha, delta_share, loaded)
    }

    /// Loads the cache at `p` where the vertex's decisions read it; false where it knows
    /// nothing.
    fn load(&mut self, p: Vec3A) -> bool {
        let loaded =
            self.settings.guide.at_vertices() && self.ctx.cache.load(p, self.sampler.next_1d());
        self.counters.field_lookups += u64::from(loaded);
        loaded
    }

    /// The weight window after distance sampling: roulette or splitting of a path that
    /// collided at `t` in medium `m` by what the collision is expected to bring back, the
    /// light scattered there (the loaded cache's estimate). Split copies wait with the
    /// collision ahead of them. False when roulette ends the path.
    fn vertex_window(&mut self, s: &mut PathState, m: u32, t: f32, delta_share: f32) -> bool {
        let Some(pixel) = self.ctx.pixel else { return true };
        let g = self.scene.media[m as usize].phase.mean_cosine();
        let cache = &*self.ctx.cache;
        // The same robust floor as the window after direction sampling (`adjoint`).
        let adjoint = cache.inscattered(s.ray.direction, g).max(cache.mean_radiance());
        let q = window::factor(luminance(s.beta), adjoint, pixel);
        if q == 1.0 {
            return true;
        }
        let at = Some((t, delta_share));
        let (ctx, branches) = (&mut *self.ctx, &mut *self.branches);
        split(s, q, Continuation::VertexWindow, at, ctx, branches, self.sampler) > 0
    }

    /// What a path does at its collision at `t` in medium `m`, with the cache `loaded` there:
    /// next-event estimation, then a new direction from the vertex's mixture, and roulette or
    /// splitting. False when the path ends here.
    fn medium_scatter(
        &mut self,
        s: &mut PathState,
        m: u32,
        t: f32,
        alpha: f32,
        delta_share: f32,
        loaded: bool,
    ) -> bool {
        let (scene, settings) = (self.scene, self.settings);
        let (p, dir) = (s.ray.at(t), s.ray.direction);
        let phase = scene.media[m as usize].phase;
        let g = phase.mean_cosine();
        let guide = settings.guide;
        let product =
            guide.directions && alpha > 0.0 && loaded && self.ctx.cache.product_hg(dir, g);
        if product && g.abs() >= EXACT_PRODUCT_MIN_G {
            self.counters.products += 1;
        } else if product && g.abs() >= PRODUCT_MIN_G {
            self.counters.lobe_products += 1;
        }
        let mix = Mixture::at(settings, alpha, product, scene, p);
        let cache = &*self.ctx.cache;
        let direct = sample_light(
            scene,
            p,
            None,
            s.medium,
            self.sampler,
            self.counters,
            NeeLights::All { delta_share },
            |wi| Spectrum::splat(phase.eval(dir, wi)),
            |wi| mix.pdf(cache, wi, phase.eval(dir, wi)),
        );
        // Earlier vertices learn it (this one learns it in its direct fluence).
        let c = s.beta * direct.contribution;
        self.found(c, LightSource::NeeMedium, s.depth, s.beta, direct.distance);
        let d = self.medium_direction(&mix, phase, dir);
        self.trace_direction(s.depth, false, loaded, &d);
        if !positive(d.pdf) {
            return false;
        }
        s.beta *= d.weight;
        s.guided_gain *= d.gain;
        record_vertex(self.ctx, p, d.wi, d.pdf, s.beta, true, &direct);
        s.ray = Ray::new(p, d.wi);
        s.prev = Previous { position: p, pdf: d.pdf, delta: false };
        self.go_on(s, loaded, &mix, d.wi)
    }

    /// A direction at a medium vertex from `mix` around the phase function (the weight is one
    /// where phase sampling draws alone: it draws exactly the phase function).
    fn medium_direction(
        &mut self,
        mix: &Mixture,
        phase: PhaseFunction,
        dir: Vec3A,
    ) -> DirectionSample {
        let (wi, pdf, pp, strategy) = if mix.mixes() {
            let (strategy, u) = mix.choose(self.sampler.next_1d());
            let wi = match strategy {
                Strategy::Standard => phase.sample(dir, self.sampler.next_2d()).0,
                _ => mix.sample(self.ctx.cache, strategy, u, self.sampler.next_2d()),
            };
            let pp = phase.eval(dir, wi);
            (wi, mix.pdf(self.ctx.cache, wi, pp), pp, strategy)
        } else {
            let (wi, pp) = phase.sample(dir, self.sampler.next_2d());
            (wi, pp, pp, Strategy::Standard)
        };
        let ratio = if mix.mixes() { pp / pdf } else { 1.0 };
        DirectionSample {
            wi,
            pdf,
            weight: Spectrum::splat(ratio),
            gain: ratio,
            standard_pdf: pp,
            strategy,
            delta: false,
            eta: 1.0,
        }
    }

    /// Roulette that waited for the flight into a light's glow (see [`continue_path`]); false
    /// when the path ends.
    fn settle(&mut self, s: &mut PathState) -> bool {
        match s.roulette.take() {
            Some((q, rule)) => survives(s, q, rule, self.ctx, self.sampler),
            None => true,
        }
    }

    /// Roulette or splitting after the direction `wi` was chosen from `mix` at a vertex (by the
    /// weight window where the cache was `loaded` there). False when the path ends.
    fn go_on(&mut self, s: &mut PathState, loaded: bool, mix: &Mixture, wi: Vec3A) -> bool {
        let adjoint = if self.window_rr && loaded { adjoint(self.ctx.cache, wi) } else { 0.0 };
        let glow = mix.in_glow(wi);
        continue_path(self.settings, s, adjoint, glow, self.ctx, self.branches, self.sampler)
    }

    fn trace_direction(&mut self, depth: u32, surface: bool, loaded: bool, d: &DirectionSample) {
        trace(self.ctx, || TraceEvent::Direction {
            depth,
            surface,
            loaded,
            strategy: d.strategy,
            pdf: d.pdf,
            standard_pdf: d.standard_pdf,
            weight: luminance(d.weight),
        });
    }

    /// Whether the path passes straight through the surface it hit, without a scattering
    /// event: always through a null surface, through a thin dielectric with the share that
    /// passes (Mitsuba's null component), its weight unchanged since that share is the
    /// probability. Otherwise the surface scatters (a thin dielectric then reflects).
    fn passes_straight(&mut self, s: &PathState, hit: &SurfaceHit) -> bool {
        match self.scene.null_transmission(hit.shape, s.ray.direction.dot(hit.ng), || hit.uv) {
            Some(p) if p >= 1.0 => true,
            Some(p) => self.sampler.next_1d() < p,
            None => false,
        }
    }

    /// Whether the emitters the path finds now are hidden: seen straight from the camera
    /// (Mitsuba's `hide_emitters`, depth 0 after any null crossings).
    fn hides_emitters(&self, s: &PathState) -> bool {
        s.depth == 0 && self.scene.settings().hide_emitters
    }

    /// The path escaped: infinite lights it sees, weighed against next-event estimation.
    fn escape(&mut self, s: &PathState) {
        if self.hides_emitters(s) {
            return;
        }
        for &li in &self.scene.infinite_lights {
            let (le, pdf) = self.scene.lights[li as usize].eval_escaped(s.ray.direction);
            if le.max_element() > 0.0 {
                let c = s.beta * le * mis_emitter(self.scene, s.prev, pdf);
                self.found(c, LightSource::Escape, s.depth, s.beta, 0.0);
            }
        }
    }

    /// The path hit a surface: the light it emits, weighed against next-event estimation.
    fn emitter_hit(&mut self, s: &PathState, hit: &SurfaceHit) {
        let scene = self.scene;
        let Some(li) = scene.surfaces[hit.shape as usize].light else { return };
        if self.hides_emitters(s) {
            return;
        }
        let light = &scene.lights[li as usize];
        let le = light.eval_area(hit.ng, -s.ray.direction);
        if le.max_element() > 0.0 {
            let pdf = light.pdf_area(&scene.shapes, s.prev.position, hit.p, hit.ng);
            let c = s.beta * le * mis_emitter(scene, s.prev, pdf);
            self.found(c, LightSource::EmitterHit, s.depth, s.beta, hit.t);
        }
    }

    /// A scattering surface: next-event estimation where the BSDF has a smooth part, then a
    /// new direction from the vertex's mixture, and roulette or splitting. False when the path
    /// ends here.
    fn surface_vertex(&mut self, s: &mut PathState, hit: &SurfaceHit, guiding: bool) -> bool {
        let (scene, settings) = (self.scene, self.settings);
        self.counters.surface_scatters += 1;
        s.depth += 1;
        if settings.max_depth.is_some_and(|d| s.depth >= d) {
            return false;
        }
        let at = SurfacePoint::new(scene, hit, s.ray.direction);
        let guide = settings.guide;
        let smooth = at.bsdf.has_smooth_component();
        let guides = at.bsdf.guides();
        let loaded =
            guides && guide.at_vertices() && self.ctx.cache.load(hit.p, self.sampler.next_1d());
        self.counters.field_lookups += u64::from(loaded);
        // Surfaces have a share of their own (`render::DEFAULT_SURFACE_ALPHA`).
        let alpha = if guiding { settings.surface_alpha } else { 0.0 };
        let product =
            guide.directions && alpha > 0.0 && loaded && self.ctx.cache.product_cosine(hit.ns);
        let mix = if guides {
            Mixture::at(settings, alpha, product, scene, hit.p)
        } else {
            Mixture::NONE
        };
        let mut direct = DirectSample::NONE;
        if smooth {
            let cache = &*self.ctx.cache;
            direct = sample_light(
                scene,
                hit.p,
                Some(hit),
                s.medium,
                self.sampler,
                self.counters,
                NeeLights::All { delta_share: 1.0 },
                |wi| at.eval(wi),
                |wi| mix.pdf(cache, wi, at.pdf(wi)),
            );
            let c = s.beta * direct.contribution;
            self.found(c, LightSource::NeeSurface, s.depth, s.beta, direct.distance);
        }
        let Some(d) = self.surface_direction(&mix, &at) else { return false };
        // Shading and geometric normals may disagree: a direction under the geometric
        // surface would leak light through it.
        if !d.delta && (d.wi.dot(hit.ng) > 0.0) != (at.frame.to_local(d.wi).z > 0.0) {
            return false;
        }
        self.trace_direction(s.depth, true, loaded, &d);
        if d.weight.max_element() <= 0.0 || !positive(d.pdf) {
            return false;
        }
        s.beta *= d.weight;
        s.eta *= d.eta;
        s.guided_gain *= d.gain;
        if !d.delta {
            record_vertex(self.ctx, hit.p, d.wi, d.pdf, s.beta, false, &direct);
        }
        s.medium = scene.medium_after(hit, d.wi, s.medium);
        s.ray = Ray::new(offset_origin(hit.p, hit.ng, d.wi), d.wi);
        s.prev = Previous { position: hit.p, pdf: d.pdf, delta: d.delta };
        self.go_on(s, loaded, &mix, d.wi)
    }

    /// A direction at a surface from `mix` around the BSDF; `None` where the BSDF draws none.
    /// The number that chooses the strategy, rescaled, also picks the BSDF's lobe (or the
    /// halo's light), so every branch sees a uniform number.
    fn surface_direction(
        &mut self,
        mix: &Mixture,
        at: &SurfacePoint<'_>,
    ) -> Option<DirectionSample> {
        let (strategy, mut u1) = if mix.mixes() {
            mix.choose(self.sampler.next_1d())
        } else {
            (Strategy::Standard, self.sampler.next_1d())
        };
        // A thin dielectric's transmission was already taken as a null crossing
        // (`passes_straight`): what scatters here reflects, as 0 draws its reflection.
        if matches!(*at.bsdf, Bsdf::ThinDielectric { .. })
            && !self.scene.settings.surface_events_only
        {
            u1 = 0.0;
        }
        let cache = &*self.ctx.cache;
        // BSDF sampling's density over the mixture's at `wi`.
        let gain_at =
            |wi: Vec3A, pdf: f32| if mix.mixes() && pdf > 0.0 { at.pdf(wi) / pdf } else { 1.0 };
        let mixed = |wi: Vec3A, f: Spectrum, eta: f32, strategy: Strategy| {
            let pdf = mix.pdf(cache, wi, at.pdf(wi));
            let weight = if pdf > 0.0 { f / pdf } else { Spectrum::ZERO };
            let (gain, standard_pdf) = (gain_at(wi, pdf), at.pdf(wi));
            DirectionSample { wi, pdf, weight, gain, standard_pdf, strategy, delta: false, eta }
        };
        if strategy != Strategy::Standard {
            let wi = mix.sample(cache, strategy, u1, self.sampler.next_2d());
            return Some(mixed(wi, at.eval(wi), 1.0, strategy));
        }
        let bs = at.bsdf.sample(at.wo, at.uv, u1, self.sampler.next_2d())?;
        let wi = at.frame.to_world(bs.wi).normalize();
        let plain = |weight: Spectrum, pdf: f32, delta: bool| DirectionSample {
            wi,
            pdf,
            weight,
            gain: 1.0,
            standard_pdf: pdf,
            strategy,
            delta,
            eta: bs.eta,
        };
        Some(if mix.mixes() && !bs.delta {
            mixed(wi, at.bsdf.eval(at.wo, bs.wi, at.uv), bs.eta, strategy)
        } else if mix.mixes() {
            // A delta lobe is drawn with the standard share's probability.
            let share = mix.standard_share();
            plain(bs.weight / share, bs.pdf * share, true)
        } else {
            plain(bs.weight, bs.pdf, bs.delta)
        })
    }
}

/// A surface hit as the BSDF sees it: the BSDF, its shading frame, the outgoing direction in
/// that frame, and the texture coordinates.
struct SurfacePoint<'a> {
    bsdf: &'a Bsdf,
    frame: Frame,
    wo: Vec3A,
    uv: Vec2,
}

impl<'a> SurfacePoint<'a> {
    fn new(scene: &'a Scene, hit: &SurfaceHit, ray_dir: Vec3A) -> Self {
        let bsdf = &scene.surfaces[hit.shape as usize].bsdf;
        let frame =
            if bsdf.is_anisotropic() { scene.tangent_frame(hit) } else { Frame::from_z(hit.ns) };
        SurfacePoint { bsdf, frame, wo: frame.to_local(-ray_dir), uv: hit.uv }
    }

    /// The BSDF's value towards the world direction `wi`.
    fn eval(&self, wi: Vec3A) -> Spectrum {
        self.bsdf.eval(self.wo, self.frame.to_local(wi), self.uv)
    }

    /// The BSDF sampling density of the world direction `wi`.
    fn pdf(&self, wi: Vec3A) -> f32 {
        self.bsdf.pdf(self.wo, self.frame.to_local(wi), self.uv)
    }
}

/// The mixture a vertex draws its direction from: the guided distribution (at `guided`, when
/// the cache prepared one), the glow around point lights (`guided::halo`, at its share where
/// one may be seen from the vertex), and the phase function or BSDF (the rest).
#[derive(Clone, Debug)]
struct Mixture {
    guided: f32,
    halo: Option<Halo>,
}

impl Mixture {
    /// The standard strategy alone.
    const NONE: Mixture = Mixture { guided: 0.0, halo: None };

    /// The mixture at `x` for a guided share `alpha` (used when `product`: the cache holds a
    /// distribution for the vertex); the halo joins wherever directions are guided.
    fn at(settings: &WalkSettings, alpha: f32, product: bool, scene: &Scene, x: Vec3A) -> Self {
        let guiding = settings.guide.directions && alpha > 0.0;
        Mixture {
            guided: if product { alpha } else { 0.0 },
            halo: if guiding { Halo::at(x, &scene.point_lights) } else { None },
        }
    }

    /// Whether anything but the standard strategy is in it.
    fn mixes(&self) -> bool {
        self.guided > 0.0 || self.halo.is_some()
    }

    /// Whether `wi` heads into a light's glow (see [`continue_path`]).
    fn in_glow(&self, wi: Vec3A) -> bool {
        self.halo.as_ref().is_some_and(|h| h.covers(wi))
    }

    fn halo_share(&self) -> f32 {
        if self.halo.is_some() { halo::SHARE } else { 0.0 }
    }

    /// The standard strategy's share.
    fn standard_share(&self) -> f32 {
        1.0 - self.guided - self.halo_share()
    }

    /// The strategy a uniform `u` chooses, and `u` rescaled to a uniform number again.
    fn choose(&self, u: f32) -> (Strategy, f32) {
        let halo = self.halo_share();
        if u < self.guided {
            (Strategy::Guided, u / self.guided)
        } else if u < self.guided + halo {
            (Strategy::Halo, (u - self.guided) / halo)
        } else {
            (Strategy::Standard, (u - self.guided - halo) / self.standard_share())
        }
    }

    /// A direction from the guided distribution or the halo (`pick` chooses the halo's light).
    fn sample<C: RadianceCache>(&self, cache: &C, strategy: Strategy, pick: f32, u: Vec2) -> Vec3A {
        match (&self.halo, strategy) {
            (Some(h), Strategy::Halo) => h.sample(pick, u),
            _ => cache.sample(u),
        }
    }

    /// The mixture's density at `wi`, where the standard strategy's is `standard`.
    fn pdf<C: RadianceCache>(&self, cache: &C, wi: Vec3A, standard: f32) -> f32 {
        let guided = if self.guided > 0.0 { self.guided * cache.pdf(wi) } else { 0.0 };
        match &self.halo {
            None if self.guided > 0.0 => guided + (1.0 - self.guided) * standard,
            None => standard,
            Some(h) => guided + halo::SHARE * h.pdf(wi) + self.standard_share() * standard,
        }
    }
}

/// Russian roulette (or splitting) after a direction was chosen; false when the path ends.
/// With a usable `adjoint` and a pixel estimate, the weight window decides (and very deep
/// paths meet the standard rule too); otherwise the standard rule from `rr_depth` on.
///
/// Roulette of a direction into a point light's `glow` waits until the flight along it has
/// taken its extra collision ([`Walker::settle`]): the ray may pass the light closely, where
/// the light it brings back grows as one over the distance, and neither the fitted adjoint nor
/// the path weight (small there, as the halo's density is large) sees that. Rouletted before
/// the flight at the smallest survival, survivors carried that light at ten times its weight:
/// the fog room's fireflies (see docs/experiments.md).
fn continue_path<C>(
    settings: &WalkSettings,
    s: &mut PathState,
    adjoint: f32,
    glow: bool,
    ctx: &mut WalkContext<'_, C>,
    branches: &mut Branches,
    sampler: &mut Sampler,
) -> bool {
    if adjoint > 0.0
        && let Some(pixel) = ctx.pixel
    {
        let q = window::factor(luminance(s.beta), adjoint, pixel);
        if glow && q < 1.0 {
            s.roulette = Some((q, Continuation::Window));
            return true;
        }
        let n = split(s, q, Continuation::Window, None, ctx, branches, sampler);
        if n == 0 {
            return false;
        }
        // A window that keeps returning 1 (an albedo-1 medium, a flat cache) must not make a
        // walk endless: deep paths get the standard roulette as well.
        if n > 1 || s.depth < settings.rr_depth.max(WINDOW_RR_DEPTH) {
            return true;
        }
    } else if s.depth < settings.rr_depth {
        return true;
    }
    let q = (s.beta.max_element() * s.eta * s.eta).min(0.95);
    if glow && q > 0.0 {
        s.roulette = Some((q, Continuation::Standard));
        return true;
    }
    survives(s, q, Continuation::Standard, ctx, sampler)
}

/// Roulette or splitting by a weight window's factor `q` (the expected number of walks that go
/// on), limited to the room left for walks: each goes on with weight `1 / q`, the copies from
/// the stack, resuming at the collision `at` ahead of them (its distance and `delta_share`) or
/// with the next segment. Returns how many go on, the path itself among them (0: it ends).
fn split<C>(
    s: &mut PathState,
    q: f32,
    rule: Continuation,
    at: Option<(f32, f32)>,
    ctx: &mut WalkContext<'_, C>,
    branches: &mut Branches,
    sampler: &mut Sampler,
) -> u32 {
    let room = branches.stack.remaining_capacity().min(MAX_WALKS - branches.walks + 1);
    // Limiting q itself (not the rounded count) to the room left keeps E[n] / q = 1.
    let q = q.min(room.max(1) as f32);
    let n = window::copies(q, sampler.next_1d());
    let depth = s.depth;
    trace(ctx, || TraceEvent::Continue { depth, rule, q, copies: n });
    if n == 0 {
        return 0;
    }
    s.beta /= q;
    if let Some(r) = ctx.recorder.as_deref() {
        s.branch = r.branch();
    }
    let copy = PathState { at_vertex: at, ..*s };
    for _ in 1..n {
        branches.stack.push(copy);
        branches.walks += 1;
    }
    n
}

/// Roulette with survival probability `q` by `rule`: survivors are weighted by `1 / q`.
fn survives<C>(
    s: &mut PathState,
    q: f32,
    rule: Continuation,
    ctx: &mut WalkContext<'_, C>,
    sampler: &mut Sampler,
) -> bool {
    let survives = !q.is_nan() && q > 0.0 && sampler.next_1d() < q;
    let (depth, copies) = (s.depth, u32::from(survives));
    trace(ctx, || TraceEvent::Continue { depth, rule, q, copies });
    if survives {
        s.beta /= q;
    }
    survives
}

/// Writes `event()` down when the walk is traced.
#[inline]
fn trace<C>(ctx: &mut WalkContext<'_, C>, event: impl FnOnce() -> TraceEvent) {
    if let Some(t) = ctx.trace.as_deref_mut() {
        t.push(event());
    }
}

fn light_event(
    depth: u32,
    source: LightSource,
    c: Spectrum,
    beta: Spectrum,
    distance: f32,
) -> TraceEvent {
    TraceEvent::Light { depth, source, contribution: luminance(c), beta: luminance(beta), distance }
}

/// What a path is expected to bring back after its direction `wi` was chosen at the loaded
/// point, for the weight window: the incident radiance along `wi`, or the mean incident
/// radiance (which includes the direct light next-event estimation collects) where that is
/// larger. Survivors of roulette are weighted by `1 / q`, so an adjoint that underestimates
/// makes fireflies while one that overestimates only splits more; hence the larger of the two.
fn adjoint<C: RadianceCache>(cache: &C, wi: Vec3A) -> f32 {
    cache.incident(wi).max(cache.mean_radiance())
}

/// MIS weight of an emitter found by the previous direction sample.
#[inline]
fn mis_emitter(scene: &Scene, prev: Previous, light_pdf: f32) -> f32 {
    if prev.delta { 1.0 } else { power_heuristic(prev.pdf, light_pdf / scene.lights.len() as f32) }
}

/// One next-event estimate: its contribution (before the path throughput) and what training
/// learns from it.
#[derive(Clone, Copy)]
struct DirectSample {
    contribution: Spectrum,
    /// Density of the light sample, light selection included (for a delta light, the
    /// selection probability alone).
    pdf: f32,
    /// MIS-weighted radiance arriving from the light (luminance): `radiance / pdf` estimates
    /// the fluence next-event estimation collects.
    radiance: f32,
    /// Unit direction towards the sampled light.
    direction: Vec3A,
    /// Distance to the light sample.
    distance: f32,
}

impl DirectSample {
    const NONE: DirectSample = DirectSample {
        contribution: Spectrum::ZERO,
        pdf: 0.0,
        radiance: 0.0,
        direction: Vec3A::ZERO,
        distance: 0.0,
    };
}

/// Next-event estimation: one light chosen uniformly, a direction sampled on it, weighed
/// against the scattering strategy (its value `f(wi)` and density `pdf(wi)`) with the power
/// heuristic. The density, which for a guided vertex is a mixture evaluation, is asked for
/// only where it counts: not for delta lights, nor for a light the shadow ray found blocked.
#[allow(clippy::too_many_arguments)]
fn sample_light(
    scene: &Scene,
    p: Vec3A,
    surface: Option<&SurfaceHit>,
    medium: Option<u32>,
    sampler: &mut Sampler,
    counters: &mut Counters,
    lights: NeeLights,
    f: impl Fn(Vec3A) -> Spectrum,
    pdf: impl Fn(Vec3A) -> f32,
) -> DirectSample {
    let pick = sampler.next_1d();
    let u = sampler.next_2d();
    // An extra collision picks among delta lights alone: picking among all, it would waste
    // its shadow ray and its parts' lookups whenever it drew another light.
    let n = match lights {
        NeeLights::All { .. } => scene.lights.len(),
        NeeLights::Delta => scene.delta_lights.len(),
    };
    if n == 0 {
        return DirectSample::NONE;
    }
    let k = ((pick * n as f32) as usize).min(n - 1);
    let light = match lights {
        NeeLights::All { .. } => &scene.lights[k],
        NeeLights::Delta => &scene.lights[scene.delta_lights[k] as usize],
    };
    let Some(ls) = light.sample(&scene.shapes, p, u) else { return DirectSample::NONE };
    let f = f(ls.wi);
    if f.max_element() <= 0.0 {
        return DirectSample::NONE;
    }
    let origin = surface.map_or(p, |h| offset_origin(p, h.ng, ls.wi));
    // A light seen through a transmitting surface is reached through the medium beyond it.
    let medium = surface.map_or(medium, |h| scene.medium_after(h, ls.wi, medium));
    // Aim from the offset origin at the sampled point itself: the offset moves the origin
    // towards the light, and along `wi` the light's own surface would then lie closer than
    // `distance`, by offset / cos at the light, and block the ray (far from a light, where the
    // offset grows with the coordinates, and at grazing angles on the light).
    let (dir, reach) = match light {
        Light::Area { .. } => {
            let to = p + ls.wi * ls.distance - origin;
            let length = to.length();
            (to / length, length * (1.0 - 1e-4))
        }
        l if l.is_infinite() => (ls.wi, scene.infinite_reach(p)),
        _ => (ls.wi, ls.distance),
    };
    let tr = shadow_transmittance(scene, Ray::new(origin, dir), reach, medium, sampler, counters);
    if tr.max_element() <= 0.0 {
        return DirectSample::NONE;
    }
    let light_pdf = ls.pdf / n as f32;
    let w = if ls.delta { 1.0 } else { power_heuristic(light_pdf, pdf(ls.wi)) };
    let arriving = tr * ls.radiance * w;
    // The share of a delta light another estimate covers too is left out of the contribution
    // only: the direct-fluence record stays the whole estimate.
    let share = match lights {
        NeeLights::All { delta_share } if ls.delta => delta_share,
        _ => 1.0,
    };
    DirectSample {
        contribution: f * arriving * (share / light_pdf),
        pdf: light_pdf,
        radiance: luminance(arriving),
        direction: dir,
        distance: ls.distance,
    }
}

/// The lights a next-event estimate covers.
#[derive(Clone, Copy, Debug, PartialEq)]
enum NeeLights {
    /// All lights, delta ones weighted by `delta_share` (their MIS weight against a guided
    /// flight's extra collision; 1 when there is none).
    All { delta_share: f32 },
    /// Delta lights alone, one picked uniformly among them, unweighted (an extra collision,
    /// which carries its MIS weight).
    Delta,
}

fn record_vertex<C: RadianceCache>(
    ctx: &mut WalkContext<'_, C>,
    p: Vec3A,
    wi: Vec3A,
    pdf: f32,
    beta: Spectrum,
    volume: bool,
    direct: &DirectSample,
) {
    if let Some(r) = ctx.recorder.as_deref_mut() {
        // The field learns what the continuation brings back; next-event estimates go to the
        // cache's direct-fluence records instead (`guided::DirectFluence`).
        r.add_vertex(p.into(), wi.into(), pdf, luminance(beta), volume);
        let fluence = if direct.pdf > 0.0 { direct.radiance / direct.pdf } else { 0.0 };
        ctx.cache.record_direct(DirectRecord {
            position: p,
            fluence: if fluence.is_finite() { fluence } else { 0.0 },
            direction: direct.direction,
        });
    }
}

#[inline]
fn record_contribution<C>(ctx: &mut WalkContext<'_, C>, c: Spectrum) {
    if let Some(r) = ctx.recorder.as_deref_mut() {
        let v = luminance(c);
        if v > 0.0 {
            r.add_weighted_contribution(v);
        }
    }
}

/// Transmittance along a shadow ray through media and null surfaces; zero when anything else
/// blocks it.
pub fn shadow_transmittance(
    scene: &Scene,
    ray: Ray,
    distance: f32,
    mut medium: Option<u32>,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    let mut crossings = ArrayVec::<Crossing, SHADOW_CROSSINGS>::new();
    match scene.trace_shadow(&ray, distance, medium, &mut crossings) {
        ShadowTrace::Blocked => Spectrum::ZERO,
        ShadowTrace::Overflow => shadow_steps(scene, ray, distance, medium, sampler, counters),
        ShadowTrace::Clear => {
            let mut tr = Spectrum::ONE;
            let mut start = 0.0;
            // The shadow ray's end closes the last part.
            let end = Crossing { t: distance, passes: 1.0, medium: None };
            for &Crossing { t: end, passes, medium: next } in crossings.iter().chain([&end]) {
                let part = Ray::new(ray.at(start), ray.direction);
                tr *= part_transmittance(scene, medium, &part, end - start, sampler, counters);
                tr *= passes;
                if tr.max_element() <= 0.0 {
                    return Spectrum::ZERO;
                }
                (start, medium) = (end, next);
            }
            tr
        }
    }
}

/// The transmittance of `length` of `ray` inside `medium` (one where there is none), by the
/// medium's tracker.
fn part_transmittance(
    scene: &Scene,
    medium: Option<u32>,
    ray: &Ray,
    length: f32,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    medium.map_or(Spectrum::ONE, |m| {
        let (medium, tracker) = (&scene.media[m as usize], scene.trackers[m as usize]);
        transmittance_tracked(medium, tracker, ray, length, sampler, counters)
    })
}

/// [`shadow_transmittance`] one null surface at a time, for rays crossing more of them than
/// one traversal collects.
fn shadow_steps(
    scene: &Scene,
    mut ray: Ray,
    mut distance: f32,
    mut medium: Option<u32>,
    sampler: &mut Sampler,
    counters: &mut Counters,
) -> Spectrum {
    let mut tr = Spectrum::ONE;
    for _ in 0..MAX_NULL_CROSSINGS {
        let hit = scene.intersect(&ray, distance);
        let seg = hit.as_ref().map_or(distance, |h| h.t);
        tr *= part_transmittance(scene, medium, &ray, seg, sampler, counters);
        if tr.max_element() <= 0.0 {
            return Spectrum::ZERO;
        }
        let Some(hit) = hit else { return tr };
        match scene.null_transmission(hit.shape, ray.direction.dot(hit.ng), || hit.uv) {
            Some(passes) => tr *= passes,
            None => return Spectrum::ZERO,
        }
        medium = scene.medium_after(&hit, ray.direction, medium);
        let origin = offset_origin(hit.p, hit.ng, ray.direction);
        distance -= (origin - ray.origin).length();
        if distance <= 0.0 {
            return tr;
        }
        ray = Ray::new(origin, ray.direction);
    }
    Spectrum::ZERO
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two media in nested null shapes (a sphere inside a box, crossed twice each) and, beyond
    /// the box, two opaque rectangles with a gap between them.
    const NESTED: &str = r#"
[camera]
origin = [0, 0, 6]
target = [0, 0, 0]
fov = 40
resolution = [8, 8]

[media.thin]
type = "homogeneous"
sigma_t = [0.3, 0.4, 0.5]
albedo = 0.5

[media.dense]
type = "homogeneous"
sigma_t = 2
albedo = 0.5

[[shapes]]
type = "cube"
transform = [{ scale = [2, 1.5, 2] }]
bsdf = { type = "null" }
interior = "thin"

[[shapes]]
type = "sphere"
center = [0.3, 0, 0]
radius = 0.8
bsdf = { type = "null" }
interior = "dense"
exterior = "thin"

[[shapes]]
type = "rectangle"
transform = [{ scale = [3, 1, 1] }, { translate = [0, 2, -2.5] }]
bsdf = { type = "diffuse" }

[[shapes]]
type = "rectangle"
transform = [{ scale = [3, 1, 1] }, { translate = [0, -2, -2.5] }]
bsdf = { type = "diffuse" }

[[lights]]
type = "constant"
radiance = 1
"#;

    /// One traversal that collects null crossings must agree with crossing them one at a
    /// time, which re-traces from each crossing and so sees every hit of a closed shape.
    #[test]
    fn shadow_rays_in_one_traversal_see_what_step_by_step_tracing_sees() {
        let path = std::path::Path::new("nested.toml");
        let scene = crate::scene::load_str(path, NESTED, &[]).unwrap_or_else(|e| panic!("{e}"));
        let mut sampler = Sampler::new(7, 0, 0);
        let mut counters = Counters::default();
        let (mut differ, mut blocked, mut crossed, n) = (0, 0, 0, 20_000);
        for i in 0..n {
            let mut u = || 2.0 * sampler.next_1d() - 1.0;
            let origin = 2.2 * Vec3A::new(u(), u(), u());
            let dir = Vec3A::new(u(), u(), u()).normalize_or(Vec3A::X);
            let ray = Ray::new(origin, dir);
            let reach = [f32::INFINITY, 2.5, 6.0][i % 3];
            let medium = [None, Some(0), Some(1)][i % 3];
            let one = shadow_transmittance(&scene, ray, reach, medium, &mut sampler, &mut counters);
            let steps = shadow_steps(&scene, ray, reach, medium, &mut sampler, &mut counters);
            assert!(one.is_finite() && one.min_element() >= 0.0, "{ray:?}: {one:?}");
            // Step by step skips RAY_EPSILON (1 + |p|), about 4e-4, along the normal at each
            // of up to 4 crossings, through sigma_t up to 2: optical depth 0.005 up to about
            // 80 degrees from the normal.
            differ += usize::from((one - steps).abs().max_element() > 0.005 * steps.max_element());
            blocked += usize::from(steps.max_element() == 0.0);
            let mut crossings = ArrayVec::<Crossing, SHADOW_CROSSINGS>::new();
            let trace = scene.trace_shadow(&ray, reach, medium, &mut crossings);
            crossed += usize::from(trace == ShadowTrace::Clear && crossings.len() >= 3);
        }
        // Both must occur often for the comparison to mean anything.
        assert!(blocked > n / 20 && crossed > n / 50, "blocked {blocked}, crossed 3+ {crossed}");
        // Rays within rounding of an edge may go either way, and step by step skips
        // offset / |cos| of a ray grazing a surface (10 rays here, all through the sphere at
        // |cos| < 0.2, by 0.5-2%); missing or mislabelled crossings change hundreds (894
        // without the second crossings of closed shapes).
        assert!(differ <= n / 1000, "{differ} of {n} rays differ");
    }

    /// A shadow ray crossing more null surfaces than one traversal collects is traced step by
    /// step, and still sees the transmittance of every box it passes.
    #[test]
    fn shadow_rays_crossing_many_boxes_keep_their_transmittance() {
        let mut text = String::from(
            "[camera]\norigin = [0, 0, 6]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [8, 8]\n\n\
             [media.fog]\ntype = \"homogeneous\"\nsigma_t = 0.5\nalbedo = 0.5\n",
        );
        // Ten boxes 0.2 wide along x, 0.5 apart: twenty crossings.
        for k in 0..10 {
            let x = k as f32 * 0.5;
            text += &format!(
                "\n[[shapes]]\ntype = \"cube\"\ntransform = [{{ scale = [0.1, 1, 1] }}, \
                 {{ translate = [{x}, 0, 0] }}]\nbsdf = {{ type = \"null\" }}\ninterior = \"fog\"\n"
            );
        }
        let path = std::path::Path::new("boxes.toml");
        let scene = crate::scene::load_str(path, &text, &[]).unwrap_or_else(|e| panic!("{e}"));
        let ray = Ray::new(Vec3A::new(-1.0, 0.1, 0.2), Vec3A::X);
        let mut crossings = ArrayVec::<Crossing, SHADOW_CROSSINGS>::new();
        assert_eq!(scene.trace_shadow(&ray, 10.0, None, &mut crossings), ShadowTrace::Overflow);
        let mut sampler = Sampler::new(7, 0, 0);
        let tr =
            shadow_transmittance(&scene, ray, 10.0, None, &mut sampler, &mut Counters::default());
        // Ten boxes of 0.2 at sigma_t 0.5; restarting at each box, step-by-step tracing skips
        // 1e-4 (1 + |x|) of its fog: 0.0016 of optical depth in all.
        let expected = (-0.5f32 * 10.0 * 0.2).exp();
        assert!((tr.x - expected).abs() < 2e-3 * expected, "{tr:?} against {expected}");
        // Blocked rays stay blocked however many boxes precede the wall.
        let wall = format!(
            "{text}\n[[shapes]]\ntype = \"rectangle\"\ntransform = [{{ rotate = {{ axis = [0, 1, 0], \
             angle = 90 }} }}, {{ translate = [6, 0, 0] }}]\nbsdf = {{ type = \"diffuse\" }}\n"
        );
        let scene = crate::scene::load_str(path, &wall, &[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scene.trace_shadow(&ray, 10.0, None, &mut crossings), ShadowTrace::Blocked);
        let tr =
            shadow_transmittance(&scene, ray, 10.0, None, &mut sampler, &mut Counters::default());
        assert_eq!(tr, Spectrum::ZERO);
    }

    /// A thin dielectric lets a shadow ray through with the share Mitsuba's null component
    /// passes, `1 - R'` at the ray's angle, from either side; a diffuse surface blocks it.
    #[test]
    fn shadow_rays_pass_thin_dielectrics_by_their_null_transmission() {
        let text = "[camera]\norigin = [0, 0, 6]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [8, 8]\n\n\
                    [[shapes]]\ntype = \"rectangle\"\nscale = 1\ntransform = [{ scale = 5 }]\n\
                    bsdf = { type = \"thindielectric\", int_ior = 1.5, ext_ior = 1 }\n";
        let text = text.replace("scale = 1\n", "");
        let scene = crate::scene::load_str(std::path::Path::new("pane.toml"), &text, &[])
            .unwrap_or_else(|e| panic!("{e}"));
        let mut sampler = Sampler::new(3, 0, 0);
        for (dir, cos) in [(Vec3A::new(0.0, 0.0, -1.0), 1.0f32), (Vec3A::new(0.6, 0.0, 0.8), 0.8)] {
            for side in [1.0f32, -1.0] {
                let ray = Ray::new(-side * 2.0 * dir, side * dir);
                let tr = shadow_transmittance(
                    &scene,
                    ray,
                    4.0,
                    None,
                    &mut sampler,
                    &mut Counters::default(),
                );
                let expected = crate::bsdf::Bsdf::ThinDielectric { eta: 1.5 }
                    .null_transmission(cos, Vec2::ZERO)
                    .unwrap();
                assert!(
                    (tr.x - expected).abs() < 1e-6,
                    "cos {cos}, side {side}: {tr:?} against {expected}"
                );
            }
        }
        // At normal incidence 1 - R' = 12/13 (R' = 1/13 for eta 1.5).
        let normal = crate::bsdf::Bsdf::ThinDielectric { eta: 1.5 }
            .null_transmission(1.0, Vec2::ZERO)
            .unwrap();
        assert!((normal - 12.0 / 13.0).abs() < 1e-6);
        let opaque = text
            .replace("type = \"thindielectric\", int_ior = 1.5, ext_ior = 1", "type = \"diffuse\"");
        let scene =
            crate::scene::load_str(std::path::Path::new("wall.toml"), &opaque, &[]).unwrap();
        let ray = Ray::new(Vec3A::new(0.0, 0.0, 2.0), Vec3A::new(0.0, 0.0, -1.0));
        let tr =
            shadow_transmittance(&scene, ray, 4.0, None, &mut sampler, &mut Counters::default());
        assert_eq!(tr, Spectrum::ZERO);
    }
}
