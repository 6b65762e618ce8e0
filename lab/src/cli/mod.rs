//! Command-line arguments (clap), their validation into a `Command`, and running it.

mod crop;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use crop::{crops, noisiest_window, parse_crop};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Duration;
use zerovar::guided::TrainedField;
use zerovar::output::{ImageMetadata, write_exr, write_png};
use zerovar::render::{
    Budget, GuidingOptions, RenderOptions, TrainBudget, render, render_with_field,
};
use zerovar::render::{DEFAULT_TRAIN_SHARE, MAX_TRAIN_PASSES, parse_guiding};
use zerovar::render::{RenderStats, TrainingStats};

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
    /// A method: NAME=key:value,... with keys guiding, alpha, surface-alpha, distance-alpha,
    /// train-share, train-passes, train-time, tracker, combine, parallax (repeatable)
    /// [default: unguided, guided=guiding:full and auto=guiding:auto].
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

#[derive(Args)]
struct GuidingArgs {
    /// Guided decisions: off, directions, distances, rr, full, or a +-joined list
    /// (e.g. directions+rr); auto is full guiding (or roulette alone, where that pays
    /// better) in the tiles where a pilot finds it pays, and unguided sampling elsewhere
    /// [default: auto; full for `train` and with --field].
    #[arg(long, value_name = "MODE")]
    guiding: Option<String>,
    /// Probability of the guided strategy in each mixture with standard sampling in media, in
    /// [0, 1] (used up to 0.8: standard sampling always keeps 20%, which bounds every weight).
    #[arg(long, default_value_t = 0.5)]
    alpha: f32,
    /// The same at surfaces, in [0, 1] (used up to 0.8).
    #[arg(long, default_value_t = zerovar::render::DEFAULT_SURFACE_ALPHA)]
    surface_alpha: f32,
    /// Probability of the zero-variance collision density in guided flights' mixture with
    /// standard tracking, in [0, 1] (used up to 0.8). Guided flights take extra collisions for
    /// delta lights whatever it is; the default 0 spares each flight a field lookup, which at
    /// equal time paid better on every bench scene.
    #[arg(long, default_value_t = zerovar::render::DEFAULT_DISTANCE_ALPHA)]
    distance_alpha: f32,
    /// Share of the budget (--time or --spp) that training takes, in (0, 1): doubling passes
    /// of 1, 2, 4, ... samples per pixel while the next fits in it; the render gets the rest
    /// [default: 0.25].
    #[arg(long, allow_negative_numbers = true, conflicts_with_all = ["train_passes", "train_time"])]
    train_share: Option<f64>,
    /// Train this many passes instead (with --spp, the render then renders all of it).
    #[arg(long, conflicts_with = "train_time")]
    train_passes: Option<u32>,
    /// Train for this many seconds instead (doubling passes; --time still includes them).
    #[arg(long, allow_negative_numbers = true)]
    train_time: Option<f64>,
    /// Parallax-aware lobes: each learns how far its light comes from and is re-aimed at it
    /// from every point of its region (on), or fixed directions per region (off, for
    /// comparison) [default: on].
    #[arg(long, value_enum, value_name = "ON|OFF")]
    parallax: Option<Switch>,
}

/// A setting that is on or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Switch {
    /// On.
    On,
    /// Off.
    Off,
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
    guiding: GuidingArgs,
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
    /// Free-flight tracker: auto (per medium: closed form if homogeneous, decomposition for
    /// grids, spectral only if chromatic) or one for every medium: analytic, analytic-spectral,
    /// regular, delta, weighted-delta, decomposition, weighted-decomposition, spectral,
    /// spectral-max, spectral-average, spectral-decomposition, ray-marching-biased (BIASED).
    #[arg(long, default_value = "auto", value_name = "TRACKER")]
    tracker: zerovar::tracking::TrackerChoice,
}

#[derive(Args)]
struct CheckArgs {
    #[command(flatten)]
    scene: SceneArgs,
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
    guiding: GuidingArgs,
    /// Render guided by a field saved by `zerovar train` (no training phase).
    #[arg(long, value_name = "FIELD")]
    field: Option<PathBuf>,
    /// Find the N samples that hold most of the image's error and trace their paths: a
    /// table on stderr, and every decision of each path in --stats.
    #[arg(long, value_name = "N", default_value_t = 0)]
    fireflies: usize,
    /// What becomes of the training passes' images: combine (averaged into the result by
    /// inverse variance) or discard.
    #[arg(long, value_enum, default_value_t = TrainingImages::Combine, value_name = "WHAT")]
    training_images: TrainingImages,
}

/// What `render` does with the training passes' images.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum TrainingImages {
    /// Average them into the result, one weight per image by its inverse relative variance.
    Combine,
    /// Drop them: the result is the render phase's samples alone.
    Discard,
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
            scene.set_tracker(a.scene.tracker)?;
            print!("{}", scene.describe());
            Ok(())
        }
        CommandArgs::Render(a) => run_render(validate(a)?),
        CommandArgs::Train(a) => run_train(a),
        CommandArgs::Reference(a) => run_reference(a),
        CommandArgs::Compare(a) => run_compare(a),
    }
}

