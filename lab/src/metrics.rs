//! Image error metrics against a reference: relMSE, MSE, MAPE and SMAPE per channel and
//! overall, with optional trimming of the worst pixels, as used to compare renderers.
//!
//! Definitions (per pixel p and channel c, image I, reference R, epsilon = 1e-3):
//! relMSE = (I - R)^2 / (R^2 + eps); MSE = (I - R)^2; MAPE = |I - R| / (|R| + eps);
//! SMAPE = 2 |I - R| / (|I| + |R| + eps); each averaged over pixels. Trimming drops the given
//! fraction of pixels with the largest error (per metric and channel) before averaging, so a
//! handful of fireflies do not decide a comparison (VSPG trims 0.01%).
//!
//! A reference is itself a finite render, and its noise adds to every image's relMSE:
//! E[(I - R)^2] = Var I + Var R for independent unbiased I and R. Left in, it pulls every
//! error ratio towards 1 (a 120 s reference caps a 20 s render's measurable gain near 7x).
//! Given the reference's per-pixel standard error s (the `stderr` layer `zerovar reference`
//! writes), [`compare_with_reference_noise`] also reports the reference's share,
//! s^2 / (R^2 + eps) averaged over the same kept pixels, and the excess relMSE (the image's
//! own error) with its standard error over pixels.

use serde::Serialize;

/// The denominator offset of the relative metrics (the renderer's own, so that its
/// error-driven choices and these reports measure alike).
pub use zerovar::math::RELATIVE_EPSILON as EPSILON;

/// One metric per channel and over all channels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PerChannel {
    /// Red, green, blue.
    pub rgb: [f64; 3],
    /// The mean over channels.
    pub all: f64,
}

/// All metrics of one image against a reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageError {
    /// Relative mean squared error.
    pub rel_mse: PerChannel,
    /// The reference's own noise in `rel_mse`, when the reference carries its standard error.
    pub reference_noise: Option<ReferenceNoise>,
    /// Mean squared error.
    pub mse: PerChannel,
    /// Mean absolute percentage error (as a fraction).
    pub mape: PerChannel,
    /// Symmetric mean absolute percentage error (as a fraction, at most 2).
    pub smape: PerChannel,
}

/// The reference noise's share of relMSE, and what is left.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReferenceNoise {
    /// The expected relMSE of the reference against the truth: s^2 / (R^2 + eps), averaged
    /// over the pixels the relMSE kept.
    pub share: PerChannel,
    /// relMSE minus that share: an unbiased estimate of the image's own relMSE. It can come
    /// out negative when the image is far less noisy than the reference.
    pub excess: PerChannel,
    /// The standard error of `excess.all` over pixels (channels taken as fully correlated).
    pub excess_std_error: f64,
}

impl ReferenceNoise {
    /// Whether the excess stands out of its own noise (more than twice its standard error):
    /// only then does a ratio of two excess relMSEs mean anything.
    pub fn resolved(&self) -> bool {
        self.excess.all > 2.0 * self.excess_std_error
    }
}

/// Why two images cannot be compared.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MetricsError {
    /// Different pixel counts.
    #[error(
        "the image has {image} pixels but the reference has {reference}; render both at the same resolution"
    )]
    SizeMismatch {
        /// Pixels of the image.
        image: usize,
        /// Pixels of the reference.
        reference: usize,
    },
    /// The trimmed fraction is outside [0, 0.5).
    #[error("trim fraction {0} must lie in [0, 0.5)")]
    BadTrim(f64),
}

fn metric(
    image: &[[f32; 3]],
    reference: &[[f32; 3]],
    trim: f64,
    f: impl Fn(f64, f64) -> f64,
) -> PerChannel {
    trimmed(image, reference, None, trim, |i, r, _| (f(i, r), 0.0)).0
}

