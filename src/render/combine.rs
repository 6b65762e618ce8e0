//! Combining images: the training passes' images with the render's by inverse variance (each
//! half of an image weighed by its other half's variance), and the smoothed per-pixel
//! estimates weight windows centre on.

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

/// Mean per-pixel relative variance of pixel means: luminance variance times `weights`,
/// relMSE's per-pixel weight. That is what the combination should minimise; absolute variance
/// would let the brightest pixels decide.
pub(super) fn image_variance(pixels: &[PixelSum], weights: &[f64]) -> f64 {
    let total: f64 = pixels
        .iter()
        .zip(weights)
        .map(|(p, w)| w * p.luminance_variance() / f64::from(p.count.max(1)))
        .sum();
    total / pixels.len().max(1) as f64
}

/// The images of `training` and `last` averaged with weights inversely proportional to their
/// estimated relative variance, each weight estimated from samples other than those it
/// weighs. Every film keeps its even- and odd-numbered samples apart (`Film::with_halves`);
/// the films' even halves are averaged with weights from their odd halves and the odd halves
/// with weights from the even halves, and the two averages are averaged. A weight estimated
/// from the image it weighs falls where that image has a firefly, which biases the mean low;
/// here a half's samples meet their weight only through the field that later passes learnt
/// from them. Halves of fewer than two samples per pixel weigh nothing (where no film of a
/// half has two, every sample counts alike); `last` alone is returned when a film lacks its
/// halves.
pub(super) fn combine_training(training: &[Film], last: &Film) -> Vec<[f32; 3]> {
    let films: Vec<&Film> = training.iter().chain(std::iter::once(last)).collect();
    let Some(halves) = films.iter().map(|f| f.half(0).zip(f.half(1))).collect::<Option<Vec<_>>>()
    else {
        debug_assert!(false, "combine_training needs films that keep their halves");
        return last.image();
    };
    let halves: Vec<[Vec<PixelSum>; 2]> = halves.into_iter().map(|(a, b)| [a, b]).collect();
    let mut image = vec![[0.0f64; 3]; last.pixels.len()];
    for half in 0..2 {
        let other = 1 - half;
        let judge = &halves[halves.len() - 1][other];
        let relative: Vec<f64> = judge
            .iter()
            .map(|p| {
                let m = f64::from(luminance(Spectrum::from_array(p.mean())));
                1.0 / (m * m + crate::math::RELATIVE_EPSILON)
            })
            .collect();
        // A half of fewer than two samples per pixel cannot judge the other half; where a
        // judge sees no variance at all (a constant image), sample counts decide.
        let judged = |h: &[Vec<PixelSum>; 2]| h[other].iter().all(|p| p.count >= 2);
        let variances: Vec<Option<f64>> = halves
            .iter()
            .map(|h| judged(h).then(|| image_variance(&h[other], &relative)))
            .collect();
        let weights: Vec<f64> = if variances.iter().flatten().all(|v| *v > 0.0 && v.is_finite()) {
            variances.iter().map(|v| v.map_or(0.0, |v| 1.0 / v)).collect()
        } else {
            let count = |h: &[Vec<PixelSum>; 2]| h[half].iter().map(|p| f64::from(p.count)).sum();
            halves
                .iter()
                .zip(&variances)
                .map(|(h, v)| if v.is_some() { count(h) } else { 0.0 })
                .collect()
        };
        let total: f64 = weights.iter().sum();
        if total <= 0.0 {
            return pooled(&films);
        }
        for (h, w) in halves.iter().zip(&weights) {
            if *w == 0.0 {
                continue;
            }
            for (c, p) in image.iter_mut().zip(&h[half]) {
                let m = p.mean();
                for k in 0..3 {
                    c[k] += 0.5 * w / total * f64::from(m[k]);
                }
            }
        }
    }
    image.into_iter().map(|c| c.map(|v| v as f32)).collect()
}

