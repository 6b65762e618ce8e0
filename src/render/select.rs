//! Guiding only where it pays (`--guiding auto`). After training, a short pilot renders every
//! 16x16 tile unguided and with each candidate (the requested components and, beside more,
//! roulette alone), each from streams of its own; each candidate's best choice of tiles is
//! the one with the highest efficiency `1 / (relative variance x cost)` of the image, and the
//! candidate whose choice gains most out of sample (judged on samples it was not made from)
//! wins. Where no choice gains out of sample, every tile is guided with the requested
//! components if that gains on all the pilot's samples, and none otherwise.
//!
//! Cost is the pilot's counted work (`Counters`) weighted by per-operation costs, not wall
//! time, so the choice, and with it the image, depends on the seed alone, whatever the thread
//! count or the machine's load. The pilot's samples are not used in the image: the choice is
//! independent of the samples a pixel averages, so each pixel stays an unbiased estimate
//! whichever strategy its tile got.

use super::{
    Budget, Guidance, Monitor, Pass, RenderOptions, TILE, pixel_estimates, render_pass, tiles,
    walk_settings,
};
use crate::film::Film;
use crate::guided::Components;
use crate::integrators::walk::WalkSettings;
use crate::math::RELATIVE_EPSILON as EPSILON;
use crate::rng::mix64;
use crate::scene::Scene;
use crate::stats::Counters;
use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Nanoseconds of one thread per counted operation: a non-negative least-squares fit (relative
/// error) to single-thread render times of the ten example and bench scenes, each unguided,
/// fully guided and with each component alone (`tools/fit-cost-model.py`). It predicts a
/// guided sample's cost relative to an unguided one closely enough to choose by (see
/// docs/experiments.md).
const NS_PER_PATH: f64 = 35.0;
const NS_PER_SEGMENT: f64 = 96.0;
const NS_PER_SCATTER: f64 = 61.0;
const NS_PER_DENSITY_LOOKUP: f64 = 114.0;
const NS_PER_GUIDED_DENSITY_LOOKUP: f64 = 83.0;
const NS_PER_FIELD_LOOKUP: f64 = 161.0;
const NS_PER_PRODUCT: f64 = 288.0;
/// The fitted cost of the reweighted product, which the one-lobe product replaced at the same
/// criterion cost (docs/experiments.md).
const NS_PER_LOBE_PRODUCT: f64 = 191.0;
/// Extra collisions for delta lights, with the flights whose parts were weighed but drew none.
const NS_PER_EXTRA_COLLISION: f64 = 433.0;

/// What the pilot of adaptive guiding decided.
#[derive(Clone, Debug, Serialize)]
pub struct Selection {
    /// Tiles of the image.
    pub tiles: usize,
    /// Tiles rendered guided.
    pub guided_tiles: usize,
    /// What the guided tiles guide (`full`, or `rr` where roulette alone pays better).
    pub components: String,
    /// Each candidate's components and the validated gain of its best choice of tiles.
    pub candidates: Vec<(String, f64)>,
    /// Samples per pixel of each pilot (guided and unguided).
    pub pilot_spp: u32,
    /// Seconds the pilot took.
    pub seconds: f64,
    /// Modelled cost of a guided sample over an unguided one, over the whole image (with the
    /// chosen components).
    pub cost_ratio: f64,
    /// Relative variance of a guided sample over an unguided one, over the whole image.
    pub variance_ratio: f64,
    /// Modelled efficiency of the image with the chosen tiles guided over the image all
    /// unguided (relative variance times cost, inverted).
    pub gain: f64,
    /// Modelled gain of guiding every tile with the chosen components (the choice guides
    /// every tile unless leaving some out gains `PARTIAL_MARGIN` times more).
    pub everywhere_gain: f64,
    /// The gain out of sample: each half of the pilot's samples chooses tiles, the other half
    /// judges the choice (the geometric mean of both ways). Unlike `gain`, the noise a choice
    /// was made from does not inflate it; it decides, and where no candidate's is above 1, every
    /// tile is guided with the requested components if `everywhere_gain` is, and none if not.
    pub validated_gain: f64,
    /// The two ways `validated_gain` is the geometric mean of: the choice made on the first
    /// half of the pilot's samples judged on the second, and the other way round.
    pub one_way_gains: [f64; 2],
    /// The share of the unguided pilot's relative variance held by its 1% of pixels with the
    /// most: a few percent for light tails, most of it where rare bright paths make the error.
    pub unguided_tail_share: f64,
    /// Whether this pilot ran early in training and found too little `gain` to go on: the
    /// rest of the training budget was rendered unguided.
    pub stopped_training: bool,
    /// The early pilot's selection, when adaptive guiding looked early and went on training.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub early: Option<Box<Selection>>,
    /// Whether this is the early look's choice, decisive enough that no pilot followed
    /// training (every tile guided).
    pub decided_early: bool,
}

/// The modelled cost of the work `c` counts, in nanoseconds of one thread.
pub(crate) fn cost(c: &Counters) -> f64 {
    NS_PER_PATH * c.paths as f64
        + NS_PER_SEGMENT * c.segments as f64
        + NS_PER_SCATTER * (c.medium_scatters + c.surface_scatters) as f64
        + NS_PER_DENSITY_LOOKUP * (c.density_lookups - c.guided_density_lookups) as f64
        + NS_PER_GUIDED_DENSITY_LOOKUP * c.guided_density_lookups as f64
        + NS_PER_FIELD_LOOKUP * c.field_lookups as f64
        + NS_PER_PRODUCT * c.products as f64
        + NS_PER_LOBE_PRODUCT * c.lobe_products as f64
        + NS_PER_EXTRA_COLLISION * c.extra_collisions as f64
}

/// The guided strategies a pilot weighs against unguided sampling: the requested components,
/// and weight-window roulette alone when they include it with more. Roulette alone costs a
/// field lookup per vertex where guided distances and product directions cost several, and
/// in dense, bright media it gives most of their gain (see docs/experiments.md).
fn candidates(requested: Components) -> Vec<Components> {
    let mut list = vec![requested];
    if requested.roulette && (requested.directions || requested.distances) {
        list.push(Components::ROULETTE);
    }
    list
}

/// What the pilot chose: per tile whether it is guided, the guided components, and the report.
pub(super) struct Choice {
    /// Per tile, whether it is guided.
    pub tiles: Vec<bool>,
    /// What guided tiles guide.
    pub components: Components,
    /// The report.
    pub selection: Selection,
}

/// The share of the unguided pilot's relative variance held by its 1% of pixels with the most
/// (`Selection::unguided_tail_share`) from which the pilot is heavy-tailed: a few rare bright
/// paths make the error, which a pilot of a few spp mostly misses, so its gains scatter by
/// orders of magnitude from seed to seed. Light-tailed images hold a few percent there, their
/// pixels' own sampling noise, so the limit sits far from both kinds (see docs/experiments.md).
/// A heavy-tailed pilot neither stops training early nor ranks roulette alone against the
/// requested components.
pub const TAIL_LIMIT: f64 = 0.45;

/// The fewest samples per pixel of the pilot that chooses the tiles to render guided: with
/// fewer, its variance estimates are so noisy that the choice follows their noise, most of
/// all where samples are heavy-tailed (see docs/experiments.md).
pub(super) const MIN_TILE_PILOT_SPP: u32 = 8;

/// Runs the pilot with `guidance`'s field; returns which tiles to guide and how, or `None`
/// when the render was cancelled. `last_pass` is the spp of the last training pass, which
/// sizes it: a quarter of it, from `min_spp` (4, the fewest that give each half of the
/// samples a variance, for the early look that only decides whether training goes on;
/// [`MIN_TILE_PILOT_SPP`] for the choice of tiles) to 16.
pub(super) fn pilot(
    scene: &Scene,
    options: &RenderOptions,
    guidance: &Guidance<'_>,
    last_pass: u32,
    min_spp: u32,
    monitor: &Monitor<'_>,
) -> Option<Choice> {
    let start = Instant::now();
    let [w, h] = scene.camera.resolution();
    // Never more than a quarter of a sample budget (nor fewer than 2).
    let mut count = (last_pass / 4).clamp(min_spp.max(4), 16);
    if let Budget::Samples(spp) = options.budget {
        count = count.min((spp / 4).max(4));
    }
    let settings = walk_settings(scene, options);
    let strategies = candidates(settings.guide);
    let total = (1 + strategies.len() as u64) * u64::from(count) * u64::from(w) * u64::from(h);
    let done = AtomicU64::new(0);
    let report = |n: u64| monitor.report(done.fetch_add(n, Ordering::Relaxed) + n, total);
    // Strategy 0 is unguided sampling, k > 0 candidate k - 1. Each renders its samples in two
    // halves: a choice of tiles made on one half is judged on the other.
    let half = count / 2;
    let run = |k: usize, guide: Components, part: u32| {
        let settings = WalkSettings { guide, ..settings };
        let mut film = Film::new(w, h);
        let pass = Pass {
            settings: &settings,
            // Streams of their own, independent of training's and the image's.
            seed: mix64(options.seed ^ (0x7069_6C6F_7400 + k as u64)),
            first: part * half,
            count: if part == 0 { half } else { count - half },
            field: (k > 0).then_some((guidance.field, guidance.direct)),
            estimate: guidance.estimate.as_deref(),
            record: 0,
            guided_tiles: None,
            largest: false,
        };
        render_pass(scene, pass, &mut film, monitor, &report).map(|o| (film, o.tile_counters))
    };
    let halves = |k: usize, guide: Components| Some([run(k, guide, 0)?, run(k, guide, 1)?]);
    let unguided = halves(0, Components::OFF)?;
    let mut guided = vec![halves(1, strategies[0])?];
    // Relative variance needs each pixel's value, and a pilot's own mean is no good for it: an
    // outlier inflates the mean it is divided by. The training images' (blurred) estimates
    // are; without them (a loaded field), the first guided pilot's, blurred the same way.
    let own;
    let estimate = match &guidance.estimate {
        Some(e) => e,
        None => {
            own = pixel_estimates(&guided[0].clone().map(|(film, _)| film)).expect("two films");
            &own
        }
    };
    // A heavy-tailed pilot cannot rank the candidates, its gains scattering from seed to seed
    // (docs/experiments.md): there the requested components stand alone.
    let tail = tail_share(&unguided, estimate);
    let strategies = if tail < TAIL_LIMIT { strategies } else { strategies[..1].to_vec() };
    for (k, &c) in strategies.iter().enumerate().skip(1) {
        guided.push(halves(k + 1, c)?);
    }
    let columns = w.div_ceil(TILE) as usize;
    let choices = guided
        .iter()
        .zip(&strategies)
        .map(|(pilot, &components)| {
            let parts = [0, 1].map(|i| measure(&pilot[i], &unguided[i], estimate, w, h));
            judge(&parts, components, count, columns)
        })
        .collect();
    let mut best = pick(choices);
    best.selection.unguided_tail_share = tail;
    best.selection.seconds = start.elapsed().as_secs_f64();
    Some(best)
}

/// One candidate's choice of tiles from the two halves of its pilot (`columns` tiles per row),
/// with its gains in sample, out of sample and guiding every tile.
fn judge(
    parts: &[Vec<TileMeasure>; 2],
    components: Components,
    pilot_spp: u32,
    columns: usize,
) -> Choice {
    let all: Vec<TileMeasure> = parts[0].iter().zip(&parts[1]).map(|(a, b)| *a + *b).collect();
    let tiles = decide(&all, columns);
    let mut selection = summarise(&all, &tiles, components, pilot_spp);
    selection.everywhere_gain = gain(&all, &vec![true; all.len()]);
    selection.one_way_gains = one_way_gains(parts, columns);
    selection.validated_gain = selection.one_way_gains.iter().product::<f64>().sqrt();
    Choice { tiles, components, selection }
}

/// The candidate whose choice of tiles gains most out of sample (ties go to the earlier, the
/// requested components, first in `choices`), if that gain is above 1; else
/// [`no_choice_pays`].
fn pick(mut choices: Vec<Choice>) -> Choice {
    let gains: Vec<(String, f64)> =
        choices.iter().map(|c| (c.components.name(), c.selection.validated_gain)).collect();
    let winner = (1..choices.len()).fold(0, |b, k| {
        let better = choices[k].selection.validated_gain > choices[b].selection.validated_gain;
        if better { k } else { b }
    });
    let mut best = if choices[winner].selection.validated_gain > 1.0 {
        choices.swap_remove(winner)
    } else {
        no_choice_pays(choices.swap_remove(0))
    };
    best.selection.candidates = gains;
    best
}

/// What is guided when no candidate's choice of tiles pays out of sample: every tile with the
/// `requested` components where that gains on all the pilot's samples, else none. Guiding
/// every tile is not picked from the pilot's noise, so its gain needs no other half to judge
/// it; and where rare bright paths make the error, a half of the pilot that missed them shows
/// guiding no gain at all, so a gain both halves must show is missed where guiding pays
/// several times over (see docs/experiments.md).
fn no_choice_pays(requested: Choice) -> Choice {
    let Choice { mut tiles, components, mut selection } = requested;
    let everywhere = selection.everywhere_gain > 1.0;
    tiles.iter_mut().for_each(|g| *g = everywhere);
    selection.guided_tiles = if everywhere { tiles.len() } else { 0 };
    selection.gain = if everywhere { selection.everywhere_gain } else { 1.0 };
    Choice { tiles, components, selection }
}

/// The share of the relative variance of `pilot`'s pixels (both halves pooled, each pixel
/// weighted as relMSE weighs it by `estimate`) that its 1% of pixels with the most hold.
fn tail_share(pilot: &[(Film, Vec<Counters>); 2], estimate: &[f32]) -> f64 {
    let mut v: Vec<f64> = (0..estimate.len())
        .map(|p| {
            let mut sum = pilot[0].0.pixels[p];
            sum.merge(&pilot[1].0.pixels[p]);
            sum.luminance_variance() / (f64::from(estimate[p]).powi(2) + EPSILON)
        })
        .collect();
    let total: f64 = v.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return 0.0;
    }
    v.sort_unstable_by(|a, b| b.total_cmp(a));
    let top = v.len().div_ceil(100);
    v[..top].iter().sum::<f64>() / total
}

