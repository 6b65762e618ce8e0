//! `zerovar compare`: several methods (named sets of render options) on one scene with the
//! same budget, training included in a guided method's time, their error against a
//! reference over several seeds, and tables (markdown, CSV, JSON) and images of the outcome.
//!
//! Single runs of firefly-prone scenes scatter by factors, so each method renders once per
//! seed at the full budget and the tables give the median and the range of its relMSE,
//! untrimmed and with the worst pixels left out. The first seed also renders at 1/8, 1/4 and
//! 1/2 of the budget, each a separate equal-budget run, for the convergence curve.
//!
//! When the reference carries its standard error, efficiencies are computed from the excess
//! relMSE (the reference's own noise taken out, see [`crate::metrics`]) provided every method's
//! excess stands out of its noise; otherwise from the raw relMSE, and the table says which.

use crate::metrics::{ImageError, MetricsError, compare_with_reference_noise};
use serde::Serialize;
use zerovar::guided::Components;
use zerovar::render::{Budget, RenderError, RenderOptions, TrainBudget, render};
use zerovar::scene::Scene;
use zerovar::tracking::TrackerChoice;

/// A named set of render options.
#[derive(Clone, Debug)]
pub struct Method {
    /// Its name in tables and file names.
    pub name: String,
    /// The options (the budget is the comparison's).
    pub options: RenderOptions,
    /// The tracker for every medium.
    pub tracker: TrackerChoice,
}

/// Why a comparison cannot run.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// A `--method` specification does not parse.
    #[error("--method {spec}: {why}")]
    Method {
        /// The specification.
        spec: String,
        /// What is wrong.
        why: String,
    },
    /// A render failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The reference does not fit.
    #[error("reference: {0}")]
    Metrics(#[from] MetricsError),
    /// No seed to render with.
    #[error("no seeds: give at least one")]
    NoSeeds,
    /// A method's tracker cannot apply to the scene.
    #[error("method {method}: {message}")]
    Tracker {
        /// The method.
        method: String,
        /// The tracker error.
        message: String,
    },
}

impl Method {
    /// Parses `NAME=key:value,key:value,...` over `base`. The keys are the guiding settings
    /// (`zerovar::render::SETTINGS`: the CLI's flags without `--`, with the same values and
    /// rules) and `tracker` (a `--tracker` name). `NAME` alone means `base` unchanged.
    pub fn parse(spec: &str, base: &RenderOptions) -> Result<Self, CompareError> {
        let err = |why: String| CompareError::Method { spec: spec.to_string(), why };
        let (name, rest) = spec.split_once('=').unwrap_or((spec, ""));
        let name = name.trim();
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || "-_".contains(c)) {
            return Err(err("the name must be letters, digits, - or _ (it names files)".into()));
        }
        let mut m =
            Method { name: name.to_string(), options: base.clone(), tracker: TrackerChoice::Auto };
        let mut settings = Vec::new();
        for pair in rest.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let Some((key, value)) = pair.split_once(':') else {
                return Err(err(format!("`{pair}` is not key:value")));
            };
            if key.trim() == "tracker" {
                m.tracker = value.parse().map_err(|e| err(format!("tracker: {e}")))?;
            } else {
                settings.push((key.trim(), value));
            }
        }
        m.options.guiding.apply(settings).map_err(|e| {
            let known = matches!(e, zerovar::render::SettingError::Unknown { .. });
            err(if known { format!("{e}, or tracker") } else { e.to_string() })
        })?;
        Ok(m)
    }

    /// The default methods: unguided, guided with everything on, and adaptive guiding (full
    /// guiding in the tiles where it pays).
    pub fn defaults(base: &RenderOptions) -> Vec<Method> {
        let mut guided = base.clone();
        guided.guiding.components = Components::FULL;
        let mut auto = guided.clone();
        auto.guiding.adaptive = true;
        vec![
            Method {
                name: "unguided".into(),
                options: RenderOptions { guiding: Default::default(), ..base.clone() },
                tracker: TrackerChoice::Auto,
            },
            Method { name: "guided".into(), options: guided, tracker: TrackerChoice::Auto },
            Method { name: "auto".into(), options: auto, tracker: TrackerChoice::Auto },
        ]
    }
}

