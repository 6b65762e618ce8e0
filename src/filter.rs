//! Pixel reconstruction filters as Mitsuba 3 defines them (`box`, `tent`, `gaussian`), drawn
//! by filter importance sampling: a camera sample's film position is drawn from its pixel's
//! filter, exactly proportional to it by rejection, so every sample weighs one. A pixel's
//! mean is then the filter-weighted average of radiance over its footprint, which is what
//! Mitsuba's film converges to when it splats every sample into its neighbours. The footprint
//! is cut at the image's edges, as Mitsuba's film drops what falls outside the image and
//! divides by the weight that fell inside.

use glam::Vec2;

use crate::rng::Sampler;

/// A separable pixel filter: the film weight of a sample at offset `(x, y)` from a pixel's
/// centre is `f(x) f(y)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum PixelFilter {
    /// 1 within half a pixel: the sample is uniform in its pixel.
    #[default]
    Box,
    /// `max(0, 1 - |x| / radius)` (radius 1 by default).
    Tent {
        /// Half the tent's width, in pixels.
        #[serde(default = "one")]
        radius: f32,
    },
    /// `max(0, exp(-x^2 / (2 stddev^2)) - exp(-radius^2 / (2 stddev^2)))`, radius 4 stddev:
    /// a Gaussian that reaches zero at its radius (stddev 0.5 by default, Mitsuba's default
    /// filter).
    Gaussian {
        /// The standard deviation, in pixels.
        #[serde(default = "half")]
        stddev: f32,
    },
}

fn one() -> f32 {
    1.0
}

fn half() -> f32 {
    0.5
}

/// The most trials of the rejection sampler for one draw. Each is accepted with probability
/// at least 0.3 (the Gaussian over its whole width; a cut footprint or the tent accepts more
/// often), so 256 all fail with probability below 1e-39; the last offset is then kept.
const MAX_TRIALS: u32 = 256;

impl PixelFilter {
    /// How far from the pixel's centre its weight reaches, in pixels.
    pub fn radius(&self) -> f32 {
        match *self {
            Self::Box => 0.5,
            Self::Tent { radius } => radius,
            Self::Gaussian { stddev } => 4.0 * stddev,
        }
    }

    /// The filter's weight at offset `x` from a pixel's centre (largest at the centre).
    pub fn eval(&self, x: f32) -> f32 {
        let r = self.radius();
        if x.abs() > r {
            return 0.0;
        }
        match *self {
            Self::Box => 1.0,
            Self::Tent { radius } => (1.0 - x.abs() / radius).max(0.0),
            Self::Gaussian { stddev } => {
                let a = -0.5 / (stddev * stddev);
                ((a * x * x).exp() - (a * r * r).exp()).max(0.0)
            }
        }
    }

    /// A film position for a sample of pixel `pixel` of an image of `resolution` pixels:
    /// uniform in the pixel for the box filter (two numbers from `sampler`), else drawn from
    /// the filter around the pixel's centre, cut at the image's edges.
    pub fn film_position(
        &self,
        pixel: [u32; 2],
        resolution: [u32; 2],
        sampler: &mut Sampler,
    ) -> Vec2 {
        match self {
            Self::Box => Vec2::new(pixel[0] as f32, pixel[1] as f32) + sampler.next_2d(),
            _ => {
                let axis = |p: u32, n: u32, sampler: &mut Sampler| {
                    let centre = p as f32 + 0.5;
                    let r = self.radius();
                    let (lo, hi) = ((-r).max(-centre), r.min(n as f32 - centre));
                    centre + self.offset(lo, hi, sampler)
                };
                let x = axis(pixel[0], resolution[0], sampler);
                let y = axis(pixel[1], resolution[1], sampler);
                Vec2::new(x, y)
            }
        }
    }

    /// An offset in `[lo, hi]` with density proportional to the filter there: uniform
    /// proposals accepted with probability `f(x) / f(0)`.
    fn offset(&self, lo: f32, hi: f32, sampler: &mut Sampler) -> f32 {
        let (mut x, peak) = (0.0, self.eval(0.0));
        for _ in 0..MAX_TRIALS {
            let [u, v] = sampler.next_2d().to_array();
            x = (lo + u * (hi - lo)).clamp(lo, hi);
            if v * peak < self.eval(x) {
                return x;
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zerovar_testkit::{chi2_1d, integrate_1d};

    #[test]
    fn filters_are_mitsubas() {
        let g = PixelFilter::Gaussian { stddev: 0.5 };
        assert_eq!(g.radius(), 2.0);
        let bias = (-8.0f32).exp();
        assert!((g.eval(0.0) - (1.0 - bias)).abs() < 1e-7);
        assert!((g.eval(0.5) - ((-0.5f32).exp() - bias)).abs() < 1e-7);
        assert_eq!(g.eval(2.0), 0.0);
        assert_eq!(g.eval(-2.5), 0.0);
        let t = PixelFilter::Tent { radius: 1.0 };
        assert_eq!((t.eval(0.25), t.eval(-0.75), t.eval(1.5)), (0.75, 0.25, 0.0));
        assert_eq!(PixelFilter::Box.eval(0.5), 1.0);
    }

    /// Film positions follow the filter, cut at the image's edges, for a pixel inside the
    /// image and pixels at both corners: per axis, a chi-square test of the offsets from the
    /// pixel's centre against the filter normalised over the footprint inside the image
    /// (whose integral, as the test's expected fraction, must be 1).
    #[test]
    fn film_positions_follow_the_filter_cut_at_the_edges() {
        let resolution = [5, 3];
        for filter in [
            PixelFilter::Gaussian { stddev: 0.5 },
            PixelFilter::Gaussian { stddev: 0.3 },
            PixelFilter::Tent { radius: 1.0 },
            PixelFilter::Tent { radius: 2.5 },
        ] {
            for pixel in [[2, 1], [0, 0], [4, 2]] {
                let mut sampler = Sampler::new(7, u64::from(pixel[0]), u64::from(pixel[1]));
                let positions: Vec<Vec2> = (0..100_000)
                    .map(|_| filter.film_position(pixel, resolution, &mut sampler))
                    .collect();
                for axis in 0..2 {
                    let centre = f64::from(pixel[axis]) + 0.5;
                    let r = f64::from(filter.radius());
                    let (lo, hi) = ((-r).max(-centre), r.min(f64::from(resolution[axis]) - centre));
                    let f = |x: f64| f64::from(filter.eval(x as f32));
                    let total = integrate_1d(&f, lo, hi, 4096);
                    let offsets: Vec<f64> =
                        positions.iter().map(|p| f64::from(p[axis]) - centre).collect();
                    let edges: Vec<f64> =
                        (0..=40).map(|k| lo + (hi - lo) * f64::from(k) / 40.0).collect();
                    let outcome = chi2_1d(&offsets, &|x| f(x) / total, &edges, &[]);
                    let what = format!("{filter:?} pixel {pixel:?} axis {axis}");
                    outcome.assert_pass(1e-4, &what);
                    assert!((outcome.expected_fraction - 1.0).abs() < 1e-4, "{what}: {outcome:?}");
                }
            }
        }
    }

    /// The box filter keeps the film position uniform in the pixel, from exactly two numbers.
    #[test]
    fn the_box_filter_is_the_pixel_itself() {
        let mut a = Sampler::new(3, 1, 2);
        let mut b = Sampler::new(3, 1, 2);
        let p = PixelFilter::Box.film_position([4, 6], [8, 8], &mut a);
        assert_eq!(p, Vec2::new(4.0, 6.0) + b.next_2d());
        assert_eq!(a.next_1d(), b.next_1d());
    }
}