/// The tiles to guide by one pilot's measures (`columns` tiles per row): the best set
/// ([`choose`], on pooled measures), or every tile unless that is clearly worse.
fn decide(measured: &[TileMeasure], columns: usize) -> Vec<bool> {
    everywhere_unless_clearly_worse(measured, choose(measured, &smoothed(measured, columns)))
}

/// The gains of [`decide`]'s choice out of sample: the choice made on each half of the pilot's
/// samples, judged on the other, both ways. A choice judged on the samples it was made from
/// looks better than it is (it picks the tiles whose samples happened to look better); judged
/// on independent ones it does not.
fn one_way_gains(parts: &[Vec<TileMeasure>; 2], columns: usize) -> [f64; 2] {
    let one_way =
        |made: &[TileMeasure], judged: &[TileMeasure]| gain(judged, &decide(made, columns));
    [one_way(&parts[0], &parts[1]), one_way(&parts[1], &parts[0])]
}

/// Each tile's measures from one half of the pilot: a guided strategy's film and per-tile
/// counters, and unguided sampling's, each pixel weighted as relMSE weighs it (`estimate`).
fn measure(
    guided: &(Film, Vec<Counters>),
    unguided: &(Film, Vec<Counters>),
    estimate: &[f32],
    w: u32,
    h: u32,
) -> Vec<TileMeasure> {
    tiles(w, h)
        .iter()
        .enumerate()
        .map(|(i, &(tx, ty))| {
            let (x0, y0) = (tx * TILE, ty * TILE);
            let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
            let pixels = (y0..y1).flat_map(|y| (x0..x1).map(move |x| (y * w + x) as usize));
            let (mut guided_variance, mut unguided_variance) = (0.0, 0.0);
            for p in pixels {
                // relMSE's weight, on luminance rather than per channel.
                let weight = 1.0 / (f64::from(estimate[p]).powi(2) + EPSILON);
                guided_variance += weight * guided.0.pixels[p].luminance_variance();
                unguided_variance += weight * unguided.0.pixels[p].luminance_variance();
            }
            TileMeasure {
                guided_variance,
                unguided_variance,
                guided_cost: cost(&guided.1[i]),
                unguided_cost: cost(&unguided.1[i]),
            }
        })
        .collect()
}

