//! The render session: trains a guiding field when guiding is on, then samples the image over
//! 16x16 tiles in parallel (rayon) until a sample or time budget is spent.
//!
//! Each pixel sample draws from its own stream keyed by (seed, pixel, sample index), each
//! pixel's samples are summed in index order, and training samples are gathered in tile order
//! (the field's update is deterministic), so an image depends on the seed and the budgets
//! only, never on the thread count or the tile schedule.

use crate::film::Film;
use crate::guided::{Components, DirectFluence, TrainedField};
use crate::integrators::VolPath;
use crate::integrators::walk::WalkSettings;
use crate::scene::Scene;
use crate::stats::Counters;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;
use zerovar_guiding::{Field, GuidingError};

mod combine;
mod fireflies;
mod options;
mod passes;
mod select;
mod settings;
mod stats;
mod trackers;
mod training;

pub use fireflies::{Firefly, FireflyReport};
pub use options::{
    Budget, DEFAULT_DISTANCE_ALPHA, DEFAULT_SURFACE_ALPHA, DEFAULT_TRAIN_SHARE, GuidingOptions,
    MAX_ALPHA, MAX_THREADS, MAX_TRAIN_PASSES, OptionsError, RenderOptions, TrainBudget,
    parse_guiding,
};
pub use select::Selection;
pub use select::TAIL_LIMIT;
pub use settings::{SETTINGS, Setting, SettingError, TRAIN_BUDGET, setting};
pub use stats::{RenderStats, TrainingStats};
pub use trackers::{TrackerTrial, measure_trackers};
pub use training::{TrainingReport, TrainingStop};

use combine::{combine_training, pixel_estimates};
use passes::{
    Largest, Pass, TILE, TileWork, camera_sample, keep_largest, render_pass, tiles, with_tile_walk,
};
use training::{Training, after_training, spend, train_in_pool};

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
    /// A saved field trained on another scene (its bounds differ).
    #[error(
        "the field was trained on a scene with bounds {trained}, not this scene's {scene}; train a field for this scene with `zerovar train`"
    )]
    ForeignField {
        /// The bounds of the scene the field was trained on.
        trained: String,
        /// This scene's bounds.
        scene: String,
    },
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
        let early = training.early.take().map(Box::new);
        // Moved out, not borrowed: the render phase takes the training films by value.
        let (field, direct, films, report) = training.finish();
        let guidance = Guidance {
            field: &field,
            direct: Some(&direct),
            estimate: pixel_estimates(&films),
            guided_tiles: None,
        };
        let options = &after_training(options, &report);
        if let Some(early) = early.as_deref().filter(|e| decisive(e, options.guiding.components)) {
            let early = early.clone();
            return Ok(guided_everywhere(
                scene, options, guidance, films, threads, progress, report, early,
            ));
        }
        let mut result =
            guided_phase(scene, options, guidance, films, threads, progress, Some(report));
        if let Some(selection) = result.selection.as_mut() {
            selection.early = early;
        }
        Ok(result)
    })
}

/// The fewest samples per pixel of a sample budget that adaptive guiding shares with its
/// training and pilot: below it they would take most of the budget (the first pass, and a
/// pilot of at least 4 spp per candidate, are whole samples), so the render is unguided.
pub const MIN_ADAPTIVE_SPP: u32 = 16;

/// The gain, guiding every tile, from which the early look settles adaptive guiding's choice:
/// the pilot after training is skipped and every tile guided with the requested components.
/// The field only improves with training, and where a field of 3 spp already halves the work
/// of an image, the pilot (a tenth of the budget or more) could only confirm it. Twice, as much
/// as a partial choice must gain over guiding everywhere (`select::PARTIAL_MARGIN`).
const DECISIVE_GAIN: f64 = 2.0;

/// Whether the early look settles adaptive guiding's choice: its winner is the `requested`
/// components, it guides every tile, and the choice made on each half of its pilot, judged on
/// the other, gains at least [`DECISIVE_GAIN`]. Both halves, not their geometric mean: where
/// rare bright paths make the error, one unguided firefly in one half can lift the mean past
/// any bound, but not the half without it. Not roulette alone: it wins early on a young field
/// and loses to full guiding once the field has trained (see docs/experiments.md).
fn decisive(early: &Selection, requested: Components) -> bool {
    early.components == requested.name()
        && early.guided_tiles == early.tiles
        && early.one_way_gains.iter().all(|&g| g >= DECISIVE_GAIN)
}

/// The render phase guiding every tile with the requested components, without a pilot.
#[allow(clippy::too_many_arguments)]
fn guided_everywhere(
    scene: &Scene,
    options: &RenderOptions,
    guidance: Guidance<'_>,
    films: Vec<Film>,
    threads: usize,
    progress: &Monitor<'_>,
    report: TrainingReport,
    early: Selection,
) -> RenderResult {
    let mut result =
        final_phase(scene, options, Some(guidance), films, threads, progress, Some(report));
    result.selection = Some(Selection { decided_early: true, seconds: 0.0, ..early });
    result
}

/// Training passes after which adaptive guiding first pilots the field (1 + 2 spp).
const EARLY_PILOT_PASSES: u32 = 2;

