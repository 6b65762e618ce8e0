//! Command-line arguments (clap), their validation into a `Command`, and running it.

mod crop;
mod paths;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use crop::{crops, noisiest_window, parse_crop};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use paths::check_outputs;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Duration;
use zerovar::guided::Components;
use zerovar::guided::TrainedField;
use zerovar::output::{ImageMetadata, write_exr, write_png};
use zerovar::render::{Budget, GuidingOptions, RenderOptions, render, render_with_field};
use zerovar::render::{RenderStats, SETTINGS, Setting, TRAIN_BUDGET, TrainingStats};

#[derive(Parser)]
#[command(
    name = "zerovar",
    version,
    about = "A volumetric path tracer built around zero-variance path guiding"
)]
struct Cli {
    #[command(subcommand)]
    command: CommandArgs,
}

#[derive(Subcommand)]
enum CommandArgs {
    /// Render a scene to an EXR image and a PNG preview beside it.
    Render(RenderArgs),
    /// Load and validate a scene and print what it holds.
    Check(CheckArgs),
    /// Train a guiding field on a scene and save it, for `render --field`.
    Train(TrainArgs),
    /// Render a high-quality unguided reference with its per-pixel standard error.
    Reference(ReferenceArgs),
    /// Compare methods (sets of render options) at equal budget against a reference.
    Compare(CompareArgs),
}

#[derive(Args)]
struct BudgetArgs {
    /// Samples per pixel.
    #[arg(long, conflicts_with = "time")]
    spp: Option<u32>,
    /// Seconds.
    #[arg(long, allow_negative_numbers = true)]
    time: Option<f64>,
}

#[derive(Args)]
struct ReferenceArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Output EXR (a second layer `stderr` holds the standard error).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    budget: BudgetArgs,
    /// Seed [default: the scene's seed + 1000003, independent of renders with the scene's seed].
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args)]
struct CompareArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// The reference EXR (from `zerovar reference`).
    #[arg(long)]
    reference: PathBuf,
    #[command(flatten)]
    budget: BudgetArgs,
    /// A method: NAME=key:value,... with the guiding flags as keys (guiding, alpha,
    /// surface-alpha, distance-alpha, collision-windows, train-share, train-passes, train-time,
    /// training-images, parallax) and tracker (repeatable) [default: unguided,
    /// guided=guiding:full and auto=guiding:auto].
    #[arg(long, value_name = "NAME=OPTIONS")]
    method: Vec<String>,
    /// Directory for the tables and images.
    #[arg(long, default_value = "compare")]
    out: PathBuf,
    /// Fraction of worst pixels the trimmed relMSE leaves out (the other metrics count every
    /// pixel).
    #[arg(long, default_value_t = 0.001)]
    trim: f64,
    /// Renders of each method, with seeds from --seed on; the tables give medians and ranges.
    #[arg(long, default_value_t = 3)]
    seeds: u32,
    /// No convergence curve: each method renders only its seeds' runs, not also 1/8, 1/4 and
    /// 1/2 of the budget (the comparison takes about half the time; the plot shows one point
    /// per method).
    #[arg(long)]
    no_curve: bool,
    /// The window of `crops.png`, as X,Y,WIDTH,HEIGHT in pixels [default: a quarter of the
    /// image in each direction, where the first method's relative error is largest].
    #[arg(long, value_name = "X,Y,W,H")]
    crop: Option<String>,
    /// The first seed of the methods' renders [default: the scene's].
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
}

/// The guiding settings as flags, one per entry of `zerovar::render::SETTINGS` (for `train`,
/// only those that concern training), kept as given: the library parses and checks them, so
/// they take the same values and meet the same rules as `compare`'s method keys.
#[derive(Clone, Debug, Default)]
struct GuidingArgs<const TRAIN: bool> {
    given: Vec<(&'static str, String)>,
}

impl<const TRAIN: bool> GuidingArgs<TRAIN> {
    fn settings() -> impl Iterator<Item = &'static Setting> {
        SETTINGS.iter().filter(|s| s.trains || !TRAIN)
    }

    fn given(&self, key: &str) -> Option<&str> {
        self.given.iter().find(|(k, _)| *k == key).map(|(_, v)| v.as_str())
    }

