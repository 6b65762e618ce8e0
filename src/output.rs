//! Writing images: linear RGB EXR with the render's metadata, and a PNG preview with an
//! exposure and the sRGB transfer curve.

use std::path::Path;

/// What a render records in its EXR header.
#[derive(Clone, Debug)]
pub struct ImageMetadata {
    /// Samples per pixel.
    pub spp: u32,
    /// Seconds of rendering.
    pub seconds: f64,
    /// Seed of the random streams.
    pub seed: u64,
    /// The scene file.
    pub scene: String,
}

/// Why an image could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// EXR encoding or file error.
    #[error("{path}: cannot write EXR: {message}")]
    Exr {
        /// The file.
        path: String,
        /// The reason.
        message: String,
    },
    /// An EXR file that cannot be read, or holds more pixels than [`MAX_EXR_PIXELS`].
    #[error("{path}: cannot read EXR: {message}")]
    Read {
        /// The file.
        path: String,
        /// The reason.
        message: String,
    },
    /// PNG encoding or file error.
    #[error("{path}: cannot write PNG: {message}")]
    Png {
        /// The file.
        path: String,
        /// The reason.
        message: String,
    },
}

/// The most pixels an EXR layer may hold for zerovar to read it (16384 x 8192, 1.5 GiB of RGB):
/// the header's size is checked before any pixel is allocated, so a corrupt header cannot
/// exhaust memory, and it is far above any environment map or reference a render needs.
pub const MAX_EXR_PIXELS: usize = 1 << 27;

/// Refuses an EXR whose header claims more than [`MAX_EXR_PIXELS`] pixels in a layer.
fn check_exr_size(bytes: &[u8]) -> Result<(), String> {
    let meta = exr::meta::MetaData::read_from_buffered(bytes, false).map_err(|e| e.to_string())?;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        if w.checked_mul(h).is_none_or(|n| n > MAX_EXR_PIXELS) {
            return Err(format!(
                "its header claims {w} x {h} pixels, more than the {MAX_EXR_PIXELS} zerovar reads; the file is corrupt, or give a smaller image"
            ));
        }
    }
    Ok(())
}

/// An EXR image: width, height, row-major RGB pixels and, where the file has a layer named
/// `stderr` (as `zerovar reference` writes), its per-pixel standard errors.
pub type ExrImage = (usize, usize, Vec<[f32; 3]>, Option<Vec<[f32; 3]>>);

/// Reads the first RGB(A) layer of an EXR file as row-major pixels: (width, height, pixels).
pub fn read_exr(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>), OutputError> {
    let (w, h, pixels, _) = read_exr_with_error(path)?;
    Ok((w, h, pixels))
}

/// Reads an EXR file's image and, if it has one (as `zerovar reference` writes), its layer
/// named `stderr`. The image is the first RGB(A) layer not named `stderr`; a file with layers
/// that are not RGB (AOVs, depth) gives its first RGB layer and no standard error.
pub fn read_exr_with_error(path: &Path) -> Result<ExrImage, OutputError> {
    let fail = |message: String| OutputError::Read { path: path.display().to_string(), message };
    let bytes = crate::files::read(path).map_err(|e| fail(e.to_string()))?;
    parse_exr(&bytes).map_err(fail)
}