/// The report of one candidate's choice of tiles.
fn summarise(
    measured: &[TileMeasure],
    choice: &[bool],
    components: Components,
    pilot_spp: u32,
) -> Selection {
    let sum = |f: fn(&TileMeasure) -> f64| measured.iter().map(f).sum::<f64>();
    let sums = [
        sum(|m| m.guided_variance),
        sum(|m| m.unguided_variance),
        sum(|m| m.guided_cost),
        sum(|m| m.unguided_cost),
    ];
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    Selection {
        tiles: choice.len(),
        guided_tiles: choice.iter().filter(|&&g| g).count(),
        components: components.name(),
        candidates: Vec::new(),
        pilot_spp,
        seconds: 0.0,
        cost_ratio: ratio(sums[2], sums[3]),
        variance_ratio: ratio(sums[0], sums[1]),
        gain: gain(measured, choice),
        everywhere_gain: f64::NAN,
        validated_gain: f64::NAN,
        one_way_gains: [f64::NAN; 2],
        stopped_training: false,
        early: None,
        decided_early: false,
        unguided_tail_share: f64::NAN,
    }
}

/// `choice`, or every tile guided where that pays and `choice` does not gain
/// [`PARTIAL_MARGIN`] times more. The sweep picks the set that looks best under the pilot's
/// noise, so its modelled gain is optimistic, most where the pilot missed the rare bright
/// paths of a tile it would leave unguided.
fn everywhere_unless_clearly_worse(measured: &[TileMeasure], choice: Vec<bool>) -> Vec<bool> {
    let everywhere = vec![true; measured.len()];
    let everywhere_gain = gain(measured, &everywhere);
    if everywhere_gain > 1.0 && gain(measured, &choice) < PARTIAL_MARGIN * everywhere_gain {
        everywhere
    } else {
        choice
    }
}

