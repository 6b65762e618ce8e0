//! The render session: trains a guiding field when guiding is on, then samples the image over
//! 16x16 tiles in parallel (rayon) until a sample or time budget is spent.
//!
//! Each pixel sample draws from its own stream keyed by (seed, pixel, sample index), each
//! pixel's samples are summed in index order, and training samples are gathered in tile order
//! (the field's update is deterministic), so an image depends on the seed and the budgets
//! only, never on the thread count or the tile schedule.

use crate::film::{Film, PixelSum};
use crate::guided::{Components, DirectFluence, FieldCache, NoCache, RadianceCache, TrainedField};
use crate::integrators::VolPath;
use crate::integrators::walk::{self, WalkContext, WalkSettings};
use crate::math::{Spectrum, is_finite, luminance};
use crate::rng::{Sampler, mix64};
use crate::scene::Scene;
use crate::stats::Counters;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use zerovar_guiding::{Field, FieldConfig, FieldStats, GuidingError, PathRecorder, Sample};

mod fireflies;
mod select;

pub use fireflies::{Firefly, FireflyReport};
pub use select::Selection;

const TILE: u32 = 16;

/// The progress callback: `progress(done, total)` as work completes (samples for a sample
/// budget, milliseconds for a time budget and for training); returning `false` cancels the
/// render, which stops within one tile per thread.
pub type Progress<'a> = dyn Fn(u64, u64) -> bool + Sync + 'a;

/// The caller's callback and whether it asked to stop.
struct Monitor<'a> {
    callback: &'a Progress<'a>,
    stop: AtomicBool,
}

impl<'a> Monitor<'a> {
    fn new(callback: &'a Progress<'a>) -> Self {
        Self { callback, stop: AtomicBool::new(false) }
    }

    fn report(&self, done: u64, total: u64) {
        if !(self.callback)(done, total) {
            self.stop.store(true, Ordering::Relaxed);
        }
    }

    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// How much to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// Exactly this many samples per pixel.
    Samples(u32),
    /// As many samples per pixel as fit in this time (at least one).
    Time(Duration),
}

/// How much to train. Training renders passes of 1, 2, 4, ... samples per pixel (Mueller et
/// al. 2017), the field updated after each. A time budget ([`Budget::Time`]) is always the
/// whole render's, training included: the render phase gets what training leaves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrainBudget {
    /// A share of the render's budget, in (0, 1): doubling passes while the next one fits in
    /// that share of the time, or of the samples per pixel, and the render phase gets the
    /// rest ([`DEFAULT_TRAIN_SHARE`]). With a sample budget the image then holds the budget's
    /// samples per pixel in all, training's included (when they are combined).
    Share(f32),
    /// This many passes; with a sample budget the render phase then renders all of it.
    Passes(u32),
    /// Doubling passes until this much time is spent (at least one pass); with a sample
    /// budget the render phase then renders all of it.
    Time(Duration),
}

/// The default [`TrainBudget::Share`]: a quarter. Training passes double, so the field is
/// trained on about as many samples as a third of the render phase draws; the render phase
/// keeps three quarters of the budget whatever the scene (forced to 4, 5 or 6 passes, the
/// bench scenes' equal-time error hardly moved, see docs/experiments.md).
pub const DEFAULT_TRAIN_SHARE: f32 = 0.25;

/// Why training stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainingStop {
    /// The number of passes asked for ([`TrainBudget::Passes`]) was done.
    Passes,
    /// The next pass, twice as long as the last, would have overrun the training budget.
    Budget,
    /// [`MAX_TRAIN_PASSES`] passes were done.
    MostPasses,
    /// Adaptive guiding's early look found too little to gain: the rest was rendered
    /// unguided.
    NoGain,
}

impl TrainingStop {
    /// The reason in words.
    pub fn describe(&self) -> &'static str {
        match self {
            TrainingStop::Passes => "the passes asked for",
            TrainingStop::Budget => "the next pass would overrun its share of the budget",
            TrainingStop::MostPasses => "the most passes",
            TrainingStop::NoGain => "adaptive guiding found nothing to gain",
        }
    }
}

/// Guiding settings of a render.
#[derive(Clone, Debug)]
pub struct GuidingOptions {
    /// Which decisions are guided; nothing guided means no training.
    pub components: Components,
    /// Probability of the guided strategy in every mixture in media, in [0, 1].
    pub alpha: f32,
    /// Probability of the guided strategy in every mixture at surfaces, in [0, 1]
    /// ([`DEFAULT_SURFACE_ALPHA`]).
    pub surface_alpha: f32,
    /// Probability of the zero-variance collision density in guided flights' mixture with
    /// standard tracking, in [0, 1] ([`DEFAULT_DISTANCE_ALPHA`]); guided flights take their
    /// extra collisions for delta lights whatever it is.
    pub distance_alpha: f32,
    /// Training budget.
    pub train: TrainBudget,
    /// Settings of a new field.
    pub field: FieldConfig,
    /// Combine the training passes' images with the render's by inverse variance, rather than
    /// discarding them (the default: at equal time it lowered relMSE 6-14% on the light
    /// shaft, the back-lit cloud and the occluded light, and changed nothing where guiding
    /// does not pay). The weights follow relMSE's, so unlike the render phase's samples they
    /// depend a little on the scene's units; each image's weight is one number, so the result
    /// stays unbiased whatever they are.
    pub combine_training: bool,
    /// Guide only the 16x16 tiles where a pilot after training finds guiding more efficient
    /// than unguided sampling (see [`Selection`]); the others render unguided.
    pub adaptive: bool,
}

impl GuidingOptions {
    /// Adaptive guiding (`--guiding auto`, what `zerovar render` does by default): full
    /// guiding, or roulette alone, in the tiles where a pilot after training finds that it
    /// pays, unguided sampling elsewhere.
    pub fn auto() -> Self {
        Self { components: Components::FULL, adaptive: true, ..Self::default() }
    }
}

impl Default for GuidingOptions {
    fn default() -> Self {
        Self {
            components: Components::OFF,
            alpha: 0.5,
            surface_alpha: DEFAULT_SURFACE_ALPHA,
            distance_alpha: DEFAULT_DISTANCE_ALPHA,
            train: TrainBudget::Share(DEFAULT_TRAIN_SHARE),
            field: FieldConfig::default(),
            combine_training: true,
            adaptive: false,
        }
    }
}

