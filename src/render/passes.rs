//! Render passes: every pixel's samples `first .. first + count` over 16x16 tiles in parallel
//! (rayon), each tile walked with its own radiance cache, each sample from its own stream
//! keyed by (seed, pixel, sample index), so a pass depends on its seed alone.

use super::Monitor;
use crate::film::{Film, PixelSum};
use crate::guided::{Components, DirectFluence, FieldCache, NoCache, RadianceCache};
use crate::integrators::walk::{self, WalkContext, WalkSettings};
use crate::math::{Spectrum, is_finite, luminance};
use crate::rng::Sampler;
use crate::scene::Scene;
use crate::stats::Counters;
use rayon::prelude::*;
use zerovar_guiding::{Field, PathRecorder, Sample};

pub(super) const TILE: u32 = 16;

/// One pass over the image: which samples, drawn how.
#[derive(Clone, Copy)]
pub(super) struct Pass<'a> {
    pub(super) settings: &'a WalkSettings,
    pub(super) seed: u64,
    /// Sample indices `first .. first + count` of every pixel.
    pub(super) first: u32,
    pub(super) count: u32,
    pub(super) field: Option<(&'a Field, Option<&'a DirectFluence>)>,
    /// Per-pixel estimates for weight windows (`window::floor` is added when rendering).
    pub(super) estimate: Option<&'a [f32]>,
    /// Samples per pixel, the pass's first, whose paths are recorded as training samples;
    /// 0 records none.
    pub(super) record: u32,
    /// Per tile, whether it is guided; `None` guides every tile as `settings` say.
    pub(super) guided_tiles: Option<&'a [bool]>,
    /// Keep each pixel's largest sample (for the firefly diagnostic).
    pub(super) largest: bool,
}

/// What a pass returns.
#[derive(Default)]
pub(super) struct PassOutput {
    pub(super) counters: Counters,
    /// Counters of each tile, in tile order.
    pub(super) tile_counters: Vec<Counters>,
    /// Training samples in tile order (when recording).
    pub(super) samples: Vec<Sample>,
    /// Direct-fluence records in tile order (when recording).
    pub(super) records: Vec<crate::guided::DirectRecord>,
    /// Per pixel, its largest sample (when the pass looks for them).
    pub(super) largest: Vec<Largest>,
}

/// A pixel's largest sample so far, by luminance.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Largest {
    pub(super) value: Spectrum,
    /// Its sample index (`None` before any sample).
    pub(super) index: Option<u32>,
}

impl Largest {
    #[inline]
    pub(super) fn offer(&mut self, l: Spectrum, index: u32) {
        if self.index.is_none() || luminance(l) > luminance(self.value) {
            *self = Largest { value: l, index: Some(index) };
        }
    }

    pub(super) fn merge(&mut self, o: &Largest) {
        if let Some(i) = o.index {
            self.offer(o.value, i);
        }
    }
}

/// The tiles of a `w x h` image in row-major order.
pub(super) fn tiles(w: u32, h: u32) -> Vec<(u32, u32)> {
    (0..h.div_ceil(TILE)).flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx, ty))).collect()
}

/// Adds the pass's samples of every pixel to `film`. Returns `None`, leaving `film` untouched,
/// when `monitor` was told to stop during the pass.
pub(super) fn render_pass(
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
            if !film.odd.is_empty() {
                film.odd[p].merge(&tile.odd[i]);
            }
            if let Some(l) = tile.largest.get(i) {
                out.largest[p].merge(l);
            }
        }
    }
    Some(out)
}

/// Work on one tile that runs the walk with some radiance cache (a closure generic over the
/// cache, so that each cache gets its own monomorphised walk).
pub(super) trait TileWork {
    type Output;
    fn run<C: RadianceCache>(self, settings: &WalkSettings, cache: &mut C) -> Self::Output;
}

/// Runs `work` with the walk settings and the radiance cache of tile `index` in `pass`: the
/// field's, or none where the pass has no field or the tile is not guided. Also returns the
/// direct-fluence records the cache gathered (when the pass records).
pub(super) fn with_tile_walk<W: TileWork>(
    pass: &Pass<'_>,
    index: usize,
    work: W,
) -> (W::Output, Vec<crate::guided::DirectRecord>) {
    let guided = pass.guided_tiles.is_none_or(|g| g[index]);
    match pass.field {
        Some((f, direct)) if guided => {
            let mut cache = FieldCache::with_direct(f, direct, pass.record > 0);
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
pub(super) struct RenderTile<'a, 'p> {
    pub(super) scene: &'a Scene,
    pub(super) pass: Pass<'p>,
    pub(super) tile: (u32, u32),
    /// Added to the pixel estimates for weight windows (`window::floor`).
    pub(super) floor: f32,
}

/// What one tile of a pass returns.
#[derive(Default)]
pub(super) struct TileOutput {
    /// Per pixel of the tile, row by row.
    pub(super) sums: Vec<PixelSum>,
    /// The same, of the odd-numbered samples alone.
    pub(super) odd: Vec<PixelSum>,
    pub(super) counters: Counters,
    /// Training samples (when recording).
    pub(super) samples: Vec<Sample>,
    /// Direct-fluence records (when recording).
    pub(super) records: Vec<crate::guided::DirectRecord>,
    /// Per pixel, its largest sample (when the pass looks for fireflies).
    pub(super) largest: Vec<Largest>,
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
        out.odd.reserve(((x1 - x0) * (y1 - y0)) as usize);
        for y in y0..y1 {
            for x in x0..x1 {
                let (mut sum, mut odd) = (PixelSum::default(), PixelSum::default());
                let mut largest = Largest::default();
                for s in pass.first..pass.first + pass.count {
                    let record = s - pass.first < pass.record;
                    let mut ctx = WalkContext {
                        cache: &mut *cache,
                        pixel: pass.estimate.map(|e| e[(y * w + x) as usize] + floor),
                        recorder: if record { Some(&mut recorder) } else { None },
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
                    let finite = is_finite(l);
                    if finite {
                        largest.offer(l, s);
                        if record {
                            recorder.finish(&mut out.samples);
                        }
                    } else {
                        out.counters.invalid_samples += 1;
                        recorder.clear();
                    }
                    let l = if finite { l } else { Spectrum::ZERO };
                    sum.add(l);
                    if s % 2 == 1 {
                        odd.add(l);
                    }
                }
                out.sums.push(sum);
                out.odd.push(odd);
                if pass.largest {
                    out.largest.push(largest);
                }
            }
        }
        out
    }
}

/// Sample `s` of pixel `[x, y]` from the streams of `seed`: the radiance its walks bring back.
pub(super) fn camera_sample<C: RadianceCache>(
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
    let camera = &scene.camera;
    let (film, weight) = camera.film_sample([x, y], &mut sampler);
    let start = walk::PathStart::camera(scene, film, &mut sampler);
    walk::radiance(settings, scene, start, ctx, &mut sampler, counters) * weight
}

/// Merges a pass's largest samples into `largest` and, for the firefly diagnostic's replays,
/// keeps the windows' estimate the pass starting at sample `first` used when it is the
/// render's own (`own_estimate`), which changes from pass to pass.
pub(super) fn keep_largest(
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
