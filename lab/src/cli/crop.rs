//! `compare`'s `crops.png`: the same window of the reference and of each method's image,
//! magnified side by side, where the noise the methods differ in can be seen.

use anyhow::{Result, bail};

/// Parses `--crop X,Y,W,H` and checks the window lies inside the `w` x `h` image.
pub(super) fn parse_crop(text: &str, w: usize, h: usize) -> Result<CropWindow> {
    let v: Vec<usize> =
        text.split(',').map(|p| p.trim().parse()).collect::<Result<_, _>>().map_err(|_| {
            anyhow::anyhow!("--crop {text}: give X,Y,WIDTH,HEIGHT as four whole numbers of pixels")
        })?;
    let [x, y, cw, ch] = v[..] else {
        bail!("--crop {text}: give X,Y,WIDTH,HEIGHT as four whole numbers of pixels");
    };
    if cw == 0
        || ch == 0
        || x.checked_add(cw).is_none_or(|e| e > w)
        || y.checked_add(ch).is_none_or(|e| e > h)
    {
        bail!("--crop {text}: the window must be non-empty and inside the {w}x{h} image");
    }
    Ok(CropWindow { x, y, w: cw, h: ch })
}

/// A rectangle of pixels.
#[derive(Clone, Copy, Debug)]
pub(super) struct CropWindow {
    x: usize,
    y: usize,
    w: usize,
    h: usize,
}

/// The window, a quarter of the image in each direction on an 8-pixel grid, where `image`'s
/// mean relative squared error against `reference` is largest; each pixel's error is capped
/// at 1 so that a single firefly does not choose the window.
pub(super) fn noisiest_window(
    image: &[[f32; 3]],
    reference: &[[f32; 3]],
    w: usize,
    h: usize,
) -> CropWindow {
    let (cw, ch) = ((w / 4).max(1), (h / 4).max(1));
    let err: Vec<f64> = image
        .iter()
        .zip(reference)
        .map(|(a, r)| {
            let (a, r) = (lum(a), lum(r));
            let e = (a - r) * (a - r) / (r * r + zerovar_lab::metrics::EPSILON);
            if e.is_finite() { e.min(1.0) } else { 1.0 }
        })
        .collect();
    let mut best = (f64::NEG_INFINITY, CropWindow { x: 0, y: 0, w: cw, h: ch });
    for y in (0..=h - ch).step_by(8) {
        for x in (0..=w - cw).step_by(8) {
            let total: f64 =
                (y..y + ch).map(|yy| err[yy * w + x..yy * w + x + cw].iter().sum::<f64>()).sum();
            if total > best.0 {
                best = (total, CropWindow { x, y, w: cw, h: ch });
            }
        }
    }
    best.1
}

fn lum(p: &[f32; 3]) -> f64 {
    f64::from(zerovar::math::luminance(glam::Vec3A::from_array(*p)))
}

/// The `window` of each `w`-wide image side by side with a 2-pixel gap, magnified by a whole
/// factor from 1 to 8 to about 720 pixels in all; returns its width, height and pixels.
pub(super) fn crops(
    images: &[&[[f32; 3]]],
    w: usize,
    window: CropWindow,
) -> (usize, usize, Vec<[f32; 3]>) {
    const GAP: usize = 2;
    let n = images.len();
    let scale = (720 / (n * window.w).max(1)).clamp(1, 8);
    let (cw, ch) = (window.w * scale, window.h * scale);
    let width = n * cw + (n - 1) * GAP;
    let mut out = vec![[1.0f32; 3]; width * ch];
    for (i, img) in images.iter().enumerate() {
        let x0 = i * (cw + GAP);
        for y in 0..ch {
            for x in 0..cw {
                let src = (window.y + y / scale) * w + window.x + x / scale;
                out[y * width + x0 + x] = img[src];
            }
        }
    }
    (width, ch, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_crop_window_is_where_the_error_is() {
        let (w, h) = (64, 48);
        let reference = vec![[0.5f32; 3]; w * h];
        let mut image = reference.clone();
        // Noise in the block at (40, 24) of 16 x 12 (a quarter of the image each way), and one
        // firefly elsewhere, which must not win because each pixel's error is capped.
        for y in 24..36 {
            for x in 40..56 {
                image[y * w + x] = if (x + y) % 2 == 0 { [0.9; 3] } else { [0.1; 3] };
            }
        }
        image[3 * w + 3] = [1e6; 3];
        let c = noisiest_window(&image, &reference, w, h);
        assert_eq!((c.x, c.y, c.w, c.h), (40, 24, 16, 12));
        // Crops of two images side by side, magnified, with the gap between them.
        let (cw, ch, pixels) = crops(&[&reference, &image], w, c);
        let scale = 720 / (2 * 16);
        assert_eq!((cw, ch), (2 * 16 * scale.min(8) + 2, 12 * scale.min(8)));
        assert_eq!(pixels.len(), cw * ch);
        assert_eq!(pixels[0], [0.5; 3]);
        assert_eq!(pixels[cw - 1], image[24 * w + 55]);
    }

    #[test]
    fn crop_windows_outside_the_image_are_refused() {
        assert!(parse_crop("0,0,8,6", 8, 6).is_ok());
        for bad in
            ["1,0,8,6", "0,0,0,1", "0,0,1", "x,0,1,1", "-1,0,1,1", "18446744073709551615,0,1,1"]
        {
            let e = parse_crop(bad, 8, 6).unwrap_err().to_string();
            assert!(e.contains(&format!("--crop {bad}")), "{bad}: {e}");
        }
    }
}