/// Parses a guiding mode: what [`Components::parse`] takes, or `auto` (alone or in a `+`-list)
/// for adaptive guiding, which guides everything unless the list names components.
pub fn parse_guiding(text: &str) -> Option<(Components, bool)> {
    let mut adaptive = false;
    let rest: Vec<&str> = text
        .split('+')
        .filter(|part| {
            let auto = part.trim() == "auto";
            adaptive |= auto;
            !auto
        })
        .collect();
    if rest.is_empty() {
        return Some((Components::FULL, true));
    }
    let components = Components::parse(&rest.join("+"))?;
    // `off+auto` asks for nothing to be guided adaptively: a contradiction, not a mode.
    (components.any() || !adaptive).then_some((components, adaptive))
}

/// Validated settings of one render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// The budget of the final (render) phase.
    pub budget: Budget,
    /// Seed of the random streams.
    pub seed: u64,
    /// Worker threads (`None`: all cores).
    pub threads: Option<usize>,
    /// Guiding.
    pub guiding: GuidingOptions,
    /// Find the samples that hold the largest share of the image's error and trace their
    /// paths ([`FireflyReport`]): this many of them (0: none).
    pub fireflies: usize,
}

impl RenderOptions {
    /// Rendering with `budget` and `seed` on all cores, guided where it pays
    /// ([`GuidingOptions::auto`]), as `zerovar render` does.
    pub fn new(budget: Budget, seed: u64) -> Self {
        Self { guiding: GuidingOptions::auto(), ..Self::unguided(budget, seed) }
    }

    /// Unguided rendering with `budget` and `seed` on all cores.
    pub fn unguided(budget: Budget, seed: u64) -> Self {
        Self { budget, seed, threads: None, guiding: GuidingOptions::default(), fireflies: 0 }
    }

    /// Checks every setting; [`render`], [`render_with_field`] and [`train`] call it before
    /// any work, so options assembled in code meet the same rules as the CLI's.
    pub fn validate(&self) -> Result<(), OptionsError> {
        match self.budget {
            Budget::Samples(0) => return Err(OptionsError::ZeroSamples),
            Budget::Time(t) if t.is_zero() => return Err(OptionsError::ZeroTime),
            _ => {}
        }
        if self.threads == Some(0) {
            return Err(OptionsError::ZeroThreads);
        }
        let g = &self.guiding;
        if !(0.0..=1.0).contains(&g.alpha) {
            return Err(OptionsError::Alpha(g.alpha));
        }
        if !(0.0..=1.0).contains(&g.surface_alpha) {
            return Err(OptionsError::SurfaceAlpha(g.surface_alpha));
        }
        if !(0.0..=1.0).contains(&g.distance_alpha) {
            return Err(OptionsError::DistanceAlpha(g.distance_alpha));
        }
        match g.train {
            TrainBudget::Passes(n) if n == 0 || n > MAX_TRAIN_PASSES => {
                Err(OptionsError::TrainPasses(n))
            }
            TrainBudget::Time(t) if t.is_zero() => Err(OptionsError::ZeroTrainTime),
            TrainBudget::Share(s) if !(s > 0.0 && s < 1.0) => Err(OptionsError::TrainShare(s)),
            TrainBudget::Time(t) if matches!(self.budget, Budget::Time(b) if t >= b) => {
                Err(OptionsError::TrainTimeOverBudget)
            }
            _ => Ok(()),
        }
    }
}

/// The most training passes [`TrainBudget::Passes`] takes: pass k renders 2^k spp, so 20
/// passes are already a million samples per pixel.
pub const MAX_TRAIN_PASSES: u32 = 20;

/// The default [`GuidingOptions::distance_alpha`]: none. Guided flights keep their extra
/// collisions for delta lights (placed by the field's direct-light grid), but their own
/// collision follows standard tracking: the zero-variance collision density needs a field
/// lookup per flight, and at equal time that cost more than it saved on every bench scene
/// (`compare --time 20`, full guiding, seeds 1 / 2, at alpha 0.5 against 0: light shaft
/// 0.0045 / 0.0045 against 0.0040 / 0.0041, occluded light 0.0147 / 0.0148 against
/// 0.0127 / 0.0130, back-lit cloud 0.0235 / 0.0223 against 0.0205 / 0.0218; on the light shaft
/// 0.1, 0.2 and 0.3 gave 0.0045, 0.0043 and 0.0043, and guiding only the camera ray's flight
/// 0.0042). The in-scattered light it follows is mostly the delta lights' single scattering,
/// which the extra collisions already place; what is left varies slowly along a ray.
pub const DEFAULT_DISTANCE_ALPHA: f32 = 0.0;

/// The default [`GuidingOptions::surface_alpha`]: at a diffuse surface the standard strategy
/// (cosine sampling) covers the whole hemisphere and a dark wall sends most of its samples
/// into the dark, so a smaller defensive share pays there than in a medium, whose phase
/// sampling the field's product with HG only approximates. Per sample (`compare --spp 128`,
/// light shaft, seeds 1-4, media at 0.5): surfaces at 0.5 gave 0.0085 / 0.0083 / 0.0084 /
/// 0.0083, at 0.7 0.0079 / 0.0081 / 0.0080 / 0.0079 (0.3: 0.0092, 0.8: 0.0080, 0.9: 0.0081
/// with seed 1); occluded light, 64 spp, seeds 1-4: 0.115 summed at 0.5 against 0.109; media
/// at 0.4 or 0.6 with surfaces at 0.7 were worse (seeds 1 / 3: 0.0083 / 0.0081, 0.0080 /
/// 0.0080 against 0.0079 / 0.0080).
pub const DEFAULT_SURFACE_ALPHA: f32 = 0.7;