/// [`read_exr_with_error`] of the bytes of an EXR file: an image or a reason, never a panic,
/// and no pixel allocated before the header's size is checked.
pub fn parse_exr(bytes: &[u8]) -> Result<ExrImage, String> {
    use std::io::Cursor;
    check_exr_size(bytes)?;
    use exr::prelude::*;
    type Pixels = (usize, Vec<[f32; 3]>);
    fn create(res: Vec2<usize>, _: &RgbaChannels) -> Pixels {
        (res.width(), vec![[0.0f32; 3]; res.width() * res.height()])
    }
    fn set((w, px): &mut Pixels, pos: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)) {
        px[pos.y() * *w + pos.x()] = [r, g, b];
    }
    let all = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(create, set)
        .all_layers()
        .all_attributes()
        .from_buffered(Cursor::new(bytes));
    let Ok(image) = all else {
        // Layers that are not all RGB: the first RGB one.
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(create, set)
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(bytes))
            .map_err(|e| e.to_string())?;
        let (w, pixels) = image.layer_data.channel_data.pixels;
        return Ok((w, pixels.len() / w.max(1), pixels, None));
    };
    let (mut mean, mut error) = (None, None);
    for layer in image.layer_data {
        let is_error = layer.attributes.layer_name.as_ref().is_some_and(|n| n.eq("stderr"));
        let slot = if is_error { &mut error } else { &mut mean };
        slot.get_or_insert(layer.channel_data.pixels);
    }
    let (w, pixels) = mean.ok_or_else(|| "no RGB layer besides `stderr`".to_string())?;
    let error = error.map(|(_, e)| e);
    if let Some(e) = &error
        && e.len() != pixels.len()
    {
        return Err(format!(
            "its `stderr` layer has {} pixels but the image {}; write the reference again with `zerovar reference`",
            e.len(),
            pixels.len()
        ));
    }
    Ok((w, pixels.len() / w.max(1), pixels, error))
}

/// Writes the mean image and, as a second layer named `stderr`, its per-pixel standard error.
pub fn write_exr_with_error(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 3]],
    std_error: &[[f32; 3]],
    meta: &ImageMetadata,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let w = width as usize;
    let size = (w, height as usize);
    let mean = Layer::new(
        size,
        layer_attributes("rgb", meta),
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgb(|p: Vec2<usize>| {
            let c = pixels[p.y() * w + p.x()];
            (c[0], c[1], c[2])
        }),
    );
    let error = Layer::new(
        size,
        LayerAttributes::named("stderr"),
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgb(|p: Vec2<usize>| {
            let c = std_error[p.y() * w + p.x()];
            (c[0], c[1], c[2])
        }),
    );
    let attributes = ImageAttributes::new(IntegerBounds::from_dimensions(size));
    let image = Image::empty(attributes).with_layer(mean).with_layer(error);
    let fail = |message: String| OutputError::Exr { path: path.display().to_string(), message };
    crate::files::write_atomically(
        path,
        |tmp| image.write().to_file(tmp).map_err(|e| fail(e.to_string())),
        |e| fail(e.to_string()),
    )
}

fn layer_attributes(name: &str, meta: &ImageMetadata) -> exr::meta::header::LayerAttributes {
    use exr::meta::attribute::{AttributeValue, Text};
    let mut attributes = exr::meta::header::LayerAttributes::named(name);
    attributes.software_name =
        Some(Text::from(format!("zerovar {}", env!("CARGO_PKG_VERSION")).as_str()));
    let mut text = |k: &str, v: String| {
        // EXR text is Latin-1: other characters (a scene path with an en dash or a CJK
        // directory) become `?` rather than failing the write.
        let latin1: String = v.chars().map(|c| if u32::from(c) < 256 { c } else { '?' }).collect();
        attributes.other.insert(Text::from(k), AttributeValue::Text(Text::from(latin1.as_str())));
    };
    text("zerovar.spp", meta.spp.to_string());
    text("zerovar.seconds", format!("{:.3}", meta.seconds));
    text("zerovar.seed", meta.seed.to_string());
    text("zerovar.scene", meta.scene.clone());
    attributes
}

/// Writes row-major RGB pixels as a 32-bit float EXR with `meta` as header attributes.
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 3]],
    meta: &ImageMetadata,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let w = width as usize;
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let c = pixels[p.y() * w + p.x()];
        (c[0], c[1], c[2])
    });
    let attributes = layer_attributes("rgb", meta);
    let layer = Layer::new((w, height as usize), attributes, Encoding::SMALL_LOSSLESS, channels);
    let image = Image::from_layer(layer);
    let fail = |message: String| OutputError::Exr { path: path.display().to_string(), message };
    crate::files::write_atomically(
        path,
        |tmp| image.write().to_file(tmp).map_err(|e| fail(e.to_string())),
        |e| fail(e.to_string()),
    )
}

/// The sRGB transfer curve of a linear value, clamped to [0, 1].
fn srgb(v: f32) -> f32 {
    let v = if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 };
    if v <= 0.003_130_8 { 12.92 * v } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 }
}

