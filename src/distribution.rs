//! Discrete distributions sampled by inverting a cumulative table: triangle areas of a mesh,
//! pixels of an environment map, rows and columns of a 2D table.

/// A distribution over indices proportional to non-negative weights.
#[derive(Clone, Debug, Default)]
pub(crate) struct Distribution1D {
    cdf: Vec<f64>,
    total: f64,
}

impl Distribution1D {
    /// A distribution proportional to `weights`; `None` when they sum to zero or any weight is
    /// negative or not finite.
    pub(crate) fn new(weights: impl IntoIterator<Item = f64>) -> Option<Self> {
        let mut acc = 0.0;
        let mut cdf = Vec::new();
        for w in weights {
            if !(w >= 0.0 && w.is_finite()) {
                return None;
            }
            acc += w;
            cdf.push(acc);
        }
        (acc > 0.0).then_some(Self { cdf, total: acc })
    }

    /// Sum of the weights.
    pub(crate) fn total(&self) -> f64 {
        self.total
    }

    /// Probability of index `i`.
    #[inline]
    pub(crate) fn prob(&self, i: usize) -> f64 {
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        (self.cdf[i] - lo) / self.total
    }

    /// Picks an index for `u` in [0, 1); also returns `u` rescaled to [0, 1) within the chosen
    /// interval, so one number can drive a further choice.
    #[inline]
    pub(crate) fn sample(&self, u: f32) -> (usize, f32) {
        let target = u as f64 * self.total;
        // Entries of zero weight have empty intervals and are never chosen.
        let i = self.cdf.partition_point(|&c| c <= target).min(self.cdf.len() - 1);
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let width = self.cdf[i] - lo;
        let rest = if width > 0.0 { ((target - lo) / width).clamp(0.0, 1.0 - 1e-7) } else { 0.5 };
        (i, rest as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_in_proportion_and_skips_zero_weights() {
        let d = Distribution1D::new([1.0, 0.0, 3.0]).unwrap();
        let mut counts = [0usize; 3];
        let n = 40_000;
        for k in 0..n {
            let (i, rest) = d.sample((k as f32 + 0.5) / n as f32);
            assert!((0.0..1.0).contains(&rest));
            counts[i] += 1;
        }
        assert_eq!(counts, [10_000, 0, 30_000]);
        assert_eq!(d.prob(2), 0.75);
        assert!(Distribution1D::new([0.0, 0.0]).is_none());
        assert!(Distribution1D::new([1.0, f64::NAN]).is_none());
    }
}