/// Why [`RenderOptions::validate`] refused the options.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OptionsError {
    /// A sample budget of zero.
    #[error("a budget of 0 samples per pixel: give at least one")]
    ZeroSamples,
    /// A time budget of zero.
    #[error("a time budget of zero: give a positive duration")]
    ZeroTime,
    /// Zero worker threads.
    #[error("0 threads: give at least one, or `None` for every core")]
    ZeroThreads,
    /// The guided strategy's probability is outside [0, 1] (or NaN).
    #[error("alpha {0}: give a probability in [0, 1]")]
    Alpha(f32),
    /// The guided strategy's probability at surfaces is outside [0, 1] (or NaN).
    #[error("surface alpha {0}: give a probability in [0, 1]")]
    SurfaceAlpha(f32),
    /// The zero-variance collision density's probability is outside [0, 1] (or NaN).
    #[error("distance alpha {0}: give a probability in [0, 1]")]
    DistanceAlpha(f32),
    /// A number of training passes outside 1..=[`MAX_TRAIN_PASSES`].
    #[error("{0} training passes: give 1 to 20 (pass k renders 2^k spp)")]
    TrainPasses(u32),
    /// A training time of zero.
    #[error("a training time of zero: give a positive duration")]
    ZeroTrainTime,
    /// A training share outside (0, 1) (or NaN).
    #[error("training share {0}: give a fraction of the budget above 0 and below 1")]
    TrainShare(f32),
    /// A training time as long as the whole time budget, or longer.
    #[error(
        "the training time is not shorter than the time budget, which includes it; give a shorter training time or a longer budget"
    )]
    TrainTimeOverBudget,
}

/// What training produced.
#[derive(Clone, Debug)]
pub struct TrainingReport {
    /// Passes run.
    pub passes: u32,
    /// Samples per pixel over all passes.
    pub spp: u32,
    /// Seconds spent training (rendering and updating; with adaptive guiding, its early pilot).
    pub seconds: f64,
    /// Training samples the field learned from.
    pub samples: u64,
    /// The field after training.
    pub field: FieldStats,
    /// Why training stopped.
    pub stop: TrainingStop,
}

/// A finished render.
#[derive(Clone, Debug)]
pub struct RenderResult {
    /// The accumulated image of the render phase.
    pub film: Film,
    /// The image to write: the film's, or combined with the training images.
    pub image: Vec<[f32; 3]>,
    /// Samples per pixel of the render phase.
    pub spp: u32,
    /// Seconds of the render phase (with adaptive guiding, its pilot included).
    pub seconds: f64,
    /// Event counters of the render phase.
    pub counters: Counters,
    /// Threads used.
    pub threads: usize,
    /// Training, when guiding was on and no field was given.
    pub training: Option<TrainingReport>,
    /// Which tiles adaptive guiding chose to guide, when it was on.
    pub selection: Option<Selection>,
    /// Whether the progress callback cancelled the render: `spp` passes were completed and
    /// the image holds exactly those.
    pub cancelled: bool,
    /// The render phase's largest samples and their paths, when
    /// [`RenderOptions::fireflies`] asked for them.
    pub fireflies: Option<FireflyReport>,
}

/// Why a render could not run.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The thread pool could not be built.
    #[error("cannot start {threads} worker threads: {message}")]
    Threads {
        /// Threads requested.
        threads: usize,
        /// The system's reason.
        message: String,
    },
    /// The progress callback cancelled the render during training.
    #[error("cancelled during training")]
    Cancelled,
    /// The options broke a rule (see [`RenderOptions::validate`]).
    #[error("render options: {0}")]
    Options(#[from] OptionsError),
    /// The guiding field rejected its settings or its training samples.
    #[error("guiding: {0}")]
    Guiding(#[from] GuidingError),
}

/// Renders `scene`, training a field first when guiding is on; `progress` reports and may
/// cancel (see `Progress`).
pub fn render(
    scene: &Scene,
    options: &RenderOptions,
    progress: &Progress<'_>,
) -> Result<RenderResult, RenderError> {
    in_pool(options, |threads| {
        let progress = &Monitor::new(progress);
        let too_few = options.guiding.adaptive
            && matches!(options.guiding.train, TrainBudget::Share(_))
            && matches!(options.budget, Budget::Samples(n) if n < MIN_ADAPTIVE_SPP);
        if !options.guiding.components.any() || too_few {
            return Ok(final_phase(scene, options, None, Vec::new(), threads, progress, None));
        }
        let mut training = Training::new(options)?;
        if options.guiding.adaptive {
            training.run(scene, options, progress, EARLY_PILOT_PASSES)?;
            if let Some(result) = early_pilot(scene, options, &mut training, threads, progress) {
                return Ok(result);
            }
        }
        training.run(scene, options, progress, u32::MAX)?;
        // Moved out, not borrowed: the render phase takes the training films by value.
        let (field, direct, films, report) = training.finish();
        let guidance = Guidance {
            field: &field,
            direct: Some(&direct),
            estimate: pixel_estimates(&films),
            guided_tiles: None,
        };
        let options = &after_training(options, &report);
        Ok(guided_phase(scene, options, guidance, films, threads, progress, Some(report)))
    })
}

/// The fewest samples per pixel of a sample budget that adaptive guiding shares with its
/// training and pilot: below it they would take most of the budget (the first pass, and a
/// pilot of at least 2 spp per candidate, are whole samples), so the render is unguided.
pub const MIN_ADAPTIVE_SPP: u32 = 16;

/// Training passes after which adaptive guiding first pilots the field (1 + 2 spp).
const EARLY_PILOT_PASSES: u32 = 2;
/// Least modelled gain of the early pilot's choice for training to go on. The field after
/// two passes is poorer than after training, so the early gain understates the final one
/// (`--stats`, image-wide efficiency of guiding every tile after 2 and 5 passes: light shaft
/// 1.03 and 1.46, occluded light 1.8 and 4.5), and it is noisy (the light shaft's early
/// choice gained 1.08 with seed 0); where guiding cannot pay (the easy haze, the chromatic
/// slab) the early pilot chose no tile at all (gain exactly 1) with every seed tried. So only
/// a choice of next to nothing stops training.
const EARLY_MIN_GAIN: f64 = 1.02;

/// Adaptive guiding's early look: after a short training, a pilot judges whether guiding
/// can pay anywhere; if not, training stops and the rest of its budget (and the render's)
/// goes to unguided sampling. `None` means training goes on, the pilot's time counted as
/// training's.
fn early_pilot(
    scene: &Scene,
    options: &RenderOptions,
    training: &mut Training,
    threads: usize,
    progress: &Monitor<'_>,
) -> Option<RenderResult> {
    if training.done {
        return None; // nothing left to save: the ordinary pilot decides
    }
    let guidance = training.guidance();
    let last_pass = 1 << (EARLY_PILOT_PASSES - 1);
    let selection = select::pilot(scene, options, &guidance, last_pass, 2, progress)?.selection;
    if selection.gain >= EARLY_MIN_GAIN {
        training.seconds += selection.seconds;
        return None;
    }
    training.stop = TrainingStop::NoGain;
    // Training ends here: its films go to the render (for `combine_training`).
    let report = training.report();
    let mut options = after_training(options, &report);
    spend(&mut options, selection.seconds);
    let films = std::mem::take(&mut training.films);
    let mut result = final_phase(scene, &options, None, films, threads, progress, Some(report));
    result.seconds += selection.seconds;
    result.selection = Some(Selection { guided_tiles: 0, stopped_training: true, ..selection });
    Some(result)
}

/// `options` for the render phase after `training`: a time budget loses the seconds training
/// took (the budget is the whole render's), a sample budget the samples per pixel it drew
/// when training had a share of it; at least one sample per pixel is left.
fn after_training(options: &RenderOptions, training: &TrainingReport) -> RenderOptions {
    let mut options = options.clone();
    match (options.budget, options.guiding.train) {
        (Budget::Time(_), _) => spend(&mut options, training.seconds),
        (Budget::Samples(n), TrainBudget::Share(_)) => {
            options.budget = Budget::Samples(n.saturating_sub(training.spp).max(1));
        }
        (Budget::Samples(_), _) => {}
    }
    options
}

/// What training may take: at most this many passes, samples per pixel and seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TrainingLimit {
    passes: u32,
    spp: Option<u64>,
    seconds: Option<f64>,
}