/// The modelled efficiency of the image with the tiles in `choice` guided over the image all
/// unguided.
fn gain(measured: &[TileMeasure], choice: &[bool]) -> f64 {
    let (v_u, c_u) = totals(measured, &vec![false; measured.len()]);
    let (v, c) = totals(measured, choice);
    let gain = v_u * c_u / (v * c);
    // A black image (no variance either way) gains nothing.
    if gain.is_finite() { gain } else { 1.0 }
}

/// The image's variance and cost (sums over tiles) when the tiles in `choice` are guided.
fn totals(tiles: &[TileMeasure], choice: &[bool]) -> (f64, f64) {
    tiles.iter().zip(choice).fold((0.0, 0.0), |(v, c), (m, &g)| {
        if g {
            (v + m.guided_variance, c + m.guided_cost)
        } else {
            (v + m.unguided_variance, c + m.unguided_cost)
        }
    })
}

/// One tile's pilot: relative variance and modelled cost of the pilot's samples, each way.
#[derive(Clone, Copy, Debug, Default)]
struct TileMeasure {
    guided_variance: f64,
    unguided_variance: f64,
    guided_cost: f64,
    unguided_cost: f64,
}

impl std::ops::Add for TileMeasure {
    type Output = Self;

    fn add(self, o: Self) -> Self {
        Self {
            guided_variance: self.guided_variance + o.guided_variance,
            unguided_variance: self.unguided_variance + o.unguided_variance,
            guided_cost: self.guided_cost + o.guided_cost,
            unguided_cost: self.unguided_cost + o.unguided_cost,
        }
    }
}

