//! Image error metrics against a reference: relMSE, MSE, MAPE and SMAPE per channel and
//! overall, with optional trimming of the worst pixels, as used to compare renderers.
//!
//! Definitions (per pixel p and channel c, image I, reference R, epsilon = 1e-3):
//! relMSE = (I - R)^2 / (R^2 + eps); MSE = (I - R)^2; MAPE = |I - R| / (|R| + eps);
//! SMAPE = 2 |I - R| / (|I| + |R| + eps); each averaged over pixels. Trimming drops the given
//! fraction of pixels with the largest error (per metric and channel) before averaging, so a
//! handful of fireflies do not decide a comparison (VSPG trims 0.01%).

use serde::Serialize;

/// The denominator offset of the relative metrics.
pub const EPSILON: f64 = 1e-3;

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
    /// Mean squared error.
    pub mse: PerChannel,
    /// Mean absolute percentage error (as a fraction).
    pub mape: PerChannel,
    /// Symmetric mean absolute percentage error (as a fraction, at most 2).
    pub smape: PerChannel,
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
    let keep = image.len()
        - ((image.len() as f64 * trim).floor() as usize).min(image.len().saturating_sub(1));
    let mut values = Vec::with_capacity(image.len());
    let rgb: [f64; 3] = std::array::from_fn(|c| {
        values.clear();
        values.extend(image.iter().zip(reference).map(|(i, r)| f(i[c] as f64, r[c] as f64)));
        if keep < values.len() {
            values.select_nth_unstable_by(keep, |a, b| a.total_cmp(b));
        }
        values[..keep].iter().sum::<f64>() / keep.max(1) as f64
    });
    PerChannel { rgb, all: rgb.iter().sum::<f64>() / 3.0 }
}

/// Compares `image` with `reference` (row-major RGB of the same size), dropping the fraction
/// `trim` of worst pixels per metric and channel.
pub fn compare(
    image: &[[f32; 3]],
    reference: &[[f32; 3]],
    trim: f64,
) -> Result<ImageError, MetricsError> {
    if image.len() != reference.len() || image.is_empty() {
        return Err(MetricsError::SizeMismatch { image: image.len(), reference: reference.len() });
    }
    if !(0.0..0.5).contains(&trim) {
        return Err(MetricsError::BadTrim(trim));
    }
    Ok(ImageError {
        rel_mse: metric(image, reference, trim, |i, r| (i - r).powi(2) / (r * r + EPSILON)),
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
}