impl TrainingLimit {
    fn of(options: &RenderOptions) -> Self {
        let most = Self { passes: MAX_TRAIN_PASSES, spp: None, seconds: None };
        match (options.guiding.train, options.budget) {
            (TrainBudget::Passes(n), _) => Self { passes: n.min(MAX_TRAIN_PASSES), ..most },
            (TrainBudget::Time(t), _) => Self { seconds: Some(t.as_secs_f64()), ..most },
            (TrainBudget::Share(s), Budget::Time(t)) => {
                Self { seconds: Some(t.as_secs_f64() * f64::from(s)), ..most }
            }
            (TrainBudget::Share(s), Budget::Samples(n)) => {
                Self { spp: Some((f64::from(n) * f64::from(s)) as u64), ..most }
            }
        }
    }
}

/// Takes `seconds` already spent for the render (training's, a pilot's) out of a time budget.
fn spend(options: &mut RenderOptions, seconds: f64) {
    if let Budget::Time(t) = options.budget {
        options.budget = Budget::Time(t.saturating_sub(Duration::from_secs_f64(seconds)));
    }
}

/// Renders `scene` guided by a field trained earlier (no training phase).
pub fn render_with_field(
    scene: &Scene,
    options: &RenderOptions,
    trained: &TrainedField,
    progress: &Progress<'_>,
) -> Result<RenderResult, RenderError> {
    in_pool(options, |threads| {
        let progress = &Monitor::new(progress);
        let guidance = Guidance {
            field: &trained.field,
            direct: trained.direct.as_ref(),
            estimate: None,
            guided_tiles: None,
        };
        Ok(guided_phase(scene, options, guidance, Vec::new(), threads, progress, None))
    })
}

/// Trains a field on `scene` with the training budget of `options`.
pub fn train(
    scene: &Scene,
    options: &RenderOptions,
    progress: &Progress<'_>,
) -> Result<(TrainedField, TrainingReport), RenderError> {
    in_pool(options, |_| {
        let progress = &Monitor::new(progress);
        let (field, direct, _, report) = train_in_pool(scene, options, progress)?;
        Ok((TrainedField { field, direct: Some(direct) }, report))
    })
}

fn in_pool<T: Send>(
    options: &RenderOptions,
    work: impl FnOnce(usize) -> Result<T, RenderError> + Send,
) -> Result<T, RenderError> {
    // Every entry point starts here, so none can skip the checks.
    options.validate()?;
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(t) = options.threads {
        builder = builder.num_threads(t);
    }
    let pool = builder.build().map_err(|e| RenderError::Threads {
        threads: options.threads.unwrap_or(0),
        message: e.to_string(),
    })?;
    let threads = pool.current_num_threads();
    pool.install(|| work(threads))
}

fn walk_settings(scene: &Scene, options: &RenderOptions) -> WalkSettings {
    WalkSettings {
        guide: options.guiding.components,
        alpha: options.guiding.alpha,
        surface_alpha: options.guiding.surface_alpha,
        distance_alpha: options.guiding.distance_alpha,
        ..VolPath::from_scene(scene).settings()
    }
}

/// Training passes: 1, 2, 4, ... spp, each guided by the field so far, the field updated with
/// its samples after each. Returns the field, its direct fluence (from the last pass), the
/// passes' films and a report.
fn train_in_pool(
    scene: &Scene,
    options: &RenderOptions,
    progress: &Monitor<'_>,
) -> Result<(Field, DirectFluence, Vec<Film>, TrainingReport), RenderError> {
    let mut training = Training::new(options)?;
    training.run(scene, options, progress, u32::MAX)?;
    Ok(training.finish())
}

/// A training phase that can stop after some passes and resume (adaptive guiding's early
/// look at whether guiding can pay).
struct Training {
    field: Field,
    direct: DirectFluence,
    films: Vec<Film>,
    spp: u32,
    samples: u64,
    /// Seconds spent in training passes and in adaptive guiding's early pilot.
    seconds: f64,
    /// Whether the budget is spent.
    done: bool,
    /// Why training stopped (once `done`).
    stop: TrainingStop,
    /// Samples per pixel of the next pass.
    next: u32,
}

impl Training {
    fn new(options: &RenderOptions) -> Result<Self, RenderError> {
        Ok(Self {
            field: Field::new(options.guiding.field.clone())?,
            direct: DirectFluence::default(),
            films: Vec::new(),
            spp: 0,
            samples: 0,
            seconds: 0.0,
            done: false,
            stop: TrainingStop::Budget,
            next: 1,
        })
    }

