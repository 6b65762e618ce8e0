//! The render session: samples the image over 16x16 tiles in parallel (rayon) until a sample
//! or time budget is spent.
//!
//! Each pixel sample draws from its own stream keyed by (seed, pixel, sample index), and each
//! pixel's samples are summed in index order, so an image depends on the seed and the sample
//! count only, never on the thread count or the tile schedule.

use crate::film::{Film, PixelSum};
use crate::integrators::VolPath;
use crate::math::is_finite;
use crate::rng::Sampler;
use crate::scene::Scene;
use crate::stats::Counters;
use glam::Vec2;
use rayon::prelude::*;
use std::time::{Duration, Instant};

const TILE: u32 = 16;

/// How much to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// Exactly this many samples per pixel.
    Samples(u32),
    /// As many samples per pixel as fit in this time (at least one).
    Time(Duration),
}

/// Validated settings of one render.
#[derive(Clone, Copy, Debug)]
pub struct RenderOptions {
    /// The budget.
    pub budget: Budget,
    /// Seed of the random streams.
    pub seed: u64,
    /// Worker threads (`None`: all cores).
    pub threads: Option<usize>,
}

/// A finished render.
#[derive(Clone, Debug)]
pub struct RenderResult {
    /// The accumulated image.
    pub film: Film,
    /// Samples per pixel rendered.
    pub spp: u32,
    /// Seconds spent sampling.
    pub seconds: f64,
    /// Event counters.
    pub counters: Counters,
    /// Threads used.
    pub threads: usize,
}

/// Why a render could not start.
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
}

/// Renders `scene`. `progress(done, total)` is called as work completes (in samples for a
/// sample budget, in milliseconds for a time budget).
pub fn render(
    scene: &Scene,
    options: &RenderOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<RenderResult, RenderError> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(t) = options.threads {
        builder = builder.num_threads(t);
    }
    let pool = builder.build().map_err(|e| RenderError::Threads {
        threads: options.threads.unwrap_or(0),
        message: e.to_string(),
    })?;
    let threads = pool.current_num_threads();
    Ok(pool.install(|| render_in_pool(scene, options, progress, threads)))
}

fn render_in_pool(
    scene: &Scene,
    options: &RenderOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
    threads: usize,
) -> RenderResult {
    let [w, h] = scene.camera.resolution;
    let mut film = Film::new(w, h);
    let mut counters = Counters::default();
    let start = Instant::now();
    let mut done = 0u32;
    match options.budget {
        Budget::Samples(spp) => {
            let total = spp as u64 * w as u64 * h as u64;
            let finished = std::sync::atomic::AtomicU64::new(0);
            counters += render_pass(scene, options.seed, 0, spp, &mut film, &|n| {
                let d = finished.fetch_add(n, std::sync::atomic::Ordering::Relaxed) + n;
                progress(d, total);
            });
            done = spp;
        }
        Budget::Time(limit) => {
            let total = limit.as_millis() as u64;
            let mut batch = 1u32;
            loop {
                let pass_start = Instant::now();
                counters += render_pass(scene, options.seed, done, batch, &mut film, &|_| {});
                done += batch;
                let elapsed = start.elapsed();
                progress((elapsed.as_millis() as u64).min(total), total);
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
    RenderResult { film, spp: done, seconds: start.elapsed().as_secs_f64(), counters, threads }
}

/// Adds samples `first .. first + count` of every pixel to `film`.
fn render_pass(
    scene: &Scene,
    seed: u64,
    first: u32,
    count: u32,
    film: &mut Film,
    on_tile: &(dyn Fn(u64) + Sync),
) -> Counters {
    let [w, h] = scene.camera.resolution;
    let tiles: Vec<(u32, u32)> = (0..h.div_ceil(TILE))
        .flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx, ty)))
        .collect();
    let integrator = VolPath::from_scene(scene);
    let results: Vec<(Vec<PixelSum>, Counters)> = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let mut counters = Counters::default();
            let (x0, y0) = (tx * TILE, ty * TILE);
            let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
            let mut sums = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
            for y in y0..y1 {
                for x in x0..x1 {
                    let pixel = (y as u64) * w as u64 + x as u64;
                    let mut sum = PixelSum::default();
                    for s in first..first + count {
                        let mut sampler = Sampler::new(seed, pixel, s as u64);
                        let jitter = sampler.next_2d();
                        let ray = scene.camera.ray(Vec2::new(x as f32, y as f32) + jitter);
                        let l = integrator.radiance(
                            scene,
                            ray,
                            scene.camera_medium,
                            &mut sampler,
                            &mut counters,
                        );
                        if is_finite(l) {
                            sum.add(l);
                        } else {
                            counters.invalid_samples += 1;
                            sum.add(crate::math::Spectrum::ZERO);
                        }
                    }
                    sums.push(sum);
                }
            }
            on_tile(sums.len() as u64 * count as u64);
            (sums, counters)
        })
        .collect();
    let mut counters = Counters::default();
    for (&(tx, ty), (sums, c)) in tiles.iter().zip(results) {
        counters += c;
        let (x0, y0) = (tx * TILE, ty * TILE);
        let tw = (x0 + TILE).min(w) - x0;
        for (i, s) in sums.iter().enumerate() {
            let (x, y) = (x0 + i as u32 % tw, y0 + i as u32 / tw);
            film.pixels[(y * w + x) as usize].merge(s);
        }
    }
    counters
}
