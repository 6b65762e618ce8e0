//! The film: per-pixel running sums in f64 (so millions of samples do not lose precision) of
//! RGB and of squared and cubed luminance, giving the image and per-pixel variance (and
//! skewness) estimates.

use crate::math::{Spectrum, luminance};

/// Accumulated samples of one pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelSum {
    /// Sum of RGB samples.
    pub rgb: [f64; 3],
    /// Sum of squared luminance.
    pub lum_sq: f64,
    /// Sum of cubed luminance (the skewness of a pixel's samples, for statistical tests).
    pub lum_cube: f64,
    /// Sum of squared RGB samples.
    pub rgb_sq: [f64; 3],
    /// Number of samples.
    pub count: u32,
}

impl PixelSum {
    /// Adds one sample.
    #[inline]
    pub fn add(&mut self, c: Spectrum) {
        for (i, v) in c.to_array().into_iter().enumerate() {
            self.rgb[i] += v as f64;
            self.rgb_sq[i] += v as f64 * v as f64;
        }
        let l = luminance(c) as f64;
        self.lum_sq += l * l;
        self.lum_cube += l * l * l;
        self.count += 1;
    }

    /// The samples of this sum that `part` (a sum of some of them) does not hold.
    pub fn without(&self, part: &PixelSum) -> PixelSum {
        PixelSum {
            rgb: std::array::from_fn(|i| self.rgb[i] - part.rgb[i]),
            lum_sq: self.lum_sq - part.lum_sq,
            lum_cube: self.lum_cube - part.lum_cube,
            rgb_sq: std::array::from_fn(|i| self.rgb_sq[i] - part.rgb_sq[i]),
            count: self.count - part.count,
        }
    }

    /// Merges another sum into this one.
    pub fn merge(&mut self, o: &PixelSum) {
        for i in 0..3 {
            self.rgb[i] += o.rgb[i];
            self.rgb_sq[i] += o.rgb_sq[i];
        }
        self.lum_sq += o.lum_sq;
        self.lum_cube += o.lum_cube;
        self.count += o.count;
    }

    /// The unbiased sample variance of one RGB sample (zero with fewer than two samples).
    pub fn variance(&self) -> [f64; 3] {
        if self.count < 2 {
            return [0.0; 3];
        }
        let n = self.count as f64;
        std::array::from_fn(|i| {
            let mean = self.rgb[i] / n;
            (self.rgb_sq[i] / n - mean * mean).max(0.0) * n / (n - 1.0)
        })
    }

    /// The unbiased sample variance of one sample's luminance (zero with fewer than two).
    pub fn luminance_variance(&self) -> f64 {
        if self.count < 2 {
            return 0.0;
        }
        let n = self.count as f64;
        let mean = luminance(Spectrum::from_array(self.mean())) as f64;
        (self.lum_sq / n - mean * mean).max(0.0) * n / (n - 1.0)
    }

    /// The standard error of the mean RGB (zero with fewer than two samples).
    pub fn std_error(&self) -> [f32; 3] {
        let n = self.count.max(1) as f64;
        self.variance().map(|v| (v / n).sqrt() as f32)
    }

    /// The mean RGB.
    pub fn mean(&self) -> [f32; 3] {
        let n = self.count.max(1) as f64;
        self.rgb.map(|s| (s / n) as f32)
    }
}

/// A film of `width * height` pixels.
#[derive(Clone, Debug)]
pub struct Film {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) pixels: Vec<PixelSum>,
    /// Per pixel, the sum of its odd-numbered samples alone, when the film keeps its two
    /// halves apart (empty otherwise): each half's variance can then weigh the other half.
    pub(crate) odd: Vec<PixelSum>,
}

impl Film {
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The pixel sums, row-major, `width * height` of them.
    pub fn pixels(&self) -> &[PixelSum] {
        &self.pixels
    }

    /// An empty film.
    pub fn new(width: u32, height: u32) -> Self {
        let pixels = vec![PixelSum::default(); (width * height) as usize];
        Self { width, height, pixels, odd: Vec::new() }
    }

    /// An empty film that also keeps the sums of odd-numbered samples apart.
    pub fn with_halves(width: u32, height: u32) -> Self {
        let film = Self::new(width, height);
        Self { odd: film.pixels.clone(), ..film }
    }

    /// Per pixel, the sum of the even-numbered (`half` 0) or odd-numbered (1) samples; `None`
    /// when the film does not keep its halves.
    pub fn half(&self, half: usize) -> Option<Vec<PixelSum>> {
        if self.odd.len() != self.pixels.len() {
            return None;
        }
        Some(match half {
            0 => self.pixels.iter().zip(&self.odd).map(|(all, odd)| all.without(odd)).collect(),
            _ => self.odd.clone(),
        })
    }

    /// The image as row-major RGB means.
    pub fn image(&self) -> Vec<[f32; 3]> {
        self.pixels.iter().map(PixelSum::mean).collect()
    }

    /// Mean RGB over all pixels.
    pub fn average(&self) -> [f64; 3] {
        let mut acc = [0.0; 3];
        for p in &self.pixels {
            let m = p.mean();
            for i in 0..3 {
                acc[i] += m[i] as f64;
            }
        }
        acc.map(|a| a / self.pixels.len().max(1) as f64)
    }
}