    /// The settings applied over `base`; errors name the flag.
    fn apply(&self, mut base: GuidingOptions) -> Result<GuidingOptions> {
        base.apply(self.given.iter().map(|(k, v)| (*k, v.as_str())))
            .map_err(|e| anyhow::anyhow!("--{e}"))?;
        Ok(base)
    }
}

impl<const TRAIN: bool> clap::FromArgMatches for GuidingArgs<TRAIN> {
    fn from_arg_matches(m: &clap::ArgMatches) -> Result<Self, clap::Error> {
        let given = Self::settings()
            .filter_map(|s| m.get_one::<String>(s.key).map(|v| (s.key, v.clone())))
            .collect();
        Ok(Self { given })
    }

    fn update_from_arg_matches(&mut self, m: &clap::ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
    }
}

impl<const TRAIN: bool> Args for GuidingArgs<TRAIN> {
    fn augment_args(cmd: clap::Command) -> clap::Command {
        Self::settings().fold(cmd, |cmd, s| {
            let others =
                TRAIN_BUDGET.iter().filter(|k| TRAIN_BUDGET.contains(&s.key) && **k != s.key);
            cmd.arg(
                clap::Arg::new(s.key)
                    .long(s.key)
                    .value_name(s.value)
                    .help(s.help)
                    .allow_negative_numbers(true)
                    .conflicts_with_all(others.copied()),
            )
        })
    }

    fn augment_args_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_args(cmd)
    }
}

#[derive(Args)]
struct TrainArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Where to save the field.
    #[arg(short, long)]
    output: PathBuf,
    /// The render budget the field is for (--spp or --time, as `render` takes them): training
    /// takes its share of it, as `render` would [default: the scene's render.spp].
    #[command(flatten)]
    budget: BudgetArgs,
    #[command(flatten)]
    guiding: GuidingArgs<true>,
    /// Seed of the random streams [default: the scene's render.seed].
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args)]
struct SceneArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// Override a value of the scene's [defaults] table (repeatable).
    #[arg(short = 'D', value_name = "KEY=VALUE")]
    define: Vec<String>,
    /// Free-flight tracker: auto (per medium: closed form if homogeneous, delta tracking for
    /// grey grids, spectral tracking for chromatic ones) or one for every medium: analytic, analytic-spectral,
    /// regular, delta, weighted-delta, decomposition, weighted-decomposition, spectral,
    /// spectral-max, spectral-average, spectral-decomposition, ray-marching-biased (BIASED).
    #[arg(long, default_value = "auto", value_name = "TRACKER")]
    tracker: zerovar::tracking::TrackerChoice,
}

#[derive(Args)]
struct CheckArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Also measure, on each heterogeneous medium, every tracker that can handle it: unguided
    /// renders with only that medium's tracker changed, about SECONDS of rendering per medium,
    /// reported as efficiency relative to the tracker the scene uses there.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    trackers: Option<f64>,
}

