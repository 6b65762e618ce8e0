//! A foreign toy renderer embedding the guiding field: a point light in an infinite
//! homogeneous medium. Paths start at random points of a box, scatter with Henyey-Greenstein,
//! and find light by next-event estimation; the recorder turns them into training samples,
//! the field learns over a few passes, and is then queried.
//!
//! Run with `cargo run --release -p zerovar-guiding --example toy`.

use glam::{Vec2, Vec3};
use rand_pcg::Pcg32;
use rand_pcg::rand_core::Rng;
use zerovar_guiding::{Field, FieldConfig, PathRecorder, VolumeDistribution, hg};

const LIGHT: Vec3 = Vec3::new(0.0, 0.0, 4.0);
const SIGMA_T: f32 = 0.5; // extinction; albedo 0.9
const G: f32 = 0.6;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut rng = Pcg32::new(1, 1);
    let mut u = move || (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
    let mut field =
        Field::new(FieldConfig { max_samples_per_leaf: 4000, ..FieldConfig::default() })?;
    let (mut recorder, mut dist, mut samples) =
        (PathRecorder::new(), VolumeDistribution::default(), Vec::new());
    for pass in 0..6 {
        samples.clear();
        for _ in 0..20_000 {
            let mut x = Vec3::new(u(), u(), u()) * 4.0 - 2.0;
            // beta: path throughput arriving at x, the albedo of its collision included.
            let (mut ray, mut beta) = (hg::hg_sample(Vec3::Z, 0.0, Vec2::new(u(), u())), 1.0f32);
            for _bounce in 0..8 {
                // Next-event estimation towards the light (intensity 50, transmittance e^-sigma d).
                let to_light = LIGHT - x;
                let d = to_light.length();
                let wl = to_light / d;
                let li = 50.0 * (-SIGMA_T * d).exp() / (d * d);
                let phase = |w: Vec3| hg::hg_pdf(ray.dot(w), G);
                // What this vertex scatters towards the previous one reaches every earlier vertex.
                recorder.add_weighted_contribution(beta * phase(wl) * li);
                // Guided or phase sampling, one-sample mixture 50/50 once the field is trained.
                let guided = dist.init(&field, x, u());
                if guided {
                    dist.apply_hg_product(ray, G);
                }
                let w = if guided && u() < 0.5 {
                    dist.sample(Vec2::new(u(), u()))
                } else {
                    hg::hg_sample(ray, G, Vec2::new(u(), u()))
                };
                let pdf = if guided { 0.5 * dist.pdf(w) + 0.5 * phase(w) } else { phase(w) };
                beta *= phase(w) / pdf;
                recorder.add_vertex(x, w, pdf, beta, true);
                // A point light is a delta: its sample carries the irradiance li with "pdf" 1.
                recorder.add_direct_sample(x, wl, 1.0, li, true);
                x += w * (-(1.0 - u()).ln() / SIGMA_T); // analog free flight
                ray = w;
                beta *= 0.9; // albedo of the next collision
            }
            recorder.finish(&mut samples);
        }
        field.update(&samples)?;
        let s = field.stats();
        println!(
            "pass {pass}: {} samples, {} regions, {} lobes, update {:.1} ms",
            samples.len(),
            s.regions,
            s.lobes,
            s.last_update_seconds * 1e3
        );
    }
    // Query: the learned incident light at a point should point at the light.
    let x = Vec3::new(0.5, -0.5, 0.0);
    if dist.init(&field, x, 0.5) {
        let to_light = (LIGHT - x).normalize();
        let d = (LIGHT - x).length();
        let direct = 50.0 * (-SIGMA_T * d).exp() / (d * d);
        println!(
            "at {x}: fluence {:.3} (direct part alone {direct:.3}), L towards light {:.3}, away {:.3}",
            dist.fluence(),
            dist.incident_radiance(to_light),
            dist.incident_radiance(-to_light)
        );
        println!(
            "in-scattered radiance along +z: {:.3}, along -z: {:.3}",
            dist.inscattered_radiance(Vec3::Z, G),
            dist.inscattered_radiance(-Vec3::Z, G)
        );
        dist.apply_hg_product(Vec3::X, G);
        let (w, pdf) = dist.sample_with_pdf(Vec2::new(0.3, 0.7));
        println!("a guided direction {w} with pdf {pdf:.3} (pdf check {:.3})", dist.pdf(w));
    }
    Ok(())
}
