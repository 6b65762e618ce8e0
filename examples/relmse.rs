//! Relative mean squared error of EXR images against a reference, as the guided-against-
//! unguided measurements in README use it (until `zerovar compare` exists):
//! `cargo run --release --example relmse -- REFERENCE.exr IMAGE.exr...`.
//!
//! relMSE = mean over pixels and channels of (I - R)^2 / (R^2 + 1e-3).

fn read(path: &str) -> Result<(usize, usize, Vec<[f32; 3]>), String> {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0.0f32; 3]; res.width() * res.height()]),
        |(w, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| px[pos.y() * *w + pos.x()] = [r, g, b],
    )
    .map_err(|e| format!("{path}: {e}"))?;
    let (w, px) = image.layer_data.channel_data.pixels;
    Ok((w, px.len() / w.max(1), px))
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [reference, images @ ..] = args.as_slice() else {
        return Err("usage: relmse REFERENCE.exr IMAGE.exr...".into());
    };
    let (w, h, r) = read(reference)?;
    for path in images {
        let (wi, hi, img) = read(path)?;
        if (wi, hi) != (w, h) {
            return Err(format!("{path}: {wi}x{hi} does not match the reference's {w}x{h}"));
        }
        let mut sum = 0.0f64;
        for (a, b) in img.iter().zip(&r) {
            for c in 0..3 {
                let (a, b) = (a[c] as f64, b[c] as f64);
                sum += (a - b).powi(2) / (b * b + 1e-3);
            }
        }
        println!("{path}: relMSE {:.5}", sum / (3 * w * h) as f64);
    }
    Ok(())
}