#[derive(Args)]
struct RenderArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Output EXR file [default: the scene's name with .exr, in the current directory].
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Samples per pixel [default: the scene's render.spp].
    #[arg(long, conflicts_with = "time")]
    spp: Option<u32>,
    /// Render for this many seconds instead of a fixed sample count.
    #[arg(long, allow_negative_numbers = true)]
    time: Option<f64>,
    /// Seed of the random streams [default: the scene's render.seed].
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Write render statistics as JSON to this file.
    #[arg(long, value_name = "FILE.json")]
    stats: Option<PathBuf>,
    /// Exposure of the PNG preview in stops.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
    #[command(flatten)]
    guiding: GuidingArgs<false>,
    /// Render guided by a field saved by `zerovar train` (no training phase).
    #[arg(long, value_name = "FIELD")]
    field: Option<PathBuf>,
    /// Find the N samples that hold most of the image's error and trace their paths: a
    /// table on stderr, and every decision of each path in --stats.
    #[arg(long, value_name = "N", default_value_t = 0)]
    fireflies: usize,
}

/// A fully validated render request.
struct RenderCommand {
    scene: PathBuf,
    defines: Vec<(String, String)>,
    output: PathBuf,
    png: PathBuf,
    spp: Option<u32>,
    time: Option<Duration>,
    seed: Option<u64>,
    threads: Option<usize>,
    stats: Option<PathBuf>,
    exposure: f32,
    progress: bool,
    tracker: zerovar::tracking::TrackerChoice,
    guiding: GuidingOptions,
    field: Option<PathBuf>,
    fireflies: usize,
}

pub(crate) fn run() -> Result<()> {
    match Cli::parse().command {
        CommandArgs::Check(a) => {
            let defines = parse_defines(&a.scene.define)?;
            let mut scene = zerovar::scene::load(&a.scene.scene, &defines)?;
            scene.set_tracker(a.scene.tracker).map_err(|e| anyhow::anyhow!("--{e}"))?;
            print!("{}", scene.describe());
            if let Some(seconds) = a.trackers {
                if !(seconds > 0.0 && seconds.is_finite()) {
                    bail!("--trackers {seconds}: give the seconds to spend per medium, above 0");
                }
                print_tracker_trials(&mut scene, seconds)?;
            }
            Ok(())
        }
        CommandArgs::Render(a) => run_render(validate(a)?),
        CommandArgs::Train(a) => run_train(a),
        CommandArgs::Reference(a) => run_reference(a),
        CommandArgs::Compare(a) => run_compare(a),
    }
}

/// `check --trackers`: each heterogeneous medium's candidate trackers, measured.
fn print_tracker_trials(scene: &mut zerovar::scene::Scene, seconds: f64) -> Result<()> {
    let mut measured = 0;
    for i in 0..scene.media().len() {
        let own = scene.trackers()[i];
        let trials = zerovar::render::measure_trackers(scene, i, seconds, None)?;
        // A forced tracker that is not a candidate (ray marching) is measured against delta.
        let Some(base) =
            trials.iter().find(|t| t.tracker == own.steerable()).or(trials.first()).copied()
        else {
            continue;
        };
        measured += 1;
        println!(
            "trackers on `{}` ({} unguided renders of {} spp each; efficiency = 1 / (relative \
             variance x seconds) relative to {}, then without the worst 0.1% of pixels):",
            scene.media()[i].name,
            base.runs,
            base.spp,
            base.tracker.name()
        );
        for t in &trials {
            println!(
                "  {:<24} {:>5.2} {:>5.2}   relative variance {:.3e} ({:.3e}), {:.3} s per \
                 render, {:.2} density lookups per path",
                t.tracker.name(),
                t.efficiency() / base.efficiency(),
                t.trimmed_efficiency() / base.trimmed_efficiency(),
                t.relative_variance,
                t.trimmed_relative_variance,
                t.seconds,
                t.lookups_per_path,
            );
        }
        let better = |t: &&zerovar::render::TrackerTrial| {
            t.efficiency() > HINT_MARGIN * base.efficiency()
                && t.trimmed_efficiency() > HINT_MARGIN * base.trimmed_efficiency()
        };
        if let Some(t) =
            trials.iter().filter(better).max_by(|a, b| a.efficiency().total_cmp(&b.efficiency()))
        {
            println!(
                "  hint: --tracker {} measures {:.2}x the efficiency of {} here",
                t.tracker.name(),
                t.efficiency() / base.efficiency(),
                base.tracker.name()
            );
        }
    }
    if measured == 0 {
        println!("trackers: no heterogeneous medium, nothing to measure (closed forms are exact)");
    }
    Ok(())
}

/// How much more efficient a tracker must measure, with and without the worst pixels, before
/// `check --trackers` suggests it: twice the 5-10% by which two measurements of one tracker
/// on one scene differ on a 2-core machine (docs/experiments.md).
const HINT_MARGIN: f64 = 1.2;

fn validate_budget(b: &BudgetArgs, default_spp: u32) -> Result<Budget> {
    match (b.spp, b.time) {
        (Some(0), _) => bail!("--spp 0: give at least one sample per pixel"),
        (Some(n), _) => Ok(Budget::Samples(n)),
        (None, Some(t)) if !(t > 0.0 && t.is_finite() && t < 1e7) => {
            bail!("--time {t}: give a positive number of seconds below 1e7 (about 16 weeks)")
        }
        (None, Some(t)) => Ok(Budget::Time(Duration::from_secs_f64(t))),
        (None, None) => Ok(Budget::Samples(default_spp)),
    }
}

fn run_reference(a: ReferenceArgs) -> Result<()> {
    if a.threads == Some(0) {
        bail!("--threads 0: give at least one thread, or leave it out to use every core");
    }
    if a.output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref()
        != Some("exr")
    {
        bail!("-o {}: the reference must be an .exr file", a.output.display());
    }
    check_outputs(&[("the scene", &a.scene.scene)], &[("-o", &a.output)])?;
    let defines = parse_defines(&a.scene.define)?;
    let mut scene = zerovar::scene::load(&a.scene.scene, &defines)?;
    scene.set_tracker(a.scene.tracker).map_err(|e| anyhow::anyhow!("--{e}"))?;
    let Some(default_spp) = scene.settings().spp.checked_mul(16) else {
        bail!(
            "{}: a reference renders 16 times the scene's {} spp, more than can be counted; give --spp or --time",
            a.scene.scene.display(),
            scene.settings().spp
        );
    };
    let budget = validate_budget(&a.budget, default_spp)?;
    let seed = a.seed.unwrap_or(scene.settings().seed.wrapping_add(1_000_003));
    let options = RenderOptions { threads: a.threads, ..RenderOptions::unguided(budget, seed) };
    let bar = progress_bar(!a.quiet && std::io::stderr().is_terminal());
    let result = render(&scene, &options, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
        true
    })?;
    bar.finish_and_clear();
    let [w, h] = scene.camera().resolution();
    let error: Vec<[f32; 3]> = result.film.pixels().iter().map(|p| p.std_error()).collect();
    let meta = ImageMetadata {
        spp: result.spp,
        seconds: result.seconds,
        seed,
        scene: a.scene.scene.display().to_string(),
    };
    zerovar::output::write_exr_with_error(&a.output, w, h, &result.image, &error, &meta)?;
    write_png(&a.output.with_extension("png"), w, h, &result.image, 0.0)?;
    eprintln!("reference: {} spp in {:.1} s -> {}", result.spp, result.seconds, a.output.display());
    Ok(())
}

