//! The firefly diagnostic: which samples carry the largest share of an image's error, and the
//! path of each, decision by decision (`RenderOptions::fireflies`, `zerovar render
//! --fireflies N`).
//!
//! During the render each pixel keeps its largest sample (by luminance). Afterwards the
//! pixels whose largest sample deviates most from the pixel's mean, weighted as relMSE weighs
//! it (`1 / (mean^2 + epsilon)`), are replayed: a sample's streams are keyed by (seed, pixel,
//! sample index), and the field and pixel estimates are fixed during the render phase, so the
//! replay draws the same path again, this time with a trace attached. Training passes are
//! searched the same way, each before the field learns from it (their images are averaged
//! into the result, so their fireflies are the result's too).

use super::{Pass, TILE, TileWork, camera_sample, with_tile_walk};
use crate::film::Film;
use crate::guided::RadianceCache;
use crate::integrators::trace::{Continuation, LightSource, Strategy, Trace, TraceEvent};
use crate::integrators::walk::{WalkContext, WalkSettings};
use crate::math::RELATIVE_EPSILON as EPSILON;
use crate::math::{Spectrum, luminance};
use crate::scene::Scene;
use crate::stats::Counters;
use serde::Serialize;

/// The largest samples of a render and their paths.
#[derive(Clone, Debug, Serialize)]
pub struct FireflyReport {
    /// The share of the image's relative squared deviation (the sum over pixels of the
    /// squared deviation of each sample from its pixel's mean, weighted as relMSE weighs
    /// pixels) that the listed samples hold.
    pub share: f64,
    /// The samples, largest share first.
    pub samples: Vec<Firefly>,
    /// The training passes' largest samples, by their share of their own pass's image (where
    /// the training images are averaged into the result), largest first.
    pub training: Vec<Firefly>,
}

/// One sample and its path.
#[derive(Clone, Debug, Serialize)]
pub struct Firefly {
    /// Its pixel, `[x, y]`.
    pub pixel: [u32; 2],
    /// Its sample index.
    pub sample: u32,
    /// The training pass that drew it (`None`: the render phase).
    pub pass: Option<u32>,
    /// Its value.
    pub value: [f32; 3],
    /// The pixel's mean over its pass (the render phase, or its training pass).
    pub pixel_mean: [f32; 3],
    /// Its share of the image's relative squared deviation.
    pub share: f64,
    /// Whether its tile was rendered guided.
    pub guided: bool,
    /// Whether the replay drew the same value (it must: a sample depends on its streams
    /// alone).
    pub replayed: bool,
    /// Every decision of its walks and every light they found.
    pub events: Trace,
}

/// Replays one sample of one pixel with a trace.
struct Replay<'a, 'p> {
    scene: &'a Scene,
    pass: Pass<'p>,
    pixel: [u32; 2],
    sample: u32,
    floor: f32,
}

impl TileWork for Replay<'_, '_> {
    type Output = (Spectrum, Trace);

    fn run<C: RadianceCache>(self, settings: &WalkSettings, cache: &mut C) -> (Spectrum, Trace) {
        let [x, y] = self.pixel;
        let w = self.scene.camera.resolution()[0];
        let mut trace = Trace::new();
        // Recording a training path does not change its decisions: the replay needs none.
        let mut ctx = WalkContext {
            cache,
            pixel: self.pass.estimate.map(|e| e[(y * w + x) as usize] + self.floor),
            recorder: None,
            trace: Some(&mut trace),
        };
        let mut counters = Counters::default();
        let seed = self.pass.seed;
        let l = camera_sample(
            self.scene,
            settings,
            seed,
            self.pixel,
            self.sample,
            &mut ctx,
            &mut counters,
        );
        (l, trace)
    }
}