/// Writes an 8-bit sRGB PNG preview, scaling linear values by 2^`exposure`.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 3]],
    exposure: f32,
) -> Result<(), OutputError> {
    let gain = exposure.exp2();
    let bytes: Vec<u8> =
        pixels.iter().flat_map(|c| c.map(|v| (srgb(v * gain) * 255.0 + 0.5) as u8)).collect();
    let fail = |message: String| OutputError::Png { path: path.display().to_string(), message };
    crate::files::write_atomically(
        path,
        |tmp| {
            image::save_buffer(tmp, &bytes, width, height, image::ColorType::Rgb8)
                .map_err(|e| fail(e.to_string()))
        },
        |e| fail(e.to_string()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene path outside Latin-1 (EXR's text) still writes, its metadata with `?` in place
    /// of the characters EXR cannot hold.
    #[test]
    fn metadata_outside_latin1_writes() {
        let dir = std::env::temp_dir().join(format!("zerovar-output-text-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let meta =
            ImageMetadata {
                spp: 1, seconds: 0.0, seed: 0, scene: "目录/fog–sphere ☃.toml".into()
            };
        let path = dir.join("text.exr");
        write_exr(&path, 2, 1, &[[0.5; 3]; 2], &meta).unwrap();
        write_exr_with_error(&path, 2, 1, &[[0.5; 3]; 2], &[[0.1; 3]; 2], &meta).unwrap();
        assert_eq!(read_exr(&path).unwrap().2, vec![[0.5; 3]; 2]);
    }

    /// A file whose header claims 60000 x 60000 pixels (a few hundred bytes on disk) is refused
    /// from its header, before any pixel is allocated, by both readers.
    #[test]
    fn an_exr_header_claiming_too_many_pixels_is_refused() {
        let dir = std::env::temp_dir().join(format!("zerovar-output-big-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let small = dir.join("small.exr");
        let meta = ImageMetadata { spp: 1, seconds: 0.0, seed: 0, scene: "s.toml".into() };
        write_exr(&small, 2, 2, &[[0.5; 3]; 4], &meta).unwrap();
        let mut bytes = std::fs::read(&small).unwrap();
        // The data window: `dataWindow\0box2i\0`, a 4-byte size, then xMin, yMin, xMax, yMax.
        let key = b"dataWindow\0box2i\0";
        let at =
            bytes.windows(key.len()).position(|w| w == key).expect("a data window") + key.len();
        for (i, v) in [0i32, 0, 59_999, 59_999].into_iter().enumerate() {
            bytes[at + 4 + 4 * i..at + 8 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        let big = dir.join("big.exr");
        std::fs::write(&big, bytes).unwrap();
        assert!(read_exr(&small).is_ok());
        for e in [read_exr(&big).unwrap_err(), read_exr_with_error(&big).unwrap_err()] {
            let e = e.to_string();
            assert!(e.contains("big.exr: cannot read EXR: its header claims 60000 x 60000"), "{e}");
        }
    }

    #[test]
    fn the_standard_error_layer_reads_back_only_where_written() {
        let dir = std::env::temp_dir().join(format!("zerovar-output-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let meta = ImageMetadata { spp: 4, seconds: 1.0, seed: 7, scene: "s.toml".into() };
        let (w, h) = (5u32, 3u32);
        let mean: Vec<[f32; 3]> = (0..15).map(|i| [i as f32, 0.5, -1.0]).collect();
        let error: Vec<[f32; 3]> = (0..15).map(|i| [0.1 * i as f32, 0.2, 0.3]).collect();
        let with = dir.join("with.exr");
        write_exr_with_error(&with, w, h, &mean, &error, &meta).unwrap();
        let (rw, rh, m, e) = read_exr_with_error(&with).unwrap();
        assert_eq!((rw, rh), (5, 3));
        assert_eq!((m, e), (mean.clone(), Some(error)));
        let without = dir.join("without.exr");
        write_exr(&without, w, h, &mean, &meta).unwrap();
        let (_, _, m, e) = read_exr_with_error(&without).unwrap();
        assert_eq!((m, e), (mean.clone(), None));
        assert_eq!(read_exr(&with).unwrap().2, mean);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
