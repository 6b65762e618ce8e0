//! Embedding zerovar with guiding: train a field once, save it, and render later frames with
//! it, as a pipeline rendering many frames of one scene would.
//!
//! `cargo run --release --example trained_field`

use std::path::Path;
use zerovar::guided::{Components, TrainedField};
use zerovar::render::{Budget, RenderOptions, TrainBudget, render_with_field, train};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scene = zerovar::scene::load(Path::new("scenes/fog-sphere.toml"), &[])?;
    let mut options = RenderOptions::unguided(Budget::Samples(4), 0);
    options.guiding.components = Components::FULL;
    options.guiding.train = TrainBudget::Passes(3);

    let (trained, report) = train(&scene, &options, &|_, _| true)?;
    println!(
        "trained {} passes ({} spp) in {:.2} s: {} regions, {} lobes, {} KiB",
        report.passes,
        report.spp,
        report.seconds,
        report.field.regions,
        report.field.lobes,
        report.field.memory_bytes / 1024
    );
    let path = std::env::temp_dir().join("zerovar-example.zvg");
    trained.save(std::io::BufWriter::new(std::fs::File::create(&path)?))?;

    // Later, perhaps in another process: load the field and render with it.
    let trained = TrainedField::load(std::io::BufReader::new(std::fs::File::open(&path)?))?;
    let result = render_with_field(&scene, &options, &trained, &|_, _| true)?;
    println!(
        "rendered {} spp in {:.2} s, mean pixel {:?}",
        result.spp,
        result.seconds,
        result.film.average()
    );
    std::fs::remove_file(&path)?;
    Ok(())
}