/// The `count` pixels whose largest sample holds the most of `film`'s relative squared
/// deviation, each replayed with `pass` (whose estimate is the one the sample's own pass used,
/// `estimate_for(sample)`); `training` is the training pass that drew `film`, if one did.
/// Pixels are weighted by `1 / (m^2 + epsilon)` with `m` the pixel's mean in `judge` where
/// given (a training pass's few samples per pixel make a poor judge of their own firefly: its
/// pixel's mean rises with it), else in `film`.
#[allow(clippy::too_many_arguments)]
pub(super) fn find<'p>(
    scene: &Scene,
    pass: Pass<'p>,
    training: Option<u32>,
    film: &Film,
    judge: Option<&[f32]>,
    largest: &[super::Largest],
    count: usize,
    estimate_for: impl Fn(u32) -> Option<&'p [f32]>,
) -> FireflyReport {
    let [w, _] = scene.camera.resolution();
    let mut total = 0.0;
    let mut ranked: Vec<(f64, usize)> = Vec::with_capacity(largest.len());
    for (i, (p, big)) in film.pixels().iter().zip(largest).enumerate() {
        let mean = f64::from(luminance(Spectrum::from_array(p.mean())));
        let m = judge.map_or(mean, |j| f64::from(j[i]));
        let weight = 1.0 / (m * m + EPSILON);
        // The sum of squared deviations of the pixel's samples from their mean.
        total += weight * (p.lum_sq - f64::from(p.count) * mean * mean).max(0.0);
        if big.index.is_some() {
            let d = f64::from(luminance(big.value)) - mean;
            ranked.push((weight * d * d, i));
        }
    }
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    ranked.truncate(count);
    let columns = w.div_ceil(TILE);
    let samples: Vec<Firefly> = ranked
        .iter()
        .map(|&(deviation, i)| {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let big = largest[i];
            let sample = big.index.expect("ranked pixels have a sample");
            let pass = Pass { estimate: estimate_for(sample), ..pass };
            let floor = pass.estimate.map_or(0.0, crate::guided::window::floor);
            let tile = ((y / TILE) * columns + x / TILE) as usize;
            let guided = pass.field.is_some() && pass.guided_tiles.is_none_or(|g| g[tile]);
            let replay = Replay { scene, pass, pixel: [x, y], sample, floor };
            let ((value, events), _) = with_tile_walk(&pass, tile, replay);
            Firefly {
                pixel: [x, y],
                sample,
                pass: training,
                value: big.value.to_array(),
                pixel_mean: film.pixels()[i].mean(),
                share: if total > 0.0 { deviation / total } else { 0.0 },
                guided,
                replayed: value == big.value,
                events,
            }
        })
        .collect();
    FireflyReport { share: samples.iter().map(|f| f.share).sum(), samples, training: Vec::new() }
}

impl FireflyReport {
    /// A table for people: per sample, its share, how far it lies above its pixel's mean, the
    /// light that made it (what found it, at which depth and distance, the path weight that
    /// carried it) and the decisions that multiplied that weight by 2 or more.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "the {} largest samples hold {:.1}% of the image's relative squared deviation\n",
            self.samples.len(),
            100.0 * self.share
        );
        s += &table(&self.samples);
        if !self.training.is_empty() {
            s += "the training passes' largest samples (share of their own pass's image):\n";
            s += &table(&self.training);
        }
        s
    }
}

/// One row per sample (see [`FireflyReport::summary`]); a training pass's samples name it.
fn table(samples: &[Firefly]) -> String {
    let mut s = String::from(
        "  share  pixel      sample  x mean   guided  largest light (depth, distance, weight)  weight built by\n",
    );
    for f in samples {
        let mean = luminance(Spectrum::from_array(f.pixel_mean));
        let value = luminance(Spectrum::from_array(f.value));
        let ratio = if mean > 0.0 { format!("{:.0}", value / mean) } else { "inf".into() };
        s += &format!(
            "  {:5.1}% ({:4},{:4}) {:7} {:>7}  {:6}  {:40} {}{}{}\n",
            100.0 * f.share,
            f.pixel[0],
            f.pixel[1],
            f.sample,
            ratio,
            if f.guided { "yes" } else { "no" },
            largest_light(&f.events),
            weight_makers(&f.events),
            f.pass.map_or(String::new(), |p| format!(" (training pass {p})")),
            if f.replayed { "" } else { " (replay differs)" }
        );
    }
    s
}