/// One point of a convergence curve.
#[derive(Clone, Debug, Serialize)]
pub struct Checkpoint {
    /// Fraction of the budget.
    pub fraction: f64,
    /// Seconds in all, training included.
    pub seconds: f64,
    /// Samples per pixel of the render phase.
    pub spp: u32,
    /// Error against the reference (untrimmed).
    pub error: ImageError,
}

/// One render of a method at the full budget.
#[derive(Clone, Debug, Serialize)]
pub struct Run {
    /// Its seed.
    pub seed: u64,
    /// Seconds in all, training included.
    pub seconds: f64,
    /// Samples per pixel of the render phase.
    pub spp: u32,
    /// Error against the reference, every pixel counted.
    pub error: ImageError,
    /// Error with the comparison's `trim` of worst pixels left out.
    pub trimmed: ImageError,
    /// Training: passes, spp, seconds and why it stopped (guided methods).
    pub training: Option<RunTraining>,
    /// What adaptive guiding chose (`auto` methods).
    pub selection: Option<zerovar::render::Selection>,
}

/// A run's training, as `--stats` reports it.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct RunTraining {
    /// Training passes.
    pub passes: u32,
    /// Samples per pixel over them.
    pub spp: u32,
    /// Their seconds.
    pub seconds: f64,
    /// Why training stopped.
    pub stop: zerovar::render::TrainingStop,
}

/// The median of some runs' values and their range.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Spread {
    /// The median (the mean of the middle two for an even count).
    pub median: f64,
    /// The smallest.
    pub min: f64,
    /// The largest.
    pub max: f64,
}

impl Spread {
    /// The spread of `values` (NaN for none).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let mut v: Vec<f64> = values.into_iter().collect();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n == 0 {
            return Self { median: f64::NAN, min: f64::NAN, max: f64::NAN };
        }
        let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
        Self { median, min: v[0], max: v[n - 1] }
    }
}

/// The outcome of one method.
#[derive(Clone, Debug, Serialize)]
pub struct MethodResult {
    /// The method's name.
    pub name: String,
    /// One render per seed at the full budget.
    pub runs: Vec<Run>,
    /// Convergence of the first seed (renders at fractions of the budget), the last point
    /// its full-budget run.
    pub checkpoints: Vec<Checkpoint>,
    /// relMSE over the runs.
    pub rel_mse: Spread,
    /// relMSE with the worst pixels left out, over the runs.
    pub trimmed_rel_mse: Spread,
    /// relMSE less the reference's own noise, over the runs (when the reference has its
    /// standard error).
    pub excess_rel_mse: Option<Spread>,
    /// Seconds over the runs.
    pub seconds: Spread,
    /// The error the efficiency is computed from: the median relMSE (see `error_basis`).
    pub error: f64,
    /// Which relMSE `error` is.
    pub error_basis: ErrorBasis,
    /// Efficiency 1 / (error x median seconds).
    pub efficiency: f64,
    /// Efficiency relative to the first method's.
    pub speedup: f64,
    /// The first seed's image at the full budget (not serialised).
    #[serde(skip)]
    pub image: Vec<[f32; 3]>,
}

/// Which relMSE a comparison's efficiencies are computed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorBasis {
    /// relMSE against the reference as it is.
    RelMse,
    /// relMSE less the reference's own noise (every run's excess was resolved).
    Excess,
}

