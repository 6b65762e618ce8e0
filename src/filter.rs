//! Pixel reconstruction filters as Mitsuba 3 defines them (`box`, `tent`, `gaussian`,
//! `mitchell`, `catmullrom`, `lanczos`), drawn by filter importance sampling: a camera
//! sample's film position is drawn from its pixel's filter, exactly proportional to its
//! magnitude by rejection. A pixel's mean is then the filter-weighted average of radiance over
//! its footprint, which is what Mitsuba's film converges to when it splats every sample into
//! its neighbours. The footprint is cut at the image's edges, as Mitsuba's film drops what
//! falls outside the image and divides by the weight that fell inside.
//!
//! Samples of the filters without negative lobes weigh one. Where a filter is negative the
//! sample carries its sign, and every sample of a filter with negative lobes the ratio of the
//! footprint's integral of `|f|` to that of `f` (per axis, from a table of both integrals
//! built once per camera), so that the weighted samples average to the filter's mean.

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
    /// The Mitchell-Netravali cubic of radius 2, with negative lobes (B = C = 1/3 by default;
    /// Mitsuba's `catmullrom` is B = 0, C = 1/2).
    Mitchell {
        /// The cubic's B.
        #[serde(default = "third")]
        b: f32,
        /// The cubic's C.
        #[serde(default = "third")]
        c: f32,
    },
    /// `sinc(x) sinc(x / lobes)` within `lobes` pixels (3 by default), with negative lobes.
    Lanczos {
        /// The lobes on each side, which is the radius in pixels.
        #[serde(default = "three")]
        lobes: u32,
    },
}

fn one() -> f32 {
    1.0
}

fn half() -> f32 {
    0.5
}

fn third() -> f32 {
    1.0 / 3.0
}

fn three() -> u32 {
    3
}

/// The most trials of the rejection sampler for one draw. Each is accepted with probability at
/// least [`MIN_ACCEPTANCE`] (a footprint cut at the image's edges keeps its centre, where the
/// filter is largest, and accepts more often), so 1024 all fail with probability below 1e-46;
/// the last offset is then kept.
const MAX_TRIALS: u32 = 1024;

/// The lowest acceptance rate of the rejection sampler over a filter's whole width that a
/// camera takes ([`FilterTable::new`] refuses wider filters): the 3-lobed Lanczos filter
/// accepts 0.22, the Gaussian 0.3, an 8-lobed Lanczos filter 0.11.
pub const MIN_ACCEPTANCE: f32 = 0.1;

impl PixelFilter {
    /// How far from the pixel's centre its weight reaches, in pixels.
    pub fn radius(&self) -> f32 {
        match *self {
            Self::Box => 0.5,
            Self::Tent { radius } => radius,
            Self::Gaussian { stddev } => 4.0 * stddev,
            Self::Mitchell { .. } => 2.0,
            Self::Lanczos { lobes } => lobes as f32,
        }
    }

    /// Whether the filter is negative anywhere (its samples then carry signed weights).
    pub fn has_negative_lobes(&self) -> bool {
        matches!(self, Self::Mitchell { .. } | Self::Lanczos { .. })
    }

    /// How `zerovar check` names the filter.
    pub fn describe(&self) -> String {
        match *self {
            Self::Box => "box".to_string(),
            Self::Tent { radius } => format!("tent (radius {radius})"),
            Self::Gaussian { stddev } => format!("gaussian (stddev {stddev})"),
            Self::Mitchell { b, c } => format!("mitchell (B {b}, C {c})"),
            Self::Lanczos { lobes } => format!("lanczos ({lobes} lobes)"),
        }
    }

    /// The filter's weight at offset `x` from a pixel's centre, as Mitsuba's film weighs
    /// samples: the filter's value at the last of [`STEPS`] equal steps over its radius that
    /// `|x|` has passed, zero from the radius on (the box: one within half a pixel).
    pub fn eval(&self, x: f32) -> f32 {
        let x = x.abs();
        if *self == Self::Box {
            return if x <= 0.5 { 1.0 } else { 0.0 };
        }
        let r = self.radius();
        if x >= r {
            return 0.0;
        }
        let step = (x * (STEPS as f32 / r)).floor().min(STEPS as f32 - 1.0);
        self.profile(step * r / STEPS as f32)
    }