    /// Runs passes until `until` passes are done or the training budget is spent.
    fn run(
        &mut self,
        scene: &Scene,
        options: &RenderOptions,
        progress: &Monitor<'_>,
        until: u32,
    ) -> Result<(), RenderError> {
        let settings = walk_settings(scene, options);
        let [w, h] = scene.camera.resolution();
        let limit = TrainingLimit::of(options);
        let pixels = u64::from(w) * u64::from(h);
        // Progress in samples, or in milliseconds under a time limit.
        let total = match (limit.seconds, limit.spp) {
            (Some(t), _) => (t * 1000.0) as u64,
            (None, Some(spp)) => spp.max(1) * pixels,
            (None, None) => ((1u64 << limit.passes) - 1) * pixels,
        };
        let last = limit.passes;
        while !self.done && (self.films.len() as u32) < until.min(last) {
            let pass = self.films.len() as u32;
            let count = self.next;
            let mut film = Film::new(w, h);
            let estimate = pixel_estimates(&self.films);
            // Each pass draws from its own streams, independent of the render phase's.
            let seed = mix64(options.seed ^ (0x7261_696E_0000 + pass as u64));
            let pass_start = Instant::now();
            let spec = Pass {
                settings: &settings,
                seed,
                first: 0,
                count,
                field: Some((&self.field, Some(&self.direct))),
                estimate: estimate.as_deref(),
                record: true,
                guided_tiles: None,
                largest: false,
            };
            let Some(out) = render_pass(scene, spec, &mut film, progress, &|_| {}) else {
                return Err(RenderError::Cancelled);
            };
            self.field.update(&out.samples)?;
            self.direct = DirectFluence::build(&self.field, &out.records);
            self.samples += out.samples.len() as u64;
            self.spp += count;
            self.films.push(film);
            let pass_seconds = pass_start.elapsed().as_secs_f64();
            self.seconds += pass_seconds;
            if pass + 1 >= last {
                self.done = true;
                self.stop = match options.guiding.train {
                    TrainBudget::Passes(_) => TrainingStop::Passes,
                    _ => TrainingStop::MostPasses,
                };
            }
            // The next pass doubles, or fills what is left of the limit if that is less; one
            // smaller than this pass is not worth its field update, and training stops.
            let mut fits = u64::from(count) * 2;
            if let Some(t) = limit.seconds {
                let per_spp = pass_seconds / f64::from(count);
                fits = fits.min((0.95 * (t - self.seconds) / per_spp).max(0.0) as u64);
            }
            if let Some(spp) = limit.spp {
                fits = fits.min(spp.saturating_sub(u64::from(self.spp)));
            }
            if !self.done && fits < u64::from(count) {
                self.done = true;
                self.stop = TrainingStop::Budget;
            }
            self.next = fits.min(u64::from(u32::MAX)) as u32;
            match limit.seconds {
                None => progress.report((u64::from(self.spp) * pixels).min(total), total),
                Some(_) => progress.report(((self.seconds * 1000.0) as u64).min(total), total),
            }
        }
        Ok(())
    }

    /// The field so far, as the render phase would use it.
    fn guidance(&self) -> Guidance<'_> {
        Guidance {
            field: &self.field,
            direct: Some(&self.direct),
            estimate: pixel_estimates(&self.films),
            guided_tiles: None,
        }
    }

    fn report(&self) -> TrainingReport {
        TrainingReport {
            passes: self.films.len() as u32,
            spp: self.spp,
            seconds: self.seconds,
            samples: self.samples,
            field: self.field.stats(),
            stop: self.stop,
        }
    }

    fn finish(self) -> (Field, DirectFluence, Vec<Film>, TrainingReport) {
        let report = self.report();
        (self.field, self.direct, self.films, report)
    }
}

/// Per-pixel luminance estimates from the training films: the mean over all their samples,
/// box-filtered over 5x5 pixels, since a weight window centred on a noisy estimate (a
/// firefly, or a pixel whose few samples missed the light) would roulette or split the
/// wrong paths.
fn pixel_estimates(films: &[Film]) -> Option<Vec<f32>> {
    let first = films.first()?;
    let (w, h) = (first.width as usize, first.height as usize);
    let mut sums = vec![PixelSum::default(); first.pixels.len()];
    for f in films {
        for (s, p) in sums.iter_mut().zip(&f.pixels) {
            s.merge(p);
        }
    }
    let raw: Vec<f32> = sums.iter().map(|s| luminance(Spectrum::from_array(s.mean()))).collect();
    let mut out = vec![0.0; raw.len()];
    for y in 0..h {
        for x in 0..w {
            let (y0, y1) = (y.saturating_sub(2), (y + 3).min(h));
            let (x0, x1) = (x.saturating_sub(2), (x + 3).min(w));
            let total: f32 = (y0..y1).flat_map(|yy| raw[yy * w + x0..yy * w + x1].iter()).sum();
            out[y * w + x] = total / ((y1 - y0) * (x1 - x0)) as f32;
        }
    }
    Some(out)
}

/// What the render phase is guided by.
struct Guidance<'a> {
    field: &'a Field,
    direct: Option<&'a DirectFluence>,
    /// Per-pixel estimates for weight windows, from the training images.
    estimate: Option<Vec<f32>>,
    /// Per tile, whether it is guided (`None`: every tile).
    guided_tiles: Option<Vec<bool>>,
}

/// The render phase with a field: with `adaptive` guiding, a pilot first chooses which tiles
/// guiding pays in (its time comes out of a time budget).
fn guided_phase(
    scene: &Scene,
    options: &RenderOptions,
    mut guidance: Guidance<'_>,
    training_films: Vec<Film>,
    threads: usize,
    progress: &Monitor<'_>,
    report: Option<TrainingReport>,
) -> RenderResult {
    if !options.guiding.adaptive {
        return final_phase(
            scene,
            options,
            Some(guidance),
            training_films,
            threads,
            progress,
            report,
        );
    }
    let last_pass = report.as_ref().map_or(16, |r| 1u32 << r.passes.saturating_sub(1));
    let Some(choice) =
        select::pilot(scene, options, &guidance, last_pass, select::MIN_TILE_PILOT_SPP, progress)
    else {
        // Cancelled during the pilot: nothing rendered.
        let mut options = options.clone();
        options.budget = Budget::Samples(0);
        return final_phase(scene, &options, None, training_films, threads, progress, report);
    };
    let select::Choice { tiles, components, selection } = choice;
    guidance.guided_tiles = Some(tiles);
    let mut options = options.clone();
    options.guiding.components = components;
    spend(&mut options, selection.seconds);
    let mut result =
        final_phase(scene, &options, Some(guidance), training_films, threads, progress, report);
    result.seconds += selection.seconds;
    result.selection = Some(selection);
    result
}

