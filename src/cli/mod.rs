//! Command-line arguments (clap), their validation into a `Command`, and running it.

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Duration;
use zerovar::output::{ImageMetadata, write_exr, write_png};
use zerovar::render::{Budget, RenderOptions, render};
use zerovar::stats::RenderStats;

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
}

#[derive(Args)]
struct SceneArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// Override a value of the scene's [defaults] table (repeatable).
    #[arg(short = 'D', value_name = "KEY=VALUE")]
    define: Vec<String>,
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
}

pub(crate) fn run() -> Result<()> {
    match Cli::parse().command {
        CommandArgs::Check(a) => {
            let defines = parse_defines(&a.scene.define)?;
            let scene = zerovar::scene::load(&a.scene.scene, &defines)?;
            print!("{}", scene.describe());
            Ok(())
        }
        CommandArgs::Render(a) => run_render(validate(a)?),
    }
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
    Ok(RenderCommand {
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
    })
}

fn run_render(c: RenderCommand) -> Result<()> {
    let scene = zerovar::scene::load(&c.scene, &c.defines)?;
    let budget = match (c.time, c.spp) {
        (Some(t), _) => Budget::Time(t),
        (None, Some(n)) => Budget::Samples(n),
        (None, None) => Budget::Samples(scene.settings.spp),
    };
    let seed = c.seed.unwrap_or(scene.settings.seed);
    let options = RenderOptions { budget, seed, threads: c.threads };
    let bar = progress_bar(c.progress);
    let result = render(&scene, &options, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })?;
    bar.finish_and_clear();

    let [w, h] = scene.camera.resolution;
    let image = result.film.image();
    let meta = ImageMetadata {
        spp: result.spp,
        seconds: result.seconds,
        seed,
        scene: c.scene.display().to_string(),
    };
    write_exr(&c.output, w, h, &image, &meta)?;
    write_png(&c.png, w, h, &image, c.exposure)?;
    let mut stats = RenderStats::from_counters(&result.counters, result.seconds);
    stats.scene = meta.scene.clone();
    stats.spp = result.spp;
    stats.resolution = [w, h];
    stats.seed = seed;
    stats.threads = result.threads;
    if let Some(path) = &c.stats {
        write_stats(path, &stats)?;
    }
    eprintln!(
        "{}: {} spp in {:.2} s ({:.0} paths/s) -> {} and {}",
        c.scene.display(),
        result.spp,
        result.seconds,
        stats.paths_per_second,
        c.output.display(),
        c.png.display()
    );
    if stats.invalid_samples > 0 {
        eprintln!("warning: {} NaN or infinite samples were dropped", stats.invalid_samples);
    }
    Ok(())
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