fn run_compare(a: CompareArgs) -> Result<()> {
    use zerovar_lab::compare::{Method, csv, markdown, run};
    if a.threads == Some(0) {
        bail!("--threads 0: give at least one thread, or leave it out to use every core");
    }
    if !(0.0..0.5).contains(&a.trim) {
        bail!("--trim {}: give a fraction in [0, 0.5)", a.trim);
    }
    if a.seeds == 0 || a.seeds > 1000 {
        bail!("--seeds {}: give 1 to 1000 renders per method", a.seeds);
    }
    let defines = parse_defines(&a.scene.define)?;
    let mut scene = zerovar::scene::load(&a.scene.scene, &defines)?;
    let budget = validate_budget(&a.budget, scene.settings().spp)?;
    let base = RenderOptions {
        threads: a.threads,
        ..RenderOptions::unguided(budget, a.seed.unwrap_or(scene.settings().seed))
    };
    let mut methods = if a.method.is_empty() {
        Method::defaults(&base)
    } else {
        a.method.iter().map(|m| Method::parse(m, &base)).collect::<Result<Vec<_>, _>>()?
    };
    // --tracker is every method's tracker unless the method names one.
    for (k, m) in methods.iter_mut().enumerate() {
        if !a.method.get(k).is_some_and(|spec| spec.contains("tracker:")) {
            m.tracker = a.scene.tracker;
        }
    }
    let mut names = std::collections::HashSet::new();
    if let Some(m) = methods.iter().find(|m| !names.insert(m.name.clone())) {
        bail!("--method {}: two methods have this name", m.name);
    }
    // Created before the checks, which try writing in it.
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create the output directory", a.out.display()))?;
    check_compare_outputs(&a, &methods)?;
    let (rw, rh, reference, reference_error) = zerovar::output::read_exr_with_error(&a.reference)?;
    let [w, h] = scene.camera().resolution();
    if (rw, rh) != (w as usize, h as usize) {
        bail!(
            "--reference {}: it is {rw}x{rh} but the scene renders {w}x{h}",
            a.reference.display()
        );
    }
    let crop = a.crop.as_deref().map(|c| parse_crop(c, w as usize, h as usize)).transpose()?;
    if reference_error.is_none() {
        eprintln!(
            "note: {} has no `stderr` layer, so its own noise stays in every relMSE (a reference from `zerovar reference` has one)",
            a.reference.display()
        );
    }
    let protocol = zerovar_lab::compare::Protocol {
        budget,
        seeds: (0..u64::from(a.seeds)).map(|k| base.seed.wrapping_add(k)).collect(),
        trim: a.trim,
        curve: !a.no_curve,
    };
    let results = run(
        &mut scene,
        &reference,
        reference_error.as_deref(),
        &methods,
        &protocol,
        &|m, step, steps| {
            eprintln!("{}: render {}/{steps}", methods[m].name, step + 1);
        },
    )?;
    let table = markdown(&results, a.trim);
    print!("{table}");
    let write = |name: &str, text: String| -> Result<()> {
        let path = a.out.join(name);
        write_atomically(&path, |tmp| Ok(std::fs::write(tmp, &text)?))
            .with_context(|| format!("{}: cannot write", path.display()))
    };
    write("results.md", table.clone())?;
    write("results.csv", csv(&results))?;
    write("results.json", serde_json::to_string_pretty(&results)? + "\n")?;
    let stem = a.scene.scene.file_stem().unwrap_or_default().to_string_lossy();
    let title = format!("{stem}: relMSE against time");
    for plot in ["convergence.png", "convergence.svg"] {
        // The tables are the results; a plot that cannot be drawn is worth a warning only.
        if let Err(e) = zerovar_lab::plot::convergence(&results, &title, &a.out.join(plot)) {
            eprintln!("warning: {e}");
        }
    }
    let mut strip = reference.clone();
    let mut strip_w = w as usize;
    for r in &results {
        let meta = ImageMetadata {
            spp: r.runs[0].spp,
            seconds: r.runs[0].seconds,
            seed: base.seed,
            scene: a.scene.scene.display().to_string(),
        };
        write_exr(&a.out.join(format!("{}.exr", r.name)), w, h, &r.image, &meta)?;
        write_png(&a.out.join(format!("{}.png", r.name)), w, h, &r.image, 0.0)?;
        let err = zerovar_lab::metrics::false_colour(&r.image, &reference);
        write_png(&a.out.join(format!("{}-error.png", r.name)), w, h, &err, 0.0)?;
        strip = side_by_side(&strip, strip_w, &r.image, w as usize, h as usize);
        strip_w += w as usize;
    }
    write_png(&a.out.join("strip.png"), strip_w as u32, h, &strip, 0.0)?;
    let images: Vec<&[[f32; 3]]> =
        std::iter::once(&reference[..]).chain(results.iter().map(|r| &r.image[..])).collect();
    let window = crop.unwrap_or_else(|| {
        let first = results.first().map_or(&reference[..], |r| &r.image[..]);
        noisiest_window(first, &reference, w as usize, h as usize)
    });
    let (cw, ch, crops) = crops(&images, w as usize, window);
    write_png(&a.out.join("crops.png"), cw as u32, ch as u32, &crops, 0.0)?;
    eprintln!("wrote {}", a.out.display());
    Ok(())
}

