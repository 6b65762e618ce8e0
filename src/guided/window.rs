//! Guided Russian roulette and splitting by weight windows (Vorba and Krivanek 2016).
//!
//! A path whose expected contribution `beta * adjoint` is far below the pixel's estimated
//! value is rouletted, one far above it is split, so every path carries about the pixel value
//! (the zero-variance ideal). The survival factor is clamped so that a poor cache (zero, or
//! wrong by orders of magnitude) can neither end paths it should not nor split without bound.

/// Ratio of the window's upper to lower bound (s = 5 in ADRRS).
const SPREAD: f32 = 5.0;
/// Smallest survival probability: a cache that claims zero cannot end every path.
pub const MIN_SURVIVAL: f32 = 0.1;
/// Largest splitting factor at one decision.
pub const MAX_SPLIT: f32 = 8.0;
/// Share of the image's mean estimate added to every pixel's (see [`floor`]).
pub const FLOOR_SHARE: f32 = 1.0;

/// What every pixel's estimate gets added, so that black and near-black pixels do not make
/// every path look too bright and split without end: a share of the image's mean, never a
/// constant, so that the windows (and with them every guided decision) do not depend on the
/// scene's units (an absolute floor made a dimly lit scene worse than unguided). The whole
/// mean rouletted more of the dim pixels' paths than half of it did, and they were cheaper
/// for about as much error; smaller and larger shares were worse (see docs/experiments.md).
pub fn floor(estimates: &[f32]) -> f32 {
    if estimates.is_empty() {
        return 0.0;
    }
    let sum: f64 = estimates.iter().map(|&e| f64::from(e)).sum();
    FLOOR_SHARE * (sum / estimates.len() as f64) as f32
}

/// The survival (below 1) or splitting (above 1) factor for a path of throughput `beta`
/// (luminance) whose continuation is expected to bring back `adjoint`, in a pixel estimated
/// at `pixel` ([`floor`] included); 1 when the window leaves the path alone or the estimates
/// are unusable.
#[inline]
pub fn factor(beta: f32, adjoint: f32, pixel: f32) -> f32 {
    if !(beta > 0.0 && adjoint > 0.0 && adjoint.is_finite() && pixel.is_finite() && pixel >= 0.0) {
        return 1.0;
    }
    // Window centre C = I / adjoint; lower bound 2C / (1 + s), upper s times that.
    let centre = pixel / adjoint;
    let lower = 2.0 * centre / (1.0 + SPREAD);
    let upper = SPREAD * lower;
    let q = if beta < lower {
        beta / lower
    } else if beta > upper {
        beta / upper
    } else {
        1.0
    };
    if q.is_finite() { q.clamp(MIN_SURVIVAL, MAX_SPLIT) } else { 1.0 }
}

/// How many copies continue for factor `q` (stochastic rounding, `u` in [0, 1)); each copy
/// is weighted by 1 / q, so the expected weight is unchanged.
#[inline]
pub fn copies(q: f32, u: f32) -> u32 {
    // q + u can round up to the next integer in f32 (64 + 0.99999994 is 65): never more than
    // ceil(q) copies.
    ((q + u).floor() as u32).min(q.ceil() as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_roulettes_low_splits_high_and_keeps_expectation() {
        // Pixel 1, adjoint 1: window [1/3, 5/3] around the centre 1.
        assert_eq!(factor(1.0, 1.0, 1.0), 1.0);
        assert!((factor(0.1, 1.0, 1.0) - 0.3).abs() < 1e-6);
        assert!((factor(0.05, 1.0, 1.0) - 0.15).abs() < 1e-6);
        assert!((factor(10.0, 1.0, 1.0) - 6.0).abs() < 1e-5);
        // The window scales with the pixel and inversely with the adjoint.
        assert_eq!(factor(0.1, 4.0, 4.0), factor(0.1, 1.0, 1.0));
        assert_eq!(factor(0.1 * 1024.0, 1.0, 1024.0), factor(0.1, 1.0, 1.0));
        // Clamped both ways, and inert on unusable input.
        assert_eq!(factor(1e-9, 1.0, 1.0), MIN_SURVIVAL);
        assert_eq!(factor(1e9, 1.0, 1.0), MAX_SPLIT);
        assert_eq!(factor(1.0, 0.0, 1.0), 1.0);
        assert_eq!(factor(1.0, f32::NAN, 1.0), 1.0);
        // A black image (no floor to lift it) leaves paths alone rather than splitting all.
        assert_eq!(factor(1.0, 1.0, 0.0), 1.0);
        assert_eq!(floor(&[0.0; 4]), 0.0);
        assert_eq!(floor(&[1.0, 3.0]), 2.0 * FLOOR_SHARE);
        // E[copies(q)] / q = 1 for any q.
        for q in [0.05f32, 0.3, 1.0, 2.5, 8.0] {
            let n = 10_000;
            let total: u32 = (0..n).map(|i| copies(q, (i as f32 + 0.5) / n as f32)).sum();
            assert!((total as f32 / n as f32 / q - 1.0).abs() < 1e-3, "q {q}");
        }
    }
}