/// Least validated gain (out of sample, `Selection::validated_gain`) of the early pilot's
/// choice for training to go on; below it, the rest of training's share renders unguided.
/// Training takes a quarter of the budget, so a field that gains less than a tenth after 3
/// spp is not worth it; where guiding pays, the early look gains far more (see
/// docs/experiments.md).
const EARLY_MIN_GAIN: f64 = 1.1;

/// Whether the early look's pilot can be trusted to find no gain: its unguided samples are not
/// heavy-tailed ([`select::TAIL_LIMIT`]). Where they are, training goes on and the pilot after
/// it decides: going on wrongly costs at most the guided part of training's share; stopping
/// wrongly has cost ten times the error and more (see docs/experiments.md).
fn trusted(early: &Selection) -> bool {
    early.unguided_tail_share < select::TAIL_LIMIT
}

/// Whether the early look's `selection` stops training: a trusted pilot found no gain worth it
/// out of sample. The validated gain alone, not guiding every tile on all the pilot's samples
/// (`select::pilot`'s fallback): that answers a half of a heavy-tailed pilot missing the rare
/// bright paths, and a trusted pilot is light-tailed, its halves alike.
fn stops_training(selection: &Selection) -> bool {
    selection.validated_gain < EARLY_MIN_GAIN && trusted(selection)
}

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
    let selection = select::pilot(scene, options, &guidance, last_pass, 4, progress)?.selection;
    if !stops_training(&selection) {
        training.seconds += selection.seconds;
        training.early = Some(selection);
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
    result.selection =
        Some(Selection { guided_tiles: 0, gain: 1.0, stopped_training: true, ..selection });
    Some(result)
}

/// Renders `scene` guided by a field trained earlier (no training phase).
pub fn render_with_field(
    scene: &Scene,
    options: &RenderOptions,
    trained: &TrainedField,
    progress: &Progress<'_>,
) -> Result<RenderResult, RenderError> {
    if !trained.fits(&scene.bounds()) {
        let b = |a: crate::math::Aabb| format!("{:?} .. {:?}", a.min.to_array(), a.max.to_array());
        return Err(RenderError::ForeignField {
            trained: trained.scene_bounds.map_or_else(String::new, b),
            scene: b(scene.bounds()),
        });
    }
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
        let scene_bounds = Some(scene.bounds());
        Ok((TrainedField { field, direct: Some(direct), scene_bounds }, report))
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
        collision_windows: options.guiding.collision_windows,
        ..VolPath::from_scene(scene).settings()
    }
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
        record: 0,
        guided_tiles: guidance.as_ref().and_then(|g| g.guided_tiles.as_deref()),
        largest: options.fireflies > 0,
    };
    let [w, h] = scene.camera.resolution();
    let combine = options.guiding.combine_training && !training_films.is_empty();
    let mut film = if combine { Film::with_halves(w, h) } else { Film::new(w, h) };
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
        let mut found = fireflies::find(
            scene,
            pass(0, 0),
            None,
            &film,
            None,
            &largest,
            options.fireflies,
            estimate_for,
        );
        if combine {
            found.training = report.as_ref().map_or_else(Vec::new, |r| r.fireflies.clone());
        }
        found
    });
    let image = if combine { combine_training(&training_films, &film) } else { film.image() };
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

#[cfg(test)]
mod tests {
    use super::*;

    fn early(validated_gain: f64, unguided_tail_share: f64) -> Selection {
        Selection {
            tiles: 4,
            guided_tiles: 4,
            components: "full".into(),
            candidates: Vec::new(),
            pilot_spp: 4,
            seconds: 0.0,
            cost_ratio: 1.0,
            variance_ratio: 1.0,
            gain: validated_gain,
            everywhere_gain: validated_gain,
            validated_gain,
            one_way_gains: [validated_gain; 2],
            stopped_training: false,
            early: None,
            decided_early: false,
            unguided_tail_share,
        }
    }

    /// The early look stops training only on a pilot whose unguided error is not up to a few
    /// rare paths.
    #[test]
    fn a_heavy_tailed_early_look_does_not_stop_training() {
        assert!(stops_training(&early(0.9, 0.1)));
        assert!(!stops_training(&early(1.2, 0.1)));
        assert!(!stops_training(&early(0.5, 0.6)));
    }

    /// The early look settles the choice only where its pooled choice guides every tile with
    /// the requested components and each half's choice, judged on the other, gains twice,
    /// heavy-tailed or not.
    #[test]
    fn the_early_look_decides_on_both_halves_of_its_pilot() {
        assert!(decisive(&early(2.5, 0.1), Components::FULL));
        assert!(decisive(&early(2.5, 0.9), Components::FULL));
        // One half's firefly makes a large mean of a small gain.
        let lopsided = Selection { one_way_gains: [30.0, 1.5], ..early(6.7, 0.9) };
        assert!(!decisive(&lopsided, Components::FULL));
        let roulette = Selection { components: "rr".into(), ..early(2.5, 0.1) };
        assert!(!decisive(&roulette, Components::FULL));
        assert!(decisive(&roulette, Components::ROULETTE));
        assert!(!decisive(&Selection { guided_tiles: 3, ..early(2.5, 0.1) }, Components::FULL));
    }
}