/// What a comparison renders and how it measures.
#[derive(Clone, Debug)]
pub struct Protocol {
    /// The budget of every run.
    pub budget: Budget,
    /// One run per seed for every method; the first also draws the convergence curve.
    pub seeds: Vec<u64>,
    /// The fraction of worst pixels the trimmed relMSE leaves out.
    pub trim: f64,
    /// Whether each method also renders 1/8, 1/4 and 1/2 of the budget with the first seed,
    /// for the convergence curve.
    pub curve: bool,
}

/// Runs every method with the protocol's budget and seeds on `scene` and measures it against
/// `reference`, whose per-pixel standard error `reference_error` (if known) is taken out of
/// the relMSE. `progress(method index, step, steps)` reports as each render starts.
pub fn run(
    scene: &mut Scene,
    reference: &[[f32; 3]],
    reference_error: Option<&[[f32; 3]]>,
    methods: &[Method],
    protocol: &Protocol,
    progress: &dyn Fn(usize, usize, usize),
) -> Result<Vec<MethodResult>, CompareError> {
    let measure = |image: &[[f32; 3]], trim: f64| {
        compare_with_reference_noise(image, reference, reference_error, trim)
    };
    // Size and trim are checked before any rendering.
    measure(reference, protocol.trim)?;
    let pixels = (scene.camera().resolution()[0] * scene.camera().resolution()[1]) as usize;
    if pixels != reference.len() {
        return Err(MetricsError::SizeMismatch { image: pixels, reference: reference.len() }.into());
    }
    let Some(&first_seed) = protocol.seeds.first() else {
        return Err(CompareError::NoSeeds);
    };
    let fractions: &[f64] = if protocol.curve { &[0.125, 0.25, 0.5] } else { &[] };
    let steps = fractions.len() + protocol.seeds.len();
    let render_at = |scene: &mut Scene, m: &Method, fraction: f64, seed: u64| {
        scene.set_tracker(m.tracker).map_err(|e| CompareError::Tracker {
            method: m.name.clone(),
            message: e.to_string(),
        })?;
        let mut options = m.options.clone();
        options.seed = seed;
        options.budget = scaled(protocol.budget, fraction, &mut options);
        let r = render(scene, &options, &|_, _| true)?;
        let seconds = r.seconds + r.training.as_ref().map_or(0.0, |t| t.seconds);
        Ok::<_, CompareError>((r, seconds))
    };
    // The convergence curves first, then the seeds' runs taken in turns across the methods,
    // so that a machine whose speed drifts during the comparison favours no method.
    let mut checkpoints = Vec::with_capacity(methods.len());
    for (mi, m) in methods.iter().enumerate() {
        let mut curve = Vec::with_capacity(fractions.len() + 1);
        for (ci, &fraction) in fractions.iter().enumerate() {
            progress(mi, ci, steps);
            let (r, seconds) = render_at(scene, m, fraction, first_seed)?;
            curve.push(Checkpoint {
                fraction,
                seconds,
                spp: r.spp,
                error: measure(&r.image, 0.0)?,
            });
        }
        checkpoints.push(curve);
    }
    let mut runs = vec![Vec::with_capacity(protocol.seeds.len()); methods.len()];
    let mut images = vec![Vec::new(); methods.len()];
    for (k, &seed) in protocol.seeds.iter().enumerate() {
        for (mi, m) in methods.iter().enumerate() {
            progress(mi, fractions.len() + k, steps);
            let (r, seconds) = render_at(scene, m, 1.0, seed)?;
            let error = measure(&r.image, 0.0)?;
            if k == 0 {
                checkpoints[mi].push(Checkpoint { fraction: 1.0, seconds, spp: r.spp, error });
                images[mi] = r.image.clone();
            }
            let training = r.training.as_ref().map(|t| RunTraining {
                passes: t.passes,
                spp: t.spp,
                seconds: t.seconds,
                stop: t.stop,
            });
            runs[mi].push(Run {
                seed,
                seconds,
                spp: r.spp,
                error,
                trimmed: measure(&r.image, protocol.trim)?,
                training,
                selection: r.selection.clone(),
            });
        }
    }
    let mut results = Vec::with_capacity(methods.len());
    for (((m, runs), checkpoints), image) in methods.iter().zip(runs).zip(checkpoints).zip(images) {
        let excess = runs
            .iter()
            .map(|r| r.error.reference_noise.map(|n| n.excess.all))
            .collect::<Option<Vec<f64>>>()
            .map(Spread::of);
        results.push(MethodResult {
            name: m.name.clone(),
            rel_mse: Spread::of(runs.iter().map(|r| r.error.rel_mse.all)),
            trimmed_rel_mse: Spread::of(runs.iter().map(|r| r.trimmed.rel_mse.all)),
            excess_rel_mse: excess,
            seconds: Spread::of(runs.iter().map(|r| r.seconds)),
            runs,
            checkpoints,
            error: 0.0,
            error_basis: ErrorBasis::RelMse,
            efficiency: 0.0,
            speedup: 1.0,
            image,
        });
    }
    let resolved = |r: &MethodResult| {
        r.runs.iter().all(|run| run.error.reference_noise.is_some_and(|n| n.resolved()))
    };
    let basis = if results.iter().all(resolved) { ErrorBasis::Excess } else { ErrorBasis::RelMse };
    for r in &mut results {
        r.error_basis = basis;
        r.error = match (basis, r.excess_rel_mse) {
            (ErrorBasis::Excess, Some(e)) => e.median,
            _ => r.rel_mse.median,
        };
        r.efficiency = 1.0 / (r.error * r.seconds.median).max(1e-300);
    }
    scene
        .set_tracker(TrackerChoice::Auto)
        .map_err(|e| CompareError::Tracker { method: "auto".into(), message: e.to_string() })?;
    let base = results.first().map_or(1.0, |r| r.efficiency);
    for r in &mut results {
        r.speedup = r.efficiency / base;
    }
    Ok(results)
}

