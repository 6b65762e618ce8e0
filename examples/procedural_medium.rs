//! A scene assembled entirely in code: a procedural noise cloud in a null box over a floor,
//! lit by the sun and the sky, built with `SceneBuilder`, trained and rendered with adaptive
//! guiding into an in-memory image, and written as PNG. No scene file is involved.
//!
//! `cargo run --release --example procedural_medium [-- OUT.png]`

use glam::Vec3;
use std::path::PathBuf;
use zerovar::media::NoiseCloud;
use zerovar::output::write_png;
use zerovar::render::{Budget, RenderOptions, TrainBudget, render};
use zerovar::scene::SceneBuilder;
use zerovar::scene::desc::{
    AlbedoDesc, BsdfDesc, CameraDesc, LightDesc, MediumDesc, PhaseDesc, Rgb, ShapeDesc,
    TransformStep,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out =
        std::env::args().nth(1).map_or_else(|| PathBuf::from("procedural.png"), PathBuf::from);
    let camera =
        CameraDesc::look_at(Vec3::new(0.0, 1.2, 4.5), Vec3::new(0.0, 1.0, 0.0), 40.0, [160, 120]);
    // The noise fills the unit cube; place it on the box [-1, 1] x [0, 2] x [-1, 1].
    let to_box = vec![
        TransformStep::Translate(Vec3::splat(-0.5)),
        TransformStep::Scale(Rgb::Grey(2.0)),
        TransformStep::Translate(Vec3::Y),
    ];
    let cloud = MediumDesc {
        kind: "noise".into(),
        scale: Some(8.0),
        albedo: Some(AlbedoDesc::Constant(Rgb::Grey(0.95))),
        noise: Some(NoiseCloud { seed: 7, threshold: 0.3, ..NoiseCloud::default() }),
        transform: to_box,
        phase: Some(PhaseDesc::hg(0.6)),
        ..Default::default()
    };
    let sun = LightDesc {
        kind: "directional".into(),
        direction: Some(Vec3::new(-0.5, -1.0, -0.3)),
        irradiance: Some(Rgb::Grey(3.0)),
        angular_diameter: Some(0.53),
        ..Default::default()
    };
    let floor = vec![
        TransformStep::Rotate { axis: Vec3::X, angle: -90.0 },
        TransformStep::Scale(Rgb::Grey(4.0)),
    ];
    let scene = SceneBuilder::new(camera)
        .medium("cloud", cloud)
        .shape(ShapeDesc {
            interior: Some("cloud".into()),
            transform: vec![TransformStep::Translate(Vec3::Y)],
            ..ShapeDesc::placed("cube", Vec::new(), BsdfDesc::null())
        })
        .shape(ShapeDesc::placed("rectangle", floor, BsdfDesc::diffuse(Rgb::Grey(0.5))))
        .light(sun)
        .light(LightDesc::constant(Rgb::Rgb([0.15, 0.2, 0.3])))
        .build()?;

    let mut options = RenderOptions::unguided(Budget::Samples(16), 0);
    options.guiding.components = zerovar::guided::Components::FULL;
    options.guiding.adaptive = true;
    options.guiding.train = TrainBudget::Passes(4);
    let result = render(&scene, &options, &|_, _| true)?;
    let [w, h] = scene.camera().resolution();
    write_png(&out, w, h, &result.image, 0.0)?;
    let tiles = result.selection.map_or(0, |s| s.guided_tiles);
    println!(
        "{} spp in {:.1} s ({tiles} of {} tiles guided) -> {}",
        result.spp,
        result.seconds,
        w.div_ceil(16) * h.div_ceil(16),
        out.display()
    );
    Ok(())
}
