//! Embedding zerovar: the host application supplies the density (here an analytic smoke
//! plume standing in for a simulation) through `DensityFunction`; zerovar derives majorants
//! from its bounds, picks a tracker and renders. The rest of the scene comes from TOML text.
//!
//! `cargo run --release --example custom_medium [-- OUT.exr]`

use glam::{Vec3, Vec3A};
use std::path::Path;
use std::sync::Arc;
use zerovar::math::Spectrum;
use zerovar::media::{
    AlbedoField, DensityField, DensityFunction, Heterogeneous, Medium, MediumKind,
};
use zerovar::output::{ImageMetadata, write_exr};
use zerovar::phase::PhaseFunction;
use zerovar::render::{Budget, RenderOptions, render};
use zerovar::transform::Transform;

/// A plume rising along y and widening with height, in the unit cube.
#[derive(Debug)]
struct Plume;

impl DensityFunction for Plume {
    fn density(&self, p: Vec3A) -> f32 {
        let radius = 0.08 + 0.3 * p.y;
        let r2 = (p.x - 0.5).powi(2) + (p.z - 0.5).powi(2);
        (1.0 - r2 / (radius * radius)).max(0.0) * (1.0 - p.y)
    }

    fn max_density(&self) -> f32 {
        1.0
    }

    fn bounds(&self, lo: Vec3A, hi: Vec3A) -> (f32, f32) {
        // The plume's density falls with height, and is 0 outside its widest radius.
        let radius = 0.08 + 0.3 * hi.y;
        let nearest = Vec3A::new(0.5, 0.0, 0.5).clamp(lo, hi);
        let r2 = (nearest.x - 0.5).powi(2) + (nearest.z - 0.5).powi(2);
        if r2 >= radius * radius { (0.0, 0.0) } else { (0.0, 1.0 - lo.y) }
    }
}

const SCENE: &str = r#"
[camera]
origin = [0, 1.2, 4.5]
target = [0, 1, 0]
fov = 40
resolution = [160, 120]

[media.smoke]
type = "homogeneous"    # replaced in code below

[[shapes]]
type = "cube"
transform = [{ translate = [0, 1, 0] }]
bsdf = { type = "null" }
interior = "smoke"

[[shapes]]
type = "rectangle"
transform = [{ rotate = { axis = [1, 0, 0], angle = -90 } }, { scale = 4 }]

[[lights]]
type = "directional"
direction = [-0.5, -1, -0.3]
irradiance = 3
angular_diameter = 0.53

[[lights]]
type = "constant"
radiance = 0.15
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scene = zerovar::scene::load_str(Path::new("plume.toml"), SCENE, &[])?;
    // The plume fills the unit cube mapped onto the scene's [-1, 1] x [0, 2] x [-1, 1] box.
    let to_world = Transform::scale(Vec3::splat(2.0))
        .ok_or("bad scale")?
        .then(&Transform::translate(Vec3::new(-1.0, 0.0, -1.0)));
    let smoke = Heterogeneous::new(
        to_world,
        DensityField::Custom(Arc::new(Plume)),
        12.0,
        Spectrum::ONE,
        AlbedoField::Constant(Spectrum::splat(0.9)),
    );
    let medium = Medium {
        name: "smoke".into(),
        kind: MediumKind::Heterogeneous(Box::new(smoke)),
        phase: PhaseFunction::HenyeyGreenstein { g: 0.3 },
        emission: Spectrum::ZERO,
    };
    scene.replace_medium("smoke", medium)?;
    let result = render(&scene, &RenderOptions::unguided(Budget::Samples(16), 0), &|_, _| true)?;
    println!("{}", scene.describe());
    println!("mean pixel {:?} after {:.2} s", result.film.average(), result.seconds);
    if let Some(out) = std::env::args().nth(1) {
        let [w, h] = scene.camera().resolution();
        let meta = ImageMetadata {
            spp: result.spp,
            seconds: result.seconds,
            seed: 0,
            scene: "custom_medium".into(),
        };
        write_exr(Path::new(&out), w, h, &result.image, &meta)?;
        println!("wrote {out}");
    }
    Ok(())
}