/// Per channel: the trimmed mean of `f(i, r, s).0` (pixels ranked by it), the mean of
/// `f(i, r, s).1` over the same pixels, and the standard error of the mean of their difference.
fn trimmed(
    image: &[[f32; 3]],
    reference: &[[f32; 3]],
    reference_error: Option<&[[f32; 3]]>,
    trim: f64,
    f: impl Fn(f64, f64, f64) -> (f64, f64),
) -> (PerChannel, PerChannel, [f64; 3]) {
    let keep = image.len()
        - ((image.len() as f64 * trim).floor() as usize).min(image.len().saturating_sub(1));
    let mut values = Vec::with_capacity(image.len());
    let mut second = [0.0; 3];
    let mut std_error = [0.0; 3];
    let rgb: [f64; 3] = std::array::from_fn(|c| {
        values.clear();
        values.extend(image.iter().zip(reference).enumerate().map(|(p, (i, r))| {
            let s = reference_error.map_or(0.0, |e| e[p][c] as f64);
            f(i[c] as f64, r[c] as f64, s)
        }));
        if keep < values.len() {
            values.select_nth_unstable_by(keep, |a, b| a.0.total_cmp(&b.0));
        }
        let kept = &values[..keep];
        let n = keep.max(1) as f64;
        let mean = kept.iter().map(|v| v.0).sum::<f64>() / n;
        second[c] = kept.iter().map(|v| v.1).sum::<f64>() / n;
        let d = mean - second[c];
        let var = kept.iter().map(|v| (v.0 - v.1 - d).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        std_error[c] = (var / n).sqrt();
        mean
    });
    let all = |v: [f64; 3]| PerChannel { rgb: v, all: v.iter().sum::<f64>() / 3.0 };
    (all(rgb), all(second), std_error)
}

/// Compares `image` with `reference` (row-major RGB of the same size), dropping the fraction
/// `trim` of worst pixels per metric and channel.
pub fn compare(
    image: &[[f32; 3]],
    reference: &[[f32; 3]],
    trim: f64,
) -> Result<ImageError, MetricsError> {
    compare_with_reference_noise(image, reference, None, trim)
}

/// As [`compare`], and with the reference's per-pixel standard error `reference_error` (same
/// layout) the reference noise's share of relMSE and the excess over it.
pub fn compare_with_reference_noise(
    image: &[[f32; 3]],
    reference: &[[f32; 3]],
    reference_error: Option<&[[f32; 3]]>,
    trim: f64,
) -> Result<ImageError, MetricsError> {
    if image.len() != reference.len() || image.is_empty() {
        return Err(MetricsError::SizeMismatch { image: image.len(), reference: reference.len() });
    }
    if let Some(e) = reference_error
        && e.len() != reference.len()
    {
        return Err(MetricsError::SizeMismatch { image: e.len(), reference: reference.len() });
    }
    if !(0.0..0.5).contains(&trim) {
        return Err(MetricsError::BadTrim(trim));
    }
    let (rel_mse, share, std_error) =
        trimmed(image, reference, reference_error, trim, |i, r, s| {
            let d = r * r + EPSILON;
            ((i - r).powi(2) / d, s * s / d)
        });
    let reference_noise = reference_error.map(|_| ReferenceNoise {
        share,
        excess: PerChannel {
            rgb: std::array::from_fn(|c| rel_mse.rgb[c] - share.rgb[c]),
            all: rel_mse.all - share.all,
        },
        excess_std_error: std_error.iter().sum::<f64>() / 3.0,
    });
    Ok(ImageError {
        rel_mse,
        reference_noise,
        mse: metric(image, reference, trim, |i, r| (i - r).powi(2)),
        mape: metric(image, reference, trim, |i, r| (i - r).abs() / (r.abs() + EPSILON)),
        smape: metric(image, reference, trim, |i, r| {
            2.0 * (i - r).abs() / (i.abs() + r.abs() + EPSILON)
        }),
    })
}

/// Per-pixel relative error |I - R| / (|R| + 0.01), mapped to a false colour (black through
/// red and yellow to white, saturating at 1) for error images.
pub fn false_colour(image: &[[f32; 3]], reference: &[[f32; 3]]) -> Vec<[f32; 3]> {
    image
        .iter()
        .zip(reference)
        .map(|(i, r)| {
            let e: f32 =
                (0..3).map(|c| (i[c] - r[c]).abs() / (r[c].abs() + 0.01)).sum::<f32>() / 3.0;
            let e = if e.is_finite() { e.clamp(0.0, 1.0) } else { 1.0 };
            [(3.0 * e).min(1.0), (3.0 * e - 1.0).clamp(0.0, 1.0), (3.0 * e - 2.0).clamp(0.0, 1.0)]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_match_hand_computed_values() {
        let reference = [[1.0, 0.0, 2.0], [0.5, 0.5, 0.5]];
        let image = [[1.5, 0.0, 2.0], [0.5, 1.0, 0.0]];
        let e = compare(&image, &reference, 0.0).unwrap();
        // red: pixel 1 (0.5^2 / (1 + 1e-3)), pixel 2 0 -> mean over 2 pixels.
        let red = 0.25 / 1.001 / 2.0;
        let green = 0.25 / (0.25 + 1e-3) / 2.0;
        let blue = 0.25 / (0.25 + 1e-3) / 2.0;
        assert!((e.rel_mse.rgb[0] - red).abs() < 1e-12);
        assert!((e.rel_mse.rgb[1] - green).abs() < 1e-12);
        assert!((e.rel_mse.rgb[2] - blue).abs() < 1e-12);
        assert!((e.rel_mse.all - (red + green + blue) / 3.0).abs() < 1e-12);
        assert!((e.mse.rgb[0] - 0.125).abs() < 1e-12);
        assert!((e.mape.rgb[0] - 0.5 / 1.001 / 2.0).abs() < 1e-12);
        assert!((e.smape.rgb[2] - 2.0 * 0.5 / (0.5 + 1e-3) / 2.0).abs() < 1e-12);
        assert_eq!(compare(&image, &image, 0.0).unwrap().rel_mse.all, 0.0);
    }

    #[test]
    fn trimming_removes_only_the_worst_pixels() {
        let reference = vec![[1.0f32; 3]; 10_000];
        let mut image = reference.clone();
        image[17] = [1000.0; 3]; // one firefly
        image[5] = [1.1; 3];
        let full = compare(&image, &reference, 0.0).unwrap();
        let trimmed = compare(&image, &reference, 1e-4).unwrap();
        assert!(full.rel_mse.all > 90.0);
        let expected = 0.01 / 1.001 / 9_999.0;
        assert!((trimmed.rel_mse.all - expected).abs() < 1e-9, "{}", trimmed.rel_mse.all);
        assert!(matches!(
            compare(&image, &reference[..5], 0.0),
            Err(MetricsError::SizeMismatch { .. })
        ));
        assert!(matches!(compare(&image, &reference, 0.5), Err(MetricsError::BadTrim(_))));
    }

    /// Gaussian noise from the crate's sampler (Box-Muller): one standard normal per call.
    fn normal(rng: &mut zerovar::rng::Sampler) -> f64 {
        let u = 1.0 - rng.next_1d() as f64;
        let v = rng.next_1d() as f64;
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    #[test]
    fn reference_noise_is_taken_out_of_relmse() {
        // Truth mu per pixel; a reference with 5% relative noise and its standard error; an
        // image with 10% relative noise. The excess relMSE must estimate the image's own
        // relMSE, mean of s_I^2 / (R^2 + eps), within its reported standard error; the raw
        // relMSE is above it by the reference's share, about 0.05^2.
        let n = 100_000;
        let mut rng = zerovar::rng::Sampler::new(7, 0, 0);
        let mut reference = Vec::with_capacity(n);
        let mut reference_error = Vec::with_capacity(n);
        let mut image = Vec::with_capacity(n);
        let mut own = 0.0;
        for p in 0..n {
            let mu = 0.2 + (p % 97) as f64 / 20.0;
            let (s_ref, s_img) = (0.05 * mu, 0.1 * mu);
            let px = |rng: &mut zerovar::rng::Sampler, s: f64| {
                std::array::from_fn::<f32, 3, _>(|_| (mu + s * normal(rng)) as f32)
            };
            let r = px(&mut rng, s_ref);
            own += (0..3).map(|c| s_img * s_img / ((r[c] as f64).powi(2) + EPSILON)).sum::<f64>()
                / 3.0;
            reference.push(r);
            reference_error.push([s_ref as f32; 3]);
            image.push(px(&mut rng, s_img));
        }
        own /= n as f64;
        let e =
            compare_with_reference_noise(&image, &reference, Some(&reference_error), 0.0).unwrap();
        let noise = e.reference_noise.expect("the reference's error was given");
        let tolerance = 4.0 * noise.excess_std_error;
        assert!(tolerance < 0.05 * own, "standard error {tolerance} too large to test anything");
        assert!((noise.excess.all - own).abs() < tolerance, "{} vs {own}", noise.excess.all);
        assert!((e.rel_mse.all - own).abs() > 5.0 * tolerance, "the share is visible in relMSE");
        assert!((noise.share.all - 0.0025).abs() < 0.0001, "share {}", noise.share.all);
        assert!(noise.resolved());
        assert!(compare(&image, &reference, 0.0).unwrap().reference_noise.is_none());
        assert!(matches!(
            compare_with_reference_noise(&image, &reference, Some(&reference_error[1..]), 0.0),
            Err(MetricsError::SizeMismatch { .. })
        ));
    }
}