/// Refuses a `compare` whose outputs would replace its scene or reference, or each other.
fn check_compare_outputs(a: &CompareArgs, methods: &[zerovar_lab::compare::Method]) -> Result<()> {
    let mut files: Vec<String> = [
        "results.md",
        "results.csv",
        "results.json",
        "convergence.png",
        "convergence.svg",
        "strip.png",
        "crops.png",
    ]
    .map(String::from)
    .into();
    for m in methods {
        files.extend(["exr", "png"].map(|e| format!("{}.{e}", m.name)));
        files.push(format!("{}-error.png", m.name));
    }
    let paths: Vec<PathBuf> = files.iter().map(|f| a.out.join(f)).collect();
    let labels: Vec<String> = files.iter().map(|f| format!("the {f} of --out")).collect();
    let outputs: Vec<(&str, &Path)> =
        labels.iter().zip(&paths).map(|(l, p)| (l.as_str(), p.as_path())).collect();
    check_outputs(
        &[("the scene", &a.scene.scene), ("the reference of --reference", &a.reference)],
        &outputs,
    )
}

/// Two row-major images of equal height placed left and right.
fn side_by_side(
    left: &[[f32; 3]],
    lw: usize,
    right: &[[f32; 3]],
    rw: usize,
    h: usize,
) -> Vec<[f32; 3]> {
    (0..h)
        .flat_map(|y| {
            left[y * lw..(y + 1) * lw].iter().chain(&right[y * rw..(y + 1) * rw]).copied()
        })
        .collect()
}

