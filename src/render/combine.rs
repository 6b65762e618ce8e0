//! Combining images: the training passes' images with the render's by inverse variance, and
//! the smoothed per-pixel estimates weight windows centre on.

use crate::film::{Film, PixelSum};
use crate::math::{Spectrum, luminance};

/// Per-pixel luminance estimates from the training films: the mean over all their samples,
/// box-filtered over 5x5 pixels, since a weight window centred on a noisy estimate (a
/// firefly, or a pixel whose few samples missed the light) would roulette or split the
/// wrong paths.
pub(super) fn pixel_estimates(films: &[Film]) -> Option<Vec<f32>> {
    let first = films.first()?;
    let (w, h) = (first.width as usize, first.height as usize);
    let mut sums = vec![PixelSum::default(); first.pixels.len()];
    for f in films {
        for (s, p) in sums.iter_mut().zip(&f.pixels) {
            s.merge(p);
        }
    }
    let raw: Vec<f32> = sums.iter().map(|s| luminance(Spectrum::from_array(s.mean()))).collect();
    let mut out = vec![0.0; raw.len()];
    for y in 0..h {
        for x in 0..w {
            let (y0, y1) = (y.saturating_sub(2), (y + 3).min(h));
            let (x0, x1) = (x.saturating_sub(2), (x + 3).min(w));
            let total: f32 = (y0..y1).flat_map(|yy| raw[yy * w + x0..yy * w + x1].iter()).sum();
            out[y * w + x] = total / ((y1 - y0) * (x1 - x0)) as f32;
        }
    }
    Some(out)
}

/// Mean per-pixel relative variance of a film's pixel means: luminance variance times
/// `weights`, relMSE's per-pixel weight. That is what the combination should minimise;
/// absolute variance would let the brightest pixels decide.
pub(super) fn image_variance(film: &Film, weights: &[f64]) -> f64 {
    let total: f64 = film
        .pixels()
        .iter()
        .zip(weights)
        .map(|(p, w)| w * p.luminance_variance() / f64::from(p.count.max(1)))
        .sum();
    total / film.pixels().len().max(1) as f64
}

/// The images of `training` and `last` averaged with weights inversely proportional to their
/// estimated relative variance (equal weights if a variance is zero), relative to `last`'s
/// values. The weights are one per image, so the average stays unbiased up to their own
/// estimation noise, which averages over every pixel.
pub(super) fn combine_by_inverse_variance(training: &[Film], last: &Film) -> Vec<[f32; 3]> {
    let films: Vec<&Film> = training.iter().chain(std::iter::once(last)).collect();
    let relative: Vec<f64> = last
        .pixels()
        .iter()
        .map(|r| {
            let m = f64::from(crate::math::luminance(glam::Vec3A::from(r.mean())));
            1.0 / (m * m + crate::math::RELATIVE_EPSILON)
        })
        .collect();
    let weights: Vec<f64> = films
        .iter()
        .map(|f| image_variance(f, &relative))
        .map(|v| if v > 0.0 && v.is_finite() { 1.0 / v } else { 0.0 })
        .collect();
    let total: f64 = weights.iter().sum();
    let weights: Vec<f64> = if total > 0.0 {
        weights.iter().map(|w| w / total).collect()
    } else {
        vec![1.0 / films.len() as f64; films.len()]
    };
    (0..last.pixels.len())
        .map(|i| {
            let mut c = [0.0f64; 3];
            for (f, w) in films.iter().zip(&weights) {
                let m = f.pixels[i].mean();
                for k in 0..3 {
                    c[k] += w * m[k] as f64;
                }
            }
            c.map(|v| v as f32)
        })
        .collect()
}