fn final_phase(
    scene: &Scene,
    options: &RenderOptions,
    guidance: Option<Guidance<'_>>,
    training_films: Vec<Film>,
    threads: usize,
    progress: &Monitor<'_>,
    report: Option<TrainingReport>,
) -> RenderResult {
    let settings = if guidance.is_some() {
        walk_settings(scene, options)
    } else {
        VolPath::from_scene(scene).settings()
    };
    // Without training images (a loaded field), weight windows centre on the image rendered
    // so far, renewed after each pass: each pass's windows then depend only on earlier passes'
    // independent samples, so every pass stays unbiased.
    let own_estimate =
        guidance.as_ref().is_some_and(|g| g.estimate.is_none()) && settings.guide.roulette;
    let mut estimate: Option<Vec<f32>> = None;
    let pass = |first: u32, count: u32| Pass {
        settings: &settings,
        seed: options.seed,
        first,
        count,
        field: guidance.as_ref().map(|g| (g.field, g.direct)),
        estimate: guidance.as_ref().and_then(|g| g.estimate.as_deref()),
        record: false,
        guided_tiles: guidance.as_ref().and_then(|g| g.guided_tiles.as_deref()),
        largest: options.fireflies > 0,
    };
    let [w, h] = scene.camera.resolution();
    let mut film = Film::new(w, h);
    let mut counters = Counters::default();
    let mut largest =
        vec![Largest::default(); if options.fireflies > 0 { (w * h) as usize } else { 0 }];
    // The weight windows' estimate each pass used, by its first sample (when they change).
    let mut estimates: Vec<(u32, Vec<f32>)> = Vec::new();
    let start = Instant::now();
    let mut done = 0u32;
    match options.budget {
        Budget::Samples(spp) => {
            // Doubling passes, so a cancelled render still returns whole passes.
            let total = (spp as u64 * w as u64 * h as u64).max(1);
            let finished = AtomicU64::new(0);
            while done < spp {
                let batch = done.max(1).min(spp - done);
                let report = |n| {
                    let d = finished.fetch_add(n, Ordering::Relaxed) + n;
                    progress.report(d, total);
                };
                let mut this = pass(done, batch);
                this.estimate = this.estimate.or(estimate.as_deref());
                let Some(out) = render_pass(scene, this, &mut film, progress, &report) else {
                    break;
                };
                keep_largest(&mut largest, &out, &mut estimates, done, own_estimate, &estimate);
                counters += out.counters;
                done += batch;
                if own_estimate {
                    estimate = pixel_estimates(std::slice::from_ref(&film));
                }
            }
        }
        Budget::Time(limit) => {
            let total = (limit.as_millis() as u64).max(1);
            let mut batch = 1u32;
            loop {
                let pass_start = Instant::now();
                let mut this = pass(done, batch);
                this.estimate = this.estimate.or(estimate.as_deref());
                let Some(out) = render_pass(scene, this, &mut film, progress, &|_| {}) else {
                    break;
                };
                keep_largest(&mut largest, &out, &mut estimates, done, own_estimate, &estimate);
                counters += out.counters;
                done += batch;
                if own_estimate {
                    estimate = pixel_estimates(std::slice::from_ref(&film));
                }
                let elapsed = start.elapsed();
                progress.report((elapsed.as_millis() as u64).min(total), total);
                if progress.stopped() {
                    break;
                }
                let per_sample = pass_start.elapsed().as_secs_f64() / batch as f64;
                let left = limit.as_secs_f64() - elapsed.as_secs_f64();
                if left <= per_sample {
                    break;
                }
                // Grow passes geometrically, but never past the remaining time.
                batch = ((left / per_sample) as u32).clamp(1, batch.saturating_mul(2));
            }
        }
    }
    let fireflies = (options.fireflies > 0 && !progress.stopped()).then(|| {
        let estimate_for = |sample: u32| {
            let own = estimates.iter().rev().find(|(first, _)| *first <= sample);
            own.map(|(_, e)| &e[..]).or(guidance.as_ref().and_then(|g| g.estimate.as_deref()))
        };
        fireflies::find(scene, pass(0, 0), &film, &largest, options.fireflies, estimate_for)
    });
    let image = if options.guiding.combine_training && !training_films.is_empty() {
        combine_by_inverse_variance(&training_films, &film)
    } else {
        film.image()
    };
    RenderResult {
        film,
        image,
        spp: done,
        seconds: start.elapsed().as_secs_f64(),
        counters,
        threads,
        training: report,
        selection: None,
        cancelled: progress.stopped(),
        fireflies,
    }
}

/// Merges a pass's largest samples into `largest` and, for the firefly diagnostic's replays,
/// keeps the windows' estimate the pass starting at sample `first` used when it is the
/// render's own (`own_estimate`), which changes from pass to pass.
fn keep_largest(
    largest: &mut [Largest],
    out: &PassOutput,
    estimates: &mut Vec<(u32, Vec<f32>)>,
    first: u32,
    own_estimate: bool,
    estimate: &Option<Vec<f32>>,
) {
    if largest.is_empty() {
        return;
    }
    for (l, o) in largest.iter_mut().zip(&out.largest) {
        l.merge(o);
    }
    if own_estimate && let Some(e) = estimate {
        estimates.push((first, e.clone()));
    }
}

/// Mean per-pixel relative variance of a film's pixel means: luminance variance times
/// `weights`, relMSE's per-pixel weight. That is what the combination should minimise;
/// absolute variance would let the brightest pixels decide.
fn image_variance(film: &Film, weights: &[f64]) -> f64 {
    let total: f64 = film
        .pixels()
        .iter()
        .zip(weights)
        .map(|(p, w)| w * p.luminance_variance() / f64::from(p.count.max(1)))
        .sum();
    total / film.pixels().len().max(1) as f64
}