/// How much more a choice that leaves some tiles unguided must gain than guiding every tile:
/// the best-looking choice is picked under the pilot's noise, and where unguided samples are
/// heavy-tailed, the tiles a smaller margin left out drew fireflies (see docs/experiments.md).
const PARTIAL_MARGIN: f64 = 2.0;

/// Tiles within this many tiles (a square) pool their pilots for the choice.
const POOL_RADIUS: usize = 2;

/// Each tile's measures summed over its neighbourhood (`columns` tiles per row). A few samples
/// per pixel mostly miss the rare bright paths that make unguided sampling noisy, so a single
/// tile's pilot picks the strategy by chance; pooled over 80x80 pixels it sees them, while
/// the choice still follows the image's structure (a light shaft, a silver lining).
fn smoothed(tiles: &[TileMeasure], columns: usize) -> Vec<TileMeasure> {
    let rows = tiles.len().div_ceil(columns.max(1));
    (0..tiles.len())
        .map(|i| {
            let (x, y) = (i % columns, i / columns);
            let mut sum = TileMeasure::default();
            for ny in y.saturating_sub(POOL_RADIUS)..(y + POOL_RADIUS + 1).min(rows) {
                for nx in x.saturating_sub(POOL_RADIUS)..(x + POOL_RADIUS + 1).min(columns) {
                    if let Some(&m) = tiles.get(ny * columns + nx) {
                        sum = sum + m;
                    }
                }
            }
            sum
        })
        .collect()
}