/// Every sample of `films` averaged alike (weights fixed by the sample counts).
fn pooled(films: &[&Film]) -> Vec<[f32; 3]> {
    let mut all = films[0].pixels.clone();
    for f in &films[1..] {
        for (a, p) in all.iter_mut().zip(&f.pixels) {
            a.merge(p);
        }
    }
    all.iter().map(PixelSum::mean).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;

    /// Films of `pixels` pixels with `spp` samples each, from a heavy-tailed distribution: 1,
    /// or 50 with probability 2% (a firefly).
    fn films(spp: &[u32], pixels: u32, sampler: &mut Sampler) -> Vec<Film> {
        spp.iter()
            .map(|&n| {
                let mut film = Film::with_halves(pixels, 1);
                for p in 0..pixels as usize {
                    for s in 0..n {
                        let v = if sampler.next_1d() < 0.02 { 50.0 } else { 1.0 };
                        film.pixels[p].add(Spectrum::splat(v));
                        if s % 2 == 1 {
                            film.odd[p].add(Spectrum::splat(v));
                        }
                    }
                }
                film
            })
            .collect()
    }

    /// Each film weighted by the inverse of its own relative variance (the combination before
    /// 2026-12-02): a firefly raises an image's variance and so lowers its weight.
    fn self_weighted(training: &[Film], last: &Film) -> Vec<[f32; 3]> {
        let films: Vec<&Film> = training.iter().chain(std::iter::once(last)).collect();
        let relative = vec![1.0; last.pixels.len()];
        let weights: Vec<f64> = films
            .iter()
            .map(|f| image_variance(&f.pixels, &relative))
            .map(|v| if v > 0.0 { 1.0 / v } else { 0.0 })
            .collect();
        let total: f64 = weights.iter().sum();
        (0..last.pixels.len())
            .map(|i| {
                let mut c = [0.0f32; 3];
                for (f, w) in films.iter().zip(&weights) {
                    let m = f.pixels[i].mean();
                    for k in 0..3 {
                        c[k] += (w / total) as f32 * m[k];
                    }
                }
                c
            })
            .collect()
    }

    /// The combined image's mean over many independent sets of heavy-tailed films, as a z
    /// score against the distribution's mean (1.98).
    fn bias_z(combine: impl Fn(&[Film], &Film) -> Vec<[f32; 3]>) -> f64 {
        let mut sampler = Sampler::new(42, 0, 0);
        let (trials, mut sum, mut sum_sq) = (4000, 0.0, 0.0);
        for _ in 0..trials {
            let mut f = films(&[4, 8, 16, 48], 16, &mut sampler);
            let last = f.pop().unwrap();
            let image = combine(&f, &last);
            let m = image.iter().map(|c| f64::from(c[0])).sum::<f64>() / image.len() as f64;
            sum += m;
            sum_sq += m * m;
        }
        let mean = sum / trials as f64;
        let se = ((sum_sq / trials as f64 - mean * mean) / trials as f64).sqrt();
        (mean - 1.98) / se
    }

    #[test]
    fn weights_from_the_other_half_keep_the_combination_unbiased() {
        let z = bias_z(combine_training);
        assert!(z.abs() < 4.0, "cross-half weights: z = {z:.2}");
        // The same check rejects weights estimated from the images they weigh.
        let z = bias_z(self_weighted);
        assert!(z < -6.0, "self-estimated weights should bias the mean low: z = {z:.2}");
    }

    #[test]
    fn halves_too_small_to_judge_weigh_nothing() {
        let mut sampler = Sampler::new(7, 0, 0);
        let mut f = films(&[1, 2, 8], 4, &mut sampler);
        let last = f.pop().unwrap();
        // The 1- and 2-spp films have no half of two samples: the last film's halves count.
        let (even, odd) = (last.half(0).unwrap(), last.half(1).unwrap());
        let halves: Vec<[f32; 3]> = even
            .iter()
            .zip(&odd)
            .map(|(e, o)| std::array::from_fn(|k| 0.5 * e.mean()[k] + 0.5 * o.mean()[k]))
            .collect();
        let combined = combine_training(&f, &last);
        for (c, h) in combined.iter().zip(&halves) {
            assert!((c[0] - h[0]).abs() <= 1e-6 * h[0], "{combined:?} against {halves:?}");
        }
        // Where no film has a half of two samples, all samples count alike.
        let mut f = films(&[1, 2, 2], 4, &mut sampler);
        let last = f.pop().unwrap();
        let refs: Vec<&Film> = f.iter().chain([&last]).collect();
        assert_eq!(combine_training(&f, &last), pooled(&refs));
    }
}