/// The images of `training` and `last` averaged with weights inversely proportional to their
/// estimated relative variance (equal weights if a variance is zero), relative to `last`'s
/// values. The weights are one per image, so the average stays unbiased up to their own
/// estimation noise, which averages over every pixel.
fn combine_by_inverse_variance(training: &[Film], last: &Film) -> Vec<[f32; 3]> {
    let films: Vec<&Film> = training.iter().chain(std::iter::once(last)).collect();
    let relative: Vec<f64> = last
        .pixels()
        .iter()
        .map(|r| {
            let m = f64::from(crate::math::luminance(glam::Vec3A::from(r.mean())));
            1.0 / (m * m + crate::metrics::EPSILON)
        })
        .collect();
    let weights: Vec<f64> = films
        .iter()
        .map(|f| image_variance(f, &relative))
        .map(|v| if v > 0.0 && v.is_finite() { 1.0 / v } else { 0.0 })
        .collect();
    let total: f64 = weights.iter().sum();
    let weights: Vec<f64> = if total > 0.0 {
        weights.iter().map(|w| w / total).collect()
    } else {
        vec![1.0 / films.len() as f64; films.len()]
    };
    (0..last.pixels.len())
        .map(|i| {
            let mut c = [0.0f64; 3];
            for (f, w) in films.iter().zip(&weights) {
                let m = f.pixels[i].mean();
                for k in 0..3 {
                    c[k] += w * m[k] as f64;
                }
            }
            c.map(|v| v as f32)
        })
        .collect()
}

/// One pass over the image: which samples, drawn how.
#[derive(Clone, Copy)]
struct Pass<'a> {
    settings: &'a WalkSettings,
    seed: u64,
    /// Sample indices `first .. first + count` of every pixel.
    first: u32,
    count: u32,
    field: Option<(&'a Field, Option<&'a DirectFluence>)>,
    /// Per-pixel estimates for weight windows (`window::floor` is added when rendering).
    estimate: Option<&'a [f32]>,
    /// Record training samples (splitting is then off).
    record: bool,
    /// Per tile, whether it is guided; `None` guides every tile as `settings` say.
    guided_tiles: Option<&'a [bool]>,
    /// Keep each pixel's largest sample (for the firefly diagnostic).
    largest: bool,
}

/// What a pass returns.
#[derive(Default)]
struct PassOutput {
    counters: Counters,
    /// Counters of each tile, in tile order.
    tile_counters: Vec<Counters>,
    /// Training samples in tile order (when recording).
    samples: Vec<Sample>,
    /// Direct-fluence records in tile order (when recording).
    records: Vec<crate::guided::DirectRecord>,
    /// Per pixel, its largest sample (when the pass looks for them).
    largest: Vec<Largest>,
}

/// A pixel's largest sample so far, by luminance.
#[derive(Clone, Copy, Debug, Default)]
struct Largest {
    value: Spectrum,
    /// Its sample index (`None` before any sample).
    index: Option<u32>,
}

impl Largest {
    #[inline]
    fn offer(&mut self, l: Spectrum, index: u32) {
        if self.index.is_none() || luminance(l) > luminance(self.value) {
            *self = Largest { value: l, index: Some(index) };
        }
    }

    fn merge(&mut self, o: &Largest) {
        if let Some(i) = o.index {
            self.offer(o.value, i);
        }
    }
}

/// The tiles of a `w x h` image in row-major order.
fn tiles(w: u32, h: u32) -> Vec<(u32, u32)> {
    (0..h.div_ceil(TILE)).flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx, ty))).collect()
}

/// Adds the pass's samples of every pixel to `film`. Returns `None`, leaving `film` untouched,
/// when `monitor` was told to stop during the pass.
fn render_pass(
    scene: &Scene,
    pass: Pass<'_>,
    film: &mut Film,
    monitor: &Monitor<'_>,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Option<PassOutput> {
    let [w, h] = scene.camera.resolution();
    let tiles = tiles(w, h);
    let floor = pass.estimate.map_or(0.0, crate::guided::window::floor);
    let results: Vec<TileOutput> = tiles
        .par_iter()
        .enumerate()
        .map(|(index, &tile)| {
            if monitor.stopped() {
                return TileOutput::default(); // the pass is discarded below
            }
            let work = RenderTile { scene, pass, tile, floor };
            let (mut out, records) = with_tile_walk(&pass, index, work);
            out.records = records;
            on_tile(out.sums.len() as u64 * pass.count as u64);
            out
        })
        .collect();
    if monitor.stopped() {
        return None;
    }
    let mut out = PassOutput::default();
    // A training pass gathers hundreds of megabytes of samples: sized once, not grown by
    // doubling (each doubling copied everything so far).
    out.samples.reserve_exact(results.iter().map(|r| r.samples.len()).sum());
    out.records.reserve_exact(results.iter().map(|r| r.records.len()).sum());
    if pass.largest {
        out.largest = vec![Largest::default(); (w * h) as usize];
    }
    for (&(tx, ty), tile) in tiles.iter().zip(results) {
        out.counters += tile.counters;
        out.tile_counters.push(tile.counters);
        out.samples.extend(tile.samples);
        out.records.extend(tile.records);
        let (x0, y0) = (tx * TILE, ty * TILE);
        let tw = (x0 + TILE).min(w) - x0;
        for (i, s) in tile.sums.iter().enumerate() {
            let (x, y) = (x0 + i as u32 % tw, y0 + i as u32 / tw);
            let p = (y * w + x) as usize;
            film.pixels[p].merge(s);
            if let Some(l) = tile.largest.get(i) {
                out.largest[p].merge(l);
            }
        }
    }
    Some(out)
}

/// Work on one tile that runs the walk with some radiance cache (a closure generic over the
/// cache, so that each cache gets its own monomorphised walk).
trait TileWork {
    type Output;
    fn run<C: RadianceCache>(self, settings: &WalkSettings, cache: &mut C) -> Self::Output;
}

/// Runs `work` with the walk settings and the radiance cache of tile `index` in `pass`: the
/// field's, or none where the pass has no field or the tile is not guided. Also returns the
/// direct-fluence records the cache gathered (when the pass records).
fn with_tile_walk<W: TileWork>(
    pass: &Pass<'_>,
    index: usize,
    work: W,
) -> (W::Output, Vec<crate::guided::DirectRecord>) {
    let guided = pass.guided_tiles.is_none_or(|g| g[index]);
    match pass.field {
        Some((f, direct)) if guided => {
            let mut cache = FieldCache::with_direct(f, direct, pass.record);
            let out = work.run(pass.settings, &mut cache);
            (out, cache.take_records())
        }
        _ => {
            let unguided = WalkSettings { guide: Components::OFF, ..*pass.settings };
            (work.run(if guided { pass.settings } else { &unguided }, &mut NoCache), Vec::new())
        }
    }
}