/// Which tiles to guide. Every tile gets the same samples per pixel, so what counts is the
/// whole image: its relative variance (the sum over tiles) times its cost (also a sum), the
/// inverse of efficiency. Minimising `V C` means guiding tile `i` when `dv_i C > dc_i V`
/// (variance saved `dv`, cost added `dc`) at the optimum's totals, so the candidates are the
/// sets `{i : dv_i > lambda dc_i}` for `lambda = V / C` from 0 up: a sweep over the tiles'
/// breakpoints `dv_i / dc_i` evaluates them all. (The best set can differ from every such set
/// by second-order terms `dv_i dc_i`, negligible once each tile is a small part of the image.)
/// Ties go to unguided sampling.
///
/// Which side of `lambda` a tile falls on is read from `pooled` (its neighbourhood's
/// measures, robust to the pilot's noise); the image's totals that judge each set are sums of
/// the tiles' own measures in `tiles`, each tile counted once.
fn choose(tiles: &[TileMeasure], pooled: &[TileMeasure]) -> Vec<bool> {
    let dv = |m: &TileMeasure| m.unguided_variance - m.guided_variance;
    let dc = |m: &TileMeasure| m.guided_cost - m.unguided_cost;
    // At lambda -> 0 every tile that saves variance is in; as lambda grows, a tile that costs
    // more leaves at dv / dc and one that saves cost but adds variance joins at dv / dc.
    let initial: Vec<bool> = pooled.iter().map(|m| dv(m) > 0.0).collect();
    let mut choice = initial.clone();
    let mut events: Vec<(f64, usize)> = pooled
        .iter()
        .enumerate()
        .filter(|(_, m)| (dv(m) > 0.0 && dc(m) > 0.0) || (dv(m) < 0.0 && dc(m) < 0.0))
        .map(|(i, m)| (dv(m) / dc(m), i))
        .collect();
    events.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let (mut v, mut c) = totals(tiles, &choice);
    let (mut best, mut best_events) = (v * c, 0);
    for (k, &(_, i)) in events.iter().enumerate() {
        let m = &tiles[i];
        let sign = if choice[i] { -1.0 } else { 1.0 };
        choice[i] = !choice[i];
        v += sign * (m.guided_variance - m.unguided_variance);
        c += sign * (m.guided_cost - m.unguided_cost);
        if v * c < best {
            (best, best_events) = (v * c, k + 1);
        }
    }
    let mut choice = initial;
    for &(_, i) in &events[..best_events] {
        choice[i] = !choice[i];
    }
    choice
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(guided_variance: f64, unguided_variance: f64, guided_cost: f64) -> TileMeasure {
        TileMeasure { guided_variance, unguided_variance, guided_cost, unguided_cost: 1.0 }
    }

    /// The product of the image's variance and cost for a choice, by brute force.
    fn product(tiles: &[TileMeasure], choice: &[bool]) -> f64 {
        let pick = |m: &TileMeasure, g: bool| {
            if g {
                (m.guided_variance, m.guided_cost)
            } else {
                (m.unguided_variance, m.unguided_cost)
            }
        };
        let (v, c) = tiles
            .iter()
            .zip(choice)
            .map(|(m, &g)| pick(m, g))
            .fold((0.0, 0.0), |(v, c), (dv, dc)| (v + dv, c + dc));
        v * c
    }

    /// Two pilot halves of `n` pixels with 2 samples each: `value(pixel, sample)`.
    fn pilot_of(n: u32, value: impl Fn(u32, u32) -> f32) -> [(Film, Vec<Counters>); 2] {
        [0, 1].map(|half| {
            let mut film = Film::new(n, 1);
            for (p, sum) in film.pixels.iter_mut().enumerate() {
                for s in 0..2 {
                    sum.add(crate::math::Spectrum::splat(value(p as u32, 2 * half + s)));
                }
            }
            (film, Vec::new())
        })
    }

    /// Light tails leave the top 1% of pixels a few percent of the variance; one pixel in
    /// four hundred with a firefly holds most of it.
    #[test]
    fn the_tail_share_tells_rare_bright_paths_from_light_noise() {
        let estimate = vec![1.0f32; 400];
        // Every pixel 1 or 1.5, in an order that varies with the pixel.
        let light = pilot_of(400, |p, s| if (p * 7 + s * 3) % 4 < 2 { 1.0 } else { 1.5 });
        let share = tail_share(&light, &estimate);
        assert!(share < 0.05, "light tails: {share}");
        let heavy = pilot_of(400, light_or_firefly);
        let share = tail_share(&heavy, &estimate);
        assert!(share > 0.9, "one firefly: {share}");
        // A black pilot has no tail.
        assert_eq!(tail_share(&pilot_of(400, |_, _| 0.0), &estimate), 0.0);
    }

    fn light_or_firefly(p: u32, s: u32) -> f32 {
        if p == 17 && s == 2 {
            400.0
        } else if (p + s).is_multiple_of(2) {
            1.0
        } else {
            1.5
        }
    }

    /// Where one half of the pilot favours guiding a tile and the other half the opposite,
    /// the choice looks good on the half it was made from and the validated gain says it is
    /// not; where both halves favour guiding, the validated gain says so.
    #[test]
    fn the_validated_gain_sees_through_a_choice_made_on_noise() {
        let plain = |n: usize| vec![tile(1.0, 1.0, 1.2); n];
        // Twelve tiles in a row; pooling spans five, so tiles 0 and 11 are judged apart.
        let mut a = plain(12);
        let mut b = plain(12);
        a[0] = tile(0.1, 4.0, 1.2); // half a: guiding tile 0 looks 40x better
        b[0] = tile(4.0, 1.0, 1.2); // half b: 4x worse
        let made_on_a = decide(&a, 12);
        assert!(made_on_a[0] && gain(&a, &made_on_a) > 1.1, "{made_on_a:?}");
        let [ab, ba] = one_way_gains(&[a.clone(), b.clone()], 12);
        assert!((ab * ba).sqrt() < 1.0, "validated gains {ab} {ba}");
        // Both halves: guiding halves the variance everywhere at 1.2x the cost.
        let good = vec![tile(0.5, 1.0, 1.2); 12];
        for real in one_way_gains(&[good.clone(), good], 12) {
            assert!((real - 1.0 / 0.6).abs() < 1e-9, "validated gain {real}");
        }
    }

    /// A heavy-tailed pilot: guiding halves the variance everywhere at 1.2x the cost, but one
    /// half of the unguided samples missed the rare bright paths (its variance looks 0.4 of
    /// guided's) while the other caught them (20x). No choice of tiles validates; guiding every
    /// tile gains on all the samples, so every tile is guided, with the requested components
    /// even where roulette alone validates better (though not above 1).
    #[test]
    fn where_no_choice_validates_every_tile_is_guided_if_that_gains() {
        let parts = [vec![tile(1.0, 0.4, 1.2); 12], vec![tile(1.0, 20.0, 1.2); 12]];
        let full = judge(&parts, Components::FULL, 8, 12);
        assert!(full.selection.validated_gain < 1.0, "{}", full.selection.validated_gain);
        // Roulette alone: cheaper, so it validates better than full, still below 1.
        let cheap = [vec![tile(1.0, 0.4, 1.05); 12], vec![tile(1.0, 20.0, 1.05); 12]];
        let roulette = judge(&cheap, Components::ROULETTE, 8, 12);
        let (f, r) = (full.selection.validated_gain, roulette.selection.validated_gain);
        assert!(f < r && r < 1.0, "full {f}, roulette {r}");
        let chosen = pick(vec![full, roulette]);
        assert_eq!(chosen.components, Components::FULL);
        assert!(chosen.tiles.iter().all(|&g| g));
        assert_eq!(chosen.selection.guided_tiles, 12);
        assert!((chosen.selection.gain - 10.2 / 1.2).abs() < 1e-9, "{}", chosen.selection.gain);
        // Where guiding every tile loses on all the samples too, nothing is guided.
        let parts = [vec![tile(1.0, 0.4, 1.2); 12], vec![tile(1.0, 1.0, 1.2); 12]];
        let chosen = pick(vec![judge(&parts, Components::FULL, 8, 12)]);
        assert!(chosen.tiles.iter().all(|&g| !g));
        assert_eq!((chosen.selection.guided_tiles, chosen.selection.gain), (0, 1.0));
    }

    /// A choice that validates is rendered as chosen, whichever candidate made it: here
    /// roulette alone validates better than full guiding (both pay most in the first four
    /// tiles, where unguided sampling is 50x noisier, and guide every tile).
    #[test]
    fn the_candidate_whose_choice_validates_best_is_rendered() {
        let mut noisy = vec![tile(1.0, 1.0, 1.5); 12];
        noisy[..4].fill(tile(1.0, 50.0, 1.5));
        let full = judge(&[noisy.clone(), noisy], Components::FULL, 8, 12);
        let mut cheap = vec![tile(1.0, 1.0, 1.1); 12];
        cheap[..4].fill(tile(1.0, 50.0, 1.1));
        let roulette = judge(&[cheap.clone(), cheap], Components::ROULETTE, 8, 12);
        let (f, r) = (full.selection.validated_gain, roulette.selection.validated_gain);
        assert!(1.0 < f && f < r, "full {f}, roulette {r}");
        let chosen = pick(vec![full, roulette]);
        assert_eq!(chosen.components, Components::ROULETTE);
        assert_eq!(chosen.selection.candidates.len(), 2);
        assert_eq!(chosen.selection.validated_gain, r);
        assert!(chosen.tiles.iter().all(|&g| g), "{:?}", chosen.tiles);
    }

    #[test]
    fn roulette_alone_is_a_candidate_only_beside_more() {
        assert_eq!(candidates(Components::FULL), [Components::FULL, Components::ROULETTE]);
        let distances_rr = Components { distances: true, ..Components::ROULETTE };
        assert_eq!(candidates(distances_rr), [distances_rr, Components::ROULETTE]);
        assert_eq!(candidates(Components::ROULETTE), [Components::ROULETTE]);
        let directions = Components { directions: true, ..Components::OFF };
        assert_eq!(candidates(directions), [directions]);
    }

    #[test]
    fn guides_only_where_the_image_gains() {
        // Guiding costs twice as much everywhere; it pays only in the noisy tile.
        let tiles = [tile(1.0, 1.0, 2.0), tile(1.0, 100.0, 2.0), tile(1.0, 1.1, 2.0)];
        assert_eq!(choose(&tiles, &tiles), [false, true, false]);
        // Cheaper and better: always; worse and dearer: never; a tie: unguided.
        let tiles = [tile(0.5, 1.0, 0.5), tile(2.0, 1.0, 3.0), tile(1.0, 1.0, 1.0)];
        assert_eq!(choose(&tiles, &tiles), [true, false, false]);
        // Black tiles (no variance either way) stay unguided.
        let black = [tile(0.0, 0.0, 2.0)];
        assert_eq!(choose(&black, &black), [false]);
    }

    #[test]
    fn leaving_tiles_unguided_must_gain_clearly_more_than_guiding_all() {
        // Guiding pays 4x in the first tile and loses a little in the second: the image gains
        // more with the second unguided, but by less than the margin.
        let tiles = [tile(1.0, 4.0, 1.0), tile(1.05, 1.0, 1.0)];
        let partial = vec![true, false];
        assert!(gain(&tiles, &partial) > gain(&tiles, &[true, true]));
        assert!(gain(&tiles, &partial) < PARTIAL_MARGIN * gain(&tiles, &[true, true]));
        assert_eq!(everywhere_unless_clearly_worse(&tiles, partial), [true, true]);
        // It loses 3x there: unguided it stays.
        let tiles = [tile(1.0, 4.0, 1.0), tile(3.0, 1.0, 1.0)];
        assert_eq!(everywhere_unless_clearly_worse(&tiles, vec![true, false]), [true, false]);
        // Where guiding everything does not pay, the choice stands (here: none).
        let tiles = [tile(2.0, 1.0, 1.0), tile(2.0, 1.0, 1.0)];
        assert_eq!(everywhere_unless_clearly_worse(&tiles, vec![false, false]), [false, false]);
    }

    #[test]
    fn the_choice_is_the_best_over_all_choices_when_tiles_are_small_parts_of_the_image() {
        // Pseudo-random images: 8 tiles where guiding may pay, among 40 where it cannot (as in
        // a real image, no tile is a large part of it). Exhaustive search over the 8 finds the
        // optimum; the sweep must find it too.
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..500 {
            let mut tiles: Vec<TileMeasure> =
                (0..8).map(|_| tile(next() * 4.0, next() * 4.0, 0.5 + next() * 3.0)).collect();
            tiles.extend((0..40).map(|_| tile(1.0, 1.0, 2.0)));
            let chosen = product(&tiles, &choose(&tiles, &tiles));
            let best = (0..1u32 << 8)
                .map(|bits| {
                    let choice: Vec<bool> = (0..48).map(|i| i < 8 && bits >> i & 1 == 1).collect();
                    product(&tiles, &choice)
                })
                .fold(f64::INFINITY, f64::min);
            assert!(chosen <= best * (1.0 + 1e-12), "sweep {chosen} against the optimum {best}");
        }
    }
}
