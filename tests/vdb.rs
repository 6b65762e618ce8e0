//! OpenVDB grids in scenes: a `.vdb` renders exactly as the `.vol` of the same voxels, its own
//! index-to-world map places it (before the scene's transform), and bad files are errors
//! naming the file, the scene line and the fix.

use crate::common::{repo, write};
use glam::Vec3A;
use zerovar::math::Ray;
use zerovar::media::Medium;
use zerovar::render::{Budget, RenderOptions, render};
use zerovar::rng::Sampler;
use zerovar::scene::{Scene, SceneError, load_str};
use zerovar::stats::Counters;
use zerovar::tracking::transmittance;
use zerovar_testkit::MeanEstimate;

fn data(name: &str) -> String {
    repo("tests/data/vdb").join(name).to_str().unwrap().replace('\\', "/")
}

/// A scene around one grid medium given by its TOML fields.
fn toml(medium: &str) -> String {
    format!(
        r#"
[render]
spp = 2
max_depth = 16

[camera]
origin = [0.4, 0.5, 4]
target = [0, 0, 0]
fov = 40
resolution = [24, 16]

[media.m]
type = "grid"
albedo = 0.9
phase = {{ type = "hg", g = 0.3 }}
{medium}

[[shapes]]
type = "cube"
transform = [{{ scale = 6 }}]
bsdf = {{ type = "null" }}
interior = "m"

[[lights]]
type = "directional"
direction = [-0.3, -1, -0.2]
irradiance = 2

[[lights]]
type = "constant"
radiance = 0.3
"#
    )
}

fn load(name: &str, text: &str) -> Result<Scene, SceneError> {
    load_str(&write(name, text), text, &[])
}

fn image(scene: &Scene) -> Vec<[f32; 3]> {
    render(scene, &RenderOptions::unguided(Budget::Samples(2), 7), &|_, _| true).unwrap().image
}

