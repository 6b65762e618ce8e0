//! The options of a render, as the CLI, `compare`'s methods and the library give them, and
//! the rules they must meet ([`RenderOptions::validate`]).

use crate::guided::Components;
pub use crate::integrators::walk::MAX_ALPHA;
use std::time::Duration;
use zerovar_guiding::FieldConfig;

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

/// Guiding settings of a render.
#[derive(Clone, Debug)]
pub struct GuidingOptions {
    /// Which decisions are guided; nothing guided means no training.
    pub components: Components,
    /// Probability of the guided strategy in every mixture in media, in [0, [`MAX_ALPHA`]].
    pub alpha: f32,
    /// Probability of the guided strategy in every mixture at surfaces, in [0, [`MAX_ALPHA`]]
    /// ([`DEFAULT_SURFACE_ALPHA`]).
    pub surface_alpha: f32,
    /// Probability of the zero-variance collision density in guided flights' mixture with
    /// standard tracking, in [0, [`MAX_ALPHA`]] ([`DEFAULT_DISTANCE_ALPHA`]); guided flights
    /// take their extra collisions for delta lights whatever it is.
    pub distance_alpha: f32,
    /// Weight windows also after each medium collision, before its next-event estimate,
    /// besides the one after each direction (needs roulette guided). Off by default: at equal
    /// time on the tuning scenes they cost more than they saved (see docs/experiments.md).
    pub collision_windows: bool,
    /// Training budget.
    pub train: TrainBudget,
    /// Settings of a new field.
    pub field: FieldConfig,
    /// Combine the training passes' images with the render's by inverse variance, rather than
    /// discarding them (the default: at equal time it lowers the error where guiding pays and
    /// changes nothing where it does not; see docs/experiments.md). The weights follow
    /// relMSE's, so unlike the render phase's samples they depend a little on the scene's
    /// units. Each image's weight is estimated from its other half of samples (even against
    /// odd), never from the samples it weighs, so no image's own fireflies lower its weight.
    pub combine_training: bool,
    /// Guide only the 16x16 tiles where a pilot after training finds guiding more efficient
    /// than unguided sampling (see [`Selection`](super::Selection)); the others render unguided.
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
            collision_windows: false,
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
    /// paths ([`FireflyReport`](super::FireflyReport)): this many of them (0: none).
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

    /// Checks every setting; [`render`](super::render),
    /// [`render_with_field`](super::render_with_field) and [`train`](super::train) call it
    /// before any work, so options assembled in code meet the same rules as the CLI's.
    pub fn validate(&self) -> Result<(), OptionsError> {
        match self.budget {
            Budget::Samples(0) => return Err(OptionsError::ZeroSamples),
            Budget::Time(t) if t.is_zero() => return Err(OptionsError::ZeroTime),
            _ => {}
        }
        if self.threads == Some(0) {
            return Err(OptionsError::ZeroThreads);
        }
        if let Some(n) = self.threads.filter(|&n| n > MAX_THREADS) {
            return Err(OptionsError::TooManyThreads(n));
        }
        self.guiding.validate()?;
        match (self.guiding.train, self.budget) {
            (TrainBudget::Time(t), Budget::Time(b)) if t >= b => {
                Err(OptionsError::TrainTimeOverBudget)
            }
            _ => Ok(()),
        }
    }
}

impl GuidingOptions {
    /// Checks the guiding settings (what [`RenderOptions::validate`] checks of them).
    pub fn validate(&self) -> Result<(), OptionsError> {
        let probability = |a: f32| (0.0..=MAX_ALPHA).contains(&a);
        if !probability(self.alpha) {
            return Err(OptionsError::Alpha(self.alpha));
        }
        if !probability(self.surface_alpha) {
            return Err(OptionsError::SurfaceAlpha(self.surface_alpha));
        }
        if !probability(self.distance_alpha) {
            return Err(OptionsError::DistanceAlpha(self.distance_alpha));
        }
        // A decision asked for but left unguided by its share would be silence.
        let c = self.components;
        if c.directions && self.alpha == 0.0 && self.surface_alpha == 0.0 {
            return Err(OptionsError::NothingGuided);
        }
        if c.distances && self.alpha == 0.0 {
            return Err(OptionsError::DistancesUnguided);
        }
        if self.collision_windows && !c.roulette {
            return Err(OptionsError::CollisionWindowsUnguided);
        }
        match self.train {
            TrainBudget::Passes(n) if n == 0 || n > MAX_TRAIN_PASSES => {
                Err(OptionsError::TrainPasses(n))
            }
            TrainBudget::Time(t) if t.is_zero() => Err(OptionsError::ZeroTrainTime),
            TrainBudget::Share(s) if !(s > 0.0 && s < 1.0) => Err(OptionsError::TrainShare(s)),
            _ => Ok(()),
        }
    }
}

