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
    /// PNG encoding or file error.
    #[error("{path}: cannot write PNG: {message}")]
    Png {
        /// The file.
        path: String,
        /// The reason.
        message: String,
    },
}

/// Reads the first RGB(A) layer of an EXR file as row-major pixels: (width, height, pixels).
pub fn read_exr(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>), OutputError> {
    let (w, h, pixels, _) = read_exr_with_error(path)?;
    Ok((w, h, pixels))
}

/// Reads an EXR file's first RGB(A) layer and, if it has one (as `zerovar reference` writes),
/// its layer named `stderr`: (width, height, pixels, standard errors).
#[allow(clippy::type_complexity)]
pub fn read_exr_with_error(
    path: &Path,
) -> Result<(usize, usize, Vec<[f32; 3]>, Option<Vec<[f32; 3]>>), OutputError> {
    let image = exr::prelude::read_all_rgba_layers_from_file(
        path,
        |res, _| (res.width(), vec![[0.0f32; 3]; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b]
        },
    )
    .map_err(|e| OutputError::Exr { path: path.display().to_string(), message: e.to_string() })?;
    let mut layers = image.layer_data.into_iter();
    let first = layers.next().ok_or_else(|| OutputError::Exr {
        path: path.display().to_string(),
        message: "no RGB layer".into(),
    })?;
    let (w, pixels) = first.channel_data.pixels;
    let error = layers
        .find(|l| l.attributes.layer_name.as_ref().is_some_and(|n| n.eq("stderr")))
        .map(|l| l.channel_data.pixels.1)
        .filter(|e| e.len() == pixels.len());
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
    Image::empty(attributes)
        .with_layer(mean)
        .with_layer(error)
        .write()
        .to_file(path)
        .map_err(|e| OutputError::Exr { path: path.display().to_string(), message: e.to_string() })
}

fn layer_attributes(name: &str, meta: &ImageMetadata) -> exr::meta::header::LayerAttributes {
    use exr::meta::attribute::{AttributeValue, Text};
    let mut attributes = exr::meta::header::LayerAttributes::named(name);
    attributes.software_name =
        Some(Text::from(format!("zerovar {}", env!("CARGO_PKG_VERSION")).as_str()));
    let mut text = |k: &str, v: String| {
        attributes.other.insert(Text::from(k), AttributeValue::Text(Text::from(v.as_str())));
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
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| OutputError::Exr { path: path.display().to_string(), message: e.to_string() })
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
    image::save_buffer(path, &bytes, width, height, image::ColorType::Rgb8)
        .map_err(|e| OutputError::Png { path: path.display().to_string(), message: e.to_string() })
}