    /// The filter's own curve at `x` within its radius.
    fn profile(&self, x: f32) -> f32 {
        let r = self.radius();
        match *self {
            Self::Box => 1.0,
            Self::Tent { radius } => (1.0 - x / radius).max(0.0),
            Self::Gaussian { stddev } => {
                let a = -0.5 / (stddev * stddev);
                ((a * x * x).exp() - (a * r * r).exp()).max(0.0)
            }
            Self::Mitchell { b, c } => {
                let (x2, x3) = (x * x, x * x * x);
                let v = if x < 1.0 {
                    (12.0 - 9.0 * b - 6.0 * c) * x3
                        + (-18.0 + 12.0 * b + 6.0 * c) * x2
                        + (6.0 - 2.0 * b)
                } else {
                    (-b - 6.0 * c) * x3
                        + (6.0 * b + 30.0 * c) * x2
                        + (-12.0 * b - 48.0 * c) * x
                        + (8.0 * b + 24.0 * c)
                };
                v / 6.0
            }
            Self::Lanczos { .. } => {
                // sin(pi x) sin(pi x / r) / (pi x)(pi x / r), which tends to 1 at 0.
                let (a, b) = (std::f32::consts::PI * x, std::f32::consts::PI * x / r);
                if a < 1e-4 { 1.0 } else { a.sin() * b.sin() / (a * b) }
            }
        }
    }
}

/// Steps of a filter over its radius: Mitsuba's film weighs each sample by a table of the
/// filter at 31 points per radius (`eval_discretized`, checked with Mitsuba 3.9's Python
/// module), so its images converge to that step function's average, not the curve's.
pub const STEPS: usize = 31;

/// What drawing from a filter needs, computed once per camera: a bound of `|f|`, and for the
/// filters with negative lobes the integrals of `|f|` and of `f` from 0 to each half-integer
/// offset below the radius and to the radius, where the image's edges can cut a footprint.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterTable {
    filter: PixelFilter,
    /// At least the largest `|f|`: the rejection sampler's envelope.
    peak: f32,
    /// `(integral of |f|, integral of f)` from 0 to `j + 1/2` for each `j + 1/2` below the
    /// radius, then to the radius.
    integrals: Vec<(f64, f64)>,
}

impl FilterTable {
    /// The table of `filter`, or why the filter cannot be drawn from: one whose integral over
    /// some footprint the image's edges can leave is not positive (no weighting can then make a
    /// pixel its average), or whose rejection sampler would accept less than
    /// [`MIN_ACCEPTANCE`] of its proposals.
    pub fn new(filter: PixelFilter) -> Result<Self, String> {
        let r = f64::from(filter.radius());
        // The filter is a step function: its integrals are exact sums over the steps.
        let (steps, width) =
            if filter == PixelFilter::Box { (1, 0.5) } else { (STEPS, r / STEPS as f64) };
        let value = |k: usize| f64::from(filter.eval(((k as f64 + 0.5) * width) as f32));
        let integral = |b: f64| {
            (0..steps).fold((0.0, 0.0), |(abs, signed), k| {
                let part = (b.min((k + 1) as f64 * width) - k as f64 * width).max(0.0);
                (abs + value(k).abs() * part, signed + value(k) * part)
            })
        };
        let mut ends: Vec<f64> = (0..).map(|j| f64::from(j) + 0.5).take_while(|&e| e < r).collect();
        ends.push(r);
        let integrals = ends.iter().map(|&e| integral(e)).collect();
        let peak = (0..steps).map(|k| value(k).abs()).fold(0.0, f64::max) as f32;
        let table = Self { filter, peak, integrals };
        let (abs, _) = table.integral(r as f32);
        let acceptance = 2.0 * abs / (2.0 * r * f64::from(peak));
        if acceptance < f64::from(MIN_ACCEPTANCE) {
            return Err(format!(
                "the {} pixel filter is too wide for its weight: a sample would be accepted \
                 {:.3} of the time (at least {MIN_ACCEPTANCE} is needed)",
                filter.describe(),
                acceptance
            ));
        }
        // Every footprint an edge can cut: from -a to b, a and b half-integers or the radius.
        let last = table.integrals.len();
        for i in 0..last {
            for j in 0..last {
                if table.integrals[i].1 + table.integrals[j].1 <= 1e-6 * abs {
                    return Err(format!(
                        "the {} pixel filter's weights sum to zero or less over a pixel's \
                         footprint cut by the image's edges: no weighting averages that pixel",
                        filter.describe()
                    ));
                }
            }
        }
        Ok(table)
    }

    /// The filter.
    pub fn filter(&self) -> PixelFilter {
        self.filter
    }