/// The light event with the largest contribution, described.
fn largest_light(events: &[TraceEvent]) -> String {
    let best = events
        .iter()
        .filter_map(|e| match *e {
            TraceEvent::Light { depth, source, contribution, beta, distance } => {
                Some((contribution, depth, source, beta, distance))
            }
            _ => None,
        })
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let Some((_, depth, source, beta, distance)) = best else { return "none".into() };
    let name = match source {
        LightSource::NeeMedium => "nee in medium",
        LightSource::NeeSurface => "nee at surface",
        LightSource::ExtraCollision => "extra collision",
        LightSource::EmitterHit => "emitter hit",
        LightSource::Escape => "escape",
        LightSource::MediumEmission => "medium emission",
    };
    format!("{name} ({depth}, {distance:.3}, {beta:.3})")
}

/// The decisions that multiplied the path weight by 2 or more.
fn weight_makers(events: &[TraceEvent]) -> String {
    let parts: Vec<String> = events
        .iter()
        .filter_map(|e| match *e {
            TraceEvent::Flight { depth, guided, weight, .. } if weight >= 2.0 => Some(format!(
                "{} flight@{depth} x{weight:.1}",
                if guided { "guided" } else { "std" }
            )),
            TraceEvent::Direction { depth, surface, strategy, weight, .. } if weight >= 2.0 => {
                let at = if surface { "surface" } else { "medium" };
                let by = match strategy {
                    Strategy::Standard => "std",
                    Strategy::Guided => "guided",
                    Strategy::Halo => "halo",
                };
                Some(format!("{by} dir@{depth} {at} x{weight:.1}"))
            }
            TraceEvent::Continue { depth, rule, q, copies } if copies > 0 && q <= 0.5 => {
                let rule = match rule {
                    Continuation::Window => "window",
                    Continuation::VertexWindow => "vertex window",
                    Continuation::Standard => "rr",
                };
                Some(format!("{rule}@{depth} x{:.1}", 1.0 / q))
            }
            _ => None,
        })
        .collect();
    if parts.is_empty() { "-".into() } else { parts.join(", ") }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{Budget, GuidingOptions, RenderOptions, render};

    /// A point light in fog before a wall, seen from inside the fog: next-event estimates
    /// near the light make a few samples far larger than the rest.
    const FOG: &str = r#"
[render]
max_depth = 6

[camera]
origin = [0, 0, 3]
target = [0, 0, 0]
fov = 50
resolution = [10, 8]
medium = "fog"

[media.fog]
type = "homogeneous"
sigma_t = 0.6
albedo = 0.8
phase = { type = "hg", g = 0.3 }

[[shapes]]
type = "rectangle"
transform = [{ scale = 4 }, { translate = [0, 0, -2] }]
bsdf = { type = "diffuse", reflectance = [0.7, 0.5, 0.3] }

[[lights]]
type = "point"
position = [0.4, 0.2, 0.5]
intensity = 3
"#;

    fn light_sum(events: &[TraceEvent]) -> f32 {
        events
            .iter()
            .map(|e| match e {
                TraceEvent::Light { contribution, .. } => *contribution,
                _ => 0.0,
            })
            .sum()
    }

    /// The report names the samples that really deviate most (found here by rendering every
    /// sample again, one at a time), and each trace accounts for its sample's whole value.
    #[test]
    fn the_largest_samples_are_found_and_their_traces_add_up_to_them() {
        let scene = crate::scene::load_str(std::path::Path::new("fog.toml"), FOG, &[])
            .unwrap_or_else(|e| panic!("{e}"));
        for guided in [false, true] {
            let mut options = RenderOptions::unguided(Budget::Samples(24), 5);
            options.fireflies = 4;
            if guided {
                options.guiding = GuidingOptions {
                    components: crate::guided::Components::FULL,
                    train: crate::render::TrainBudget::Passes(3),
                    combine_training: false,
                    ..GuidingOptions::default()
                };
            }
            let result = render(&scene, &options, &|_, _| true).expect("renders");
            let report = result.fireflies.expect("asked for");
            assert_eq!(report.samples.len(), 4);
            let [w, h] = scene.camera.resolution();
            // Every sample's deviation, by brute force (unguided: no field to replay with).
            let mut all = Vec::new();
            if !guided {
                let settings = crate::integrators::VolPath::from_scene(&scene).settings();
                for p in 0..(w * h) as usize {
                    let mean =
                        f64::from(luminance(Spectrum::from_array(result.film.pixels()[p].mean())));
                    for s in 0..24 {
                        let mut cache = crate::guided::NoCache;
                        let mut ctx = WalkContext::new(&mut cache);
                        let pixel = [p as u32 % w, p as u32 / w];
                        let l = camera_sample(
                            &scene,
                            &settings,
                            5,
                            pixel,
                            s,
                            &mut ctx,
                            &mut Counters::default(),
                        );
                        let d = f64::from(luminance(l)) - mean;
                        all.push((d * d / (mean * mean + EPSILON), pixel, s));
                    }
                }
                all.sort_by(|a, b| b.0.total_cmp(&a.0));
            }
            let mut pixels_seen = std::collections::HashSet::new();
            for f in &report.samples {
                assert!(f.replayed, "guided {guided}: {f:?}");
                let value = luminance(Spectrum::from_array(f.value));
                let traced = light_sum(&f.events);
                assert!((traced - value).abs() <= 1e-4 * value.max(1e-6), "{traced} vs {value}");
                assert!(pixels_seen.insert(f.pixel), "one sample per pixel");
                assert_eq!(f.guided, guided);
            }
            if !guided {
                // The largest deviations overall, one per pixel, are the report's.
                let mut expected = Vec::new();
                let mut seen = std::collections::HashSet::new();
                for &(_, pixel, s) in &all {
                    if seen.insert(pixel) {
                        expected.push((pixel, s));
                    }
                }
                let got: Vec<_> = report.samples.iter().map(|f| (f.pixel, f.sample)).collect();
                assert_eq!(got, expected[..4]);
                assert!(report.share > 0.0 && report.share < 1.0, "{}", report.share);
            }
        }
    }

    /// Training passes are searched too, each with the field it was drawn with: their samples
    /// replay exactly (recorded ones too) and name their pass.
    #[test]
    fn training_passes_fireflies_are_found_and_replayed() {
        let scene = crate::scene::load_str(std::path::Path::new("fog.toml"), FOG, &[])
            .unwrap_or_else(|e| panic!("{e}"));
        let mut options = RenderOptions::unguided(Budget::Samples(64), 5);
        options.fireflies = 6;
        options.guiding = GuidingOptions {
            components: crate::guided::Components::FULL,
            train: crate::render::TrainBudget::Passes(4),
            ..GuidingOptions::default()
        };
        let result = render(&scene, &options, &|_, _| true).expect("renders");
        let report = result.fireflies.expect("asked for");
        assert_eq!(report.training.len(), 6);
        let passes: std::collections::HashSet<u32> =
            report.training.iter().filter_map(|f| f.pass).collect();
        assert!(report.training.iter().all(|f| f.pass.is_some_and(|p| p < 4)));
        assert!(passes.len() > 1, "samples of one pass only: {passes:?}");
        for f in &report.training {
            assert!(f.replayed, "{f:?}");
            let value = luminance(Spectrum::from_array(f.value));
            let traced = light_sum(&f.events);
            assert!((traced - value).abs() <= 1e-4 * value.max(1e-6), "{traced} vs {value}");
        }
        assert!(report.samples.iter().all(|f| f.pass.is_none()));
    }
}