/// The budget for a checkpoint: `fraction` of the comparison's, and of a method's explicit
/// training time (a share of the budget scales with it by itself).
fn scaled(budget: Budget, fraction: f64, options: &mut RenderOptions) -> Budget {
    if let TrainBudget::Time(tt) = options.guiding.train {
        options.guiding.train = TrainBudget::Time(tt.mul_f64(fraction));
    }
    match budget {
        Budget::Samples(n) => Budget::Samples(((n as f64 * fraction).round() as u32).max(1)),
        Budget::Time(t) => Budget::Time(t.mul_f64(fraction)),
    }
}

/// A spread as `median [min, max]`.
fn spread(s: &Spread) -> String {
    format!("{:.3e} [{:.2e}, {:.2e}]", s.median, s.min, s.max)
}

/// The results as a markdown table: per method the median over the seeds and the range of
/// relMSE, of relMSE less the reference's noise (when known) and of relMSE with the worst
/// pixels left out, and a line saying which relMSE the efficiencies use.
pub fn markdown(results: &[MethodResult], trim: f64) -> String {
    let with_noise = results.iter().all(|r| r.excess_rel_mse.is_some());
    let seeds = results.first().map_or(0, |r| r.runs.len());
    let mut s = String::from("| method | seconds | spp | relMSE |");
    if with_noise {
        s += " relMSE - reference noise |";
    }
    s += &format!(
        " relMSE without the worst {}% | MAPE | SMAPE | efficiency | speed-up |\n|---|---|---|---|",
        100.0 * trim
    );
    if with_noise {
        s += "---|";
    }
    s += "---|---|---|---|---|\n";
    for r in results {
        let spp = Spread::of(r.runs.iter().map(|run| f64::from(run.spp)));
        s += &format!(
            "| {} | {:.2} | {:.0} | {} |",
            r.name,
            r.seconds.median,
            spp.median,
            spread(&r.rel_mse)
        );
        if let Some(e) = r.excess_rel_mse.filter(|_| with_noise) {
            s += &format!(" {} |", spread(&e));
        }
        let mape = Spread::of(r.runs.iter().map(|run| run.error.mape.all));
        let smape = Spread::of(r.runs.iter().map(|run| run.error.smape.all));
        s += &format!(
            " {} | {:.4} | {:.4} | {:.4e} | {:.2} |\n",
            spread(&r.trimmed_rel_mse),
            mape.median,
            smape.median,
            r.efficiency,
            r.speedup
        );
    }
    s += &format!(
        "\nMedians over {seeds} seed{} [smallest, largest]; efficiency is 1 / (median relMSE x median seconds), training included.\n",
        if seeds == 1 { "" } else { "s" }
    );
    if let Some(n) = results.first().and_then(|r| r.runs[0].error.reference_noise) {
        s += &format!(
            "The reference's own noise adds {:.4e} to every relMSE (its standard error layer). ",
            n.share.all
        );
        s += match results.first().map(|r| r.error_basis) {
            Some(ErrorBasis::Excess) => "Efficiency and speed-up use the relMSE less it.\n",
            _ => {
                "Some run's error is not resolved above it (excess below twice its standard error), so efficiency and speed-up use the raw relMSE: render a longer reference.\n"
            }
        };
    }
    s
}