    /// `(integral of |f|, integral of f)` from 0 to `b`, a half-integer below the radius or
    /// anything from the radius on.
    fn integral(&self, b: f32) -> (f64, f64) {
        let last = self.integrals.len() - 1;
        if b >= self.filter.radius() {
            return self.integrals[last];
        }
        self.integrals[((b - 0.5).round().max(0.0) as usize).min(last)]
    }

    /// A film position for a sample of pixel `pixel` of an image of `resolution` pixels, and
    /// the sample's weight: uniform in the pixel for the box filter (two numbers from
    /// `sampler`), else drawn from the filter's magnitude around the pixel's centre, cut at
    /// the image's edges; the weight is one but for the filters with negative lobes.
    pub fn film_sample(
        &self,
        pixel: [u32; 2],
        resolution: [u32; 2],
        sampler: &mut Sampler,
    ) -> (Vec2, f32) {
        if self.filter == PixelFilter::Box {
            return (Vec2::new(pixel[0] as f32, pixel[1] as f32) + sampler.next_2d(), 1.0);
        }
        let (x, wx) = self.axis(pixel[0], resolution[0], sampler);
        let (y, wy) = self.axis(pixel[1], resolution[1], sampler);
        (Vec2::new(x, y), wx * wy)
    }

    /// A coordinate along one axis, for pixel `p` of `n`, and its weight.
    fn axis(&self, p: u32, n: u32, sampler: &mut Sampler) -> (f32, f32) {
        let centre = p as f32 + 0.5;
        let r = self.filter.radius();
        let (lo, hi) = ((-r).max(-centre), r.min(n as f32 - centre));
        let x = self.offset(lo, hi, sampler);
        if !self.filter.has_negative_lobes() {
            return (centre + x, 1.0);
        }
        let ((a0, s0), (a1, s1)) = (self.integral(-lo), self.integral(hi));
        let weight = ((a0 + a1) / (s0 + s1)) as f32;
        (centre + x, if self.filter.eval(x) < 0.0 { -weight } else { weight })
    }

