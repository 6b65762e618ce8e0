//! Relative mean squared error of EXR images against a reference (the metric of
//! `zerovar compare`, for images rendered elsewhere):
//! `cargo run --release --example relmse -- REFERENCE.exr IMAGE.exr...`.

use std::path::Path;
use zerovar::output::read_exr;
use zerovar_lab::metrics::compare;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [reference, images @ ..] = args.as_slice() else {
        return Err("usage: relmse REFERENCE.exr IMAGE.exr...".into());
    };
    let (_, _, r) = read_exr(Path::new(reference))?;
    for path in images {
        let (_, _, img) = read_exr(Path::new(path))?;
        let e = compare(&img, &r, 0.0).map_err(|e| format!("{path}: {e}"))?;
        println!("{path}: relMSE {:.5}", e.rel_mse.all);
    }
    Ok(())
}