/// Validates guiding arguments. `field_use` names what needs a field (`train`, or rendering
/// with `--field`): there guiding defaults to full, and `off` is an error.
fn validate_guiding<const TRAIN: bool>(
    a: &GuidingArgs<TRAIN>,
    field_use: Option<&str>,
) -> Result<GuidingOptions> {
    let base = match field_use {
        Some(_) => GuidingOptions { components: Components::FULL, ..GuidingOptions::default() },
        None => GuidingOptions::auto(),
    };
    let options = a.apply(base)?;
    if let Some(what) = field_use
        && !options.components.any()
    {
        bail!(
            "--guiding {}: {what} needs something guided; give full (the default there), directions, distances, rr or a +-joined list",
            a.given("guiding").unwrap_or("off")
        );
    }
    Ok(options)
}

fn run_train(a: TrainArgs) -> Result<()> {
    let guiding = validate_guiding(&a.guiding, Some("training a field"))?;
    check_outputs(&[("the scene", &a.scene.scene)], &[("-o", &a.output)])?;
    if a.threads == Some(0) {
        bail!("--threads 0: give at least one thread, or leave it out to use every core");
    }
    let defines = parse_defines(&a.scene.define)?;
    let mut scene = zerovar::scene::load(&a.scene.scene, &defines)?;
    scene.set_tracker(a.scene.tracker).map_err(|e| anyhow::anyhow!("--{e}"))?;
    let seed = a.seed.unwrap_or(scene.settings().seed);
    let options = RenderOptions {
        budget: validate_budget(&a.budget, scene.settings().spp)?,
        seed,
        threads: a.threads,
        guiding,
        fireflies: 0,
    };
    let bar = progress_bar(!a.quiet && std::io::stderr().is_terminal());
    let (field, report) = zerovar::render::train(&scene, &options, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
        true
    })?;
    bar.finish_and_clear();
    // Written only now and atomically, so a failed or cancelled training leaves no partial
    // file behind.
    write_atomically(&a.output, |tmp| -> Result<()> {
        let file = std::fs::File::create(tmp)?;
        Ok(field.save(std::io::BufWriter::new(file))?)
    })
    .with_context(|| format!("{}: cannot write the field", a.output.display()))?;
    eprintln!(
        "{}: trained {} passes ({} spp) in {:.2} s: {} regions, {} lobes, {} KiB -> {}",
        a.scene.scene.display(),
        report.passes,
        report.spp,
        report.seconds,
        report.field.regions,
        report.field.lobes,
        report.field.memory_bytes / 1024,
        a.output.display()
    );
    Ok(())
}

fn parse_defines(raw: &[String]) -> Result<Vec<(String, String)>> {
    raw.iter()
        .map(|d| match d.split_once('=') {
            Some((k, v)) if !k.trim().is_empty() => {
                Ok((k.trim().to_string(), v.trim().to_string()))
            }
            _ => bail!("-D {d}: expected KEY=VALUE, for example -D spp=64"),
        })
        .collect()
}