/// Every run and checkpoint of every method as CSV (`fraction` 1 rows are the runs).
pub fn csv(results: &[MethodResult]) -> String {
    let mut s = String::from(
        "method,seed,fraction,seconds,spp,relmse,relmse_trimmed,mse,mape,smape,relmse_r,relmse_g,relmse_b,reference_noise,relmse_excess,relmse_excess_se\n",
    );
    let mut row = |name: &str,
                   seed: u64,
                   fraction: f64,
                   seconds: f64,
                   spp: u32,
                   e: &ImageError,
                   trimmed: Option<f64>| {
        s += &format!(
            "{name},{seed},{fraction},{seconds:.4},{spp},{:.6e},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e}",
            e.rel_mse.all,
            trimmed.map_or(String::new(), |t| format!("{t:.6e}")),
            e.mse.all,
            e.mape.all,
            e.smape.all,
            e.rel_mse.rgb[0],
            e.rel_mse.rgb[1],
            e.rel_mse.rgb[2]
        );
        // Empty cells when the reference's noise is unknown.
        s += &match e.reference_noise {
            Some(n) => {
                format!(",{:.6e},{:.6e},{:.6e}\n", n.share.all, n.excess.all, n.excess_std_error)
            }
            None => ",,,\n".into(),
        };
    };
    for r in results {
        let seed = r.runs[0].seed;
        for c in r.checkpoints.iter().filter(|c| c.fraction < 1.0) {
            row(&r.name, seed, c.fraction, c.seconds, c.spp, &c.error, None);
        }
        for run in &r.runs {
            row(
                &r.name,
                run.seed,
                1.0,
                run.seconds,
                run.spp,
                &run.error,
                Some(run.trimmed.rel_mse.all),
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use zerovar::render::Budget;

    #[test]
    fn spreads_are_medians_and_ranges() {
        let s = Spread::of([3.0, 1.0, 2.0]);
        assert_eq!((s.median, s.min, s.max), (2.0, 1.0, 3.0));
        assert_eq!(Spread::of([4.0, 1.0, 2.0, 10.0]).median, 3.0);
        assert!(Spread::of([]).median.is_nan());
    }

    #[test]
    fn method_options_parse_and_bad_ones_are_named() {
        let base = RenderOptions::unguided(Budget::Samples(4), 1);
        let m = Method::parse(
            "g=guiding:full,alpha:0.7,surface-alpha:0.8,distance-alpha:0.25,train-passes:3,training-images:discard",
            &base,
        )
        .expect("valid method");
        assert_eq!(m.options.guiding.distance_alpha, 0.25);
        assert_eq!(m.options.guiding.surface_alpha, 0.8);
        assert!(m.options.guiding.field.parallax);
        let flat = Method::parse("f=guiding:full,parallax:off", &base).expect("valid method");
        assert!(!flat.options.guiding.field.parallax);
        assert_eq!(m.name, "g");
        assert!(m.options.guiding.components.any() && !m.options.guiding.combine_training);
        assert_eq!(m.options.guiding.alpha, 0.7);
        assert_eq!(m.options.guiding.train, TrainBudget::Passes(3));
        let plain = Method::parse("u", &base).expect("a bare name");
        // Training images are combined unless a method says otherwise.
        assert!(plain.options.guiding.combine_training && !plain.options.guiding.components.any());
        for (spec, says) in [
            ("g=training-images:maybe", "training-images `maybe`: give combine or discard"),
            ("g=parallax:some", "parallax `some`: give on or off"),
            ("g=alpha:2", "alpha 2: give a probability in [0, 0.8]"),
            ("g=distance-alpha:-1", "distance-alpha -1: give a probability"),
            ("g=surface-alpha:1.5", "surface-alpha 1.5: give a probability"),
            ("g=train-passes:2,train-share:0.1", "train-passes and train-share both"),
            ("g=tracker:sideways", "tracker: unknown tracker `sideways`"),
            ("g=speed:3", "unknown setting `speed`; the settings are guiding, alpha"),
            ("g=speed:3", "parallax, or tracker"),
            ("g=guiding", "is not key:value"),
            ("bad name=guiding:full", "the name must be"),
        ] {
            let e = Method::parse(spec, &base).expect_err(spec).to_string();
            assert!(e.contains(says), "{spec}: {e}");
        }
    }

    #[test]
    fn full_budget_runs_take_turns_across_the_methods() {
        let text = r#"
[camera]
origin = [0, 0, 3]
target = [0, 0, 0]
fov = 40
resolution = [4, 3]

[[shapes]]
type = "sphere"
center = [0, 0, 0]
radius = 1

[[lights]]
type = "constant"
radiance = 1
"#;
        let mut scene = zerovar::scene::load_str(std::path::Path::new("turns.toml"), text, &[])
            .expect("a valid scene");
        let base = RenderOptions::unguided(Budget::Samples(2), 1);
        let methods = ["a", "b"].map(|n| Method::parse(n, &base).expect("a bare name"));
        let reference = vec![[0.5f32; 3]; 12];
        let mut protocol =
            Protocol { budget: Budget::Samples(2), seeds: vec![7, 8], trim: 0.0, curve: true };
        let order = std::cell::RefCell::new(Vec::new());
        let results = run(&mut scene, &reference, None, &methods, &protocol, &|m, step, _| {
            order.borrow_mut().push((m, step));
        })
        .expect("the comparison runs");
        // Three convergence checkpoints per method, then seed 7 for a and b, then seed 8.
        let expected =
            [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (0, 3), (1, 3), (0, 4), (1, 4)];
        assert_eq!(order.replace(Vec::new()), expected);
        for r in &results {
            assert_eq!(r.runs.iter().map(|run| run.seed).collect::<Vec<_>>(), [7, 8]);
            assert_eq!(r.checkpoints.len(), 4);
        }
        // Without the curve, only the seeds' runs, the first of each the curve's one point.
        protocol.curve = false;
        let results = run(&mut scene, &reference, None, &methods, &protocol, &|m, step, _| {
            order.borrow_mut().push((m, step));
        })
        .expect("the comparison runs");
        assert_eq!(order.into_inner(), [(0, 0), (1, 0), (0, 1), (1, 1)]);
        for r in &results {
            assert_eq!(r.runs.len(), 2);
            assert_eq!(r.checkpoints.iter().map(|c| c.fraction).collect::<Vec<_>>(), [1.0]);
        }
    }
}
