//! Branch-free single-precision functions for loops over lobes that the compiler vectorises.
//!
//! Sampling distributions evaluate 8 to 32 vMF lobes per query, each with an exponential;
//! libm's `expf` is a call per lobe that no loop around it can vectorise, and it was a third
//! of a guided render's time. The functions here are plain arithmetic with selects in place of
//! branches, so a loop over a block of [`LANES`] lobes becomes vector code. Their accuracy
//! (a few ulps, measured in the tests) matters little to guiding, whose distributions only
//! need to be evaluated consistently with how they are sampled: every density and weight of a
//! lobe set is computed with these same functions.

/// Lobes per block: lobe sets are stored and evaluated in blocks of this many lanes.
pub(crate) const LANES: usize = 8;

/// Arguments are clamped to `[-EXP_LIMIT, EXP_LIMIT]`: at the lower end `2^n` is built with a
/// zero exponent field, which is exactly 0, and at the upper end it stays finite (lobe
/// exponents are never positive anyway).
const EXP_LIMIT: f32 = 88.0;

/// `e^x` to within 2 ulps for normal results up to `e^88`; 0 below about -87.7 (and for
/// NaN), subnormal between there and the smallest normal result.
///
/// Cody-Waite reduction `x = n ln 2 + r`, `|r| <= ln 2 / 2`, then a degree-6 polynomial for
/// `e^r` (the classic single-precision minimax coefficients) and `2^n` built in the exponent.
/// No branch, select or float-to-int conversion: `n` is read off the bits of the rounding sum.
#[inline(always)]
pub(crate) fn exp(x: f32) -> f32 {
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that n * LN2_HI is exact for |n| < 2^9.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5 * 2^23: adding it rounds to an integer, which then sits in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    // `max` first: it maps NaN to the lower limit (where `clamp` would keep NaN).
    #[allow(clippy::manual_clamp)]
    let xc = x.max(-EXP_LIMIT).min(EXP_LIMIT);
    let shifted = xc * LOG2_E + ROUND;
    let n = shifted - ROUND;
    let r = xc - n * LN2_HI - n * LN2_LO;
    let p = 1.987_569_1e-4;
    let p = p * r + 1.398_199_9e-3;
    let p = p * r + 8.333_452e-3;
    let p = p * r + 4.166_579_6e-2;
    let p = p * r + 0.166_666_65;
    let p = p * r + 0.5;
    let poly = p * r * r + r + 1.0;
    // n + 127 in [0, 254]: the bits of 2^n, or of +0 for n = -127.
    let biased = shifted.to_bits().wrapping_sub(ROUND.to_bits()).wrapping_add(127);
    poly * f32::from_bits(biased << 23)
}

/// `(1 - e^{-y}) / y` for `y >= 0`, to a few ulps, with the limit 1 at 0: the vMF
/// normalisation is `1 / (4 pi s(2 kappa))`.
///
/// Below 1/2 the subtraction would cancel, so a Taylor series is used (its first omitted
/// term is below 1.3e-7 relative there).
#[inline(always)]
pub(crate) fn one_minus_exp_neg_over(y: f32) -> f32 {
    let series = 1.0
        + y * (-1.0 / 2.0
            + y * (1.0 / 6.0
                + y * (-1.0 / 24.0 + y * (1.0 / 120.0 + y * (-1.0 / 720.0 + y * (1.0 / 5040.0))))));
    let ys = y.max(0.5);
    let direct = (1.0 - exp(-ys)) / ys;
    if y < 0.5 { series } else { direct }
}

/// The mean cosine `A(kappa) = coth(kappa) - 1/kappa` of a vMF lobe, to 2e-6 relative
/// (`vmf::mean_cosine` is the accurate one): a series below 1/2, where `coth` and `1/kappa`
/// cancel, and `1 + 2 e / (1 - e) - 1/kappa` with `e = e^{-2 kappa}` above, where terms of
/// about 2 cancel to 0.16 at the switch (four bits lost).
#[inline(always)]
pub(crate) fn mean_cosine(kappa: f32) -> f32 {
    let k2 = kappa * kappa;
    let series = kappa * (1.0 / 3.0 - k2 * (1.0 / 45.0 - k2 * (2.0 / 945.0 - k2 * (1.0 / 4725.0))));
    let ks = kappa.max(0.5);
    let e = exp(-2.0 * ks);
    let direct = 1.0 + 2.0 * e / (1.0 - e) - 1.0 / ks;
    if kappa < 0.5 { series } else { direct }
}

