//! Mitsuba's `bitmap` texture: an image of linear RGB reflectances looked up at texture
//! coordinates, bilinearly (Mitsuba's default) or at the nearest texel, with the coordinates
//! repeated, mirrored or clamped outside [0, 1]. Row 0 is the image's top and lies at v = 0,
//! as in Mitsuba (whose OBJ loader flips v to match).

use crate::math::Spectrum;
use glam::Vec2;

/// What happens to texture coordinates outside [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    /// The image tiles the plane (Mitsuba's default).
    Repeat,
    /// Every other tile is mirrored.
    Mirror,
    /// The border texels extend outwards.
    Clamp,
}

/// An image texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Bitmap {
    width: usize,
    height: usize,
    texels: Vec<Spectrum>,
    bilinear: bool,
    wrap: Wrap,
    /// Tiles per unit of uv (Mitsuba's `to_uv` scale).
    scale: Vec2,
    mean: Spectrum,
}

impl Bitmap {
    /// A texture of `width` x `height` texels, row by row from the top; `None` unless the
    /// texels fill the size exactly and the size is not empty.
    pub fn new(
        width: usize,
        height: usize,
        texels: Vec<[f32; 3]>,
        bilinear: bool,
        wrap: Wrap,
        scale: Vec2,
    ) -> Option<Self> {
        if width == 0 || height == 0 || texels.len() != width.checked_mul(height)? {
            return None;
        }
        let texels: Vec<Spectrum> = texels.into_iter().map(Spectrum::from).collect();
        let sum = texels.iter().fold(glam::DVec3::ZERO, |acc, t| acc + t.as_dvec3());
        let mean = (sum / texels.len() as f64).as_vec3a();
        Some(Self { width, height, texels, bilinear, wrap, scale, mean })
    }

    /// The mean over the image.
    pub fn mean(&self) -> Spectrum {
        self.mean
    }

    /// The smallest value of any channel.
    pub fn min(&self) -> f32 {
        self.texels.iter().map(|t| t.min_element()).fold(f32::INFINITY, f32::min)
    }

    /// The largest value of any channel.
    pub fn max(&self) -> f32 {
        self.texels.iter().map(|t| t.max_element()).fold(0.0, f32::max)
    }

    /// The least and greatest of the texels read as one number (`Texture::eval_1`).
    pub fn range_1(&self) -> (f32, f32) {
        self.texels
            .iter()
            .map(|&t| super::luminance_1(t))
            .fold((f32::INFINITY, 0.0f32), |(lo, hi), v| (lo.min(v), hi.max(v)))
    }

    /// The reflectance at texture coordinates `uv`.
    pub fn eval(&self, uv: Vec2) -> Spectrum {
        let p = uv * self.scale * Vec2::new(self.width as f32, self.height as f32);
        if !p.is_finite() {
            return self.mean;
        }
        if !self.bilinear {
            let (x, y) = (p.x.floor() as i64, p.y.floor() as i64);
            return self.texel(x, y);
        }
        let p = p - Vec2::splat(0.5);
        let (fx, fy) = (p.x.floor(), p.y.floor());
        let (wx, wy) = (p.x - fx, p.y - fy);
        let (x, y) = (fx as i64, fy as i64);
        let top = self.texel(x, y) * (1.0 - wx) + self.texel(x + 1, y) * wx;
        let bottom = self.texel(x, y + 1) * (1.0 - wx) + self.texel(x + 1, y + 1) * wx;
        top * (1.0 - wy) + bottom * wy
    }

    fn texel(&self, x: i64, y: i64) -> Spectrum {
        let (x, y) = (self.wrap.index(x, self.width), self.wrap.index(y, self.height));
        self.texels[y * self.width + x]
    }
}

impl Wrap {
    /// The texel index of `i` along an axis of `n` texels.
    fn index(self, i: i64, n: usize) -> usize {
        let n = n as i64;
        let i = match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::Clamp => i.clamp(0, n - 1),
            Wrap::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
        };
        i as usize
    }
}

/// An 8- or 16-bit sRGB-encoded value in [0, 1] made linear (the sRGB transfer curve).
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(bilinear: bool, wrap: Wrap) -> Bitmap {
        // 2 x 2: red, green on top; blue, white below.
        let texels = vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]];
        Bitmap::new(2, 2, texels, bilinear, wrap, Vec2::ONE).unwrap()
    }

    #[test]
    fn nearest_and_bilinear_lookups() {
        let b = image(false, Wrap::Repeat);
        assert_eq!(b.eval(Vec2::new(0.25, 0.25)), Spectrum::new(1.0, 0.0, 0.0), "top left");
        assert_eq!(b.eval(Vec2::new(0.75, 0.25)), Spectrum::new(0.0, 1.0, 0.0), "top right");
        assert_eq!(b.eval(Vec2::new(0.25, 0.75)), Spectrum::new(0.0, 0.0, 1.0), "v grows down");
        assert_eq!(b.eval(Vec2::new(1.25, -0.75)), b.eval(Vec2::new(0.25, 0.25)), "repeats");
        let b = image(true, Wrap::Repeat);
        // Texel centres are exact; the image's centre is the mean of all four.
        assert_eq!(b.eval(Vec2::new(0.25, 0.75)), Spectrum::new(0.0, 0.0, 1.0));
        let centre = b.eval(Vec2::splat(0.5));
        assert!((centre - Spectrum::new(0.5, 0.5, 0.5)).abs().max_element() < 1e-6);
        assert!((b.mean() - Spectrum::new(0.5, 0.5, 0.5)).abs().max_element() < 1e-6);
        // At u = 0 a repeating texture blends the left and right columns.
        let edge = b.eval(Vec2::new(0.0, 0.25));
        assert!((edge - Spectrum::new(0.5, 0.5, 0.0)).abs().max_element() < 1e-6);
        let clamped = image(true, Wrap::Clamp).eval(Vec2::new(0.0, 0.25));
        assert_eq!(clamped, Spectrum::new(1.0, 0.0, 0.0));
        let mirrored = image(false, Wrap::Mirror);
        assert_eq!(mirrored.eval(Vec2::new(1.25, 0.25)), Spectrum::new(0.0, 1.0, 0.0));
        assert!(b.eval(Vec2::new(f32::NAN, 0.0)).is_finite());
    }

    #[test]
    fn srgb_curve_matches_its_definition() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041_14).abs() < 1e-6);
        assert!((srgb_to_linear(0.04) - 0.04 / 12.92).abs() < 1e-9);
    }

    #[test]
    fn sizes_must_match() {
        assert!(Bitmap::new(2, 2, vec![[0.0; 3]; 3], true, Wrap::Repeat, Vec2::ONE).is_none());
        assert!(Bitmap::new(0, 2, vec![], true, Wrap::Repeat, Vec2::ONE).is_none());
    }
}