/// Renders every pixel sample of a tile.
struct RenderTile<'a, 'p> {
    scene: &'a Scene,
    pass: Pass<'p>,
    tile: (u32, u32),
    /// Added to the pixel estimates for weight windows (`window::floor`).
    floor: f32,
}

/// What one tile of a pass returns.
#[derive(Default)]
struct TileOutput {
    /// Per pixel of the tile, row by row.
    sums: Vec<PixelSum>,
    counters: Counters,
    /// Training samples (when recording).
    samples: Vec<Sample>,
    /// Direct-fluence records (when recording).
    records: Vec<crate::guided::DirectRecord>,
    /// Per pixel, its largest sample (when the pass looks for fireflies).
    largest: Vec<Largest>,
}

impl TileWork for RenderTile<'_, '_> {
    type Output = TileOutput;

    fn run<C: RadianceCache>(self, settings: &WalkSettings, cache: &mut C) -> TileOutput {
        let RenderTile { scene, pass, tile: (tx, ty), floor } = self;
        let [w, h] = scene.camera.resolution();
        let mut out = TileOutput::default();
        let mut recorder = PathRecorder::new();
        let (x0, y0) = (tx * TILE, ty * TILE);
        let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
        out.sums.reserve(((x1 - x0) * (y1 - y0)) as usize);
        for y in y0..y1 {
            for x in x0..x1 {
                let mut sum = PixelSum::default();
                let mut largest = Largest::default();
                for s in pass.first..pass.first + pass.count {
                    let mut ctx = WalkContext {
                        cache: &mut *cache,
                        pixel: pass.estimate.map(|e| e[(y * w + x) as usize] + floor),
                        recorder: if pass.record { Some(&mut recorder) } else { None },
                        trace: None,
                    };
                    let l = camera_sample(
                        scene,
                        settings,
                        pass.seed,
                        [x, y],
                        s,
                        &mut ctx,
                        &mut out.counters,
                    );
                    if is_finite(l) {
                        sum.add(l);
                        largest.offer(l, s);
                        if pass.record {
                            recorder.finish(&mut out.samples);
                        }
                    } else {
                        out.counters.invalid_samples += 1;
                        sum.add(Spectrum::ZERO);
                        recorder.clear();
                    }
                }
                out.sums.push(sum);
                if pass.largest {
                    out.largest.push(largest);
                }
            }
        }
        out
    }
}

/// Sample `s` of pixel `[x, y]` from the streams of `seed`: the radiance its walks bring back.
fn camera_sample<C: RadianceCache>(
    scene: &Scene,
    settings: &WalkSettings,
    seed: u64,
    [x, y]: [u32; 2],
    s: u32,
    ctx: &mut WalkContext<'_, C>,
    counters: &mut Counters,
) -> Spectrum {
    let pixel = u64::from(y) * u64::from(scene.camera.resolution()[0]) + u64::from(x);
    let mut sampler = Sampler::new(seed, pixel, u64::from(s));
    let jitter = sampler.next_2d();
    let ray = scene.camera.ray(Vec2::new(x as f32, y as f32) + jitter);
    walk::radiance(settings, scene, ray, scene.camera_medium, ctx, &mut sampler, counters)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timed(budget: f64, train: TrainBudget) -> RenderOptions {
        let mut options = RenderOptions::unguided(Budget::Time(Duration::from_secs_f64(budget)), 0);
        options.guiding.train = train;
        options
    }

    fn seconds(options: &RenderOptions) -> f64 {
        match options.budget {
            Budget::Time(t) => t.as_secs_f64(),
            Budget::Samples(_) => panic!("a time budget stays one"),
        }
    }

    fn trained(seconds: f64, spp: u32) -> TrainingReport {
        TrainingReport {
            passes: 0,
            spp,
            seconds,
            samples: 0,
            field: Field::new(FieldConfig::default()).expect("default field").stats(),
            stop: TrainingStop::Budget,
        }
    }

    #[test]
    fn the_budget_includes_training() {
        // A time budget loses what training took, whatever the training budget; a pilot's
        // seconds come out of it too.
        for train in [TrainBudget::Share(0.25), TrainBudget::Time(Duration::from_secs(5))] {
            let options = timed(20.0, train);
            assert!((seconds(&after_training(&options, &trained(4.5, 31))) - 15.5).abs() < 1e-9);
            let mut options = after_training(&options, &trained(4.5, 31));
            spend(&mut options, 2.0);
            assert!((seconds(&options) - 13.5).abs() < 1e-9);
        }
        // A sample budget shared with training loses training's samples per pixel; with
        // passes asked for explicitly, the render phase renders all of it.
        let mut spp = RenderOptions::unguided(Budget::Samples(64), 0);
        assert!(matches!(after_training(&spp, &trained(1.0, 15)).budget, Budget::Samples(49)));
        assert!(matches!(after_training(&spp, &trained(1.0, 63)).budget, Budget::Samples(1)));
        spp.guiding.train = TrainBudget::Passes(4);
        assert!(matches!(after_training(&spp, &trained(1.0, 15)).budget, Budget::Samples(64)));
    }

    #[test]
    fn a_share_limits_training_to_its_part_of_the_budget() {
        let limit = TrainingLimit::of(&timed(20.0, TrainBudget::Share(0.25)));
        assert_eq!(limit.seconds, Some(5.0));
        assert_eq!(limit.spp, None);
        let mut spp = RenderOptions::unguided(Budget::Samples(64), 0);
        spp.guiding.train = TrainBudget::Share(0.25);
        assert_eq!(TrainingLimit::of(&spp).spp, Some(16));
        spp.guiding.train = TrainBudget::Passes(3);
        assert_eq!(TrainingLimit::of(&spp), TrainingLimit { passes: 3, spp: None, seconds: None });
        // Shares outside (0, 1) and training times as long as the budget are refused.
        for bad in [0.0, 1.0, -0.5, f32::NAN] {
            spp.guiding.train = TrainBudget::Share(bad);
            assert!(matches!(spp.validate(), Err(OptionsError::TrainShare(_))), "{bad}");
        }
        let long = timed(5.0, TrainBudget::Time(Duration::from_secs(5)));
        assert_eq!(long.validate(), Err(OptionsError::TrainTimeOverBudget));
    }
}
