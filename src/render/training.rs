//! Training: passes of 1, 2, 4, ... samples per pixel, each guided by the field so far, the
//! field updated with its samples after each, until the training budget is spent; and what the
//! render phase's budget is after it.

use super::combine::pixel_estimates;
use super::passes::{Pass, render_pass};
use super::{
    Budget, Guidance, MAX_TRAIN_PASSES, Monitor, RenderError, RenderOptions, TrainBudget,
    walk_settings,
};
use crate::film::Film;
use crate::guided::DirectFluence;
use crate::rng::mix64;
use crate::scene::Scene;
use std::time::{Duration, Instant};
use zerovar_guiding::{Field, FieldStats};

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
    /// Each pass's largest samples, traced before the field learnt from the pass (when the
    /// render looks for fireflies), largest share of its pass's image first.
    pub fireflies: Vec<super::Firefly>,
}

/// `options` for the render phase after `training`: a time budget loses the seconds training
/// took (the budget is the whole render's), a sample budget the samples per pixel it drew
/// when training had a share of it; at least one sample per pixel is left.
pub(super) fn after_training(options: &RenderOptions, training: &TrainingReport) -> RenderOptions {
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
pub(super) struct TrainingLimit {
    pub(super) passes: u32,
    pub(super) spp: Option<u64>,
    pub(super) seconds: Option<f64>,
}

impl TrainingLimit {
    pub(super) fn of(options: &RenderOptions) -> Self {
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
pub(super) fn spend(options: &mut RenderOptions, seconds: f64) {
    if let Budget::Time(t) = options.budget {
        options.budget = Budget::Time(t.saturating_sub(Duration::from_secs_f64(seconds)));
    }
}

/// The most path vertices one training pass records (about 90 bytes each with its
/// direct-light record): a pass of more records only its first samples per pixel, so memory
/// stays bounded whatever the resolution and the number of passes. Far above what a field
/// needs to learn from (a few million samples a pass).
pub(super) const MAX_RECORDED_VERTICES: u64 = 1 << 24;

/// Training passes: 1, 2, 4, ... spp, each guided by the field so far, the field updated with
/// its samples after each. Returns the field, its direct fluence (from the last pass), the
/// passes' films and a report.
pub(super) fn train_in_pool(
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
pub(super) struct Training {
    pub(super) field: Field,
    pub(super) direct: DirectFluence,
    pub(super) films: Vec<Film>,
    pub(super) spp: u32,
    pub(super) samples: u64,
    /// Camera paths whose vertices were recorded (`samples` of them).
    recorded_paths: u64,
    /// Seconds spent in training passes and in adaptive guiding's early pilot.
    pub(super) seconds: f64,
    /// Whether the budget is spent.
    pub(super) done: bool,
    /// Why training stopped (once `done`).
    pub(super) stop: TrainingStop,
    /// Samples per pixel of the next pass.
    pub(super) next: u32,
    /// Adaptive guiding's early look, when it let training go on.
    pub(super) early: Option<super::Selection>,
    /// The passes' largest samples (see [`TrainingReport::fireflies`]).
    fireflies: Vec<super::Firefly>,
}

impl Training {
    pub(super) fn new(options: &RenderOptions) -> Result<Self, RenderError> {
        Ok(Self {
            field: Field::new(options.guiding.field.clone())?,
            direct: DirectFluence::default(),
            films: Vec::new(),
            spp: 0,
            samples: 0,
            recorded_paths: 0,
            seconds: 0.0,
            done: false,
            stop: TrainingStop::Budget,
            next: 1,
            early: None,
            fireflies: Vec::new(),
        })
    }

    /// Runs passes until `until` passes are done or the training budget is spent.
    pub(super) fn run(
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
            let mut film = Film::with_halves(w, h);
            let estimate = pixel_estimates(&self.films);
            // Each pass draws from its own streams, independent of the render phase's.
            let seed = mix64(options.seed ^ (0x7261_696E_0000 + pass as u64));
            let pass_start = Instant::now();
            let record = self.recorded_spp(count, pixels);
            let spec = Pass {
                settings: &settings,
                seed,
                first: 0,
                count,
                field: Some((&self.field, Some(&self.direct))),
                estimate: estimate.as_deref(),
                record,
                guided_tiles: None,
                largest: options.fireflies > 0,
            };
            let Some(out) = render_pass(scene, spec, &mut film, progress, &|_| {}) else {
                return Err(RenderError::Cancelled);
            };
            if options.fireflies > 0 {
                let found = super::fireflies::find(
                    scene,
                    spec,
                    Some(pass),
                    &film,
                    estimate.as_deref(),
                    &out.largest,
                    options.fireflies,
                    |_| estimate.as_deref(),
                );
                self.fireflies.extend(found.samples);
                self.fireflies.sort_by(|a, b| b.share.total_cmp(&a.share));
                self.fireflies.truncate(options.fireflies);
            }
            self.field.update(&out.samples)?;
            self.direct = DirectFluence::build(&self.field, &out.records);
            self.samples += out.samples.len() as u64;
            self.recorded_paths += u64::from(record) * pixels;
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

    /// How many of a pass's `count` samples per pixel to record: all of them unless the
    /// vertices they would hold, at the recorded paths' mean length so far, pass
    /// [`MAX_RECORDED_VERTICES`]; at least one.
    fn recorded_spp(&self, count: u32, pixels: u64) -> u32 {
        let paths = self.recorded_paths;
        let per_path = if paths > 0 { (self.samples as f64 / paths as f64).max(1.0) } else { 1.0 };
        let fits = MAX_RECORDED_VERTICES as f64 / (per_path * pixels.max(1) as f64);
        count.min(fits.max(1.0) as u32)
    }

    /// The field so far, as the render phase would use it.
    pub(super) fn guidance(&self) -> Guidance<'_> {
        Guidance {
            field: &self.field,
            direct: Some(&self.direct),
            estimate: pixel_estimates(&self.films),
            guided_tiles: None,
        }
    }

    pub(super) fn report(&self) -> TrainingReport {
        TrainingReport {
            passes: self.films.len() as u32,
            spp: self.spp,
            seconds: self.seconds,
            samples: self.samples,
            field: self.field.stats(),
            stop: self.stop,
            fireflies: self.fireflies.clone(),
        }
    }

    pub(super) fn finish(self) -> (Field, DirectFluence, Vec<Film>, TrainingReport) {
        let report = self.report();
        (self.field, self.direct, self.films, report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{Budget, OptionsError, RenderOptions, TrainBudget};
    use zerovar_guiding::FieldConfig;

    /// A pass records all its samples while they fit the vertex budget at the recorded paths'
    /// mean length, and only its first samples per pixel beyond: memory stays bounded however
    /// many passes double the samples.
    #[test]
    fn training_records_a_bounded_number_of_vertices_per_pass() {
        let options = RenderOptions::unguided(Budget::Samples(64), 0);
        let mut t = Training::new(&options).unwrap();
        let pixels = 256;
        assert_eq!(t.recorded_spp(1, pixels), 1);
        // Paths of 4 vertices so far: 2^24 / (4 x 256) = 16384 samples per pixel fit.
        (t.recorded_paths, t.samples) = (1000, 4000);
        assert_eq!(t.recorded_spp(8192, pixels), 8192);
        assert_eq!(t.recorded_spp(1 << 19, pixels), 16384);
        // Never none, however long the paths.
        t.samples = u64::MAX / 2;
        assert_eq!(t.recorded_spp(1 << 19, pixels), 1);
    }

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
            fireflies: Vec::new(),
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