/// The most worker threads a render takes: far more than any machine's cores, and few enough
/// that per-thread buffers cannot exhaust memory.
pub const MAX_THREADS: usize = 1024;

/// The most training passes [`TrainBudget::Passes`] takes: pass k renders 2^k spp, so 20
/// passes are already a million samples per pixel.
pub const MAX_TRAIN_PASSES: u32 = 20;

/// The default [`GuidingOptions::distance_alpha`]: none. Guided flights keep their extra
/// collisions for delta lights (placed by the field's direct-light grid), but their own
/// collision follows standard tracking: the zero-variance collision density needs a field
/// lookup per flight, and at equal time that cost more than it saved on every bench scene
/// (see docs/experiments.md). The in-scattered light it follows is mostly the delta lights'
/// single scattering, which the extra collisions already place; what is left varies slowly
/// along a ray.
pub const DEFAULT_DISTANCE_ALPHA: f32 = 0.0;

/// The default [`GuidingOptions::surface_alpha`]: at a diffuse surface the standard strategy
/// (cosine sampling) covers the whole hemisphere and a dark wall sends most of its samples
/// into the dark, so a smaller defensive share pays there than in a medium, whose phase
/// sampling the field's product with HG only approximates (see docs/experiments.md).
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
    /// More worker threads than [`MAX_THREADS`].
    #[error("{0} threads: give at most 1024 (each holds its own tile buffers)")]
    TooManyThreads(usize),
    /// The guided strategy's probability is outside [0, [`MAX_ALPHA`]] (or NaN).
    #[error(
        "alpha {0}: give a probability in [0, 0.8] (standard sampling keeps at least 20%, which bounds every guided weight)"
    )]
    Alpha(f32),
    /// The guided strategy's probability at surfaces is outside [0, [`MAX_ALPHA`]] (or NaN).
    #[error(
        "surface-alpha {0}: give a probability in [0, 0.8] (standard sampling keeps at least 20%, which bounds every guided weight)"
    )]
    SurfaceAlpha(f32),
    /// The zero-variance collision density's probability is outside [0, [`MAX_ALPHA`]] (or
    /// NaN).
    #[error(
        "distance-alpha {0}: give a probability in [0, 0.8] (standard tracking keeps at least 20%, which bounds every guided weight)"
    )]
    DistanceAlpha(f32),
    /// Directions are guided at alpha 0 in media and at surfaces: none would be.
    #[error(
        "directions are guided at alpha 0 and surface-alpha 0, so none would be: give a positive alpha or surface-alpha, or leave directions out of --guiding"
    )]
    NothingGuided,
    /// Distances are guided at alpha 0: guided flights take the media's share, so none would
    /// be.
    #[error(
        "distances are guided at alpha 0, so none would be (guided flights, extra collisions included, come with the media's guided share): give a positive alpha, or leave distances out of --guiding"
    )]
    DistancesUnguided,
    /// Collision windows asked for without guided roulette, which they are part of.
    #[error(
        "collision-windows on needs guided roulette: add rr to --guiding (full and auto include it), or leave collision-windows off"
    )]
    CollisionWindowsUnguided,
    /// A number of training passes outside 1..=[`MAX_TRAIN_PASSES`].
    #[error("train-passes {0}: give 1 to 20 (pass k renders 2^k spp)")]
    TrainPasses(u32),
    /// A training time of zero.
    #[error("train-time 0: give a positive number of seconds")]
    ZeroTrainTime,
    /// A training share outside (0, 1) (or NaN).
    #[error("train-share {0}: give a fraction of the budget above 0 and below 1")]
    TrainShare(f32),
    /// A training time as long as the whole time budget, or longer.
    #[error(
        "the training time is not shorter than the time budget, which includes it; give a shorter training time or a longer budget"
    )]
    TrainTimeOverBudget,
}
