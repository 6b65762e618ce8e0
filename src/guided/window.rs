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
/// Added to the pixel estimate so black pixels do not make every path look too bright.
const PIXEL_FLOOR: f32 = 0.01;

/// The survival (below 1) or splitting (above 1) factor for a path of throughput `beta`
/// (luminance) whose continuation is expected to bring back `adjoint`, in a pixel estimated
/// at `pixel`; 1 when the window leaves the path alone or the estimates are unusable.
#[inline]
pub fn factor(beta: f32, adjoint: f32, pixel: f32) -> f32 {
    if !(beta > 0.0 && adjoint > 0.0 && adjoint.is_finite() && pixel.is_finite() && pixel >= 0.0) {
        return 1.0;
    }
    // Window centre C = I / adjoint; lower bound 2C / (1 + s), upper s times that.
    let centre = (pixel + PIXEL_FLOOR) / adjoint;
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
        // Pixel 1, adjoint 1: window [1/3, 5/3] around the centre 1 (plus the floor).
        assert_eq!(factor(1.0, 1.0, 0.99), 1.0);
        assert!((factor(0.1, 1.0, 0.99) - 0.3).abs() < 1e-6);
        assert!((factor(0.05, 1.0, 0.99) - 0.15).abs() < 1e-6);
        assert!((factor(10.0, 1.0, 0.99) - 6.0).abs() < 1e-5);
        // Clamped both ways, and inert on unusable input.
        assert_eq!(factor(1e-9, 1.0, 1.0), MIN_SURVIVAL);
        assert_eq!(factor(1e9, 1.0, 1.0), MAX_SPLIT);
        assert_eq!(factor(1.0, 0.0, 1.0), 1.0);
        assert_eq!(factor(1.0, f32::NAN, 1.0), 1.0);
        // E[copies(q)] / q = 1 for any q.
        for q in [0.05f32, 0.3, 1.0, 2.5, 8.0] {
            let n = 10_000;
            let total: u32 = (0..n).map(|i| copies(q, (i as f32 + 0.5) / n as f32)).sum();
            assert!((total as f32 / n as f32 / q - 1.0).abs() < 1e-3, "q {q}");
        }
    }
}