/// The Henyey-Greenstein density at `cos` for `|g| <= 0.99` (`hg::hg_pdf` in single precision
/// and without a call).
///
/// `1 + g^2 - 2 g cos` is summed as `(1 - |g|)^2 + 2 |g| (1 - sign(g) cos)`, two terms that
/// are never negative, so the peak of a sharp lobe keeps its digits.
#[inline(always)]
pub(crate) fn hg_pdf(cos: f32, g: f32) -> f32 {
    let a = g.abs();
    let denom =
        ((1.0 - a) * (1.0 - a) + 2.0 * a * (1.0 - 1.0f32.copysign(g) * cos)).max(f32::MIN_POSITIVE);
    (1.0 - g * g) * (0.25 / std::f32::consts::PI) / (denom * denom.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The error of `got` in units in the last place of the f32 nearest `want`.
    fn ulps(got: f32, want: f64) -> f64 {
        let w = (want as f32).abs().max(f32::MIN_POSITIVE);
        (f64::from(got) - want).abs() / (f64::from(w.next_up()) - f64::from(w))
    }

    #[test]
    fn exp_is_within_two_ulps_and_flushes_below_the_normal_range() {
        let mut worst = 0.0f64;
        let mut x = -87.3f32;
        while x < 88.0 {
            let want = f64::from(x).exp();
            worst = worst.max(ulps(exp(x), want));
            x += 0.000_731;
        }
        for x in [0.0f32, -0.0, 1e-30, -1e-30, -1e-7, 1e-7, 0.346_573_6, -0.346_573_6] {
            worst = worst.max(ulps(exp(x), f64::from(x).exp()));
        }
        assert!(worst <= 2.0, "worst error {worst} ulps");
        assert_eq!(exp(0.0), 1.0);
        for x in [-87.7f32, -100.0, -1e6, f32::NEG_INFINITY, f32::NAN] {
            assert_eq!(exp(x), 0.0, "{x}");
        }
        // Between the normal range and the flush, within the smallest normal of e^x.
        let mut x = -87.7f32;
        while x < -87.3 {
            assert!((f64::from(exp(x)) - f64::from(x).exp()).abs() < f64::from(f32::MIN_POSITIVE));
            x += 1e-3;
        }
        assert_eq!(exp(1e6), exp(88.0));
    }

    #[test]
    fn one_minus_exp_neg_over_is_accurate_on_both_sides_of_the_switch() {
        let mut worst = 0.0f64;
        let mut y = 0.0f32;
        while y < 60.0 {
            let yd = f64::from(y);
            let want = if y == 0.0 { 1.0 } else { -(-yd).exp_m1() / yd };
            worst = worst.max(ulps(one_minus_exp_neg_over(y), want));
            y = if y < 1.0 { y + 1.3e-4 } else { y * 1.001 };
        }
        assert!(worst <= 4.0, "worst error {worst} ulps");
        assert_eq!(one_minus_exp_neg_over(0.0), 1.0);
        assert!((one_minus_exp_neg_over(2e6) - 5e-7).abs() < 1e-12);
    }

    #[test]
    fn mean_cosine_and_hg_agree_with_the_double_precision_ones() {
        let mut k = 0.0f32;
        while k < 1e6 {
            let (got, want) =
                (f64::from(mean_cosine(k)), crate::directional::vmf::mean_cosine_f64(f64::from(k)));
            assert!((got - want).abs() <= 2e-6 * want, "kappa {k}: {got} vs {want}");
            k = if k < 1.0 { k + 1e-3 } else { k * 1.01 };
        }
        for g in [-0.99f32, -0.7, -0.2, 0.0, 0.3, 0.85, 0.99] {
            for i in 0..=200 {
                let cos = -1.0 + 0.01 * i as f32;
                let (got, want) = (hg_pdf(cos, g), crate::directional::hg::hg_pdf(cos, g));
                assert!((got - want).abs() <= 1e-5 * want, "g {g} cos {cos}: {got} vs {want}");
            }
        }
    }
}