#[test]
fn a_vdb_renders_exactly_as_the_vol_of_its_voxels_from_toml_and_xml() {
    // blob.vol holds the dense grid of blob.vdb; the matrix puts its unit cube where the
    // VDB's voxel size and translation put the VDB's box.
    let vol = load(
        "vol.toml",
        &toml(&format!(
            "density = \"{}\"\nscale = 3\ntransform = [{{ matrix = [[2.25, 0, 0, -1.125], \
             [0, 1.75, 0, -0.875], [0, 0, 1.25, -0.625], [0, 0, 0, 1]] }}]",
            data("blob.vol")
        )),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let vdb = load("vdb.toml", &toml(&format!("density = \"{}\"\nscale = 3", data("blob.vdb"))))
        .unwrap_or_else(|e| panic!("{e}"));
    let reference = image(&vol);
    assert!(reference.iter().flatten().any(|&v| v > 0.0));
    assert!(reference == image(&vdb), "the .vdb and the .vol render differently");

    let xml = format!(
        r#"<scene version="3.0.0">
    <integrator type="volpath"><integer name="max_depth" value="16"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0.4, 0.5, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film>
    </sensor>
    <medium type="heterogeneous" id="m">
        <volume type="gridvolume" name="sigma_t">
            <string name="filename" value="{}"/>
            <string name="grid_name" value="density"/>
        </volume>
        <rgb name="albedo" value="0.9"/>
        <float name="scale" value="3"/>
        <phase type="hg"><float name="g" value="0.3"/></phase>
    </medium>
    <shape type="cube">
        <transform name="to_world"><scale value="6"/></transform>
        <bsdf type="null"/><ref name="interior" id="m"/>
    </shape>
    <emitter type="directional"><vector name="direction" value="-0.3, -1, -0.2"/><rgb name="irradiance" value="2"/></emitter>
    <emitter type="constant"><rgb name="radiance" value="0.3"/></emitter>
</scene>
"#,
        data("blob.vdb")
    );
    let path = write("vdb.xml", &xml);
    let from_xml = zerovar::scene::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
    assert!(reference == image(&from_xml), "the XML .vdb renders differently");
}

/// Ratio-tracked transmittance along `ray` for 10 units.
fn tracked(m: &Medium, ray: &Ray) -> MeanEstimate {
    let mut counters = Counters::default();
    let mut est = MeanEstimate::default();
    for i in 0..20_000 {
        let mut s = Sampler::new(3, 0, i);
        est.push(transmittance(m, ray, 10.0, &mut s, &mut counters)[0] as f64);
    }
    est
}

#[test]
fn the_vdb_transform_places_the_grid_and_the_scene_transform_moves_it() {
    // offset.vdb: density 2 in index 0..3, voxels of 1/4, translated by (3, 0, 0). Along x the
    // trilinear density integrates to 2 * 4 * 0.25 = 2 (the ramps into the border voxels add
    // what the clamped half voxels lose), so with scale 0.5 a ray through it sees exp(-1).
    for (shift, y) in [("", 0.375f32), ("transform = [{ translate = [0, 5, 0] }]", 5.375)] {
        let text = toml(&format!("density = \"{}\"\nscale = 0.5\n{shift}", data("offset.vdb")));
        let scene = load("offset.toml", &text).unwrap_or_else(|e| panic!("{e}"));
        let m = &scene.media()[0];
        let through = Ray::new(Vec3A::new(1.5, y, 0.375), Vec3A::X);
        tracked(m, &through).assert_matches((-1.0f64).exp(), 4.5, &format!("through ({shift})"));
        // Where the block would be if the VDB's translation were dropped, or applied after
        // the scene's transform (which would scale the shift of 5 by the voxel size): nothing.
        let t = tracked(m, &Ray::new(Vec3A::new(0.375, y, -2.0), Vec3A::Z));
        assert!(t.mean > 0.999_999 && t.std_error() < 1e-9, "beside: {t:?} ({shift})");
        // Point lookups agree: inside the block's world box and outside it.
        assert_eq!(m.coefficients(Vec3A::new(3.4, y, 0.375)).sigma_t[0], 1.0);
        assert_eq!(m.coefficients(Vec3A::new(0.4, y, 0.375)).sigma_t[0], 0.0);
    }
}

#[test]
fn bad_vdb_files_are_errors_naming_the_file_and_the_fix() {
    let mut truncated = std::fs::read(data("blob.vdb")).unwrap();
    truncated.truncate(truncated.len() / 2);
    write("half-a.vdb", truncated);
    write("text.vdb", "this is not an OpenVDB file at all");
    let temp = |n: &str| crate::common::temp_dir().join(n).to_str().unwrap().replace('\\', "/");
    let cases: Vec<(String, &str, Vec<&str>)> = vec![
        (temp("nowhere.vdb"), "", vec!["nowhere.vdb: cannot read the VDB file"]),
        (temp("half-a.vdb"), "", vec!["half-a.vdb: truncated", "re-export"]),
        (temp("text.vdb"), "", vec!["text.vdb: not an OpenVDB file"]),
        (data("multi.vdb"), "", vec!["no grid named `density`", "`smoke`, `temperature`"]),
        (data("multi.vdb"), "grid_name = \"fog\"", vec!["no grid named `fog`", "grid_name"]),
        (data("multi.vdb"), "grid_name = \"vel\"", vec!["`vel` is of type Tree_vec3s_5_4_3"]),
        (data("huge.vdb"), "", vec!["1009027027 voxels", "crop or resample"]),
        (data("negative.vdb"), "", vec!["voxel [1, 0, 1] holds -1"]),
        (data("blob.vol"), "grid_name = \"density\"", vec!["applies only to a .vdb"]),
        (data("blob.vdb"), "albedo = \"x.vol\"", vec!["albedo grid needs a .vol density"]),
    ];
    for (file, extra, needles) in cases {
        let text = toml(&format!("density = \"{file}\"\n{extra}")).replace("albedo = 0.9\n", "");
        let e = load("bad.toml", &text).unwrap_err().to_string();
        assert!(e.contains("bad.toml:") && e.contains("media.m"), "{e}");
        for n in needles {
            assert!(e.contains(n), "{file} {extra}: `{n}` not in: {e}");
        }
    }
    let e = load("bad.toml", &toml("density = 1\ngrid_name = \"density\"")).unwrap_err();
    assert!(e.to_string().contains("applies only to a .vdb"), "{e}");
    // In XML: a grid name for a .vol file, and a grid the file lacks, at the volume's line.
    for (file, name, needle) in [
        (data("blob.vol"), "density", "bad.xml:4:1: grid_name applies only to a .vdb"),
        (data("multi.vdb"), "fog", "no grid named `fog`"),
    ] {
        let xml = format!(
            "<scene version=\"3.0.0\">\n<medium type=\"heterogeneous\" id=\"m\">\n\
             <volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" \
             value=\"{file}\"/>\n<string name=\"grid_name\" value=\"{name}\"/></volume>\n\
             </medium>\n<shape type=\"cube\"><ref name=\"interior\" id=\"m\"/>\
             <bsdf type=\"null\"/></shape>\n<emitter type=\"constant\"/>\n<sensor type=\"perspective\"><float name=\"fov\" \
             value=\"40\"/></sensor>\n<integrator type=\"volpath\"/>\n</scene>\n"
        );
        let e = zerovar::scene::load(&write("bad.xml", &xml), &[]).unwrap_err().to_string();
        assert!(e.contains(needle), "{e}");
    }
}

#[test]
fn the_example_vdb_cloud_has_the_density_field_of_the_vol_cloud() {
    // vdb-cloud.toml places cloud.vdb (the voxels of cloud.vol) where cloud.toml puts
    // cloud.vol; outside the VDB's active box cloud.vol holds zeros, as the VDB's border does.
    let load = |f: &str| zerovar::scene::load(&repo(f), &[]).unwrap_or_else(|e| panic!("{e}"));
    let (vol, vdb) = (load("scenes/cloud.toml"), load("scenes/vdb-cloud.toml"));
    let (a, b) = (&vol.media()[0], &vdb.media()[0]);
    let mut s = Sampler::new(5, 0, 0);
    let mut inside = 0;
    for _ in 0..20_000 {
        let u = Vec3A::new(s.next_1d(), s.next_1d(), s.next_1d());
        let p = Vec3A::new(-2.0, -0.2, -2.0) + u * Vec3A::new(4.0, 2.8, 4.0);
        let (x, y) = (a.coefficients(p).sigma_t[0], b.coefficients(p).sigma_t[0]);
        // Placement differs only by rounding of the two transforms (about 1e-7 of a voxel).
        assert!((x - y).abs() <= 1e-3 * x.max(1.0), "at {p}: {x} vs {y}");
        inside += (x > 0.0) as u32;
    }
    assert!(inside > 1000, "only {inside} points in the cloud");
}