fn validate_budget(b: &BudgetArgs, default_spp: u32) -> Result<Budget> {
    match (b.spp, b.time) {
        (Some(0), _) => bail!("--spp 0: give at least one sample per pixel"),
        (Some(n), _) => Ok(Budget::Samples(n)),
        (None, Some(t)) if !(t > 0.0 && t.is_finite() && t < 1e7) => {
            bail!("--time {t}: give a positive number of seconds")
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
    let defines = parse_defines(&a.scene.define)?;
    let mut scene = zerovar::scene::load(&a.scene.scene, &defines)?;
    scene.set_tracker(a.scene.tracker)?;
    let budget = validate_budget(&a.budget, scene.settings().spp * 16)?;
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
    let (rw, rh, reference, reference_error) = zerovar::output::read_exr_with_error(&a.reference)?;
    let [w, h] = scene.camera().resolution();
    if (rw, rh) != (w as usize, h as usize) {
        bail!(
            "--reference {}: it is {rw}x{rh} but the scene renders {w}x{h}",
            a.reference.display()
        );
    }
    let crop = a.crop.as_deref().map(|c| parse_crop(c, w as usize, h as usize)).transpose()?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create the output directory", a.out.display()))?;
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
        std::fs::write(&path, text).with_context(|| format!("{}: cannot write", path.display()))
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
fn validate_guiding(a: &GuidingArgs, field_use: Option<&str>) -> Result<GuidingOptions> {
    let text = a.guiding.as_deref().unwrap_or(if field_use.is_some() { "full" } else { "auto" });
    let Some((components, adaptive)) = parse_guiding(text) else {
        bail!(
            "--guiding {text}: use off, directions, distances, rr, full, auto, or a +-joined list"
        );
    };
    if let Some(what) = field_use
        && !components.any()
    {
        bail!(
            "--guiding {text}: {what} needs something guided; give full (the default there), directions, distances, rr or a +-joined list"
        );
    }
    if !(0.0..=1.0).contains(&a.alpha) {
        bail!("--alpha {}: give a probability in [0, 1]", a.alpha);
    }
    if !(0.0..=1.0).contains(&a.surface_alpha) {
        bail!("--surface-alpha {}: give a probability in [0, 1]", a.surface_alpha);
    }
    if !(0.0..=1.0).contains(&a.distance_alpha) {
        bail!("--distance-alpha {}: give a probability in [0, 1]", a.distance_alpha);
    }
    let train = match (a.train_time, a.train_passes, a.train_share) {
        (Some(t), _, _) if !(t > 0.0 && t.is_finite() && t < 1e7) => {
            bail!("--train-time {t}: give a positive number of seconds")
        }
        (Some(t), _, _) => TrainBudget::Time(Duration::from_secs_f64(t)),
        (None, Some(n), _) if n == 0 || n > MAX_TRAIN_PASSES => {
            bail!("--train-passes {n}: give 1 to 20 passes (pass k renders 2^k spp)")
        }
        (None, Some(n), _) => TrainBudget::Passes(n),
        (None, None, Some(f)) if !(f > 0.0 && f < 1.0) => {
            bail!("--train-share {f}: give a fraction of the budget above 0 and below 1")
        }
        (None, None, Some(f)) => TrainBudget::Share(f as f32),
        (None, None, None) => TrainBudget::Share(DEFAULT_TRAIN_SHARE),
    };
    let mut field = GuidingOptions::default().field;
    if let Some(p) = a.parallax {
        field.parallax = p == Switch::On;
    }
    Ok(GuidingOptions {
        components,
        alpha: a.alpha,
        surface_alpha: a.surface_alpha,
        distance_alpha: a.distance_alpha,
        train,
        adaptive,
        field,
        ..GuidingOptions::default()
    })
}

fn run_train(a: TrainArgs) -> Result<()> {
    let guiding = validate_guiding(&a.guiding, Some("training a field"))?;
    if a.threads == Some(0) {
        bail!("--threads 0: give at least one thread, or leave it out to use every core");
    }
    let defines = parse_defines(&a.scene.define)?;
    let mut scene = zerovar::scene::load(&a.scene.scene, &defines)?;
    scene.set_tracker(a.scene.tracker)?;
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
    // Created only now, so a failed or cancelled training leaves no empty file behind.
    let file = std::fs::File::create(&a.output)
        .with_context(|| format!("{}: cannot create the field file", a.output.display()))?;
    field
        .save(std::io::BufWriter::new(file))
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
            bail!("--time {t}: give a positive number of seconds")
        }
        Some(t) => Some(Duration::from_secs_f64(t)),
        None => None,
    };
    if a.threads == Some(0) {
        bail!("--threads 0: give at least one thread, or leave it out to use every core");
    }
    if !a.exposure.is_finite() {
        bail!("--exposure {}: give a finite number of stops", a.exposure);
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
    if a.field.is_some() && a.guiding.parallax.is_some() {
        bail!(
            "--parallax: a saved field keeps the setting it was trained with; give --parallax to `zerovar train`"
        );
    }
    let combine_training = a.training_images == TrainingImages::Combine;
    let guiding = GuidingOptions { combine_training, ..guiding };
    if let Some(f) = &a.field
        && !f.is_file()
    {
        bail!("--field {}: no such file; create one with `zerovar train`", f.display());
    }
    Ok(RenderCommand {
        guiding,
        field: a.field,
        scene: a.scene.scene,
        defines,
        png: output.with_extension("png"),
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
    scene.set_tracker(c.tracker)?;
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
            render_with_field(&scene, &options, &trained, &report)?
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
                 (modelled gain {:.2}): rendered unguided",
                result.training.as_ref().map_or(0, |t| t.passes),
                sel.gain
            );
        } else if sel.decided_early {
            eprintln!(
                "{name}: adaptive guiding guided every tile with {} (decided after 2 training passes: modelled gain {:.2})",
                sel.components, sel.gain
            );
        } else {
            eprintln!(
                "{name}: adaptive guiding guided {} of {} tiles with {} (modelled gain {:.2})",
                sel.guided_tiles, sel.tiles, sel.components, sel.gain
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
    let json = serde_json::to_string_pretty(stats)?;
    std::fs::write(path, json + "\n")
        .with_context(|| format!("{}: cannot write statistics", path.display()))
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