fn validate(a: RenderArgs) -> Result<RenderCommand> {
    let defines = parse_defines(&a.scene.define)?;
    if a.spp == Some(0) {
        bail!("--spp 0: give at least one sample per pixel");
    }
    let time = match a.time {
        Some(t) if !(t > 0.0 && t.is_finite() && t < 1e7) => {
            bail!("--time {t}: give a positive number of seconds below 1e7 (about 16 weeks)")
        }
        Some(t) => Some(Duration::from_secs_f64(t)),
        None => None,
    };
    if a.threads == Some(0) {
        bail!("--threads 0: give at least one thread, or leave it out to use every core");
    }
    if !(-64.0..=64.0).contains(&a.exposure) {
        bail!("--exposure {}: give a number of stops from -64 to 64", a.exposure);
    }
    let output = a.output.unwrap_or_else(|| {
        let stem = a.scene.scene.file_stem().unwrap_or_else(|| "render".as_ref());
        PathBuf::from(stem).with_extension("exr")
    });
    if output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref()
        != Some("exr")
    {
        bail!(
            "-o {}: the output must be an .exr file (a .png preview is written beside it)",
            output.display()
        );
    }
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        bail!("-o {}: the directory {} does not exist", output.display(), dir.display());
    }
    let guiding =
        validate_guiding(&a.guiding, a.field.is_some().then_some("rendering with --field"))?;
    if a.field.is_some() && a.guiding.given("parallax").is_some() {
        bail!(
            "--parallax: a saved field keeps the setting it was trained with; give --parallax to `zerovar train`"
        );
    }
    // With a saved field nothing trains: a training setting would be ignored.
    for key in ["train-share", "train-passes", "train-time", "training-images"] {
        if a.field.is_some() && a.guiding.given(key).is_some() {
            bail!(
                "--{key}: rendering with --field trains nothing; leave it out, or give it to `zerovar train`"
            );
        }
    }
    if let Some(f) = &a.field
        && !f.is_file()
    {
        bail!("--field {}: no such file; create one with `zerovar train`", f.display());
    }
    let png = output.with_extension("png");
    let mut inputs = vec![("the scene", a.scene.scene.as_path())];
    inputs.extend(a.field.as_deref().map(|f| ("the field of --field", f)));
    let mut outputs = vec![("-o", output.as_path()), ("the PNG preview of -o", png.as_path())];
    outputs.extend(a.stats.as_deref().map(|s| ("--stats", s)));
    check_outputs(&inputs, &outputs)?;
    Ok(RenderCommand {
        guiding,
        field: a.field,
        scene: a.scene.scene,
        defines,
        png,
        output,
        spp: a.spp,
        time,
        seed: a.seed,
        threads: a.threads,
        stats: a.stats,
        exposure: a.exposure,
        progress: !a.quiet && std::io::stderr().is_terminal(),
        tracker: a.scene.tracker,
        fireflies: a.fireflies,
    })
}

fn run_render(c: RenderCommand) -> Result<()> {
    let mut scene = zerovar::scene::load(&c.scene, &c.defines)?;
    scene.set_tracker(c.tracker).map_err(|e| anyhow::anyhow!("--{e}"))?;
    let budget = match (c.time, c.spp) {
        (Some(t), _) => Budget::Time(t),
        (None, Some(n)) => Budget::Samples(n),
        (None, None) => Budget::Samples(scene.settings().spp),
    };
    let seed = c.seed.unwrap_or(scene.settings().seed);
    let options = RenderOptions {
        budget,
        seed,
        threads: c.threads,
        guiding: c.guiding.clone(),
        fireflies: c.fireflies,
    };
    let bar = progress_bar(c.progress);
    let report = |done, total| {
        bar.set_length(total);
        bar.set_position(done);
        true
    };
    let result = match &c.field {
        Some(path) => {
            let file = std::fs::File::open(path)
                .with_context(|| format!("{}: cannot open the field", path.display()))?;
            let trained = TrainedField::load(std::io::BufReader::new(file))
                .with_context(|| format!("{}: cannot load the field", path.display()))?;
            render_with_field(&scene, &options, &trained, &report)
                .with_context(|| format!("--field {}", path.display()))?
        }
        None => render(&scene, &options, &report)?,
    };
    bar.finish_and_clear();

    let [w, h] = scene.camera().resolution();
    let image = &result.image;
    let meta = ImageMetadata {
        spp: result.spp,
        seconds: result.seconds,
        seed,
        scene: c.scene.display().to_string(),
    };
    write_exr(&c.output, w, h, image, &meta)?;
    write_png(&c.png, w, h, image, c.exposure)?;
    let stats = render_stats(&result, meta.scene.clone(), [w, h], seed);
    if let Some(path) = &c.stats {
        write_stats(path, &stats)?;
    }
    tell(&c, &options, &result, &stats);
    Ok(())
}