    /// An offset in `[lo, hi]` with density proportional to the filter's magnitude there:
    /// uniform proposals accepted with probability `|f(x)| / peak`.
    fn offset(&self, lo: f32, hi: f32, sampler: &mut Sampler) -> f32 {
        let mut x = 0.0;
        for _ in 0..MAX_TRIALS {
            let [u, v] = sampler.next_2d().to_array();
            x = (lo + u * (hi - lo)).clamp(lo, hi);
            if v * self.peak < self.filter.eval(x).abs() {
                return x;
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zerovar_testkit::{MeanEstimate, chi2_1d, integrate_1d};

    /// Each filter's weights against Mitsuba 3.9.1's own (`eval_discretized` of its
    /// Python module, the table its film weighs samples by), at offsets inside and between its
    /// steps, just inside its radius and at it. Mitsuba's Gaussian differs in the fourth
    /// decimal: its exponential is an approximation (its `eval(0)` is 0.99925, not 1 - e^-8).
    #[test]
    fn filters_are_mitsubas() {
        let at = [0.0f32, 0.3, 0.7, 1.2, 1.5, 2.6];
        let cases: [(PixelFilter, [f32; 6], f32, f32); 6] = [
            (
                PixelFilter::Mitchell { b: 1.0 / 3.0, c: 1.0 / 3.0 },
                [0.888_888_96, 0.775_745_1, 0.369_716_5, -0.005_042_539, -0.035_327_725, 0.0],
                -0.001_282_808,
                1e-6,
            ),
            (
                PixelFilter::Mitchell { b: 0.0, c: 0.5 },
                [1.0, 0.859_286_4, 0.362_223_57, -0.056_728_523, -0.064_449_31, 0.0],
                -0.001_946_926,
                1e-6,
            ),
            (
                PixelFilter::Lanczos { lobes: 3 },
                [1.0, 0.853_712_2, 0.366_151_93, -0.102_574_63, -0.142_404_87, 0.023_270_734],
                0.001_092_199,
                1e-6,
            ),
            (
                PixelFilter::Lanczos { lobes: 2 },
                [1.0, 0.869_712_7, 0.370_937_8, -0.070_594_45, -0.066_618_36, 0.0],
                -0.001_101_63,
                1e-6,
            ),
            (
                PixelFilter::Gaussian { stddev: 0.5 },
                [0.999_247_1, 0.874_983_3, 0.434_683_08, 0.067_070_5, 0.011_879_71, 0.0],
                0.000_220_787,
                6e-4,
            ),
            (
                PixelFilter::Tent { radius: 1.5 },
                [1.0, 0.806_451_6, 0.548_387_05, 0.225_806_47, 0.0, 0.0],
                0.032_258_034,
                1e-6,
            ),
        ];
        for (filter, mitsuba, near_radius, tolerance) in cases {
            for (x, expected) in at.iter().zip(mitsuba) {
                let got = filter.eval(*x);
                assert!((got - expected).abs() <= tolerance, "{filter:?} at {x}: {got}");
                assert_eq!(filter.eval(-*x), got, "{filter:?} at -{x}");
            }
            let r = filter.radius();
            let got = filter.eval(r - 1e-4);
            assert!((got - near_radius).abs() <= tolerance, "{filter:?} near r: {got}");
            assert_eq!(filter.eval(r), 0.0, "{filter:?} at its radius");
        }
        assert_eq!(PixelFilter::Box.eval(0.5), 1.0);
        assert_eq!(PixelFilter::Box.eval(0.51), 0.0);
    }

    /// `integral g(x, f(x)) dx` over `[lo, hi]`, exactly for a filter's steps: the steps'
    /// edges split the range, and so does `split` (where `g` jumps).
    fn step_integral(
        filter: PixelFilter,
        (lo, hi): (f64, f64),
        split: f64,
        g: &dyn Fn(f64, f64) -> f64,
    ) -> f64 {
        let r = f64::from(filter.radius());
        let width = r / STEPS as f64;
        let mut cuts: Vec<f64> = (-(STEPS as i32)..=STEPS as i32)
            .map(|k| f64::from(k) * width)
            .chain([lo, hi, split])
            .filter(|&x| x >= lo && x <= hi)
            .collect();
        cuts.sort_by(f64::total_cmp);
        cuts.windows(2)
            .map(|c| {
                let v = f64::from(filter.eval((0.5 * (c[0] + c[1])) as f32));
                integrate_1d(&|x| g(x, v), c[0], c[1], 4)
            })
            .sum()
    }

    /// The offset of a film sample from its pixel's centre, and its weight, along one axis.
    fn offsets(
        table: &FilterTable,
        pixel: [u32; 2],
        resolution: [u32; 2],
        axis: usize,
        n: usize,
    ) -> Vec<(f64, f64)> {
        let mut sampler = Sampler::new(7, u64::from(pixel[0]), u64::from(pixel[1]));
        let centre = f64::from(pixel[axis]) + 0.5;
        (0..n)
            .map(|_| {
                let (p, w) = table.film_sample(pixel, resolution, &mut sampler);
                (f64::from(p[axis]) - centre, f64::from(w))
            })
            .collect()
    }

    /// Film positions follow the filter's magnitude, cut at the image's edges, for a pixel
    /// inside the image and pixels at both corners: per axis, a chi-square test of the offsets
    /// from the pixel's centre against `|f|` normalised over the footprint inside the image
    /// (whose integral, as the test's expected fraction, must be 1). Filters without negative
    /// lobes give every sample a weight of one.
    #[test]
    fn film_positions_follow_the_filter_cut_at_the_edges() {
        let resolution = [5, 3];
        for filter in [
            PixelFilter::Gaussian { stddev: 0.5 },
            PixelFilter::Gaussian { stddev: 0.3 },
            PixelFilter::Tent { radius: 1.0 },
            PixelFilter::Tent { radius: 2.5 },
            PixelFilter::Mitchell { b: 1.0 / 3.0, c: 1.0 / 3.0 },
            PixelFilter::Mitchell { b: 0.0, c: 0.5 },
            PixelFilter::Lanczos { lobes: 3 },
            PixelFilter::Lanczos { lobes: 2 },
        ] {
            let table = FilterTable::new(filter).unwrap();
            for pixel in [[2, 1], [0, 0], [4, 2]] {
                for axis in 0..2 {
                    let samples = offsets(&table, pixel, resolution, axis, 100_000);
                    let centre = f64::from(pixel[axis]) + 0.5;
                    let r = f64::from(filter.radius());
                    let (lo, hi) = ((-r).max(-centre), r.min(f64::from(resolution[axis]) - centre));
                    let f = |x: f64| f64::from(filter.eval(x as f32)).abs();
                    let total = step_integral(filter, (lo, hi), lo, &|_, v| v.abs());
                    let xs: Vec<f64> = samples.iter().map(|s| s.0).collect();
                    // Bins on the filter's steps, where its density is constant.
                    let width = r / STEPS as f64;
                    let mut edges: Vec<f64> = (-(STEPS as i32)..=STEPS as i32)
                        .map(|k| f64::from(k) * width)
                        .filter(|&x| x > lo && x < hi)
                        .chain([lo, hi])
                        .collect();
                    edges.sort_by(f64::total_cmp);
                    let outcome = chi2_1d(&xs, &|x| f(x) / total, &edges, &[]);
                    let what = format!("{filter:?} pixel {pixel:?} axis {axis}");
                    outcome.assert_pass(1e-4, &what);
                    assert!((outcome.expected_fraction - 1.0).abs() < 1e-4, "{what}: {outcome:?}");
                    if !filter.has_negative_lobes() {
                        assert!(samples.iter().all(|s| s.1 == 1.0), "{what}");
                    }
                }
            }
        }
    }

    /// With negative lobes, the weighted samples average to the filter's mean of a function
    /// over the footprint: `integral f g / integral f`, for `g` 1 (the weights' mean must be 1,
    /// so a pixel keeps its brightness), a ramp and a step, inside the image and at its
    /// corners, where the cut footprint's integrals come from the table. Each to 4.5 standard
    /// errors, each standard error below 0.3% of the answer's scale.
    #[test]
    fn signed_filter_samples_average_to_the_filters_mean() {
        let resolution = [6, 1];
        for filter in [
            PixelFilter::Mitchell { b: 1.0 / 3.0, c: 1.0 / 3.0 },
            PixelFilter::Mitchell { b: 0.0, c: 0.5 },
            PixelFilter::Lanczos { lobes: 3 },
        ] {
            let table = FilterTable::new(filter).unwrap();
            for (pixel, axis) in [([3, 0], 0), ([0, 0], 0), ([5, 0], 0), ([2, 0], 1)] {
                let samples = offsets(&table, pixel, resolution, axis, 400_000);
                let centre = f64::from(pixel[axis]) + 0.5;
                let r = f64::from(filter.radius());
                let (lo, hi) = ((-r).max(-centre), r.min(f64::from(resolution[axis]) - centre));
                let norm = step_integral(filter, (lo, hi), lo, &|_, v| v);
                let tests: [(&str, &dyn Fn(f64) -> f64); 3] =
                    [("one", &|_| 1.0), ("ramp", &|x| 2.0 + x), ("step", &|x| f64::from(x > 0.3))];
                for (name, g) in tests {
                    let expected = step_integral(filter, (lo, hi), 0.3, &|x, v| v * g(x)) / norm;
                    let est: MeanEstimate = samples.iter().map(|(x, w)| w * g(*x)).collect();
                    let what = format!("{filter:?}, pixel {pixel:?} axis {axis}, {name}");
                    assert!(est.std_error() < 3e-3 * expected.abs().max(1.0), "{what}: {est:?}");
                    est.assert_matches(expected, 4.5, &what);
                }
            }
        }
    }

    /// Filters whose cut footprints can sum to zero, and Lanczos filters too wide for the
    /// rejection sampler, are refused.
    #[test]
    fn filters_that_cannot_average_a_pixel_are_refused() {
        // B = 10: the cubic dips below zero so far that a footprint cut to 0.5 on one side
        // sums to less than nothing.
        assert!(FilterTable::new(PixelFilter::Mitchell { b: 10.0, c: 0.0 }).is_err());
        assert!(FilterTable::new(PixelFilter::Mitchell { b: 1.0, c: 0.0 }).is_ok());
        assert!(FilterTable::new(PixelFilter::Lanczos { lobes: 8 }).is_ok());
        assert!(FilterTable::new(PixelFilter::Lanczos { lobes: 16 }).is_err());
    }

    /// The box filter keeps the film position uniform in the pixel, from exactly two numbers.
    #[test]
    fn the_box_filter_is_the_pixel_itself() {
        let mut a = Sampler::new(3, 1, 2);
        let mut b = Sampler::new(3, 1, 2);
        let table = FilterTable::new(PixelFilter::Box).unwrap();
        let (p, w) = table.film_sample([4, 6], [8, 8], &mut a);
        assert_eq!((p, w), (Vec2::new(4.0, 6.0) + b.next_2d(), 1.0));
        assert_eq!(a.next_1d(), b.next_1d());
    }
}
