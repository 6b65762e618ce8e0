//! Measuring which tracker pays on one medium of a scene (`zerovar check --trackers`): each
//! candidate renders the scene unguided a few times with only that medium's tracker changed,
//! and its efficiency is the inverse of one render's relative variance (from the spread of the
//! renders) times its seconds. Renders never consult it: a choice made from wall time would
//! make an image depend on the machine's load, so `auto` keeps its fixed choice, which the
//! measurements in docs/experiments.md support, and `check` shows where another tracker pays.

use super::{Budget, RenderError, RenderOptions, render};
use crate::scene::Scene;
use crate::tracking::Tracker;

/// Renders per candidate: the spread of four images gives each pixel's variance with three
/// degrees of freedom, and a sum over many pixels steadies the image's.
const RUNS: u64 = 4;

/// The denominator's floor in relative variance, as in relMSE: `var / (mean^2 + 1e-3)`, so
/// black pixels do not dominate.
const RELATIVE_FLOOR: f64 = 1e-3;

/// One tracker's figures on one medium.
#[derive(Clone, Copy, Debug)]
pub struct TrackerTrial {
    /// The tracker measured.
    pub tracker: Tracker,
    /// Samples per pixel of each render.
    pub spp: u32,
    /// Renders, each with a seed of its own.
    pub runs: u32,
    /// Wall-clock seconds of one render (the mean over the renders).
    pub seconds: f64,
    /// Density lookups per camera path.
    pub lookups_per_path: f64,
    /// One render's relative variance, averaged over pixels and channels.
    pub relative_variance: f64,
    /// The same with the 0.1% of pixel-channels of largest variance left out, which shows how
    /// much of it is a few fireflies.
    pub trimmed_relative_variance: f64,
}

impl TrackerTrial {
    /// `1 / (relative variance x seconds)`.
    pub fn efficiency(&self) -> f64 {
        1.0 / (self.relative_variance * self.seconds)
    }

    /// The same without the worst 0.1% of pixel-channels.
    pub fn trimmed_efficiency(&self) -> f64 {
        1.0 / (self.trimmed_relative_variance * self.seconds)
    }
}

/// Every candidate tracker of medium `medium` ([`crate::tracking::candidates`]), measured in
/// about `seconds` of rendering in all; the other media keep their trackers. Empty for a
/// homogeneous medium, whose closed form is exact.
pub fn measure_trackers(
    scene: &mut Scene,
    medium: usize,
    seconds: f64,
    threads: Option<usize>,
) -> Result<Vec<TrackerTrial>, RenderError> {
    let candidates = crate::tracking::candidates(&scene.media()[medium]);
    if candidates.is_empty() {
        return Ok(Vec::new());
    }
    let own = scene.trackers()[medium];
    let trials = measure_each(scene, medium, &candidates, seconds, threads);
    scene.set_medium_tracker(medium, own);
    trials
}

/// What [`measure_trackers`] does, less restoring the medium's own tracker.
fn measure_each(
    scene: &mut Scene,
    medium: usize,
    candidates: &[Tracker],
    seconds: f64,
    threads: Option<usize>,
) -> Result<Vec<TrackerTrial>, RenderError> {
    let options = |spp, seed| RenderOptions {
        threads,
        ..RenderOptions::unguided(Budget::Samples(spp), seed)
    };
    let probe = render(scene, &options(1, 0), &|_, _| true)?;
    let per_spp = probe.seconds.max(1e-4);
    let spp =
        (seconds / (per_spp * (RUNS * candidates.len() as u64) as f64)).clamp(1.0, 4096.0) as u32;
    // Seed-major, so that a slow spell of the machine falls on every candidate alike.
    let mut runs = vec![(0.0, 0u64, 0u64, Vec::new()); candidates.len()];
    for seed in 1..=RUNS {
        for (&tracker, (seconds, lookups, paths, images)) in candidates.iter().zip(&mut runs) {
            scene.set_medium_tracker(medium, tracker);
            let r = render(scene, &options(spp, seed), &|_, _| true)?;
            *seconds += r.seconds;
            *lookups += r.counters.density_lookups;
            *paths += r.counters.paths;
            images.push(r.image);
        }
    }
    let trials = candidates
        .iter()
        .zip(runs)
        .map(|(&tracker, (seconds, lookups, paths, images))| {
            let (relative_variance, trimmed_relative_variance) = relative_variance(&images);
            TrackerTrial {
                tracker,
                spp,
                runs: RUNS as u32,
                seconds: seconds / RUNS as f64,
                lookups_per_path: lookups as f64 / paths.max(1) as f64,
                relative_variance,
                trimmed_relative_variance,
            }
        })
        .collect();
    Ok(trials)
}

/// Per pixel-channel, the sample variance of the images' values over their mean squared
/// (floored), averaged: all of them, and without the largest 0.1%.
fn relative_variance(images: &[Vec<[f32; 3]>]) -> (f64, f64) {
    let n = images.len() as f64;
    let mut values: Vec<f64> = (0..images[0].len())
        .flat_map(|p| (0..3).map(move |c| (p, c)))
        .map(|(p, c)| {
            let mean = images.iter().map(|im| f64::from(im[p][c])).sum::<f64>() / n;
            let var = images.iter().map(|im| (f64::from(im[p][c]) - mean).powi(2)).sum::<f64>()
                / (n - 1.0);
            var / (mean * mean + RELATIVE_FLOOR)
        })
        .collect();
    let all = values.iter().sum::<f64>() / values.len() as f64;
    values.sort_by(f64::total_cmp);
    let keep = values.len() - values.len() / 1000;
    (all, values[..keep].iter().sum::<f64>() / keep as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_variance_of_known_images() {
        // 2000 pixels whose three channels are 1 in one image and 3 in the other (mean 2,
        // variance 2), but for one pixel whose green is 0 and 300.
        let mut a = vec![[1.0f32; 3]; 2000];
        let mut b = vec![[3.0f32; 3]; 2000];
        (a[7][1], b[7][1]) = (0.0, 300.0);
        let (all, trimmed) = relative_variance(&[a, b]);
        let usual = 2.0 / (4.0 + RELATIVE_FLOOR);
        let odd = 150.0f64.powi(2) * 2.0 / (150.0f64.powi(2) + RELATIVE_FLOOR);
        assert!((all - (5999.0 * usual + odd) / 6000.0).abs() < 1e-9, "{all}");
        // The 0.1% left out is 6 of the 6000 pixel-channels: the odd one and 5 usual ones.
        assert!((trimmed - usual).abs() < 1e-9, "{trimmed}");
    }
}