/// The `--stats` report of a finished render.
fn render_stats(
    result: &zerovar::render::RenderResult,
    scene: String,
    resolution: [u32; 2],
    seed: u64,
) -> RenderStats {
    let mut stats = RenderStats::from_counters(&result.counters, result.seconds);
    stats.scene = scene;
    stats.spp = result.spp;
    stats.resolution = resolution;
    stats.seed = seed;
    stats.threads = result.threads;
    stats.selection = result.selection.clone();
    stats.fireflies = result.fireflies.clone();
    stats.training = result.training.as_ref().map(|t| TrainingStats {
        passes: t.passes,
        spp: t.spp,
        seconds: t.seconds,
        samples: t.samples,
        regions: t.field.regions,
        lobes: t.field.lobes,
        memory_bytes: t.field.memory_bytes,
        share: t.seconds / (t.seconds + result.seconds).max(1e-9),
        stop: t.stop,
    });
    stats
}

/// What a finished render tells on stderr: training, adaptive guiding's choice, the render
/// and where it went, the firefly table, and dropped samples.
fn tell(
    c: &RenderCommand,
    options: &RenderOptions,
    result: &zerovar::render::RenderResult,
    stats: &RenderStats,
) {
    let name = c.scene.display();
    if let Some(t) = &stats.training {
        eprintln!(
            "{name}: trained {} passes ({} spp) in {:.2} s, {:.0}% of the render ({}): {} regions, {} lobes",
            t.passes,
            t.spp,
            t.seconds,
            100.0 * t.share,
            t.stop.describe(),
            t.regions,
            t.lobes
        );
    }
    if let Some(sel) = &result.selection {
        if sel.stopped_training {
            eprintln!(
                "{name}: adaptive guiding found no tile worth guiding after {} training passes \
                 (validated gain {:.2}): rendered unguided",
                result.training.as_ref().map_or(0, |t| t.passes),
                sel.validated_gain
            );
        } else if sel.decided_early {
            let [a, b] = sel.one_way_gains;
            eprintln!(
                "{name}: adaptive guiding guided every tile with {} (decided after 2 training \
                 passes: each half of its pilot, judged by the other, gains {a:.2} and {b:.2})",
                sel.components
            );
        } else if sel.guided_tiles > 0 && sel.validated_gain <= 1.0 {
            eprintln!(
                "{name}: adaptive guiding guided every tile with {} (no choice of tiles gained \
                 on both halves of the pilot, validated gain {:.2}; guiding every tile gains \
                 {:.2} on all its samples)",
                sel.components, sel.validated_gain, sel.everywhere_gain
            );
        } else {
            eprintln!(
                "{name}: adaptive guiding guided {} of {} tiles with {} (validated gain {:.2})",
                sel.guided_tiles, sel.tiles, sel.components, sel.validated_gain
            );
        }
    }
    eprintln!(
        "{name}: {} spp in {:.2} s ({:.0} paths/s) -> {} and {}",
        result.spp,
        result.seconds,
        stats.paths_per_second,
        c.output.display(),
        c.png.display()
    );
    if options.guiding.adaptive && result.training.is_none() && c.field.is_none() {
        // (Only with training sharing the budget: see `MIN_ADAPTIVE_SPP`.)
        eprintln!(
            "{name}: adaptive guiding: {} spp are too few to train a field and choose where it pays ({} or more); rendered unguided",
            result.spp,
            zerovar::render::MIN_ADAPTIVE_SPP
        );
    }
    if let Some(f) = &result.fireflies {
        eprint!("{name}: {}", f.summary());
    }
    if stats.invalid_samples > 0 {
        eprintln!("warning: {} NaN or infinite samples were dropped", stats.invalid_samples);
    }
}

fn write_stats(path: &Path, stats: &RenderStats) -> Result<()> {
    let json = serde_json::to_string_pretty(stats)? + "\n";
    write_atomically(path, |tmp| Ok(std::fs::write(tmp, &json)?))
        .with_context(|| format!("{}: cannot write statistics", path.display()))
}

/// Writes `path` atomically through `write` (see `zerovar::files::write_atomically`).
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    zerovar::files::write_atomically(path, write, anyhow::Error::from)
}

fn progress_bar(visible: bool) -> ProgressBar {
    if !visible {
        return ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
    }
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent}% (ETA {eta})",
        )
        .expect("the template is valid"),
    );
    bar
}
